"""cdpm sweep --ray on a local Ray (2 CPUs, no dashboard): the same rows as local processes,
and a Ray worker that dies is that run's error row."""

import functools

import pytest

import sweep_hooks
from cdpm_drake.runs import sweep as sw

ray = pytest.importorskip("ray")

SWEEP = """\
name: small_ray
base: exp2_interaction
overlay: {duration: 0.1}
axes:
  - {field: interference.default.F_u, values: [2.0, 3.0, 4.0]}
  - {field: admittance.damping, values: [5.0, 7.0]}
"""


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    # The hooks live in tests/, which Ray's workers cannot import: send them by value.
    ray.cloudpickle.register_pickle_by_value(sweep_hooks)
    yield
    ray.cloudpickle.unregister_pickle_by_value(sweep_hooks)
    ray.shutdown()


def _timeless(rows):
    return [{k: v for k, v in r.items() if k not in ("wall_s", "rtf")} for r in rows]


def test_ray_rows_equal_local_rows(tmp_path, local_ray):
    path = tmp_path / "sweep.yaml"
    path.write_text(SWEEP)
    s = sw.load_sweep(path)
    # Chunks of 4: one task of 4 runs and one of 2, so grouping is exercised.
    on_ray = sw.run_sweep(s, tmp_path / "ray", ray=True, ray_chunk=4, progress=False)
    assert on_ray.runner.startswith("Ray (a local Ray, 2 CPUs, 2 tasks)")
    local = sw.run_sweep(s, tmp_path / "local", workers=2, progress=False)
    assert [r["status"] for r in on_ray.rows] == ["ok"] * 6
    assert _timeless(on_ray.rows) == _timeless(local.rows)
    # Ray resumes like the local runner.
    assert sw.run_sweep(s, tmp_path / "ray", ray=True, progress=False).ran == 0


def test_ray_worker_death_is_that_runs_error(tmp_path, local_ray):
    path = tmp_path / "sweep.yaml"
    path.write_text(SWEEP)
    kill = functools.partial(sweep_hooks.kill_worker_if, "interference.default.F_u", 3.0)
    outcome = sw.run_sweep(sw.load_sweep(path), tmp_path / "out", ray=True, ray_chunk=3,
                           progress=False, before_run=kill)
    # The crashed chunks are split into one run per task, so only F_u = 3 runs are errors.
    for r in outcome.rows:
        if r["interference.default.F_u"] == "3.0":
            assert r["status"] == "error" and "Ray worker died" in r["error"], r
        else:
            assert r["status"] == "ok", r
    assert len(outcome.rows) == 6
