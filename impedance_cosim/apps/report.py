"""`report.html`: a results folder as one page to open and share, self-contained (figures inline
as data: URIs, no style sheet, script, font or anything else fetched): how the result was made
(run.json), the summary next to what the paper states, the figures and the units of the signals;
the same page for a Result of the Python API (Result.report); for a sweep, its provenance, its
maps and its table."""

from __future__ import annotations

import csv
import shlex
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from impedance_cosim.apps.html_page import esc as _e
from impedance_cosim.apps.html_page import fixed, page, plain, png_data_uri, table

if TYPE_CHECKING:
    from impedance_cosim.apps.paper_claims import Run

REPORT_NAME = "report.html"
MAX_TABLE_ROWS = 500  # a sweep's table in the page; the CSV has them all
CAPTIONS = {
    "fig1_position_force.png": "Fig. 1: position and force tracking",
    "fig2_observer.png": "Fig. 2: the velocity observer, eq. (9)",
    "fig3_velocity_tracking.png": "Fig. 3: velocity tracking",
    "fig4_observer_vs_difference.png": "Fig. 4: observer vs numerical differentiation in the loop",
}


def _figures(paths: Sequence[Path], none: str = "") -> str:
    parts = []
    for path in paths:
        name = Path(path).name
        caption = f"{CAPTIONS[name]} ({name})" if name in CAPTIONS else name
        if (image := png_data_uri(path)) is None:
            parts.append(f"<p>{_e(name)}: missing or not a PNG, not shown.</p>")
        else:
            uri, w, h = image
            parts.append(f'<figure><img src="{uri}" alt="{_e(caption)}" width="{w}" height="{h}">'
                         f"<figcaption>{_e(caption)}</figcaption></figure>")  # fmt: skip
    return "".join(parts) or f"<p>{_e(none or 'No figures were made by this command.')}</p>"


def _write(path: Path, text: str, error: BaseException | None) -> Path | None:
    """Write the page atomically. When it cannot be written: a one-line OSError if the command
    was otherwise fine, else a line on stderr and None (the command's own error goes on)."""
    from impedance_cosim.util.atomic import atomic_write

    try:
        with atomic_write(path, encoding="utf-8") as f:
            f.write(text)
    except OSError as exc:
        message = f"could not write {path}: {exc.strerror or exc}"
        if error is None:
            raise OSError(message) from None
        print(f"impedance-cosim: {message}", file=sys.stderr)
        return None
    return path


# --- the run report ---------------------------------------------------------------------------


def _status(record: Mapping[str, Any], error: BaseException | None) -> tuple[str, str]:
    """The command's outcome, "ok", "diverged" (a run asked for diverged: a result) or "failed"
    (results.exit_status's order), and the runs that were not ok, as text."""
    runs = record.get("runs", [])
    asked = [r for r in runs if not r.get("role")]  # not the Fig. 4 comparison runs
    problems = [f"{r.get('scenario')}: " + (r.get("error") if r.get("status") == "diverged"
                else f"{r.get('status')}: {r.get('error')}")
                for r in asked if r.get("status") != "ok"]  # fmt: skip
    text = " ".join(str(error).split()) if error is not None else ""
    if error is not None and not any(text and text in p for p in problems):
        problems.append(text or type(error).__name__)
    if not runs and not problems:
        problems.append("no run was made")
    statuses = [r.get("status") for r in asked]
    if error is not None or not runs or any(s not in ("ok", "diverged") for s in statuses):
        return "failed", "; ".join(problems)
    return ("diverged" if "diverged" in statuses else "ok"), "; ".join(problems)


def _heading(record: Mapping[str, Any]) -> str:
    """Each run and its status, as the page's heading says them: 'observer ok, difference
    diverged at t = 0.4825 s; Fig. 4 comparison (jacobi): observer ok, difference diverged ...'."""
    groups: dict[str, list[str]] = {}
    for r in record.get("runs", []):
        status = str(r.get("status"))
        if status == "diverged":
            status = str(r.get("error") or status).partition(":")[0]  # "diverged at t = ... s"
        elif status != "ok":
            status = status.upper()
        role = f"{r['role']} ({r.get('algorithm')})" if r.get("role") else ""
        groups.setdefault(role, []).append(f"{r.get('scenario')} {status}")
    parts = [(f"{role}: " if role else "") + ", ".join(v) for role, v in groups.items()]
    return "; ".join(parts) or "no run"


