"""The report page reads well in a browser 1280 px wide: no table (FMU files with their sha256,
long paths) wider than the window, and measured times with a sensible number of digits (run.json
keeps them all). Opened by chromium, headless, as in tests/test_report.py."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from test_report import _record

from impedance_cosim.apps import html_page, report
from impedance_cosim.cli import main

REQUIRE = os.environ.get("IMPCOSIM_REQUIRE_PLATFORMS") == "1"


@pytest.fixture(scope="module")
def short_run(ssp_path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("layout") / "res"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.5", "--out", str(out), "--no-progress",
            "--no-figures"]  # fmt: skip
    assert main(argv) == 0
    return out


def _widths(page: Path, profile: Path) -> tuple[int, int]:
    """(document width, window width) in CSS px, from the page with a probe script added."""
    found = _probe(page, profile, "document.documentElement.scrollWidth + 'x' + window.innerWidth")
    width, window = found.split("x")
    return int(width), int(window)


def _probe(page: Path, profile: Path, expression: str, window: str = "1280,900") -> str:
    """The value of a JavaScript expression in the page as chromium (headless) lays it out."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        (pytest.fail if REQUIRE else pytest.skip)("chromium not found (apt-get install chromium)")
    text = page.read_text(encoding="utf-8")
    probe = page.with_name("probe.html")
    probe.write_text(
        text.replace(html_page.CSP, html_page.CSP + "; script-src 'unsafe-inline'").replace(
            "</body>",
            f"<script>document.body.dataset.w = String({expression});</script></body>",
        ),
        encoding="utf-8",
    )
    command = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
               "--disable-background-networking", f"--user-data-dir={profile}",
               f"--window-size={window}", "--dump-dom", probe.as_uri()]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=180, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    found = re.search(r'data-w="([^"]*)"', done.stdout)
    assert found, done.stdout[-2000:]
    return found[1]


@pytest.mark.tools
def test_no_table_is_wider_than_a_1280_px_window(short_run, tmp_path):
    width, window = _widths(short_run / "report.html", tmp_path / "profile")
    assert window >= 1200 and width <= window, (width, window)


def test_times_in_the_page_are_rounded_and_every_digit_stays_in_run_json(short_run):
    record = json.loads((short_run / "run.json").read_text())
    wall = record["runs"][0]["wall_time_s"]
    text = (short_run / "report.html").read_text(encoding="utf-8")
    assert f'<td class="n">{wall:.2f}</td>' in text
    runs = text.split("<h2>Runs")[1].split("<h2>Provenance")[0]
    head = text.split("<h2>Provenance")[1].split("<h3>")[0]
    assert not re.search(r'<td( class="n")?>\d+\.\d{5,}</td>', runs + head), runs + head


# The lines each number cell of the page takes (a Range's rectangles: one per line of text).
WRAPPED = """[...document.querySelectorAll('td.n')].filter(td => { const r = document.createRange();
r.selectNodeContents(td); return r.getClientRects().length > 1; }).map(td => td.textContent)
.join(' ') || 'none'"""


@pytest.mark.tools
def test_numbers_in_the_runs_table_do_not_wrap_in_a_narrow_window(tmp_path):
    """A default run's table (the pair and its Jacobi pair, a divergence's long error) in a
    window 700 px wide: no number is broken over two lines (800/1, 0.002/5)."""
    page = tmp_path / "report.html"
    page.write_text(report.run_report(_record()), encoding="utf-8")
    numbers = _probe(page, tmp_path / "profile", WRAPPED.replace("\n", " "), "700,900")
    assert numbers == "none", f"wrapped over lines: {numbers}"
