"""Every engine runs every scenario's archive as our master does, with no project code in the loop.

Each scenario is an archive of its own (PaperScenario-native-<scenario>.ssp: its SSD binds the
scenario's parameter set on each component), run with the native FMUs. The engines:

- libcosim (libcosimpy): applies the component-level bindings itself; Jacobi; times from integer
  nanoseconds; connections start from the initialized outputs.
- ecospy: applies the bindings when the set is named in init(parameter_set=...); Jacobi; times
  accumulate (t += h); connections start from the initialized outputs.
- fmpy's simulate_ssp: applies no binding (the parameter set is passed, collected from the SSD
  with fmpy's own reader); Jacobi; times accumulate; every connection starts at 0.0, so the plant's
  first step gets zero torque; each row is stamped with its step's start time.

Each engine is compared with our master's Jacobi run twice: on the engine's conventions (time grid,
start values: RunOptions(step_times=..., zero_start_inputs=...)) every connected signal agrees
within 1e-9 (measured: bit-identical); on our own conventions (t_0 + i h) libcosim and ecospy agree
within 1e-9 in the stable scenario (observer), and the difference and measured scenarios
(unstable under Jacobi) diverge at the same step in all of them (Fig. 4 outside our master). fmpy
cannot agree with our default run: its zero start torque moves the whole run (measured: 3e-5 rad
on q1 after the first step).
"""

from __future__ import annotations

import numpy as np
import pytest

from impedance_cosim.cosim.engines.others import (
    CONNECTED,
    AccumulatedTimes,
    first_beyond,
    largest_difference,
    nanosecond_times,
    run_in_ecospy,
    run_in_fmpy,
    run_in_libcosim,
)
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import SCENARIOS
from impedance_cosim.packaging.build import build_ssp

H = 0.0025
# contact starts at 3.85 s; difference stops before its loop overflows (a step whose outputs
# would not be finite is refused: under fmpy at 0.4975 s)
STOPS = {"observer": 4.5, "measured": 2.75, "difference": 0.495}
# Under Jacobi (the torque one step late) only the observer scenario is stable: the difference
# and the measured ones diverge, |tau1| > 1e6 N m from these times on (our master, measured).
DIVERGES = {"difference": 0.4825, "measured": 2.6075}


def _ecospy():
    try:
        import ecospy
    except (ImportError, OSError) as exc:  # OSError: libtbb12 missing
        pytest.skip(f"ecospy unavailable: {exc}")
    return ecospy


@pytest.fixture(scope="module")
def archives(native_dir, tmp_path_factory):
    """One archive per scenario (native FMUs), as the build makes them."""
    out = tmp_path_factory.mktemp("scenario_archives")
    return {
        s: build_ssp(out, f"PaperScenario-native-{s}", native_dir, scenario=s) for s in SCENARIOS
    }


def ours(archive, stop: float, **conventions) -> dict[str, np.ndarray]:
    with read_ssp(archive) as system:
        (scenario,) = system.parameter_sets  # one set per scenario archive
        result = Master(
            system,
            RunOptions(
                parameter_set=scenario,
                algorithm="jacobi",
                stop_time=stop,
                divergence_limit=1e300,
                **conventions,
            ),
        ).run()
    return {name: result[name] for name in ["time", *CONNECTED]}


def in_fmpy(archive, stop: float) -> dict[str, np.ndarray]:
    return run_in_fmpy(archive, stop, H)


def in_ecospy(archive, scenario: str, stop: float) -> dict[str, np.ndarray]:
    _ecospy()
    return run_in_ecospy(archive, scenario, stop, H, CONNECTED)


def in_libcosim(archive, stop: float) -> dict[str, np.ndarray]:
    pytest.importorskip("libcosimpy")
    return run_in_libcosim(archive, None, stop, H, log_level="error")


def divergence_time(run: dict, shift: int = 0) -> float:
    """When |tau1| first exceeds 1e6 N m (our master's divergence limit)."""
    row = first_beyond(run)
    assert row is not None, "did not diverge"
    return (row + shift) * H


# each engine's time grid for our master (t_i as it computes them)
GRIDS = {"libcosim": nanosecond_times, "ecospy": AccumulatedTimes}


