"""Batched sweeps: FMU instances reused through fmi2Reset give the same results bit for bit as
new instances (native and Python FMUs, parameters, scenarios and noise seeds changing from run to
run, a diverging run in between); a batched dask sweep gives the same rows as single runs in
series; batch sizes follow the measured cost and cover every point once."""

from __future__ import annotations

import numpy as np
import pytest

from impedance_cosim.apps import sweep
from impedance_cosim.apps.sweep import execute as sweep_batch
from impedance_cosim.cosim.fmus.pool import InstancePool
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

RUNS = [  # one after another on the same instances: each must equal a run on new instances
    {"overrides": {"plant.q_noise": 1e-4, "plant.noise_seed": 3}},
    {"overrides": {"controller.K": 20, "plant.m3": 2.0}},
    {"parameter_set": "difference", "algorithm": "jacobi"},  # diverges
    {"parameter_set": "difference"},
    {"overrides": {"plant.q_noise": 1e-4, "plant.noise_seed": 3}},
]


@pytest.mark.parametrize("flavour", ["python", "native"])
def test_reused_instances_give_identical_results(flavour, ssp_path, native_dir):
    ssp = ssp_path if flavour == "python" else native_dir.parent / "PaperScenario-native.ssp"
    system = read_ssp(ssp)
    pool = InstancePool()
    for kwargs in RUNS:
        fresh = Master(system, RunOptions(stop_time=1.5, **kwargs)).run()
        reused = Master(system, RunOptions(stop_time=1.5, **kwargs), instances=pool).run()
        assert reused.names == fresh.names and reused.error == fresh.error
        assert reused.data.shape == fresh.data.shape and len(fresh.data) > 100
        assert np.array_equal(reused.data, fresh.data)  # bit for bit
    assert any(r.get("algorithm") == "jacobi" for r in RUNS)
    # every run after the first on reused instances, also the one after the diverged run (its
    # FMUs returned no error: reset and reused): 2 components x (5 runs - 1)
    assert pool.reused == 2 * 4
    pool.clear()


def test_batched_dask_sweep_equals_single_runs(native_dir):
    ssp = native_dir.parent / "PaperScenario-native.ssp"
    plan = sweep.plan_sweep(
        ["controller.K=10,50", "system.rate=200,400,800", "system.algorithm=gauss-seidel,jacobi"],
        ssp=ssp,
        stop=2.0,
    )
    serial = sweep.run_serial(plan, fresh=True)  # new instances per run: the reference
    recorded: dict[int, dict] = {}
    with sweep.dask_client(workers=2) as client:
        rows = sweep_batch.run_dask(plan, client, record=recorded.__setitem__, target_s=0.05)
    assert sorted(recorded) == list(range(12))
    assert any(r["status"] != "ok" for r in serial) and any(r["status"] == "ok" for r in serial)
    strip = [{k: v for k, v in r.items() if k != "wall_s"} for r in serial]
    assert [{k: v for k, v in r.items() if k != "wall_s"} for r in rows] == strip
    pooled = sweep.run_serial(plan)  # --serial: instances reused in this process, as on dask
    assert [{k: v for k, v in r.items() if k != "wall_s"} for r in pooled] == strip


def test_plans_as_one_stream_equal_their_single_runs(native_dir, tmp_path):
    """The study's maps on a cluster as one stream of batches: each plan's table gets exactly
    its own rows, equal to its runs in series (and a resumed table's rows are not run again)."""
    from impedance_cosim.apps.sweep.table import open_table

    ssp = native_dir.parent / "PaperScenario-native.ssp"
    plans = {
        "a": sweep.plan_sweep(["controller.K=10,50", "system.rate=200,400"], ssp=ssp, stop=1.0),
        "b": sweep.plan_sweep(["plant.m3=0.5,2,4"], ssp=ssp, stop=1.0),
    }
    with open_table(tmp_path / "a.csv", plans["a"]) as table:  # two of a's runs done before
        for i in (0, 3):
            table.add(i, sweep.run_serial(plans["a"], indices=[i])[0])
    with (
        open_table(tmp_path / "a.csv", plans["a"], resume=True) as a,
        open_table(tmp_path / "b.csv", plans["b"]) as b,
        sweep.dask_client(workers=2) as client,
    ):
        assert a.done == {0, 3}
        calls = []
        rows = sweep_batch.run_plans(plans, {"a": a, "b": b}, client, lambda n, r: calls.append(r))
    assert len(calls) == 2 + 3  # only the runs not in the tables
    for name, plan in plans.items():  # the reference: the same plan in series into a table
        with open_table(tmp_path / f"serial_{name}.csv", plan) as table:
            serial = sweep_batch.run_plan(plan, table, None, None)
        assert len(serial) == len(rows[name]) == len(plan.points)
        for want, got in zip(serial, rows[name], strict=True):
            assert {**want, "wall_s": None} == {**got, "wall_s": None}, name


def test_batches_follow_the_measured_cost():
    costs = {i: (800.0 if i % 2 else 8000.0) for i in range(100)}  # two run lengths
    batcher = sweep_batch.Batcher(costs, workers=2, target_s=0.3)
    first = batcher.next()
    assert first == [0]  # nothing timed yet
    batcher.measured(0, 0.04)  # 8000 steps in 40 ms: 5 us per step
    batches = [first]
    while batch := batcher.next():
        batches.append(batch)
        seconds = sum(costs[i] for i in batch) * 5e-6
        assert len(batch) == 1 or seconds <= 0.3 + 1e-9
    assert sorted(i for b in batches for i in b) == list(range(100))  # each point once, in order
    assert max(len(b) for b in batches) >= 8  # several runs per task
    assert len(batches[-1]) <= 2  # the tail shrinks so that no worker waits for a long batch
