"""The fuzz targets and how to build them (used by benchmarks/fuzz.py and
tests/test_fuzz_corpora.py).

C targets (fuzz/c/*.c): compiled with clang together with the sources/ that a native FMU ships
(its buildDescription.xml names the files), either for libFuzzer (-fsanitize=fuzzer,address,
undefined) or, for replaying the corpus in the tests, with the harness's own main() (address and
undefined sanitizers only). Python targets (fuzz/py/*.py): each has ``entry(data: bytes)``,
which must return or raise nothing but the documented error class of what it feeds.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

FUZZ = Path(__file__).resolve().parent
REPO = FUZZ.parent
CORPUS = FUZZ / "corpus"

# C target name -> (harness, FMU path inside `impedance-cosim build --out`, extra defines)
C_TARGETS = {
    "fmi2_state_plant": ("state.c", "native/PumaPlant.fmu", []),
    "fmi2_state_controller": ("state.c", "native/ImpedanceController.fmu", []),
    "fmi3_state_plant": ("state.c", "fmi3/PumaPlant.fmu", ["-DFUZZ_FMI3"]),
    "fmi3_state_controller": ("state.c", "fmi3/ImpedanceController.fmu", ["-DFUZZ_FMI3"]),
    "fmi2_calls_plant": ("calls.c", "native/PumaPlant.fmu", []),
    "fmi2_calls_controller": ("calls.c", "native/ImpedanceController.fmu", []),
    "fmi3_calls_plant": ("calls3.c", "fmi3/PumaPlant.fmu", []),
    "fmi3_calls_controller": ("calls3.c", "fmi3/ImpedanceController.fmu", []),
    "closedloop_params": ("closedloop.c", "fmi3/PaperClosedLoop-observer.fmu", []),
}
PY_TARGETS = sorted(p.stem for p in (FUZZ / "py").glob("*.py") if not p.stem.startswith("_"))
SANITIZE = "-fsanitize=address,undefined"


def clang() -> str | None:
    return shutil.which(os.environ.get("CC_FUZZ", "clang"))


@functools.cache
def build_fmus(out: Path) -> Path:
    """The native FMUs of the current sources built into OUT, once per process: FMUs left from
    older sources would fuzz old code (the build cache makes this quick)."""
    subprocess.run(
        [sys.executable, "-m", "impedance_cosim", "build", "--out", str(out)],
        check=True,
        capture_output=True,
        text=True,
    )
    return out


def extract_sources(fmu: Path, dest: Path) -> list[Path]:
    """The FMU's sources/ into DEST; the C files its buildDescription.xml lists."""
    with zipfile.ZipFile(fmu) as z:
        for name in z.namelist():
            if name.startswith("sources/") and not name.endswith("/"):
                (dest / Path(name).name).write_bytes(z.read(name))
    tree = ET.parse(dest / "buildDescription.xml")
    return [dest / f.get("name") for f in tree.iter("SourceFile")]


def build_c(name: str, fmus: Path, work: Path, libfuzzer: bool) -> Path:
    """Compile C target NAME: for libFuzzer, or as a replay binary (the harness's main())."""
    harness, fmu, defines = C_TARGETS[name]
    src = work / f"{name}-src"
    src.mkdir(parents=True, exist_ok=True)
    files = extract_sources(fmus / fmu, src)
    exe = work / (name + ("" if libfuzzer else "-replay"))
    flags = [
        "-g",
        "-O1" if libfuzzer else "-O0",
        "-fno-omit-frame-pointer",
        "-fno-sanitize-recover=undefined",
    ]
    if libfuzzer:
        flags += ["-fsanitize=fuzzer," + SANITIZE.split("=", 1)[1], "-DFUZZ_LIBFUZZER"]
    else:
        flags += [SANITIZE]
    cmd = [clang() or "clang", *flags, *defines, "-I", str(src), "-o", str(exe)]
    cmd += [str(f) for f in files] + [str(FUZZ / "c" / harness), "-lm"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return exe


def corpus(name: str) -> list[Path]:
    folder = CORPUS / name
    return sorted(p for p in folder.iterdir() if p.is_file()) if folder.is_dir() else []


def work_dir() -> Path:
    """Where builds, runs and findings go (IMPCOSIM_FUZZ_WORK, else a folder in /tmp)."""
    return Path(os.environ.get("IMPCOSIM_FUZZ_WORK", "/tmp/impcosim-fuzz"))


def python_module(name: str):
    """The Python target NAME's module (fuzz/py/NAME.py), imported once."""
    import importlib

    py = str(FUZZ / "py")
    if py not in sys.path:
        sys.path.insert(0, py)
    return importlib.import_module(name)


def write_seeds(name: str, dest: Path, work: Path) -> None:
    """A few valid inputs of target NAME into DEST (the start of its corpus)."""
    dest.mkdir(parents=True, exist_ok=True)
    if name in C_TARGETS:
        exe = build_c(name, build_fmus(work / "fmus"), work / "build", libfuzzer=False)
        subprocess.run([str(exe), "--seed", str(dest)], check=True, capture_output=True)
        return
    seeds: dict[str, bytes] = {}
    if name == "datagram":
        from bridge_model import protocol as p

        key = python_module("datagram").KEY
        seeds = {
            "init": b"\x01" + p.pack(key, p.INIT, 0, 7, 0.0, 0.0, [1.0] * 12, stamp_ns=1),
            "step": b"\x01" + p.pack(key, p.STEP, 3, 7, 0.5, 0.0025, [1.0, 2.0, 3.0], stamp_ns=2),
            "error": b"\x00" + p.pack(key, p.ERROR, 1, 7, 0, 0, text="bad", code=p.SEQUENCE),
        }
    elif name == "sweep_grid":
        seeds = {
            "list": b"controller.K=1,2,3.5",
            "lin": b"plant.wall_k=lin:1e3:1e5:5",
            "log": b"plant.wall_k=log:1e3:1e5:4",
            "range": b"controller.B=range:0:10",
            "logrange": b"controller.B=logrange:1:10",
            "text": b"controller.velocity_source=observer,difference",
        }
    elif name in ("robot_session", "result_files", "cli_options", "ssm"):
        seeds = python_module(name).seeds()
    elif name in ("ssp1", "ssp2"):
        seeds = python_module(name).TARGET.seeds()
    for stem, data in seeds.items():
        (dest / stem).write_bytes(data)
