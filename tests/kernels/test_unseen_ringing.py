"""The unseen-ringing kernel against closed forms: a platform at rest at its statics whose
load steps (the reels' acceleration, the hand's force) rings about the new statics with the
energy of the step's static displacement, E = 1/2 f^T K^-1 f; undamped, the trapezoidal rule
keeps that energy exactly, so each cable's swing is k_i sqrt(w_i^T K^-1 w_i) sqrt(f^T K^-1 f)
(kernels/unseen_ringing.py), K = W diag(EA / L) W^T recomputed here from the robot's
geometry with numpy."""

import dataclasses

import numpy as np
import pytest

from cdpm_drake.config import load_resolved_scenario
from cdpm_drake.kernels.unseen_ringing import (ringing_params, ringing_scratch, ringing_sizes,
                                               ringing_tick)

STEP = 0.002


def _robot():
    return load_resolved_scenario("exp2_interaction").robot


def _stiffness(robot, p):
    """K (6, 6), W (6, m), k (m,) of the level platform at p, with numpy."""
    rho = robot.reels - (p + robot.attachments)
    L = np.linalg.norm(rho, axis=1)
    u = rho / L[:, None]
    W = np.vstack([u.T, np.cross(robot.attachments, u).T])
    k = robot.dynamics.EA / L
    return W @ np.diag(k) @ W.T, W, k


def _run(robot, dynamics, ticks, *, v_of, F_of, T=None, floor=4.0):
    """(swing, warned) of the last tick: the kernel on a level platform held at the
    workspace centre, the command twist v_of(tick) (6,), the hand F_of(tick) (3,)."""
    m = robot.num_cables
    s = ringing_sizes(m)
    params = ringing_params(dynamics, time_step=STEP, floor=floor, warmup=1)
    p = robot.workspace.center
    T = np.full(m, 50.0) if T is None else T
    memory = np.zeros(s["memory"])
    out = np.empty(s["out"])
    scratch = ringing_scratch(m)
    for tick in range(ticks):
        x = np.concatenate([p, np.eye(3).ravel(), v_of(tick), F_of(tick), T, memory])
        ringing_tick(np.ascontiguousarray(robot.reels), np.ascontiguousarray(robot.attachments),
                     params, scratch, x, out)
        memory = out[s["memory_at"]:].copy()
    m = robot.num_cables
    return out[:m].copy(), out[m:2 * m].copy()


def _undamped(robot, bandwidth=1e12):
    # An instant drive (the lag's gain 1 - exp(-h bandwidth) = 1): the command's acceleration
    # is the reels'.
    return dataclasses.replace(robot.dynamics, damping=0.0, bandwidth=bandwidth)


def test_acceleration_step_rings_with_the_energy_of_its_static_displacement():
    robot = _robot()
    a = np.array([0.4, -0.3, 2.0])  # m/s^2, from tick 1 on
    swing, _ = _run(robot, _undamped(robot), 60,
                       v_of=lambda n: np.r_[a * STEP * max(n - 1, 0), np.zeros(3)],
                       F_of=lambda n: np.zeros(3))
    K, W, k = _stiffness(robot, robot.workspace.center)
    f = np.r_[-robot.dynamics.mass * a, np.zeros(3)]
    Kinv = np.linalg.inv(K)
    expected = k * np.sqrt(np.einsum("ij,jk,ki->i", W.T, Kinv, W) * (f @ Kinv @ f))
    np.testing.assert_allclose(swing, expected, rtol=1e-9)
    # paper_7cable's cable 2 takes ~5.6 N per m/s^2 (docs/dynamic_plant.md): a 2 m/s^2 step
    # swings it by several newtons.
    assert swing[1] > 5.0


def test_hand_step_rings_with_its_wrench_at_the_handle():
    robot = _robot()
    F = np.array([3.0, -2.0, 40.0])  # N, from tick 1 on
    swing, _ = _run(robot, _undamped(robot), 40, v_of=lambda n: np.zeros(6),
                       F_of=lambda n: F if n >= 1 else np.zeros(3))
    K, W, k = _stiffness(robot, robot.workspace.center)
    h = robot.dynamics.handle
    f = np.r_[F, np.cross(h, F)]  # the hand's wrench about the centre, level platform
    Kinv = np.linalg.inv(K)
    expected = k * np.sqrt(np.einsum("ij,jk,ki->i", W.T, Kinv, W) * (f @ Kinv @ f))
    np.testing.assert_allclose(swing, expected, rtol=1e-9)
    # The moment counts: without it (a hand at the centre) the swing differs.
    f0 = np.r_[F, np.zeros(3)]
    assert not np.allclose(swing, k * np.sqrt(np.einsum("ij,jk,ki->i", W.T, Kinv, W)
                                              * (f0 @ Kinv @ f0)), rtol=1e-3)


def test_the_cables_damping_takes_the_swing_down_and_the_drives_lag_smooths_it():
    robot = _robot()
    a = np.array([0.0, 0.0, 2.0])
    v_of = lambda n: np.r_[a * STEP * max(n - 1, 0), np.zeros(3)]  # noqa: E731
    zero = lambda n: np.zeros(3)  # noqa: E731
    undamped, _ = _run(robot, _undamped(robot), 400, v_of=v_of, F_of=zero)
    damped, _ = _run(robot, dataclasses.replace(robot.dynamics, bandwidth=1e12), 400,
                        v_of=v_of, F_of=zero)
    # The robot's 20 N s/m a cable, ~5 % of critical: 0.8 s of ringing loses most of it.
    assert np.all(damped < 0.5 * undamped)
    lagged, _ = _run(robot, _undamped(robot, robot.dynamics.bandwidth), 400, v_of=v_of,
                        F_of=zero)
    # The drives' 10 ms lag passes the 4-14 Hz modes' excitation only in part.
    assert np.all(lagged < undamped) and np.all(lagged > 0.2 * undamped)


@pytest.mark.parametrize("estimate, warned", [(60.0, 0.0), (4.0, 1.0)])
def test_a_cable_is_warned_where_its_estimate_less_its_swing_is_below_the_floor(estimate,
                                                                                warned):
    robot = _robot()
    a = np.array([0.0, 0.0, 2.0])
    T = np.full(robot.num_cables, 60.0)
    T[1] = estimate
    swing, flags = _run(robot, _undamped(robot), 60,
                                  v_of=lambda n: np.r_[a * STEP * max(n - 1, 0), np.zeros(3)],
                                  F_of=lambda n: np.zeros(3), T=T)
    assert 4.0 - swing[1] < 4.0 < 60.0 - swing.max()  # the swing is what decides
    assert flags[1] == warned and flags.sum() == warned
