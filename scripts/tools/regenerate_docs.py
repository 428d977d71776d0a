"""Regenerate every simulation-derived number and picture that README.md and docs/ show, from
the current code.

Numbers live in marked blocks of the pages, `<!-- generated: NAME -->...<!-- /generated -->`
(inline or around a table); the prose around them stays hand-written and this script only
rewrites what lies between the markers. Pictures are written with the numbers they show as PNG
text metadata (key `cdpm_generated`: JSON with the script, the picture's name and its
numbers), so that tests/docs/test_generated_docs.py can check them against a recomputation
and tell a picture this script drew from one drawn by hand.

Numbers that depend on the machine (real-time factors) are written as measured, with the
date and the machine, and no test compares them. The adversarial benchmark's tables in
docs/benchmarks.md (scripts/bench/adversarial_benchmark.py, ~7 min on two cores) and the
hand-measured paragraphs of the pages are not regenerated here.

    python scripts/tools/regenerate_docs.py              # everything (~1.5 min on two cores)
    python scripts/tools/regenerate_docs.py --list       # the blocks and pictures
    python scripts/tools/regenerate_docs.py --only readme_exp2_paper --only exp1_distances
    python scripts/tools/regenerate_docs.py --check      # which blocks are stale (not the pictures)
"""

import argparse
import dataclasses
import datetime
import json
import logging
import os
import platform
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
BLOCK = re.compile(r"<!-- generated: ([\w-]+) -->(.*?)<!-- /generated -->", re.S)
PNG_KEY = "cdpm_generated"
SCRIPT = "scripts/tools/regenerate_docs.py"
EXPERIMENTS = ("exp1_no_interaction", "exp2_interaction", "exp3_two_pairs")
FULL_POSE = "controller: {pose: full, tension_control: true}"
# Machine-dependent text is wrapped in these while rendering: written as it is, matched by
# any text in the staleness test.
MEASURED_START, MEASURED_END = "\x01", "\x02"


# A number from a simulation is wrapped in these: written as formatted, matched within its
# tolerance (the same code on another CPU rounds differently and the closed loop carries it).
APPROX_START, APPROX_SEP, APPROX_END = "\x03", "\x1f", "\x04"
_TOKEN = re.compile(f"{MEASURED_START}.*?{MEASURED_END}|{APPROX_START}(.*?){APPROX_SEP}(.*?)"
                    f"{APPROX_SEP}(.*?){APPROX_END}", re.S)

# How far a simulated number may move between hosts (absolute, in the number's unit). Measured
# by rerunning every simulated block on one machine in four floating-point configurations of
# another host: numba compiling for this CPU (AVX-512), for generic x86-64 and for Haswell
# (NUMBA_CPU_NAME), OpenBLAS's Haswell kernels instead of SkylakeX's (OPENBLAS_CORETYPE), and
# numpy without its AVX-512 loops (NPY_DISABLE_CPU_FEATURES). The kernels are bit for bit the
# same on every CPU target (no fast-math); OpenBLAS's kernels move the closed loop's results:
# exp2's smallest true tension 3.9497 -> 3.9233 N (the 3.92 N another host gave), an estimated
# distance by 0.01 mm, a time by 0.01 s, no count of ticks (TOLERANCE_SPREAD, the largest
# moves seen). Each tolerance is about four times its spread; counts stay exact.
TOLERANCE_SPREAD = {"N": 0.026, "mm": 0.01, "s": 0.01, "deg": 0.0, "ticks": 0}
TOLERANCE = {"N": 0.1, "mm": 0.05, "s": 0.05, "deg": 0.02, "ticks": 0}


def measured(text: str) -> str:
    """Machine-dependent text (a real-time factor): written, never compared."""
    return f"{MEASURED_START}{text}{MEASURED_END}"


def approx(value: float, fmt: str, unit: str) -> str:
    """A number a simulation gives, formatted with `fmt`: a page's number matches when it is
    within TOLERANCE[unit] of `value` (plus half its last written digit)."""
    return (f"{APPROX_START}{format(value, fmt)}{APPROX_SEP}{float(value)!r}{APPROX_SEP}"
            f"{TOLERANCE[unit]!r}{APPROX_END}")


