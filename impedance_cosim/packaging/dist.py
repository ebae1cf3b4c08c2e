"""The distribution bundle (`impedance-cosim dist`): what a user downloads, one zip.

It holds every FMU (Python and native, every platform they carry), both system archives, the
arm's robot description files (URDF, MJCF), the reference results (*_ref.csv), the licence, a
generated README and SHA256SUMS. It is reproducible: the FMUs and system archives are built
with fixed dates and modes, and the bundle itself has sorted members, one fixed date and one
fixed mode, so building twice gives the same bytes.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import textwrap
import time
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from impedance_cosim.packaging.archive_out import ArchiveWriteError, write_zip
from impedance_cosim.packaging.build import DEFAULT_OUT, FMUS, NATIVE, REPO
from impedance_cosim.packaging.build_all import build_all
from impedance_cosim.version import __version__

DATE = (2020, 1, 1, 0, 0, 0)  # the date of every member (zip cannot store times before 1980)
NAME = f"impedance-cosim-{__version__}"


def reference_results() -> list[Path]:
    """The reference results kept in the repository (see impedance_cosim.packaging.regression)."""
    from impedance_cosim.packaging.regression import REFERENCES

    return sorted(REFERENCES, key=lambda p: p.name)


def build_dist(dist_dir: Path, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build every FMU and system archive into out_dir, then bundle them into
    dist_dir/impedance-cosim-<version>.zip; return the bundle's path."""
    Path(dist_dir).mkdir(parents=True, exist_ok=True)  # fail before building, not after
    print(f"building every FMU and archive into {out_dir} ...", flush=True)
    started = time.perf_counter()

    def progress(name: str) -> None:
        print(f"  {time.perf_counter() - started:5.1f} s  built {name}", flush=True)

    try:
        built = build_all(Path(out_dir), progress=progress)
    except RuntimeError as exc:  # a failed compile: one message, no traceback
        raise ValueError(str(exc)) from None
    print(f"bundling {len(built)} files into {dist_dir} ...", flush=True)
    return bundle(built, Path(out_dir), Path(dist_dir))


def expected_members() -> list[str]:
    """The archives a complete bundle must hold (relative to its fmus/ folder)."""
    names = [f"{FMUS[k].model_name}.fmu" for k in FMUS]
    native = [k for k in FMUS if (NATIVE / k / "model.c").is_file()]
    names += [f"native/{FMUS[k].model_name}.fmu" for k in native]
    from impedance_cosim.cosim.system.paper import SCENARIOS

    systems = [f"{base}{s}.ssp" for base in ("PaperScenario", "PaperScenario-native")
               for s in ("", *(f"-{name}" for name in SCENARIOS))]  # fmt: skip
    fmi3 = ["PumaPlant", "ImpedanceController", "ImpedanceControllerClocked"] if native else []
    names += [f"fmi3/{n}.fmu" for n in fmi3]
    names += [f"fmi3/arrays/{n}.fmu" for n in fmi3[:2]]  # the array edition (fmi/fmi3_arrays.py)
    loops = [f"{d}/PaperClosedLoop-{s}.fmu" for d in ("native", "fmi3") for s in SCENARIOS]
    names += loops if native else []  # the closed loop as one FMU (packaging/closedloop.py)
    fmi3_systems = ["PaperScenario-fmi3.ssp", "PaperScenario-fmi3-ssp2.ssp",
                    "PaperScenario-fmi3-arrays-ssp2.ssp"] if native else []  # fmt: skip
    return names + systems + fmi3_systems


def robot_members() -> list[str]:
    """The arm's robot description files a complete bundle holds (relative to its fmus/)."""
    from impedance_cosim.packaging.robot_files import MJCF_NAME, URDF_NAME

    return [f"robot/{MJCF_NAME}", f"robot/{URDF_NAME}"]


