"""A robot whose cables cannot resist every wrench of the rigid platform (wrench matrix rank <
6) is refused on the free-rotating dynamic plant (issue 31 item 4), naming every direction it
cannot resist (issue 32 bug 7); locked or kinematic it still runs. The directions named are
checked against the null space of W^T computed here: the wrench matrix built from the geometry
in this file, numpy's SVD."""

import logging
import re

import numpy as np
import pytest

from cdpm_drake.cli import main
from cdpm_drake.config import UnholdableRobot, load_scenario
from conftest import to_yaml

AXIS = {"x": 0, "y": 1, "z": 2}
OVERLAY = ("{{robot: {robot}, swaps: [], initial_position: null, interference: {{enabled: "
           "false}}, plant: !DynamicReels {{{plant}}}}}")


def readme_robot(tmp_path):
    """docs/robots.md's four-cable robot ("A robot that can only translate"), verbatim, as a file."""
    from helpers_docs import guide_text

    blocks = re.findall(r"```yaml\n(.*?)```", guide_text(), re.DOTALL)
    path = tmp_path / "my_robot.yaml"
    path.write_text(next(b for b in blocks if b.startswith("name: my_4cable")))
    return path


def line_robot(tmp_path, axis=(1.0, 0.0, 0.0), name="line_8cable"):
    """cube_8cable's reels with every attachment point on one line through the platform
    centre along `axis`: the cables' moments about that line are all zero, rank 5."""
    reels = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [4.0, 3.0, 0.0], [0.0, 3.0, 0.0],
             [0.0, 0.0, 3.0], [4.0, 0.0, 3.0], [4.0, 3.0, 3.0], [0.0, 3.0, 3.0]]
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    offsets = [-0.15, 0.15, 0.12, -0.12, -0.09, 0.09, 0.06, -0.06]
    spec = {"name": name, "reels": reels,
            "attachments": [[round(float(s * c), 6) for c in a] for s in offsets],
            "workspace": {"lower": [0.5, 0.5, 0.5], "upper": [3.5, 2.5, 2.5]}}
    path = tmp_path / f"{name}.yaml"
    path.write_text(to_yaml(spec) + "\n")
    return path, spec


