"""The hardware side: the reel link to the reel bridge and everything a real-time run needs.

  protocol.py       datagram layout, encode/decode, sequence numbers (hardware/PROTOCOL.md)
  link.py           the controller's non-blocking UDP endpoint, with counters
  config.py         `HardwareReels`, the scenario's `!HardwareReels` plant entry
  reels.py          HardwareReelsSystem, the Drake plant talking to the bridge (imports Drake)
  canopen_config.py `CanopenReels`, the `!CanopenReels` plant entry, and its bus-load budget
  canopen_bus.py    CanopenMaster: SDO mapping, NMT, RPDO + SYNC, TPDO/EMCY/heartbeat intake
  canopen_reels.py  CanopenReelsSystem, the Drake plant on CiA 402 drives (imports Drake)
  force_config.py   the handle's force sensor configs (`!BridgeForce`, `!CanopenForceSensor`,
                    `!NetFT`) and their checks
  force_sources.py  scaling, axes and tare; ATI's RDT; NetFTSource (a Net F/T over UDP)
  interface.py      HardwarePlant: what every hardware plant implements (hardware/INTERFACE.md)
  tick_log.py       the streaming per-tick log; tick_log_sink.py its Drake wrapper
  priority.py       SCHED_FIFO for the control loop and the emulator (`--rt-priority`)

Only reels.py, canopen_reels.py and tick_log_sink.py import Drake; the rest runs in the emulator process and
in plain tests. The emulator (`cdpm_drake/emulator/`, cdpm-reel-emulator) is a rehearsal
tool, not part of the driver: it uses this package's protocol, never the other way round, and
nothing here imports the scenario, the builder or the CLI.
"""