def bundle(files: list[Path], out_dir: Path, dist_dir: Path) -> Path:
    """Zip the built files (all under out_dir), the references, LICENSE, README and SHA256SUMS
    into dist_dir/<NAME>.zip, reproducibly. ValueError when an expected archive is missing."""
    members: dict[str, bytes] = {}
    for f in files:
        members[f"fmus/{Path(f).resolve().relative_to(out_dir.resolve()).as_posix()}"] = Path(
            f
        ).read_bytes()
    missing = [m for m in expected_members() + robot_members() if f"fmus/{m}" not in members]
    if missing:
        raise ValueError(
            f"the bundle is incomplete, missing {', '.join(missing)}"
            " (the native FMUs need a C compiler: gcc or $CC)"
        )
    for ref in reference_results():
        members[f"reference/{ref.name}"] = ref.read_bytes()
    members["LICENSE"] = (REPO / "LICENSE").read_bytes()
    members["README.txt"] = readme(members).encode("utf-8")
    sums = "".join(f"{hashlib.sha256(members[m]).hexdigest()}  {m}\n" for m in sorted(members))
    members["SHA256SUMS"] = sums.encode()
    dist_dir.mkdir(parents=True, exist_ok=True)
    target = dist_dir / f"{NAME}.zip"
    with write_zip(target) as z:  # whole under its name or not there (archive_out.py)
        for name in sorted(members):
            info = zipfile.ZipInfo(f"{NAME}/{name}", date_time=DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            info.create_system = 3  # Unix, whatever the building machine
            z.writestr(info, members[name])
    return target


def _fmu_line(name: str, data: bytes) -> str:
    """One README line for an FMU: interfaces, platforms, what it is."""
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        md = ET.fromstring(z.read("modelDescription.xml"))
        platforms = sorted({n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")})
        sources = any(n.startswith("sources/") for n in z.namelist())
    kinds = [k for k in ("ModelExchange", "CoSimulation", "ScheduledExecution")
             if md.find(k) is not None]  # fmt: skip
    kinds.insert(0, f"FMI {md.get('fmiVersion')}")
    where = ", ".join(platforms) + (", sources" if sources else "")
    about = textwrap.fill(md.get("description", ""), 94, initial_indent=" " * 6,
                          subsequent_indent=" " * 6)  # fmt: skip
    return f"  {name}\n      {' + '.join(kinds)}; binaries: {where}\n{about}\n"


def fmi_versions(members: dict[str, bytes]) -> str:
    """The FMI standards of the bundle's FMUs, as the README names them ("FMI 2.0 and FMI 3.0")."""
    versions = set()
    for name, data in members.items():
        if name.endswith(".fmu"):
            with zipfile.ZipFile(io.BytesIO(data)) as z:
                versions.add(ET.fromstring(z.read("modelDescription.xml")).get("fmiVersion"))
    return " and ".join(f"FMI {v}" for v in sorted(versions, key=str)) or "FMI"


def readme(members: dict[str, bytes]) -> str:
    """The bundle's README.txt, generated from what it holds."""
    fmus = "".join(_fmu_line(m, d) for m, d in sorted(members.items()) if m.endswith(".fmu"))
    ssps = "".join(f"  {m}\n" for m in sorted(members) if m.endswith(".ssp"))
    refs = "".join(f"  {m}\n" for m in sorted(members) if m.startswith("reference/"))
    robots = "".join(f"  {m}\n" for m in sorted(members) if m.startswith("fmus/robot/"))
    standards = fmi_versions(members)
    title = f"{NAME}: Impedance Control Without Using Velocity Measurements, as {standards} FMUs"
    return f"""{title}
{"=" * len(title)}

The paper's reduced-order velocity observer + impedance controller and its 3-DOF planar
PUMA-560 subset touching a stiff wall, as {standards} FMUs (Co-Simulation; the
native plant and controller also Model Exchange; PaperClosedLoop-<scenario>: the whole closed
loop as one FMU) and SSP 1.0 systems.
Each FMU documents itself: open documentation/index.html inside it (unzip it first); it
lists every variable with unit, range, default and meaning, the equations and the interfaces.

FMUs (fmus/: the Python flavour, which needs a Python host such as fmpy; fmus/native/: the
same models in C99, for any FMI host; fmus/fmi3/: the C99 models as FMI 3.0, the controller
also with its sampling as an FMI 3.0 clock, fmus/fmi3/arrays/ with the joint vectors as FMI 3.0
arrays, and fmus/fmi3/python/ the Python ones):
{fmus}
Systems (SSP 1.0: the two FMUs wired; each scenario (observer, difference, measured) is a system
description binding its own parameter set: in PaperScenario*.ssp as SSP variants
(SystemStructure.ssd = observer, difference.ssd, measured.ssd), and alone in
PaperScenario*-<scenario>.ssp for engines that read only SystemStructure.ssd;
PaperScenario-fmi3-ssp2.ssp is the FMI 3.0 system as SSP 2.0, with the clocked controller, and
PaperScenario-fmi3-arrays-ssp2.ssp with the array FMUs wired by array connectors):
{ssps}
Reference results (CSV; each FMU's default experiment, and the paper's 20 s closed loop):
{refs}
The arm for robotics tools (the plant's parameters as MJCF for MuJoCo and as URDF for Pinocchio
and ROS tools; URDF cannot carry the motor inertias and gravity along -y: set them after
loading, as its header comment says; the project's docs/robotics.md):
{robots}
Run one FMU with fmpy (pip install fmpy):

  fmpy simulate fmus/native/PumaPlant.fmu --output-interval 0.0025
  fmpy simulate fmus/ImpedanceController.fmu --output-interval 0.0025

Run the system with the impedance-cosim package, or with libcosim, ecospy or fmpy (see the
project's README, "Running our FMUs and systems elsewhere"):

  impedance-cosim run --ssp fmus/PaperScenario-native.ssp --scenario difference

SHA256SUMS lists the checksum of every file (sha256sum -c SHA256SUMS).
Licence: BSD-2-Clause, see LICENSE (also inside every FMU, documentation/licenses/).
"""


def cmd_dist(args: argparse.Namespace) -> int:
    """`impedance-cosim dist`: build everything and write the bundle."""
    started = time.perf_counter()
    try:
        path = build_dist(Path(args.out), Path(args.fmus))
    except ArchiveWriteError:  # a full disk: a failed run (exit 1), the line names the file
        raise
    except OSError as exc:  # an unwritable or misnamed folder: one line, not a traceback
        where = exc.filename or args.out
        raise ValueError(f"cannot write {where}: {exc.strerror or exc}") from None
    print(f"wrote {path}")
    print(summary(path, time.perf_counter() - started))
    return 0


def summary(path: Path, seconds: float) -> str:
    """One line on the bundle as measured: its size, members, and the build's wall time."""
    with zipfile.ZipFile(path) as z:
        members = len(z.namelist())
    size = path.stat().st_size
    return (
        f"{path.name}: {size / 1e6:.1f} MB ({size} bytes), {members} files; built and bundled"
        f" in {seconds:.1f} s"
    )


def add_parser(sub) -> None:
    """The `dist` subcommand."""
    p = sub.add_parser("dist", help="build everything and zip the distribution bundle")
    p.add_argument("--out", default="dist", help="where the bundle goes (default dist/), as"
                   " every command's --out names the folder it writes its results to")  # fmt: skip
    p.add_argument("--fmus", default=str(DEFAULT_OUT),
                   help="where the FMUs are built (default: the repository's fmus/)")  # fmt: skip
    p.set_defaults(func=cmd_dist)
