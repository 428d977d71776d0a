"""No allocation in the tick: the kinetostatic, model-monitor and safety-filter kernels (the
filter's QP included) and the unseen-ringing kernel (no tension sensor; 43 allocations a call
before its buffer) work in their block's buffers (numba's allocation counter, NRT_STATS, over
1000 calls as the blocks make them, on the shipped experiments' paper_7cable: one internal
force, the max-min solved in closed form; a robot with two or more, cube_8cable, still
allocates the QP form's work arrays, qp.py), and exp2's diagram as shipped, warmed and its
log reserved, grows no Python memory over 1000 ticks (tracemalloc around
Simulator.AdvanceTo). Each check has a control that allocates, to show it would catch one."""

import os
import subprocess
import sys
import textwrap

import numpy as np

# Run with NUMBA_NRT_STATS=1 (read when numba starts): prints, per kernel, numba's allocations
# per call beyond one per array argument (each argument's unboxing makes one MemInfo).
KERNELS = textwrap.dedent("""
    import numpy as np, numba
    from numba.core.runtime import rtsys
    from cdpm_drake.kernels.call import bind, owned, owned_scratch
    from cdpm_drake.kernels.kinetostatics import (KIN_OUT, X_R, X_STATE, kinetostatic_params,
                                                  kinetostatic_tick, margin_scratch)
    from cdpm_drake.kernels.model_monitor import monitor_params, monitor_sizes, monitor_tick
    from cdpm_drake.robot import load_robot, resolve_robot_path

    def per_call(kernel, args):
        f = bind(kernel, *args)
        f(*args)
        before = rtsys.get_allocation_stats().alloc
        for _ in range(1000):
            f(*args)
        arrays = sum(len(a) if isinstance(a, tuple) else 1 for a in args
                     if isinstance(a, (np.ndarray, tuple)))
        return (rtsys.get_allocation_stats().alloc - before) / 1000 - arrays

    robot = load_robot(resolve_robot_path("paper_7cable"))
    m = robot.num_cables
    reels, att = owned(robot.reels), owned(robot.attachments)
    scratch = owned_scratch(margin_scratch(m))
    x = np.zeros(X_R + 9)
    x[:3] = robot.workspace.center + [0.9, 0.3, 0.2]
    x[3:6] = [8.0, -5.0, -20.0]
    x[X_STATE + 4:X_STATE + 7] = [0.4, 0.1, -0.2]  # moving: the look ahead samples
    x[X_R:] = np.eye(3).ravel()
    results = {}
    for soft in (0.0, 2.0):  # the hard margin (its active set) and the soft (Newton)
        params = owned(kinetostatic_params(
            robot, floor=3.0, ceiling=60.0, rows=6, barrier=True, t_l=5.0, t_u=12.0,
            F_u=3.0, eps=0.1, force=True, a_brake=2.0, time_step=0.002, soft=soft))
        out = np.empty(KIN_OUT)
        results[f"kinetostatic_tick soft={soft}"] = per_call(
            kinetostatic_tick, (reels, att, params, scratch, x, out))
        assert np.isfinite(out[3]) and np.any(out[4:7] != 0.0), out
    s = monitor_sizes(m, True, False, False, False)
    xm = np.zeros(s["x"])
    xm[:m] = np.linalg.norm(robot.reels - robot.workspace.center - robot.attachments, axis=1)
    xm[m:m + 3] = robot.workspace.center
    xm[m + 6:m + 15] = np.eye(3).ravel()
    par = owned(monitor_params(robot, EA=0.0, slack_tension=1.0, slack_length=0.01,
                               fit_tolerance=0.02, unholdable=1.0, ticks=5, estimate=False,
                               full_pose=True, rows=6, holdable=1.0, slack_ticks=5))
    results["monitor_tick"] = per_call(monitor_tick, (reels, att, par, scratch, xm,
                                                      np.empty(s["out"])))

    from cdpm_drake.kernels.safety_filter import (filter_params, filter_scratch, filter_sizes,
                                                  filter_tick)
    i, j = robot.pair_index
    pi, pj = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    P = pi.size
    dmin = owned(np.full(P, 0.06))
    bounds = owned(np.array([robot.workspace.lower, robot.workspace.upper]))
    for full in (False, True):
        fs = filter_sizes(P, full)
        xf = np.zeros(fs["x"])
        xf[0:3] = [0.6, -0.4, 0.3]  # above the speed limit: the QP and its cutting planes
        xf[3:6] = robot.workspace.center + [0.9, 0.3, 0.2]
        xf[6 + P] = 0.5  # a kinetostatic margin about to bind, its look ahead 2 cm on
        xf[7 + P:10 + P] = [-20.0, 5.0, 10.0]
        xf[10 + P] = 0.02
        if full:
            xf[14 + P:23 + P] = np.eye(3).ravel()
        xf[fs["memory_at"] + 4:fs["memory_at"] + 7] = [0.2, -0.1, 0.1]  # the last command
        fp = owned(filter_params(time_step=0.002, gamma=0.2, a_brake=1.0, max_velocity=0.5,
                                 max_acceleration=2.0, return_speed=0.02, full_pose=full,
                                 kinetostatic=True, smoothing=0.1))
        outf = np.empty(fs["out"])
        results[f"filter_tick full={full}"] = per_call(filter_tick, (
            reels, att, pi, pj, dmin, bounds, fp, owned_scratch(filter_scratch(P, full)), xf,
            outf))
        assert outf[6] >= 1 and outf[7] != 0, outf  # modified, some barrier or ball binding

    from cdpm_drake.kernels.unseen_ringing import (ringing_params, ringing_scratch,
                                                   ringing_sizes, ringing_tick)
    rs = ringing_sizes(m)
    xr = np.zeros(rs["x"])
    xr[0:3] = robot.workspace.center + [0.9, 0.3, 0.2]
    xr[3:12] = np.eye(3).ravel()
    xr[12:18] = [0.3, -0.2, 0.1, 0.05, 0.0, -0.02]  # the command twist
    xr[18:21] = [8.0, -5.0, -20.0]
    xr[21:21 + m] = 2.0  # estimates near the floor: cables warned of
    mem = xr[21 + m:]
    mem[0] = 50.0  # past the warm-up, a ringing under way: every solve and the swing
    mem[1:7] = [0.1, 0.0, -0.1, 0.0, 0.02, 0.0]
    mem[7:19] = 1e-4
    rp = owned(ringing_params(robot.dynamics, time_step=0.002, floor=4.0, warmup=10))
    outr = np.empty(rs["out"])
    results["ringing_tick"] = per_call(ringing_tick, (
        reels, att, rp, owned_scratch(ringing_scratch(m)), xr, outr))
    assert np.all(outr[:m] > 0.0) and outr[m:2 * m].any(), outr  # swings, a cable warned of

    @numba.njit
    def allocating(x, out):  # the control: a kernel with one work array of its own
        w = np.empty(3)
        w[:] = x[:3]
        out[0] = w.sum()

    results["control"] = per_call(allocating, (np.ones(3), np.empty(1)))
    print(results)
""")


