"""The results CSV's fast formatter writes exactly the bytes of Python's repr (the shortest text
that reads back to the same double), on real runs of every scenario and on edge values."""

from __future__ import annotations

import numpy as np
import pytest

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results.result import format_rows
from impedance_cosim.cosim.ssp.read import read_ssp


def repr_rows(data: np.ndarray) -> str:
    """The reference: every value as repr, comma-separated, a line per row."""
    return "".join(",".join(repr(float(v)) for v in row) + "\n" for row in data)


EDGES = [1e-300, 5e-324, -0.0, 0.0, 1e16, 9999999999999998.0, 123456789012345678.0, 1e-05,
         -1.5e-05, 9.999999999999999e-05, 1e-04, 1e-07, -1.2345e-09, 10.00001,
         2.2250738585072014e-308, 1.7976931348623157e308, 1e22, 0.1, 1.0, -1e100]  # fmt: skip


def test_edge_values_are_spelled_as_repr() -> None:
    data = np.array([EDGES, [-x for x in EDGES]])
    assert format_rows(data) == repr_rows(data)


def test_non_finite_values_are_spelled_as_repr() -> None:
    data = np.array([[0.5, np.nan, np.inf, -np.inf], [1e-05, 1.0, 2.0, 3.0]])
    assert format_rows(data) == repr_rows(data) == "0.5,nan,inf,-inf\n1e-05,1.0,2.0,3.0\n"


def test_random_bit_patterns_and_magnitudes_are_spelled_as_repr() -> None:
    rng = np.random.default_rng(24)
    bits = rng.integers(0, 2**64, size=(20000, 6), dtype=np.uint64).view(np.float64)
    bits = bits[np.isfinite(bits).all(axis=1)]
    scaled = rng.standard_normal((20000, 6)) * 10.0 ** rng.integers(-12, 20, (20000, 6))
    for block in (bits, scaled):
        assert format_rows(block) == repr_rows(block)


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.slow
def test_every_scenario_run_is_spelled_as_repr(native_ssp, algorithm: str) -> None:
    system = read_ssp(native_ssp)
    try:
        for scenario in system.parameter_sets:
            result = Master(system, RunOptions(parameter_set=scenario, algorithm=algorithm)).run()
            assert len(result.data) > 100, (scenario, result.error)
            assert format_rows(result.data) == repr_rows(result.data), scenario
    finally:
        system.close()


def test_a_value_equal_to_the_placeholder_still_reads_as_repr() -> None:
    from impedance_cosim.cosim.results import result as results

    data = np.array([[1.5e-05, results._PLACE, 2e-07], [0.25, 1e-05, 3.0]])
    assert format_rows(data) == repr_rows(data)


def test_each_model_description_is_parsed_once_per_run(native_ssp, monkeypatch) -> None:
    """Nothing computed twice: the master's checks and the FMU instances share one parse."""
    from impedance_cosim.cosim.fmus import files as fmu_files

    parsed: list[str] = []
    real = fmu_files.read_model_description

    def counted(path, *args, **kwargs):
        parsed.append(path)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(fmu_files, "read_model_description", counted)
    fmu_files._description.cache_clear()
    system = read_ssp(native_ssp)
    try:
        result = Master(system, RunOptions(stop_time=0.1)).run()
    finally:
        system.close()
    assert result.ok, result.error
    assert len(parsed) == len(set(parsed)) == len(system.components), parsed
