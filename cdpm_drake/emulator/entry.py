"""The console entry point `cdpm-reel-emulator` (and `cdpm emulate`): the UDP reel bridge
(emulator/main.py) or, with `--canopen`, CiA 402 drives on a CAN bus
(emulator/canopen_drives.py). Here so that those two import neither each other."""

import sys


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--canopen" in argv:  # CiA 402 drives on a CAN bus instead of the UDP bridge
        from cdpm_drake.emulator.canopen_drives import main as canopen_main

        argv.remove("--canopen")
        return canopen_main(argv)
    from cdpm_drake.emulator.main import main as bridge_main

    return bridge_main(argv)
