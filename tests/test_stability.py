"""The stability study: bisection logic, the linearised loop (on cases with known answers and
against the simulated loop), the Fig. 4 measurements, and the study commands reproducing the
committed tables (docs/boundaries.csv, linear.csv, fig4_conditions.csv,
observer_discretization.csv) on a reduced selection."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from impedance_cosim.apps import fig4, linearize
from impedance_cosim.apps.stability import bisection as stability
from impedance_cosim.apps.stability.command import read_csv
from impedance_cosim.cosim.master.plain_loop import loop_step
from impedance_cosim.physics.ode import integrate

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"


# --- bisection ----------------------------------------------------------------------------------


def fake_study(todo, stable):
    """bisect_all with a runner that calls stable(case, x) instead of a simulation."""
    queue = []

    def submit(case, x):
        queue.append((case, x))

    def wait():
        case, x = queue.pop(0)
        return case, x, {"status": "ok" if stable(case, x) else "diverged", "error": "boom"}

    return [b.row() for b in stability.bisect_all(todo, submit, wait)]


def test_bisection_finds_rate_to_1_hz_and_gain_to_1_percent():
    rate = stability.Case("rate", "observer", "jacobi", "ideal")
    gain = stability.Case("K", "observer", "gauss-seidel", "ideal", "implicit")
    rows = fake_study([rate, gain], lambda c, x: x >= 243.0 if c.quantity == "rate" else x < 364.0)
    assert (rows[0]["critical"], rows[0]["unstable_at"]) == (243.0, 242.0)
    assert rows[0]["note"] == "boom" and rows[0]["runs"] <= 12
    assert rows[1]["critical"] < 364.0 <= rows[1]["unstable_at"] <= 1.01 * rows[1]["critical"]


def test_bisection_without_boundary_says_which_side():
    case = stability.Case("wall_k", "measured", "gauss-seidel", "ideal")
    (row,) = fake_study([case], lambda c, x: True)
    assert row["critical"] is None and row["runs"] == 2
    assert row["note"].startswith("stable over the whole bracket")
    (row,) = fake_study([case], lambda c, x: False)
    assert row["note"].startswith("unstable over the whole bracket")


def test_bisection_progress_counts_runs_and_finished_bisections():
    """progress(runs, bisections finished) after every run; no bisection over max_runs."""
    todo = [stability.Case(q, "observer", "jacobi", "ideal") for q in ("rate", "wall_k")]
    queue, calls = [], []

    def wait():
        case, x = queue.pop(0)
        stable = x >= 243.0 if case.quantity == "rate" else x < 2e6
        return case, x, {"status": "ok" if stable else "diverged"}

    done = stability.bisect_all(todo, lambda c, x: queue.append((c, x)), wait,
                                lambda runs, finished: calls.append((runs, finished)))  # fmt: skip
    total = sum(len(b.runs) for b in done)
    assert [r for r, _ in calls] == list(range(1, total + 1))
    assert calls[-2][1] == 1 and calls[-1][1] == 2  # the first finished one run before the end
    assert all(f == 0 for _, f in calls[: min(len(b.runs) for b in done) - 1])
    assert all(2 < len(b.runs) <= stability.max_runs(b.case.quantity) for b in done)


def test_case_points_and_selection():
    assert len(stability.cases(["K"], ["12-bit"], ["observer"], ["jacobi"])) == 3
    with pytest.raises(stability.StabilityError, match="nothing to run"):
        stability.cases(["K"], ["ideal"], ["difference"])
    with pytest.raises(stability.StabilityError, match="unknown sensor 'x'"):
        stability.cases(["rate"], ["x"])
    p = stability.Case("K", "observer", "jacobi", "10-bit", "exponential").point(500.0)
    assert p["controller.K2"] == 500.0 and p["system.encoder_bits"] == 10
    assert p["controller.observer_discretization"] == "exponential" and p["system.rate"] == 400.0
    assert stability.Case("rate", "measured", "jacobi", "ideal").point(321.0)["system.rate"] == 321


# --- the linearisation on cases with known answers -------------------------------------------


def damper_map(b_over_m: float, rate: float, delayed: bool):
    """A mass under sampled velocity damping, m v' = -b v(t_k) (or v(t_k-1) one sample late),
    integrated over the sample by the plant's own integrator: state (v, v_prev)."""
    h = 1.0 / rate

    def step(x):
        v, v_prev = x
        u = -b_over_m * (v_prev if delayed else v)
        _, y, _, _ = integrate(lambda y: (u,), 0.0, (v,), h, 1e-3, 1e-12, 1e-14)
        return np.array([y[0], v])

    return step