def written(text: str) -> str:
    """The rendered text as the page holds it (the markers dropped)."""
    text = _TOKEN.sub(lambda m: m.group(1) if m.group(1) is not None else m.group(0), text)
    return text.replace(MEASURED_START, "").replace(MEASURED_END, "")


def pattern(text: str) -> re.Pattern:
    """A regex matching the page's text for this rendering: literal, but anything (on one
    line) where the rendering holds measured text and any number (a group) where it holds a
    simulated one."""
    out, at = [], 0
    for m in _TOKEN.finditer(text):
        out.append(re.escape(text[at:m.start()]))
        out.append(r"[^\n|]*?" if m.group(1) is None else r"(-?[0-9]+(?:\.[0-9]+)?)")
        at = m.end()
    out.append(re.escape(text[at:]))
    return re.compile("".join(out), re.S)


def mismatch(text: str, shown: str) -> str | None:
    """Why the page's `shown` text is not this rendering (None when it is): its literal text
    differs, or a simulated number lies outside its tolerance."""
    m = pattern(text).fullmatch(shown)
    if m is None:
        return f"the text differs: the code gives {written(text)!r}"
    numbers = [t for t in _TOKEN.finditer(text) if t.group(1) is not None]
    for group, token in zip(m.groups(), numbers):
        value, tol = float(token.group(2)), float(token.group(3))
        decimals = len(group.split(".")[1]) if "." in group else 0
        if abs(float(group) - value) > tol + 0.5 * 10.0 ** -decimals + 1e-12:
            return (f"{group} where the code gives {value:.6g} (tolerance {tol:g}): the code "
                    f"gives {written(text)!r}")
    return None


def machine() -> str:
    """The CPU model and core count, for measured numbers."""
    model = platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = " ".join(line.split(":", 1)[1].split())
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores"


def today() -> str:
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")


# --- runs, each simulated once per process ----------------------------------------------------

class Runs:
    """Simulations of (scenario name, overlay), each scenario run once: two overlays that
    resolve to the same scenario share a run."""

    def __init__(self):
        self._done = {}

    def __call__(self, name: str, text: str = ""):
        from pydrake.common.yaml import yaml_dump_typed

        from cdpm_drake.config import load_scenario
        from cdpm_drake.runs.simulate import simulate

        scenario = load_scenario(name, text or None)
        key = yaml_dump_typed(scenario)
        if key not in self._done:
            print(f"regenerate_docs: simulating {name} {text}".rstrip(), file=sys.stderr)
            self._done[key] = simulate(scenario=scenario)
        return self._done[key]


def closest_pair_mm(log, pair=(1, 3)) -> float:
    """The smallest distance (mm) of the pair over the run, as the controller saw it."""
    k = [tuple(p) for p in log["pairs"]].index(tuple(pair))
    return 1000 * float(np.min(log["pair_distances"][:, k]))


def dynamic(sensor: str | None = None, extra: str = "") -> str:
    """The overlay of the dynamic plant with the full pose and tension control."""
    plant = "!DynamicReels {}" if sensor is None else f"!DynamicReels {{tension_sensor: {sensor}}}"
    return "{" + FULL_POSE + f", plant: {plant}" + (", " + extra if extra else "") + "}"


def min_true_tension(runs, name: str, sensor: str) -> float:
    return float(runs(name, dynamic(sensor)).log["tensions"].min())


# --- the blocks --------------------------------------------------------------------------------

@dataclasses.dataclass
class Block:
    """A marked block of a page: `render(runs)` is its text; a table block also names its
    rows (`rows`) and renders one (`row(runs, key)`), so a test can recompute a sample."""
    name: str
    page: str  # "README" or a docs/ page's stem
    render: object
    rows: tuple = ()
    row: object = None
    note: str = ""


def _methods_cell(method: str):
    def render(runs):
        text = "" if method == "promise" else f"method: {method}"  # promise: the default
        return f"{approx(closest_pair_mm(runs('exp2_interaction', text).log), '.2f', 'mm')} mm"
    return render


