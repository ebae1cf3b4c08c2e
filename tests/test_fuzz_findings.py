"""Regression tests of what the fuzz targets found (fuzz/, docs/failures.md): each case is a
reproducer also kept in the target's corpus (fuzz/corpus/<target>/), here with the documented
outcome spelled out."""

from __future__ import annotations

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
