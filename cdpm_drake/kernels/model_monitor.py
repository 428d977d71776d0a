"""Knowing when the controller's model of the robot breaks (beyond the paper): from the
measurements alone, a slack cable, lengths the estimated pose no longer explains, or a hand
force the cables cannot hold. numpy and numba, no Drake.

Every controller here assumes taut, straight cables. When one goes slack (a hand lifts the
platform, the cables cannot hold the force it applies) the lengths the reels pay out stop
describing the platform, and everything computed from them (the pose, the distances between
cables, the tensions) becomes fiction. The monitor watches, each tick, with what the
controller already has:

- the measured tension, where the plant has one (a drive's torque, a load cell): a cable
  measured below measured_slack is slack (the estimate from the lengths cannot see a cable
  ringing slack);
- else the tension estimate (full pose with tension control: the pose fit's residual along
  the wrench matrix's nullspace, pose_control.py): a cable whose estimate is below
  -slack_tension is slack;
- without one, the length residual r_i = |a_i - B_i| - l_i of the estimated pose: a slack
  cable is longer than the geometry, r_i < -slack_length (a taut one is stretched, r_i > 0);
- every cable's residual (after the modelled stretch, where there is one) within
  fit_tolerance: beyond it the pose estimate no longer fits the lengths;
- t*, the largest minimum tension with which the cables could hold the weight and the
  measured hand force at the estimated pose (kinetostatics.margin): below -unholdable no
  tension holds the platform against that hand;
- the measured tension, where the plant has one, against the cables' overload (a multiple
  of the controller's ceiling max_tension): a cable pulled that far above what the
  controller keeps it under is overloaded, whatever the controller believes (its estimate
  comes from lengths, which a ringing or snagged cable does not show).

A condition that lasts `ticks` consecutive ticks is a fault (ModelFault, naming the cable, the
reason and the numbers); a slack cable where t* says the cables can hold the hand (t* >=
holdable) must last `slack_ticks` (a knock slackens a cable for a few milliseconds
whatever the controller does, and it takes the slack up again). The diagram's block raises
it, which stops a simulation and, on the robot, sends zero reel velocity (realtime.py), as
every fault does.
"""

import math

import numba
import numpy as np

from cdpm_drake.kernels.kinetostatics import (MARGIN_T_STAR, margin_in, scratch_views,
                                              tension_line)
from cdpm_drake.kernels.full_pose import held_wrench
from cdpm_drake.kernels.tension import max_min_1d

_jit = numba.njit(cache=True, error_model="numpy")

# monitor_tick's status / reason codes (the cable is reported beside them).
OK, SLACK, MISFIT, UNHOLDABLE, OVERLOAD = 0, 1, 2, 3, 4
REASONS = ("ok", "slack cable", "lengths no longer fit the pose", "hand force cannot be held",
           "cable overloaded")

# Parameters (a flat array, `monitor_params`).
(M_EA, M_SLACK_TENSION, M_SLACK_LENGTH, M_FIT, M_UNHOLDABLE, M_TICKS, M_ESTIMATE, M_FULL,
 M_MASS, M_HANDLE, M_ROWS, M_HOLDABLE, M_SLACK_TICKS, M_MEASURED, M_OVERLOAD,
 M_RECONCILING) = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 12, 13, 14, 15, 16, 17)
# The memory: ticks of slack, misfit, unholdable, overload.
MEMORY = 4


class ModelFault(RuntimeError):
    """The controller's model no longer describes the robot (a slack cable, lengths that do
    not fit, a hand force no tension holds): the run stops with zero reel velocity."""


def monitor_params(robot, *, EA, slack_tension, slack_length, fit_tolerance, unholdable,
                   ticks, estimate: bool, full_pose: bool, rows: int, holdable: float,
                   slack_ticks: int, measured_slack: float = 0.0,
                   overload: float = 0.0, reconciling: bool = False) -> np.ndarray:
    """The monitor's parameters: EA (N; 0: no modelled stretch), the thresholds (N, m, m, N),
    the ticks a condition must last, whether there is a tension estimate and a full pose,
    the platform's mass (kg) and handle (m, platform frame), the wrench rows (3 or 6), the t*
    (N) from which the cables hold the hand and the ticks a slack cable must last there, the
    measured tension (N) below which a cable is slack (0: no slack from measured tensions),
    the measured tension (N) above which a cable is overloaded (0: none), and whether it
    reads the encoder zero's `reconciled` flag (lengths from homed encoders: no slack is
    judged on the lengths or the estimate before it is 1)."""
    d = robot.dynamics
    return np.array([EA, slack_tension, slack_length, fit_tolerance, unholdable, ticks,
                     1.0 if estimate else 0.0, 1.0 if full_pose else 0.0, d.mass, *d.handle,
                     rows, holdable, slack_ticks, measured_slack, overload,
                     1.0 if reconciling else 0.0], dtype=float)


