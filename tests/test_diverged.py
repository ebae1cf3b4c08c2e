"""A diverged run is a result, not a crash (results.Divergence, run_status, exit_status): its
rows, its summary, its Fig. 4, its place in run.json and report.html, exit status 3 (1 = failed);
the same in the API. Also what "settled" means in the summary, and the messages of issue 21."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from test_report import check_page

import impedance_cosim as ic
from impedance_cosim.apps import analysis
from impedance_cosim.cli import main
from impedance_cosim.cosim.results.result import Divergence, exit_status, run_status

DIVERGED = "diverged at t = 0.4825 s: controller.tau1 beyond 1e6"  # the difference under Jacobi


def test_one_definition_of_a_runs_status_and_the_exit_status():
    d = Divergence(0.4825, "controller.tau1", -1070697.5, 1e6)
    assert str(d) == f"{DIVERGED} (-1.071e6)"
    assert str(Divergence(1.0, "plant.x", float("nan"), 1e6)).endswith("plant.x not finite (nan)")
    assert [run_status(None), run_status(str(d), d), run_status("plant: doStep failed")] == [
        "ok", "diverged", "failed"]  # fmt: skip
    assert [exit_status([]), exit_status(["ok", "diverged"]), exit_status(["diverged", "failed"])
            ] == [0, 3, 1]  # fmt: skip


@pytest.mark.slow
def test_run_under_jacobi_writes_its_fig4_and_exits_diverged(ssp_path, tmp_path, capsys):
    """`run --algorithm jacobi`: the difference diverges at 0.4825 s; the command writes Fig. 4
    from the rows up to the divergence and exits 3 (not 1), with no error line."""
    out = tmp_path / "j"
    argv = ["run", "--ssp", str(ssp_path), "--algorithm", "jacobi", "--stop", "1", "--out",
            str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 3
    std = capsys.readouterr()
    assert f"difference: {DIVERGED} (-1.071e6), 194 rows -> {out / 'difference.csv'}" in std.out
    assert "error" not in std.err
    assert (out / "fig4_observer_vs_difference.png").stat().st_size > 10_000
    runs = json.loads((out / "run.json").read_text())["runs"]
    assert [(r["scenario"], r["status"], r["rows"]) for r in runs] == [
        ("observer", "ok", 401), ("difference", "diverged", 194)]  # fmt: skip
    assert runs[1]["error"].startswith(DIVERGED)
    page = check_page(out / "report.html")
    text = " ".join(page.text)
    assert f"impedance-cosim run: observer ok, difference {DIVERGED.partition(':')[0]}" in text
    assert "A run diverged (a result, exit status 3;" in text and len(page.images()) == 4


def test_a_diverged_main_run_has_its_summary_and_fig4(ssp_path, tmp_path, capsys):
    out = tmp_path / "d"
    argv = ["run", "--ssp", str(ssp_path), "--scenario", "difference", "--algorithm", "jacobi",
            "--stop", "1", "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 3
    assert f"\n{DIVERGED} (-1.071e6)\n" in capsys.readouterr().out  # the summary: one line
    summary = json.loads((out / "difference_summary.json").read_text())
    assert summary["status"] == "diverged" and summary["diverged_at_s"] == 0.4825
    assert summary["diverged_signal"] == "controller.tau1" and summary["divergence_limit"] == 1e6
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["fig4_observer_vs_difference.png"]  # Figs. 1-3 are not drawn on a divergence
    page = check_page(out / "report.html")
    assert page.row("contact force")[3] == "not measured: the run diverged"
    assert page.row("gains")[3].endswith("(as in the paper)")
    assert f"{DIVERGED} (-1.071e6): the paper's quantities are not measured" in " ".join(page.text)


@pytest.mark.slow
def test_the_default_run_draws_both_conditions_and_exits_ok(ssp_path, tmp_path, capsys):
    """The default run: the pair under sample-and-hold (both bounded) and the paper's pair under
    one sample of delay (the difference diverges) in one Fig. 4; exit 0 (the comparison's
    divergence is the figure's point, not this command's result)."""
    out = tmp_path / "default"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.6", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    assert f"difference (Fig. 4 comparison): {DIVERGED}" in capsys.readouterr().out
    runs = json.loads((out / "run.json").read_text())["runs"]
    assert [(r["scenario"], r["algorithm"], r["status"], r.get("role")) for r in runs] == [
        ("observer", "gauss-seidel", "ok", None), ("difference", "gauss-seidel", "ok", None),
        ("observer", "jacobi", "ok", "Fig. 4 comparison"),
        ("difference", "jacobi", "diverged", "Fig. 4 comparison")]  # fmt: skip
    assert (out / "difference-jacobi.csv").is_file()


@pytest.mark.slow
def test_fig4_titles_say_the_condition_and_the_range(ssp_path):
    """Each panel: its condition, the time range it shows, how the run ended."""
    gs = [ic.simulate(s, ssp=ssp_path, stop_time=0.6) for s in ("observer", "difference")]
    jac = [ic.simulate(s, ssp=ssp_path, stop_time=0.6, algorithm="jacobi")
           for s in ("observer", "difference")]  # fmt: skip
    rows = [("sample-and-hold (Gauss-Seidel)", *[r.signals for r in gs]),
            (analysis.condition_label("jacobi"), *[_Signals(r) for r in jac])]  # fmt: skip
    fig = analysis.figure_4(rows)
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == [
        "sample-and-hold (Gauss-Seidel)\n(a) observer in the loop, t = 0-0.6 s: bounded to 0.6 s",
        "sample-and-hold (Gauss-Seidel)\n(b) numerical diff. in the loop, t = 0-0.6 s: bounded to"
        " 0.6 s",
        "one-sample delay (Jacobi)\n(c) observer in the loop, t = 0-0.4825 s: bounded to 0.6 s",
        "one-sample delay (Jacobi)\n(d) numerical diff. in the loop, t = 0-0.4825 s: diverges at"
        " t = 0.4825 s",
    ]
    assert fig.axes[3].get_yscale() == "symlog" and fig.axes[2].get_yscale() == "linear"
    assert analysis.condition_label("jacobi", {"plant.euler_substeps": 1}) == (
        "one-sample delay (Jacobi), plant: one Euler step per period"
    )


class _Signals(dict):
    """A Result's signals with its divergence (what figure_4 reads of a RunResult)."""

    def __init__(self, result: ic.Result) -> None:
        super().__init__(result.signals)
        self.divergence = result.divergence


