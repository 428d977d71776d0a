"""The safety filter's math (cdpm_drake.kernels.safety_filter) against independent references: the
pair barrier's distance against the segment distance (itself checked against FCL and Drake),
its gradient against central finite differences, the filter's command against closed forms
(a face of the box, the speed and acceleration limits) and against Clarabel solving the same
weighted projection."""

import math

import numpy as np
import pytest

from cdpm_drake.kernels.interference import segment_distance
from cdpm_drake.kernels.safety_limits import face_cap
from cdpm_drake.kernels.pose import rotation_exp
from cdpm_drake.kernels.safety_filter import (BIND_ACCELERATION, BIND_BOX, BIND_KINETOSTATIC,
                                      BIND_PAIR, BIND_SPEED, CURVE_SHARE, LOST_DEPTH,
                                      LOST_SPEED, OUT_MEMORY, OUT_V_D, RAMP_SHARE,
                                      STATUS_HOLD, STATUS_MODIFIED, STATUS_NO_RETURN,
                                      STATUS_PASS, barrier_position, filter_params,
                                      filter_scratch, filter_sizes, filter_tick,
                                      pair_barrier)

T = 0.002
V_MAX, A_MAX = 0.5, 2.0
A_BRAKE = A_MAX / math.sqrt(3.0)
GAMMA = 0.2


def _robot():
    from cdpm_drake.robot import load_robot, resolve_robot_path

    return load_robot(resolve_robot_path("paper_7cable"))


def _rotation(phi):
    R = np.empty((3, 3))
    rotation_exp(*phi, R)
    return R


def test_pair_barrier_distance_and_gradient_match_independent_references():
    robot = _robot()
    rng = np.random.default_rng(7)
    i_all, j_all = robot.pair_index
    for _ in range(120):
        q = int(rng.integers(len(i_all)))
        i, j = int(i_all[q]), int(j_all[q])
        p = rng.uniform(robot.workspace.lower, robot.workspace.upper)
        R = _rotation(rng.normal(size=3) * 0.2)
        grad = np.empty(6)
        d = pair_barrier(robot.reels, robot.attachments, i, j, p, R, grad)
        B = p + robot.attachments @ R.T
        ref = segment_distance(B[i], robot.reels[i], B[j], robot.reels[j]).distance
        assert d == pytest.approx(ref, abs=1e-12)
        # Central differences in position and in rotation about the base axes (exp([h e]x) R).
        h = 1e-6
        fd = np.empty(6)
        g = np.empty(6)
        for k in range(6):
            e = np.zeros(3)
            e[k % 3] = h
            if k < 3:
                plus = pair_barrier(robot.reels, robot.attachments, i, j, p + e, R, g)
                minus = pair_barrier(robot.reels, robot.attachments, i, j, p - e, R, g)
            else:
                plus = pair_barrier(robot.reels, robot.attachments, i, j, p, _rotation(e) @ R, g)
                minus = pair_barrier(robot.reels, robot.attachments, i, j, p, _rotation(-e) @ R,
                                     g)
            fd[k] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(grad, fd, atol=2e-6)


