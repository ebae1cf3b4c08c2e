"""The documentation an FMU carries: documentation/index.html, the licence and the model.png icon.

index.html is generated from the FMU's own modelDescription.xml (itself written from the model's
variable table) and its member list, so it lists exactly the variables, interfaces, capability
flags and platforms the archive has. It is one self-contained file (inline style, Unicode
equations, no scripts, no external links) and opens without network.
"""

from __future__ import annotations

import html
import xml.etree.ElementTree as ET
from pathlib import Path

from impedance_cosim.packaging.icons import icon_png
from impedance_cosim.packaging.model_docs import model_file

REPO = Path(__file__).resolve().parents[2]
LICENSE_FILE = REPO / "LICENSE"
INDEX = "documentation/index.html"
LICENSE_MEMBER = "documentation/licenses/license.txt"  # FMI 2.0.x: licenses/license.{txt,html}
ICON = "model.png"
EXTERNAL = "documentation/externalDependencies.txt"

STYLE = """body{font-family:sans-serif;max-width:62em;margin:1em auto;padding:0 1em;line-height:1.4}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 6px;
text-align:left;vertical-align:top}th{background:#eee}.eq{margin:.4em 0 .4em 2em;
font-family:serif;font-size:110%}pre,code{background:#f4f4f4}pre{padding:.4em}"""


def documentation_members(model_description: bytes, members: list[str], flavour: str) -> dict:
    """The documentation members of an FMU (name -> bytes) for its modelDescription.xml and the
    names of its other members (binaries, sources); flavour is "pythonfmu", "pythonfmu3" or
    "native C99"."""
    root = ET.fromstring(model_description)
    out = {
        INDEX: index_html(root, members, flavour).encode("utf-8"),
        LICENSE_MEMBER: LICENSE_FILE.read_bytes(),
        ICON: icon_png(root.get("modelName", "")),
    }
    needs = external_dependencies(root.get("modelName", ""), flavour)
    if needs:
        out[EXTERNAL] = needs.encode("utf-8")
    return out


def external_dependencies(model_name: str, flavour: str) -> str:
    """What the FMU needs outside its archive to load and run (FMI 2.0.x externalDependencies):
    its flavour's host, and <model folder>/<model name>_dependencies.txt where the model has one."""
    lines = []
    if flavour == "pythonfmu":
        lines.append(
            "A Python 3 host process (e.g. fmpy, libcosimpy, ecospy): the binaries are pythonfmu"
            " 0.7 wrappers that run resources/*.py in the Python of the process that loads them"
            " (standard library only). They do not load in C hosts: use the native FMUs there."
        )
    if flavour == "pythonfmu3":
        lines.append(
            "A Python 3 host process with FMI 3.0 support (e.g. fmpy): the binaries are pythonfmu3"
            " 0.3.4 wrappers that run resources/*.py in the Python of the process that loads them"
            " (standard library only). For C hosts use the native FMI 3.0 FMUs."
        )
    needs = model_file(model_name, "_dependencies.txt")  # what this model itself needs
    if needs is not None:
        lines.append(needs.strip())
    return "\n\n".join(lines) + "\n" if lines else ""


# --- the page ---------------------------------------------------------------------------------


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _table(head: list[str], rows: list[list[str]], raw: bool = False) -> str:
    """An HTML table; cells are escaped unless raw."""
    th = "".join(f"<th>{_e(h)}</th>" for h in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{c if raw else _e(c)}</td>" for c in row) + "</tr>\n" for row in rows
    )
    return f"<table>\n<tr>{th}</tr>\n{body}</table>\n"


def variables_of(root: ET.Element) -> list[dict[str, str]]:
    """Every ScalarVariable of a modelDescription: name, valueReference, causality, variability,
    initial, type, unit, min, max, start, description (empty strings where absent)."""
    if root.get("fmiVersion", "").startswith("3"):
        return _variables_of3(root)
    out = []
    for sv in root.iter("ScalarVariable"):
        typ = next(iter(sv))
        row = {k: sv.get(k, "") for k in ("name", "valueReference", "causality", "variability")}
        row["initial"] = sv.get("initial", "")
        row["type"] = typ.tag
        row.update({k: typ.get(k, "") for k in ("unit", "min", "max", "start")})
        row["description"] = sv.get("description", "")
        out.append(row)
    return out


