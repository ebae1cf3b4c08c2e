"""Every figure and table committed under docs/ is written by a command named next to it: in
docs/figures.md, from benchmarks/docs_figures.py's WRITERS, and the command's code does write a
file of that name; the committed Fig. 4 figures are the ones `run` draws now."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))

from docs_figures import WRITERS  # noqa: E402


def committed() -> list[str]:
    """The PNG and CSV files under docs/ that git tracks (or, outside a checkout, that exist)."""
    try:
        done = subprocess.run(["git", "ls-files", "docs"], cwd=REPO, capture_output=True,
                              text=True, check=True, timeout=60)  # fmt: skip
        files = [Path(p) for p in done.stdout.split()]
    except (OSError, subprocess.CalledProcessError):
        files = [p.relative_to(REPO) for p in (REPO / "docs").iterdir()]
    return sorted(p.name for p in files if p.parent.name == "docs" and p.suffix in (".png", ".csv"))


def test_every_docs_file_has_a_writer_named_in_the_markdown():
    files = committed()
    assert files, "no docs files found"
    missing = [f for f in files if f not in WRITERS]
    assert not missing, f"docs files written by no command in WRITERS: {missing}"
    gone = [f for f in WRITERS if not (REPO / "docs" / f).is_file()]
    assert not gone, f"WRITERS names files docs/ does not have: {gone}"
    table = (REPO / "docs" / "figures.md").read_text(encoding="utf-8").splitlines()
    for name in files:
        lines = [line for line in table if f"`{name}`" in line]
        assert lines, f"docs/figures.md does not name {name}"
        assert f"`{WRITERS[name].command()}`" in lines[0], f"{name}: not next to its command"


def test_each_writer_writes_that_file():
    """The name a command writes in its --out folder is one its code writes."""
    from impedance_cosim.apps.report import CAPTIONS
    from impedance_cosim.apps.stability.command import FIGURES, TABLES
    from impedance_cosim.apps.sweep.study import STUDY

    study = set()
    for name, m in STUDY.items():
        study |= {f"map_{name}.csv", f"map_{name}.png"}
        study |= {f"map_{name}_{metric}.png" for metric in m.plots[1:]}
    writes = {"run": set(CAPTIONS), "stability": {*TABLES.values(), *FIGURES.values()},
              "sweep": study}  # fmt: skip
    for name, w in WRITERS.items():
        if w.script:  # told the file's path: the script must take --figure
            assert "--figure" in (REPO / w.script).read_text(encoding="utf-8"), name
            continue
        assert w.writes in writes[w.argv[0]], f"{name}: `{w.command()}` writes no {w.writes}"


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.mark.parametrize(("name", "rows"), [("fig4_observer_vs_difference.png", 2),
                                            ("fig4_jacobi.png", 1)])  # fmt: skip
def test_the_committed_fig4_is_the_one_run_draws(name, rows):
    """Regenerated with the command (benchmarks/docs_figures.py run): analysis.figure_4's size
    for its rows of conditions (two for the default run, one under Jacobi)."""
    from impedance_cosim.apps.analysis import FIG4_DPI, FIG4_ROW_INCHES, FIG4_WIDTH_INCHES

    width, height = _png_size(REPO / "docs" / name)
    assert width == round(FIG4_WIDTH_INCHES * FIG4_DPI)
    assert height == round((1.0 + FIG4_ROW_INCHES * rows) * FIG4_DPI)
