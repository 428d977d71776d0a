"""The two errors a command raises to end with a one-line message and no traceback: a bad
argument (CliError, exit 2) and a file or folder that cannot be found or read (InputError,
exit 1). `cdpm_drake.cli.cdpm.main` turns them into exit codes."""


class CliError(Exception):
    """A bad command-line argument (usage, exit 2); printed without a traceback."""


class InputError(Exception):
    """A file or folder named on the command line that cannot be found or read (exit 1, as
    for a scenario or robot that cannot be found); printed without a traceback."""