def monitor_sizes(m: int, full_pose: bool, estimate: bool, measured: bool = False,
                  reconciling: bool = False) -> dict:
    """x: lengths (m), p (3), F_H (3), and R (9) for the full pose, the tension estimate (m)
    with one, the measured tensions (m) with them, the encoder zero's reconciled flag (1)
    with it, then the memory: counters (MEMORY); out: status (1), cable (1, 1-based, 0
    none), value (1: the number behind it, N or m), t* (1, N), residual (m, m), next memory
    (MEMORY)."""
    x = (m + 6 + (9 if full_pose else 0) + (m if estimate else 0) + (m if measured else 0)
         + (1 if reconciling else 0))
    return {"x": x + MEMORY, "out": m + 4 + MEMORY, "memory": MEMORY, "memory_at": m + 4}


@numba.njit(cache=True, error_model="numpy", inline="always")  # no tuple passed by value
def hand_t_star(reels, attachments, rows, p, R, w, views):
    """t* at the pose (p, R) under the wrench w (kinetostatics.margin's t*: N, +inf where an
    internal force raises every tension, -inf where the first `rows` rows of the wrench
    matrix are rank-deficient), the cables posed in views[:3]. A robot with one internal
    force (m = rows + 1) takes its line of tensions by Gaussian elimination
    (kinetostatics.tension_line) instead of the pivoted QR, which was most of the monitor's
    cost: the max-min over that line does not depend on which point and direction describe
    it (max_min_1d is exact); equal to the QR's t* to round-off (tests/kernels/
    test_model_monitor.py)."""
    if reels.shape[0] == rows + 1:
        if not tension_line(reels, attachments, rows, p, R, w, views):
            return -math.inf
        return max_min_1d(views[9], views[14])[0]
    return margin_in(reels, attachments, rows, p, R, w, 0.0, math.inf, views, 0.0,
                     MARGIN_T_STAR)[1]


