"""The paper's closed loop of each scenario as one native FMU (FMI 2.0 and 3.0 Co-Simulation):
fmus/native/PaperClosedLoop-<scenario>.fmu and fmus/fmi3/PaperClosedLoop-<scenario>.fmu.

native/closedloop/model.c steps the plant's and the controller's model.c (unchanged, each in its
own translation unit with its own config.h) as our master's Gauss-Seidel loop steps their FMUs.
Its variables: every parameter of both parts as plant.<name> / controller.<name> (start values
from the scenario's parameter set, tunable where the part's is) and every output of both parts
(plant.q1, ..., controller.tau1, ...): the names of the master's result columns, under FMI's
structured naming convention. The connected inputs are internal.
"""

from __future__ import annotations

import dataclasses
import hashlib
import uuid
import xml.etree.ElementTree as ET
from pathlib import Path

from controller_model.model import ControllerModel
from impedance_cosim.cosim.system.paper import CONNECTIONS, SCENARIO_DESCRIPTIONS, SCENARIOS
from impedance_cosim.fmi.fmi2_description import model_description
from impedance_cosim.fmi.fmi3_description import c_config3, model_description3
from impedance_cosim.fmi.variables import ModelExchange, Variable
from impedance_cosim.packaging.build import (
    DEFAULT_OUT,
    FMI2_GLUE,
    FMI_HEADERS,
    NATIVE,
    NATIVE_SHARED,
    _build_description,
    pack_native_fmu,
)
from impedance_cosim.packaging.cgen import c_config
from impedance_cosim.version import __version__
from plant_model.model import PlantModel

PARTS = {"plant": PlantModel, "controller": ControllerModel}  # part name -> model class
PART_ENUM = {"plant": "PART_PLANT", "controller": "PART_CONTROLLER"}
NO_STATES = ModelExchange(())  # the Model Exchange side the glue compiles against (not offered)
OWN_SOURCES = ("parts.h", "part_api.h", "plant_part.c", "controller_part.c", "model.h", "model.c")
INCLUDED = ("part_api.h", "plant_model.c", "controller_model.c")  # included, not compiled alone
STEP = 1 / 400


def fmu_name(scenario: str) -> str:
    """The FMU's file name (without .fmu): PaperClosedLoop-<scenario>."""
    return f"PaperClosedLoop-{scenario}"


def model_identifier(scenario: str) -> str:
    """The FMU's modelIdentifier, a C name: PaperClosedLoop_<scenario>."""
    return fmu_name(scenario).replace("-", "_")


def table(scenario: str) -> list[tuple[Variable, str, int]]:
    """The closed loop's variables (parameters of both parts, then their outputs), each with its
    part and value reference there; start values are the scenario's parameter set."""
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; choose from {sorted(SCENARIOS)}")
    values = SCENARIOS[scenario]
    rows = []
    for causality in ("parameter", "output"):
        for part, cls in PARTS.items():
            for vr, v in enumerate(cls.variables()):
                if v.causality != causality:
                    continue
                name = f"{part}.{v.name}"
                start = values.get(name, v.start)
                if v.enumeration and isinstance(start, str):
                    start = v.enumeration.value(start)
                text = f"{part.capitalize()}: {v.description}"
                rows.append((dataclasses.replace(v, name=name, start=start, description=text),
                             part, vr))  # fmt: skip
    return rows


def variables(scenario: str) -> list[Variable]:
    """The closed loop's variable table (value reference = position)."""
    return [v for v, _, _ in table(scenario)]


def _part_vr(part: str, name: str) -> int:
    return [v.name for v in PARTS[part].variables()].index(name)


def c_config_closed_loop(scenario: str) -> str:
    """config.h of the closed loop: its variable table (cgen.c_config), no Model Exchange offered,
    where each variable lives in its part (LINKS) and the SSD's connections (FEED, TORQUE)."""
    rows = table(scenario)
    text = c_config(model_identifier(scenario), [v for v, _, _ in rows], NO_STATES)
    links = "".join(f"\n    {{{PART_ENUM[p]}, {vr}}}, /* {v.name} */" for v, p, vr in rows)
    feed = [(_part_vr(se, sc), _part_vr(ee, ec)) for se, sc, ee, ec in CONNECTIONS if se == "plant"]
    torque = [(_part_vr(se, sc), _part_vr(ee, ec))
              for se, sc, ee, ec in CONNECTIONS if se == "controller"]  # fmt: skip
    extra = [
        "#define ME_OFFERED 0 /* co-simulation only */",
        "enum { PART_PLANT = 0, PART_CONTROLLER = 1 };",
        "typedef struct {",
        "    int part; /* PART_* */",
        "    int vr;   /* the value reference in the part's own table */",
        "} PartLink;",
        f"static const PartLink LINKS[N_VARS] = {{{links}\n}};",
        "/* plant output -> controller input (value references in the parts) */",
        f"#define N_FEED {len(feed)}",
        "static const int FEED[N_FEED][2] = {" + ", ".join(f"{{{a}, {b}}}" for a, b in feed) + "};",
        "/* controller output -> plant input */",
        f"#define N_TORQUE {len(torque)}",
        "static const int TORQUE[N_TORQUE][2] = {"
        + ", ".join(f"{{{a}, {b}}}" for a, b in torque)
        + "};",
        "",
        "#endif",
        "",
    ]
    return text.removesuffix("#endif\n") + "\n".join(extra)


