"""The SSP system and the master: equality with the plain-model loop, Jacobi's delay, parameter
bindings, initialization, time stamps, divergence, bad input; and the paper's story on the run."""

from __future__ import annotations

import io
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from controller_model.model import ControllerModel
from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.plain_loop import run_models
from impedance_cosim.cosim.ssp.read import SspError, read_ssp
from impedance_cosim.cosim.system.paper import source_files

DT = 1 / 400


def modified(ssp: Path, tmp_path: Path, edits: dict, drop: tuple = ()) -> Path:
    """A copy of an archive with some members rewritten (bytes or function of bytes) or dropped."""
    out = tmp_path / "edited.ssp"
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(out, "w") as zout:
        for name in zin.namelist():
            if name in drop:
                continue
            data = zin.read(name)
            edit = edits.get(name)
            zout.writestr(name, edit(data) if callable(edit) else (edit or data))
    return out


@pytest.fixture(scope="module")
def paper_run(ssp_path):
    result = Master(read_ssp(ssp_path)).run()
    assert result.ok, result.error
    return result


def test_ssp_sources_are_generated_from_the_system_definition():
    """ssp/*.ssd/ssv are the committed output of impedance_cosim.cosim.system.paper (regenerate with
    `python -m impedance_cosim.cosim.system.paper`)."""
    folder = Path(__file__).resolve().parent.parent / "ssp"
    for name, content in source_files().items():
        assert (folder / name).read_bytes() == content, name


def test_gauss_seidel_equals_the_plain_model_loop(paper_run):
    ref = run_models(stop_time=20.0)
    assert set(ref) <= set(paper_run.names)
    for name, values in ref.items():
        assert np.allclose(paper_run[name], values, rtol=0, atol=1e-9), name


def test_jacobi_is_the_same_loop_with_one_step_of_delay(ssp_path):
    jacobi = Master(read_ssp(ssp_path), RunOptions(algorithm="jacobi", stop_time=2.0)).run()
    ref = run_models(stop_time=2.0, algorithm="jacobi")
    for name, values in ref.items():
        assert np.allclose(jacobi[name], values, rtol=0, atol=1e-9), name
    gs = run_models(stop_time=2.0)
    assert np.abs(jacobi["plant.x"] - gs["plant.x"]).max() > 1e-6  # the delay matters


def test_times_are_exact_multiples_of_the_step(paper_run):
    n = len(paper_run["time"]) - 1
    assert n == 8000
    assert np.array_equal(paper_run["time"], np.arange(n + 1) * DT)


def test_initial_values_are_exchanged(paper_run):
    """The controller's first sample uses the plant's initial angles: no torque kick at t = 0."""
    plant0 = {n: paper_run[f"plant.{n}"][0] for n in ("q1", "q2", "q3", "fx", "fy", "n")}
    inputs = (*plant0.values(), 0.0, 0.0, 0.0)
    expected = ControllerModel({}, 0.0, inputs).outputs()[:3]
    taus = [paper_run[f"controller.tau{i}"] for i in (1, 2, 3)]
    assert tuple(t[0] for t in taus) == pytest.approx(expected, abs=1e-12)
    assert all(t[1] == t[0] for t in taus)  # sample 0 held over the first step
    assert abs(paper_run["controller.e_x"][0]) < 1e-12  # the arm starts on the trajectory


def test_parameter_sets_are_applied(ssp_path):
    """The 'measured' set feeds the true velocity; the 'difference' set the backward difference."""
    system = read_ssp(ssp_path)
    measured = Master(system, RunOptions(parameter_set="measured", stop_time=0.5)).run()
    for i in (1, 2, 3):  # the sample taken at t_i is recorded at t_i+1
        assert np.array_equal(measured[f"controller.qd_hat{i}"][2:], measured[f"plant.qd{i}"][1:-1])
    diff = Master(system, RunOptions(parameter_set="difference", stop_time=0.5)).run()
    assert np.array_equal(diff["controller.qd_hat1"][2:], diff["controller.qd_diff1"][2:])


def test_parameter_bindings_change_the_run(ssp_path, tmp_path):
    """Edit the observer gain in the archive's observer set: the observer output changes."""

    def lower_gain(data: bytes) -> bytes:
        text = data.decode()
        start = text.index('name="K1"')
        return (text[:start] + text[start:].replace('value="50.0"', 'value="5.0"', 1)).encode()

    edited = modified(ssp_path, tmp_path, {"resources/observer_controller.ssv": lower_gain})
    base = Master(read_ssp(ssp_path), RunOptions(stop_time=0.5)).run()
    changed = Master(read_ssp(edited), RunOptions(stop_time=0.5)).run()
    assert np.abs(changed["controller.qd_obs1"] - base["controller.qd_obs1"]).max() > 1e-4
    assert np.array_equal(changed["controller.qd_obs2"][:1], base["controller.qd_obs2"][:1])


