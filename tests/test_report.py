"""report.html (issue 14): `impedance-cosim run` leaves one self-contained page in its results
folder (also when it failed; none with --no-report), and a sweep's page is made from its table,
maps and provenance. Each page must parse as HTML5 without a parse error (html5lib, strict), embed
every image as a PNG data: URI and reference nothing outside itself; a real browser (Debian's
chromium, headless) opens it and decodes every image. Without chromium that test skips; with
IMPCOSIM_REQUIRE_PLATFORMS=1 (set by .ci/run) it fails instead."""

from __future__ import annotations

import base64
import io
import json
import os
import shlex
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import html5lib
import matplotlib.image
import pytest

from impedance_cosim.apps import html_page, report
from impedance_cosim.cli import main
from impedance_cosim.cosim.results.provenance import file_sha256

REQUIRE = os.environ.get("IMPCOSIM_REQUIRE_PLATFORMS") == "1"
VOID = {"meta", "img", "br", "hr", "input", "link", "source", "wbr", "col", "area", "base"}
FETCHING = {"link", "script", "iframe", "frame", "object", "embed", "base", "audio", "video",
            "source", "track", "picture", "form"}  # fmt: skip
URL_ATTRIBUTES = {"src", "href", "srcset", "poster", "data", "action", "formaction", "background",
                  "ping", "manifest", "cite", "longdesc", "xlink:href"}  # fmt: skip