def _filter(robot, *, v_d, p, v_prev=(0.0, 0.0, 0.0), kappa=100.0, grad_kappa=(0, 0, 0),
            ray=math.inf, d_min=None, crossed=None, kinetostatic=True, full=False,
            w_d=(0.0, 0.0, 0.0), cable_brake=None, give_way=math.inf, a_prev=(0.0, 0.0, 0.0),
            valid=False):
    """One filter tick on paper_7cable (level); returns (v, status, binding, out). valid:
    the memory holds a last command (not the first tick)."""
    i, j = robot.pair_index
    pi, pj = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    P = pi.size
    dmin = np.full(P, 0.05) if d_min is None else np.asarray(d_min, dtype=float)
    bounds = np.array([robot.workspace.lower, robot.workspace.upper])
    params = filter_params(time_step=T, gamma=GAMMA, a_brake=A_BRAKE, max_velocity=V_MAX,
                           max_acceleration=A_MAX, return_speed=0.02,
                           full_pose=full, kinetostatic=kinetostatic, cable_brake=cable_brake,
                           give_way=give_way)
    s = filter_sizes(P, full)
    x = np.zeros(s["x"])
    x[0:3], x[3:6] = v_d, p
    x[6:6 + P] = 0.0 if crossed is None else crossed
    x[6 + P] = kappa
    x[7 + P:10 + P] = grad_kappa
    x[10 + P] = ray
    if full:
        x[11 + P:14 + P] = w_d
        x[14 + P:23 + P] = np.eye(3).ravel()
    # The memory: [p_c (3), valid (1), v_prev (3), w_prev (3), a_prev (3)].
    x[s["memory_at"] + 4:s["memory_at"] + 7] = v_prev
    if valid:
        x[s["memory_at"]:s["memory_at"] + 3] = p
        x[s["memory_at"] + 3] = 1.0
    x[s["memory_at"] + 10:s["memory_at"] + 13] = a_prev
    out = np.empty(s["out"])
    status = filter_tick(robot.reels, robot.attachments, pi, pj, dmin, bounds, params,
                         filter_scratch(P, full), x, out)
    return out[:3].copy(), int(status), int(out[7]), out


def test_a_command_far_from_every_barrier_passes_unchanged():
    robot = _robot()
    v_d = np.array([0.1, -0.05, 0.02])
    v, status, binding, out = _filter(robot, v_d=v_d, p=robot.workspace.center, v_prev=v_d)
    assert status == STATUS_PASS and binding == 0
    np.testing.assert_array_equal(v, v_d)
    np.testing.assert_array_equal(out[OUT_V_D:OUT_V_D + 3], v_d)  # asked for, for the log
    np.testing.assert_array_equal(out[OUT_MEMORY + 4:OUT_MEMORY + 7], v)  # the next memory


@pytest.mark.parametrize("gap", [0.002, 0.01, 0.05, 0.2])
def test_a_face_of_the_box_caps_the_speed_towards_it_by_the_braking_curve(gap):
    # Moving at 0.3 m/s along +x with the upper x face `gap` m away: the barrier h = gap
    # (g = 1) allows rate(h) = min(gamma h / T, cap(h)) (the module's definition; cap is the
    # virtual wall's braking curve, limits.face_cap, at CURVE_SHARE of a_brake); the
    # previous command (at v_d) lets the ramp ask a decrease of RAMP_SHARE a_max T at most, but
    # never a step through the face (h / T): v_x = min(v_d, max(rate, v_d - ramp), h / T).
    robot = _robot()
    p = robot.workspace.center.copy()
    p[0] = robot.workspace.upper[0] - gap
    v_d = np.array([0.3, 0.0, 0.0])
    rate = min(GAMMA * gap / T, face_cap(gap, CURVE_SHARE * A_BRAKE, T))
    expected = min(0.3, max(rate, 0.3 - RAMP_SHARE * A_MAX * T), gap / T)
    v, status, binding, _ = _filter(robot, v_d=v_d, p=p, v_prev=v_d)
    assert v[0] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert v[1] == v[2] == 0.0
    if expected < 0.3:
        assert status == STATUS_MODIFIED and binding & BIND_BOX


def test_the_acceleration_and_speed_limits_hold_exactly():
    robot = _robot()
    rng = np.random.default_rng(1)
    for _ in range(200):
        v_prev = rng.normal(size=3) * 0.2
        v_prev *= min(1.0, V_MAX / np.linalg.norm(v_prev))  # a command it gave: within limits
        v_d = rng.normal(size=3) * 0.6
        v, status, _, _ = _filter(robot, v_d=v_d, p=robot.workspace.center, v_prev=v_prev)
        assert np.linalg.norm(v) <= V_MAX * (1 + 1e-8)
        assert np.linalg.norm(v - v_prev) <= A_MAX * T * (1 + 1e-8) + 1e-9
        if status == STATUS_PASS:  # the request met both: passed as it was
            np.testing.assert_array_equal(v, v_d)