def _banner(kind: str, problems: str, record: Mapping[str, Any], kept: str, what: str) -> str:
    """The line at the top of a run's page: what happened, in words a reader can act on."""
    if kind == "failed":
        return f"This {what} FAILED: {problems}. Kept in the results folder: {kept}."
    others = [r for r in record.get("runs", []) if r.get("role") and r.get("status") != "ok"]
    extra = [f"{label(r)}: {r.get('error')}" for r in others]
    note = f" The {FIG4_NOTE}: {'; '.join(extra)}." if extra else ""
    if kind == "diverged":
        return (f"A run diverged (a result, exit status 3; its rows up to the divergence are"
                f" kept): {problems}.{note} Files: {kept}.")  # fmt: skip
    return f"All runs finished.{note} Files: {kept}."


FIG4_NOTE = "runs under one sample of delay, for Fig. 4's second row (the paper's figure)"


def _kept(record: Mapping[str, Any], figures: Sequence[Path], out: Path,
          suffix: str = "") -> list[str]:  # fmt: skip
    """The files this command left in the results folder (suffix: ".partial" when it did not
    complete, its files beside the earlier ones)."""
    files = []
    for r in record.get("runs", []):
        kept = r.get("results") or {"file": r.get("csv"), "rows": r.get("rows", "?")}
        if kept.get("file"):
            files.append(f"{kept['file']} ({kept.get('rows', '?')} rows, {label(r)})")
        name = f"{r.get('scenario')}_summary.json{suffix}"
        if "summary" in r and (out / name).is_file():
            files.append(f"{name} (the summary)")
    files += [f"{Path(p).name} (figure)" for p in figures]
    return [*files, f"run.json{suffix} (provenance)", f"{REPORT_NAME}{suffix} (this page)"]


def label(r: Mapping[str, Any]) -> str:
    """A run as the page names it: 'observer', or for a run made for a figure, its algorithm
    and role: 'observer (Jacobi, Fig. 4 comparison)'."""
    if not r.get("role"):
        return str(r.get("scenario"))
    algorithm = "-".join(w.capitalize() for w in str(r.get("algorithm")).split("-"))
    return f"{r.get('scenario')} ({algorithm}, {r['role']})"


def _outcome(r: Mapping[str, Any]) -> tuple[str, str]:
    """A run's status and error cells, the status not repeated: a divergence's 'diverged at
    t = 0.4825 s: controller.tau1 beyond 1e6' becomes ('diverged at t = 0.4825 s',
    'controller.tau1 beyond 1e6')."""
    status, error = str(r.get("status") or ""), str(r.get("error") or "")
    if status == "diverged" and error.startswith("diverged"):
        when, _, why = error.partition(": ")
        return when, why
    return status, error


def _main(runs: Sequence[Run]) -> Run:
    """The run the summary is about: the first with one (the chosen scenario), else the first."""
    return next((r for r in runs if "summary" in r), runs[0] if runs else {})


def run_report(
    record: Mapping[str, Any],
    figures: Sequence[Path] = (),
    error: BaseException | None = None,
    out: Path = Path("."),
    suffix: str = "",
) -> str:
    """The page of one `impedance-cosim run` (or swap): record is its run.json, figures the PNG
    files it wrote, error the exception it is ending with (if any)."""
    kind, problems = _status(record, error)
    command = record.get("command") or []
    verb = command[1] if len(command) > 1 else "run"
    scenario = _main(record.get("runs", [])).get("scenario") or "no scenario"
    heading = _heading(record)
    failed = kind == "failed" and "FAILED" not in heading  # e.g. an error after the runs
    title = f"impedance-cosim {verb}: {heading}" + (", FAILED" if failed else "")
    kept = ", ".join(_kept(record, figures, out, suffix))
    banner = _banner(kind, problems, record, kept, "command")
    body = _run_sections(record, figures, f"this command ({scenario})", "run.json",
                         "The columns of the CSV files that have a unit")  # fmt: skip
    return page(title, f'<p class="{kind}">{_e(banner)}</p>\n{body}')


def result_report(record: Mapping[str, Any], figures: Sequence[Path] = ()) -> str:
    """The page of a Result of the Python API (impedance_cosim.simulate): record is its
    provenance (run.json's form, with the call instead of a command), figures its PNG files."""
    kind, problems = _status(record, None)
    main = _main(record.get("runs", []))
    scenario = main.get("scenario") or "no scenario"
    call = str(record.get("call") or "simulate(...)")
    title = f"impedance_cosim.{call.partition('(')[0]}: {_heading(record)}"
    rows = main.get("rows", 0)
    banner = {
        "ok": f"The run reached its stop time ({rows} rows).",
        "diverged": f"The run diverged (a result): {problems}. The Result keeps its {rows} rows,"
        " up to the divergence.",
        "failed": f"This run FAILED: {problems}. The Result keeps its {rows} rows.",
    }[kind]
    units = "The signals that have a unit"
    none = f"No figures: {'the run has no summary' if kind == 'ok' else 'the run did not finish'}."
    body = _run_sections(record, figures, f"this run ({scenario})", "Result.provenance", units,
                         none)  # fmt: skip
    return page(title, f'<p class="{kind}">{_e(banner)}</p>\n{body}')


