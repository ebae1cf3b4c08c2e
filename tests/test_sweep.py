"""Parameter sweeps: a small sweep on a 2-worker LocalCluster equals single runs of the same
parameters, failures are rows, and bad input fails before any work starts."""

from __future__ import annotations

import time

import psutil
import pytest

from impedance_cosim.apps import sweep
from impedance_cosim.cli import main
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp


@pytest.fixture(scope="module")
def native_ssp(native_dir):
    return native_dir.parent / "PaperScenario-native.ssp"  # built beside the Python one


def _children() -> set[int]:
    """Child processes, less multiprocessing's resource tracker (one per process, by design)."""
    return {p.pid for p in psutil.Process().children(recursive=True)
            if "resource_tracker" not in " ".join(p.cmdline())}  # fmt: skip


def test_dask_sweep_equals_single_runs(native_ssp, tmp_path, capsys):
    before = _children()
    out = tmp_path / "sweep"
    args = [
        "sweep",
        "--ssp",
        str(native_ssp),
        "--workers",
        "2",
        "--stop",
        "4.5",
        "--out",
        str(out),
        "--grid",
        "system.algorithm=gauss-seidel,jacobi",
        "--grid",
        "system.scenario=observer,difference",
        "--set",
        "plant.q_noise=1e-4",
        "--plot",
        "peak_torque_N_m",
        "--no-progress",
    ]
    assert main(args) == 0
    assert "4 runs" in capsys.readouterr().out
    assert _children() <= before  # the LocalCluster's worker processes are gone
    rows = sweep.read_table(out / "sweep.csv")
    assert (out / "sweep_peak_torque_N_m.png").stat().st_size > 5_000
    system = read_ssp(native_ssp)
    for row in rows:
        result = Master(
            system,
            RunOptions(
                parameter_set=row["system.scenario"],
                algorithm=row["system.algorithm"],
                stop_time=4.5,
                overrides={"plant.q_noise": 1e-4},
            ),
        ).run()
        if result.ok:
            expected = sweep.run_metrics(result)
            assert row["status"] == "ok" and row["error"] is None
            assert {m: row[m] for m in sweep.METRICS} == expected  # identical, not just close
        else:
            assert row["status"] == "diverged" and row["error"] == result.error
            assert row["t_end_s"] == result.data[-1, 0]
    status = {(r["system.algorithm"], r["system.scenario"]): r["status"] for r in rows}
    assert status == {
        ("gauss-seidel", "observer"): "ok",
        ("gauss-seidel", "difference"): "ok",
        ("jacobi", "observer"): "ok",
        ("jacobi", "difference"): "diverged",
    }
    ok = next(r for r in rows if r["status"] == "ok")
    assert 40 < ok["impact_peak_N"] < 200 and ok["contact_start_s"] == pytest.approx(3.85)


def test_serial_rows_and_failed_runs_are_rows(native_ssp):
    plan = sweep.plan_sweep(
        ["controller.velocity_source=observer,7", "system.rate=400"], ssp=native_ssp, stop=0.5
    )
    rows = sweep.run_serial(plan)
    assert [r["status"] for r in rows] == ["ok", "failed"]
    assert rows[1]["error"] and rows[0]["peak_torque_N_m"] > 0