def _sources(scenario: str, glue: tuple[str, ...] = FMI2_GLUE) -> dict[str, bytes]:
    """The C sources (flat): the shared code with one FMI version's glue, each part's model
    under <part>_*, the closed loop."""
    import fmpy

    files = {name: (NATIVE / "src" / name).read_bytes() for name in (*NATIVE_SHARED, *glue)}
    for part in PARTS:
        for name in ("config.h", "model.h", "model.c"):
            files[f"{part}_{name}"] = (NATIVE / part / name).read_bytes()
        own = NATIVE / part / f"{part}.h"  # what the part's model files share, if they are two
        if own.is_file():
            files[own.name] = own.read_bytes()
    for name in OWN_SOURCES:
        files[name] = (NATIVE / "closedloop" / name).read_bytes()
    files["config.h"] = c_config_closed_loop(scenario).encode()
    headers = Path(fmpy.__file__).parent / "c-code"
    for name in FMI_HEADERS:
        files[name] = (headers / name).read_bytes()
    return files


def _description(scenario: str) -> str:
    return (f"The paper's closed loop, scenario {scenario} ({SCENARIO_DESCRIPTIONS[scenario]}):"
            " the impedance controller and the PUMA plant in one FMU, stepped as the"
            " co-simulation master's Gauss-Seidel loop (controller samples, then the plant"
            " integrates with the torque held) at the controller's sample period")  # fmt: skip


def _experiment() -> dict[str, float]:
    return {"startTime": 0.0, "stopTime": 20.0, "stepSize": STEP}


def _fields(scenario: str, standard: str) -> dict:
    """What the FMI 2.0 and 3.0 modelDescription.xml of a closed loop share."""
    return {
        "model_name": model_identifier(scenario),
        "description": _description(scenario),
        "variables": variables(scenario),
        "default_experiment": _experiment(),
        "generation_tool": f"impedance_cosim {__version__} (native C99, {standard}closed loop)",
        "output_dependencies": "",
        "naming": "structured",
    }


def xml2(scenario: str, guid: str, c_files: list[str]) -> bytes:
    """The FMI 2.0 modelDescription.xml (Co-Simulation only; no inputs)."""
    return model_description(**_fields(scenario, ""), guid=guid, source_files=c_files)


def xml3(scenario: str, token: str) -> bytes:
    """The FMI 3.0 modelDescription.xml (Co-Simulation only), with fixedInternalStepSize: the
    loop runs at the controller's sample period (its default, 1/400 s) whatever the host's step."""
    raw = model_description3(**_fields(scenario, "FMI 3.0, "), token=token)
    root = ET.fromstring(raw)
    root.find("CoSimulation").set("fixedInternalStepSize", repr(STEP))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _c_files(sources: dict[str, bytes], included: tuple[str, ...]) -> list[str]:
    return sorted(n for n in sources if n.endswith(".c") and n not in included)


def _token(xml: bytes, sources: dict[str, bytes]) -> str:
    digest = hashlib.sha256(xml)
    for name in sorted(sources):
        digest.update(name.encode() + sources[name])
    return "{" + str(uuid.UUID(digest.hexdigest()[:32])) + "}"


def build_closed_loop(scenario: str, out_dir: Path = DEFAULT_OUT / "native") -> Path:
    """out_dir/PaperClosedLoop-<scenario>.fmu, FMI 2.0 (binaries for every platform here)."""
    sources = _sources(scenario)
    c_files = _c_files(sources, INCLUDED)
    guid = _token(xml2(scenario, "", c_files), sources)
    sources["guid.h"] = f'#define MODEL_GUID "{guid}"\n'.encode()
    sources["buildDescription.xml"] = _build_description(model_identifier(scenario), c_files)
    target = Path(out_dir) / f"{fmu_name(scenario)}.fmu"
    return pack_native_fmu(target, xml2(scenario, guid, c_files), sources, c_files,
                           model_identifier(scenario))  # fmt: skip


def build_closed_loop3(scenario: str, out_dir: Path = DEFAULT_OUT / "fmi3") -> Path:
    """out_dir/PaperClosedLoop-<scenario>.fmu, FMI 3.0 (the FMI 3 layer over the same code)."""
    import fmpy

    from impedance_cosim.packaging.build_fmi3 import FMI3_GLUE, FMI3_HEADERS

    sources = _sources(scenario, FMI3_GLUE)
    headers = Path(fmpy.__file__).parent / "c-code"
    for name in FMI3_HEADERS:
        sources[name] = (headers / name).read_bytes()
    n_table = len(table(scenario))
    sources["fmi3_config.h"] = c_config3(n_table, NO_STATES, None, variables(scenario)).encode()
    c_files = _c_files(sources, INCLUDED)
    token = _token(xml3(scenario, ""), sources)
    sources["guid.h"] = f'#define MODEL_GUID "{token}"\n'.encode()
    sources["buildDescription.xml"] = _build_description(model_identifier(scenario), c_files,
                                                         "3.0")  # fmt: skip
    target = Path(out_dir) / f"{fmu_name(scenario)}.fmu"
    return pack_native_fmu(target, xml3(scenario, token), sources, c_files,
                           model_identifier(scenario), fmi_version=3)  # fmt: skip


def build_closed_loops(out_dir: Path = DEFAULT_OUT) -> list[Path]:
    """Every scenario's closed-loop FMU, FMI 2.0 into out_dir/native, FMI 3.0 into out_dir/fmi3."""
    out_dir = Path(out_dir)
    built = [build_closed_loop(s, out_dir / "native") for s in SCENARIOS]
    return built + [build_closed_loop3(s, out_dir / "fmi3") for s in SCENARIOS]
