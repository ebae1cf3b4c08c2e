"""Build the Python FMUs into fmus/: pythonfmu packs the slave script with the model code, then the
modelDescription.xml is replaced by the complete one written from the model's variable table."""

from __future__ import annotations

import hashlib
import importlib
import shutil
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

from impedance_cosim.fmi.model_description import model_description
from impedance_cosim.packaging import toolchains
from impedance_cosim.packaging.archive_out import write_zip
from impedance_cosim.packaging.isolate import content_tag, isolate
from impedance_cosim.packaging.pyfmu_guard import guard_binaries
from impedance_cosim.version import __version__

REPO = Path(__file__).resolve().parents[2]  # the checkout (impedance_cosim/packaging/..)
DEFAULT_OUT = REPO / "fmus"
# The part of impedance_cosim that runs inside the FMUs (standard library only, plus pythonfmu):
# the physics and the FMI glue, less the symbolic derivation (sympy, build time only).
FMU_CORE = ("__init__.py", "version.py", "physics", "fmi")
NOT_BUNDLED = frozenset({"derivation.py", "bind_source.py"})


@dataclass(frozen=True)
class FmuSpec:
    """A Python FMU: its slave script, its model package and its model class."""

    key: str
    package: str  # e.g. plant_model
    script: str  # slave script file in the package, e.g. PumaPlant.py
    model_class: str  # dotted path of the FmuModel class
    uses: tuple[str, ...] = ()  # other model packages bundled with it (their code, not slaves)
    resources: tuple[str, ...] = ()  # robot description files it carries (robot_files.py)

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
    "bridge": FmuSpec(
        "bridge",
        "bridge_model",
        "BridgePlant.py",
        "bridge_model.model.BridgeModel",
        uses=("plant_model",),  # the plant's interface, defined once in plant_model.model
    ),
    "pinocchio": FmuSpec(
        "pinocchio",
        "plant_model",
        "PinocchioPlant.py",
        "plant_model.urdf_plant.PinocchioPlantModel",
        resources=("puma3.urdf",),  # the arm it loads with Pinocchio (plant_model/urdf_plant.py)
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


def stage_core(stage: Path) -> Path:
    """Copy the part of impedance_cosim bundled in the Python FMUs into stage; its folder."""
    core = stage / "impedance_cosim"
    for item in FMU_CORE:
        src = REPO / "impedance_cosim" / item
        if src.is_dir():
            _stage(src, core / item, skip=NOT_BUNDLED)
        else:
            core.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, core / item)
    return core


def _stage_resources(spec: FmuSpec, package: Path, scratch: Path) -> str:
    """Copy the robot description files spec carries into its staged package (so the FMU's
    resources hold them beside its code); their text, for the content tag."""
    if not spec.resources:
        return ""
    from impedance_cosim.packaging.robot_files import write_robot_files

    written = {f.name: f for f in write_robot_files(scratch)}
    text = ""
    for name in spec.resources:
        shutil.copy2(written[name], package / name)
        text += written[name].read_text(encoding="utf-8")
    return text


