"""safety.png and trajectory.png tell what the safety filter did (issue 32): the plotted data
read back from the figures' artists must equal what the log says, worked out here by hand
(closed forms, loops over ticks) rather than by the figure's own helpers."""

import numpy as np
import pytest
from helpers_synthetic_log import synthetic_log

from cdpm_drake.kernels.safety_filter import LOST_SPEED
from cdpm_drake.views.figures_motion import figure_trajectory
from cdpm_drake.views.figures_safety import figure_safety

TICK = 0.002


def _safety_log(duration=0.4):
    """A log with the filter's keys: it passes every tick unchanged, kappa 3 N, pair margin
    2 mm, t* 20 N, the speed limit 0.5 m/s."""
    log = synthetic_log(duration)
    T = len(log["time"])
    return dict(log, filter_status=np.zeros((T, 1)), filter_binding=np.zeros((T, 1)),
                velocity_limited=log["velocity"].copy(), kappa=np.full((T, 1), 3.0),
                t_star_hand=np.full((T, 1), 20.0), pair_margin=np.full((T, 1), 0.002),
                max_velocity=np.array(0.5))


def _by_gid(ax, gid):
    return [a for a in ax.get_children() if getattr(a, "get_gid", lambda: None)() == gid]


def _x_extent(artist):
    """(first, last) x (s) of a fill_between band or an axvspan rectangle."""
    if hasattr(artist, "get_paths"):
        x = np.concatenate([path.vertices[:, 0] for path in artist.get_paths()])
        return float(x.min()), float(x.max())
    return float(artist.get_x()), float(artist.get_x() + artist.get_width())


def test_the_change_the_filter_made_is_drawn_where_the_speeds_coincide():
    # The filter turns the asked velocity by 30 degrees without slowing it: the two speeds
    # are equal (the asked line was hidden under the commanded one); |asked - commanded| of
    # two vectors of length v at angle theta is 2 v sin(theta / 2) (the chord).
    log = _safety_log()
    T = len(log["time"])
    v = 0.1
    theta = np.radians(30.0)
    log["velocity_limited"] = np.tile([v, 0.0, 0.0], (T, 1))
    log["velocity"] = np.tile([v * np.cos(theta), v * np.sin(theta), 0.0], (T, 1))
    fig = figure_safety(log)
    speeds, change = fig.axes[1], fig.axes[2]
    lines = {line.get_label(): line for line in speeds.get_lines()}
    np.testing.assert_allclose(lines["asked (admittance, limits)"].get_ydata(),
                               lines["commanded (safety filter)"].get_ydata())
    diff, = _by_gid(change, "asked - commanded")
    np.testing.assert_allclose(diff.get_ydata(), np.full(T, 2 * v * np.sin(theta / 2)),
                               rtol=1e-12)


def test_the_speed_limit_and_the_lost_margin_cap_are_two_rows_and_two_lines():
    # The speed bit (8) binds on ticks 20-39 at 0.5 m/s = max_velocity (the speed limit) and
    # on ticks 100-149 at 0.07 m/s (the cap that slows the platform while a margin is lost):
    # the summary tells them apart (cli/summaries.py); the figure must too.
    log = _safety_log()
    t = log["time"]
    T = len(t)
    direction = np.array([0.6, 0.8, 0.0])
    speed = np.full(T, 0.2)
    speed[20:40], speed[100:150] = 0.5, 0.07
    log["velocity"] = speed[:, None] * direction
    log["velocity_limited"] = log["velocity"].copy()
    log["filter_binding"] = np.zeros((T, 1))
    log["filter_binding"][20:40] = 8
    log["filter_binding"][100:150] = 8
    log["filter_status"][20:40] = log["filter_status"][100:150] = 1
    fig = figure_safety(log)
    bands, speeds = fig.axes[0], fig.axes[1]
    names = [label.get_text() for label in bands.get_yticklabels()]
    assert "speed limit (0.5 m/s)" in names
    assert f"lost-margin speed cap (to {LOST_SPEED:g} m/s)" in names
    limit, = _by_gid(bands, "bound: speed limit (0.5 m/s)")
    assert _x_extent(limit) == pytest.approx((t[20], t[39]))
    cap, = _by_gid(bands, f"bound: lost-margin speed cap (to {LOST_SPEED:g} m/s)")
    assert _x_extent(cap) == pytest.approx((t[100], t[149]))
    line, = _by_gid(speeds, "max_velocity")
    assert list(line.get_ydata()) == [0.5, 0.5]
    held, = _by_gid(speeds, "lost-margin cap")
    y = np.asarray(held.get_ydata())
    np.testing.assert_allclose(y[100:150], 0.07)
    assert np.isnan(np.delete(y, np.arange(100, 150))).all()
    assert "0.20-0.30 s (50 ticks)" in held.get_label()