def _shipped_holding(runs) -> str:
    from cdpm_drake.config import load_scenario, scenario_robot
    from cdpm_drake.robot.statics import holding_tension

    smallest = min(float(np.min(holding_tension(scenario_robot(load_scenario(n)),
                                                runs(n).log["p"]))) for n in EXPERIMENTS)
    return approx(smallest, ".2f", "N")


def _paper_share(runs) -> str:
    from cdpm_drake.kernels.tension import step_grid
    from cdpm_drake.robot import load_robot
    from cdpm_drake.robot.statics import holding_tension

    r = load_robot("paper_7cable")
    t = holding_tension(r, step_grid(r.workspace.lower, r.workspace.upper, 0.05))
    return f"{100 * float(np.mean(t >= 5.0)):.1f}"


def _tension_pair(runs) -> str:
    none = min_true_tension(runs, "exp2_interaction", "none")
    drive = min_true_tension(runs, "exp2_interaction", "drive_torque")
    return (f"{approx(none, '.2f', 'N')} N without a sensor, {approx(drive, '.2f', 'N')} N "
            "with the drive torque")


def _tension_none(runs) -> str:
    return f"{approx(min_true_tension(runs, 'exp2_interaction', 'none'), '.2f', 'N')} N"


def _tension_from_to(runs) -> str:
    return (f"from {approx(min_true_tension(runs, 'exp2_interaction', 'none'), '.2f', 'N')} to "
            f"{approx(min_true_tension(runs, 'exp2_interaction', 'drive_torque'), '.2f', 'N')} N")


def _exp2_smallest(runs) -> str:
    def where(log):
        T = np.asarray(log["tensions"])
        k, i = np.unravel_index(int(np.argmin(T)), T.shape)
        return float(T[k, i]), int(i) + 1, float(log["time"][k])

    on = where(runs("exp2_interaction", dynamic()).log)
    off = where(runs("exp2_interaction",
                     dynamic(extra="safety_filter: {enabled: false}")).log)
    return (f"its smallest true tension is cable {on[1]}'s {approx(on[0], '.2f', 'N')} N at "
            f"{approx(on[2], '.2f', 's')} s (with the filter off: cable {off[1]}'s "
            f"{approx(off[0], '.2f', 'N')} N at {approx(off[2], '.2f', 's')} s)")


FIG5 = "{safety_filter: {enabled: false}, model_monitor: {enabled: false}}"


def cpu_realtime_factor(name: str, text: str = "", repeats: int = 3) -> float:
    """Simulated seconds per second of this process's CPU time, best of `repeats` runs: the
    real-time factor of an idle host, which a loaded one does not change (its wall clock
    does)."""
    import time

    from cdpm_drake.config import load_scenario
    from cdpm_drake.runs.simulate import simulate

    scenario = load_scenario(name, text or None)
    best = 0.0
    for _ in range(repeats):
        start = time.process_time()
        simulate(scenario=scenario)
        best = max(best, scenario.duration / (time.process_time() - start))
    return best


def _exp2_realtime(runs) -> str:
    """exp2's real-time factor as shipped and as the paper's Fig. 5 (filter and monitor off),
    loggers on: the one place the guide states it."""
    def rate(text):
        factor = cpu_realtime_factor("exp2_interaction", text)
        return measured(f"{factor:.0f}x"), measured(f"{2000 / factor:.0f} us")

    (s_x, s_us), (f_x, f_us) = rate(""), rate(FIG5)
    return (f"Experiment 2 (30 s, every signal logged) runs at {s_x} real time as shipped "
            f"({s_us} of CPU per 2 ms tick) and at {f_x} as the paper's Fig. 5, filter and "
            f"monitor off ({f_us}): simulated time per CPU second, best of 3 runs, measured "
            f"{measured(today())} on {measured(machine())}; the wall clock gives the same on an "
            "idle host and less on a loaded one")