def wrench_matrix_here(reels, attachments, p, rpy=(0.0, 0.0, 0.0)):
    """W (6, m) from the geometry: column i [u_i; (R b_i) x u_i], u_i the unit vector from
    the attachment point to the reel exit, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, pi, y = rpy
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(pi), 0, np.sin(pi)], [0, 1, 0], [-np.sin(pi), 0, np.cos(pi)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    b = np.asarray(attachments, dtype=float) @ (Rz @ Ry @ Rx).T
    cols = []
    for a_i, b_i in zip(np.asarray(reels, dtype=float), b):
        u = a_i - (np.asarray(p) + b_i)
        u /= np.linalg.norm(u)
        cols.append(np.concatenate([u, np.cross(b_i, u)]))
    return np.array(cols).T


def null_space_of_WT(W):
    """(rank, N (6, 6 - rank)): an orthonormal basis of the wrenches no tensions produce."""
    U, s, _ = np.linalg.svd(W)
    rank = int(np.sum(s > 1e-9 * s[0]))
    return rank, U[:, rank:]


def named_directions(message):
    """The wrench directions (6,) a refusal names, read back from its words."""
    text = re.search(r"no cable tensions resist (.*?) \(\d+ directions?;", message).group(1)
    out = []

    def vec(s):
        return np.array([float(x) for x in s.split(",")])

    patterns = [
        (r"(forces along|moments about) ((?:[xyz], )*[xyz] and [xyz])",
         lambda m: [np.eye(6)[AXIS[c] + (3 if m.group(1) == "moments about" else 0)]
                    for c in re.findall(r"[xyz]", m.group(2))]),
        (r"a force along \[([^\]]*)\] with a moment about \[([^\]]*)\] of (\S+) N m per N",
         lambda m: [np.concatenate([vec(m.group(1)), float(m.group(3)) * vec(m.group(2))])]),
        (r"a moment about the axis \[([^\]]*)\]",
         lambda m: [np.concatenate([np.zeros(3), vec(m.group(1))])]),
        (r"a force along \[([^\]]*)\]", lambda m: [np.concatenate([vec(m.group(1)),
                                                                   np.zeros(3)])]),
        (r"a (force along|moment about) ([xyz])\b",
         lambda m: [np.eye(6)[AXIS[m.group(2)] + (3 if m.group(1) == "moment about" else 0)]]),
    ]
    for pattern, read in patterns:
        for m in re.finditer(pattern, text):
            out.extend(read(m))
        text = re.sub(pattern, "", text)
    assert not re.search(r"force|moment", text), f"words left unread: {text!r}"
    return np.array(out)


def assert_names_the_missing_wrenches(message, W):
    """The named directions are as many as the null space of W^T has dimensions, and no
    combination of them is a wrench the cables produce: N^T E is square and well
    conditioned (each named direction has a part the cables cannot give, and together with
    W's range they span every wrench)."""
    rank, N = null_space_of_WT(W)
    E = named_directions(message)
    assert E.shape == (6 - rank, 6), (E, rank)
    E = E / np.linalg.norm(E, axis=1, keepdims=True)
    assert np.linalg.svd(N.T @ E.T, compute_uv=False).min() > 0.3, message
    return rank, N, E


def test_the_readme_robot_is_refused_on_the_free_plant_naming_all_three_moments(tmp_path,
                                                                              caplog):
    path = readme_robot(tmp_path)
    with caplog.at_level(logging.WARNING, logger="cdpm_drake.robot"):
        with pytest.raises(UnholdableRobot) as e:
            load_scenario("exp1_no_interaction", OVERLAY.format(robot=path, plant=""))
    message = str(e.value)
    reels = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [2.0, 3.0, 0.0], [2.0, 1.5, 3.0]]
    attachments = [[-0.1, -0.1, 0.0], [0.1, -0.1, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 0.1]]
    W = wrench_matrix_here(reels, attachments, [2.0, 1.5, 1.25])  # the box centre: the start
    rank, N, E = assert_names_the_missing_wrenches(message, W)
    assert rank == 3
    assert message.startswith("robot 'my_4cable' (4 cables) cannot hold a platform that turns "
                              "freely: its wrench matrix has rank 3 < 6 (4 cables: below 6 at "
                              "every pose) at the start, initial_position [2.0, 1.5, 1.25] m")
    # The three pure moments: the cables' lines meet (rank 3), so W's range is the forces
    # through one point and no pure moment is in it.
    assert "resist moments about x, y and z (3 directions;" in message
    np.testing.assert_allclose(np.abs(E[:, 3:]), np.eye(3))
    for way in ("plant.lock_rotation: true", "plant: !SimulatedReels {}", "at least 7 cables"):
        assert way in message
    # The load-time warning (issue 32 bug 7: named two of the three) names all three too.
    (warning,) = [r.getMessage() for r in caplog.records if "4 cables cannot hold" in
                  r.getMessage()]
    assert "no cable tensions resist moments about x, y and z there" in warning, warning


@pytest.mark.parametrize("axis,words", [
    ((1.0, 0.0, 0.0), "a moment about x"),
    ((1.0, 1.0, 0.0), "a moment about the axis [0.71, 0.71, 0.00]")])
def test_a_rank_5_robot_is_refused_naming_the_moment_about_its_attachment_line(tmp_path, axis,
                                                                               words):
    path, spec = line_robot(tmp_path, axis)
    with pytest.raises(UnholdableRobot) as e:
        load_scenario("exp1_no_interaction", OVERLAY.format(robot=path, plant=""))
    message = str(e.value)
    W = wrench_matrix_here(spec["reels"], spec["attachments"], [2.0, 1.5, 1.5])
    rank, N, E = assert_names_the_missing_wrenches(message, W)
    assert rank == 5 and "rank 5 < 6 at the start" in message and "(8 cables)" in message
    assert f"resist {words} (1 direction;" in message, message
    # The one missing wrench is the moment about the line (SVD here): the named one is it.
    a = np.asarray(axis) / np.linalg.norm(axis)
    np.testing.assert_allclose(np.abs(N[:, 0]), np.abs(np.concatenate([[0, 0, 0], a])),
                               atol=1e-9)
    assert abs(float(N[:, 0] @ E[0])) == pytest.approx(1.0, abs=0.01)