@pytest.mark.parametrize("cable_brake", [None, 0.5])
def test_the_kinetostatic_barrier_and_its_look_ahead(cable_brake):
    # The rows' ramp: RAMP_SHARE a_max T a tick, or the cable brake's (a robot with mass).
    per_tick = RAMP_SHARE * A_MAX * T if cable_brake is None else cable_brake * T
    robot = _robot()
    p = robot.workspace.center
    # kappa = 0.5 N with the margin falling 100 N/m along +x: moving +x at 0.3 m/s the
    # barrier allows rate = min(gamma kappa / T, g cap(kappa / g)) N/s, i.e. v_x <= rate / g.
    kappa, g = 0.5, 100.0
    v_d = np.array([0.3, 0.0, 0.0])
    rate = min(GAMMA * kappa / T, g * face_cap(kappa / g, CURVE_SHARE * A_BRAKE, T))
    v, status, binding, _ = _filter(robot, v_d=v_d, p=p, v_prev=v_d, kappa=kappa,
                                    grad_kappa=(-g, 0.0, 0.0), cable_brake=cable_brake)
    assert v[0] == pytest.approx(max(rate / g, 0.3 - per_tick), rel=1e-12)
    assert binding & BIND_KINETOSTATIC
    # Off: the same inputs pass.
    v, status, _, _ = _filter(robot, v_d=v_d, p=p, v_prev=v_d, kappa=kappa,
                              grad_kappa=(-g, 0.0, 0.0), kinetostatic=False)
    assert status == STATUS_PASS
    # The look ahead: the margin is lost 2 cm along the last command (gradient here flat):
    # the speed along it brakes to the braking curve of 2 cm, a_max T a tick at most.
    v, status, binding, _ = _filter(robot, v_d=v_d, p=p, v_prev=v_d, kappa=5.0,
                                    grad_kappa=(0.0, 0.0, 0.0), ray=0.02,
                                    cable_brake=cable_brake)
    assert v[0] == pytest.approx(max(face_cap(0.02, A_BRAKE, T), 0.3 - per_tick), rel=1e-12)
    assert binding & BIND_KINETOSTATIC