def test_a_speed_limit_far_above_the_speeds_is_named_not_drawn():
    log = _safety_log()  # speeds ~0.2 m/s at most, the limit 0.5 m/s
    log["max_velocity"] = np.array(5.0)
    speeds = figure_safety(log).axes[1]
    note, = _by_gid(speeds, "max_velocity")
    assert note.get_text() == "speed limit max_velocity = 5 m/s: far above these speeds"
    assert max(np.nanmax(line.get_ydata()) for line in speeds.get_lines()) < 1.0


def test_an_infinite_t_star_and_lost_margins_are_shaded_with_their_spans():
    log = _safety_log()
    t = log["time"]
    log["t_star_hand"][:50] = np.inf  # ticks 0-49: an internal force raises every tension
    log["kappa"][60:70] = -0.1  # kinetostatic margin lost on ticks 60-69
    log["kappa"][80] = -1e-9  # round-off at the barrier: not lost
    log["pair_margin"][150:175] = -0.0003  # pair margin lost on ticks 150-174
    fig = figure_safety(log)
    ax_k, ax_p = fig.axes[3], fig.axes[4]
    half = TICK / 2
    inf, = _by_gid(ax_k, "t_star_hand +inf")
    assert _x_extent(inf) == pytest.approx((t[0] - half, t[49] + half))
    assert inf.get_label() == ("t* = +inf (an internal force raises every tension): "
                               "0.00-0.10 s (50 ticks)")
    lost, = _by_gid(ax_k, "kappa lost")
    assert _x_extent(lost) == pytest.approx((t[60] - half, t[69] + half))
    assert lost.get_label() == "kappa < 0, margin lost: 0.12-0.14 s (10 ticks)"
    pair, = _by_gid(ax_p, "pair_margin lost")
    assert _x_extent(pair) == pytest.approx((t[150] - half, t[174] + half))
    assert pair.get_label() == "pair margin lost (estimate): 0.30-0.35 s (25 ticks)"
    # t* is drawn where finite and not where +inf.
    t_star, = _by_gid(ax_k, "t_star_hand")
    assert np.isnan(t_star.get_ydata()[:50]).all() and (t_star.get_ydata()[50:] == 20).all()


def test_a_dynamic_run_draws_the_true_pair_margin_beside_the_estimate():
    # The true margin: per tick, the smallest over pairs of the true distance (negative for a
    # pair that truly crossed) less its d_min, worked out in a loop.
    log = _safety_log()
    T = len(log["time"])
    rng = np.random.default_rng(3)
    true = log["pair_distances"] + rng.uniform(-0.004, 0.004, log["pair_distances"].shape)
    crossed = np.zeros(true.shape, dtype=bool)
    crossed[200:, 0] = True
    log.update(pair_distances_true=true, crossed_true=crossed, d_min=log["d_l"].copy())
    expected = np.empty(T)
    for k in range(T):
        expected[k] = min((-true[k, q] if crossed[k, q] else true[k, q]) - log["d_min"][q]
                          for q in range(true.shape[1]))
    ax_p = figure_safety(log).axes[4]
    line, = _by_gid(ax_p, "pair_margin_true")
    np.testing.assert_allclose(line.get_ydata(), 1000 * expected, rtol=1e-12)
    assert line.get_label() == "closest pair above its d_min (true, dynamic plant)"
    estimate, = _by_gid(ax_p, "pair_margin")
    np.testing.assert_allclose(estimate.get_ydata(), 2.0)  # mm: the estimate's 0.002 m


def test_a_dynamic_run_draws_the_true_path_beside_the_estimate():
    log = synthetic_log(0.2)
    T = len(log["time"])
    offset = np.array([0.003, -0.004, 0.0])  # 5 mm from the estimate
    log["p_true"] = log["p"] + offset
    fig = figure_trajectory(log)
    zoom = fig.axes[0]
    true_path, = _by_gid(zoom, "true path")
    np.testing.assert_allclose(np.array(true_path.get_data_3d()).T, log["p_true"])
    path, = _by_gid(zoom, "path")
    assert path.get_label() == "platform path p (controller's estimate)"
    assert "at most 5.00 mm from the truth" in zoom.get_title()
    assert T == len(np.array(true_path.get_data_3d()).T)
    # Without the truth, neither the line nor its legend entry.
    del log["p_true"]
    assert not _by_gid(figure_trajectory(log).axes[0], "true path")