# The dynamic plant against the kinematic plant (scripts/tools/dynamic_plant_report.py's runs).
CONTROLLERS = (("full pose + tension control", "full pose", FULL_POSE),
               ("length loop (default)", "length loop", ""),
               ("open loop (`length_gain: 0`)", "open loop", "controller: {length_gain: 0}"))
DYNAMIC_ROWS = tuple((name, label) for _, label, _ in CONTROLLERS for name in EXPERIMENTS)


def _dynamic_row(runs, key) -> str:
    from cdpm_drake.kernels.rotation import rotation_angle, rotations_from_rpy

    name, label = key
    first, text = next((f, t) for f, lab, t in CONTROLLERS if lab == label)
    shown = first if name == "exp1_no_interaction" else first.split(" (")[0]
    kinematic = runs(name).log
    result = runs(name, "{plant: !DynamicReels {}" + (", " + text if text else "") + "}")
    log = result.log
    active = np.asarray(kinematic["active"]).any(axis=0)
    if not active.any():  # no pair interferes: the closest one
        active[int(np.argmin(kinematic["pair_distances"].min(axis=0)))] = True
    d = [1000 * float(np.min(log_[key_][:, active])) for log_, key_ in
         ((log, "pair_distances_true"), (log, "pair_distances"), (kinematic, "pair_distances"))]
    slack = approx(int(np.any(log["slack"], axis=1).sum()), "d", "ticks")
    if result.error is not None:
        slack = f"{slack} (monitor fault at {approx(log['time'][-1], '.1f', 's')} s)"
    tilt = np.degrees(rotation_angle(rotations_from_rpy(log["rpy_true"]))).max()
    err = 1000 * np.linalg.norm(log["p"] - log["p_true"], axis=1).max()
    mm = [approx(v, ".2f", "mm") for v in (err, *d)]
    return (f"| {name[:4]} | {shown} | {slack} | {approx(log['tensions'].min(), '.2f', 'N')} | "
            f"{approx(tilt, '.2f', 'deg')} | {mm[0]} | {mm[1]} / {mm[2]} / {mm[3]} | "
            f"{measured(f'{result.realtime_factor:.0f}x')} |")


def _dynamic_table(runs) -> str:
    head = ("| experiment | controller | slack ticks | min tension (N) | max tilt (deg) | "
            "FK error (mm) | closest interfering pair: true / estimated / kinematic plant (mm) "
            f"| real-time factor ({measured(f'measured {today()} on {machine()}')}) |\n"
            "| --- | --- | --- | --- | --- | --- | --- | --- |\n")
    return "\n" + head + "\n".join(_dynamic_row(runs, k) for k in DYNAMIC_ROWS) + "\n"


def _kinematic_closest(runs) -> str:
    exp2 = closest_pair_mm(runs("exp2_interaction").log)
    paper = closest_pair_mm(runs("exp2_interaction", "method: paper").log)  # the README's
    log3 = runs("exp3_two_pairs").log
    changed = int(np.sum(np.asarray(log3["filter_status"]) != 0))
    closest3 = min(closest_pair_mm(log3, (1, 3)), closest_pair_mm(log3, (5, 7)))
    return (f"keeps exp2's pair 1-3 at d_min = d_l ({approx(exp2, '.2f', 'mm')} mm), where the "
            f"paper's force alone let it reach {approx(paper, '.2f', 'mm')} mm; exp3's pairs stay "
            f"above their d_l of 57 mm (closest {approx(closest3, '.2f', 'mm')} mm), and the "
            f"filter changed the command on {approx(changed, 'd', 'ticks')} of its ticks")


# The tension damping benchmark's table (scripts/bench/tension_damping_benchmark.py).
DAMPING_CASES = ("exp2 lift 40 N", "exp2 corner 20 N", "cube_8cable push 10 N",
                 "own_7cable push 10 N")
DAMPING_LABELS = {"exp2 lift 40 N": "exp2, lift 40 N", "exp2 corner 20 N": "exp2, corner 20 N",
                  "cube_8cable push 10 N": "cube_8cable (5-7 swapped), push 10 N",
                  "own_7cable push 10 N": "own_7cable (5-7 swapped), push 10 N"}
