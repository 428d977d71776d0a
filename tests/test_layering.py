"""The package's folders are its layers, and imports point down only:

    cli/ -> runs/ (simulate, realtime, sweep/, the log) -> diagram.py, config/, emulator/
         -> systems/, hardware/, robot/ -> kernels/ (numba and numpy, no Drake)

Read from the source with `ast`, so a new upward import fails here by name. A rule is a
folder (or a root module) and the folders it may import; text.py and data/ are leaves every
layer may use."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "cdpm_drake"
LEAVES = {"text", "data"}
# What each top-level unit of the package may import from the package (besides itself and
# the leaves). Views read logs through runs/ and draw the diagram they are handed.
MAY_IMPORT = {
    "kernels": set(),
    "robot": {"kernels"},
    "hardware": {"kernels", "robot", "systems"},
    "systems": {"kernels", "robot"},
    "config": {"kernels", "robot", "hardware"},
    "diagram": {"kernels", "robot", "systems", "hardware", "config"},
    "emulator": {"kernels", "robot", "systems", "hardware", "config", "diagram", "runs"},
    "runs": {"kernels", "robot", "systems", "hardware", "config", "diagram"},
    "views": {"kernels", "robot", "config", "runs"},
    "cli": {"kernels", "robot", "systems", "hardware", "config", "diagram", "emulator",
            "runs", "views"},
}
ROOT_MODULES_AT_MOST = 6
LINES_AT_MOST = 800


def _unit(path: Path) -> str:
    """The top-level unit of the package that `path` belongs to (its folder, or the root
    module's name)."""
    rel = path.relative_to(PACKAGE).parts
    return rel[0] if len(rel) > 1 else Path(rel[0]).stem


def _package_imports(path: Path) -> set[str]:
    """The top-level units of cdpm_drake that `path` imports (relative or absolute)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    here = list(path.relative_to(PACKAGE).parts[:-1])
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - (node.level - 1)]
                parts = base + ((node.module or "").split(".") if node.module else [])
                if parts:
                    out.add(parts[0])
                else:
                    out.update(a.name.split(".")[0] for a in node.names)
            elif node.module == "cdpm_drake":
                out.update(a.name for a in node.names)
            elif node.module and node.module.startswith("cdpm_drake."):
                out.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("cdpm_drake."):
                    out.add(a.name.split(".")[1])
    return out


def _modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def test_every_unit_imports_only_the_layers_below_it():
    offenders = {}
    for path in _modules():
        unit = _unit(path)
        if unit in LEAVES or unit == "__init__":
            continue
        assert unit in MAY_IMPORT, f"{path}: a new top-level unit {unit!r} has no rule here"
        bad = _package_imports(path) - MAY_IMPORT[unit] - LEAVES - {unit, "__version__"}
        if bad:
            offenders[str(path.relative_to(PACKAGE))] = sorted(bad)
    assert not offenders, f"imports that climb a layer: {offenders}"


def test_the_leaves_import_nothing_of_the_package():
    for path in _modules():
        if _unit(path) in LEAVES:
            assert not _package_imports(path) - {_unit(path)}, path


def _imports_drake(path: Path) -> bool:
    """True when `path` imports pydrake anywhere (at module level or inside a function)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        names = ([node.module or ""] if isinstance(node, ast.ImportFrom)
                 else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
        if any(n.split(".")[0] == "pydrake" for n in names):
            return True
    return False


def test_the_kernels_import_no_drake():
    offenders = [str(p.relative_to(PACKAGE)) for p in _modules()
                 if _unit(p) == "kernels" and _imports_drake(p)]
    assert not offenders, f"kernels importing Drake: {offenders}"


def test_the_root_holds_only_the_builder_and_a_few_leaves():
    root = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(root) <= ROOT_MODULES_AT_MOST, root


def test_no_package_file_is_over_800_lines():
    long = {str(p.relative_to(PACKAGE)): n for p in _modules()
            if (n := len(p.read_text().splitlines())) > LINES_AT_MOST}
    assert not long, long


def test_no_private_name_is_imported_across_modules():
    offenders = []
    for top in ("cdpm_drake", "tests", "scripts"):
        for path in sorted((PACKAGE.parent / top).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if (isinstance(node, ast.ImportFrom) and node.module
                        and node.module.startswith("cdpm_drake")):
                    offenders += [f"{path.name}: {node.module}.{a.name}" for a in node.names
                                  if a.name.startswith("_") and not a.name.startswith("__")]
    assert not offenders, offenders


def test_the_emulator_lives_outside_the_driver_package():
    assert not (PACKAGE / "hardware" / "emulator.py").exists()
    assert "hardware" in set().union(*(_package_imports(p)
                                       for p in (PACKAGE / "emulator").glob("*.py")))


def test_the_import_reader_sees_relative_and_absolute_imports():
    # The walker above is only as good as this reader: check it on known text.
    assert {"kernels", "robot"} <= _package_imports(PACKAGE / "hardware" / "reels.py")
    assert _imports_drake(PACKAGE / "hardware" / "reels.py")
    assert not _imports_drake(PACKAGE / "kernels" / "kinematics.py")
    assert _unit(PACKAGE / "systems" / "plants" / "dynamic_plant.py") == "systems"
    assert _unit(PACKAGE / "diagram.py") == "diagram"


def test_the_emulators_two_command_lines_import_neither_each_other():
    """emulator/main.py (the UDP bridge) and emulator/canopen_drives.py (CiA 402 drives)
    share what they build alike through emulator/plant_setup.py; the console entry point
    that chooses between them is emulator/entry.py."""
    import ast

    def imported(path):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
            elif isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
        return names

    emulator = PACKAGE / "emulator"
    assert "cdpm_drake.emulator.canopen_drives" not in imported(emulator / "main.py")
    assert "cdpm_drake.emulator.main" not in imported(emulator / "canopen_drives.py")
    assert {"cdpm_drake.emulator.main", "cdpm_drake.emulator.canopen_drives"} <= imported(
        emulator / "entry.py")
