"""Regression tests of what the fuzz targets found (fuzz/, docs/failures.md): each case is a
reproducer also kept in the target's corpus (fuzz/corpus/<target>/), here with the documented
outcome spelled out."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from impedance_cosim.apps.sweep.table import TableError, read_table
from impedance_cosim.cosim.results.result import read_csv


@pytest.mark.parametrize(
    "content",
    [b"", b"\xff\xfe", b"x" * 200_000, b"a,b\n1\n", b"a,b\n1,nope\n"],
    ids=["empty", "not-utf8", "huge-field", "short-row", "not-a-number"],
)
def test_read_csv_refuses_a_bad_file_with_one_line(tmp_path: Path, content: bytes):
    """fuzz target `result_files`: StopIteration, UnicodeDecodeError and csv.Error came out."""
    path = tmp_path / "run.csv"
    path.write_bytes(content)
    with pytest.raises(ValueError, match="run.csv is not a results CSV") as caught:
        read_csv(path)
    assert "\n" not in str(caught.value) and not isinstance(caught.value, UnicodeDecodeError)


@pytest.mark.parametrize(
    "content", [b"a,b\n1,2,3\n", b"a,b\n1\n", b"\xff", b"x" * 200_000],
    ids=["long-row", "short-row", "not-utf8", "huge-field"],
)  # fmt: skip
def test_read_table_refuses_a_bad_table_with_table_error(tmp_path: Path, content: bytes):
    """fuzz target `result_files`: AttributeError (a row longer or shorter than the header),
    UnicodeDecodeError and csv.Error came out of read_table."""
    path = tmp_path / "sweep.csv"
    path.write_bytes(content)
    with pytest.raises(TableError) as caught:
        read_table(path)
    assert "\n" not in str(caught.value)


def test_read_csv_and_read_table_still_read_good_files(tmp_path: Path):
    (tmp_path / "run.csv").write_text('time,"a,b"\n0.0,1.5\n0.0025,2\n')
    data = read_csv(tmp_path / "run.csv")
    assert list(data) == ["time", "a,b"] and data["a,b"].tolist() == [1.5, 2.0]
    (tmp_path / "sweep.csv").write_text("run,controller.K,status,error\n1,10,ok,\n")
    assert read_table(tmp_path / "sweep.csv") == [
        {"run": 1, "controller.K": 10, "status": "ok", "error": None}
    ]


def test_output_interval_of_more_than_2_53_steps_is_a_cli_error():
    """fuzz target `cli_options`: `run --stop 1e-297 --step 1e-300 --output-interval 1e10` was
    an internal error (OverflowError: interval / step is inf, round() of it), exit status 1."""
    from impedance_cosim.apps.options import CliError, output_every

    with pytest.raises(CliError, match="more than 2\\*\\*53 steps"):
        output_every(1e10, 1e-300, 1000)
    assert output_every(0.01, 0.0025, 800) == 4


def test_controller_event_after_a_huge_time_skip_is_refused_not_a_hang(native_dir: Path):
    """fuzz target `fmi3_calls_controller`: fmi3SetTime(1e308) then fmi3UpdateDiscreteStates
    took every sample up to t (one per 1/400 s: a hang). Now the event refuses to take more
    than max_samples_per_step samples; the same code serves FMI 2.0 Model Exchange, here."""
    from fmpy.fmi1 import FMICallException
    from test_model_exchange import CONTROLLER, MEPlant

    me = MEPlant(native_dir, CONTROLLER)
    me.initialize()
    me.fmu.setTime(1e308)
    with pytest.raises(FMICallException):
        me.fmu.newDiscreteStates()
    assert any("max_samples_per_step" in m for m in me.messages), me.messages
    me.fmu.terminate()
    me.fmu.freeInstance()


START = (0.0, 0.7, -0.7, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # angles, wrist force, measured qd
HUGE_ANGLE = (1e307, *START[1:])  # K (q1 - q1_prev) overflows (K = 50)
REFUSAL = "output tau1 is not finite (nan): the computation overflowed"  # C and Python alike


def test_python_controller_refuses_a_step_whose_outputs_overflow():
    """fuzz target `closedloop_params` (fuzz/corpus/closedloop_params/nan-output-huge-gain:
    an output became NaN after steps that returned OK). A controller step whose outputs would not
    be finite is refused, naming the output, and the model stays at the step's start."""
    from controller_model.model import ControllerModel
    from impedance_cosim.fmi.model import ModelError

    model = ControllerModel({})
    model.do_step(0.0, 1 / 400, START)  # sample 0 was taken at initialization
    before = model.outputs()
    with pytest.raises(ModelError) as refused:
        model.do_step(1 / 400, 1 / 400, HUGE_ANGLE)  # sample 1, at t = 1/400
    assert str(refused.value) == REFUSAL
    assert model.t == 1 / 400 and model.outputs() == before
    model.do_step(1 / 400, 1 / 400, START)  # and it can go on
    assert all(math.isfinite(v) for v in model.outputs())


def test_native_controller_refuses_a_step_whose_outputs_overflow(native_dir: Path):
    """The same through the native FMI 2.0 controller: fmi2Discard, the same message in the log,
    and the outputs of the step's start kept."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.fmi2 import defaultCallbacks as default  # noqa: N813

    path = native_dir / "ImpedanceController.fmu"
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    messages: list[str] = []
    # Our own callbacks, not the logger argument of fmpy's instantiate_fmu: see the last test.
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda *a: messages.append(a[-1].decode()))
    callbacks.allocateMemory, callbacks.freeMemory = default.allocateMemory, default.freeMemory
    identifier = md.coSimulation.modelIdentifier
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                    modelIdentifier=identifier, instanceName="controller")  # fmt: skip
    fmu.instantiate(callbacks=callbacks)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    angles = [vr[n] for n in ("q1", "q2", "q3")]
    fmu.setReal(angles, list(START[:3]))
    fmu.doStep(0.0, 1 / 400)
    before = fmu.getReal(outputs)
    fmu.setReal(angles, list(HUGE_ANGLE[:3]))
    with pytest.raises(FMICallException):
        fmu.doStep(1 / 400, 1 / 400)
    assert messages == [f"at t=0.0025000000000000001: {REFUSAL}"]
    assert fmu.getReal(outputs) == before
    fmu.terminate()
    fmu.freeInstance()


def test_no_test_hands_fmpy_a_logger_it_keeps_process_wide():
    """The logger argument of fmpy's instantiate_fmu and simulate_fmu sets the one logger of
    fmpy's native logging proxy (process-wide) to a callback that is freed with the FMU; the next
    FMU that logs through fmpy's default callbacks then calls freed memory (it crashed an xdist
    worker in test_closedloop's refused ME instantiation). Tests pass their own callbacks."""
    import re

    call = re.compile(r"(instantiate_fmu|simulate_fmu)\((?:[^()]|\([^()]*\))*\blogger=")
    found = [p.name for p in Path(__file__).parent.glob("*.py") if call.search(p.read_text())]
    assert found == []