DAMPING_COLUMNS = (("none", False), ("drive_torque", False), ("drive_torque", True),
                   ("load_cell", True))


def _damping_bench():
    sys.path.insert(0, str(REPO / "scripts" / "bench"))
    import tension_damping_benchmark as bench
    return bench


def _damping_cell(runs, case, sensor, damping) -> str:
    bench = _damping_bench()
    scenario, hand = bench.hands()[case]
    key = ("damping", case, sensor, damping)
    if key not in runs._done:
        print(f"regenerate_docs: {case}, {sensor}, damping {damping}", file=sys.stderr)
        runs._done[key] = bench.measure(
            (case, scenario, bench.overlay(hand, sensor=sensor, damping=damping), {}))
    r = runs._done[key]
    cell = approx(r["slack_holdable"], "d", "ticks")
    if r["fault"]:
        cell += f", fault at {approx(r['end'], '.3f', 's')} s"
    elif r["slack_holdable"] == 0:
        cell += f" (min {approx(r['min_tension'], '.2f', 'N')} N)"
    return cell


def _damping_row(runs, case) -> str:
    if case == "shipped":
        cells = []
        for sensor, damping in DAMPING_COLUMNS:
            if sensor == "drive_torque" and not damping:
                cells.append("-")
                continue
            cells.append(", ".join(approx(min_true_tension(runs, n, sensor), ".2f", "N")
                                   for n in EXPERIMENTS) + " N")
        return ("| exp1, exp2, exp3 (their operators, 30 s): smallest true tension | "
                + " | ".join(cells) + " |")
    return (f"| {DAMPING_LABELS[case]} | "
            + " | ".join(_damping_cell(runs, case, s, d) for s, d in DAMPING_COLUMNS) + " |")


def _damping_table(runs) -> str:
    head = ("| case (10 s) | none | drive_torque, damping off | drive_torque | load_cell |\n"
            "| --- | --- | --- | --- | --- |\n")
    return ("\n" + head + "\n".join(_damping_row(runs, c) for c in DAMPING_CASES + ("shipped",))
            + "\n")


# --- the sweeps: their pictures hold the numbers, the prose is rendered from them ------------

SWEEP_METRICS = ("min_distance", "time_below_d_l", "operator_effort", "min_distance_true",
                 "crossings_true", "slack_ticks", "min_tension", "max_rotation")


def sweep_rows(runs, name: str):
    """(columns, rows) of the shipped sweep `name`, run once on every core."""
    key = ("sweep", name)
    if key not in runs._done:
        from cdpm_drake.runs.sweep.results import columns_for
        from cdpm_drake.runs.sweep.run import run_sweep
        from cdpm_drake.runs.sweep.variants import load_sweep

        s = load_sweep(name)
        out = run_sweep(s, tempfile.mkdtemp(prefix=f"{name}-"), progress=False)
        rows = [{k: v for k, v in r.items() if not k.startswith("_")} for r in out.rows]
        runs._done[key] = (columns_for(s), rows)
    return runs._done[key]


def sweep_numbers(columns, rows) -> dict:
    """The numbers a sweep's pictures and prose show: per run its swept values and metrics."""
    from cdpm_drake.runs.sweep.results import swept_fields

    fields = swept_fields(columns)
    return {"fields": fields,
            "runs": [{"run": r["run"], "status": r["status"],
                      **{f: float(r[f]) for f in fields},
                      **{m: float(r[m]) for m in SWEEP_METRICS
                         if m in r and str(r[m]) not in ("", "nan")}} for r in rows]}


def _by(numbers, field):
    out = {}
    for r in numbers["runs"]:
        out.setdefault(r[field], []).append(r)
    return dict(sorted(out.items()))


def _span(values, fmt, unit=""):
    lo, hi = min(values), max(values)
    a, b = format(lo, fmt), format(hi, fmt)
    return (a if a == b else f"{a}-{b}") + unit