def _variables_of3(root: ET.Element) -> list[dict[str, str]]:
    """variables_of for FMI 3.0, whose variables are elements named by their type."""
    out = []
    for el in root.find("ModelVariables") or ():
        keys = ("name", "valueReference", "causality", "variability", "initial", "unit", "min",
                "max", "start", "description")  # fmt: skip
        row = {k: el.get(k, "") for k in keys}
        row["causality"] = row["causality"] or "local"
        row["type"] = el.tag
        start = el.find("Start")
        if start is not None:
            row["start"] = start.get("value", "")
        out.append(row)
    return out


COLUMNS = ("name", "valueReference", "causality", "variability", "type", "unit", "min", "max",
           "start", "description")  # fmt: skip


def _start(v: dict[str, str]) -> str:
    """The start value, or how the variable is initialized when it has none (outputs)."""
    return v["start"] or (f"({v['initial']})" if v["initial"] else "")


def _variables_section(root: ET.Element) -> str:
    head = ["name", "value ref.", *COLUMNS[2:]]
    parts = []
    found = [v["causality"] for v in variables_of(root)]
    known = ["parameter", "calculatedParameter", "input", "output", "local", "independent"]
    order = sorted(set(found), key=lambda c: (known.index(c) if c in known else len(known), c))
    for causality in order:
        rows = [
            [*(v[k] for k in COLUMNS[:-2]), _start(v), v["description"]]
            for v in variables_of(root)
            if v["causality"] == causality
        ]
        if rows:
            parts.append(f"<h3>causality {_e(causality)} ({len(rows)})</h3>\n")
            parts.append(_table(head, rows))
    return "".join(parts)


def _interfaces_section(root: ET.Element, members: list[str]) -> str:
    parts = []
    for kind in ("ModelExchange", "CoSimulation", "ScheduledExecution"):
        el = root.find(kind)
        if el is None:
            continue
        rows = [[k, v] for k, v in el.attrib.items()]
        sources = [f.get("name", "") for f in el.iter("File")]
        if sources:
            rows.append(["SourceFiles", ", ".join(sources)])
        parts.append(f"<h3>{kind}</h3>\n" + _table(["attribute", "value"], rows))
    n_states = len(root.findall("ModelStructure/Derivatives/Unknown")) + len(
        root.findall("ModelStructure/ContinuousStateDerivative")
    )
    n_events = root.get("numberOfEventIndicators") or len(
        root.findall("ModelStructure/EventIndicator")
    )
    parts.append(f"<p>Continuous states: {n_states}. Event indicators: {_e(n_events)}.</p>\n")
    for clock in root.iter("Clock"):
        parts.append(
            f"<p>Clock <code>{_e(clock.get('name'))}</code>: {_e(clock.get('description'))}"
            f" (intervalVariability {_e(clock.get('intervalVariability'))}; the importer reads"
            " the interval with fmi3GetIntervalDecimal after initialization and calls"
            " fmi3ActivateModelPartition at every tick, after setting the clocked inputs;"
            " the clocked outputs are then the new sample's).</p>\n"
        )
    platforms = sorted({m.split("/")[1] for m in members if m.count("/") >= 2
                        and m.startswith("binaries/")})  # fmt: skip
    files = {p: sorted(m.split("/", 2)[2] for m in members if m.startswith(f"binaries/{p}/"))
             for p in platforms}  # fmt: skip
    rows = [[p, ", ".join(files[p])] for p in platforms]
    parts.append("<h3>Platforms</h3>\n" + _table(["binaries/", "files"], rows))
    if any(m.startswith("sources/") for m in members):
        parts.append(
            "<p>The C sources are in <code>sources/</code> with <code>buildDescription.xml</code>:"
            " a tool (or <code>fmpy compile</code>) can build the library for another platform"
            " (e.g. macOS).</p>\n"
        )
    return "".join(parts)


# A parameter change worth showing in each model's fmpy command line.
EXAMPLES = {
    "PumaPlant": "q_noise 1e-4 noise_seed 7",
    "PinocchioPlant": "q_noise 1e-4 noise_seed 7",
    "MujocoPlant": "q_noise 1e-4 noise_seed 7",
    "ImpedanceController": "K1 80 K2 80 K3 80",
    "BridgePlant": "robot_port 50400",
}
ROBOT = (
    "<p>BridgePlant needs its robot process running first, e.g. <code>impedance-cosim robot"
    " --port 50400 --lockstep</code> (from the impedance-cosim package), or your own one"
    " speaking the same protocol.</p>\n"
)


