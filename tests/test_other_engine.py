"""The same .ssp in another engine: libcosim (libcosimpy from PyPI) against our master.

libcosim's fixed-step algorithm is Jacobi and starts the connections from the initialized outputs,
so it is compared with our Jacobi master, row for row (both record the outputs after
initialization, then after each step). libcosim computes times from integer nanoseconds, t_i =
(i * h_ns) / 1e9 and step length t_i+1 - t_i, where our master uses i * h and h: on libcosim's
grid our master gives bit-identical results, on its own they differ by round-off (measured: at
most 7e-11 over the 20 s observer run, in the torque and the contact force; 1e-13 in the joint
velocities). The tolerance below is 1e-9, absolute, on every output.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_master import modified  # an archive with members edited

from impedance_cosim.cosim.engines.others import EngineError, nanosecond_times, run_in_libcosim
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

pytest.importorskip("libcosimpy")

H = 0.0025
H_NS = 2_500_000
STOP = 20.0
SIGNALS = [
    "plant.x",
    "plant.y",
    "plant.contact_force",
    *(f"plant.qd{i}" for i in (1, 2, 3)),
    *(f"controller.tau{i}" for i in (1, 2, 3)),
]


def master_run(
    ssp_path, parameter_set: str, stop: float, algorithm: str = "jacobi", libcosim_grid=False
):
    """Our master; libcosim_grid: every step on libcosim's time grid (t and h from integer ns)."""
    result = Master(
        read_ssp(ssp_path),
        RunOptions(
            parameter_set=parameter_set,
            algorithm=algorithm,
            stop_time=stop,
            step_times=nanosecond_times(0.0, H) if libcosim_grid else None,
        ),
    ).run()
    assert result.ok, result.error
    return result


@pytest.fixture(scope="module")
def libcosim_run(ssp_path):
    return run_in_libcosim(ssp_path, "observer", STOP, H)


def test_libcosim_records_every_output_at_every_step(libcosim_run):
    steps = round(STOP / H)
    assert np.array_equal(libcosim_run["time"], np.arange(steps + 1) * H_NS / 1e9)
    assert set(SIGNALS) <= set(libcosim_run)
    assert all(len(v) == steps + 1 for v in libcosim_run.values())


def test_libcosim_matches_our_jacobi_master_to_1e_9(ssp_path, libcosim_run):
    ours = master_run(ssp_path, "observer", STOP)
    assert np.allclose(ours["time"], libcosim_run["time"], rtol=0, atol=1e-12)
    assert set(libcosim_run) == set(ours.names)
    for name, values in libcosim_run.items():
        assert np.allclose(values, ours[name], rtol=0, atol=1e-9), name


@pytest.mark.slow
def test_libcosim_is_bit_identical_to_our_jacobi_master_on_its_time_grid(ssp_path, libcosim_run):
    ours = master_run(ssp_path, "observer", STOP, libcosim_grid=True)
    for name, values in libcosim_run.items():
        if name != "time":
            assert np.array_equal(values, ours[name]), name


def test_libcosim_is_not_gauss_seidel(ssp_path, libcosim_run):
    """Against our default (controller first) the torque reaches the plant one step earlier:
    the difference is that delay, not round-off."""
    ours = master_run(ssp_path, "observer", STOP, algorithm="gauss-seidel")
    assert np.max(np.abs(libcosim_run["controller.tau1"] - ours["controller.tau1"])) > 0.1
    assert np.max(np.abs(libcosim_run["plant.contact_force"] - ours["plant.contact_force"])) > 1.0


def test_libcosim_runs_the_chosen_parameter_set(ssp_path):
    """libcosim ignores system-level ParameterBindings; run_in_libcosim applies the set itself.
    (The difference scenario goes unstable under Jacobi after ~0.45 s, so the run is short.)"""
    stop = 0.25
    theirs = run_in_libcosim(ssp_path, "difference", stop, H)
    ours = master_run(ssp_path, "difference", stop, libcosim_grid=True)
    for name, values in theirs.items():
        if name != "time":
            assert np.array_equal(values, ours[name]), name
    observer = run_in_libcosim(ssp_path, "observer", stop, H)
    assert not np.array_equal(theirs["controller.qd_hat1"], observer["controller.qd_hat1"])


def test_libcosim_reports_a_failing_step_as_an_error(ssp_path, tmp_path):
    """A step the plant refuses (fmi2Discard) stops libcosim with an EngineError naming the plant,
    and the process lives on. The refusal: a plant whose work bound (max_rhs_evaluations = 25)
    the first contact exceeds (a Python FMU runs its own bundled code, so nothing of it can be
    patched from here). (A failure during initialization instead aborts the whole process: not
    tested here.)"""
    bounded = modified(ssp_path, tmp_path, {"resources/observer_plant.ssv": work_bound(25)})
    with pytest.raises(EngineError, match=r"t=[0-9.]+ s.*plant"):
        run_in_libcosim(bounded, "observer", 5.0, H)


def work_bound(evaluations: int):
    """An edit of a plant .ssv: one more parameter, max_rhs_evaluations."""

    def edit(data: bytes) -> bytes:
        extra = (
            '<ssv:Parameter name="max_rhs_evaluations">'
            f'<ssv:Integer value="{evaluations}" /></ssv:Parameter>'
        )
        return data.replace(b"</ssv:Parameters>", extra.encode() + b"</ssv:Parameters>", 1)

    return edit


def test_bad_arguments_are_refused(ssp_path):
    with pytest.raises(ValueError, match="parameter set"):
        run_in_libcosim(ssp_path, "nonsense", 1.0, H)
    with pytest.raises(ValueError, match="nanoseconds"):
        run_in_libcosim(ssp_path, "observer", 1.0, 1e-10)
