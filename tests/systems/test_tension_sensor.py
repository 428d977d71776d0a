"""The plants' measured tensions (`tension_measured`, issue 31): a sensor on the dynamic
plant (the reel drives' force through the controller's model of the drives, or a load cell),
NaN where a plant has none.

References: the plant's ground truth (`tensions`, logged by the plant itself); with a sensor
that has no noise, lag or model error, the drive's equation of motion makes the measured
tension the true one to round-off (an independent check of the sign conventions of the
drive force, kernels/plant/cable_net.py, and its inversion, kernels/drive_torque.py).
"""

import numpy as np
import pytest

from cdpm_drake.config import ScenarioError, load_scenario
from cdpm_drake.robot import ROBOTS_DIR
from cdpm_drake.runs.simulate import simulate

FULL = "controller: {pose: full, tension_control: true}"
# A 10 N push across pair 1-3 of exp2, ramped in over 0.1 s: the platform's modes ring.
PUSH = ("operator: !ScriptedOperator {times: [0, 0.1, 10], forces: [[0, 0, 0], "
        "[-7.07, 0, -7.07], [-7.07, 0, -7.07]]}")


def _run(plant: str, duration=1.0, extra="", name="exp2_interaction"):
    scenario = load_scenario(name, "{%s, plant: !DynamicReels {%s}, %s%s}" % (
        FULL, plant, PUSH, extra))
    result = simulate(scenario=scenario, duration=duration)
    assert result.error is None, result.error
    return result.log


def _lagged(log):
    """(measured, true) with the measurement of tick k+1 beside the truth of tick k: the
    sensor is sampled at the tick and held, as the encoders are."""
    return log["tension_measured"][1:], log["tensions"][:-1]


def test_drive_torque_is_a_sensor_not_a_copy_of_the_truth():
    log = _run("")  # the default sensor: drive_torque
    measured, true = _lagged(log)
    assert np.all(np.isfinite(measured))
    # It rings (the truth moves by several N) ...
    assert np.all(true.std(axis=0) > 0.3)
    # ... and the sensor follows it: correlation with the truth, cable by cable.
    for i in range(true.shape[1]):
        assert np.corrcoef(measured[:, i], true[:, i])[0, 1] > 0.8, i
    # Not a copy: noise, quantisation, lag and the model's friction and inertia errors.
    error = measured - true
    assert np.all(error.std(axis=0) > 0.1)
    # The noise (0.3 N), the filter, the model errors: within a few N of the truth.
    assert np.abs(error).max() < 5.0


def test_an_exact_drive_model_measures_the_true_tension_to_round_off(tmp_path):
    # Without Coulomb friction (whose force is set-valued while a reel sticks) and with the
    # plant's step equal to the tick (the tick's speed difference is the step's acceleration),
    # a sensor with no noise, quantum, filter or model error inverts the drive's equation of
    # motion exactly.
    robot = tmp_path / "robot.yaml"
    robot.write_text((ROBOTS_DIR / "paper_7cable.yaml").read_text().replace(
        "coulomb_friction: 0.125", "coulomb_friction: 0.0"))
    exact = ("time_step: 0.002, tension_sensor: drive_torque, drive_torque: {noise_std: 0, "
             "quantum: 0, filter_time_constant: 0, inertia_error: 0, friction_error: 0}")
    log = _run(exact, duration=0.6, extra=", robot: %s" % robot)
    measured, true = _lagged(log)
    assert true.std() > 0.3  # not trivially at rest
    np.testing.assert_allclose(measured, true, rtol=0, atol=1e-8)
    # With the model's friction 30 % off the truth, it is not exact any more.
    off = _run(exact.replace("friction_error: 0", "friction_error: 0.3"), duration=0.6,
               extra=", robot: %s" % robot)
    measured, true = _lagged(off)
    assert np.abs(measured - true).max() > 1e-4


def test_no_sensor_and_the_kinematic_plant_measure_nan():
    log = _run("tension_sensor: none", duration=0.1)
    assert log["tension_measured"].shape == log["tensions"].shape
    assert np.all(np.isnan(log["tension_measured"]))
    kinematic = simulate(scenario=load_scenario("exp2_interaction"), duration=0.1).log
    assert kinematic["tension_measured"].shape == (51, 7)
    assert np.all(np.isnan(kinematic["tension_measured"]))


def test_a_load_cell_bias_shows_as_a_constant_offset_per_cable():
    exact = "tension_sensor: load_cell, load_cell: {noise_std: 0, bias_std: 0.5, bandwidth: 1e9}"
    measured, true = _lagged(_run(exact, duration=0.4))
    offset = measured - true
    # A bias per cable, the same all run (the cell's response is instant here, no noise).
    np.testing.assert_allclose(offset, offset[0][None, :].repeat(len(offset), 0), atol=1e-9)
    assert np.all(np.abs(offset[0]) > 1e-3) and np.ptp(offset[0]) > 0.1
    # Another seed, other biases; no bias, the truth.
    other = _lagged(_run(exact, duration=0.1, extra=", random_seed: 5"))
    assert np.abs((other[0] - other[1])[0] - offset[0]).max() > 0.05
    none = _lagged(_run(exact.replace("bias_std: 0.5", "bias_std: 0"), duration=0.1))
    np.testing.assert_allclose(none[0], none[1], atol=1e-9)


def test_the_sensor_noise_repeats_with_the_seed():
    a = _run("", duration=0.2)["tension_measured"]
    b = _run("", duration=0.2)["tension_measured"]
    c = _run("", duration=0.2, extra=", random_seed: 3")["tension_measured"]
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.05


@pytest.mark.parametrize("plant, message", [
    ("tension_sensor: torque", "plant.tension_sensor must be one of"),
    ("drive_torque: {noise_std: -1}", "plant.drive_torque.noise_std"),
    ("drive_torque: {inertia_error: -1}", "plant.drive_torque.inertia_error"),
    ("load_cell: {bandwidth: 0}", "plant.load_cell.bandwidth"),
])
def test_bad_sensor_settings_are_refused_naming_field_and_value(plant, message):
    with pytest.raises(ScenarioError, match=message):
        load_scenario("exp2_interaction", "plant: !DynamicReels {%s}" % plant)
