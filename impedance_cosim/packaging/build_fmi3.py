"""Build the FMI 3.0 edition of the native FMUs into fmus/fmi3/, and its system archive.

The same model code (native/<model>/model.c, config.h) and the same variable tables as the FMI 2.0
native FMUs, and the same instance core (native/src/instance.c, instance_me.c); the glue is
native/src/fmi3_*.c (FMI3_GLUE) instead of the FMI 2.0 glue. The FMUs:
- PumaPlant.fmu: Co-Simulation and Model Exchange;
- ImpedanceController.fmu: Co-Simulation (and Model Exchange): for any FMI 3 host; with event
  mode in Co-Simulation its sampling is the time-based clock `sample_clock` (CS_CLOCK);
- ImpedanceControllerClocked.fmu: Scheduled Execution, its sampling as a periodic input clock
  (`sample_clock`, interval = the parameter sample_period), for hosts that schedule clocks;
- arrays/PumaPlant.fmu, arrays/ImpedanceController.fmu: the array edition, the joint vectors as
  fixed-size Float64 arrays (fmi/fmi3_arrays.py; fmi3_config.h's FMI3_ARRAYS and
  native/src/fmi3_arrays.c map them to the table's slots);
- python/PumaPlant.fmu, python/ImpedanceController.fmu: the Python FMUs as FMI 3.0 (pythonfmu3,
  Co-Simulation), when pythonfmu3 is installed.
"""

from __future__ import annotations

import hashlib
import sys
import tempfile
import uuid
import zipfile
from pathlib import Path

from impedance_cosim.fmi.fmi3_arrays import ARRAYS3, Fmi3Array, array_description3, c_arrays3
from impedance_cosim.fmi.fmi3_description import SampleClock, c_config3, model_description3
from impedance_cosim.fmi.variables import full_table
from impedance_cosim.packaging.archive_out import write_zip
from impedance_cosim.packaging.build import (
    DEFAULT_OUT,
    FMUS,
    NATIVE,
    FmuSpec,
    _add_documentation,
    _build_description,
    _info,
    _native_sources,
    build_ssp,
    model_fields,
    pack_native_fmu,
)
from impedance_cosim.packaging.build_ssp2 import build_ssp2
from impedance_cosim.packaging.isolate import content_tag, isolate
from impedance_cosim.packaging.pyfmu_guard import guard_binaries

FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
FMI3_GLUE = (
    "fmi3_glue.c",
    "fmi3_values.c",  # getters and setters
    "fmi3_events.c",
    "fmi3_cosim.c",  # fmi3DoStep: early return, intermediate update, event mode in CS
    "fmi3_stubs.c",
    "fmi3_wrapper.h",
    "fmi3_states.h",  # the FMI 3.0 states and each function's legal ones
)
SAMPLE_CLOCK = SampleClock(
    "sample_clock",
    "sample_period",
    "The controller's sampling: periodic, one tick every sample_period seconds from the start"
    " time; at each tick the observer and the control law take a sample of the inputs",
)
CLOCKED_NAME = "ImpedanceControllerClocked"  # file name of the clocked controller
# models whose co-simulation returns early at a discrete-state switch when the importer allows it
# (model.c implements model_step_early): the plant, at the wall contact
EARLY_RETURN = {"plant"}
# models whose Co-Simulation declares the sample clock: with eventModeUsed its ticks are events
CS_CLOCK = {"controller"}


def _xml(cls, token: str, clock: SampleClock | None, early: bool, cs_clock, arrays) -> bytes:
    xml = model_description3(
        token=token,
        **model_fields(cls, "native C99, FMI 3.0"),
        model_exchange=getattr(cls, "MODEL_EXCHANGE", None),
        clock=clock,
        early_return=early,
        cs_clock=cs_clock,
    )
    return array_description3(xml, arrays) if arrays else xml


def build_native_fmu3(
    spec: FmuSpec,
    out_dir: Path = DEFAULT_OUT / "fmi3",
    clock: SampleClock | None = None,
    arrays: tuple[Fmi3Array, ...] = (),
) -> Path:
    """Build the FMI 3.0 native FMU of a model (with clock: its Scheduled Execution variant; with
    arrays: its array edition, those array variables in place of their scalar elements)."""
    import fmpy

    cls = spec.load_model_class()
    me = getattr(cls, "MODEL_EXCHANGE", None)
    early = spec.key in EARLY_RETURN and clock is None
    cs_clock = SAMPLE_CLOCK if spec.key in CS_CLOCK and clock is None else None
    sources = _native_sources(spec, FMI3_GLUE)
    headers = Path(fmpy.__file__).parent / "c-code"
    for name in FMI3_HEADERS:
        sources[name] = (headers / name).read_bytes()
    n_table = len(full_table(cls.variables(), me))
    sources["fmi3_config.h"] = c_config3(
        n_table, me, clock or cs_clock, cls.variables(), early
    ).encode()
    c_files = sorted(n for n in sources if n.endswith(".c"))
    if arrays:  # fmi3_values.c maps the arrays' value references with fmi3_arrays.c
        for name in ("fmi3_arrays.c", "fmi3_arrays.h"):
            sources[name] = (NATIVE / "src" / name).read_bytes()
        scalar_xml = _xml(cls, "", clock, early, cs_clock, ())
        sources["fmi3_config.h"] += c_arrays3(scalar_xml, arrays).encode()
        c_files = sorted({*c_files, "fmi3_arrays.c"})
    digest = hashlib.sha256(_xml(cls, "", clock, early, cs_clock, arrays))
    for name in sorted(sources):
        digest.update(name.encode() + sources[name])
    token = "{" + str(uuid.UUID(digest.hexdigest()[:32])) + "}"
    sources["guid.h"] = f'#define MODEL_GUID "{token}"\n'.encode()
    sources["buildDescription.xml"] = _build_description(cls.MODEL_NAME, c_files, "3.0")
    target = Path(out_dir) / f"{CLOCKED_NAME if clock else cls.MODEL_NAME}.fmu"
    xml = _xml(cls, token, clock, early, cs_clock, arrays)
    return pack_native_fmu(target, xml, sources, c_files, cls.MODEL_NAME, fmi_version=3)


