"""`cdpm warm`: every group of kernels the commands need, compiled (or loaded from the cache)
in one step, a line per group with what it compiled and its time; afterwards a command of
each kind compiles nothing, so it prints no compile notice."""

import io
import re
import subprocess
import sys

from cdpm_drake.cli import main
from cdpm_drake.cli.compile_notice import COMPILE_NOTICE
from cdpm_drake.cli.warm import GROUPS, warm


def test_warm_says_each_group_with_what_it_compiled_and_its_time(capsys):
    assert main(["warm"]) == 0
    out = capsys.readouterr()
    lines = out.out.splitlines()
    assert lines[0].startswith(f"cdpm warm: compiling the per-tick math of {len(GROUPS)} groups")
    for k, (what, commands, _, _) in enumerate(GROUPS, 1):
        line = next((l for l in lines if l.startswith(f"  [{k}/{len(GROUPS)}] {what} ")), None)
        assert line is not None, (what, lines)
        assert re.search(r": \d+ compiled, \d+\.\d s$", line), line
        assert f"(cdpm {commands})" in line
    total = float(re.search(r"done in ([0-9.]+) s", lines[-1]).group(1))
    per_group = sum(float(re.search(r"compiled, ([0-9.]+) s$", l).group(1))
                    for l in lines if l.startswith("  ["))
    assert total >= per_group - 0.1 * len(GROUPS)  # rounding of each line
    # warm says what it compiles itself: the one-line notice of other commands is not repeated.
    assert COMPILE_NOTICE not in out.err


# Variants of the commands beyond the groups: the same kernels, other branches, so after
# warm they compile nothing either (simulate's scenario and overlay).
BEYOND = (("exp2_interaction", "method: paper"),
          ("exp2_interaction", "{plant: !DynamicReels {tension_sensor: load_cell}, "
                               "controller: {pose: full, tension_control: true}}"),
          ("exp3_two_pairs", "{plant: !DynamicReels {tension_sensor: none}}"))


def test_after_warm_a_command_of_each_kind_compiles_nothing(tmp_path):
    """Each group's own command and the variants beyond them, each in a fresh process that
    shares the cache: no compilation, so no compile notice."""
    warm(out=io.StringIO())
    cdpm = [sys.executable, "-m", "cdpm_drake.cli"]
    commands = [(scenario, overlay) for _, _, scenario, overlay in GROUPS] + list(BEYOND)
    assert any(s is None for s, _ in commands)  # cdpm info's workspace statics
    for k, (scenario, overlay) in enumerate(commands):
        if scenario is None:
            args = ["info", "paper_7cable", "--grid", "0.2"]
        else:
            args = ["simulate", scenario, "--duration", "0.1", "--no-progress",
                    "--out", str(tmp_path / f"run{k}")]
            if overlay:
                args += ["--scenario-text", overlay]
        run = subprocess.run(cdpm + args, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, (args, run.stderr[-2000:])
        assert COMPILE_NOTICE not in run.stderr, (args, run.stderr[-2000:])