def test_overrides_and_vector_shorthand(ssp_path):
    master = Master(
        read_ssp(ssp_path), RunOptions(overrides={"controller.K": "80", "plant.q_noise": 1e-5})
    )
    assert [master.parameters["controller"][f"K{i}"] for i in (1, 2, 3)] == [80.0] * 3
    assert master.parameters["plant"]["q_noise"] == 1e-5


@pytest.mark.slow
def test_diverging_run_stops_with_a_clear_message_and_partial_results(ssp_path):
    result = Master(
        read_ssp(ssp_path), RunOptions(overrides={"controller.G": 1e9}, stop_time=5.0)
    ).run()
    assert not result.ok
    assert "diverged" in result.error or "failed" in result.error
    assert 2 < len(result["time"]) < 2001
    assert np.all(np.isfinite(result.data[:-1]))


@pytest.mark.parametrize(
    "edits,drop,message",
    [
        ({"SystemStructure.ssd": b"<ssd:SystemStructureDescription"}, (), "malformed SSD"),
        (
            {"SystemStructure.ssd": lambda d: d.replace(b"<ssd:Connections>", b"<ssd:Conections>")},
            (),
            "malformed SSD",
        ),
        ({}, ("resources/PumaPlant.fmu",), "PumaPlant.fmu is missing from the archive"),
        (
            {
                "SystemStructure.ssd": lambda d: d.replace(
                    b'endConnector="q1"', b'endConnector="q9"'
                )
            },
            (),
            "connector controller.q9 is not declared",
        ),
    ],
)
def test_malformed_archives_are_refused(ssp_path, tmp_path, edits, drop, message):
    with pytest.raises(SspError, match=message):
        read_ssp(modified(ssp_path, tmp_path, edits, drop))


def test_connector_missing_in_the_fmu_is_refused(ssp_path, tmp_path):
    def rename(d: bytes) -> bytes:
        return d.replace(b'name="q1" kind="input"', b'name="q_one" kind="input"').replace(
            b'endConnector="q1"', b'endConnector="q_one"'
        )

    edited = modified(ssp_path, tmp_path, {"SystemStructure.ssd": rename})
    with pytest.raises(SspError, match="variant difference.ssd describes another system"):
        read_ssp(edited)
    system = read_ssp(edited, ssd="SystemStructure.ssd")  # that SSD alone
    with pytest.raises(MasterError, match="controller.q_one: no such variable"):
        Master(system)


def test_unit_mismatch_is_refused(ssp_path, tmp_path):
    def degrees(d: bytes) -> bytes:  # the controller's q1 connector in degrees
        i = d.index(b'name="q1" kind="input"')
        j = d.index(b'unit="rad"', i)
        return d[:j] + b'unit="deg"' + d[j + len(b'unit="rad"') :]

    with pytest.raises(SspError, match=r"unit mismatch \(rad -> deg\)"):
        read_ssp(modified(ssp_path, tmp_path, {"SystemStructure.ssd": degrees}))


@pytest.mark.parametrize(
    "overrides,message",
    [
        ({"controller.Kx": 1}, "unknown parameter controller.Kx"),
        ({"robot.K1": 1}, "unknown component 'robot'"),
        ({"K1": 1}, "must be written component.variable"),
        ({"plant.tau1": 1}, "plant.tau1 is an input, not a parameter"),
        ({"controller.K1": "fast"}, "'fast' is not a valid Real"),
    ],
)
def test_bad_overrides_are_refused(ssp_path, overrides, message):
    with pytest.raises(MasterError, match=message):
        Master(read_ssp(ssp_path), RunOptions(overrides=overrides))


def test_bad_run_settings_are_refused(ssp_path):
    system = read_ssp(ssp_path)
    with pytest.raises(MasterError, match="no parameter set 'fast'"):
        Master(system, RunOptions(parameter_set="fast"))
    with pytest.raises(MasterError, match="algorithm must be one of"):
        Master(system, RunOptions(algorithm="newton"))
    with pytest.raises(MasterError, match="not a whole number"):
        Master(system, RunOptions(stop_time=1.0001))


# --- the paper's story, on the master's run ------------------------------------------------------


def test_paper_scenario_contact_force(paper_run):
    """Contact at x = 0.65 m from t = 3.85 s; impact overshoot, then the force settles near
    k * 0.00196 m = 19.6 N while the tool slides down the wall; contact ends near 6.2 s."""
    t, force = paper_run["time"], paper_run["plant.contact_force"]
    assert t[force > 0][0] == pytest.approx(3.85, abs=0.02)
    assert 40.0 < force.max() < 150.0  # impact overshoot
    assert np.all(np.abs(force[(t >= 5.5) & (t <= 6.1)] - 19.6) < 0.5)
    assert np.all(np.abs(force[(t >= 15.5) & (t <= 16.1)] - 19.6) < 0.5)
    assert force[(t > 6.3) & (t < 13.8)].max() == 0.0


