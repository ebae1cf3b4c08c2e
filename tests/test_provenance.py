"""Provenance (issue 14): every results folder carries run.json saying how its results were made:
the command, the system archive and FMU files with their sha256, scenario, overrides and the
parameter values in effect, algorithm, step, stop, versions, times, and the units of the CSV's
columns (the CSV header stays fmpy's)."""

from __future__ import annotations

import hashlib
import json
import zipfile

import numpy as np
from fmpy.util import read_csv

from impedance_cosim.cli import main
from impedance_cosim.cosim.results.provenance import file_sha256


def test_run_json_records_how_the_result_was_made(ssp_path, tmp_path):
    out = tmp_path / "res"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.2", "--set", "controller.K=80",
            "--algorithm", "jacobi", "--out", str(out), "--no-figures",
            "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    record = json.loads((out / "run.json").read_text())
    assert record["command"][1:] == argv
    assert record["system"] == {"ssp": str(ssp_path), "sha256": file_sha256(ssp_path)}
    assert record["versions"]["fmpy"] and record["versions"]["impedance-cosim"]
    assert record["wall_time_s"] > 0 and record["started"].endswith("+00:00")
    (run,) = record["runs"]
    assert run["scenario"] == "observer" and run["status"] == "ok" and run["error"] is None
    assert run["algorithm"] == "jacobi" and run["step_size"] == 1 / 400 and run["stop_time"] == 0.2
    assert run["overrides"] == {"controller.K": "80"}
    assert [run["parameters"]["controller"][f"K{i}"] for i in (1, 2, 3)] == [80.0] * 3
    with zipfile.ZipFile(ssp_path) as z:  # the FMUs the run used: the archive's own members
        for comp, fmu in run["fmus"].items():
            assert fmu["in_system_archive"] is True
            assert fmu["sha256"] == hashlib.sha256(z.read(fmu["file"])).hexdigest(), comp
    rows = read_csv(out / run["csv"])  # fmpy still reads the CSV: plain names in the header
    assert run["rows"] == len(rows) == 81
    assert set(run["units"]) <= {"time", *rows.dtype.names}
    assert run["units"]["time"] == "s" and run["units"]["plant.x"] == "m"
    assert run["units"]["controller.tau1"] == "N.m"
    assert run["summary"] and run["real_time_factor"] > 0


def test_a_failed_run_keeps_its_record(ssp_path, tmp_path):
    out = tmp_path / "bad"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.2", "--set", "plant.x0=5.0",
            "--out", str(out), "--no-figures", "--no-progress"]  # fmt: skip
    assert main(argv) == 1
    (run,) = json.loads((out / "run.json.partial").read_text())["runs"]
    assert run["status"] == "failed" and "unreachable" in run["error"]
    assert run["overrides"] == {"plant.x0": "5.0"}


def test_sha256_of_a_file(tmp_path):
    f = tmp_path / "x.bin"
    f.write_bytes(np.arange(300_000, dtype=np.uint8).tobytes())  # more than one read block
    assert file_sha256(f) == hashlib.sha256(f.read_bytes()).hexdigest()


def test_a_record_that_cannot_be_written_is_one_warning(ssp_path, tmp_path, capsys):
    """run.json cannot be written (a folder is in its place): one warning line; the run's
    results and its exit status stand."""
    out = tmp_path / "res"
    (out / "run.json").mkdir(parents=True)
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.2", "--out", str(out), "--no-figures",
            "--no-progress", "--no-report"]  # fmt: skip
    assert main(argv) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "warning:" in err[0] and "run.json not written" in err[0], err
    assert len(read_csv(out / "observer.csv")) == 81
