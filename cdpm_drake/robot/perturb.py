"""A robot as built, not as its file says: seeded perturbations of a robot's geometry and
dynamics (plain numpy, no Drake). The plants play such a robot under a controller that keeps
the file's, to measure what model error costs and what a calibration wins back."""

import dataclasses
import math

import numpy as np

from cdpm_drake.robot.model import Robot, RobotError


def check_model_error(error, field: str = "plant.model_error") -> None:
    """ValueError naming the field and value of a bad model_error entry."""
    for name in ("reels_std", "attachments_std", "encoder_offset_std", "EA_rel_std",
                 "mass_rel_std", "com_std"):
        value = getattr(error, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value) or value < 0:
            raise ValueError(f"{field}.{name} must be a number >= 0, got {value!r}")
    # Beyond these the perturbed robot is another robot, not a file's error: a cable exit 1 m
    # off, or a stiffness or mass that may come out negative.
    for name, bound, unit in (("reels_std", 0.5, "m"), ("attachments_std", 0.1, "m"),
                              ("encoder_offset_std", 0.5, "m"), ("EA_rel_std", 0.3, ""),
                              ("mass_rel_std", 0.3, ""), ("com_std", 0.1, "m")):
        value = getattr(error, name)
        if value > bound:
            raise ValueError(f"{field}.{name} is {value!r}{' ' + unit if unit else ''}; at "
                             f"most {bound} {unit or '(a fraction)'} models a robot file's "
                             "error")
    seed = error.seed
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise ValueError(f"{field}.seed must be an integer >= 0 or null, got {seed!r}")


def has_model_error(error) -> bool:
    return any(getattr(error, name) > 0 for name in (
        "reels_std", "attachments_std", "encoder_offset_std", "EA_rel_std", "mass_rel_std",
        "com_std"))


def perturbed_robot(robot: Robot, error, seed: int) -> tuple[Robot, np.ndarray]:
    """(the perturbed robot, each encoder's zero error (m,) m). One draw from
    numpy's default_rng([seed, 40]) in a fixed order (reels, attachments, encoder zeros, EA,
    mass, centre of mass), so that a field left at 0 does not change the others' draw."""
    rng = np.random.default_rng([int(seed), 40])
    m = robot.num_cables
    d_reels = rng.standard_normal((m, 3)) * float(error.reels_std)
    d_attach = rng.standard_normal((m, 3)) * float(error.attachments_std)
    offsets = rng.standard_normal(m) * float(error.encoder_offset_std)
    ea = 1.0 + rng.standard_normal() * float(error.EA_rel_std)
    mass = 1.0 + rng.standard_normal() * float(error.mass_rel_std)
    # Drawn last: the draws before it are those of a robot perturbed before it existed.
    d_com = rng.standard_normal(3) * float(error.com_std)
    if ea <= 0.1 or mass <= 0.1:
        raise RobotError(f"plant.model_error: the draw of seed {seed} makes EA x {ea:.3f} or "
                         f"the mass x {mass:.3f}: take a smaller *_rel_std or another seed")
    dynamics = dataclasses.replace(robot.dynamics, EA=robot.dynamics.EA * ea,
                                   mass=robot.dynamics.mass * mass,
                                   com=robot.dynamics.com + d_com)
    true = dataclasses.replace(robot, reels=robot.reels + d_reels,
                               attachments=robot.attachments + d_attach, dynamics=dynamics,
                               name=f"{robot.name}_as_built")
    return true, offsets
