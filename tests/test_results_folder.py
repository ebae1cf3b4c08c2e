"""A results folder keeps an earlier run's files until a later run completes (issue 35, item 2).

A command writes into `.staging-<pid>/` inside --out. When it completes (exit 0, or 3: a diverged
run is a result) its files replace the earlier ones and the earlier run's stale files go; when it
fails (exit 1) or is interrupted (130), every earlier file stays as it was, and what it computed
is kept beside them as `<name>.partial` (rows, summary, figures, run.json, report.html).
Failures are injected deterministically (a start pose out of reach, a patched Master.run)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from impedance_cosim.cli import main

UNREACHABLE = ["--set", "plant.x0=5.0"]  # fails at initialization: exit 1, 0 rows


def run(ssp: Path, out: Path, *extra: str, command: str = "run") -> int:
    return main([command, "--ssp", str(ssp), "--stop", "0.5", "--out", str(out), "--no-progress",
                 *extra])  # fmt: skip


def files(out: Path) -> dict[str, bytes]:
    """Every file in out (not in subfolders) by name, with its bytes."""
    return {p.name: p.read_bytes() for p in sorted(out.iterdir())
            if p.is_file() and not p.name.startswith(".")}  # fmt: skip


@pytest.mark.slow
def test_a_failed_run_leaves_the_earlier_files_as_they_were(native_ssp, tmp_path, capsys):
    """On main: the failed run removed 10 files of the earlier one (figures, the Fig. 4 runs,
    its summary) and wrote its own observer.csv, run.json and report.html over the earlier."""
    out = tmp_path / "res"
    assert run(native_ssp, out) == 0
    before = files(out)
    assert {"observer.csv", "fig1_position_force.png", "report.html", "run.json"} <= set(before)
    capsys.readouterr()
    assert run(native_ssp, out, *UNREACHABLE) == 1
    captured = capsys.readouterr()
    assert "removed" not in captured.err, captured.err
    after = files(out)
    assert {n: after[n] for n in before} == before  # every earlier file, byte for byte
    partial = {"observer.csv.partial", "run.json.partial", "report.html.partial"}
    assert set(after) - set(before) == partial
    assert f"0 rows kept in {out / 'observer.csv.partial'}" in captured.err
    record = json.loads((out / "run.json.partial").read_text())
    assert record["runs"][0]["status"] == "failed"
    assert record["runs"][0]["results"]["file"] == "observer.csv.partial"
    assert ".staging" not in (out / "run.json.partial").read_text()
    assert list(out.glob(".staging-*")) == []


@pytest.mark.slow
def test_a_failed_swap_leaves_the_earlier_swap_as_it_was(native_ssp, native_dir, tmp_path, capsys):
    """The issue's case: a good swap, then one that fails (there: MuJoCo not installed; here: a
    start pose out of reach) said "removed 6 file(s) of an earlier run from results/swap/"."""
    out = tmp_path / "swap"
    replace = ["--replace", f"plant={native_dir / 'PumaPlant.fmu'}"]
    assert run(native_ssp, out, *replace, command="swap") == 0
    before = files(out)
    capsys.readouterr()
    assert run(native_ssp, out, *replace, *UNREACHABLE, command="swap") == 1
    assert "removed" not in capsys.readouterr().err
    after = files(out)
    assert {n: after[n] for n in before} == before
    assert "observer.csv.partial" in after


@pytest.mark.slow
def test_a_failed_no_figures_run_keeps_the_earlier_figures(native_ssp, tmp_path):
    out = tmp_path / "res"
    assert run(native_ssp, out) == 0
    figures = {p.name: p.read_bytes() for p in out.glob("fig*.png")}
    assert len(figures) == 4
    assert run(native_ssp, out, "--no-figures", *UNREACHABLE) == 1
    assert {p.name: p.read_bytes() for p in out.glob("fig*.png")} == figures


@pytest.mark.slow
def test_an_interrupted_run_keeps_its_rows_as_partial_and_the_earlier_files(
    native_ssp, tmp_path, capsys, monkeypatch
):
    """Ctrl-C (a KeyboardInterrupt raised by a patched Master.run, no signal) as the Fig. 4 pair
    runs: exit 130; the main run's whole rows, its summary and figures 1-3 are kept as .partial,
    the earlier run's files are as they were."""
    from impedance_cosim.cosim.master.master import Master

    out = tmp_path / "res"
    assert run(native_ssp, out) == 0
    before = files(out)
    original = Master.run

    def interrupted_at_difference(self, *args, **kwargs):
        if self.parameter_set == "difference":
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Master, "run", interrupted_at_difference)
    capsys.readouterr()
    assert run(native_ssp, out) == 130
    after = files(out)
    assert {n: after[n] for n in before} == before
    assert after["observer.csv.partial"] == before["observer.csv"]  # the same run, whole
    assert {"observer_summary.json.partial", "fig1_position_force.png.partial",
            "run.json.partial", "report.html.partial"} <= set(after)  # fmt: skip
    assert "fig4_observer_vs_difference.png.partial" not in after
    assert list(out.glob(".staging-*")) == []


def test_a_diverged_run_is_a_result_and_replaces_the_earlier_one(native_ssp, tmp_path, capsys):
    """Exit 3 (a run diverged) completes the command: its files replace the earlier ones, the
    earlier run's stale files are removed (one line), and nothing is called .partial."""
    out = tmp_path / "res"
    assert run(native_ssp, out, "--no-figures") == 0
    earlier = (out / "observer.csv").read_bytes()
    capsys.readouterr()
    diverging = ["--stop", "1", "--scenario", "difference", "--algorithm", "jacobi"]
    assert run(native_ssp, out, *diverging) == 3
    err = capsys.readouterr().err
    assert "removed 1 file(s) of an earlier run" in err and "observer_summary.json" in err
    assert not list(out.glob("*.partial")) and list(out.glob(".staging-*")) == []
    assert (out / "observer.csv").read_bytes() != earlier  # the Fig. 4 pair's, under Jacobi
    record = json.loads((out / "run.json").read_text())
    assert record["runs"][0]["status"] == "diverged" and "jacobi" in record["command"]


def test_a_completed_run_removes_what_a_failed_one_kept(native_ssp, tmp_path, capsys):
    out = tmp_path / "res"
    assert run(native_ssp, out, "--no-figures", *UNREACHABLE) == 1
    assert sorted(p.name for p in out.glob("*.partial")) == [
        "observer.csv.partial",
        "report.html.partial",
        "run.json.partial",
    ]
    capsys.readouterr()
    assert run(native_ssp, out, "--no-figures") == 0
    assert "removed 3 file(s) of an earlier run" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "observer.csv",
        "observer_summary.json",
        "report.html",
        "run.json",
    ]


@pytest.mark.parametrize("status", [0, 1])
def test_no_staging_folder_is_left(native_ssp, tmp_path, status):
    out = tmp_path / "res"
    assert run(native_ssp, out, "--no-figures", *(UNREACHABLE if status else [])) == status
    assert [p.name for p in out.iterdir() if p.is_dir()] == []