def test_a_pair_barrier_is_met_and_the_command_is_the_weighted_projection():
    """On exp2's robot near the 1-3 boundary, with random commands: the filter's command
    meets every pair barrier row (recomputed here from the gradient and the module's rate)
    and is the closest such command (Clarabel on the same rows, speed and acceleration
    balls as second-order cones)."""
    from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

    from cdpm_drake.kernels.safety_filter import barrier_rate
    from cdpm_drake.config import load_resolved_scenario

    robot = load_resolved_scenario("exp2_interaction").robot
    i, j = robot.pair_index
    q = robot.pair_position(1, 3)
    params = filter_params(time_step=T, gamma=GAMMA, a_brake=A_BRAKE, max_velocity=V_MAX,
                           max_acceleration=A_MAX, return_speed=0.02,
                           full_pose=False, kinetostatic=False)
    rng = np.random.default_rng(5)
    p0 = np.array([1.56, 3.24, 1.22])
    checked = 0
    for _ in range(60):
        p = p0 + rng.normal(size=3) * 0.05
        grad = np.empty(6)
        d = pair_barrier(robot.reels, robot.attachments, int(i[q]), int(j[q]), p, np.eye(3),
                         grad)
        d_min = np.full(robot.num_pairs, 0.0)
        d_min[q] = d - rng.uniform(-0.0005, 0.002)
        v_prev = rng.normal(size=3) * 0.2
        v_d = v_prev + rng.normal(size=3) * 0.003
        v, status, binding, _ = _filter(robot, v_d=v_d, p=p, v_prev=v_prev, d_min=d_min,
                                        kinetostatic=False)
        if status == STATUS_HOLD:
            continue
        # The row as the module's docstring defines it: linearised a tick ahead (p + T
        # v_prev), asking at most |g| a_max T more than v_prev gave, never a step through.
        h = d - d_min[q]
        rate = barrier_rate(h, np.linalg.norm(grad[:3]), params)
        ramp = np.linalg.norm(grad[:3]) * RAMP_SHARE * A_MAX * T
        g = np.empty(6)
        h1 = pair_barrier(robot.reels, robot.attachments, int(i[q]), int(j[q]),
                          p + T * v_prev, np.eye(3), g) - d_min[q]
        g = g[:3]
        rhs = min(g @ v_prev - rate + (h - h1) / T, g @ v_prev + ramp)
        if h >= 0 and h1 >= 0:
            rhs = max(rhs, g @ v_prev - h1 / T)
        if status == STATUS_NO_RETURN:  # a lost margin held, not restored
            rhs = min(rhs, 0.0)
        assert g @ v >= rhs - 1e-9
        prog = MathematicalProgram()
        z = prog.NewContinuousVariables(3)
        prog.AddQuadraticCost(np.eye(3), -v_d, z, is_convex=True)
        prog.AddLinearConstraint(g[None, :], [rhs], [np.inf], z)
        cone = np.vstack([np.zeros((1, 3)), np.eye(3)])  # (a, z): |z| <= a
        # The speed limit; while the margin is lost (by more than LOST_DEPTH of travel), a
        # speed falling from V_MAX to LOST_SPEED at twice that depth, braked to at
        # RAMP_SHARE of a_max.
        depth = -h / np.linalg.norm(grad[:3])
        deep = depth > LOST_DEPTH
        slow_to = V_MAX + min(1.0, depth / LOST_DEPTH - 1.0) * (LOST_SPEED - V_MAX)
        cap = (min(V_MAX, max(slow_to, np.linalg.norm(v_prev) - RAMP_SHARE * A_MAX * T))
               if deep else V_MAX)
        prog.AddLorentzConeConstraint(cone, np.r_[cap, np.zeros(3)], z)
        prog.AddLorentzConeConstraint(cone, np.r_[A_MAX * T, -v_prev], z)
        options = SolverOptions()
        for name in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
            options.SetOption(ClarabelSolver.id(), name, 1e-12)
        result = ClarabelSolver().Solve(prog, None, options)
        if not result.is_success():
            continue
        # The same point (Clarabel's interior point on two cones is good to ~1e-6), and ours
        # no worse: it meets the balls (cut to 1e-9) and costs no more.
        ref = result.GetSolution(z)
        np.testing.assert_allclose(v, ref, atol=1e-5)
        assert np.linalg.norm(v) <= cap * (1 + 1e-8) + 1e-9
        assert np.linalg.norm(v - v_prev) <= A_MAX * T * (1 + 1e-8) + 1e-9
        assert np.sum((v - v_d) ** 2) <= np.sum((ref - v_d) ** 2) + 1e-10
        checked += 1
        if status != STATUS_PASS:  # the lost margin's speed cap binds too (deep)
            assert binding & (BIND_PAIR | BIND_ACCELERATION | (BIND_SPEED if deep else 0))
    assert checked > 30