def test_the_api_says_diverged(ssp_path):
    r = ic.simulate("difference", ssp=ssp_path, stop_time=1.0, algorithm="jacobi")
    assert r.status == "diverged" and not r.ok and r.divergence.t == 0.4825
    assert r.summary["status"] == "diverged" and r.summary["diverged"].startswith(DIVERGED)
    assert repr(r) == f"<Result 'difference': {DIVERGED} (-1.071e6), 194 rows to 0.4825 s>"
    assert str(r).endswith(f"\n{DIVERGED} (-1.071e6)")
    with pytest.raises(ic.RunFailedError, match="diverged at t = 0.4825 s"):
        r.check()


def _force(t: np.ndarray, end: float, settle: float, noise: float = 0.0) -> np.ndarray:
    """A contact from 1 s to `end`: an impact decaying with time constant settle onto 19.6 N,
    with noise (N, seeded) on top."""
    f = 19.6 + 60 * np.exp(-(t - 1.0) / settle) * np.cos(30 * (t - 1.0))
    f += noise * np.random.default_rng(1).standard_normal(len(t))
    return np.where((t >= 1.0) & (t <= end), f, 0.0)


def test_settled_means_the_halves_of_the_window_agree():
    t = np.arange(0, 5.0 + 1e-9, 0.0025)
    assert analysis.settled_force(t, _force(t, 5.0, 0.1), 5.0) == pytest.approx(19.6, abs=0.01)
    noisy = analysis.settled_force(t, _force(t, 5.0, 0.1, noise=2.0), 5.0)  # noise: settled
    assert noisy == pytest.approx(19.6, abs=0.5)
    assert analysis.settled_force(t, _force(t, 1.5, 0.1), 1.5) is None  # window before contact
    assert analysis.settled_force(t, _force(t, 1.8, 0.3), 1.8) is None  # still ringing
    drift = np.where(t >= 1.0, 40.0 - 5.0 * t, 0.0)  # 40 N falling 5 N/s: not settled
    assert analysis.settled_force(t, drift, 5.0) is None