def render_sweep_kinematic(numbers) -> str:
    """exp2_du_Fu's prose numbers: the closest approach and time below d_l per F_u, the
    operator effort at the smallest and largest d_u."""
    fu = _by(numbers, "interference.default.F_u")
    du = _by(numbers, "interference.default.d_u")
    crossed = sum(1 for r in numbers["runs"] if r["min_distance"] <= 0)
    parts = [f"{_span([1000 * r['min_distance'] for r in rs], '.2f')} mm at F_u = {f:g} N"
             for f, rs in fu.items()]
    below = [f"{_span([r['time_below_d_l'] for r in rs], '.1f')} s at {f:g} N"
             for f, rs in fu.items()]
    d_lo, d_hi = min(du), max(du)
    return (f"{'no pair crosses' if crossed == 0 else f'a pair crosses in {crossed} runs'}; "
            f"the closest approach is {', '.join(parts)} (below d_l for {', '.join(below)}: "
            f"`time_below_d_l`); the operator effort is "
            f"{_span([r['operator_effort'] for r in du[d_lo]], '.0f')} N s at d_u = "
            f"{1000 * d_lo:g} mm and {_span([r['operator_effort'] for r in du[d_hi]], '.0f')} "
            f"N s at {1000 * d_hi:g} mm")


def render_sweep_dynamic(numbers) -> str:
    """exp2_dynamic_du_Fu's prose numbers: tilt, true and estimated closest approach, slack,
    crossings, and the smallest tension over the runs and at the smallest and largest F_u."""
    runs_ = numbers["runs"]
    fu = _by(numbers, "interference.default.F_u")
    f_lo, f_hi = min(fu), max(fu)
    crossed = sum(1 for r in runs_ if r.get("crossings_true", 0) > 0)
    slack = sum(r.get("slack_ticks", 0) for r in runs_)
    faults = sum(1 for r in runs_ if r["status"] != "ok")
    return (f"the platform tilts by {_span([r['max_rotation'] for r in runs_], '.2f')} degrees, "
            f"{'no pair truly crosses' if not crossed else f'a pair truly crosses in {crossed} runs'}, "
            f"{'no cable goes slack' if not slack else f'{slack:.0f} slack ticks in all'}"
            f"{'' if not faults else f', {faults} runs fault'}, and the true closest approach "
            f"is {_span([1000 * r['min_distance_true'] for r in runs_], '.1f')} mm against the "
            f"controller's estimate of {_span([1000 * r['min_distance'] for r in runs_], '.2f')} "
            f"mm. The smallest cable tension is "
            f"{_span([r['min_tension'] for r in runs_], '.1f')} N over the runs, "
            f"{_span([r['min_tension'] for r in fu[f_lo]], '.1f')} N at F_u = {f_lo:g} N and "
            f"{_span([r['min_tension'] for r in fu[f_hi]], '.1f')} N at {f_hi:g} N")


def _sweep_block(picture: str, render):
    def block(runs):
        return render(read_picture(DOCS / picture)["numbers"])
    return block


BLOCKS = [
    Block("readme_exp2_promise", "README", _methods_cell("promise")),
    Block("readme_exp2_paper", "README", _methods_cell("paper")),
    Block("dynamic_exp2_tension", "dynamic_plant", _tension_from_to),
    Block("dynamic_exp2_tension_none", "dynamic_plant", _tension_none),
    Block("benchmarks_exp2_realtime", "benchmarks", _exp2_realtime),
    Block("robots_shipped_holding", "robots", _shipped_holding),
    Block("robots_paper_share", "robots", _paper_share),
    Block("dynamic_experiments", "dynamic_plant", _dynamic_table, DYNAMIC_ROWS, _dynamic_row),
    Block("dynamic_kinematic_closest", "dynamic_plant", _kinematic_closest),
    Block("dynamic_exp2_smallest", "dynamic_plant", _exp2_smallest),
    Block("dynamic_braking_tension", "dynamic_plant", _tension_pair),
    Block("dynamic_damping_table", "dynamic_plant", _damping_table,
          DAMPING_CASES + ("shipped",), _damping_row),
    Block("sweep_exp2_numbers", "sweeps",
          _sweep_block("sweep_exp2_du_Fu_heatmap.png", render_sweep_kinematic),
          note="rendered from the picture's numbers"),
    Block("sweep_exp2_dynamic_numbers", "sweeps",
          _sweep_block("sweep_exp2_dynamic_du_Fu_heatmap.png", render_sweep_dynamic),
          note="rendered from the picture's numbers"),
]


