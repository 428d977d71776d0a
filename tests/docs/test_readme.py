"""The README says what a new user needs (issue 10, point 11): the supported platforms, every
command, the exit codes `cdpm --help` prints; its page on the robot (docs/on_the_robot.md) what
the run report's figures mean; the scripts' docstrings speak of the project only (not of its
issue tracker)."""

import ast
import re
from pathlib import Path

from cdpm_drake.cli.cdpm import EXIT_CODES, build_parser
from helpers_docs import page

REPO = Path(__file__).resolve().parents[2]
README = page("README")
FLAT = " ".join(README.split())  # line breaks fall anywhere in prose
ON_THE_ROBOT = " ".join(page("on_the_robot").split())


def test_the_readme_names_the_drake_release_pyproject_pins():
    import re
    from pathlib import Path

    pyproject = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    pin = re.search(r'"(drake>=[0-9.]+)"', pyproject).group(1)
    assert f"`{pin}`" in FLAT, pin
    # The platforms below are that release's wheels: one version in both places.
    assert len(set(re.findall(r"drake>=([0-9.]+)", FLAT))) == 1


def test_the_readme_states_the_supported_platforms():
    # Drake 1.51's wheels on PyPI: manylinux_2_34_x86_64 for cp310..cp314, macosx_15_0_arm64
    # for cp313 and cp314 (nothing for Windows, Linux arm64 or Intel Macs).
    for fact in ("Linux x86_64", "glibc 2.34", "CPython 3.10 to 3.14", "macOS 15",
                 "Apple silicon (arm64)", "CPython 3.13 or 3.14", "Not Windows"):
        assert fact in FLAT, fact


def test_the_readme_lists_every_command():
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    for name in commands:
        assert re.search(rf"^\| `cdpm {name}\b", README, re.MULTILINE), name


def test_the_readme_and_help_give_the_same_exit_codes():
    for code in ("0", "1", "2", "130", "143"):
        assert f"`{code}`" in README
        assert re.search(rf"^  {code}\s+\S", EXIT_CODES, re.MULTILINE), code
    assert "143` after SIGTERM" in FLAT and "143  stopped by SIGTERM" in EXIT_CODES


def test_the_readme_defines_the_run_reports_figures():
    # The README's "On the robot" names them; docs/on_the_robot.md defines them.
    for term in ("tick period", "compute time per tick", "overruns"):
        assert term in FLAT, term
    for term in ("**tick period**", "**compute time per tick**", "**overruns**"):
        assert term in ON_THE_ROBOT, term
    assert ("more than one period (2 ms) behind the schedule set by the first tick"
            in ON_THE_ROBOT)


def test_script_docstrings_speak_of_the_project_only():
    for path in sorted((REPO / "scripts").rglob("*.py")):
        tree = ast.parse(path.read_text())
        texts = [ast.get_docstring(tree) or ""]
        texts += [n.value.value for n in ast.walk(tree) if isinstance(n, ast.Expr)
                  and isinstance(n.value, ast.Constant) and isinstance(n.value.value, str)]
        comments = [line for line in path.read_text().splitlines() if "#" in line]
        for text in texts + comments:
            assert not re.search(r"\bissue \d|\bitem \d|\blead'?s?\b", text, re.IGNORECASE), (
                path.name, text[:120])
