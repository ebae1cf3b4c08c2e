"""`impedance-cosim stability` keeps every finished run: SIGINT or SIGTERM (to a subprocess, sent
once the first runs of the part are on disk) stops it with one line and exit status 128 +
signal, the part's log holds the finished runs (each the run an uninterrupted study makes), a
command without --resume or with another plan is refused, and --resume gives the uninterrupted
table without running the kept runs again. The same for each part in-process (an interruption
or a failure raised by the n-th run), and the report of an interrupted or failed command."""

from __future__ import annotations

import dataclasses
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_report import check_page

from impedance_cosim.apps import fig4
from impedance_cosim.apps.stability import bisection as stability
from impedance_cosim.apps.stability import parts as stability_parts
from impedance_cosim.apps.stability.command import read_csv, write_csv
from impedance_cosim.cli import main

DOCS = Path(__file__).resolve().parent.parent / "docs"
SELECTION = ["--quantity", "rate", "--sensor", "ideal"]  # 6 bisections, 71 runs


def command(ssp: Path, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "impedance_cosim.cli", "stability", "boundaries", *SELECTION,
            "--serial", "--no-figures", "--no-progress", "--ssp", str(ssp), "--out", str(out),
            *extra]  # fmt: skip


def records(log: Path) -> list[dict]:
    """The finished runs in a part's log (complete lines after the plan)."""
    return [json.loads(line) for line in log.read_text().splitlines()[1:]]


@pytest.fixture(scope="module")
def reference(native_ssp, tmp_path_factory) -> tuple[dict, bytes]:
    """The uninterrupted study of SELECTION: every run's outcome by its log key, and the table."""
    todo = stability.cases(["rate"], ["ideal"])
    runs = {}

    def keep(case, x, row):
        runs[("run", *dataclasses.astuple(case), float(x))] = {
            "status": row["status"], "error": row.get("error") or ""}  # fmt: skip

    rows = stability.run_study(todo, native_ssp, finished_run=keep)
    table = tmp_path_factory.mktemp("reference") / "boundaries.csv"
    write_csv(table, stability.COLUMNS, rows)
    assert len(runs) == sum(r["runs"] for r in rows) > 60
    return runs, table.read_bytes()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.slow
def test_a_signal_mid_part_keeps_its_runs_and_resume_finishes_it(
    native_ssp, tmp_path, reference, signum
):
    runs, table = reference
    out = tmp_path / "o"
    log = out / "boundaries.runs.jsonl"
    proc = subprocess.Popen(command(native_ssp, out), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    end = time.monotonic() + 300  # generous: a slow, loaded machine
    while not (log.is_file() and len(log.read_text().splitlines()) > 3):
        assert proc.poll() is None and time.monotonic() < end, "no runs in the log"
        time.sleep(0.02)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=300)
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, err
    kept = records(log)
    assert 3 <= len(kept) < len(runs)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert (f"interrupted by {name}: boundaries: {len(kept)} finished runs kept in {log}; to "
            "finish, run the same command with --resume") in err  # fmt: skip
    for r in kept:  # each kept run is a run of the uninterrupted study, with its outcome
        assert runs[tuple(r["key"])] == r["data"]
    assert not (out / "boundaries.csv").exists()
    state = json.loads((out / "stability.run.json").read_text())["parts"]["boundaries"]
    assert state["status"] == "interrupted" and state["runs"] == len(kept)

    before = log.read_text()
    for extra, message in [
        ((), f"{log} holds {len(kept)} finished runs of an interrupted `stability boundaries`"),
        (("--resume", "--stop", "10"), "another study: its stop is 20.0, this command's 10.0"),
    ]:
        done = subprocess.run(command(native_ssp, out, *extra), capture_output=True, text=True)
        assert done.returncode == 2 and message in done.stderr, done.stderr
        assert done.stderr.count("\n") == 1 and log.read_text() == before

    done = subprocess.run(command(native_ssp, out, "--resume"), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert f"({len(runs)} runs, {len(kept)} kept from an earlier run)" in done.stdout
    assert (out / "boundaries.csv").read_bytes() == table  # the uninterrupted table
    assert not log.exists()


def interrupting(monkeypatch, module, name: str, at: int, error: BaseException) -> list:
    """Wrap module.name so that its call number `at` raises error; returns the list of calls."""
    calls = []
    real = getattr(module, name)

    def wrapper(*args, **kwargs):
        calls.append(args)
        if len(calls) == at:
            raise error
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, wrapper)
    return calls


def stability_main(ssp: Path, out: Path, *args: str) -> int:
    return main(["stability", *args, "--serial", "--no-progress", "--no-figures", "--ssp",
                 str(ssp), "--out", str(out)])  # fmt: skip


@pytest.mark.slow
def test_gain_interrupted_then_resumed(native_ssp, tmp_path, monkeypatch, capsys):
    out = tmp_path / "g"
    interrupting(monkeypatch, stability_parts, "run_point", 11, KeyboardInterrupt())
    assert stability_main(native_ssp, out, "gain") == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"gain: 10 finished runs kept in {out}" in err
    assert len(records(out / "gain.runs.jsonl")) == 10
    page = check_page(out / "report.html")
    text = " ".join(page.text)
    assert "impedance-cosim stability: gain, INTERRUPTED" in text
    assert "INTERRUPTED: interrupted by SIGINT; 10 finished runs kept in gain.runs.jsonl" in text
    monkeypatch.undo()
    calls = interrupting(monkeypatch, stability_parts, "run_point", 0, KeyboardInterrupt())
    assert stability_main(native_ssp, out, "gain", "--resume") == 0
    assert len(calls) == 30 - 10
    got = read_csv(out / "observer_discretization.csv")
    assert got == read_csv(DOCS / "observer_discretization.csv")


