"""The project's scripts (scripts/, not a package) as modules, for tests that run their
functions."""

import importlib.util
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"


def load_script(relative: str):
    """scripts/<relative> (e.g. "tools/make_reference_logs.py") imported as a module named
    after its file."""
    path = SCRIPTS / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
