"""Imports point down (the brief: cli -> runners -> builder/scenario -> systems/, hardware/ ->
the math). Read from the source with `ast`, so a new upward import fails here by name."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "cdpm_drake"
# What a driver module (the reel link and HardwareReels) may import from the package: the
# math below it and its own siblings. The emulator, the scenario, the builder and the CLI are
# above it.
DRIVER_MAY_IMPORT = {"kinematics", "robot", "rotation", "tension", "interference", "limits",
                     "kernel_call", "text", "hardware", "systems"}
MATH = ("kinematics", "interference", "limits", "tension", "rotation", "robot", "sensor",
        "operators", "kernel_call", "cables", "pose", "pose_control")


def _package_imports(path: Path) -> set[str]:
    """The top-level cdpm_drake modules `path` imports (relative or absolute)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    depth_of_package = len(path.relative_to(PACKAGE).parts)  # 1 for cdpm_drake/x.py
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                up = node.level - (depth_of_package - 1)
                parts = (node.module or "").split(".") if node.module else []
                if up <= 0:  # relative inside a sub-package: resolve against it
                    sub = path.relative_to(PACKAGE).parts[:-1]
                    base = list(sub[:len(sub) - (node.level - 1)])
                    parts = base + parts
                if parts and parts[0]:
                    out.add(parts[0])
                elif node.module is None:
                    out.update(a.name.split(".")[0] for a in node.names)
            elif node.module and node.module.startswith("cdpm_drake."):
                out.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("cdpm_drake."):
                    out.add(a.name.split(".")[1])
    return out


def test_the_driver_package_imports_nothing_above_it():
    offenders = {}
    for path in sorted((PACKAGE / "hardware").glob("*.py")):
        bad = _package_imports(path) - DRIVER_MAY_IMPORT
        if bad:
            offenders[path.name] = sorted(bad)
    assert not offenders, f"hardware/ imports from above the driver: {offenders}"


def test_the_emulator_lives_outside_the_driver_package():
    assert not (PACKAGE / "hardware" / "emulator.py").exists()
    assert "hardware" in _package_imports(PACKAGE / "emulator.py")


def _imports_drake_at_load(path: Path) -> bool:
    """True when importing `path` imports pydrake (a module-level import; a function that
    loads a YAML file with Drake's typed loader imports it only when called)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in tree.body:
        names = ([node.module or ""] if isinstance(node, ast.ImportFrom)
                 else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
        if any(n.split(".")[0] == "pydrake" for n in names):
            return True
    return False


def test_the_math_imports_no_drake_and_nothing_above_it():
    above = {"cli", "simulation", "realtime", "diagram", "scenario", "emulator", "sweep",
             "views", "systems", "hardware", "run_folder"}
    for name in MATH:
        path = PACKAGE / f"{name}.py"
        assert not _imports_drake_at_load(path), f"{name}.py imports Drake"
        assert not (_package_imports(path) & above), (name, _package_imports(path) & above)


def test_the_import_reader_sees_relative_and_absolute_imports(tmp_path):
    # The walker above is only as good as this reader: check it on known text.
    sub = PACKAGE / "hardware" / "reels.py"
    assert "kinematics" in _package_imports(sub)
    assert _imports_drake_at_load(sub)
    assert not _imports_drake_at_load(PACKAGE / "robot.py")
    assert {"hardware", "kinematics"} <= _package_imports(PACKAGE / "emulator.py")