class Page(HTMLParser):
    """The parts of a page the checks look at: elements, tables (rows of cell texts), text, and
    end tags that do not close the element that is open (a check of our own beside html5lib's)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.doctype = ""
        self.elements: list[tuple[str, dict[str, str | None]]] = []
        self.stack: list[str] = []
        self.mismatched: list[str] = []
        self.tables: list[list[list[str]]] = []
        self.text: list[str] = []
        self.style = ""

    def handle_decl(self, decl: str) -> None:
        self.doctype = decl

    def handle_starttag(self, tag: str, attrs: list) -> None:
        self.elements.append((tag, dict(attrs)))
        if tag not in VOID:
            self.stack.append(tag)
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self.tables[-1][-1].append("")

    def handle_endtag(self, tag: str) -> None:
        if not self.stack or self.stack.pop() != tag:
            self.mismatched.append(tag)

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self.stack and self.stack[-1] in ("td", "th"):
            self.tables[-1][-1][-1] += data
        if self.stack and self.stack[-1] == "style":
            self.style += data

    def row(self, first: str) -> list[str]:
        """The table row whose first cell is first."""
        rows = [r for t in self.tables for r in t if r and r[0] == first]
        assert len(rows) == 1, f"{len(rows)} rows start with {first!r}"
        return rows[0]

    def images(self) -> list[bytes]:
        """The bytes of every <img>, each checked to be a PNG data: URI that matplotlib reads at
        the size the page declares."""
        out = []
        for tag, attrs in self.elements:
            if tag != "img":
                continue
            head, _, payload = (attrs.get("src") or "").partition(",")
            assert head == "data:image/png;base64", head[:60]
            data = base64.b64decode(payload, validate=True)
            assert data.startswith(b"\x89PNG\r\n\x1a\n")
            pixels = matplotlib.image.imread(io.BytesIO(data), format="png")
            assert pixels.shape[:2] == (int(attrs["height"]), int(attrs["width"]))
            assert attrs.get("alt")
            out.append(data)
        return out


def check_page(path: Path) -> Page:
    """Parse a page as HTML5 (a parse error fails), and check it references nothing outside."""
    text = path.read_text(encoding="utf-8")
    html5lib.HTMLParser(strict=True).parse(text)  # raises html5lib's ParseError
    page = Page()
    page.feed(text)
    page.close()
    assert page.doctype.lower() == "doctype html"
    assert not page.mismatched and page.stack == [], (page.mismatched, page.stack)
    assert not FETCHING & {tag for tag, _ in page.elements}
    for tag, attrs in page.elements:
        for name in URL_ATTRIBUTES & set(attrs):
            assert tag == "img" and name == "src", f"<{tag} {name}=...>"
        assert not any(name.startswith("on") for name in attrs), tag  # no event handlers
    assert "url(" not in page.style and "@import" not in page.style
    assert "http://" not in text and "https://" not in text and "file:" not in text
    return page


@pytest.fixture(scope="module")
def paper_run(ssp_path, tmp_path_factory) -> Path:
    """`impedance-cosim run` over 4.5 s (the first contact and its impact) with its figures."""
    out = tmp_path_factory.mktemp("report") / "res"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "4.5", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    return out


def test_run_writes_a_self_contained_report(paper_run, ssp_path):
    page = check_page(paper_run / "report.html")
    text = "".join(page.text)
    record = json.loads((paper_run / "run.json").read_text())
    # every figure the run wrote, embedded byte for byte
    figures = sorted(paper_run.glob("fig*.png"))
    assert len(figures) == 4
    assert sorted(page.images()) == sorted(f.read_bytes() for f in figures)
    # provenance: the archive's sha256, the FMU files', the scenario, the command
    assert page.row("system archive sha256")[1] == file_sha256(ssp_path)
    for run in record["runs"]:
        for fmu in run["fmus"].values():
            assert fmu["sha256"] in text
    assert ("impedance-cosim run: observer ok, difference ok; Fig. 4 comparison (jacobi):"
            " observer ok, difference diverged at t = 0.4825 s") in text  # fmt: skip
    assert page.row("command")[1].endswith(f"--stop 4.5 --out {paper_run} --no-progress")
    runs = next(t for t in page.tables if t[0][0] == "run")
    assert [r[:4] for r in runs[1:]] == [
        ["observer", "ok", "", "1801"], ["difference", "ok", "", "1801"],
        ["observer (Jacobi, Fig. 4 comparison)", "ok", "", "1801"],
        ["difference (Jacobi, Fig. 4 comparison)", "diverged at t = 0.4825 s",
         "controller.tau1 beyond 1e6 (-1.071e6)", "194"]]  # fmt: skip
    # each parameter set once, naming the runs that used it
    assert [t for t in page.text if t.startswith("Parameters in effect")] == [
        "Parameters in effect: observer, observer (Jacobi, Fig. 4 comparison)",
        "Parameters in effect: difference, difference (Jacobi, Fig. 4 comparison)",
    ]
    # the summary against the paper, with this run's numbers
    summary = record["runs"][0]["summary"]
    assert page.row("contact force")[1:3] == ["19.6 N (10^4 N/m x 0.00196 m)", "section 5, Fig. 1d"]
    assert "settled_force_N" not in summary  # 4.5 s: the force still moves after the impact
    assert page.row("contact force")[3] == "not settled (contact 3.85-4.50 s)"
    assert f"peak {summary['impact_peak_N']:.1f} N" in page.row("impact")[3]
    assert page.row("update frequency")[1:] == ["400 Hz", "section 5", "400 Hz (gauss-seidel)"]
    assert page.row("gains")[3].endswith("(as in the paper)")
    assert page.row("numerical differentiation in the loop")[3].startswith("difference (")
    # the units of the signals, as in run.json
    assert page.row("plant.contact_force") == ["plant.contact_force", "N"]
    assert page.row("controller.tau1") == ["controller.tau1", "N.m"]


def test_no_report_writes_none(ssp_path, tmp_path):
    out = tmp_path / "res"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.2", "--out", str(out), "--no-progress",
            "--no-figures", "--no-report"]  # fmt: skip
    assert main(argv) == 0
    assert (out / "run.json").is_file() and not (out / "report.html").exists()


def test_swap_shares_the_option(capsys):
    with pytest.raises(SystemExit):
        main(["swap", "--help"])
    assert "--no-report" in capsys.readouterr().out


def test_a_failed_run_writes_a_report_saying_so(ssp_path, tmp_path):
    out = tmp_path / "bad"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.5", "--set", "plant.x0=5.0",
            "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 1
    page = check_page(out / "report.html.partial")  # the command did not complete: .partial
    text = " ".join(page.text)
    assert "impedance-cosim run: observer FAILED" in text
    assert "This command FAILED: observer: failed:" in text and "is unreachable" in text
    assert (
        "Kept in the results folder: observer.csv.partial (0 rows, observer), run.json.partial"
        in text
    )
    assert page.images() == [] and "No figures were made by this command." in text
    assert page.row("start pose")[3] == "(5.0 m, 0.0 m) (NOT the paper)"


def test_an_error_before_any_run_writes_no_report(ssp_path, tmp_path, capsys):
    """Bad input is one line and writes nothing, not even the folder (issue 20)."""
    out = tmp_path / "bad"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.5", "--set", "controller.nosuch=1",
            "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 2
    assert "unknown parameter controller.nosuch given with --set" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_files_of_an_earlier_run_are_removed(ssp_path, tmp_path, capsys):
    """A results folder describes one run: the figures, CSVs and summaries of an earlier command
    that this one did not write are removed (known names only), and one line says which."""
    out = tmp_path / "res"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.6", "--out", str(out), "--no-progress"]
    assert main([*argv, "--scenario", "difference"]) == 0
    assert len(check_page(out / "report.html").images()) == 4
    assert (out / "difference_summary.json").is_file() and (out / "observer-jacobi.csv").is_file()
    (out / "notes.txt").write_text("mine")  # not a name we write: left alone
    capsys.readouterr()
    assert main([*argv, "--no-figures"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    stale = ["difference-jacobi.csv", "difference.csv", "difference_summary.json",
             "fig1_position_force.png", "fig2_observer.png", "fig3_velocity_tracking.png",
             "fig4_observer_vs_difference.png", "observer-jacobi.csv"]  # fmt: skip
    assert err == [f"impedance-cosim run: removed {len(stale)} file(s) of an earlier run from"
                   f" {out}/: {', '.join(stale)}"]  # fmt: skip
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "notes.txt",
        "observer.csv",
        "observer_summary.json",
        "report.html",
        "run.json",
    ]
    page = check_page(out / "report.html")
    assert page.images() == [] and "fig1_position_force.png" not in "".join(page.text)


def test_the_heading_states_each_runs_status():
    """The observer ok and the difference failed (or diverged): the heading says each, not
    "observer, FAILED"."""
    observer = {"scenario": "observer", "status": "ok", "summary": {}}
    failed = {"scenario": "difference", "status": "failed", "error": "plant: doStep failed"}
    error = "diverged at t = 0.4825 s: controller.tau1 beyond 1e6 (-1.071e6)"
    diverged = {"scenario": "difference", "status": "diverged", "error": error}
    command = ["impedance-cosim", "run"]
    page = report.run_report({"command": command, "runs": [observer, failed]})
    assert "<h1>impedance-cosim run: observer ok, difference FAILED</h1>" in page
    assert 'class="failed">This command FAILED: difference: failed: plant: doStep' in page
    page = report.run_report({"command": command, "runs": [observer, diverged]})
    assert "<h1>impedance-cosim run: observer ok, difference diverged at t = 0.4825 s</h1>" in page
    assert 'class="diverged">A run diverged (a result, exit status 3;' in page
    page = report.run_report({"command": command, "runs": [observer]}, error=OSError("disk"))
    assert "<h1>impedance-cosim run: observer ok, FAILED</h1>" in page


RUNS_HEAD = ["run", "status", "error", "rows"]


def _runs_table(text: str) -> list[list[str]]:
    page = Page()
    page.feed(text)
    return next(t for t in page.tables if t[0][:4] == RUNS_HEAD)[1:]


def _record() -> dict:
    """A default run's record: the pair, and the pair again under Jacobi for Fig. 4."""
    error = "diverged at t = 0.4825 s: controller.tau1 beyond 1e6 (-1.071e6)"
    p_obs = {"controller": {"velocity_source": 1}}
    p_dif = {"controller": {"velocity_source": 0}}
    runs = [
        {"scenario": "observer", "status": "ok", "rows": 8001, "algorithm": "gauss-seidel",
         "parameters": p_obs, "summary": {}},
        {"scenario": "difference", "status": "ok", "rows": 8001, "algorithm": "gauss-seidel",
         "parameters": p_dif},
        {"scenario": "observer", "status": "ok", "rows": 8001, "algorithm": "jacobi",
         "role": "Fig. 4 comparison", "parameters": p_obs},
        {"scenario": "difference", "status": "diverged", "rows": 194, "algorithm": "jacobi",
         "role": "Fig. 4 comparison", "error": error, "parameters": p_dif},
    ]  # fmt: skip
    return {"command": ["impedance-cosim", "run"], "runs": runs}