def _run_section(root: ET.Element, flavour: str) -> str:
    name = root.get("modelName", "")
    exp = root.find("DefaultExperiment")
    step = exp.get("stepSize") if exp is not None else None
    stop = exp.get("stopTime") if exp is not None else None
    interval = f" --output-interval {step}" if step else ""
    lines = [
        f"pip install fmpy\nfmpy info {name}.fmu\nfmpy validate {name}.fmu",
        f"fmpy simulate {name}.fmu{interval} --output-file {name}_out.csv",
    ]
    example = EXAMPLES.get(name)
    if example:
        lines.append(f"fmpy simulate {name}.fmu{interval} --start-values {example}")
    scheduled = root.find("CoSimulation") is None and root.find("ScheduledExecution") is not None
    if scheduled:
        lines = lines[:1]  # fmpy simulate runs Co-Simulation and Model Exchange only
    if root.find("ModelExchange") is not None:
        lines.append(f"fmpy simulate {name}.fmu --interface-type ModelExchange --solver CVode")
    py = (
        "from fmpy import simulate_fmu\n"
        f"result = simulate_fmu('{name}.fmu'"
        + (f", output_interval={step}" if step else "")
        + (f", stop_time={stop}" if stop else "")
        + ")\nprint(result.dtype.names)"
    )
    if scheduled:
        py = (
            "# Scheduled Execution: your host loop activates the clock at every tick\n"
            "from fmpy.fmi3 import FMU3ScheduledExecution\n"
            "# instantiate, enterInitializationMode, set parameters, exitInitializationMode,\n"
            "# fmi3GetIntervalDecimal(clock), then at t = k * interval: set the inputs,\n"
            "# fmi3ActivateModelPartition(instance, clock, t), get the outputs"
        )
    host = (
        f"This is the Python flavour ({flavour}): it runs in a Python host process such as fmpy."
        if flavour.startswith("pythonfmu")
        else "This is the native (C99) flavour: it loads in any FMI "
        + root.get("fmiVersion", "2.0")
        + " host, no Python needed."
    )
    exp_text = ", ".join(f"{k} = {v}" for k, v in exp.attrib.items()) if exp is not None else "none"
    return (
        f"<p>{_e(host)} Default experiment: {_e(exp_text)}.</p>\n"
        f"<pre>{_e(chr(10).join(lines))}</pre>\n<p>From Python:</p>\n<pre>{_e(py)}</pre>\n"
        "<p><code>fmpy simulate</code> coarsens its output to about 1000 points unless"
        " <code>--output-interval</code> is given.</p>\n" + (ROBOT if name == "BridgePlant" else "")
    )


def index_html(root: ET.Element, members: list[str], flavour: str) -> str:
    """documentation/index.html of an FMU (see module docstring)."""
    from impedance_cosim.packaging.model_docs import model_section

    name = root.get("modelName", "")
    starts = {v["name"]: v for v in variables_of(root)}
    meta = [[k, root.get(k, "")] for k in ("modelName", "description", "author", "version",
            "copyright", "license", "generationTool", "guid", "instantiationToken", "fmiVersion")
            if k not in ("guid", "instantiationToken") or root.get(k) is not None]  # fmt: skip
    meta.append(["flavour", flavour])
    needs = external_dependencies(name, flavour)
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{_e(name)}</title>
<style>{STYLE}</style>
</head>
<body>
<h1>{_e(name)}</h1>
<p><img src="../model.png" alt="icon of {_e(name)}" width="128" height="128"></p>
<p>{_e(root.get("description", ""))}</p>
{_table(["attribute", "value"], meta)}
<h2>The model</h2>
{model_section(name, starts)}
<h2>FMI interfaces</h2>
{_interfaces_section(root, members)}
<h2>Running it with fmpy</h2>
{_run_section(root, flavour)}
{"<h2>External dependencies</h2>" + chr(10) + "<p>" + _e(needs) + "</p>" if needs else ""}
<h2>Variables</h2>
{_variables_section(root)}
<h2>Licence</h2>
<p>{_e(root.get("license", ""))}. The text (also in
<code>documentation/licenses/license.txt</code>):</p>
<pre>{_e(LICENSE_FILE.read_text())}</pre>
</body>
</html>
"""
