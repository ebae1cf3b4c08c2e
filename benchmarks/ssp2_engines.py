"""Which engine installed here reads the SSP 2.0 edition (not a test: prints the table of
docs/ssp2.md, as Markdown).

    python benchmarks/ssp2_engines.py [--stop 1.0]

Each engine gets the FMI 3.0 system as SSP 1.0 (fmus/PaperScenario-fmi3.ssp, Co-Simulation
controller) and as SSP 2.0 (fmus/PaperScenario-fmi3-ssp2.ssp, clocked controller), observer
scenario, --stop seconds, each attempt in a process of its own (an engine may abort the process).
A cell says whether it ran and, if not, the first line of its error; where it ran, the largest
difference of the connected signals from our master's Jacobi run of the SSP 1.0 archive (ours:
its own Gauss-Seidel default, compared with our Gauss-Seidel run). Engines: our master,
libcosim (libcosimpy), ecospy, fmpy's simulate_ssp, and fmu-manipulation-toolbox's fmucontainer
on the .ssp itself, its container run under `fmpy simulate`; and pyssp-standard's SSD class,
which reads SSP files but runs nothing. Build first: impedance-cosim build.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

FMUS = Path(__file__).resolve().parent.parent / "fmus"
ARCHIVES = {"SSP 1.0": "PaperScenario-fmi3.ssp", "SSP 2.0": "PaperScenario-fmi3-ssp2.ssp"}
ENGINES = ("ours", "libcosim", "ecospy", "fmpy simulate_ssp", "fmucontainer", "pyssp-standard")
SIGNALS = [f"controller.tau{i}" for i in (1, 2, 3)] + [f"plant.q{i}" for i in (1, 2, 3)]
H = 0.0025


def _ours(archive: Path, stop: float, algorithm: str) -> dict[str, np.ndarray]:
    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.ssp.read import read_ssp

    with read_ssp(archive) as system:
        run = Master(
            system, RunOptions(parameter_set="observer", algorithm=algorithm, stop_time=stop)
        ).run()
    if run.error:
        raise RuntimeError(run.error)
    return {name: run[name] for name in SIGNALS}


def _container(archive: Path, stop: float) -> dict[str, np.ndarray]:
    """fmucontainer on the .ssp itself, then fmpy simulate on the container (no signal to
    compare: from an .ssp it exposes no linked output)."""
    from impedance_cosim.cosim.engines.container import FMUCONTAINER, run_container

    with tempfile.TemporaryDirectory(prefix="impcosim_ssp2_") as tmp:
        shutil.copy(archive, Path(tmp) / "system.ssp")
        done = subprocess.run(
            [sys.executable, "-c", FMUCONTAINER, "-container", f"system.ssp:{H}"],
            cwd=tmp,
            capture_output=True,
            text=True,
        )
        if not (Path(tmp) / "system.fmu").is_file():
            text = done.stdout + done.stderr
            lines = [
                s.split("|", 1)[-1] for s in text.splitlines() if "CRITICAL" in s or "ERROR" in s
            ]
            raise RuntimeError((lines or [f"exit status {done.returncode}"])[0].strip())
        run_container(Path(tmp) / "system.fmu", stop)
    return {}


def _pyssp(archive: Path) -> str:
    """pyssp-standard's SSD class (a reader and writer, not an engine) on SystemStructure.ssd."""
    import zipfile

    from pyssp_standard.ssd import SSD

    with tempfile.TemporaryDirectory(prefix="impcosim_ssp2_") as tmp:
        with zipfile.ZipFile(archive) as z:
            z.extract("SystemStructure.ssd", tmp)
        with SSD(Path(tmp) / "SystemStructure.ssd") as ssd:
            n = len(ssd.connections())
            return f"reads it (version {ssd.version}, {n} connections)"