@pytest.mark.slow
def test_fig4_interrupted_then_resumed(native_ssp, tmp_path, monkeypatch):
    """The difference's run after the resume needs the observer run's kept signal."""
    out = tmp_path / "f"
    calls = interrupting(monkeypatch, fig4, "run_condition", 4, KeyboardInterrupt())
    assert stability_main(native_ssp, out, "fig4", "--condition", "euler") == 130
    assert [(c[1].name, c[2]) for c in calls] == [("baseline", "observer"),
            ("baseline", "difference"), ("euler", "observer"), ("euler", "difference")]  # fmt: skip
    assert len(records(out / "fig4.runs.jsonl")) == 3
    monkeypatch.undo()
    calls = interrupting(monkeypatch, fig4, "run_condition", 0, KeyboardInterrupt())
    assert stability_main(native_ssp, out, "fig4", "--condition", "euler", "--resume") == 0
    assert [(c[1].name, c[2]) for c in calls] == [("euler", "difference")]
    want = {(r["condition"], r["velocity"]): r for r in read_csv(DOCS / "fig4_conditions.csv")}
    got = read_csv(out / "fig4_conditions.csv")
    assert [(r["condition"], r["velocity"]) for r in got] == [
        ("baseline", "observer"), ("baseline", "difference"), ("euler", "observer"),
        ("euler", "difference")]  # fmt: skip
    for r in got:
        for k, v in want[(r["condition"], r["velocity"])].items():
            assert r[k] == (pytest.approx(v, rel=1e-9) if isinstance(v, float) else v), k


@pytest.mark.slow
def test_linear_fails_part_way_then_resumes(native_ssp, tmp_path, monkeypatch, capsys):
    """A failure (here a full disk at the 6th bisection run) keeps the runs before it; the page
    says so; --resume finishes the bisection and the linearised row."""
    out = tmp_path / "l"
    args = ["linear", "--velocity", "measured", "--timing", "gauss-seidel"]
    interrupting(monkeypatch, stability, "run_point", 6, OSError(28, "No space left on device"))
    assert stability_main(native_ssp, out, *args) == 1
    err = capsys.readouterr().err
    assert err.strip() == "impedance-cosim stability: error: [Errno 28] No space left on device"
    assert len(records(out / "linear.runs.jsonl")) == 5
    text = " ".join(check_page(out / "report.html").text)
    assert "This command was FAILED ([Errno 28] No space left on device)" in text
    assert "linear: 5 finished runs kept in" in text
    monkeypatch.undo()
    calls = interrupting(monkeypatch, stability, "run_point", 0, KeyboardInterrupt())
    assert stability_main(native_ssp, out, *args, "--resume") == 0
    (row,) = read_csv(out / "linear.csv")
    (bisection,) = [r for r in read_csv(DOCS / "boundaries.csv")
                    if (r["quantity"], r["velocity"], r["timing"], r["sensor"])
                    == ("rate", "measured", "gauss-seidel", "ideal")]  # fmt: skip
    assert len(calls) == bisection["runs"] - 5
    want = next(r for r in read_csv(DOCS / "linear.csv")
                if (r["velocity"], r["timing"]) == ("measured", "gauss-seidel"))  # fmt: skip
    assert row["simulated_Hz"] == want["simulated_Hz"]
    assert row["predicted_Hz"] == pytest.approx(want["predicted_Hz"], rel=1e-6)


def test_a_log_from_outside_is_checked_line_by_line(tmp_path):
    """Only well-formed runs of the same plan are kept; a torn or malformed line is run again;
    a log of another plan, or not a log, is refused with one line."""
    from impedance_cosim.apps.stability.log import FORMAT, PartLog

    plan = {"ssp_sha256": "ab" * 32, "stop": 20.0}
    good = ["run", "rate", "observer", "jacobi", "ideal", "euler", 243.0]
    lines = [
        json.dumps({"format": FORMAT, "part": "boundaries", "plan": plan}),
        json.dumps({"key": good, "data": {"status": "ok", "error": ""}}),
        json.dumps({"key": [*good[:-1], 250.0], "data": {"status": 1, "error": ""}}),
        json.dumps({"key": [*good[:-1], [1]], "data": {"status": "ok", "error": ""}}),
        json.dumps({"key": ["gain", "euler", 50.0, "ideal"], "data": {"status": "ok", "K": [1]}}),
        "[1, 2]",
        json.dumps({"key": [*good[:-1], 244.0], "data": {"status": "ok", "error": ""}})[:40],
    ]
    path = tmp_path / "boundaries.runs.jsonl"
    path.write_text("\n".join(lines))
    with PartLog(tmp_path, "boundaries", plan, True, stability_parts.valid_record) as log:
        assert log.kept == {tuple(good): {"status": "ok", "error": ""}}
        log.add(tuple([*good[:-1], 242.0]), {"status": "diverged", "error": "x"})
    assert records(path)[-1]["key"][-1] == 242.0 and len(records(path)) == 2  # rewritten
    other = {**plan, "stop": 10.0}
    with pytest.raises(stability.StabilityError, match="another study: its stop is 20.0"):
        PartLog(tmp_path, "boundaries", other, True, stability_parts.valid_record).__enter__()
    with pytest.raises(stability.StabilityError, match="holds 2 finished runs"):
        PartLog(tmp_path, "boundaries", plan, False, stability_parts.valid_record).__enter__()
    path.write_text("garbage\n" + lines[1])
    with pytest.raises(stability.StabilityError, match="not a stability log"):
        PartLog(tmp_path, "boundaries", plan, True, stability_parts.valid_record).__enter__()