SCRIPT3 = '''"""pythonfmu3 slave script of {name} as FMI 3.0: a thin shell over {cls}."""

from pythonfmu3 import Fmi3Slave

from impedance_cosim.fmi.fmi3_slave import ModelSlave3
from {module} import {cls}


class {name}3(ModelSlave3, Fmi3Slave):
    model_class = {cls}
'''


def build_python_fmu3(spec: FmuSpec, out_dir: Path = DEFAULT_OUT / "fmi3" / "python") -> Path:
    """The Python FMU of a model as FMI 3.0 (pythonfmu3): the same model package and glue mixin
    as the FMI 2.0 one, a generated slave script (module <name>3_<tag>, module names of its own
    like every bundled package: isolate.py), and the modelDescription.xml replaced by ours."""
    from pythonfmu3 import FmuBuilder  # build-time dependency only

    cls = spec.load_model_class()
    module, cls_name = spec.model_class.rsplit(".", 1)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="impcosim_py3_") as tmp:
        stage = Path(tmp) / "stage"
        _stage_python(spec, stage)
        script = Path(tmp) / f"{cls.MODEL_NAME}3.py"
        script.write_text(SCRIPT3.format(name=cls.MODEL_NAME, cls=cls_name, module=module))
        tag = content_tag(stage, script.read_text())
        slave = isolate(stage, script, tag)  # module names of this build's own (isolate.py)
        project = [stage / f"impedance_cosim_{tag}", stage / f"{spec.package}_{tag}"]
        raw = FmuBuilder.build_FMU(slave, dest=Path(tmp) / "raw", project_files=project)
        with zipfile.ZipFile(raw) as zin:
            members = sorted(n for n in zin.namelist() if n != "modelDescription.xml")
            contents = guard_binaries({n: zin.read(n) for n in members}, 3)  # pyfmu_guard.py
            members = sorted(contents)
    digest = hashlib.sha256(_xml_python(cls, ""))
    for name in members:
        digest.update(name.encode() + contents[name])
    xml = _xml_python(cls, "{" + str(uuid.UUID(digest.hexdigest()[:32])) + "}")
    target = out_dir / f"{cls.MODEL_NAME}.fmu"
    with write_zip(target) as z:
        z.writestr(_info("modelDescription.xml"), xml)
        for name in members:
            z.writestr(
                _info(name, 0o755 if name.startswith("binaries/") else 0o644), contents[name]
            )
        _add_documentation(z, xml, "pythonfmu3")
    return target


def _stage_python(spec: FmuSpec, stage: Path) -> None:
    """What the Python FMU bundles: the core of impedance_cosim and the model package."""
    from impedance_cosim.packaging.build import REPO, _stage, stage_core

    stage_core(stage)
    _stage(REPO / spec.package, stage / spec.package, skip={spec.script})


def _xml_python(cls, token: str) -> bytes:
    return model_description3(token=token, **model_fields(cls, "pythonfmu3, FMI 3.0"))


def build_fmi3(out_dir: Path = DEFAULT_OUT) -> list[Path]:
    """fmus/fmi3/: the FMI 3.0 plant and controllers (arrays/: the array edition),
    PaperScenario-fmi3.ssp (the SSD of the FMI 2.0 archive, with the FMI 3.0 plant and
    Co-Simulation controller) and its SSP 2.0 edition PaperScenario-fmi3-ssp2.ssp (the clocked
    controller, build_ssp2.py)."""
    folder = Path(out_dir) / "fmi3"
    built = [
        build_native_fmu3(FMUS["plant"], folder),
        build_native_fmu3(FMUS["controller"], folder),
        build_native_fmu3(FMUS["controller"], folder, SAMPLE_CLOCK),
    ]
    built += [build_native_fmu3(FMUS[k], folder / "arrays", arrays=ARRAYS3[k]) for k in ARRAYS3]
    built.append(build_ssp(out_dir, "PaperScenario-fmi3", folder))
    built.append(build_ssp2(out_dir, folder))  # the SSP 2.0 edition (clocked controller)
    built.append(build_ssp2(out_dir, folder / "arrays", arrays=True))  # array connectors
    try:
        import pythonfmu3  # noqa: F401
    except ImportError:
        print("FMI 3.0 Python FMUs skipped (optional: pip install pythonfmu3 adds them)",
              file=sys.stderr)  # fmt: skip
        return built
    built += [build_python_fmu3(FMUS[k], folder / "python") for k in ("plant", "controller")]
    return built