def build_fmu(spec: FmuSpec, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build one FMU into out_dir and return its path."""
    from pythonfmu import FmuBuilder  # build-time dependency only

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    package_dir = REPO / spec.package
    with tempfile.TemporaryDirectory(prefix="impcosim_build_") as tmp:
        stage = Path(tmp) / "stage"
        core = stage_core(stage)
        slaves = {s.script for s in FMUS.values()}
        _stage(package_dir, stage / spec.package, skip=slaves)  # no slave script but its own
        for package in spec.uses:
            _stage(REPO / package, stage / package, skip=slaves)
        script = package_dir / spec.script
        carried = _stage_resources(spec, stage / spec.package, Path(tmp) / "robot")
        tag = content_tag(stage, script.read_text() + carried)  # the files' text in the tag
        slave = isolate(stage, script, tag)  # module names of this build's own (isolate.py)
        packages = [core.name, spec.package, *spec.uses]
        raw = FmuBuilder.build_FMU(
            slave,
            dest=Path(tmp) / "raw",
            project_files=[stage / f"{p}_{tag}" for p in packages],
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
        contents = {n: zin.read(n) for n in zin.namelist() if n != "modelDescription.xml"}
        contents = guard_binaries(contents, 2)  # pyfmu_guard.py: refuses calls after free
        members = sorted(contents)
        digest = hashlib.sha256()
        for name in members:
            digest.update(name.encode())
            digest.update(contents[name])

        def xml(guid: str) -> bytes:
            return _model_description(cls, guid, "pythonfmu")

        digest.update(xml(""))
        guid = "{" + str(uuid.UUID(digest.hexdigest()[:32])) + "}"
        with write_zip(target) as zout:
            for name in ["modelDescription.xml", *members]:
                info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
                if name != "modelDescription.xml":
                    zout.writestr(info, contents[name])
                else:
                    zout.writestr(info, xml(guid))
            _add_documentation(zout, xml(guid), "pythonfmu")


NATIVE = REPO / "native"
NATIVE_SHARED = ("fmi2_glue.c", "glue.h", "linalg3.h", "arm.h", "arm_terms.c", "arm_terms.h",
                 "ode.c", "ode.h", "pyrandom.c", "pyrandom.h",
                 "fmi2_me.c", "instance.h", "model_me.h")  # fmt: skip
NATIVE_MODEL = ("config.h", "model.h", "model.c")
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")


def _native_sources(spec: FmuSpec) -> dict[str, bytes]:
    """The C sources of a native FMU (flat: name -> content), FMI headers from fmpy included."""
    import fmpy

    files = {}
    for name in NATIVE_SHARED:
        path = NATIVE / "src" / name
        if name.startswith(("ode", "pyrandom")) and spec.key != "plant":
            continue
        files[name] = path.read_bytes()
    for name in NATIVE_MODEL:
        files[name] = (NATIVE / spec.key / name).read_bytes()
    headers = Path(fmpy.__file__).parent / "c-code"
    for name in FMI_HEADERS:
        files[name] = (headers / name).read_bytes()
    return files


def build_native_fmu(spec: FmuSpec, out_dir: Path = DEFAULT_OUT / "native") -> Path:
    """Build the native (C99) flavour of an FMU: the same variables as the Python FMU, a library
    per platform with a compiler here (binaries/linux64, win64, aarch64-linux: see toolchains.py)
    and its sources/ (with buildDescription.xml) so tools can build it for another platform."""
    cls = spec.load_model_class()
    sources = _native_sources(spec)
    c_files = sorted(n for n in sources if n.endswith(".c"))

    def xml(guid: str) -> bytes:
        me = getattr(cls, "MODEL_EXCHANGE", None)  # Model Exchange: native flavour only
        return _model_description(cls, guid, "native C99", source_files=c_files, model_exchange=me)

    digest = hashlib.sha256(xml(""))
    for name in sorted(sources):
        digest.update(name.encode() + sources[name])
    guid = "{" + str(uuid.UUID(digest.hexdigest()[:32])) + "}"
    sources["guid.h"] = f'#define MODEL_GUID "{guid}"\n'.encode()
    sources["buildDescription.xml"] = _build_description(cls.MODEL_NAME, c_files)
    target = Path(out_dir) / f"{cls.MODEL_NAME}.fmu"
    return pack_native_fmu(target, xml(guid), sources, c_files, cls.MODEL_NAME)


def pack_native_fmu(
    target: Path,
    xml: bytes,
    sources: dict[str, bytes],
    c_files: list[str],
    model_identifier: str,
    fmi_version: int = 2,
) -> Path:
    """Compile the sources for every platform with a compiler here and write the native FMU
    archive (modelDescription, binaries/, sources/, documentation/) atomically to target."""
    import platform

    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise RuntimeError("the native build runs on linux64 (x86_64) only")
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="impcosim_native_") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name, content in sources.items():
            (src / name).write_bytes(content)
        binaries = toolchains.build_binaries(
            src, model_identifier, c_files, fmi_version=fmi_version
        )
        with write_zip(target) as z:
            z.writestr(_info("modelDescription.xml"), xml)
            for name in sorted(binaries):
                z.writestr(_info(name, 0o755), binaries[name])
            for name in sorted(sources):
                z.writestr(_info(f"sources/{name}"), sources[name])
            _add_documentation(z, xml, "native C99")
    return target


def _info(name: str, mode: int = 0o644) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = mode << 16
    return info


def _add_documentation(z: zipfile.ZipFile, model_description: bytes, flavour: str) -> None:
    """Write documentation/ (index.html, the licence) and model.png into an FMU being written,
    generated from its modelDescription and the members written so far (call it last)."""
    from impedance_cosim.packaging.documentation import documentation_members

    for name, data in documentation_members(model_description, z.namelist(), flavour).items():
        z.writestr(_info(name), data)


def _build_description(
    model_identifier: str, c_files: list[str], fmi_version: str = "2.0"
) -> bytes:
    """buildDescription.xml: one C99 configuration of the given source files, linked with libm."""
    root = ET.Element("fmiBuildDescription", {"fmiVersion": fmi_version})
    conf = ET.SubElement(root, "BuildConfiguration", {"modelIdentifier": model_identifier})
    files = ET.SubElement(conf, "SourceFileSet", {"language": "C99"})
    for name in c_files:
        ET.SubElement(files, "SourceFile", {"name": name})
    ET.SubElement(conf, "Library", {"name": "m"})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_ssp(
    out_dir: Path = DEFAULT_OUT,
    name: str = "PaperScenario",
    fmu_dir: Path | None = None,
    scenario: str | None = None,
) -> Path:
    """Pack ssp/ with the FMUs in fmu_dir (default out_dir) into out_dir/<name>.ssp and validate
    it against the SSP 1.0 schemas. Without scenario: every scenario, as SSP variants
    (SystemStructure.ssd the default, <scenario>.ssd the others); with one: that scenario alone,
    its SSD as SystemStructure.ssd (for engines that read only the default SSD)."""
    from fmpy.ssp.ssd import read_ssd

    from impedance_cosim.cosim.system import COMPONENTS, SCENARIOS, ssd_name, ssv_name

    out_dir = Path(out_dir)
    source = REPO / "ssp"
    target = out_dir / f"{name}.ssp"
    scenarios = list(SCENARIOS) if scenario is None else [scenario]

    def validate(archive: Path) -> None:
        try:
            read_ssd(str(archive), validate=True)
            for s in scenarios:  # fmpy validates only SystemStructure.ssd (and the SSVs it binds)
                if scenario is None and ssd_name(s) != "SystemStructure.ssd":
                    _validate_variant(archive, ssd_name(s))
        except Exception as exc:
            raise ValueError(f"{target.name} does not validate: {exc}") from None

    with write_zip(target, check=validate) as z:
        # writestr with fixed dates and modes (z.write would take the files' mtimes)
        for s in scenarios:
            ssd = (source / ssd_name(s)).read_bytes()
            z.writestr(_info(ssd_name(s) if scenario is None else "SystemStructure.ssd"), ssd)
        for s in scenarios:
            for comp in COMPONENTS:
                ssv = ssv_name(s, comp.name)
                z.writestr(_info(f"resources/{ssv}"), (source / ssv).read_bytes())
        for comp in COMPONENTS:
            fmu = Path(fmu_dir or out_dir) / comp.fmu
            if not fmu.is_file():
                raise FileNotFoundError(f"{fmu} is missing: build the FMUs first")
            z.writestr(_info(comp.source), fmu.read_bytes())
    return target


def _validate_variant(archive: Path, ssd: str) -> None:
    """Schema-validate a variant SSD of an archive (raises on the first problem)."""
    from fmpy.ssp.ssd import validate_tree
    from lxml import etree

    with zipfile.ZipFile(archive) as z:
        validate_tree(etree.fromstring(z.read(ssd)), "SystemStructureDescription.xsd")


def _model_description(
    cls, guid: str, flavour: str, source_files=None, model_exchange=None
) -> bytes:
    """modelDescription.xml of a model class, the same for both flavours but the tool name and
    the source file list."""
    return model_description(
        model_name=cls.MODEL_NAME,
        description=cls.DESCRIPTION,
        guid=guid,
        variables=cls.variables(),
        default_experiment=cls.DEFAULT_EXPERIMENT,
        generation_tool=f"impedance_cosim {__version__} ({flavour})",
        output_dependencies=cls.OUTPUT_DEPENDENCIES,
        source_files=source_files,
        model_exchange=model_exchange,
    )