@pytest.mark.parametrize("depth, share", [(0.0005, 0.0), (0.0015, 0.5), (0.003, 1.0)])
def test_a_lost_margin_caps_the_speed_by_how_deep_it_is_lost(depth, share):
    """The platform `depth` m beyond the upper x face of the box (h = -depth, |grad h| = 1),
    moving along the face (+y) a little faster than the cap and asked to go on: the speed is
    capped at V_MAX + share (LOST_SPEED - V_MAX), share = (depth - LOST_DEPTH) / LOST_DEPTH
    clipped to [0, 1] (the module's LOST_* comment), while the return pulls back along -x. A
    step from V_MAX to LOST_SPEED at LOST_DEPTH switched on and off as the kinetostatic
    margin hovered about it on a sliding platform, and rang the dynamic plant."""
    robot = _robot()
    p = np.array(robot.workspace.center, dtype=float)
    p[0] = robot.workspace.upper[0] + depth
    expected = V_MAX + share * (LOST_SPEED - V_MAX)
    assert depth <= LOST_DEPTH or abs(share - min(1.0, depth / LOST_DEPTH - 1.0)) < 1e-12
    speed = min(V_MAX, expected + 0.001)  # above the cap; braking (3.6 mm/s a tick) not binding
    v_prev = np.array([0.0, speed, 0.0])
    v, status, binding, _ = _filter(robot, v_d=v_prev, p=p, v_prev=v_prev,
                                    kinetostatic=False)
    assert status in (STATUS_MODIFIED, STATUS_NO_RETURN)
    assert v[0] < 0.0  # back towards the box
    assert np.linalg.norm(v) == pytest.approx(min(expected, speed), abs=1e-7)
    if share > 0.0:
        assert binding & BIND_SPEED


@pytest.mark.parametrize("cable_brake, per_tick", [(None, RAMP_SHARE * A_MAX * T),
                                                   (0.5, 0.5 * T), (50.0, RAMP_SHARE * A_MAX * T)])
def test_a_lost_margin_slows_the_platform_at_the_cable_brake_deceleration(cable_brake, per_tick):
    """3 mm beyond the box's upper x face (share 1: the cap is LOST_SPEED) at 0.3 m/s along
    the face: the cap comes down from the speed by cable_brake T a tick (a robot with mass:
    a_brake, which its cables take without ringing), by RAMP_SHARE a_max T without one, and
    never faster than that (the balls would touch in a point)."""
    robot = _robot()
    p = np.array(robot.workspace.center, dtype=float)
    p[0] = robot.workspace.upper[0] + 0.003
    v_prev = np.array([0.0, 0.3, 0.0])
    v, status, binding, _ = _filter(robot, v_d=v_prev, p=p, v_prev=v_prev, kinetostatic=False,
                                    cable_brake=cable_brake)
    assert binding & BIND_SPEED
    assert np.linalg.norm(v) == pytest.approx(0.3 - per_tick, abs=1e-9)


@pytest.mark.parametrize("a_prev, give_way", [(0.5, 40.0), (0.5, math.inf), (-0.5, 40.0),
                                               (0.3, 1000.0)])
def test_the_lost_margin_slowdown_gives_way_to_the_acceleration_the_platform_has(a_prev,
                                                                                 give_way):
    """The test above's lost margin (the cap LOST_SPEED, far below) with a cable brake of
    0.5 m/s^2, the platform at 0.3 m/s accelerating along its motion at a_prev (the last
    command's acceleration, the filter's memory), the command asking for more: the cap comes
    down from the speed by T min(0.5, -a_prev + give_way T) (safety_filter.give_way_ramp):
    at 0.5 m/s^2 and 40 m/s^3 the speed still grows by T (0.5 - 40 T), where without the
    give-way (inf) it drops by 0.5 T at once; already braking at 0.5 m/s^2 it goes on at the brake;
    at 0.3 m/s^2 and a fast give-way the brake is reached at once."""
    robot = _robot()
    p = np.array(robot.workspace.center, dtype=float)
    p[0] = robot.workspace.upper[0] + 0.003
    v_prev = np.array([0.0, 0.3, 0.0])
    v, status, binding, _ = _filter(robot, v_d=v_prev + [0.0, 0.003, 0.0], p=p,
                                      v_prev=v_prev, kinetostatic=False, cable_brake=0.5,
                                      give_way=give_way, a_prev=(0.0, a_prev, 0.0))
    assert binding & BIND_SPEED
    # Within the cutting planes' tolerance (BALL_TOL relative and absolute: 1.3e-9 m/s).
    assert np.linalg.norm(v) == pytest.approx(0.3 - T * min(0.5, -a_prev + give_way * T),
                                              abs=3e-9)