def test_the_runs_table_says_a_divergence_once():
    """'diverged' once: the status cell says when, the error cell why (not 'diverged: diverged
    at ...')."""
    text = report.run_report(_record())
    row = _runs_table(text)[3]
    assert row[1:3] == ["diverged at t = 0.4825 s", "controller.tau1 beyond 1e6 (-1.071e6)"]
    assert " ".join(row).count("diverged") == 1
    assert "diverged: diverged" not in text


def test_the_runs_for_fig4_are_labelled_with_their_algorithm_and_role():
    rows = _runs_table(report.run_report(_record()))
    assert [r[0] for r in rows] == ["observer", "difference",
                                    "observer (Jacobi, Fig. 4 comparison)",
                                    "difference (Jacobi, Fig. 4 comparison)"]  # fmt: skip


def test_each_parameter_set_is_listed_once():
    page = Page()
    page.feed(report.run_report(_record()))
    summaries = [t for t in page.text if t.startswith("Parameters in effect")]
    assert summaries == [
        "Parameters in effect: observer, observer (Jacobi, Fig. 4 comparison)",
        "Parameters in effect: difference, difference (Jacobi, Fig. 4 comparison)",
    ]


def test_number_cells_do_not_wrap():
    """Every cell that is one number has class "n", which the style sheet keeps on one line."""
    text = report.run_report(_record())
    assert "td.n{white-space:nowrap}" in html_page.STYLE
    assert '<td class="n">8001</td>' in text and '<td class="n">194</td>' in text
    assert html_page.table([], [["0.0025", "-1.5e6", "abc", "800/1", ""]]) == (
        '<table><tbody><tr><td class="n">0.0025</td><td class="n">-1.5e6</td><td>abc</td>'
        "<td>800/1</td><td></td></tr></tbody></table>"
    )


