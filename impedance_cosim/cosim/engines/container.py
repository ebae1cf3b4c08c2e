"""An archive as one container FMU (fmu-manipulation-toolbox 2.0's `fmucontainer`), run under
`fmpy simulate`: a fourth importer of our systems, beside engines.py's libcosim, ecospy and fmpy.

`pip install fmu-manipulation-toolbox==2.0` (the dev extra has it). What the container does with
our archives, read from its documentation and measured on runs here:

- Input: a JSON description (its documented format: "fmu", "link", "output", "start",
  "sequential", "step_size"), which `container_description` writes from an archive read by our
  own reader: the FMUs in the SSD's Element order, every connection as a link, every Real output
  of every component exposed as "component.variable", and the archive's parameter set as start
  values. fmucontainer also reads an .ssp itself ("ALPHA"), but then ignores ParameterBindings
  and exposes no output that is linked, so the JSON route is the one that runs a scenario.
- The loop: it cuts the loop of links before the first FMU it lists; that FMU reads its inputs
  from link buffers (0.0 at initialization, not the start values), the others read the current
  outputs. Our SSDs list the plant first (system.SSD_ELEMENT_ORDER): the plant gets the held
  torque, and the controller is initialized from the plant's initial outputs. (Listed first, the
  controller was initialized at q = 0, the stretched arm: it refused before issue 22, and now
  starts with gravity compensation only, a different run.)
- parallel (default): every FMU steps from t_i on the outputs at t_i, i.e. Jacobi, equal to
  `RunOptions(algorithm="jacobi")`; sequential (`-sequential`): Gauss-Seidel in listing order,
  equal to `RunOptions(algorithm="gauss-seidel")` with the order the SSD lists (plant, then
  controller; our default order is the annotation's, controller first: the paper's
  sample-and-hold). Measured: bit-identical in both modes over the 20 s observer scenario (same
  time grid t_0 + i h: fmpy's CS loop does not accumulate time); `master_like_container` makes
  that master run, tests/test_containers.py checks every scenario.
- Every run logs `[ERROR] Solver configure....` on success too (a message of the container's
  library): it is not an error.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.cosim.engines.others import EngineError, typed_value

FMUCONTAINER = "from fmu_manipulation_toolbox.cli.fmucontainer import fmucontainer; fmucontainer()"


def container_description(
    system: Any,
    name: str,
    sequential: bool,
    parameter_set: str | None,
    step_size: float,
    order: list[str] | None = None,
) -> dict[str, Any]:
    """fmucontainer's JSON for a read archive (a SystemDescription, extracted): FMUs by their
    archive file names in SSD order (or `order`), links, every Real output, the set's values
    as start values."""
    from fmpy import read_model_description

    files = {c.name: Path(c.source).name for c in system.components}
    listed = order or [c.name for c in system.components]
    outputs = []
    for c in system.components:
        md = read_model_description(str(c.fmu), validate=False)
        outputs += [
            [files[c.name], v.name, f"{c.name}.{v.name}"]
            for v in md.modelVariables
            if v.causality == "output" and v.type in ("Real", "Float64")
        ]
    starts = []
    for p in system.parameter_sets.get(parameter_set, []) if parameter_set else []:
        component, variable = p.name.split(".", 1)
        starts.append([files[component], variable, typed_value(p.value, p.type)])
    return {
        "name": name,
        "sequential": sequential,
        "step_size": step_size,
        "fmu": [files[n] for n in listed],
        "link": [[files[a], b, files[c], d] for a, b, c, d in system.connections],
        "output": outputs,
        "start": starts,
    }


def build_container(
    ssp_path: str | Path,
    out: str | Path,
    sequential: bool = False,
    parameter_set: str | None = None,
    step_size: float = 0.0025,
    order: list[str] | None = None,
) -> Path:
    """Build the container FMU `out` from an archive (parameter_set None: the archive's first
    set, the only one of a scenario's own archive; order: the components in another order than
    the SSD's, to show what the order does). Raises EngineError when fmucontainer fails."""
    from impedance_cosim.cosim.ssp.read import read_ssp

    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="impcosim_container_") as tmp:
        work = Path(tmp)
        with read_ssp(ssp_path) as system:
            sets = list(system.parameter_sets)
            chosen = parameter_set if parameter_set is not None else (sets[0] if sets else None)
            if chosen is not None and chosen not in sets:
                raise ValueError(f"no parameter set {chosen!r} in {ssp_path} (have {sets})")
            desc = container_description(system, out.name, sequential, chosen, step_size, order)
            for c in system.components:
                shutil.copy(c.fmu, work / Path(c.source).name)
        (work / "container.json").write_text(json.dumps(desc, indent=1))
        args = ["-container", "container.json", "-fmu-directory", str(work)]
        done = subprocess.run(
            [sys.executable, "-c", FMUCONTAINER, *args],
            cwd=work, capture_output=True, text=True, check=False,
        )  # fmt: skip
        built = work / out.name
        if done.returncode != 0 or not built.is_file():
            lines = [ln for ln in (done.stdout + done.stderr).splitlines() if "ERROR" in ln]
            raise EngineError(f"fmucontainer failed on {ssp_path}: {' '.join(lines[-2:])}")
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(built, out)
    return out


def run_container(
    fmu: str | Path, stop_time: float, step_size: float = 0.0025
) -> dict[str, np.ndarray]:
    """`fmpy simulate` on a container FMU (a process of its own), one row per step: "time" and
    every output, the outputs after initialization first. Raises EngineError when it fails."""
    with tempfile.TemporaryDirectory(prefix="impcosim_container_run_") as tmp:
        csv = Path(tmp) / "rows.csv"
        done = subprocess.run(
            [sys.executable, "-m", "fmpy", "simulate", str(fmu), "--stop-time", repr(stop_time),
             "--step-size", repr(step_size), "--output-interval", repr(step_size),
             "--output-file", str(csv)],
            capture_output=True, text=True, check=False,
        )  # fmt: skip
        if done.returncode != 0 or not csv.is_file():
            tail = (done.stderr.strip().splitlines() or ["no message"])[-1]
            raise EngineError(f"fmpy simulate {Path(fmu).name} failed: {tail}")
        with csv.open() as f:
            names = [n.strip('"') for n in f.readline().strip().split(",")]
        values = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    return {name: values[:, k] for k, name in enumerate(names)}


def master_like_container(
    ssp_path: str | Path, sequential: bool, stop_time: float, parameter_set: str | None = None
) -> Any:
    """Our master's run of the container's algorithm: Jacobi (parallel), or Gauss-Seidel in the
    SSD's listing order (sequential). Returns the RunResult (divergence limit off: compare as
    far as both run)."""
    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.ssp.read import read_ssp

    with read_ssp(ssp_path) as system:
        if sequential:
            system.order = [c.name for c in system.components]
        algorithm = "gauss-seidel" if sequential else "jacobi"
        options = RunOptions(parameter_set=parameter_set, algorithm=algorithm, stop_time=stop_time,
                             divergence_limit=1e300)  # fmt: skip
        return Master(system, options).run()