@pytest.mark.parametrize("a_prev, give_way, expected", [
    (-0.5, 40.0, 40.0 * T), (0.0, 40.0, 40.0 * T), (0.5, 40.0, 0.5 + 40.0 * T),
    (-0.5, math.inf, None), (1.95, 40.0, None)])
def test_after_a_brake_the_speed_comes_back_no_faster_than_the_brakes_come_on(a_prev, give_way,
                                                                             expected):
    """0.5 mm beyond the box's upper x face (a margin lost, by less than LOST_DEPTH: no
    slowdown) at 0.3 m/s along it, the command asking for the acceleration limit along y:
    on a robot with mass (a finite give-way rate, m/s^3) the speed grows by at most
    T (max(a_prev, 0) + give_way T) (safety_filter.regain_cap: a_prev the last command's
    acceleration along it, m/s^2): after a brake (a_prev < 0) by the give-way rate times the
    tick, not by the acceleration limit at once (a step of 2.5 m/s^2 in a tick, which rang
    exp2's cable 5 slack). Without a give-way (the kinematic plant), or where the cap is
    above the acceleration limit, the acceleration limit alone bounds it (the face's return
    takes part of its a_max T). The return along -x is the face's ramp either way."""
    robot = _robot()
    p = np.array(robot.workspace.center, dtype=float)
    p[0] = robot.workspace.upper[0] + 0.0005
    v_prev = np.array([0.0, 0.3, 0.0])
    v, status, binding, _ = _filter(robot, v_d=v_prev + [0.0, A_MAX * T, 0.0], p=p,
                                    v_prev=v_prev, kinetostatic=False, cable_brake=0.5,
                                    give_way=give_way, a_prev=(0.0, a_prev, 0.0), valid=True)
    assert v[0] == pytest.approx(-RAMP_SHARE * A_MAX * T, abs=1e-9)  # the face's return
    if expected is not None:
        # Within the cutting planes' tolerance (BALL_TOL relative and absolute: 1.3e-9 m/s).
        assert np.linalg.norm(v) == pytest.approx(0.3 + T * expected, abs=3e-9)
        assert binding & BIND_SPEED
    else:
        step = math.sqrt((A_MAX * T) ** 2 - (RAMP_SHARE * A_MAX * T) ** 2)
        assert v[1] == pytest.approx(0.3 + step, abs=3e-9)
        assert not binding & BIND_SPEED


def test_where_no_margin_is_lost_the_speed_regained_is_not_capped():
    """Far from every barrier, the same brake and ask: the acceleration limit alone bounds
    the speed (a_max T more): a hand that starts the platform moves it as on ideal reels
    (capped everywhere, the 40 N steps at t = 0 slackened more: exp2's across 1-3 233 holdable
    slack ticks for 189)."""
    robot = _robot()
    v_prev = np.array([0.3, 0.0, 0.0])
    v, status, binding, _ = _filter(robot, v_d=v_prev + [A_MAX * T, 0.0, 0.0],
                                    p=robot.workspace.center, v_prev=v_prev,
                                    kinetostatic=False, cable_brake=0.5, give_way=40.0,
                                    a_prev=(-0.5, 0.0, 0.0), valid=True)
    assert status == STATUS_PASS and binding == 0
    np.testing.assert_allclose(v, v_prev + [A_MAX * T, 0.0, 0.0], atol=1e-12)


