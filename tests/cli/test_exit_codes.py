"""Exit codes agree across every command (issue 22, point 8): a path that cannot be found is an
error (1), like a scenario that cannot be found; a malformed command line is bad usage (2). The
guide (docs/running.md, in full) and `cdpm --help` list the same codes."""

import re

import pytest
from helpers_docs import page

from cdpm_drake import cli
from cdpm_drake.cli.cdpm import EXIT_CODES, build_parser

# The exit codes in full are in docs/running.md (the README lists them in short).
README = page("running")

# Every command: (arguments, exit code, what stderr says). "MISSING" is a path in an empty
# folder; "EMPTY" an empty folder (a run folder without its files); "FILE" a file.
CASES = {
    "info": [(["MISSING/robot.yaml"], 1, "does not exist"),
             (["--bogus"], 2, "unrecognized arguments: --bogus")],
    "simulate": [(["MISSING/s.yaml"], 1, "does not exist"),
                 (["exp1_no_interaction", "--duration", "-1"], 2, "--duration must be"),
                 (["exp1_no_interaction", "--duration", "0.001"], 2,
                  "shorter than one tick"),
                 # Refused before the run: a replay that cannot be written (FILE is a file).
                 (["exp1_no_interaction", "--duration", "0.01", "--html", "FILE/replay.html"],
                  2, "--html's folder 'FILE' is not a writable directory")],
    "run": [(["MISSING/s.yaml"], 1, "does not exist"),
            ([], 2, "the following arguments are required: scenario")],
    "emulate": [(["--scenario", "MISSING/s.yaml"], 1, "does not exist"),
                (["--bogus"], 2, "unrecognized arguments: --bogus")],
    "plot": [(["MISSING"], 1, "does not exist"),
             (["EMPTY"], 1, "does not exist"),
             (["MISSING/log.npz"], 1, "does not exist"),
             ([], 2, "the following arguments are required: log")],
    "export": [(["MISSING", "--csv"], 1, "does not exist"),
               (["EMPTY"], 1, "does not exist"),  # CSV is the default format
               (["EMPTY", "--xlsx"], 2, "unrecognized arguments: --xlsx"),
               (["EMPTY", "--mat", "--mcap"], 2, "argument --mcap: not allowed with")],
    "diagram": [(["MISSING/s.yaml"], 1, "does not exist"),
                (["exp1_no_interaction", "--depth", "0"], 2, "--depth must be")],
    "sweep": [(["MISSING/sweep.yaml"], 1, "does not exist"),
              (["exp2_du_Fu", "--workers", "0"], 2, "--workers must be")],
    "recover": [(["MISSING"], 1, "does not exist"),
                (["EMPTY"], 1, "has no ticks.bin"),
                ([], 2, "the following arguments are required: RUN_DIR")],
    "list": [(["extra"], 2, "unrecognized arguments: extra")],
    "calibrate": [(["MISSING", "--robot", "paper_7cable"], 1, "does not exist"),
                  (["EMPTY", "--robot", "MISSING/robot.yaml"], 1, "does not exist"),
                  (["EMPTY", "--robot", "paper_7cable", "--max-poses", "1"], 2,
                   "--max-poses must be within")],
    "warm": [(["--bogus"], 2, "unrecognized arguments: --bogus")],
}


def _commands():
    parser = build_parser()
    return set(next(a for a in parser._actions if a.dest == "command").choices)


def test_every_command_has_its_cases():
    # A new command must say how it exits on a missing path and on bad usage.
    assert set(CASES) == _commands()


def _exit_code(argv):
    try:
        return cli.main(argv)
    except SystemExit as e:  # argparse's usage errors
        return e.code


@pytest.mark.parametrize("command, args, code, message",
                         [(c, a, code, m) for c, cases in CASES.items()
                          for a, code, m in cases])
def test_exit_codes_agree_across_commands(tmp_path, capsys, monkeypatch, command, args, code,
                                          message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "EMPTY").mkdir()
    (tmp_path / "FILE").write_text("")
    assert _exit_code([command, *args]) == code
    err = capsys.readouterr().err
    assert message in err, err
    if code == 1:
        assert err.startswith(("cdpm ", "cdpm-reel-emulator")) and ": error: " in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["EMPTY", "FILE"]  # nothing left


def _codes(text):
    return {int(c) for c in re.findall(r"^\s*(\d+)\s{2,}", text, re.MULTILINE)}


def test_the_readme_and_help_list_the_same_exit_codes():
    section = README.split("**Exit codes**", 1)[1].split("\n\n", 1)[0]
    in_readme = {int(c) for c in re.findall(r"`(\d+)`", section)}
    assert in_readme == _codes(EXIT_CODES) == {0, 1, 2, 130, 143}
    # "cannot be found" is an error (1) in both, never bad usage (2).
    one = re.search(r"`1` error \(([^)]*)\)", section).group(1)
    assert "cannot be found" in one and "cannot be found" not in section.split("`2`")[1]
    help_one = EXIT_CODES.split("\n  1 ")[1].split("\n  2 ")[0]
    assert "cannot be found" in help_one
