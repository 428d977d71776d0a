"""Every mutant of scripts/mutation/mutation_check.py, a module per layer of the package (the
folder of the file each one changes)."""

from mutants.kernels import MUTANTS as _kernels
from mutants.robot_config import MUTANTS as _robot_config
from mutants.builder import MUTANTS as _builder
from mutants.systems import MUTANTS as _systems
from mutants.runs import MUTANTS as _runs
from mutants.hardware import MUTANTS as _hardware
from mutants.cli import MUTANTS as _cli
from mutants.views import MUTANTS as _views

MUTANTS = [*_kernels, *_robot_config, *_builder, *_systems, *_runs, *_hardware, *_cli, *_views]