def test_a_return_that_needs_more_speed_than_the_regain_cap_gives_the_cap_up():
    """The crossed pair of the test below, walked back from rest on a robot with mass (the
    last command at rest, a give-way rate of 40 m/s^3): the regain cap alone would allow
    40 T^2 (0.16 mm/s) this tick, the return asks RAMP_SHARE a_max T (3.6 mm/s); the cap is
    the first thing the filter gives up, before the return, so the platform is walked back
    as without it (status modified, not 'lost margins held')."""
    from cdpm_drake.config import load_resolved_scenario

    robot = load_resolved_scenario("exp2_interaction").robot
    q = robot.pair_position(1, 3)
    crossed = np.zeros(robot.num_pairs)
    crossed[q] = 1.0
    common = dict(v_d=np.zeros(3), p=np.array([1.56, 3.24, 1.22]),
                  d_min=np.zeros(robot.num_pairs), crossed=crossed, kinetostatic=False)
    v0, status0, _, _ = _filter(robot, **common)
    v, status, binding, _ = _filter(robot, **common, cable_brake=0.5, give_way=40.0,
                                    valid=True)
    assert np.linalg.norm(v0) == pytest.approx(RAMP_SHARE * A_MAX * T, abs=1e-9)
    np.testing.assert_allclose(v, v0, atol=1e-9)
    assert status == status0 == STATUS_MODIFIED and binding == BIND_PAIR


def test_a_crossed_pair_counts_its_distance_negative_and_is_walked_back():
    """A pair the interference block saw cross (crossed = 1) is a margin lost by its distance
    plus d_min: from rest the filter asks the platform back along minus the distance's
    gradient (central differences of the segment distance here), as fast as the ramp allows
    in one tick, RAMP_SHARE a_max T (below return_speed and the gamma share of a margin of
    centimetres); the same pair not crossed is far from its d_min and nothing moves. Exp2's
    robot near its swapped pair 1-3's boundary, where that distance's closest points lie
    inside both cables (the gradient is not zero)."""
    from cdpm_drake.config import load_resolved_scenario

    robot = load_resolved_scenario("exp2_interaction").robot
    i_all, j_all = robot.pair_index
    p = np.array([1.56, 3.24, 1.22])
    q = robot.pair_position(1, 3)
    i, j = int(i_all[q]), int(j_all[q])

    def dist(x):
        B = x + robot.attachments
        return segment_distance(B[i], robot.reels[i], B[j], robot.reels[j]).distance

    h = 1e-6
    g = np.array([(dist(p + h * e) - dist(p - h * e)) / (2 * h) for e in np.eye(3)])
    d_min = np.zeros(i_all.size)
    crossed = np.zeros(i_all.size)
    crossed[q] = 1.0
    v, status, binding, out = _filter(robot, v_d=np.zeros(3), p=p, d_min=d_min,
                                      crossed=crossed, kinetostatic=False)
    assert np.linalg.norm(g) > 0.005
    assert out[8] == pytest.approx(-dist(p), abs=1e-12)  # the smallest margin: -d - d_min
    np.testing.assert_allclose(v, -RAMP_SHARE * A_MAX * T * g / np.linalg.norm(g), atol=1e-9)
    assert status == STATUS_MODIFIED and binding == BIND_PAIR
    v, status, _, out = _filter(robot, v_d=np.zeros(3), p=p, d_min=d_min, kinetostatic=False)
    assert status == STATUS_PASS and out[8] > 0.03
    np.testing.assert_array_equal(v, 0.0)


def test_with_no_safe_command_it_brakes_to_a_hold_at_the_acceleration_limit():
    """Moving at 0.3 m/s along -x and -y, 1 cm from the box's lower x and y faces: each face
    asks its velocity component up by the ramp, RAMP_SHARE a_max T (the braking curve at 1 cm
    allows less than 0.3 m/s), and the nearest command meeting both lies sqrt(2) RAMP_SHARE
    a_max T > a_max T away: outside the acceleration limit. The filter holds: it brakes the
    last command along itself by a_max T (v (1 - a_max T / |v|)), never steps to zero."""
    robot = _robot()
    p = robot.workspace.lower + np.array([0.01, 0.01, 1.0])
    rate = min(GAMMA * 0.01 / T, face_cap(0.01, CURVE_SHARE * A_BRAKE, T))
    assert rate < 0.3 - RAMP_SHARE * A_MAX * T and math.sqrt(2) * RAMP_SHARE > 1.0
    prev = np.array([-0.3, -0.3, 0.0])
    v, status, binding, out = _filter(robot, v_d=prev, p=p, v_prev=prev,
                                      d_min=np.zeros(robot.num_pairs), kinetostatic=False)
    assert status == STATUS_HOLD and binding == 0
    np.testing.assert_allclose(v, prev * (1 - A_MAX * T / np.linalg.norm(prev)), rtol=1e-12)
    np.testing.assert_array_equal(out[OUT_MEMORY + 4:OUT_MEMORY + 7], v)  # braked from here