# --- the pictures ------------------------------------------------------------------------------

def read_picture(path: Path) -> dict:
    """The metadata this script wrote into a PNG ({} for a picture it did not write)."""
    from PIL import Image

    with Image.open(path) as im:
        text = im.info.get(PNG_KEY)
    return json.loads(text) if text else {}


def save_picture(fig, path: Path, name: str, numbers: dict, dpi: int) -> None:
    meta = json.dumps({"script": SCRIPT, "name": name, "numbers": numbers}, sort_keys=True)
    fig.savefig(path, dpi=dpi, metadata={PNG_KEY: meta})


def run_figure_numbers(log, kind: str) -> dict:
    """What a run's figure shows, in the units it shows it: distances.png the closest approach
    of each pair it draws (mm: those that came within d_u, else the closest), trajectory.png the path's extent
    (mm)."""
    if kind == "distances":
        d, near = np.asarray(log["pair_distances"]), np.asarray(log["active"]).any(axis=0)
        if not near.any():  # no pair came within d_u: the figure shows the closest one
            near[int(np.argmin(d.min(axis=0)))] = True
        return {f"{int(i)}-{int(j)}": round(1000 * float(d[:, k].min()), 2)
                for k, (i, j) in enumerate(log["pairs"]) if near[k]}
    p = 1000 * np.asarray(log["p"])
    return {"lower_mm": [round(float(v), 1) for v in p.min(axis=0)],
            "upper_mm": [round(float(v), 1) for v in p.max(axis=0)],
            "duration_s": round(float(log["time"][-1]), 3)}


def workspace_numbers(resolved, path) -> dict:
    """What the workspace pictures show: per slice the share held at >= 5 N and the share
    interference-free, the extreme t* and margin (mm)."""
    from cdpm_drake.views.workspace_plots import interference_slices, slice_centre, wrench_slices

    robot = resolved.robot
    centre = slice_centre(robot, path)
    wrench = wrench_slices(robot, centre, 0.05, robot.dynamics.mass)
    inter = interference_slices(robot, centre, 0.05, resolved.interference.d_u)
    finite = [t[np.isfinite(t)] for *_, t in wrench]
    return {"held_pct": [round(100 * float(np.mean(t >= 5.0)), 1) for *_, t in wrench],
            "t_star_min_N": round(min(float(f.min()) for f in finite), 2),
            "free_pct": [round(100 * float(np.mean(s[5] >= 0)), 1) for s in inter],
            "margin_min_mm": round(1000 * min(float(s[5].min()) for s in inter), 2)}


def _run_picture(scenario: str, kind: str):
    def draw(runs, path, name):
        from cdpm_drake.views.plots import FIGURES

        log = runs(scenario).log
        save_picture(FIGURES[kind](log), path, name, run_figure_numbers(log, kind), dpi=120)
    return draw


def _workspace_picture(kind: str):
    def draw(runs, path, name):
        from cdpm_drake.config import load_resolved_scenario
        from cdpm_drake.views.workspace_plots import (figure_interference_workspace,
                                                      figure_wrench_workspace)

        resolved = load_resolved_scenario("exp2_interaction")
        robot, trail = resolved.robot, runs("exp2_interaction").log["p"]
        title = ("exp2_interaction: wrench-feasible workspace of the level platform "
                 f"({robot.dynamics.mass:g} kg at its centre, moments about the centre)"
                 if kind == "wrench" else
                 "exp2_interaction: interference-free workspace (watched pairs)")
        fig = (figure_wrench_workspace(robot, floor=5.0, path=trail, title=title)
               if kind == "wrench" else
               figure_interference_workspace(robot, d_u=resolved.interference.d_u,
                                             path=trail, title=title))
        save_picture(fig, path, name, workspace_numbers(resolved, trail), dpi=110)
    return draw