def _run_sections(record: Mapping[str, Any], figures: Sequence[Path], column: str, source: str,
                  units: str, no_figures: str = "") -> str:  # fmt: skip
    """The summary against the paper (and its every value), figures, runs, provenance and units
    of a run's page; column heads the measured values, source names where the record is kept."""
    runs = list(record.get("runs", []))
    main = _main(runs)
    parts = ["<h2>The summary against the paper</h2>"]
    if not main.get("summary"):  # the API's summary_error reads "no summary: <why>"
        reason = main.get("summary_error") or "no summary: the main run did not finish"
        parts.append(f"<p>{_e(reason[:1].upper() + reason[1:])}.</p>")
    diverged = (main.get("summary") or {}).get("status") == "diverged"
    if diverged:
        parts.append(f"<p>{_e(main['summary'].get('diverged'))}: the paper's quantities are not"
                     " measured on a diverging loop (its rows up to the divergence are in its"
                     " CSV, its Fig. 4 below).</p>")  # fmt: skip
    from impedance_cosim.apps.paper_claims import PAPER, PARAMETER_CLAIMS  # (loads the models)

    rows = []
    for c in PAPER:
        try:
            measured = c.measured(main, runs)
        except (AttributeError, KeyError, TypeError, ValueError, ZeroDivisionError):
            measured = None
        if diverged and c.measured not in PARAMETER_CLAIMS and c is not PAPER[-1]:
            measured = "not measured: the run diverged"
        rows.append((c.quantity, c.paper, c.source, measured or "not in this run"))
    parts.append(table(["", "the paper", "where", column], rows))
    if main.get("summary"):
        values = [(k, plain(v)) for k, v in main["summary"].items()]
        parts.append("<details><summary>Every value of the summary</summary>"
                     f"{table(['quantity', 'value'], values)}</details>")  # fmt: skip

    parts.append("<h2>Figures</h2>" + _figures(figures, no_figures))

    parts.append("<h2>Runs</h2>")
    parts.append(table(
        ["run", "status", "error", "rows", "CSV", "algorithm", "step [s]", "stop [s]",
         "wall time [s]", "real-time factor", "overrides"],
        [(label(r), *_outcome(r), r.get("rows", ""), r.get("csv", ""), r.get("algorithm"),
          r.get("step_size"), r.get("stop_time"), fixed(r.get("wall_time_s"), 2),
          fixed(r.get("real_time_factor"), 1), plain(r.get("overrides") or ""))
         for r in runs]))  # fmt: skip

    parts.append(_provenance(record, runs, source))
    found: dict[str, str] = {}
    for r in runs:
        found.update({k: v for k, v in r.get("units", {}).items() if k not in found})
    parts.append(f"<h2>Signals and units</h2><p>{_e(units)} (from the FMUs' model descriptions, "
                 f"as in {_e(source)}).</p>")  # fmt: skip
    parts.append(table(["signal", "unit"], sorted(found.items())) if found else "<p>None.</p>")
    return "\n".join(parts)