def test_the_barrier_position_advances_by_the_commands_and_follows_the_estimate_slowly():
    """barrier_position: p_c + T v_prev drawn towards the estimate by T / tau a tick (closed
    form: a constant offset e of the estimate decays as (1 - T / tau)^k, a ringing estimate is
    damped by that factor). The first tick (valid flag 0) and tau 0 take the estimate."""
    tau = 0.1
    p = np.array([1.0, 2.0, 1.5])
    out = np.empty(3)
    memory = np.zeros(10)
    barrier_position(p, memory, T, tau, out)
    np.testing.assert_array_equal(out, p)  # the first tick
    memory[:3], memory[3], memory[4:7] = [1.0, 2.0, 1.4], 1.0, [0.1, 0.0, 0.0]
    barrier_position(p, memory, T, tau, out)
    ahead = np.array([1.0 + T * 0.1, 2.0, 1.4])
    np.testing.assert_allclose(out, ahead + (T / tau) * (p - ahead), rtol=0, atol=1e-15)
    # At rest, an offset decays by (1 - T / tau) a tick: 1 mm -> 1 mm * 0.98^50 after 50.
    memory[:3], memory[4:7] = p + [0.001, 0.0, 0.0], 0.0
    for _ in range(50):
        barrier_position(p, memory, T, tau, out)
        memory[:3] = out
    assert out[0] - p[0] == pytest.approx(0.001 * (1 - T / tau) ** 50, rel=1e-9)
    barrier_position(p, memory, T, 0.0, out)  # tau 0: the estimate itself
    np.testing.assert_array_equal(out, p)


def test_the_filter_remembers_its_barrier_position_and_command():
    """The memory out of a tick is [p_c, 1, v, w]: the next tick's barrier_position input."""
    robot = _robot()
    v_d = np.array([0.05, 0.0, 0.0])
    v, status, _, out = _filter(robot, v_d=v_d, p=robot.workspace.center, v_prev=v_d)
    np.testing.assert_array_equal(out[OUT_MEMORY:OUT_MEMORY + 3], robot.workspace.center)
    assert out[OUT_MEMORY + 3] == 1.0


def test_two_lost_margins_that_pull_apart_are_held_not_restored():
    """At rest 2 mm below the box's lower x face (a lost margin: its return asks v_x > 0):
    alone, the filter walks it back at the ramp, RAMP_SHARE a_max T in the first tick
    (below return_speed and gamma's share), STATUS_MODIFIED. With the kinetostatic margin
    lost too and its gradient along -x (its return asks v_x < 0), no twist restores both:
    the second stage only keeps each from getting worse (grad h . v >= 0, so v_x = 0, the
    rest asked for) and says so, STATUS_NO_RETURN."""
    robot = _robot()
    p = robot.workspace.center.copy()
    p[0] = robot.workspace.lower[0] - 0.002
    rest = np.zeros(3)
    no_pairs = np.zeros(robot.num_pairs)
    v, status, binding, _ = _filter(robot, v_d=rest, p=p, d_min=no_pairs)
    assert status == STATUS_MODIFIED and binding == BIND_BOX
    np.testing.assert_allclose(v, [RAMP_SHARE * A_MAX * T, 0.0, 0.0], rtol=1e-12, atol=1e-15)
    v, status, _, _ = _filter(robot, v_d=rest, p=p, d_min=no_pairs, kappa=-0.5,
                              grad_kappa=(-50.0, 0.0, 0.0))
    assert status == STATUS_NO_RETURN
    np.testing.assert_allclose(v, 0.0, atol=1e-12)
