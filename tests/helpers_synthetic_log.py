"""A synthetic log.npz dictionary (docs/LOG_FORMAT.md) for the view tests.

The views only draw what a log says, so the log need not come from a simulation: every column
is prescribed in closed form here, which keeps the view tests fast and lets them compare the
plotted data with known numbers. The robot is the paper's seven-cable CDPM with the attachments
of cables 1 and 3 swapped, as in the paper's experiments.
"""

import numpy as np

from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot

TICK = 0.002  # s, the controller period of the paper (500 Hz)

# Logistic parameters of the paper's experiment 1 (section 5, Fig. 8): d_l = 50 mm,
# d_u = 61 mm, F_u = 2 N, eps = 0.1 N; experiment 3 uses 57 / 62 mm, 2 N for pair (5, 7).
EXP1 = (0.050, 0.061, 2.0, 0.1)
EXP3 = (0.057, 0.062, 2.0, 0.1)


def logistic(d, d_l, d_u, F_u, eps):
    """Eqs. 26-28 written out again here so the helper does not lean on the code under test."""
    b = 2.0 * np.log((F_u - eps) / eps) / (d_l - d_u)
    return F_u / (1.0 + np.exp(-b * (np.asarray(d) - 0.5 * (d_u + d_l))))


def synthetic_log(duration: float = 1.0, d13=(0.045, 0.070), d57=(0.066, 0.058),
                  crossed_ticks: int = 5, interference: bool = True,
                  fault_time: float | None = None, realtime: bool = False) -> dict:
    """A log of `duration` s: the platform moves on a straight line, the distance of pair (1,3)
    goes linearly from d13[0] to d13[1] (m), pair (5,7) from d57[0] to d57[1]; every other pair
    stays at >= 0.2 m. Pair (1,3) is flagged crossed for the first `crossed_ticks` ticks.
    interference=False writes NaN logistic parameters, as `cdpm simulate` does when the
    interference block is disabled. fault_time (s) ends the run on a fault at that tick
    (keys ending, fault_time, fault_message); realtime=True adds the columns of `cdpm run`:
    tick, wall (a 2 ms clock with one 5 ms late tick at 0.2 s), compute (0.3 ms, 1.5 ms at
    0.2 s) and watchdog_limit (3 ticks, 6 ms)."""
    robot = load_robot("paper_7cable").with_swapped_attachments(1, 3)
    T = int(round(duration / TICK)) + 1
    time = np.arange(T) * TICK
    s = time / time[-1]
    p0, p1 = np.array([1.77, 3.65, 1.22]), np.array([1.90, 3.55, 1.05])
    p = p0 + s[:, None] * (p1 - p0)

    pairs = np.array(robot.pairs, dtype=int)
    P = len(pairs)
    k13 = robot.pair_position(1, 3)
    k57 = robot.pair_position(5, 7)
    d = 0.2 + 0.01 * np.arange(P)[None, :] + 0.0 * s[:, None]
    d[:, k13] = d13[0] + s * (d13[1] - d13[0])
    d[:, k57] = d57[0] + s * (d57[1] - d57[0])
    params = np.tile(np.array(EXP1), (P, 1))
    params[k57] = EXP3
    d_l, d_u, F_u, eps = params.T.copy()
    active = d <= d_u
    crossed = np.zeros((T, P), dtype=bool)
    crossed[:crossed_ticks, k13] = True

    # Interference force: each active pair pushes along a fixed unit direction of its own.
    directions = np.zeros((P, 3))
    directions[k13] = [-0.6, 0.0, 0.8]
    directions[k57] = [0.0, 0.6, 0.8]
    alpha = np.where(active, logistic(d, d_l, d_u, F_u, eps), 0.0)
    F_int = alpha @ directions
    F_H = np.stack([8.0 * np.sin(2 * np.pi * time), 6.0 * np.cos(2 * np.pi * time),
                    -3.0 + 0.0 * time], axis=1)
    F_wall = np.zeros((T, 3))
    F_d = F_H + F_int + F_wall
    velocity = np.gradient(p, TICK, axis=0)
    lengths = cable_lengths(robot, p)
    log = {
        "time": time,
        "p": p,
        "F_H": F_H,
        "F_int": F_int,
        "F_wall": F_wall,
        "F_d": F_d,
        "velocity_admittance": velocity.copy(),
        "velocity": velocity,
        "reel_velocity": np.gradient(lengths, TICK, axis=0),
        "lengths": lengths,
        "pair_distances": d,
        "active": active,
        "crossed": crossed,
        "pairs": pairs,
        "d_l": d_l,
        "d_u": d_u,
        "F_u": F_u,
        "eps": eps,
        "F_max": np.array(2.0),
        "reels": robot.reels.copy(),
        "attachments": robot.attachments.copy(),
        "workspace_lower": robot.workspace.lower.copy(),
        "workspace_upper": robot.workspace.upper.copy(),
        "robot_name": np.array(robot.name),
        "scenario_name": np.array("synthetic"),
    }
    if fault_time is not None:
        log["ending"] = np.array("fault")
        log["fault_time"] = np.array(float(fault_time))
        log["fault_message"] = np.array("bridge silent for 3 ticks")
    if realtime:
        period = np.full(T, TICK)
        compute = np.full(T, 0.0003)
        late = int(round(0.2 / TICK))
        if late < T:
            period[late] = 0.005
            compute[late] = 0.0015
        log["tick"] = np.arange(T)
        log["wall"] = 1000.0 + np.cumsum(period) - period[0]
        log["compute"] = compute
        log["watchdog_limit"] = np.array(3 * TICK)
    if not interference:
        for key in ("d_l", "d_u", "F_u", "eps"):
            log[key] = np.full(P, np.nan)
        log["F_max"] = np.array(0.0)
        log["active"] = np.zeros((T, P), dtype=bool)
        log["crossed"] = np.zeros((T, P), dtype=bool)
        log["F_int"] = np.zeros((T, 3))
        log["F_d"] = F_H.copy()
    return log
