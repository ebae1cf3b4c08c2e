"""Each scenario's archive as one container FMU (fmu-manipulation-toolbox 2.0's fmucontainer),
run under `fmpy simulate`, against our master's run of the same algorithm (issue 22).

The container cuts the plant-controller loop before the first FMU it lists; our SSDs list the
plant first (system.SSD_ELEMENT_ORDER), so the controller is initialized from the plant's
outputs. Sequential mode is Gauss-Seidel in that order, parallel mode is Jacobi
(cosim/engines/container.py). Measured: bit-identical to our master in both modes on every row of
every output (sequential: the full 20 s of all three scenarios; parallel: the observer
scenario's 20 s). The tolerance below is 1e-9, absolute. Under Jacobi the difference and measured
scenarios diverge (tests/test_engine_conformance.py), so their parallel containers are compared
up to just before that, and their 20 s run fails in the container as in our master.
"""

from __future__ import annotations

import numpy as np
import pytest

from impedance_cosim.cosim.engines.container import (
    build_container,
    container_description,
    master_like_container,
    run_container,
)
from impedance_cosim.cosim.engines.others import EngineError
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import SCENARIOS, SSD_ELEMENT_ORDER
from impedance_cosim.packaging.build import build_ssp

pytest.importorskip("fmu_manipulation_toolbox")

STOP = 20.0
JACOBI_STOPS = {"observer": 4.5, "difference": 0.45, "measured": 2.5}  # before divergence
TOL = 1e-9


@pytest.fixture(scope="module")
def archives(native_dir, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("container_archives")
    return {
        s: build_ssp(out, f"PaperScenario-native-{s}", native_dir, scenario=s) for s in SCENARIOS
    }


@pytest.fixture(scope="module")
def containers(archives, tmp_path_factory) -> dict:
    """Each scenario's container, sequential and parallel, built once."""
    out = tmp_path_factory.mktemp("containers")
    return {
        (s, seq): build_container(archive, out / f"{s}-{'seq' if seq else 'par'}.fmu", seq)
        for s, archive in archives.items()
        for seq in (True, False)
    }


def worst(rows: dict, ours) -> tuple[float, str]:
    """Largest absolute difference over every output, row for row (the rows both have)."""
    n = len(rows["time"])
    assert len(ours.data) >= n
    diffs = {k: float(np.max(np.abs(v - ours[k][:n]))) for k, v in rows.items()}
    name = max(diffs, key=diffs.__getitem__)
    return diffs[name], name


def test_the_container_lists_the_plant_first(archives):
    assert SSD_ELEMENT_ORDER == ("plant", "controller")
    with read_ssp(archives["observer"]) as system:
        desc = container_description(system, "x.fmu", True, "observer", 0.0025)
    assert desc["fmu"] == ["PumaPlant.fmu", "ImpedanceController.fmu"]
    assert len(desc["output"]) == 24 + 20  # every Real output of both
    assert ["ImpedanceController.fmu", "velocity_source", 1] in desc["start"]


@pytest.mark.parametrize("scenario", list(SCENARIOS))
@pytest.mark.slow
def test_sequential_container_equals_our_gauss_seidel_master_in_ssd_order(
    archives, containers, scenario
):
    rows = run_container(containers[scenario, True], STOP)
    assert len(rows["time"]) == round(STOP / 0.0025) + 1
    ours = master_like_container(archives[scenario], True, STOP)
    assert ours.status == "ok", ours.error
    assert worst(rows, ours)[0] <= TOL, worst(rows, ours)
    # the scenario's parameters were applied: the law got its own velocity (the start value,
    # velocity_source = observer, would feed it the observer's)
    law, observer = rows["controller.qd_hat1"], rows["controller.qd_obs1"]
    assert np.array_equal(law, observer) == (scenario == "observer")
    if scenario == "difference":
        assert np.array_equal(law, rows["controller.qd_diff1"])


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_parallel_container_equals_our_jacobi_master(archives, containers, scenario):
    stop = JACOBI_STOPS[scenario]
    rows = run_container(containers[scenario, False], stop)
    ours = master_like_container(archives[scenario], False, stop)
    assert worst(rows, ours)[0] <= TOL, worst(rows, ours)


@pytest.mark.slow
def test_a_jacobi_run_that_diverges_fails_in_the_container_as_in_our_master(archives, containers):
    with pytest.raises(EngineError, match="fmi2DoStep failed"):
        run_container(containers["difference", False], STOP)
    assert master_like_container(archives["difference"], False, STOP).status != "ok"


def test_listing_the_controller_first_starts_it_at_the_stretched_arm(archives, tmp_path):
    """The order matters: listed first, the controller is initialized from the link buffers
    (q = 0: gravity compensation only, since issue 22; refused before), a different run."""
    fmu = build_container(
        archives["observer"], tmp_path / "reversed.fmu", False, order=["controller", "plant"]
    )
    rows = run_container(fmu, 0.25)
    ours = master_like_container(archives["observer"], False, 0.25)
    assert worst(rows, ours)[0] > 1.0
