"""A platform whose centre of mass is off its centre (plant.model_error.com_std): the dynamic
plant's true platform carries it, gravity tilts the platform, and the cables' tensions take
up its moment. The reference is the platform's statics, computed here from the log alone: at
rest, the moment of the true tensions about the platform's centre balances the weight's at
the true centre of mass, sum_i (R b_i) x T_i u_i = -(R c) x (m g)."""

import numpy as np

from cdpm_drake.config import DynamicReels, Interference, Scenario, Sensor
from cdpm_drake.config.plants import ModelError
from cdpm_drake.kernels.plant.operators import ScriptedOperator
from cdpm_drake.kernels.rotation import rotations_from_rpy
from cdpm_drake.runs.simulate import simulate

G = np.array([0.0, 0.0, -9.81])  # MultibodyPlant's default gravity, m/s^2


def _held(error: ModelError, duration=4.0):
    """paper_7cable held still (no hand force, no interference) on the dynamic plant."""
    scenario = Scenario(name="com", duration=duration, initial_position=[1.77, 2.4, 1.3],
                        interference=Interference(enabled=False),
                        sensor=Sensor(filter_window=1),
                        operator=ScriptedOperator(times=[0.0], forces=[[0.0, 0.0, 0.0]]),
                        plant=DynamicReels(model_error=error))
    result = simulate(scenario=scenario)
    assert result.error is None, result.error
    return result.log


def _cable_moment(log, k=-1):
    """The true cables' moment about the platform's centre, world frame, N m, at tick k."""
    R = rotations_from_rpy(log["rpy_true"][k:][:1])[0]
    w = np.asarray(log.get("attachments_true", log["attachments"])) @ R.T
    d = np.asarray(log.get("reels_true", log["reels"])) - log["p_true"][k] - w
    u = d / np.linalg.norm(d, axis=1)[:, None]
    return np.sum(np.cross(w, log["tensions"][k][:, None] * u), axis=0), R


def test_an_offset_centre_of_mass_tilts_the_platform_and_its_moment_is_the_cables():
    # Seed 4's draw: ~2.4 cm and ~1.3 cm sideways, ~2.5 cm down (one sigma 2 cm per axis).
    log = _held(ModelError(com_std=0.02, seed=4))
    c = np.asarray(log["com_true"])
    assert np.hypot(c[0], c[1]) > 0.02
    tau, R = _cable_moment(log)
    m = float(log["mass_true"])
    weight = -np.cross(R @ c, m * G)
    # The weight's moment is ~0.65 N m, horizontal; the cables carry it to within 1 %. About
    # the vertical the platform still swings a little in yaw (a lightly damped mode: 0.023,
    # 0.009, 0.001 N m at 2, 4, 8 s), whose moment the weight has none of.
    assert np.linalg.norm(weight) > 0.5
    np.testing.assert_allclose(tau[:2], weight[:2], atol=0.01 * np.linalg.norm(weight))
    assert abs(tau[2]) < 0.03 * np.linalg.norm(weight) and weight[2] == 0.0
    # ... and the platform hangs tilted (the file's level platform would not).
    exact = _held(ModelError())
    assert np.abs(log["rpy_true"][-1]).max() > 10 * max(np.abs(exact["rpy_true"][-1]).max(),
                                                        1e-6)


def test_no_centre_of_mass_error_keeps_the_platform_level_and_logs_nothing():
    """com_std 0 (with another error on): the centre of mass is the platform's centre, the
    cables' moment at rest is 0, and the run's truth is bit-identical to the same error
    without the field (the draw takes the centre of mass last)."""
    log = _held(ModelError(EA_rel_std=0.2, seed=4), duration=1.0)
    np.testing.assert_array_equal(log["com_true"], np.zeros(3))
    tau, _ = _cable_moment(log)
    assert np.abs(tau).max() < 1e-3
    with_field = _held(ModelError(EA_rel_std=0.2, com_std=0.0, seed=4), duration=1.0)
    np.testing.assert_array_equal(with_field["p_true"], log["p_true"])
    np.testing.assert_array_equal(with_field["rpy_true"], log["rpy_true"])
