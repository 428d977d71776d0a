"""The shipped YAML: robots, scenarios and sweeps, each found by name from any folder."""

from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
ROBOTS_DIR = DATA_DIR / "robots"
SCENARIOS_DIR = DATA_DIR / "scenarios"
SWEEPS_DIR = DATA_DIR / "sweeps"
