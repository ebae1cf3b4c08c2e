"""Build the Python FMUs into fmus/: pythonfmu packs the slave script with the model code, then the
modelDescription.xml is replaced by the complete one written from the model's variable table."""

from __future__ import annotations

import hashlib
import importlib
import shutil
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path

import impedance_cosim
from impedance_cosim.fmi.variables import model_description

REPO = Path(impedance_cosim.__file__).resolve().parent.parent
DEFAULT_OUT = REPO / "fmus"
# The part of impedance_cosim that runs inside the FMUs (standard library only, plus pythonfmu).
FMU_CORE = ("__init__.py", "arm.py", "arm_terms.py", "linalg3.py", "ode.py", "wall.py", "fmi")


@dataclass(frozen=True)
class FmuSpec:
    """A Python FMU: its slave script, its model package and its model class."""

    key: str
    package: str  # e.g. plant_model
    script: str  # slave script file in the package, e.g. PumaPlant.py
    model_class: str  # dotted path of the FmuModel class

    @property
    def model_name(self) -> str:
        return self.script.removesuffix(".py")

    def load_model_class(self):
        module, name = self.model_class.rsplit(".", 1)
        return getattr(importlib.import_module(module), name)


FMUS = {
    "plant": FmuSpec("plant", "plant_model", "PumaPlant.py", "plant_model.model.PlantModel"),
    "controller": FmuSpec(
        "controller",
        "controller_model",
        "ImpedanceController.py",
        "controller_model.model.ControllerModel",
    ),
}


def _stage(src: Path, dst: Path, skip: set[str] = frozenset()) -> None:
    """Copy a package's .py files (recursively), without caches, data or the named files."""
    for f in src.rglob("*.py"):
        if "__pycache__" in f.parts or f.name in skip:
            continue
        target = dst / f.relative_to(src)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(f, target)


def build_fmu(spec: FmuSpec, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build one FMU into out_dir and return its path."""
    from pythonfmu import FmuBuilder  # build-time dependency only

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    package_dir = REPO / spec.package
    with tempfile.TemporaryDirectory(prefix="impcosim_build_") as tmp:
        stage = Path(tmp) / "stage"
        core = stage / "impedance_cosim"
        for item in FMU_CORE:
            src = REPO / "impedance_cosim" / item
            if src.is_dir():
                _stage(src, core / item)
            else:
                core.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, core / item)
        _stage(package_dir, stage / spec.package, skip={spec.script})
        raw = FmuBuilder.build_FMU(
            package_dir / spec.script,
            dest=Path(tmp) / "raw",
            project_files=[core, stage / spec.package],
            needsExecutionTool="false",
        )
        target = out_dir / f"{spec.model_name}.fmu"
        _rewrite_model_description(Path(raw), target, spec)
    return target


def _rewrite_model_description(raw: Path, target: Path, spec: FmuSpec) -> None:
    """Copy the pythonfmu archive, replacing its modelDescription.xml by ours. The GUID is a hash
    of the interface and the bundled code, so identical sources give an identical FMU."""
    cls = spec.load_model_class()
    with zipfile.ZipFile(raw) as zin:
        members = sorted(n for n in zin.namelist() if n != "modelDescription.xml")
        digest = hashlib.sha256()
        for name in members:
            digest.update(name.encode())
            digest.update(zin.read(name))

        def xml(guid: str) -> bytes:
            return model_description(
                model_name=cls.MODEL_NAME,
                description=cls.DESCRIPTION,
                guid=guid,
                variables=cls.variables(),
                default_experiment=cls.DEFAULT_EXPERIMENT,
                generation_tool=f"impedance_cosim {impedance_cosim.__version__} (pythonfmu)",
                output_dependencies=cls.OUTPUT_DEPENDENCIES,
            )

        digest.update(xml(""))
        guid = "{" + str(uuid.UUID(digest.hexdigest()[:32])) + "}"
        tmp_target = target.with_suffix(".fmu.tmp")
        with zipfile.ZipFile(tmp_target, "w", zipfile.ZIP_DEFLATED) as zout:
            for name in ["modelDescription.xml", *members]:
                info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                if name != "modelDescription.xml":
                    info.external_attr = zin.getinfo(name).external_attr
                    zout.writestr(info, zin.read(name))
                else:
                    zout.writestr(info, xml(guid))
        tmp_target.replace(target)


def build_ssp(out_dir: Path = DEFAULT_OUT, name: str = "PaperScenario") -> Path:
    """Pack ssp/ (SystemStructure.ssd, the scenario .ssv files) with the FMUs in out_dir into
    out_dir/<name>.ssp, and validate it against the SSP 1.0 schemas."""
    from fmpy.ssp.ssd import read_ssd

    from impedance_cosim.system import COMPONENTS

    out_dir = Path(out_dir)
    source = REPO / "ssp"
    target = out_dir / f"{name}.ssp"
    tmp_target = target.with_suffix(".ssp.tmp")
    with zipfile.ZipFile(tmp_target, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(source / "SystemStructure.ssd", "SystemStructure.ssd")
        for ssv in sorted(source.glob("*.ssv")):
            z.write(ssv, f"resources/{ssv.name}")
        for comp in COMPONENTS:
            fmu = out_dir / comp.fmu
            if not fmu.is_file():
                raise FileNotFoundError(f"{fmu} is missing: build the FMUs first")
            z.write(fmu, comp.source)
    try:
        read_ssd(str(tmp_target), validate=True)
    except Exception as exc:
        tmp_target.unlink()
        raise ValueError(f"{target.name} does not validate: {exc}") from None
    tmp_target.replace(target)
    return target


def build_all(out_dir: Path = DEFAULT_OUT, only: list[str] | None = None) -> list[Path]:
    """Build the named FMUs (default: all, then the system archive) and return their paths."""
    keys = only or list(FMUS)
    unknown = [k for k in keys if k not in FMUS]
    if unknown:
        raise ValueError(f"unknown FMU {unknown}; choose from {sorted(FMUS)}")
    built = [build_fmu(FMUS[k], out_dir) for k in keys]
    if not only:
        built.append(build_ssp(out_dir))
    return built