def test_progress_is_plain_lines_off_a_terminal_and_off_with_no_progress(
    native_ssp, tmp_path, capsys, monkeypatch
):
    """stderr is not a terminal here: the progress display prints plain lines (runs done, how
    many not bounded; no delay here, 1 s by default); nothing with --no-progress."""
    from functools import partial

    from impedance_cosim.apps.sweep import execute
    from impedance_cosim.util.progress import Progress

    monkeypatch.setattr(execute, "Progress", partial(Progress, delay=0.0, every=0.0))
    args = ["sweep", "--serial", "--no-plots", "--ssp", str(native_ssp), "--stop", "0.5",
            "--grid", "controller.velocity_source=observer,7"]  # fmt: skip
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert lines[-1].startswith("sweep: 100%") and "2/2" in lines[-1], lines
    assert "1 not bounded" in lines[-1] and "\r" not in "".join(lines)
    assert main([*args, "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    assert capsys.readouterr().err == ""


def test_pseudo_parameters_map_to_the_master():
    options = {"plant_friction": [27.4, 4.54, 5.0], "stop": 2.0}
    run = sweep.run_options(
        {
            "system.rate": 200,
            "system.friction_scale": 2,
            "system.encoder_bits": 12,
            "system.algorithm": "jacobi",
            "system.scenario": "difference",
            "controller.K": 10,
        },
        options,
    )
    assert run.step_size == 0.005 and run.overrides["controller.sample_period"] == 0.005
    assert run.overrides["plant.f2"] == 9.08 and run.overrides["controller.K"] == 10
    assert run.overrides["plant.q_quant"] == pytest.approx(2 * 3.141592653589793 / 4096)
    assert run.algorithm == "jacobi" and run.parameter_set == "difference"


def test_grid_syntax():
    assert sweep.parse_axis("system.rate=100,200")[1] == [100, 200]
    assert sweep.parse_axis("plant.q_noise=log:1e-5:1e-3:3")[1] == pytest.approx([1e-5, 1e-4, 1e-3])
    assert sweep.parse_axis("controller.K=range:1:2")[1] == ("range", 1.0, 2.0)


def test_random_sample_is_seeded(native_ssp):
    kw = {"ssp": native_ssp, "random_runs": 5, "stop": 1.0}
    a = sweep.plan_sweep(["controller.K=logrange:5:500", "system.rate=100,200,400"], **kw)
    b = sweep.plan_sweep(["controller.K=logrange:5:500", "system.rate=100,200,400"], **kw)
    assert a.points == b.points and len(a.points) == 5
    assert all(5 <= p["controller.K"] <= 500 for p in a.points)


@pytest.fixture
def no_cluster(monkeypatch):
    """Fail the test if a LocalCluster or a Client would be started."""
    import distributed

    def refuse(*_a, **_k):
        raise AssertionError("a cluster was started for bad input")

    monkeypatch.setattr(distributed, "LocalCluster", refuse)
    monkeypatch.setattr(distributed, "Client", refuse)


@pytest.mark.parametrize(
    "grid, message",
    [
        (["controller.Kx=1,2"], "unknown parameter 'controller.Kx'; did you mean controller.K"),
        (["plant.noise_sd=0,1e-4"], "did you mean"),
        (["plant.x=0.3"], "plant.x is an output, not a parameter"),
        (["controller.K="], "empty grid for controller.K"),
        (["controller.K=lin:1:2:0"], "needs a count 1..100000"),
        ([], "nothing to sweep"),
        (["system.rate=333"], "not a whole number of"),
        (["system.rate=0"], "system.rate must be a positive number"),
        (["system.scenario=observer,nope"], "system.scenario must be one of"),
        (["plant.q_noise=abc"], "'abc' is not a valid Real"),
        (["controller.K=1", "controller.K=2"], "swept twice"),
        (["controller.K=range:1:2"], "is for --random sweeps"),
    ],
)
def test_bad_input_fails_before_any_work(native_ssp, tmp_path, capsys, no_cluster, grid, message):
    args = ["sweep", "--ssp", str(native_ssp), "--stop", "1.5", "--out", str(tmp_path / "o")]
    assert main([*args, *(a for g in grid for a in ("--grid", g))]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_unreachable_scheduler_fails_fast(native_ssp, tmp_path, capsys, no_cluster):
    started = time.perf_counter()
    code = main(
        [
            "sweep",
            "--ssp",
            str(native_ssp),
            "--grid",
            "controller.K=10,50",
            "--scheduler",
            "tcp://127.0.0.1:1",
            "--connect-timeout",
            "1",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    assert code == 2 and time.perf_counter() - started < 60  # a hang, not a speed: generous
    err = capsys.readouterr().err
    assert "cannot reach the dask scheduler at tcp://127.0.0.1:1" in err
    assert not (tmp_path / "o").exists()
    with pytest.raises(sweep.SweepError, match="cannot reach"):
        sweep.check_scheduler("tcp://127.0.0.1:1", timeout=0.5)


def test_each_table_records_how_it_was_made(native_ssp, tmp_path):
    """<table>.run.json beside the table: the command, versions, times, the table's plan (the
    archive's sha256 among it) and its rows by status."""
    import json

    from impedance_cosim.cosim.results.provenance import file_sha256

    out = tmp_path / "s"
    args = ["sweep", "--serial", "--no-plots", "--no-report", "--no-progress", "--ssp",
            str(native_ssp), "--stop", "0.5", "--out", str(out),
            "--grid", "controller.velocity_source=observer,7"]  # fmt: skip
    assert main(args) == 0
    record = json.loads((out / "sweep.run.json").read_text())
    assert record["command"] == ["impedance-cosim", *args]
    assert record["table"] == "sweep.csv" and record["rows"] == {"ok": 1, "failed": 1}
    assert record["plan"] == json.loads((out / "sweep.plan.json").read_text())
    assert record["plan"]["ssp_sha256"] == file_sha256(native_ssp)
    assert record["versions"]["dask"] and record["wall_time_s"] > 0


@pytest.mark.parametrize("where", ["during a run", "between runs"])
def test_an_interrupted_api_sweep_keeps_its_finished_results(native_ssp, monkeypatch, where):
    """Ctrl-C in the third of four runs: RunInterrupted carries the two finished Results (on
    main only the interrupted run's) and the third's rows so far; Ctrl-C while the third is set
    up (outside the master's run): it runs whole, the sweep stops before the fourth."""
    import signal

    import impedance_cosim as ic
    from impedance_cosim.util.interrupt import RunInterrupted

    calls = {"n": 0}
    original = Master._run if where == "during a run" else Master.__init__

    def third_gets_sigint(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == (3 if where == "during a run" else 4 + 3):  # 4 checks, then the runs
            signal.raise_signal(signal.SIGINT)  # recorded; taken at the next check
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Master, "_run" if where == "during a run" else "__init__",
                        third_gets_sigint)  # fmt: skip
    with pytest.raises(RunInterrupted) as caught:
        ic.sweep("controller.K", [10, 20, 30, 40], ssp=native_ssp, stop_time=1.0)
    exc = caught.value
    finished = (10, 20) if where == "during a run" else (10, 20, 30)
    assert [r.ok for r in exc.results] == [True] * len(finished)
    assert [r.provenance["call"] for r in exc.results] == [
        f"simulate('observer', ssp={str(native_ssp)!r}, stop_time=1.0, "
        f"overrides={{'controller.K': {k}}})" for k in finished
    ]  # fmt: skip
    assert f"{len(finished)} of 4 runs finished" in str(exc)
    if where == "during a run":
        assert exc.result is not None and 0 < len(exc.result.data) < 401
    else:
        assert exc.result is None


@pytest.mark.slow
def test_study_no_plots_draws_no_map_and_keeps_the_table(native_ssp, tmp_path):
    """sweep --study --no-plots (issue 24): no PNG (the maps were drawn after the runs, a serial
    tail), and the same table as the study with its maps, run for run (less wall_s)."""
    import csv

    def study(out, *extra: str) -> list[dict]:
        argv = ["sweep", "--study", "delay", "--serial", "--ssp", str(native_ssp), "--stop",
                "0.2", "--no-report", "--no-progress", "--out", str(out), *extra]  # fmt: skip
        assert main(argv) == 0
        with (out / "map_delay.csv").open(newline="") as f:
            return [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)]

    bare = study(tmp_path / "bare", "--no-plots")
    assert not list((tmp_path / "bare").glob("*.png"))
    drawn = study(tmp_path / "drawn")
    assert [p.name for p in (tmp_path / "drawn").glob("*.png")] == ["map_delay.png"]
    assert bare == drawn and len(bare) == len(sweep.STUDY["delay"].grid["system.rate"]) * 6


def test_the_metrics_jacobians_are_the_arms_own():
    """analysis.jacobians (the sweep metrics' vectorized J(q), filled in place) equals the arm's
    J(q) of physics.arm row by row, to the last bits libm and numpy's sin/cos may differ by."""
    import numpy as np

    from impedance_cosim.apps import analysis
    from impedance_cosim.physics.arm import Arm, ArmParams

    q = np.random.default_rng(1).uniform(-3.0, 3.0, size=(50, 3))
    got = analysis.jacobians(ArmParams(), q)
    arm = Arm(ArmParams())
    want = np.array([arm.jacobian(tuple(row)) for row in q])
    assert got.shape == (50, 3, 3)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
