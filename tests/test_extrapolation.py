"""The master's input extrapolation (extrapolation="linear", Jacobi): the controller's inputs are
the plant's outputs plus h times their time derivatives, checked against a hand computation from
what the plant reports (fmpy's own getRealOutputDerivatives) over a few steps (Python loop; the C
loop gives the same rows); Gauss-Seidel and FMUs without output derivatives refused with one
line; run.json records it; the linearised map steps like the master."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from impedance_cosim.cli import main
from impedance_cosim.cosim.fmus.fmi2 import FmuInstance
from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="needs a C compiler")

H = 1 / 400
STEPS = 6


def _spied_run(monkeypatch, native_ssp, extrapolation: str, scenario: str = "observer"):
    """Run STEPS Jacobi steps; return (result, events, controller sources): events are the
    controller's input writes ("set", values) and, after each plant step and its
    initialization, the plant's outputs and their derivatives through fmpy ("y", y, dy)."""
    events: list[tuple] = []
    setter, step, exit_init = (FmuInstance.real_setter, FmuInstance.step,
                               FmuInstance.exit_initialization)  # fmt: skip
    system = read_ssp(native_ssp)
    sources = [sc for se, sc, ee, _ in system.connections if ee == "controller"]
    outputs = [sc for se, sc, ee, _ in system.connections if se == "plant"]

    def observe(fmu: FmuInstance) -> None:
        if fmu.name == "plant":
            refs = [fmu.vr(n) for n in outputs]
            dy = fmu.slave.getRealOutputDerivatives(refs, [1] * len(refs))
            events.append(("y", dict(zip(outputs, fmu.get(outputs), strict=True)),
                           dict(zip(outputs, dy, strict=True))))  # fmt: skip

    def spy_setter(fmu, names):
        write = setter(fmu, names)

        def spied(values):
            if fmu.name == "controller":
                events.append(("set", list(values)))
            write(values)

        return spied

    def spy_step(fmu, t, h):
        step(fmu, t, h)
        observe(fmu)

    def spy_exit(fmu):
        exit_init(fmu)
        events.clear() if fmu.name == "plant" else None  # the writes of initialization
        observe(fmu)

    monkeypatch.setattr(FmuInstance, "real_setter", spy_setter)
    monkeypatch.setattr(FmuInstance, "step", spy_step)
    monkeypatch.setattr(FmuInstance, "exit_initialization", spy_exit)
    master = Master(
        system,
        RunOptions(
            parameter_set=scenario,
            algorithm="jacobi",
            step_size=H,
            stop_time=STEPS * H,
            extrapolation=extrapolation,
            loop="python",
        ),
    )  # fmt: skip  (the C loop sets its inputs in C)
    result = master.run()
    assert result.ok, result.error
    return result, events, sources


def _pairs(events: list[tuple]) -> list[tuple[list[float], dict, dict]]:
    """Each controller input write with the plant's last outputs and derivatives before it."""
    out, last = [], None
    for event in events:
        if event[0] == "y":
            last = event[1:]
        else:
            assert last is not None
            out.append((event[1], *last))
    return out


@pytest.mark.parametrize("scenario", ["observer", "difference"])
def test_linear_sets_the_controller_inputs_to_y_plus_h_times_dy(monkeypatch, native_ssp, scenario):
    result, events, sources = _spied_run(monkeypatch, native_ssp, "linear", scenario)
    pairs = _pairs(events)
    assert len(pairs) == STEPS
    moved = 0
    for k, (written, y, dy) in enumerate(pairs):
        expected = [y[n] + H * dy[n] for n in sources]
        assert written == expected, (k, written, expected)  # bit for bit
        row = dict(zip(result.names, result.data[k], strict=True))
        assert all(y[n] == row[f"plant.{n}"] for n in sources), k  # the outputs at t_k
        for i in (1, 2, 3):  # independent of the derivative call: dq/dt is the output qd
            assert written[sources.index(f"q{i}")] == row[f"plant.q{i}"] + H * row[f"plant.qd{i}"]
        moved += sum(w != y[n] for w, n in zip(written, sources, strict=True))
    assert moved > STEPS  # the extrapolation changes the inputs (the arm moves from k = 1)


def test_none_sets_the_outputs_unchanged(monkeypatch, native_ssp):
    _, events, sources = _spied_run(monkeypatch, native_ssp, "none")
    pairs = _pairs(events)
    assert len(pairs) == STEPS
    for written, y, _dy in pairs:
        assert written == [y[n] for n in sources]


