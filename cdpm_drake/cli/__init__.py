"""The `cdpm` command line: `cdpm.py` parses the arguments and runs one command, each command
family in its own module (info, simulate, run, plot, export, recover, diagram, sweep, listing),
with the arguments they share (arguments.py), their errors (errors.py), the run summaries
(summaries.py), the Meshcat views (meshcat.py) and the compile notice (compile_notice.py).

`main` is here for the console script (`cdpm = "cdpm_drake.cli:main"`) and `python -m
cdpm_drake.cli`."""

from cdpm_drake.cli.cdpm import main

__all__ = ["main"]
