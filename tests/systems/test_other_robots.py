"""Robots other than the paper's go through the whole product: a point-mass robot whose cables
all meet at one platform point (every pair skipped: nothing for the interference block to
watch) and the smallest robot a translating platform allows (3 cables)."""

import numpy as np
import pytest

from cdpm_drake.cli import main

ROBOTS = {
    "pointmass4": ("reels: [[0, 0, 3], [4, 0, 3], [4, 4, 3], [0, 4, 3]]\n"
                   "attachments: [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]\n"
                   "workspace: {lower: [1, 1, 0.5], upper: [3, 3, 2]}\n", 0),
    "tri3": ("reels: [[0, 0, 3], [4, 0, 3], [2, 4, 3]]\n"
             "attachments: [[-0.1, -0.05, 0], [0.1, -0.05, 0], [0, 0.1, 0]]\n"
             "workspace: {lower: [1.5, 1.2, 0.5], upper: [2.5, 2.2, 2]}\n", 3),
}


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_a_robot_described_by_someone_else_simulates_plots_and_replays(name, tmp_path, capsys):
    text, pairs = ROBOTS[name]
    (tmp_path / f"{name}.yaml").write_text(f"name: {name}\n{text}")
    # The scenario names its robot relative to itself; a 3 N push along +x for 1 s.
    (tmp_path / "scenario.yaml").write_text(
        f"name: push\nrobot: {name}.yaml\ninitial_position: [2.0, 1.7, 1.0]\nduration: 1.0\n"
        "operator: !ScriptedOperator {times: [0], forces: [[3.0, 0.0, 0.0]]}\n"
        "sensor: {filter_window: 1}\nplant: !SimulatedReels {}\n")
    out = tmp_path / "out"
    code = main(["simulate", str(tmp_path / "scenario.yaml"), "--out", str(out),
                 "--no-progress", "--plot", "--html", str(out / "replay.html")])
    assert code == 0, capsys.readouterr()
    log = np.load(out / "log.npz")
    m = len(log["reels"])
    assert log["lengths"].shape == (501, m) and log["pair_distances"].shape == (501, pairs)
    assert log["pairs"].shape == (pairs, 2)
    # The push moved the platform along +x only (3 N / 6.25 N s/m -> up to 0.48 m/s).
    dp = log["p"][-1] - log["p"][0]
    assert dp[0] > 0.1 and abs(dp[1]) < 1e-3 and abs(dp[2]) < 1e-3
    # The lengths are the robot's inverse kinematics of the logged positions.
    robot_reels, robot_attach = log["reels"], log["attachments"]
    rho = log["p"][:, None, :] + robot_attach - robot_reels
    np.testing.assert_allclose(log["lengths"], np.linalg.norm(rho, axis=-1), atol=1e-9)
    for png in ("distances", "forces", "trajectory", "logistic"):
        assert (out / f"{png}.png").stat().st_size > 5000
    assert (out / "replay.html").stat().st_size > 100_000


def test_the_readme_examples_load_and_simulate(tmp_path):
    # docs/robots.md's "Describe your own robot" and docs/scenarios.md's "Write a scenario" blocks,
    # verbatim: a new user copies them first.
    import re

    from helpers_docs import guide_text

    readme = guide_text()
    blocks = re.findall(r"```yaml\n(.*?)```", readme, re.DOTALL)
    robot = next(b for b in blocks if b.startswith("name: my_robot"))
    scenario = next(b for b in blocks if b.startswith("name: my_push"))
    (tmp_path / "my_robot.yaml").write_text(robot)
    (tmp_path / "my_push.yaml").write_text(scenario)
    assert main(["info", str(tmp_path / "my_robot.yaml")]) == 0
    assert main(["simulate", str(tmp_path / "my_push.yaml"), "--duration", "1",
                 "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    log = np.load(tmp_path / "out" / "log.npz")
    assert log["p"][-1, 0] > log["p"][0, 0]  # the hand pulled towards +x
