"""Robots built for tests: geometry whose closest points and crossings are known by hand, and
older attachment points of the shipped robots."""

from pathlib import Path

import numpy as np

from cdpm_drake.robot import Robot, Workspace

# paper_7cable's attachment points before they were calibrated for holding (a test copy):
# the level platform is held on 28 % of the box.
PRE_18 = [[-0.0664, 0.0862, 0.1365], [0.15, 0.15, 0.15], [-0.0942, 0.1334, -0.15],
          [0.15, 0.15, -0.15], [-0.1473, -0.1367, -0.15], [0.15, -0.15, -0.15],
          [-0.0025, -0.15, 0.15]]


def crossing_robot():
    """Cables 1 and 2 cross at p = 0 as the platform moves along x.

    Cable 1 runs from B1 = p to A1 = (0, 2, 0); cable 2 from B2 = p + (1, 1, 1) to
    A2 = (-3, 1, -3). At p = (x, 0, 0) cable 1 crosses the plane z = 0, y = 1 at x/2 (s = 1/2)
    and cable 2 crosses it at 3x/4 (t = 1/4), so they meet only at x = 0, at interior points.
    Cable 3 keeps the robot valid and stays far away.
    """
    return Robot(name="crossing", reels=np.array([[0, 2, 0], [-3, 1, -3], [0, -3, 0.0]]),
                 attachments=np.array([[0, 0, 0], [1, 1, 1], [0, -0.3, 0.0]]),
                 workspace=Workspace(np.array([-1.0, -1, -1]), np.array([1.0, 1, 1])))


def with_sections(text: str, extra: str) -> str:
    """A robot file's `text` with the top-level YAML sections of `extra` in place of its own
    sections of the same names (as YAML's last-of-two-keys read them; a robot file refuses a
    key written twice). A section is its key's line and the indented or comment lines under
    it."""
    keys = {line.split(":")[0] for line in extra.splitlines() if line[:1] not in (" ", "#", "")}
    out, skipping = [], False
    for line in text.splitlines():
        if line[:1] not in (" ", "#", ""):
            skipping = line.split(":")[0] in keys
        if not skipping:
            out.append(line)
    return "\n".join(out) + "\n" + extra + "\n"


def across_pair(scenario: str, pair: tuple[int, int]) -> np.ndarray:
    """The unit vector across a scenario's cable pair (1-based) at its start: minus the
    gradient of the pair's distance, by central differences (the adversarial benchmark's push
    direction)."""
    from cdpm_drake.config import load_resolved_scenario
    from cdpm_drake.kernels.interference import pair_distances

    resolved = load_resolved_scenario(scenario)
    robot = resolved.robot
    p0 = np.asarray(resolved.scenario.initial_position, dtype=float)
    k = robot.pair_position(*pair)
    g = np.array([(pair_distances(robot, p0 + 1e-6 * e)[k]
                   - pair_distances(robot, p0 - 1e-6 * e)[k]) / 2e-6 for e in np.eye(3)])
    return -g / np.linalg.norm(g)


def holdable_slack(resolved, log) -> int:
    """The slack ticks of a dynamic-plant log where the statics at the true pose hold the
    measured hand with every tension in [2, 100] N (the kinetostatic margin of that floor
    and the scenario's ceiling >= 0): the slack the promise forbids."""
    from cdpm_drake.robot.statics import posed_holding_tension

    slack = np.flatnonzero(log["slack"].any(axis=1))
    if not slack.size:
        return 0
    margin = posed_holding_tension(resolved.robot, log["p_true"][slack],
                                   log["rpy_true"][slack], log["F_H"][slack], floor=2.0,
                                   ceiling=resolved.scenario.controller.max_tension)
    return int(np.sum(margin >= 0.0))


BENCH_ROBOTS = Path(__file__).resolve().parents[1] / "scripts" / "bench" / "robots"


def bench_or_builtin_robot(name: str):
    """A robot of scripts/bench/robots (frame_8cable, crane_4cable, ...) or a built-in one."""
    from cdpm_drake.robot import load_robot, resolve_robot_path

    path = BENCH_ROBOTS / f"{name}.yaml"
    return load_robot(str(path) if path.exists() else resolve_robot_path(name))