@pytest.mark.parametrize(("delayed", "factor"), [(False, 0.5), (True, 1.0)])
def test_critical_rate_of_sampled_damper(delayed, factor):
    """Sample-and-hold: lambda = 1 - b h / m, unstable below b / 2m Hz; one sample late:
    z^2 - z + b h / m = 0, unstable below b / m Hz."""
    b_over_m = 300.0

    def radius(rate):
        return linearize.spectral_radius(
            linearize.jacobian(damper_map(b_over_m, rate, delayed), np.array([0.3, 0.2]))
        )

    h = 1 / 400
    lam = np.sort(np.abs(np.roots([1, -1, b_over_m * h]) if delayed else [1 - b_over_m * h, 0]))
    assert radius(400.0) == pytest.approx(lam[-1], rel=1e-8)
    assert linearize.critical_rate(radius, 50.0, 1000.0, 0.01) == pytest.approx(
        factor * b_over_m, abs=0.02
    )


def test_dominant_mode_of_a_rotation():
    r, a = 0.97, 2 * math.pi / 7.5
    m = r * np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    rho, period = linearize.dominant(m)
    assert rho == pytest.approx(r) and period == pytest.approx(7.5)
    assert linearize.dominant(np.diag([-1.2, 0.5])) == (pytest.approx(1.2), pytest.approx(2.0))


# --- the linearisation of the loop ------------------------------------------------------------


@pytest.fixture(scope="module")
def reference():
    return linearize.reference_run({}, {})


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_loop_map_state_is_complete(reference, algorithm):
    """The 18 numbers are the loop's whole state: two steps through load() equal two steps of
    the models left alone (to integrator tolerance)."""
    m = linearize.operating_point(5.5, 400.0, algorithm, {}, {"velocity_source": "difference"},
                                  reference)  # fmt: skip
    x0 = m.state()
    twice = m(x0)
    m.k += 1
    twice = m(twice)
    m.k -= 1
    m.load(x0)
    p, c = m.plant, m.controller
    out = p.outputs()
    for i in range(2):
        out = loop_step(p, c, c.start_time + (m.k + i) * m.h, m.h, algorithm, out)
    assert np.allclose(twice, m.state(), rtol=1e-9, atol=1e-9)


def test_linear_prediction_brackets_the_simulated_boundary(reference, native_ssp):
    """Sample-and-hold, true velocity: the linearised contact point predicts the critical rate,
    and the native co-simulation diverges 4 % below it and stays bounded 4 % above it."""
    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.ssp.read import read_ssp

    pred = linearize.critical_rate(
        lambda r: linearize.loop_radius(r, "gauss-seidel", "measured", reference=reference)[0],
        150.0, 400.0, 0.5)  # fmt: skip
    assert 180.0 < pred < 230.0
    system = read_ssp(native_ssp)
    outcome = {}
    for rate in (round(0.96 * pred), round(1.04 * pred)):
        r = Master(
            system,
            RunOptions(
                parameter_set="measured",
                step_size=1 / rate,
                stop_time=20.0,
                overrides={"controller.sample_period": 1 / rate},
            ),
        ).run()
        outcome[rate] = r.ok
    assert list(outcome.values()) == [False, True], outcome


# --- Fig. 4 measurements ----------------------------------------------------------------------


def test_oscillation_measures_a_known_growing_mode():
    n = np.arange(400)
    t = n / 400
    dev = 1e-4 * 1.03**n * np.sin(2 * np.pi * n / 5.8 + 0.3)
    got = fig4.oscillation(t, dev)
    assert got["period_samples"] == pytest.approx(5.8, rel=0.03)
    assert got["growth_per_sample"] == pytest.approx(1.03, abs=0.002)
    assert got["onset_s"] == pytest.approx(t[np.argmax(np.abs(dev) > 1e-3)], abs=0.02)
    assert fig4.oscillation(t, 1e-4 * np.sin(n))["onset_s"] is None


# --- the study commands reproduce the committed tables ------------------------------------------


