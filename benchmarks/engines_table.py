"""Every engine on every scenario's archive: does it run, does it apply the scenario's parameters,
and how far is it from our master's run of the same algorithm (not a test: prints the table of
docs/system.md, as Markdown).

    python benchmarks/engines_table.py [--python]

Engines: libcosim, ecospy (named set, no set, an unknown set name), fmpy's simulate_ssp (the
bindings passed as its parameter_set, and as it is), the fmucontainer FMU under `fmpy simulate`
(parallel, sequential; and built from the .ssp itself, which exposes no linked output and holds
no start value), our master. Each is compared with our master running the same algorithm
on every connected signal: "its conventions" = our master on the engine's time grid, start
inputs and step order (engines.py, containers.py), "ours" = our master's own (t_0 + i h,
connections from the initialized outputs). "parameters applied" reads which velocity the law
was fed (controller.qd_hat1 equal to qd_obs1, to qd_diff1, or to neither: measured); the
observer scenario's values are the FMUs' start values, so there it cannot tell. Jacobi runs of
the difference and measured scenarios diverge (0.4825 s, 2.6075 s), so Jacobi engines run those
to just before. Native FMUs (--python: the Python ones). Build first: impedance-cosim build.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from impedance_cosim.cosim.engines import others
from impedance_cosim.cosim.engines.container import (
    FMUCONTAINER,
    build_container,
    master_like_container,
    run_container,
)
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp
from impedance_cosim.cosim.system.paper import SCENARIOS

H = 0.0025
LAW = ["controller.qd_hat1", "controller.qd_obs1", "controller.qd_diff1"]
JACOBI_STOP = {"observer": 20.0, "difference": 0.45, "measured": 2.5}
FMUS = Path(__file__).resolve().parent.parent / "fmus"


def ours(archive: Path, algorithm: str, stop: float, **conventions) -> dict[str, np.ndarray]:
    with read_ssp(archive) as system:
        result = Master(
            system,
            RunOptions(algorithm=algorithm, stop_time=stop, divergence_limit=1e300, **conventions),
        ).run()
    return {n: result[n] for n in others.CONNECTED + LAW}


def worst(a: dict, b: dict, shift: int = 0) -> float:
    return others.largest_difference(a, b, shift)[0]


def applied(rows: dict, scenario: str) -> str:
    law, observer, difference = (rows[n] for n in LAW)
    ran = (
        "observer"
        if np.array_equal(law, observer)
        else "difference"
        if np.array_equal(law, difference)
        else "measured"
    )
    if scenario == "observer":
        return "(= start values)"
    return "yes" if ran == scenario else f"**no** (ran {ran})"


def fmpy_as_is(archive: Path, stop: float) -> dict[str, np.ndarray]:
    """simulate_ssp without a parameter_set: what a user gets from the archive alone."""
    from fmpy.ssp.simulation import simulate_ssp

    rows = simulate_ssp(str(archive), stop_time=stop, step_size=H)
    n = round(stop / H)
    return {name: rows[name][:n] for name in rows.dtype.names if name != "time"}


def container_from_ssp(archive: Path, work: Path) -> tuple[int, int]:
    """fmucontainer on the .ssp itself (its "ALPHA" SSP input): (outputs the container exposes,
    start values it holds for the embedded FMUs, counted in its resources/container.txt)."""
    folder = work / f"ssp-{archive.stem}"
    folder.mkdir()
    shutil.copy(archive, folder / "system.ssp")
    subprocess.run([sys.executable, "-c", FMUCONTAINER, "-container", f"system.ssp:{H}"],
                   cwd=folder, capture_output=True, check=True)  # fmt: skip
    md = read_model_description(str(folder / "system.fmu"), validate=False)
    outputs = sum(v.causality == "output" for v in md.modelVariables)
    with zipfile.ZipFile(folder / "system.fmu") as z:
        lines = z.read("resources/container.txt").decode().splitlines()
    starts = sum(int(lines[i + 1].split()[0]) for i, line in enumerate(lines)
                 if line.startswith("# Start values of"))  # fmt: skip
    return outputs, starts


def engine_rows(archive: Path, scenario: str, work: Path) -> list[tuple]:
    """(engine, algorithm, stop, runs, applied, vs ours on its conventions, vs ours) rows."""
    stop = JACOBI_STOP[scenario]
    jacobi = ours(archive, "jacobi", stop)
    accumulated = ours(archive, "jacobi", stop, step_times=others.AccumulatedTimes(0.0, H))
    rows = []

    def add(engine: str, algorithm: str, stop: float, run, same: dict, shift: int = 0,
            default: dict | None = None) -> None:  # fmt: skip
        try:
            theirs = run()
        except Exception as exc:  # an engine's failure (EngineError or its own) is a cell
            rows.append((engine, algorithm, f"{stop:g} s", f"fails: {exc}"[:80], "-", "-", "-"))
            return
        on_ours = worst(default, theirs, shift) if default is not None else worst(same, theirs)
        rows.append((engine, algorithm, f"{stop:g} s", "yes", applied(theirs, scenario),
                     f"{worst(same, theirs, shift):.2g}", f"{on_ours:.2g}"))  # fmt: skip

    ns_grid = ours(archive, "jacobi", stop, step_times=others.nanosecond_times(0.0, H))

    def libcosim() -> dict:
        return others.run_in_libcosim(archive, None, stop, H, "error")

    add("libcosim (as is)", "Jacobi", stop, libcosim, ns_grid, default=jacobi)
    names = others.CONNECTED + LAW
    for label, name in ((f"init(parameter_set={scenario!r})", scenario), ("init()", None),
                        ("init(parameter_set='no-such-set')", "no-such-set")):  # fmt: skip
        add(f"ecospy, {label}", "Jacobi", stop,
            lambda name=name: others.run_in_ecospy(archive, name, stop, H, names), accumulated,
            default=jacobi)  # fmt: skip
    fmpy_like = ours(archive, "jacobi", stop, step_times=others.AccumulatedTimes(0.0, H),
                     zero_start_inputs=True)  # fmt: skip
    add("fmpy simulate_ssp, bindings as parameter_set", "Jacobi", stop,
        lambda: others.run_in_fmpy(archive, stop, H), fmpy_like, shift=1,
        default=jacobi)  # fmt: skip
    add("fmpy simulate_ssp (as is)", "Jacobi", stop, lambda: fmpy_as_is(archive, stop),
        fmpy_like, shift=1, default=jacobi)  # fmt: skip
    outputs, starts = container_from_ssp(archive, work)
    rows.append(("fmucontainer on the .ssp itself", "Jacobi", "-", f"builds; {outputs} outputs",
                 f"**no** ({starts} start values)", "-", "-"))  # fmt: skip
    gs = ours(archive, "gauss-seidel", 20.0)
    for sequential, s_stop in ((False, stop), (True, 20.0)):
        mode = "sequential" if sequential else "parallel"
        fmu = build_container(archive, work / f"{scenario}-{mode}.fmu", sequential)
        result = master_like_container(archive, sequential, s_stop)
        same = {n: result[n] for n in others.CONNECTED + LAW}
        add(f"fmucontainer ({mode}) under fmpy simulate",
            "Gauss-Seidel (plant, controller)" if sequential else "Jacobi", s_stop,
            lambda fmu=fmu, s_stop=s_stop: run_container(fmu, s_stop), same,
            default=gs if sequential else jacobi)  # fmt: skip
    rows.append(("our master (the paper's run)", "Gauss-Seidel (controller, plant)", "20 s", "yes",
                 applied(gs, scenario), "0 (reference)", "0"))  # fmt: skip
    return rows


def table(python: bool = False) -> None:
    """Print the table (Markdown) for the native archives (python: the Python FMUs' ones)."""
    prefix = "PaperScenario" if python else "PaperScenario-native"
    archives = {s: FMUS / f"{prefix}-{s}.ssp" for s in SCENARIOS}
    missing = [str(a) for a in archives.values() if not a.is_file()]
    if missing:
        print(f"error: {missing[0]} is missing: run `impedance-cosim build`", file=sys.stderr)
        raise SystemExit(2)
    print(f"archives: fmus/{prefix}-<scenario>.ssp")
    print("| scenario | engine | algorithm | stop | runs | parameters applied "
          "| vs our master, its conventions | vs our master, ours |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="engines_table_") as tmp:
        for scenario, archive in archives.items():
            for row in engine_rows(archive, scenario, Path(tmp)):
                print(f"| {scenario} | " + " | ".join(row) + " |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--python", action="store_true", help="the Python FMUs' archives")
    table(parser.parse_args().python)


if __name__ == "__main__":
    main()
