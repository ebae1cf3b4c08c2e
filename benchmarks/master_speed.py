"""Time the 20 s paper scenario: our master vs fmpy's simulate_ssp on the same SSP (not a test).

Prints wall times, real-time factors, and each master's overhead per step, estimated as
(wall time - the plain models' compute time for the same loop) / steps.

fmpy's simulate_ssp starts every connector at 0.0, so the controller's first inputs are the joint
angles (0, 0, 0), the stretched-arm singularity, and it refuses the step. To time it at all, this
script starts the connectors at the FMUs' own start values instead (a wrapper around fmpy's
instantiate_fmu); that costs nothing per step. simulate_ssp also ignores the SSD's parameter
bindings and cannot set String parameters: it gets the observer set's Real parameters.

    python benchmarks/master_speed.py [--stop 20]
"""

from __future__ import annotations

import argparse
import time
import zipfile
from pathlib import Path

from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.plain_loop import run_models
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.packaging.build import DEFAULT_OUT
from impedance_cosim.packaging.build_all import build_all


def time_fmpy(ssp: Path, stop: float, step: float) -> float:
    import fmpy.ssp.simulation as sim

    from impedance_cosim.cosim.engines.others import fmpy_bindings

    original = sim.instantiate_fmu

    def instantiate_with_start_values(component, *args, **kwargs):
        original(component, *args, **kwargs)
        for connector in component.connectors:
            if connector.kind in ("input", "output"):
                connector.value = sim.get_value(component, connector.name)

    parameters = fmpy_bindings(ssp)  # the archive's default scenario (observer)
    sim.instantiate_fmu = instantiate_with_start_values
    try:
        start = time.perf_counter()
        sim.simulate_ssp(str(ssp), stop_time=stop, step_size=step, parameter_set=parameters)
        return time.perf_counter() - start
    finally:
        sim.instantiate_fmu = original


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stop", type=float, default=20.0)
    args = parser.parse_args()
    ssp = DEFAULT_OUT / "PaperScenario.ssp"
    if not ssp.is_file():
        build_all()
    with zipfile.ZipFile(ssp) as z:
        assert "SystemStructure.ssd" in z.namelist()
    step = 1 / 400
    steps = round(args.stop / step)

    start = time.perf_counter()
    run_models(stop_time=args.stop, step=step)
    t_models = time.perf_counter() - start

    start = time.perf_counter()
    result = Master(read_ssp(ssp), RunOptions(stop_time=args.stop)).run()
    t_ours = time.perf_counter() - start
    assert result.ok, result.error

    t_fmpy = time_fmpy(ssp, args.stop, step)

    print(f"{args.stop:g} s at 400 Hz ({steps} steps), Python FMUs")
    print(f"{'':32} {'wall s':>8} {'x real time':>12} {'overhead us/step':>17}")
    print(f"{'plain models (no FMI)':32} {t_models:8.2f} {args.stop / t_models:12.1f} {'':>17}")
    for name, t in (("our master (Gauss-Seidel)", t_ours), ("fmpy simulate_ssp (Jacobi)", t_fmpy)):
        overhead = 1e6 * (t - t_models) / steps
        print(f"{name:32} {t:8.2f} {args.stop / t:12.1f} {overhead:17.1f}")
    ours, theirs = (t_ours - t_models) / steps, (t_fmpy - t_models) / steps
    print(f"simulate_ssp / our master: {t_fmpy / t_ours:.2f}x wall time, "
          f"{theirs / ours:.2f}x overhead per step")  # fmt: skip


if __name__ == "__main__":
    main()