def test_the_start_orientation_is_the_pose_checked(tmp_path):
    # Turned by 90 deg about z, the x-line robot's attachment line lies along y: the missing
    # moment is about y (the SVD of W at that orientation says so too).
    path, spec = line_robot(tmp_path)
    with pytest.raises(UnholdableRobot) as e:
        load_scenario("exp1_no_interaction",
                      OVERLAY.format(robot=path, plant=f"initial_rpy: [0.0, 0.0, {np.pi / 2}]"))
    W = wrench_matrix_here(spec["reels"], spec["attachments"], [2.0, 1.5, 1.5],
                           (0.0, 0.0, np.pi / 2))
    assert_names_the_missing_wrenches(str(e.value), W)
    assert "resist a moment about y (1 direction;" in str(e.value)


def test_a_full_rank_robot_is_not_refused(tmp_path):
    # paper_7cable at exp2's start: rank 6 by the SVD here, and the free plant loads.
    from cdpm_drake.robot import load_robot

    robot = load_robot("paper_7cable")
    s = load_scenario("exp2_interaction", "plant: !DynamicReels {}")
    W = wrench_matrix_here(robot.reels, robot.attachments, s.initial_position)
    assert null_space_of_WT(W)[0] == 6
    assert s.plant.lock_rotation is False


@pytest.mark.parametrize("plant", ["plant: !DynamicReels {lock_rotation: true}",
                                   "plant: !SimulatedReels {}"])
def test_the_readme_robot_still_runs_locked_or_kinematic(tmp_path, plant):
    path = readme_robot(tmp_path)
    text = (f"{{robot: {path}, swaps: [], initial_position: null, duration: 0.2, {plant}, "
            "operator: !ScriptedOperator {times: [0, 0.2], forces: [[0, 0, 0], [2, 1, 0]]}}")
    out = tmp_path / "out"
    assert main(["simulate", "exp1_no_interaction", "--scenario-text", text, "--out", str(out),
                 "--no-progress"]) == 0
    log = np.load(out / "log.npz")
    assert log["time"].size == 101 and log["p"][-1, 0] > log["p"][0, 0]


def test_cdpm_info_says_the_run_would_be_refused_and_simulate_refuses_it(tmp_path, capsys):
    path = readme_robot(tmp_path)
    scenario = tmp_path / "free.yaml"
    scenario.write_text(f"name: free\nrobot: {path}\nduration: 0.2\nplant: !DynamicReels {{}}\n")
    assert main(["info", str(scenario), "--grid", "0.25"]) == 0
    out, err = capsys.readouterr()
    # The robot's rank warning once (issue 32: the path's simulation printed it again).
    assert (out + err).count("4 cables cannot hold the platform") == 1, out + err
    (line,) = [x for x in out.splitlines() if x.startswith("refused: ")]
    assert "`cdpm simulate` would refuse this scenario's run" in line
    assert "rank 3 < 6" in line and "moments about x, y and z" in line
    assert "plant.lock_rotation: true" in line
    assert "statics of the level platform" in out  # the report goes on
    run = tmp_path / "run"
    code = main(["simulate", str(scenario), "--out", str(run), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1, err  # cli.cdpm.EXIT_CODES: an invalid scenario
    assert "cannot hold a platform that turns freely" in err and "Traceback" not in err
    assert not (run / "log.npz").exists()


def test_a_direction_coupling_a_force_and_a_moment_is_named_whole(tmp_path):
    # hand_4cable (a garage robot written by hand): rank 4, and one of its two missing
    # directions mixes a force with a moment; the words give both and the ratio, and read
    # back they still span what W lacks.
    from conftest import HAND_ROBOT

    from cdpm_drake.robot import load_robot

    robot = load_robot(HAND_ROBOT)
    with pytest.raises(UnholdableRobot) as e:
        load_scenario("exp1_no_interaction", OVERLAY.format(robot=HAND_ROBOT, plant=""))
    message = str(e.value)
    W = wrench_matrix_here(robot.reels, robot.attachments, robot.workspace.center)
    rank, N, E = assert_names_the_missing_wrenches(message, W)
    assert rank == 4 and "(2 directions;" in message
    assert re.search(r"a force along \[[^\]]*\] with a moment about \[[^\]]*\] of \S+ N m per N",
                     message), message