def test_not_settled_says_so_with_the_contact():
    values = {"contact_phases_s": [(3.85, 5.0)], "impact_peak_N": 88.0,
              "impact_peak_time_s": 4.1, "observer_error_max_m_s": 0.003,
              "peak_torque_N_m": [1.0, 2.0, 3.0]}  # fmt: skip
    text = analysis.format_summary(values)
    assert "settled contact force: not settled (contact 3.85-5.00 s)" in text
    text = analysis.format_summary({**values, "settled_force_N": 19.77})
    assert "settled contact force: 19.77 N (target 19.6 N)" in text


def test_run_stop_5_is_not_settled(ssp_path, tmp_path, capsys):
    """`run --stop 5`: the contact began at 3.85 s and the force still moves at 5 s."""
    argv = ["run", "--ssp", str(ssp_path), "--stop", "5", "--out", str(tmp_path / "r"),
            "--no-progress", "--no-figures", "--no-report"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "settled contact force: not settled (contact 3.85-5.00 s)" in out


def test_api_messages_say_what_an_api_user_gave(ssp_path):
    with pytest.raises(
        ic.MasterError, match=r"^unknown parameter controller\.nosuch in overrides$"
    ):
        ic.simulate(ssp=ssp_path, stop_time=0.1, overrides={"controller.nosuch": 1})
    r = ic.simulate(ssp=ssp_path, stop_time=0.1, overrides={"plant.m1": -1.0})
    assert r.error == ("plant: in initialization: fmi2GetReal failed (Fatal: PumaPlant 'plant':"
                       " parameter m1 must be >= 0.0 (got -1.0))")  # fmt: skip
    assert repr(r).endswith(", no rows>")


def test_the_errors_the_api_raises_are_importable():
    from impedance_cosim import Divergence, MasterError, SspError
    from impedance_cosim.cosim.master.setup import MasterError as Original
    from impedance_cosim.cosim.ssp.read import SspError as OriginalSsp

    assert MasterError is Original and SspError is OriginalSsp and Divergence is not None
    assert {"MasterError", "SspError"} <= set(dir(ic))


def test_swap_exits_diverged_too(ssp_path, native_dir, tmp_path):
    """`swap` runs through the same code: a diverged run is exit 3 with its summary."""
    if shutil.which("gcc") is None:
        pytest.skip("no C compiler: no native plant")
    out = tmp_path / "swap"
    argv = ["swap", "--ssp", str(ssp_path), "--replace", f"plant={native_dir / 'PumaPlant.fmu'}",
            "--scenario", "difference", "--algorithm", "jacobi", "--stop", "1", "--out", str(out),
            "--no-progress", "--no-figures"]  # fmt: skip
    assert main(argv) == 3
    summary = json.loads((out / "difference_summary.json").read_text())
    assert summary["diverged"].startswith(DIVERGED)
    assert json.loads((out / "run.json").read_text())["runs"][0]["status"] == "diverged"


def test_run_help_documents_the_exit_status(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "exit status: 0 every run ok; 3 a run diverged" in help_text
