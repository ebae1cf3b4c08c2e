"""Per-step master overhead of every engine here, on the same FMUs and the same 8000 steps
(not a test: prints the table of docs/overhead.md).

The system: the paper scenario's own archive (fmus/PaperScenario-native-observer.ssp: the
native controller and plant FMUs, FMI 2.0, the observer set bound in it), 20 s at 400 Hz.

- Each engine's time per step: (CPU time of a 8000-step run - of a 80-step run) / 7920, best
  of --repeat runs of each (CPU time of this process, every thread: every engine here runs in
  it; on a shared machine the time spent waiting for a core is not counted, wall time is):
  what loading, instantiating and initializing cost is the same in both and drops out; what
  is left is the stepping with everything the engine does per step.
- The FMUs' own compute per step: each FMU stepped alone, with no master (benchmarks/
  fmu_alone.c, compiled here: before each fmi2DoStep its inputs are set from the values it got
  in our co-simulation, so it computes what it computed there; its outputs at the end are
  checked equal to the co-simulation's, bit for bit). Gauss-Seidel and Jacobi give different
  inputs, so each has its own figure.
- Master overhead per step = the engine's time per step - the FMUs' compute per step (of the
  engine's algorithm): exchanging the connected values, the engine's bookkeeping, recording.

Engines: ours (Gauss-Seidel and Jacobi, the C loop and the Python loop; records every output
into memory), fmpy 0.3.32 `simulate_ssp` (Jacobi; records every connector; started from the
FMUs' start values, see master_speed.py), libcosim (libcosimpy 0.0.6, fixed-step Jacobi; a
time-series observer on every output), ecospy 0.7.2 (Jacobi; `step(n)`, nothing recorded: its
only recorders write CSV or call Python per step), and the FMU container of
fmu-manipulation-toolbox 2.0 (built here with its own Python API: the plant listed first, links
from the SSD, the observer set as start values, every output exposed; its parallel mode is a
Jacobi master) run by fmpy's `simulate_fmu` (records the exposed outputs).

    pip install fmu-manipulation-toolbox==2.0     # the container row (skipped without it)
    python benchmarks/master_overhead.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import ctypes
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from impedance_cosim.cosim.engines.others import run_in_libcosim
from impedance_cosim.cosim.master import master as master_module
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

HERE = Path(__file__).resolve().parent
ARCHIVE = HERE.parent / "fmus" / "PaperScenario-native-observer.ssp"
H = 1 / 400
LONG, SHORT = 8000, 80  # steps


def alone_library() -> ctypes.CDLL:
    """benchmarks/fmu_alone.c compiled into a temporary folder (kept for this process)."""
    out = Path(tempfile.mkdtemp(prefix="impcosim_alone_")) / "fmu_alone.so"
    subprocess.run([os.environ.get("CC", "gcc"), "-std=c99", "-O2", "-fPIC", "-shared",
                    str(HERE / "fmu_alone.c"), "-o", str(out)], check=True)  # fmt: skip
    lib = ctypes.CDLL(str(out))
    lib.step_alone.restype = ctypes.c_double
    lib.step_alone.argtypes = [ctypes.c_void_p] * 3 + [
        ctypes.POINTER(ctypes.c_uint), ctypes.c_int, ctypes.c_void_p, ctypes.c_double,
        ctypes.c_double, ctypes.c_long,
    ]  # fmt: skip
    return lib


def fmus_alone(lib: ctypes.CDLL, system, algorithm: str) -> float:
    """Seconds per step of the FMUs' own compute (sum over the FMUs, each stepped alone on the
    inputs it got in our co-simulation with `algorithm`; see the module docstring)."""
    recorded = Master(system, RunOptions(algorithm=algorithm)).run()
    assert recorded.ok and len(recorded.data) == LONG + 1, recorded.error
    m = Master(system, RunOptions(algorithm=algorithm))
    ordered = [master_module._Slot(n, master_module.open_fmu(m.fmu_files[n], n)) for n in m.order]
    try:
        m._wire(ordered)
        m._initialize(ordered)
        total = 0.0
        for k, s in enumerate(ordered):
            # Gauss-Seidel: a component stepped before this one in the step feeds its new
            # outputs (row i + 1), the others their outputs at t_i (row i); Jacobi: all row i
            cols, late = [], []
            for j, out in s.sources:
                cols.append(recorded.names.index(f"{ordered[j].name}.{ordered[j].outputs[out]}"))
                late.append(algorithm == "gauss-seidel" and j < k)
            rows = np.arange(LONG)
            inputs = np.empty((LONG, len(cols)))
            for c, (col, shifted) in enumerate(zip(cols, late, strict=True)):
                inputs[:, c] = recorded.data[rows + 1 if shifted else rows, col]
            vr = (ctypes.c_uint * max(1, len(s.inputs)))(*(s.fmu.vr(n) for n in s.inputs))
            functions = s.fmu.slave._functions
            seconds = lib.step_alone(
                s.fmu.slave.component,
                ctypes.cast(functions["fmi2SetReal"], ctypes.c_void_p).value,
                ctypes.cast(functions["fmi2DoStep"], ctypes.c_void_p).value,
                vr, len(cols), inputs.ctypes.data, m.start_time, H, LONG,
            )  # fmt: skip
            assert seconds >= 0, f"{s.name}: a call failed stepping alone"
            final = recorded.data[-1, [recorded.names.index(f"{s.name}.{o}") for o in s.outputs]]
            assert np.array_equal(np.array(s.read()), final), f"{s.name}: not the same steps"
            total += seconds
        return total / LONG
    finally:
        for s in ordered:
            s.fmu.terminate()
            s.fmu.free()


def best(fn: Callable[[int], object], steps: int, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.process_time()
        fn(steps)
        times.append(time.process_time() - start)
    return min(times)


def per_step(fn: Callable[[int], object], repeat: int) -> float:
    """Seconds per step of an engine: (best long run - best short run) / the steps between."""
    fn(SHORT)  # warm: libraries loaded, caches filled
    return (best(fn, LONG, repeat) - best(fn, SHORT, repeat)) / (LONG - SHORT)


def ours(system, algorithm: str, loop: str) -> Callable[[int], object]:
    def run(steps: int) -> None:
        result = Master(
            system, RunOptions(algorithm=algorithm, loop=loop, stop_time=steps * H)
        ).run()
        assert result.ok and result.info["loop"] == loop, result.error

    return run


def fmpy_ssp(steps: int) -> None:
    sys.path.insert(0, str(HERE))
    from master_speed import time_fmpy  # beside this script: starts from the start values

    time_fmpy(ARCHIVE, steps * H, H)


def libcosim(steps: int) -> None:
    run_in_libcosim(ARCHIVE, None, steps * H, H, log_level="error")


def ecospy(steps: int) -> None:
    import ecospy as eco

    sim = eco.EcosSimulation(step_size=H, ssp_path=str(ARCHIVE))
    try:
        assert sim.init(parameter_set="observer"), "ecospy could not initialize"
        sim.step(steps)
        sim.terminate()
    finally:
        sim.free()


def build_container(system, folder: Path) -> Path:
    """The two FMUs in one container FMU (fmu-manipulation-toolbox's AssemblyNode): the plant
    first (the toolbox starts the first FMU listed from its link buffers, 0.0: zero torques for
    the plant, where zero joint angles would be the controller's singular pose), the SSD's
    links, the observer set's values as start values, every output exposed, parallel mode."""
    from fmu_manipulation_toolbox.assembly import AssemblyNode

    names = {c.name: Path(c.fmu) for c in system.components}
    for name, path in names.items():
        (folder / f"{name}.fmu").write_bytes(path.read_bytes())
    node = AssemblyNode("container.fmu", step_size=H, auto_link=False, auto_input=False,
                        auto_output=False)  # fmt: skip
    for name in ("plant", "controller"):
        node.add_fmu(f"{name}.fmu")
    for se, sc, ee, ec in system.connections:
        node.add_link(f"{se}.fmu", sc, f"{ee}.fmu", ec)
    for p in system.parameter_sets["observer"]:
        component, variable = p.name.split(".", 1)
        value = str(p.value).lower() if isinstance(p.value, bool) else str(p.value)
        node.add_start_value(f"{component}.fmu", variable, value)
    for name in names:
        for out in master_module.real_outputs(read_descriptions(names)[name]):
            node.add_output(f"{name}.fmu", out, f"{name}_{out}")
    node.make_fmu(folder)
    return folder / "container.fmu"


def read_descriptions(files: dict[str, Path]):
    from impedance_cosim.cosim.master.setup import read_descriptions as read

    return read(files)


def container(path: Path) -> Callable[[int], object]:
    from fmpy import simulate_fmu

    def run(steps: int) -> None:
        simulate_fmu(str(path), stop_time=steps * H, step_size=H, output_interval=H,
                     fmi_type="CoSimulation")  # fmt: skip

    return run


def container_equals_ours(path: Path, system) -> bool:
    """Every exposed output of the container's 8000 steps equal to our Jacobi master's, bit for
    bit (it reports what the toolbox's parallel mode computes)."""
    from fmpy import simulate_fmu

    theirs = simulate_fmu(str(path), stop_time=LONG * H, step_size=H, output_interval=H,
                          fmi_type="CoSimulation")  # fmt: skip
    mine = Master(system, RunOptions(algorithm="jacobi")).run()
    names = [n for n in theirs.dtype.names if n != "time"]
    return len(theirs) == len(mine.data) and all(
        np.array_equal(theirs[n], mine[n.replace("_", ".", 1)]) for n in names
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs of each length (best)")
    args = parser.parse_args()
    if not ARCHIVE.is_file():
        from impedance_cosim.packaging.build_all import build_all

        build_all()
    load = os.getloadavg()[0]
    lib = alone_library()
    with read_ssp(ARCHIVE) as system, tempfile.TemporaryDirectory() as tmp:
        compute = {a: min(fmus_alone(lib, system, a) for _ in range(args.repeat))
                   for a in ("gauss-seidel", "jacobi")}  # fmt: skip
        engines: list[tuple[str, str, Callable[[int], object] | None, str]] = []
        for algorithm in ("gauss-seidel", "jacobi"):
            for loop in ("c", "python"):
                engines.append((f"ours, {algorithm}, {loop.replace('c', 'C')} loop", algorithm,
                                ours(system, algorithm, loop), ""))  # fmt: skip
        engines += [("fmpy simulate_ssp", "jacobi", fmpy_ssp, ""),
                    ("libcosim (libcosimpy)", "jacobi", libcosim, ""),
                    ("ecospy (nothing recorded)", "jacobi", ecospy, "")]  # fmt: skip
        try:
            packed = build_container(system, Path(tmp))
            engines.append(("container FMU under fmpy", "jacobi", container(packed), ""))
            same = container_equals_ours(packed, system)
        except ImportError:
            engines.append(("container FMU under fmpy", "jacobi", None, "not installed"))
            same = None
        rows = []
        for name, algorithm, fn, note in engines:
            try:
                rows.append((name, algorithm, per_step(fn, args.repeat) if fn else None, note))
            except Exception as exc:  # noqa: BLE001 (an engine that fails is a row saying why)
                rows.append((name, algorithm, None, f"{type(exc).__name__}: {exc}"[:80]))
    print(f"{LONG} steps of 1/400 s, native FMUs ({ARCHIVE.name}); best of {args.repeat}; "
          f"{os.cpu_count()} cores, load average {load:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end")  # fmt: skip
    for algorithm, seconds in compute.items():
        print(f"the FMUs' own compute, stepped alone on the {algorithm} inputs: "
              f"{1e6 * seconds:.2f} us per step")  # fmt: skip
    if same is not None:
        print(f"the container's outputs equal our Jacobi master's, bit for bit: {same}")
    print("| engine | algorithm | CPU us per step | master overhead us per step | x ours C |")
    print("|---|---|---|---|---|")
    base = {a: next(t - compute[a] for n, al, t, _ in rows if al == a and "C loop" in n)
            for a in compute}  # fmt: skip
    for name, algorithm, seconds, note in rows:
        if seconds is None:
            print(f"| {name} | {algorithm} | - | - | - ({note}) |")
            continue
        overhead = seconds - compute[algorithm]
        ratio = f"{overhead / base[algorithm]:.0f}x" if base[algorithm] > 5e-8 else "-"
        print(f"| {name} | {algorithm} | {1e6 * seconds:.2f} | {1e6 * overhead:.2f} | {ratio} |")


if __name__ == "__main__":
    main()
