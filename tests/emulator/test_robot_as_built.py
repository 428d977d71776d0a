"""The emulator plays the robot as built under a scenario's file (`--scenario S --robot
TRUE`): its plant is TRUE's, its encoders homed on the scenario's file at the start pose, as a
real robot's homing writes the file's lengths. References: closed-form cable lengths of both
robots, and the true robot's forward kinematics."""

import numpy as np
import pytest
import yaml

from cdpm_drake.config import load_scenario, scenario_robot
from cdpm_drake.emulator.main import build_parser, build_server
from cdpm_drake.kernels.kinematics import cable_lengths
from cdpm_drake.robot import load_robot


@pytest.fixture
def true_file(tmp_path):
    """paper_7cable with its reel exits moved by 1-2 cm (a file measured with a tape)."""
    robot = load_robot("paper_7cable")
    raw = yaml.safe_load(open(robot.source).read())
    rng = np.random.default_rng(5)
    raw["reels"] = (robot.reels + rng.normal(0, 0.015, robot.reels.shape)).tolist()
    raw["name"] = "paper_7cable_as_built"
    path = tmp_path / "as_built.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def _server(*args):
    return build_server(build_parser().parse_args(list(args)))


@pytest.mark.parametrize("plant", ["kinematic", "dynamic"])
def test_the_robot_as_built_is_homed_on_the_file(true_file, plant):
    server = _server("--scenario", "exp2_interaction", "--robot", str(true_file), "--plant",
                     plant, "--port", "0")
    try:
        bridge = server.bridge
        scenario = load_scenario("exp2_interaction")
        file_robot = scenario_robot(scenario)
        true = scenario_robot(scenario, str(true_file))
        start = np.asarray(scenario.initial_position)
        # The plant is the robot as built (the scenario's swaps applied to it too) ...
        np.testing.assert_array_equal(bridge.robot.reels, true.reels)
        np.testing.assert_array_equal(bridge.robot.attachments, file_robot.attachments)
        # ... its encoders read the FILE's rigid lengths of the start pose (the homing) ...
        np.testing.assert_allclose(bridge.encoder_lengths(), cable_lengths(file_robot, start),
                                   atol=1e-9)
        # ... which differ from the true robot's by the file's error there.
        assert np.abs(cable_lengths(true, start) - cable_lengths(file_robot, start)).max() > 5e-3
        # The platform itself starts where the scenario says, on the true geometry.
        np.testing.assert_allclose(bridge.platform(), start, atol=1e-6)
    finally:
        server.stop()


def test_a_robot_of_another_cable_count_is_refused(true_file):
    with pytest.raises(ValueError, match=r"--robot 'cube_8cable' has 8 cables"):
        _server("--scenario", "exp2_interaction", "--robot", "cube_8cable", "--port", "0")


def test_the_robot_as_built_s_cables_settle_on_its_geometry(true_file):
    """Commands computed on the file pay out lengths the true robot cannot take: its taut
    cables settle where they agree best, so its encoders read its own geometry (less the
    homing's offset) at its true pose, not the commands' sum; that is what makes the
    encoders tell the file's error (the self-calibration's data)."""
    server = _server("--scenario", "exp2_interaction", "--robot", str(true_file), "--port",
                     "0")
    try:
        bridge = server.bridge
        file_robot = scenario_robot(load_scenario("exp2_interaction"))
        start = bridge.platform()
        J = np.array([(file_robot.reels[i] - start - file_robot.attachments[i])
                      / cable_lengths(file_robot, start)[i] for i in range(7)])
        bridge.set_command(-J @ np.array([0.2, -0.1, 0.05]), enable=True)
        for _ in range(1000):
            bridge.step(0.002)
        p = bridge.platform()
        assert np.linalg.norm(p - start) > 0.3  # it moved
        np.testing.assert_allclose(bridge.encoder_lengths() - bridge.encoder_offset,
                                   cable_lengths(bridge.robot, p), atol=1e-9)
        # The file's geometry no longer explains the readings (millimetres off): the file's
        # error shows.
        from cdpm_drake.kernels.kinematics import forward_kinematics
        q = forward_kinematics(file_robot, bridge.encoder_lengths(), p_guess=p,
                               max_residual=np.inf)
        misfit = np.abs(cable_lengths(file_robot, q) - bridge.encoder_lengths()).max()
        assert misfit > 1e-3, misfit
    finally:
        server.stop()