def attempt(engine: str, archive: Path, stop: float) -> dict[str, np.ndarray] | str:
    """One engine on one archive: the SIGNALS it computed (may be fewer), or what it read."""
    from impedance_cosim.cosim.engines import others as engines

    if engine == "pyssp-standard":
        return _pyssp(archive)

    if engine == "ours":
        return _ours(archive, stop, "gauss-seidel")
    if engine == "libcosim":
        return engines.run_in_libcosim(archive, None, stop, H, "error")
    if engine == "ecospy":
        return engines.run_in_ecospy(archive, "observer", stop, H, SIGNALS)
    if engine == "fmpy simulate_ssp":
        rows = engines.run_in_fmpy(archive, stop, H)
        return {name: np.concatenate([[np.nan], rows[name]]) for name in SIGNALS if name in rows}
    return _container(archive, stop)


def child(engine: str, archive: Path, stop: float) -> None:
    """Run one attempt and print its outcome as one JSON line (stdout of the engine captured)."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stdout(captured):
            theirs = attempt(engine, archive, stop)
            if isinstance(theirs, str):  # a reader: what it read is the cell
                print(json.dumps({"runs": True, "diff": None, "note": theirs}), file=sys.__stdout__)
                return
            reference = _ours(
                FMUS / ARCHIVES["SSP 1.0"], stop, "gauss-seidel" if engine == "ours" else "jacobi"
            )
        diffs = [np.nanmax(np.abs(theirs[k] - reference[k])) for k in SIGNALS if k in theirs]
        out = {"runs": True, "diff": max(diffs) if diffs else None}
    except Exception as exc:  # the engine's own words are the cell
        lines = [s.strip() for s in str(exc).splitlines() if s.strip()] or [type(exc).__name__]
        first = lines[0]
        if first.endswith(":"):  # fmpy: "Failed to validate ...:", its reasons printed before
            printed = [s for s in captured.getvalue().splitlines() if s.startswith("ERROR")]
            first += " " + (printed[0] if printed else " ".join(lines[1:2]))
        out = {"runs": False, "error": _short(first, archive)}
    print(json.dumps(out))


def _short(text: str, archive: Path) -> str:
    """An error line without the machine's paths and with the SSP namespaces as prefixes."""
    text = re.sub(r"/tmp/[\w.-]+/", "/tmp/.../", text.replace(str(archive), archive.name))
    for prefix, tag in (("ssd", "SystemStructureDescription"), ("ssc", "SystemStructureCommon")):
        text = text.replace("{http://ssp-standard.org/SSP1/" + tag + "}", prefix + ":")
    return text


def cell(engine: str, archive: Path, stop: float) -> str:
    """A table cell from a child process (a crash of the engine is a cell too)."""
    done = subprocess.run(
        [sys.executable, __file__, "--child", engine, str(archive), "--stop", str(stop)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    lines = [s for s in done.stdout.splitlines() if s.startswith("{")]
    if not lines:
        return f"crashed (exit status {done.returncode})"
    out = json.loads(lines[-1])
    if not out["runs"]:
        error = out["error"].replace("|", "/")
        return f"no: {error[:240]}{'...' if len(error) > 240 else ''}"
    if out.get("note"):
        return out["note"]
    return "yes" + ("" if out["diff"] is None else f", max diff {out['diff']:.2g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop", type=float, default=1.0)
    parser.add_argument("--child", nargs=2, metavar=("ENGINE", "ARCHIVE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], Path(args.child[1]), args.stop)
        return
    missing = [n for n in ARCHIVES.values() if not (FMUS / n).is_file()]
    if missing:
        sys.exit(f"error: {', '.join(missing)} missing in {FMUS}: run `impedance-cosim build`")
    print(
        f"observer scenario, {args.stop:g} s; max diff: connected signals vs our master"
        " (Jacobi; ours: Gauss-Seidel), SSP 1.0 archive\n"
    )
    print("| engine | " + " | ".join(f"{k} (`{v}`)" for k, v in ARCHIVES.items()) + " |")
    print("|---|" + "---|" * len(ARCHIVES))
    for engine in ENGINES:
        cells = [cell(engine, FMUS / name, args.stop) for name in ARCHIVES.values()]
        print(f"| {engine} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