@_jit
def monitor_tick(reels, attachments, params, scratch, x, out):
    """One tick (module docstring). x = [l (m) m, p (3) m, F_H (3) N, (full pose:) R (9),
    (with a tension estimate:) T_est (m) N, (params[M_MEASURED] > 0 or params[M_OVERLOAD]
    > 0:) T_measured (m) N, (params[M_RECONCILING] > 0:) reconciled (1), memory: ticks of
    slack, misfit, unholdable, overload (MEMORY)]; a cable with a finite measured tension is
    slack below params[M_MEASURED] (where > 0), whatever the estimate says, and overloaded
    above params[M_OVERLOAD] (where > 0); while `reconciled` is 0 (the encoders' zero not
    yet reconciled with the cables' stretch, encoder_zero.py) the lengths and the estimate
    judge no cable slack;
    out = [status, cable (1-based), value, t* (N), residual (m) m, next memory (MEMORY)];
    scratch: kinetostatics.margin_scratch(m). The status is the condition that has lasted
    its ticks (a fault), OK otherwise; where several have, the first of OVERLOAD, SLACK,
    MISFIT, UNHOLDABLE (an overloaded cable first: it may snap). A slack cable counts
    after params[M_TICKS] ticks where the statics at the estimated pose hold the measured
    hand force with less than params[M_HOLDABLE] in every cable (t* below it: the slack is
    the hand's doing and lasts), after params[M_SLACK_TICKS] where they hold it with more
    (the controller takes the slack of a knock up again: a hand that hits the platform with
    40 N at once slackens a cable for a few milliseconds whatever the controller does).
    Returns the status."""
    m = reels.shape[0]
    l = x[0:m]
    p = x[m:m + 3]
    F = x[m + 3:m + 6]
    k = m + 6
    views = scratch_views(scratch)  # the block's work arrays: a tick allocates nothing
    _, R, w, zero, _, _ = views[19]
    full = params[M_FULL] != 0.0
    for a in range(3):
        for b in range(3):
            R[a, b] = x[k + 3 * a + b] if full else (1.0 if a == b else 0.0)
    if full:
        k += 9
    estimate = params[M_ESTIMATE] != 0.0
    T = x[k:k + m] if estimate else x[0:m]
    measured_slack = params[M_MEASURED]
    measured = measured_slack > 0.0
    overload = params[M_OVERLOAD]
    k_measured = k + m if estimate else k
    # Before the encoders' zero is reconciled, the lengths (and the estimate on them) may be
    # off by the cables' whole stretch at the homing: no slack is judged on them.
    settled = not (params[M_RECONCILING] != 0.0 and x[x.shape[0] - MEMORY - 1] == 0.0)
    mem = x[x.shape[0] - MEMORY:]
    EA = params[M_EA]
    held_wrench(R, params[M_MASS:M_MASS + 4], F, zero, w)
    t_star = hand_t_star(reels, attachments, int(params[M_ROWS]), p, R, w, views)
    L = views[2]  # the cables' lengths at (p, R): the statics posed them
    r = out[4:4 + m]
    slack_cable, slack_value = -1, 0.0
    misfit_cable, misfit_value = -1, 0.0
    over_cable, over_value = -1, 0.0
    for i in range(m):
        if overload > 0.0 and x[k_measured + i] > overload and (
                over_cable < 0 or x[k_measured + i] > over_value):  # NaN: no reading
            over_cable, over_value = i, x[k_measured + i]
        stretched = l[i] * (1.0 + T[i] / EA) if (estimate and EA > 0.0) else l[i]
        r[i] = L[i] - stretched
        if measured and math.isfinite(x[k_measured + i]):
            # The cable's measured tension, where it has one: the estimate from the
            # lengths cannot see a cable ringing slack (nor tell a misfit from one).
            t_measured = x[k_measured + i]
            if t_measured < measured_slack and (slack_cable < 0 or
                                                t_measured < slack_value):
                slack_cable, slack_value = i, t_measured
        elif not settled:
            pass
        elif estimate:
            if T[i] < -params[M_SLACK_TENSION] and (slack_cable < 0 or T[i] < slack_value):
                slack_cable, slack_value = i, T[i]
        elif r[i] < -params[M_SLACK_LENGTH] and (slack_cable < 0 or r[i] < slack_value):
            slack_cable, slack_value = i, r[i]
        if abs(r[i]) > params[M_FIT] and abs(r[i]) > abs(misfit_value):
            misfit_cable, misfit_value = i, r[i]
    unholdable = t_star < -params[M_UNHOLDABLE]
    counts = (mem[0] + 1.0 if slack_cable >= 0 else 0.0,
              mem[1] + 1.0 if misfit_cable >= 0 else 0.0,
              mem[2] + 1.0 if unholdable else 0.0,
              mem[3] + 1.0 if over_cable >= 0 else 0.0)
    out[4 + m], out[5 + m], out[6 + m], out[7 + m] = counts
    status, cable, value = OK, 0, 0.0
    n = params[M_TICKS]
    slack_n = n if t_star < params[M_HOLDABLE] else params[M_SLACK_TICKS]
    if counts[3] >= n:
        status, cable, value = OVERLOAD, over_cable + 1, over_value
    elif counts[0] >= slack_n:
        status, cable, value = SLACK, slack_cable + 1, slack_value
    elif counts[1] >= n:
        status, cable, value = MISFIT, misfit_cable + 1, misfit_value
    elif counts[2] >= n:
        status, value = UNHOLDABLE, t_star
    out[0], out[1], out[2], out[3] = status, cable, value, t_star
    return status


def fault_message(status: int, cable: int, value: float, *, ticks: int, time_step: float,
                  estimate: bool, p, F_H=None, measured: bool = False,
                  overload: float = 0.0) -> str:
    """The words of a monitor fault: the cable (1-based), the reason, the number and for how
    many ticks (of time_step s) it lasted; measured: the slack cable's value is its
    measured tension; overload: the tension (N) an overloaded cable is above."""
    lasting = f"for {ticks} ticks ({1000 * ticks * time_step:.3g} ms)"
    where = f"at p = {np.round(np.asarray(p, dtype=float), 4).tolist()} m"
    if status == OVERLOAD:
        return (f"cable {cable} is overloaded: its measured tension is {value:.1f} N, above "
                f"{overload:g} N (model_monitor.overload x controller.max_tension) {lasting}, "
                f"{where}")
    if status == SLACK:
        what = (f"its measured tension is {value:.2f} N" if measured else
                f"its tension estimate is {value:.2f} N" if estimate else
                f"it is {1000 * -value:.2f} mm longer than the estimated pose explains")
        # A length that disagrees from the start may be the file's geometry, not slack.
        hint = ("" if measured or estimate else
                " (or the robot file's geometry is off by millimetres: cdpm calibrate)")
        return f"cable {cable} is slack: {what} {lasting}, {where}{hint}"
    if status == MISFIT:
        return (f"the cable lengths no longer fit the estimated pose: cable {cable} is "
                f"{1000 * value:+.2f} mm off it {lasting}, {where} (a slipped or broken "
                "encoder, or a robot file whose geometry is off: cdpm calibrate)")
    if status == UNHOLDABLE:
        force = "" if F_H is None else (
            f" {np.round(np.asarray(F_H, dtype=float), 2).tolist()} N")
        return (f"the hand force{force} cannot be held {where}: the best distribution of "
                f"the cables' tensions leaves one at {value:.2f} N {lasting}")
    return "ok"