def test_the_safety_kernels_allocate_nothing_a_call():
    env = dict(os.environ, NUMBA_NRT_STATS="1")
    text = subprocess.run([sys.executable, "-c", KERNELS], check=True, capture_output=True,
                          text=True, env=env).stdout
    results = eval(text.strip().splitlines()[-1])
    assert results.pop("control") == 1.0  # the counter sees one np.empty a call
    assert results == {"kinetostatic_tick soft=0.0": 0.0, "kinetostatic_tick soft=2.0": 0.0,
                       "monitor_tick": 0.0, "filter_tick full=False": 0.0,
                       "filter_tick full=True": 0.0, "ringing_tick": 0.0}


def _growth_per_tick(wrap=None):
    """Python memory (bytes) exp2's diagram as shipped keeps, and its peak above the start,
    per tick over 1000 ticks after 0.5 s of warming (its log reserved for the whole run).
    wrap: a function applied to the kinetostatic block's bound kernel (the control)."""
    import tracemalloc

    from pydrake.systems.analysis import Simulator

    from cdpm_drake.config import load_scenario
    from cdpm_drake.diagram import build_diagram, reserve_log
    from cdpm_drake.systems import kinetostatic_force

    original = kinetostatic_force.bind
    if wrap is not None:
        kinetostatic_force.bind = lambda *a: wrap(original(*a))
    try:
        diagram = build_diagram(load_scenario("exp2_interaction"))
    finally:
        kinetostatic_force.bind = original
    simulator = Simulator(diagram)
    simulator.Initialize()
    reserve_log(diagram, simulator.get_mutable_context(), 2000)
    simulator.AdvanceTo(0.5)
    tracemalloc.start()
    try:
        start = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        simulator.AdvanceTo(0.5 + 1000 * 0.002)
        now, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return (now - start) / 1000, (peak - start) / 1000


def test_the_shipped_diagram_keeps_no_memory_a_tick():
    # Measured: 0.6 bytes kept a tick and a 7 kB peak over the 1000 ticks (the port values'
    # wrappers come and go); the control, a kernel that keeps 8 floats a call, 188 bytes a
    # tick.
    kept, peak = _growth_per_tick()
    assert kept < 8.0 and peak < 64.0, (kept, peak)
    kept_list = []

    def wrap(kernel):
        def keeping(*args):
            kept_list.append(np.array(args[-1][:8]))  # a leak of 8 floats a tick
            return kernel(*args)
        return keeping

    kept, _ = _growth_per_tick(wrap)
    assert kept > 100.0 and len(kept_list) >= 1000