def test_paper_scenario_tracking_and_observer(paper_run):
    t = paper_run["time"]
    e = np.hypot(paper_run["controller.e_x"], paper_run["controller.e_y"])
    assert e[(t >= 2.0) & (t <= 3.8)].max() < 1e-3  # small before contact (after start-up)
    obs_err = np.max(
        [np.abs(paper_run[f"controller.qd_obs{i}"] - paper_run[f"plant.qd{i}"]) for i in (1, 2, 3)],
        axis=0,
    )
    start_up = obs_err[t <= 0.5].max()
    assert start_up > 5e-3  # the arm starts at rest while the trajectory moves: a transient
    assert obs_err[(t >= 2.0) & (t <= 3.8)].max() < start_up / 5  # ... that decays
    impact = obs_err[(t >= 3.8) & (t <= 4.3)].max()
    assert obs_err[(t >= 5.0) & (t <= 6.0)].max() < impact  # and decays again after the impact


def test_sampling_is_independent_of_the_master_step(ssp_path):
    """Stepped at 1/4000 s, the controller produces the same torque samples as at 1/400 s."""
    system = read_ssp(ssp_path)
    coarse = Master(system, RunOptions(stop_time=1.0)).run()
    fine = Master(system, RunOptions(stop_time=1.0, step_size=DT / 10)).run()
    for i in (1, 2, 3):
        ref = coarse[f"controller.tau{i}"][1:]  # sample k, recorded at (k + 1) * DT
        got = fine[f"controller.tau{i}"][1::10]  # ... and at k * DT + DT / 10
        assert np.abs(got - ref).max() < 1e-6 * np.abs(ref).max()


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.slow
def test_compiled_loop_equals_the_python_loop(ssp_path, algorithm):
    """native/master/loop.c takes exactly the steps of the Python loop (and keeps the same rows
    when a run diverges)."""
    system = read_ssp(ssp_path)
    runs = [
        Master(system, RunOptions(algorithm=algorithm, stop_time=2.0, loop=k)).run()
        for k in ("c", "python")
    ]
    assert runs[0].ok and np.array_equal(runs[0].data, runs[1].data)
    bad = [
        Master(system, RunOptions(overrides={"controller.G": 1e9}, stop_time=1.0, loop=k)).run()
        for k in ("c", "python")
    ]
    assert not bad[0].ok and np.array_equal(bad[0].data, bad[1].data)


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("loop", ["python", "c"])
def test_progress_names_the_parameter_set_with_time_and_real_time_factor(
    ssp_path, monkeypatch, loop
):
    """Master.run(progress=stream): plain lines in a log (no carriage return), a bar on a
    terminal; each names the parameter set and shows steps, simulated time and real-time factor."""
    from impedance_cosim.cosim.master import master

    if loop == "c" and master.c_loop.load() is None:
        pytest.skip("no C compiler for the compiled loop")
    monkeypatch.setattr(master.StepProgress, "DELAY", 0.0)
    monkeypatch.setattr(master.StepProgress, "EVERY", 0.0)
    system = read_ssp(ssp_path)
    log = io.StringIO()
    result = Master(system, RunOptions(stop_time=2.0, loop=loop)).run(progress=log)
    assert result.ok, result.error
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and len(lines) >= 2
    name = result.parameter_set or "run"
    assert all(line.startswith(f"{name}: ") for line in lines), lines
    assert "100%" in lines[-1] and "800/800" in lines[-1] and "t=2.00 s" in lines[-1]
    assert re.search(r"[0-9.]+x real time", lines[-1]), lines[-1]
    terminal = _Terminal()
    Master(system, RunOptions(stop_time=2.0, loop=loop)).run(progress=terminal)
    assert "\r" in terminal.getvalue() and "800/800" in terminal.getvalue()
    quiet = io.StringIO()
    monkeypatch.setattr(master.StepProgress, "DELAY", 60.0)
    Master(system, RunOptions(stop_time=2.0, loop=loop)).run(progress=quiet)
    assert quiet.getvalue() == ""  # a run shorter than the delay shows nothing


def test_enumeration_item_names_resolve_without_importing_the_models_first():
    """A parameter set's item name (velocity_source="difference") resolves through the master's
    explicit table of our enumerations, in a process that imported nothing else before (it used
    to rely on a registry that importing controller_model filled as a side effect)."""
    from controller_model.parameters import VELOCITY_SOURCE

    code = (
        "from types import SimpleNamespace as N\n"
        "from impedance_cosim.cosim.master.setup import _value\n"
        "v = N(declaredType=N(name='VelocitySource'), type='Integer')\n"
        "print(_value(v, 'difference', 'controller.velocity_source'))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(VELOCITY_SOURCE.value("difference"))