def cli(*args: str, tmp_path: Path, ssp: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "impedance_cosim.cli", "stability", *args,
                           "--serial", "--no-figures", "--ssp", str(ssp), "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr


def matching(rows, ref_rows, keys):
    ref = {tuple(r[k] for k in keys): r for r in ref_rows}
    return [(r, ref[tuple(r[k] for k in keys)]) for r in rows]


@pytest.mark.slow
def test_study_reproduces_committed_tables(tmp_path, native_ssp):
    cli("boundaries", "linear", "fig4", "--quantity", "rate", "--quantity", "K", "--sensor",
        "ideal", "--velocity", "measured", "--velocity", "observer", "--timing", "gauss-seidel",
        "--condition", "euler", tmp_path=tmp_path, ssp=native_ssp)  # fmt: skip
    keys = ("quantity", "velocity", "timing", "sensor", "discretization")
    pairs = matching(read_csv(tmp_path / "boundaries.csv"), read_csv(DOCS / "boundaries.csv"), keys)
    assert len(pairs) == 5
    for got, want in pairs:
        assert (got["critical"], got["unstable_at"]) == (want["critical"], want["unstable_at"])
    pairs = matching(read_csv(tmp_path / "linear.csv"), read_csv(DOCS / "linear.csv"),
                     ("velocity", "timing"))  # fmt: skip
    assert len(pairs) == 2
    for got, want in pairs:
        assert got["predicted_Hz"] == pytest.approx(want["predicted_Hz"], rel=1e-6)
        assert got["simulated_Hz"] == want["simulated_Hz"]
        assert abs(got["difference_percent"]) < 5.0
    pairs = matching(read_csv(tmp_path / "fig4_conditions.csv"),
                     read_csv(DOCS / "fig4_conditions.csv"), ("condition", "velocity"))  # fmt: skip
    assert len(pairs) == 4  # baseline and euler, both sources
    for got, want in pairs:
        assert got.keys() == want.keys()
        for k, v in want.items():
            assert got[k] == (pytest.approx(v, rel=1e-9) if isinstance(v, float) else v), k


@pytest.mark.slow
def test_gain_table_reproduces(tmp_path, native_ssp):
    cli("gain", tmp_path=tmp_path, ssp=native_ssp)
    got = read_csv(tmp_path / "observer_discretization.csv")
    assert got == read_csv(DOCS / "observer_discretization.csv")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nonsense"], "unknown part 'nonsense'"),
        (["fig4", "--condition", "moon"], "unknown condition 'moon'"),
        (["gain", "--stop", "-1"], "--stop must be a whole number of seconds >= 1"),
        (["boundaries", "--stop", "2.5"], "--stop must be a whole number of seconds >= 1"),
        (["boundaries", "--ssp", "/nonexistent.ssp"], "no system archive"),
    ],
)
def test_bad_requests_are_one_line(tmp_path, args, message):
    done = subprocess.run([sys.executable, "-m", "impedance_cosim.cli", "stability", *args,
                           "--out", str(tmp_path)], capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


# --- the observer discretizations -------------------------------------------------------------


@pytest.mark.parametrize(
    ("form", "pole"),
    [
        ("euler", lambda kh: 1.0 - kh),
        ("implicit", lambda kh: 1.0 / (1.0 + kh)),
        ("exponential", lambda kh: math.exp(-kh)),
    ],
)
@pytest.mark.parametrize("kh", [0.125, 0.9, 5.0])
def test_observer_pole_of_each_discretization(form, pole, kh):
    """Arm at rest, no gravity, friction, torque or force, angles unchanged: the observer's own
    dynamics are yhat_i = pole(K h) yhat_i-1 (quadratic Coriolis terms vanish for a tiny yhat)."""
    from controller_model.observer import observer_update
    from impedance_cosim.physics.arm import Arm, ArmParams

    arm = Arm(ArmParams(g=0.0, f1=0.0, f2=0.0, f3=0.0))
    q = (0.3, -1.2, 0.9)
    dt = 1 / 400
    k = kh / dt
    yhat = (1e-9, -2e-9, 3e-9)
    z = (0.0, 0.0, 0.0)
    got = observer_update(arm, yhat, q, q, z, z, (k, k, k), dt, form)
    for y0, y1 in zip(yhat, got):
        assert y1 / y0 == pytest.approx(pole(kh), rel=1e-6)


def test_a_parameter_the_system_lacks_is_an_error_before_any_run(monkeypatch, native_ssp):
    """Not a bracket of "unstable" runs: the study refuses to start."""
    from impedance_cosim.cosim.master.master import MasterError

    case = stability.Case("rate", "observer", "gauss-seidel", "ideal")
    monkeypatch.setitem(stability.SENSORS, "ideal", {"plant.no_such_thing": 1.0})
    with pytest.raises(MasterError, match="unknown parameter plant.no_such_thing"):
        stability.run_study([case], native_ssp)


def test_boundaries_figure_and_report_page_from_the_committed_table(tmp_path):
    """The study's figure and page from docs/boundaries.csv, without running the study (the
    study's own tests are slow): a PNG, and a page that names the part and shows its table."""
    from impedance_cosim.apps.stability.figures import boundaries_figure
    from impedance_cosim.apps.stability.report import stability_report

    rows = read_csv(Path(__file__).parents[1] / "docs" / "boundaries.csv")
    boundaries_figure(rows, tmp_path / "boundaries.png")
    assert (tmp_path / "boundaries.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (tmp_path / "boundaries.csv").write_bytes(
        (Path(__file__).parents[1] / "docs" / "boundaries.csv").read_bytes()
    )
    part = {"status": "finished", "table": "boundaries.csv", "figures": ["boundaries.png"]}
    data = {"this_command": ["boundaries"], "parts": {"boundaries": part}}
    page = stability_report(tmp_path, data, None, "")
    assert "All parts finished: boundaries." in page
    assert "boundaries.png" in page and "gauss-seidel" in page  # the figure and the table