def test_refusals_name_the_problem(ssp_path, native_ssp):
    native, python = read_ssp(native_ssp), read_ssp(ssp_path)
    with pytest.raises(MasterError, match="needs the Jacobi algorithm"):
        Master(native, RunOptions(algorithm="gauss-seidel", extrapolation="linear"))
    with pytest.raises(MasterError, match=r"PumaPlant.fmu: 0\).*maxOutputDerivativeOrder|"
                       r"maxOutputDerivativeOrder >= 1: .*PumaPlant.fmu: 0"):  # fmt: skip
        Master(python, RunOptions(algorithm="jacobi", extrapolation="linear"))
    with pytest.raises(MasterError, match="not zero_start_inputs"):
        Master(
            native, RunOptions(algorithm="jacobi", extrapolation="linear", zero_start_inputs=True)
        )
    with pytest.raises(MasterError, match="extrapolation must be one of"):
        Master(native, RunOptions(algorithm="jacobi", extrapolation="quadratic"))
    for loop in ("c", "python"):
        quantized = Master(
            native,
            RunOptions(
                algorithm="jacobi",
                stop_time=0.01,
                extrapolation="linear",
                overrides={"plant.q_quant": 1e-4},
                loop=loop,
            ),
        ).run()
        assert quantized.status == "failed" and len(quantized.data) == 1  # row t_0 kept
        assert "fmi2GetRealOutputDerivatives failed" in quantized.error
        assert "q1 has no time derivative" in quantized.error


def _linear_jacobi_run(ssp, out) -> list[str]:
    """The command line of a 0.1 s Jacobi run of SSP with linear extrapolation into OUT."""
    return ["run", "--ssp", str(ssp), "--stop", "0.1", "--algorithm", "jacobi",
            "--extrapolation", "linear", "--out", str(out), "--no-figures"]  # fmt: skip


def test_cli_records_it_in_run_json_and_refuses_the_python_plant(native_ssp, ssp_path, tmp_path,
                                                                 capsys):  # fmt: skip
    out = tmp_path / "res"
    assert main([*_linear_jacobi_run(native_ssp, out), "--no-progress"]) == 0
    (run,) = json.loads((out / "run.json").read_text())["runs"]
    assert run["extrapolation"] == "linear" and run["algorithm"] == "jacobi"
    capsys.readouterr()
    assert main(_linear_jacobi_run(ssp_path, tmp_path / "bad")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "maxOutputDerivativeOrder" in err[0], err
    assert not np.any([p.exists() for p in [tmp_path / "bad" / "run.json"]])


def test_fmi3_plant_extrapolates_like_fmi2(native_ssp, fmi3_dir):
    """fmi3GetOutputDerivatives path: the FMI 3.0 system gives the FMI 2.0 system's rows, in the
    C loop and the Python loop alike (bit for bit)."""
    rows = []
    for ssp in (native_ssp, fmi3_dir.parent / "PaperScenario-fmi3.ssp"):
        for loop in ("c", "python"):
            r = Master(
                read_ssp(ssp),
                RunOptions(
                    parameter_set="observer",
                    algorithm="jacobi",
                    stop_time=0.25,
                    extrapolation="linear",
                    loop=loop,
                ),
            ).run()
            assert r.ok, r.error
            assert r.info["loop"] == loop
            rows.append({n: r.data[:, k] for k, n in enumerate(r.names)})
    plain = Master(
        read_ssp(native_ssp),
        RunOptions(parameter_set="observer", algorithm="jacobi", stop_time=0.25),
    ).run()
    for name in ("plant.q1", "plant.q3", "controller.tau1", "controller.tau3"):
        for other in rows[1:]:
            np.testing.assert_array_equal(rows[0][name], other[name], err_msg=name)
        assert np.abs(rows[0][name] - plain.data[:, plain.names.index(name)]).max() > 1e-6


@pytest.mark.parametrize("scenario", ["observer", "measured"])
@pytest.mark.parametrize("extrapolation", ["none", "linear"])
def test_the_linearised_loop_steps_like_the_master(native_ssp, extrapolation, scenario):
    """apps/linearize.step ("jacobi" / "jacobi-linear", the plain Python models, derivatives by
    a central difference) follows the native master's Jacobi run for 1 s: the same map the
    critical rates of docs/stability.md section 4 come from ("measured": the extrapolated
    velocity's slope, the acceleration, depends on the torque the plant held)."""
    from controller_model.model import ControllerModel
    from impedance_cosim.apps import linearize as lin
    from impedance_cosim.cosim.master.plain_loop import wiring
    from plant_model.model import PlantModel

    h, n = 1 / 800, 800  # 800 Hz: the true velocity extrapolated is stable from 663 Hz
    master = Master(
        read_ssp(native_ssp),
        RunOptions(
            parameter_set=scenario,
            overrides={"controller.sample_period": h},
            algorithm="jacobi",
            step_size=h,
            stop_time=n * h,
            extrapolation=extrapolation,
        ),
    )
    result = master.run()
    assert result.ok, result.error
    plant = PlantModel(dict(master.parameters["plant"]), 0.0, None)
    p_out, (feed, tau_idx) = plant.outputs(), wiring()
    controller = ControllerModel(dict(master.parameters["controller"]), 0.0,
                                 tuple(p_out[j] for j in feed))  # fmt: skip
    plant.tau_held = tuple(controller.outputs()[j] for j in tau_idx)
    algorithm = "jacobi-linear" if extrapolation == "linear" else "jacobi"
    q = []
    for i in range(n):
        p_out = lin.step(plant, controller, i * h, h, algorithm, p_out)
        q.append(plant.q)
    native = np.column_stack([result.data[1:, result.names.index(f"plant.q{i}_true")]
                              for i in (1, 2, 3)])  # fmt: skip
    assert np.abs(np.array(q) - native).max() < 1e-9