def _provenance(record: Mapping[str, Any], runs: Sequence[Run], source: str) -> str:
    """Command (or the API's call), system archive, times, host, FMU files with sha256,
    parameters, versions."""
    system = record.get("system", {})
    command = record.get("command")
    head = [
        ("command", shlex.join(command)) if command else ("call", record.get("call", "")),
        ("system archive", system.get("ssp", "")),
        ("system archive sha256", system.get("sha256", "")),
        ("started (UTC)", record.get("started", "")),
        ("wall time [s]", fixed(record.get("wall_time_s"), 2)),
        ("host", " ".join(str(v) for v in record.get("host", {}).values())),
    ]
    parts = [f"<h2>Provenance</h2><p>As recorded in {_e(source)}.</p>", table(["", ""], head)]
    fmus: dict[tuple, list[str]] = {}
    for r in runs:
        for comp, f in r.get("fmus", {}).items():
            key = (comp, f.get("file"), f.get("in_system_archive"), f.get("sha256"),
                   f.get("model"), f.get("fmi_version"), f.get("generation_tool"))  # fmt: skip
            fmus.setdefault(key, []).append(label(r))
    parts.append("<h3>FMU files</h3>" + table(
        ["component", "file", "in the system archive", "sha256", "model", "FMI", "generated by",
         "runs"], [(*k, ", ".join(v)) for k, v in fmus.items()]))  # fmt: skip
    sets: dict[tuple, list[str]] = {}  # each parameter set once, with the runs that used it
    for r in runs:
        values = tuple((f"{c}.{k}", plain(v)) for c, p in r.get("parameters", {}).items()
                       for k, v in p.items())  # fmt: skip
        sets.setdefault(values, []).append(label(r))
    for values, names in sets.items():
        parts.append(f"<details><summary>Parameters in effect: {_e(', '.join(names))}</summary>"
                     f"{table(['parameter', 'value'], values)}</details>")  # fmt: skip
    versions = [(k, v or "not installed") for k, v in record.get("versions", {}).items()]
    parts.append("<h3>Versions</h3>" + table(["package", "version"], versions))
    return "\n".join(parts)


def write_run_report(
    out: Path,
    record: Mapping[str, Any],
    figures: Sequence[Path] = (),
    error: BaseException | None = None,
    suffix: str = "",
) -> Path | None:
    """`report.html` in the results folder out (see run_report), written atomically; suffix
    ".partial": the page of a command that did not complete, beside an earlier one's."""
    page = run_report(record, figures, error, Path(out), suffix)
    return _write(Path(out) / (REPORT_NAME + suffix), page, error)


def write_result_report(path: Path, record: Mapping[str, Any],
                        signals: Mapping[str, Any] | None) -> Path:  # fmt: skip
    """A Result's page at path (see result_report), written atomically, with Figs. 1-3 drawn from
    signals (None: no figures); OSError (one line, with the path) when it cannot be written."""
    import tempfile

    from impedance_cosim.apps import analysis

    draw = {"fig1_position_force.png": analysis.figure_1, "fig2_observer.png": analysis.figure_2,
            "fig3_velocity_tracking.png": analysis.figure_3}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="impcosim_report_") as tmp:
        figures = [] if signals is None else [Path(tmp) / name for name in draw]
        for figure in figures:
            draw[figure.name](signals, figure)
        page = result_report(record, figures)
    written = _write(Path(path), page, None)
    assert written is not None  # _write raises when there is no error to report
    return written


# --- the sweep report -------------------------------------------------------------------------


def sweep_report(
    rows: Sequence[Mapping[str, Any]] | Path,
    maps: Sequence[Path],
    provenance: Mapping[str, Any],
    title: str = "impedance-cosim sweep",
) -> str:
    """The page of a sweep: rows of its table (or the CSV path), its map PNGs and provenance
    (e.g. the plan record: archive sha256, axes, options; and the command)."""
    source = rows if isinstance(rows, Path) else None
    if isinstance(rows, Path):
        with open(rows, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    bad = sum(1 for r in rows if str(r.get("status", "")) not in ("ok", ""))
    summary = f"{len(rows)} runs, {len(rows) - bad} ok, {bad} not"
    parts = [f'<p class="{"failed" if bad else "ok"}">{_e(summary)}.</p>', "<h2>Provenance</h2>"]
    info = [(k, shlex.join(v) if k == "command" and isinstance(v, list) else plain(v))
            for k, v in provenance.items()]  # fmt: skip
    parts.append(table(["", ""], info))
    parts.append("<h2>Maps</h2>" + _figures(maps))
    columns: list[str] = []
    for r in rows:
        columns += [k for k in r if k not in columns]
    shown = rows[:MAX_TABLE_ROWS]
    where = f" (all in {source.name})" if source else ""
    note = f"first {len(shown)} of {len(rows)} rows{where}" if len(shown) < len(rows) else (
        f"{len(rows)} rows{where}")  # fmt: skip
    parts.append(f"<h2>Table</h2><p>{_e(note)}.</p>")
    parts.append(table(columns, [[plain(r.get(c)) for c in columns] for r in shown]))
    return page(title, "\n".join(parts))


def write_sweep_report(
    out: Path,
    rows: Sequence[Mapping[str, Any]] | Path,
    maps: Sequence[Path],
    provenance: Mapping[str, Any],
    title: str = "impedance-cosim sweep",
    name: str = REPORT_NAME,
) -> Path | None:
    """`report.html` (or `name`) of a sweep in its folder out (see sweep_report), atomically."""
    return _write(Path(out) / name, sweep_report(rows, maps, provenance, title), None)