def test_a_report_that_cannot_be_written_is_one_line(ssp_path, tmp_path, capsys):
    out = tmp_path / "res"
    (out / "report.html").mkdir(parents=True)  # in the way of the rename
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.2", "--out", str(out), "--no-progress",
            "--no-figures"]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("impedance-cosim run: error: could not write") and "\n" not in err
    assert (out / "run.json").is_file()
    assert report.write_run_report(out, {}, error=ValueError("x")) is None  # the error goes on
    assert "could not write" in capsys.readouterr().err


def _png(path: Path, color: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 1.5))
    ax.imshow([[0, 1], [1, 0]], cmap="gray" if color == "gray" else "viridis")
    fig.savefig(path, dpi=50)
    plt.close(fig)
    return path


def test_sweep_report_shows_maps_table_and_provenance(tmp_path):
    maps = [_png(tmp_path / "sweep_peak_force.png", "gray"), _png(tmp_path / "b.png", "color")]
    rows = [
        {"run": 1, "controller.K": 50.0, "status": "ok", "error": None, "peak_force": 88.0},
        {"run": 2, "controller.K": 5.0, "status": "ok", "error": None, "peak_force": 91.5},
        {"run": 3, "controller.K": 0.5, "status": "diverged", "peak_force": None,
         "error": "</td><script>alert(1)</script>"},  # hostile text stays text
    ]  # fmt: skip
    plan = {"command": ["impedance-cosim", "sweep", "--grid", "controller.K=0.5,5,50"],
            "ssp_sha256": "ab" * 32, "axes": {"controller.K": [0.5, 5, 50]}}  # fmt: skip
    path = report.write_sweep_report(tmp_path, rows, [*maps, tmp_path / "missing.png"], plan)
    assert path == tmp_path / "report.html"
    page = check_page(path)
    assert page.images() == [m.read_bytes() for m in maps]
    text = " ".join(page.text)
    assert "3 runs, 2 ok, 1 not." in text and "missing.png: missing or not a PNG" in text
    assert page.row("command")[1] == "impedance-cosim sweep --grid controller.K=0.5,5,50"
    assert page.row("ssp_sha256")[1] == "ab" * 32
    assert page.row("3") == ["3", "0.5", "diverged", "</td><script>alert(1)</script>", ""]
    assert page.tables[-1][0] == ["run", "controller.K", "status", "error", "peak_force"]


