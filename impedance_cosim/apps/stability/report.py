"""`report.html` of `impedance-cosim stability`: one self-contained page (as apps.report's: figures
inline, nothing fetched) with how it ended (and what was kept when it did not finish), the
provenance (stability.run.json), and per part its status, plan, figure and table."""

from __future__ import annotations

import csv
import shlex
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from impedance_cosim.apps import report
from impedance_cosim.apps.html_page import esc as _e
from impedance_cosim.apps.html_page import page as _page
from impedance_cosim.apps.html_page import plain as _plain
from impedance_cosim.apps.html_page import table as _table
from impedance_cosim.apps.report import REPORT_NAME, _figures, _write
from impedance_cosim.apps.stability.log import Record

WHAT = {
    "boundaries": "critical sample rate, observer gain K and wall stiffness, by bisection",
    "linear": "the linearised loop's critical rates next to the bisected ones",
    "fig4": "the Fig. 4 candidate conditions",
    "gain": "the observer discretizations at 400 Hz",
}


def _csv_table(path: Path) -> str:
    """A table file as an HTML table (at most report.MAX_TABLE_ROWS rows)."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        return f"<p>{_e(path.name)}: cannot be read ({_e(exc)}).</p>"
    if not rows:
        return f"<p>{_e(path.name)} is empty.</p>"
    body = rows[1 : 1 + report.MAX_TABLE_ROWS]
    note = f"{len(rows) - 1} row{'s' * (len(rows) != 2)}"
    if len(body) < len(rows) - 1:
        note += f", the first {len(body)} shown"
    return f"<p>{_e(path.name)} ({_e(note)}):</p>" + _table(rows[0], body)


def _part(out: Path, name: str, entry: Mapping[str, Any]) -> str:
    status = entry.get("status", "not started")
    table = out / str(entry.get("table", ""))
    if status == "finished":
        kept = entry.get("kept_runs")
        runs = entry.get("runs")
        said = f"finished: {entry.get('rows')} row{'s' * (entry.get('rows') != 1)}" + (
            f" from {runs} runs ({kept} kept from an earlier run)" if runs is not None else
            " (earlier: kept by --resume)")  # fmt: skip
    elif status in ("interrupted", "failed"):
        said = (f"{status.upper()}: {entry.get('error', '')}; {entry.get('runs', 0)} finished "
                f"runs kept in {entry.get('log')} (--resume finishes it)")  # fmt: skip
    else:
        said = status
    parts = [f"<h2>{_e(name)}: {_e(WHAT.get(name, ''))}</h2>",
             f'<p class="{"ok" if status == "finished" else "failed"}">{_e(said)}</p>']  # fmt: skip
    plan = [(k, _plain(v)) for k, v in entry.get("plan", {}).items()]
    parts.append(f"<details><summary>Plan (checked by --resume)</summary>"
                 f"{_table(['', ''], plan)}</details>")  # fmt: skip
    figures = [out / Path(str(f)).name for f in entry.get("figures", [])]
    if figures:
        parts.append(_figures(figures))
    if status == "finished":
        parts.append(_csv_table(table))
    return "\n".join(parts)


def stability_report(out: Path, data: Mapping[str, Any], outcome: BaseException | None,
                     kept: str) -> str:  # fmt: skip
    """The page: data is stability.run.json's record, outcome the exception the command ends
    with (None: it finished), kept the line saying what an unfinished command kept."""
    mine = list(data.get("this_command", []))
    parts = data.get("parts", {})
    if outcome is None:
        state, banner = "ok", f"All parts finished: {', '.join(mine)}."
    else:
        text = " ".join(str(outcome).split()) or type(outcome).__name__
        stopped = isinstance(outcome, KeyboardInterrupt)
        state = "INTERRUPTED" if stopped else "FAILED"
        banner = f"This command was {state} ({text}). Kept: {kept}."
    title = f"impedance-cosim stability: {', '.join(mine) or 'nothing'}, {state}"
    body = [f'<p class="{"ok" if outcome is None else "failed"}">{_e(banner)}</p>']
    system = data.get("system", {})
    command = data.get("command")
    body.append("<h2>Provenance</h2><p>As recorded in stability.run.json.</p>" + _table(["", ""], [
        ("command", shlex.join(command) if command else ""),
        ("system archive", system.get("ssp", "")),
        ("system archive sha256", system.get("sha256", "")),
        ("started (UTC)", data.get("started", "")),
        ("wall time [s]", data.get("wall_time_s", "")),
        ("host", " ".join(str(v) for v in data.get("host", {}).values())),
    ]))  # fmt: skip
    body += [_part(out, name, parts.get(name, {})) for name in mine]
    versions = [(k, v or "not installed") for k, v in data.get("versions", {}).items()]
    body.append("<h2>Versions</h2>" + _table(["package", "version"], versions))
    return _page(title, "\n".join(body))


def write_report(out: Path, record: Record, outcome: BaseException | None) -> Path | None:
    """report.html in out (atomically); see report._write for a page that cannot be written."""
    page = stability_report(Path(out), record.data(), outcome, record.kept())
    return _write(Path(out) / REPORT_NAME, page, outcome)