@pytest.mark.parametrize("engine", list(GRIDS))
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_engine_runs_each_scenario_archive_as_our_jacobi_master(archives, scenario, engine):
    stop = STOPS[scenario]
    if engine == "libcosim":
        theirs = in_libcosim(archives[scenario], stop)
    else:
        theirs = in_ecospy(archives[scenario], scenario, stop)
    same_grid = ours(archives[scenario], stop, step_times=GRIDS[engine](0.0, H))
    assert largest_difference(same_grid, theirs)[0] <= 1e-9, largest_difference(same_grid, theirs)
    default = ours(archives[scenario], stop)
    if scenario in DIVERGES:
        assert divergence_time(theirs) == divergence_time(default)
        assert divergence_time(default) == pytest.approx(DIVERGES[scenario])
    else:
        assert largest_difference(default, theirs)[0] <= 1e-9, largest_difference(default, theirs)


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_fmpy_simulate_ssp_runs_each_scenario_archive_as_our_master_on_its_conventions(
    archives, scenario
):
    stop = STOPS[scenario]
    theirs = in_fmpy(archives[scenario], stop)
    fmpy_like = ours(
        archives[scenario], stop, step_times=AccumulatedTimes(0.0, H), zero_start_inputs=True
    )
    assert largest_difference(fmpy_like, theirs, shift=1)[0] <= 1e-9, largest_difference(
        fmpy_like, theirs, shift=1
    )
    if scenario == "difference":  # Fig. 4 in fmpy: diverges, but not at the same step as ours
        assert divergence_time(theirs, shift=1) == divergence_time(fmpy_like)
        assert divergence_time(theirs, shift=1) != divergence_time(ours(archives[scenario], stop))
    # against our default run: the zero torque of the first step shows at once
    assert abs(theirs["plant.q1"][0] - ours(archives[scenario], H)["plant.q1"][1]) > 1e-5


def test_ecospy_applies_nothing_without_the_set_name(archives):
    """Measured trap: without init(parameter_set=...) ecospy applies no binding, so the difference
    archive runs with the FMUs' start values (velocity_source 1, the observer)."""
    ecospy = _ecospy()
    sim = ecospy.EcosSimulation(step_size=H, ssp_path=str(archives["difference"]))
    assert sim.init()
    assert sim.get_integer("controller::velocity_source") == 1
    sim.terminate()
    sim = ecospy.EcosSimulation(step_size=H, ssp_path=str(archives["difference"]))
    assert sim.init(parameter_set="difference")
    assert sim.get_integer("controller::velocity_source") == 2
    sim.terminate()


def test_libcosim_runs_the_default_variant_of_the_multi_scenario_archive(fmu_dir, native_dir):
    """libcosim reads only SystemStructure.ssd of an archive with variants: the observer."""
    archive = fmu_dir / "PaperScenario-native.ssp"  # built by the native_dir fixture
    theirs = in_libcosim(archive, 0.25)
    with read_ssp(archive) as system:
        assert list(system.parameter_sets) == list(SCENARIOS)
        result = Master(
            system, RunOptions(parameter_set="observer", algorithm="jacobi", stop_time=0.25)
        ).run()
    assert max(np.max(np.abs(result[n] - theirs[n])) for n in CONNECTED) <= 1e-9


def test_our_cli_runs_a_scenario_from_either_archive_form(archives, fmu_dir, tmp_path, capsys):
    """--scenario picks a variant of the multi-scenario archive, or names the one scenario of a
    scenario's own archive (another name there is one line of error)."""
    from impedance_cosim.cli import main

    runs = {}
    for form, archive in (("variants", fmu_dir / "PaperScenario-native.ssp"),
                          ("own", archives["difference"])):  # fmt: skip
        out = tmp_path / form
        args = ["run", "--ssp", str(archive), "--stop", "0.1", "--no-figures", "--out", str(out)]
        assert main([*args, "--scenario", "difference"]) == 0
        runs[form] = (out / "difference.csv").read_text()
    assert runs["variants"] == runs["own"]
    capsys.readouterr()
    args = ["run", "--ssp", str(archives["difference"]), "--stop", "0.1", "--no-figures"]
    assert main([*args, "--out", str(tmp_path / "x"), "--scenario", "observer"]) != 0
    assert "no parameter set 'observer'" in capsys.readouterr().err


def test_every_ssd_and_ssv_validates_against_the_ssp_schemas():
    """All system descriptions (the variants too) and parameter sets, against fmpy's SSP 1.0
    XSDs (validate_tree raises on the first error)."""
    from fmpy.ssp.ssd import validate_tree
    from lxml import etree

    from impedance_cosim.cosim.system.paper import source_files

    files = source_files()
    assert sorted(n for n in files if n.endswith(".ssd")) == [
        "SystemStructure.ssd", "difference.ssd", "measured.ssd"]  # fmt: skip
    assert len([n for n in files if n.endswith(".ssv")]) == 2 * len(SCENARIOS)
    for name, data in files.items():
        kind = "Description" if name.endswith(".ssd") else "ParameterValues"
        validate_tree(etree.fromstring(data), f"SystemStructure{kind}.xsd")
