"""The example notebook runs: examples/paper_scenario.ipynb executed by nbclient in a Jupyter
kernel of this Python (paper scenario, summary, provenance, Fig. 1, a small sweep)."""

from __future__ import annotations

import csv
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient
from test_report import check_page

from impedance_cosim.cosim.results.provenance import file_sha256

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "paper_scenario.ipynb"


@pytest.fixture
def kernel(tmp_path, monkeypatch) -> str:
    """A kernel spec running ipykernel in this very Python (not whatever `python` a user-wide
    Jupyter install would start), found first through JUPYTER_PATH."""
    spec = tmp_path / "jupyter" / "kernels" / "impcosim-test"
    spec.mkdir(parents=True)
    argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    kernel_json = {"argv": argv, "display_name": "impedance-cosim tests", "language": "python"}
    (spec / "kernel.json").write_text(json.dumps(kernel_json))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    return spec.name


def test_the_notebook_is_stored_without_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(c.outputs == [] and c.execution_count is None for c in code)


@pytest.mark.slow
def test_the_notebook_runs(ssp_path, tmp_path, kernel):
    work = tmp_path / "run"
    work.mkdir()
    shutil.copy(NOTEBOOK, work / NOTEBOOK.name)
    nb = nbformat.read(work / NOTEBOOK.name, as_version=4)
    (parameters,) = [c for c in nb.cells if "parameters" in c.metadata.get("tags", [])]
    parameters.source = f"SSP = {str(ssp_path)!r}"  # this checkout's archive, built by conftest
    client = NotebookClient(nb, timeout=300, kernel_name=kernel,
                            resources={"metadata": {"path": str(work)}})  # fmt: skip
    client.execute()  # raises CellExecutionError on the first cell that fails

    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    # the paper scenario's summary (20 s: both contacts)
    assert "<Result 'observer': ok, 8001 rows to 20 s>" in text
    assert "contact with the wall: 3.85-6.21 s, 13.85-16.20 s" in text
    assert "settled contact force: 19.7" in text
    # the provenance highlights: the call and the archive's checksum
    assert f"call:      simulate('observer', ssp={str(ssp_path)!r})" in text
    assert file_sha256(ssp_path)[:16] in text
    # the sweep's table: one line per stiffness
    table = text[text.index("G1 [N/m]") :].splitlines()[1:5]
    assert [line.split()[0] for line in table] == ["250", "500", "1000", "2000"]
    assert all(float(line.split()[1]) > 0 for line in table)  # an impact in every run
    # Fig. 1 and the sweep's plot, as images
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 2
    # the result as one page (Result.report), beside the notebook
    assert "report: paper_scenario.html" in text
    page = check_page(work / "paper_scenario.html")
    assert len(page.images()) == 3
    assert "impedance_cosim.simulate: observer ok" in " ".join(page.text)


def test_what_the_notebook_writes_is_ignored_by_git():
    """Running the notebook in examples/ leaves its report page there: git ignores it, so it is
    never an untracked file or committed by mistake."""
    repo = NOTEBOOK.parents[1]
    if shutil.which("git") is None or not (repo / ".git").exists():
        pytest.skip("not a git checkout")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    written = re.findall(r"\.report\(\"([^\"]+)\"\)", "".join(c.source for c in nb.cells))
    assert written, "the notebook writes no report page any more: update this test"
    for name in written:
        path = NOTEBOOK.parent / name
        p = subprocess.run(["git", "check-ignore", "-q", str(path)], cwd=repo)
        assert p.returncode == 0, f"{path.relative_to(repo)} is not ignored by git"


# --- examples/own_robot.py: the robot side of the bridge protocol, for your own robot ------------

OWN_ROBOT = NOTEBOOK.parent / "own_robot.py"


def test_the_own_robot_example_serves_a_bridge_swap(ssp_path, tmp_path):
    """docs/hil.md's "connect your own robot" script, started as a user would, serves
    `swap --replace plant=fmus/BridgePlant.fmu` over 0.5 s: the run succeeds and every row
    arrives, with the robot's sensor values in them."""
    import socket

    from impedance_cosim.cli import main

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    token = tmp_path / "robot.token"
    robot = subprocess.Popen(
        [sys.executable, str(OWN_ROBOT), str(port), str(token)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        assert robot.stdout.readline().strip() == f"robot: listening on 127.0.0.1:{port}"
        out = tmp_path / "res"
        bridge = ssp_path.parent / "BridgePlant.fmu"
        argv = ["swap", "--ssp", str(ssp_path), "--replace", f"plant={bridge}", "--stop", "0.5",
                "--set", f"plant.robot_port={port}", "--set", f"plant.robot_token_file={token}",
                "--set", "plant.timeout_s=20", "--out", str(out), "--no-figures",
                "--no-progress"]  # fmt: skip
        assert main(argv) == 0
        assert robot.poll() is None  # still serving
    finally:
        robot.kill()
        robot.wait(timeout=30)
    with (out / "observer.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 201 and float(rows[-1]["time"]) == pytest.approx(0.5)
    assert float(rows[-1]["plant.robot_t"]) == pytest.approx(0.5)  # the robot's time
    assert all(float(r["plant.link_rtt"]) >= 0 for r in rows[1:])


def test_docs_hil_shows_the_own_robot_example_as_it_is():
    """docs/hil.md lists examples/own_robot.py verbatim (the listing is not run by
    test_markdown.py; this test and the one above check it)."""
    page = (NOTEBOOK.parents[1] / "docs" / "hil.md").read_text()
    assert f"```py\n{OWN_ROBOT.read_text()}```\n" in page
