"""Scenario.method: the hard promise (the default) or the paper's method, one word apart."""

import numpy as np
import pytest

from cdpm_drake import cli
from cdpm_drake.config import ScenarioError, load_resolved_scenario, load_scenario
from cdpm_drake.runs.simulate import simulate


def test_the_paper_method_is_fig_5_without_the_filter_and_the_default_is_the_promise():
    # The reference for "the paper's method" is the scenario with the filter switched off by
    # hand (tests/runs/test_reference_logs.py's FIG_5): the same log, tick for tick.
    paper = simulate(scenario=load_scenario("exp2_interaction", "{duration: 1.0, method: paper}"))
    by_hand = simulate(scenario=load_scenario(
        "exp2_interaction", "{duration: 1.0, safety_filter: {enabled: false}}"))
    assert "filter_status" not in paper.log
    for key in ("p", "velocity", "F_int", "lengths"):
        np.testing.assert_array_equal(paper.log[key], by_hand.log[key])
    assert load_resolved_scenario("exp2_interaction").scenario.safety_filter.enabled


def test_a_method_that_does_not_exist_names_the_field_and_the_choices():
    with pytest.raises(ScenarioError) as e:
        load_resolved_scenario("exp2_interaction", "method: papr")
    assert "method must be one of ['promise', 'paper']" in str(e.value)
    assert "'papr'" in str(e.value)


def test_the_command_line_word_overrides_the_scenario(capsys, tmp_path):
    assert cli.main(["simulate", "exp2_interaction", "--duration", "0.01", "--no-progress",
                     "--scenario-text", "method: promise", "--method", "paper",
                     "--out", str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("scenario 'exp2_interaction' (the paper's method: no safety filter")
    with np.load(tmp_path / "run" / "log.npz") as log:
        assert "filter_status" not in log.files