def _sweep_picture(sweep: str, metric: str):
    def draw(runs, path, name):
        from cdpm_drake.views.sweep_plots import figure_heatmap

        columns, rows = sweep_rows(runs, sweep)
        save_picture(figure_heatmap(columns, rows, metric), path, name,
                     {"sweep": sweep, "metric": metric, **sweep_numbers(columns, rows)},
                     dpi=110)
    return draw


# {file under docs/: draw(runs, path, name)}; a sweep's pictures come before its prose block.
PICTURES = {
    "exp1_distances.png": _run_picture("exp1_no_interaction", "distances"),
    "exp2_trajectory.png": _run_picture("exp2_interaction", "trajectory"),
    "workspace_wrench_exp2.png": _workspace_picture("wrench"),
    "workspace_interference_exp2.png": _workspace_picture("interference"),
    "sweep_exp2_du_Fu_heatmap.png": _sweep_picture("exp2_du_Fu", "min_distance"),
    "sweep_exp2_dynamic_du_Fu_heatmap.png": _sweep_picture("exp2_dynamic_du_Fu",
                                                           "min_distance_true"),
    "sweep_exp2_dynamic_du_Fu_min_tension.png": _sweep_picture("exp2_dynamic_du_Fu",
                                                               "min_tension"),
}


# --- the pages ---------------------------------------------------------------------------------

def page_path(page: str) -> Path:
    return REPO / "README.md" if page == "README" else DOCS / f"{page}.md"


def blocks_of(text: str) -> dict:
    """{name: text} of a page's generated blocks."""
    found = {}
    for m in BLOCK.finditer(text):
        if m.group(1) in found:
            raise ValueError(f"generated block {m.group(1)!r} appears twice")
        found[m.group(1)] = m.group(2)
    return found


def replace_block(text: str, name: str, body: str) -> str:
    marker = re.compile(rf"(<!-- generated: {re.escape(name)} -->).*?(<!-- /generated -->)", re.S)
    if not marker.search(text):
        raise ValueError(f"no generated block {name!r} in the page")
    return marker.sub(lambda m: m.group(1) + body + m.group(2), text, count=1)


def main(argv=None) -> int:
    """The script, its warnings quiet (the runs' own warnings are not news here) and loud
    again after: a test that calls it in-process must not silence the tests after it."""
    try:
        return _main(argv)
    finally:
        logging.disable(logging.NOTSET)


def _main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", action="append", metavar="NAME",
                        help="only this block or picture (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the blocks and pictures")
    parser.add_argument("--check", action="store_true",
                        help="say which blocks are stale and exit 1 if any; write nothing")
    args = parser.parse_args(argv)
    names = [b.name for b in BLOCKS] + list(PICTURES)
    if args.list:
        for b in BLOCKS:
            print(f"block   {b.name:28s} {page_path(b.page).relative_to(REPO)}")
        for p in PICTURES:
            print(f"picture {p:28s} docs/{p}")
        return 0
    unknown = sorted(set(args.only or ()) - set(names))
    if unknown:
        parser.error(f"--only: unknown {unknown}; valid: {names}")
    logging.disable(logging.WARNING)
    runs, stale = Runs(), []
    for file, draw in PICTURES.items():
        if args.only and file not in args.only:
            continue
        if not args.check:
            draw(runs, DOCS / file, file)
            print(f"wrote docs/{file}")
    for block in BLOCKS:
        if args.only and block.name not in args.only:
            continue
        path = page_path(block.page)
        text = path.read_text()
        body = written(block.render(runs))
        if args.check:
            if mismatch(block.render(runs), blocks_of(text).get(block.name, "")) is not None:
                stale.append(block.name)
            continue
        new = replace_block(text, block.name, body)
        if new != text:
            path.write_text(new)
            print(f"updated {path.relative_to(REPO)}: {block.name}")
    if stale:
        print("stale: " + ", ".join(stale))
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