def test_sweep_writes_its_report(ssp_path, tmp_path):
    out = tmp_path / "sweep"
    argv = ["sweep", "--serial", "--ssp", str(ssp_path), "--stop", "0.5", "--out", str(out),
            "--grid", "controller.velocity_source=observer,7", "--plot", "peak_torque_N_m",
            "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    page = check_page(out / "report.html")
    assert page.images() == [(out / "sweep_peak_torque_N_m.png").read_bytes()]
    assert "2 runs, 1 ok, 1 not." in " ".join(page.text)
    assert page.row("command")[1] == shlex.join(["impedance-cosim", *argv])
    assert page.row("ssp_sha256")[1] == file_sha256(ssp_path)
    table = page.tables[-1]
    assert [r[table[0].index("status")] for r in table[1:]] == ["ok", "failed"]
    assert main([*argv, "--out", str(tmp_path / "b"), "--no-report"]) == 0
    assert not (tmp_path / "b" / "report.html").exists() and (tmp_path / "b" / "sweep.csv").exists()


@pytest.mark.slow
def test_the_study_writes_a_page_per_map(native_ssp, tmp_path):
    """sweep --study: map_<name>.report.html beside each table, with its plots embedded, and the
    table's provenance (map_<name>.run.json)."""
    import json

    out = tmp_path / "study"
    argv = ["sweep", "--study", "delay", "--serial", "--ssp", str(native_ssp), "--stop", "0.2",
            "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    page = check_page(out / "map_delay.report.html")
    assert page.images() == [(out / "map_delay.png").read_bytes()]
    assert page.row("ssp_sha256")[1] == file_sha256(native_ssp)
    rows = len((out / "map_delay.csv").read_text().splitlines()) - 1
    table = page.tables[-1]
    assert len(table) - 1 == rows > 0
    record = json.loads((out / "map_delay.run.json").read_text())
    assert record["table"] == "map_delay.csv" and sum(record["rows"].values()) == rows


def test_sweep_report_from_a_long_csv_table(tmp_path, monkeypatch):
    monkeypatch.setattr(report, "MAX_TABLE_ROWS", 5)
    table = tmp_path / "sweep.csv"
    table.write_text("run,plant.q_noise,status\n" + "".join(f"{i},{i}e-4,ok\n" for i in range(12)))
    page = check_page(report.write_sweep_report(tmp_path, table, [], {"runs": 12}))
    text = " ".join(page.text)
    assert "12 runs, 12 ok, 0 not." in text and "first 5 of 12 rows (all in sweep.csv)." in text
    assert len(page.tables[-1]) == 1 + 5 and page.tables[-1][-1] == ["4", "4e-4", "ok"]


def _chromium() -> str:
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is None:
        (pytest.fail if REQUIRE else pytest.skip)("chromium not found (apt-get install chromium)")
    return found


def _dump_dom(url: str, profile: Path) -> str:
    command = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
               f"--user-data-dir={profile}", "--dump-dom", url]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


@pytest.mark.tools
@pytest.mark.slow
def test_chromium_opens_the_report_and_decodes_every_image(paper_run, tmp_path):
    dom = _dump_dom((paper_run / "report.html").as_uri(), tmp_path / "profile")
    assert "<h1>impedance-cosim run: observer ok, difference ok; Fig. 4 comparison" in dom
    assert dom.count("<img ") == 4
    # A copy with a probe: the page's own policy, plus inline script for the probe only; an
    # image from a file beside it must be refused, the embedded ones decoded.
    text = (paper_run / "report.html").read_text(encoding="utf-8")
    assert f'content="{html_page.CSP}"' in text
    probe = text.replace(html_page.CSP, html_page.CSP + "; script-src 'unsafe-inline'").replace(
        "</body>",
        f'<img id="probe" alt="" src="{(paper_run / "fig1_position_force.png").as_uri()}">'
        "<script>addEventListener('load', () => { const all = [...document.images];"
        " const ok = all.filter(i => i.complete && i.naturalWidth > 0);"
        " document.body.dataset.decoded = ok.filter(i => i.id !== 'probe').length + '/' +"
        " (all.length - 1); document.body.dataset.probe = ok.some(i => i.id === 'probe'); });"
        "</script></body>",
    )
    (paper_run / "probe.html").write_text(probe, encoding="utf-8")
    dom = _dump_dom((paper_run / "probe.html").as_uri(), tmp_path / "profile")
    assert 'data-decoded="4/4"' in dom and 'data-probe="false"' in dom


@pytest.mark.slow
def test_stability_writes_its_report(native_ssp, tmp_path, capsys):
    """`impedance-cosim stability`: its figure inline, every table as in its CSV, the provenance;
    after --resume (finished parts kept) the same content; none with --no-report."""
    import csv

    out = tmp_path / "stability"
    argv = ["stability", "boundaries", "gain", "--quantity", "rate", "--sensor", "ideal",
            "--velocity", "measured", "--timing", "gauss-seidel", "--serial", "--no-progress",
            "--ssp", str(native_ssp), "--out", str(out)]  # fmt: skip
    for extra in ([], ["--resume"]):
        assert main([*argv, *extra]) == 0
        page = check_page(out / "report.html")
        text = " ".join(page.text)
        assert "impedance-cosim stability: boundaries, gain, ok" in text
        assert "All parts finished: boundaries, gain." in text
        assert page.images() == [(out / "boundaries.png").read_bytes()]
        assert page.row("command")[1] == shlex.join(["impedance-cosim", *argv, *extra])
        assert page.row("system archive sha256")[1] == file_sha256(native_ssp)
        for name, rows in (("boundaries.csv", 1), ("observer_discretization.csv", 30)):
            with open(out / name, newline="") as f:
                table = list(csv.reader(f))
            assert len(table) == 1 + rows and table in page.tables
        assert "finished: 30 rows from 30 runs" in text
    assert f"kept {out / 'boundaries.csv'} (finished earlier)" in capsys.readouterr().out
    assert json.loads((out / "stability.run.json").read_text())["parts"]["gain"]["kept_by_resume"]
    other = tmp_path / "b"
    assert main([*argv[:2], *argv[3:-1], str(other), "--no-report"]) == 0
    assert (other / "boundaries.csv").is_file() and not (other / "report.html").exists()
