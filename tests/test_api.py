"""The Python API (impedance_cosim.simulate / sweep / Result): the same numbers as the command
line, overrides, provenance, pandas optional, failed runs keep their rows, clear errors, and
Result.report: the CLI's self-contained report.html for a Result (checked as test_report checks
the CLI's page)."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import traceback
import zipfile

import numpy as np
import pytest
from fmpy.util import read_csv
from test_report import check_page

import impedance_cosim as ic
from impedance_cosim import api
from impedance_cosim.cli import main
from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.results.provenance import file_sha256
from impedance_cosim.cosim.results.result import Feed
from impedance_cosim.cosim.ssp.read import SspError
from impedance_cosim.util.interrupt import RunInterrupted


@pytest.fixture(scope="module")
def k80(ssp_path):
    """A short run with an override, through the API."""
    return ic.simulate(ssp=ssp_path, stop_time=0.5, overrides={"controller.K": 80})


def test_signals_are_the_cli_csv_numbers(ssp_path, tmp_path, k80):
    out = tmp_path / "cli"
    argv = ["run", "--ssp", str(ssp_path), "--stop", "0.5", "--set", "controller.K=80",
            "--out", str(out), "--no-figures", "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    cli = read_csv(out / "observer.csv")
    assert k80.ok and k80.error is None and k80.names == list(cli.dtype.names)
    assert len(k80.time) == len(cli) == 201
    for name in cli.dtype.names:  # the same doubles, not merely close ones
        assert np.array_equal(k80[name], cli[name]), name
        assert np.array_equal(k80.signals[name], cli[name]), name
    assert np.array_equal(k80.time, cli["time"])
    # to_csv writes the CLI's file byte for byte (so fmpy reads it the same way)
    assert k80.to_csv(tmp_path / "api.csv").read_bytes() == (out / "observer.csv").read_bytes()


def test_overrides_are_applied(ssp_path, k80):
    run = k80.provenance["runs"][0]
    assert run["overrides"] == {"controller.K": 80}
    assert [run["parameters"]["controller"][f"K{i}"] for i in (1, 2, 3)] == [80.0] * 3
    base = ic.simulate(ssp=ssp_path, stop_time=0.5)
    assert base.provenance["runs"][0]["parameters"]["controller"]["K1"] == 50.0
    assert np.abs(base["controller.qd_obs1"] - k80["controller.qd_obs1"]).max() > 1e-6


def test_provenance_has_the_call_and_checksums(ssp_path, k80):
    record = k80.provenance
    assert record["call"] == (
        f"simulate('observer', ssp={str(ssp_path)!r}, stop_time=0.5, "
        "overrides={'controller.K': 80})"
    )
    assert record["system"] == {"ssp": str(ssp_path), "sha256": file_sha256(ssp_path)}
    assert record["versions"]["fmpy"] and record["versions"]["impedance-cosim"]
    (run,) = record["runs"]
    assert run["status"] == "ok" and run["rows"] == 201 and run["stop_time"] == 0.5
    with zipfile.ZipFile(ssp_path) as z:
        for comp, fmu in run["fmus"].items():
            assert fmu["sha256"] == hashlib.sha256(z.read(fmu["file"])).hexdigest(), comp
    assert k80.units == run["units"] and k80.units["plant.x"] == "m"
    assert k80.units["controller.tau1"] == "N.m" and k80.units["time"] == "s"
    assert k80.summary == run["summary"] and k80.summary["duration_s"] == pytest.approx(0.5)
    assert "observer error" in str(k80)


def test_to_dataframe(k80):
    pd = pytest.importorskip("pandas")
    df = k80.to_dataframe()
    assert isinstance(df, pd.DataFrame) and list(df.columns) == k80.names
    assert np.array_equal(df["plant.x"].to_numpy(), k80["plant.x"])
    assert df.attrs["units"]["plant.contact_force"] == "N"


def test_to_dataframe_without_pandas(k80, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)  # `import pandas` raises ImportError
    with pytest.raises(ImportError, match="pip install pandas"):
        k80.to_dataframe()


@pytest.mark.slow
def test_a_failed_run_keeps_its_rows(ssp_path, capfd):
    r = ic.simulate(ssp=ssp_path, stop_time=0.5, overrides={"controller.G": 1e9})
    assert not r.ok and "plant" in r.error
    assert 1 < len(r.time) < 201 and np.all(np.isfinite(r.data))
    assert r.summary is None
    run = r.provenance["runs"][0]
    assert run["status"] == "failed" and run["rows"] == len(r.time) and run["error"] == r.error
    with pytest.raises(api.RunFailedError, match="rows kept"):
        r.check()
    assert "error: " not in capfd.readouterr().err  # the FMU's report is in r.error, once


def test_an_interrupted_run_raises_with_its_rows(ssp_path, monkeypatch):
    feed, sent = Feed.__call__, []

    def interrupt_after_a_block(self, data, rows, extra=None):  # one Ctrl-C during the run
        if rows > 1 and not sent:
            sent.append(rows)
            os.kill(os.getpid(), signal.SIGINT)
        return feed(self, data, rows, extra)

    monkeypatch.setattr(Feed, "__call__", interrupt_after_a_block)
    with pytest.raises(RunInterrupted, match="SIGINT") as excinfo:
        ic.simulate(ssp=ssp_path, stop_time=2.0)
    r = excinfo.value.result  # the block under way is finished, then the run stops
    assert isinstance(r, api.Result) and not r.ok and "interrupted by SIGINT" in r.error
    assert len(r.time) == sent[0] < 801 and np.all(np.isfinite(r.data))
    run = r.provenance["runs"][0]
    assert run["status"] == "interrupted" and run["rows"] == len(r.time)


def last_frame(excinfo) -> str:
    return traceback.extract_tb(excinfo.tb)[-1].filename


@pytest.mark.parametrize(
    "kwargs,error,message",
    [
        ({"scenario": "nope"}, MasterError, "no parameter set 'nope'"),
        ({"overrides": {"controller.nope": 1}}, MasterError, "unknown parameter controller.nope"),
        ({"overrides": {"controller.K": "soft"}}, MasterError, "controller.K1"),
        ({"stop_time": "5"}, ValueError, "stop_time must be a number"),
        ({"stop_time": -1.0}, ValueError, "stop_time must be a finite number > 0"),
        ({"step_size": 0.001, "stop_time": 0.0105}, MasterError, "not a whole number"),
        ({"stop_time": 1e-300}, ValueError, "1e-300 s is shorter than one 0.0025 s step"),
        ({"algorithm": "newton"}, MasterError, "algorithm must be one of"),
        ({"overrides": ["controller.K=80"]}, ValueError, "overrides must be a dict"),
        ({"fmu_files": {"robot": "x.fmu"}}, MasterError, "no component 'robot'"),
        ({"fmu_files": {"plant": 3}}, ValueError, "fmu_files: each value must be the path"),
    ],
)
def test_bad_input_is_one_clear_line(ssp_path, kwargs, error, message):
    kwargs = {"stop_time": 0.2, **kwargs}
    with pytest.raises(error, match=message) as excinfo:
        ic.simulate(ssp=ssp_path, **kwargs)
    assert "\n" not in str(excinfo.value)
    assert last_frame(excinfo).endswith("api.py")  # raised from the API, not from deep inside


def test_a_missing_archive(tmp_path):
    with pytest.raises(SspError, match="does not exist") as excinfo:
        ic.simulate(ssp=tmp_path / "none.ssp")
    assert last_frame(excinfo).endswith("api.py")


def test_another_fmu_in_place_of_a_component(ssp_path, native_dir, k80):
    plant = native_dir / "PumaPlant.fmu"
    r = ic.simulate(ssp=ssp_path, stop_time=0.5, overrides={"controller.K": 80},
                    fmu_files={"plant": plant})  # fmt: skip
    assert r.ok and r.names == k80.names
    fmu = r.provenance["runs"][0]["fmus"]["plant"]
    assert fmu == {**fmu, "file": str(plant), "in_system_archive": False}
    assert fmu["sha256"] == file_sha256(plant)
    assert "fmu_files={'plant': " in r.provenance["call"]


@pytest.mark.slow
def test_figure_1_is_a_figure(k80, tmp_path):
    fig = k80.figure_1(tmp_path / "fig1.png")
    assert len(fig.axes) == 4 and fig.axes[3].get_ylabel() == "force [N]"
    assert (tmp_path / "fig1.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_sweep_runs_each_value(ssp_path, monkeypatch):
    results = ic.sweep("controller.G1", [500, 2000], ssp=ssp_path, stop_time=0.5)
    assert [r.provenance["runs"][0]["parameters"]["controller"]["G1"] for r in results] == [
        500.0,
        2000.0,
    ]
    assert results[1].provenance["call"] == (
        f"simulate('observer', ssp={str(ssp_path)!r}, stop_time=0.5, "
        "overrides={'controller.G1': 2000})"
    )
    assert all(r.ok for r in results)
    assert not np.array_equal(results[0]["controller.tau1"], results[1]["controller.tau1"])
    ran = []
    monkeypatch.setattr(Master, "run", lambda self, **kw: ran.append(self))
    with pytest.raises(MasterError, match="controller.G1"):  # every value checked first
        ic.sweep("controller.G1", [500, "stiff"], ssp=ssp_path, stop_time=0.5)
    assert ran == []
    with pytest.raises(ValueError, match="values is empty"):
        ic.sweep("controller.G1", [], ssp=ssp_path)
    with pytest.raises(ValueError, match="overrides sets controller.G1, the swept parameter"):
        ic.sweep("controller.G1", [500], ssp=ssp_path, overrides={"controller.G1": 800})


def test_import_stays_light_and_the_api_is_lazy():
    code = (
        "import sys, impedance_cosim as ic\n"
        "print(sorted(m for m in ('numpy', 'fmpy', 'matplotlib') if m in sys.modules))\n"
        "from impedance_cosim.api import simulate\n"
        "print(ic.simulate is simulate, 'simulate' in dir(ic))\n"
        "try:\n"
        "    ic.nope\n"
        "except AttributeError as exc:\n"
        "    print(exc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == [
        "[]",
        "True True",
        "module 'impedance_cosim' has no attribute 'nope'",
    ]


@pytest.fixture(scope="module")
def contact(ssp_path):
    """The paper scenario into its first contact (4.5 s: the impact; the force not yet settled)."""
    return ic.simulate(ssp=ssp_path, stop_time=4.5)


@pytest.mark.slow
def test_report_is_the_cli_page_for_a_result(contact, ssp_path, tmp_path):
    assert contact.ok
    path = contact.report(tmp_path / "contact.html")
    assert path == tmp_path / "contact.html"
    page = check_page(path)  # HTML5 without a parse error, nothing referenced outside the page
    text = " ".join(page.text)
    assert "impedance_cosim.simulate: observer ok" in text
    assert "The run reached its stop time (1801 rows)." in text
    # Figs. 1-3 inline, each a PNG data: URI that decodes at the size the page declares
    images = page.images()
    assert len(images) == 3 and len(set(images)) == 3
    for caption in ("Fig. 1: position", "Fig. 2: the velocity observer", "Fig. 3: velocity"):
        assert caption in text
    # the summary against the paper, with this Result's numbers
    summary = contact.summary
    assert page.row("contact force")[1] == "19.6 N (10^4 N/m x 0.00196 m)"
    assert "settled_force_N" not in summary
    assert page.row("contact force")[3] == "not settled (contact 3.85-4.50 s)"
    assert f"peak {summary['impact_peak_N']:.1f} N" in page.row("impact")[3]
    assert page.row("gains")[3].endswith("(as in the paper)")
    # every value of the summary, to the last digit
    values = {k: page.row(k)[1] for k in summary}
    assert {k: json.loads(v) for k, v in values.items()} == json.loads(json.dumps(summary))
    # provenance: the call, the archive's and each FMU's sha256, the versions
    assert page.row("call")[1] == f"simulate('observer', ssp={str(ssp_path)!r}, stop_time=4.5)"
    assert page.row("system archive sha256")[1] == file_sha256(ssp_path)
    for fmu in contact.provenance["runs"][0]["fmus"].values():
        assert fmu["sha256"] in text
    assert page.row("fmpy")[1] == contact.provenance["versions"]["fmpy"]
    runs = next(t for t in page.tables if t[0][0] == "run")
    assert [r[:4] for r in runs[1:]] == [["observer", "ok", "", "1801"]]
    # the units, as in the Result
    for name in ("plant.contact_force", "controller.tau1", "plant.x"):
        assert page.row(name) == [name, contact.units[name]]


@pytest.mark.slow
def test_report_of_a_failed_result_says_so(ssp_path, tmp_path):
    r = ic.simulate(ssp=ssp_path, stop_time=0.5, overrides={"controller.G": 1e9})
    page = check_page(r.report(tmp_path / "failed.html"))
    text = " ".join(page.text)
    assert "impedance_cosim.simulate: observer FAILED" in text
    assert f"This run FAILED: observer: failed: {r.error}" in text
    assert f"The Result keeps its {len(r.time)} rows." in text
    assert page.images() == [] and "No figures: the run did not finish." in text
    assert page.row("gains")[3].startswith("K = 50; G = 1e+09") and "NOT the paper" in text


@pytest.mark.slow
def test_report_that_cannot_be_written_is_one_line(contact, tmp_path):
    for path in (tmp_path / "no" / "such" / "folder" / "r.html", tmp_path):
        with pytest.raises(OSError, match="could not write") as excinfo:
            contact.report(path)
        assert str(path) in str(excinfo.value) and "\n" not in str(excinfo.value)
        assert last_frame(excinfo).endswith("api.py")
    assert list(tmp_path.iterdir()) == []  # no page, no temporary file left behind
    with pytest.raises(ValueError, match="path must be the file to write"):
        contact.report(None)


def test_report_of_a_result_without_a_summary(ssp_path, tmp_path, monkeypatch):
    """A run that finished but has no summary (e.g. another FMU without one of its signals)."""

    def no_signal(_run):
        raise KeyError("plant.contact_force")

    monkeypatch.setattr(api.analysis, "summary", no_signal)
    r = ic.simulate(ssp=ssp_path, stop_time=0.2)
    assert r.ok and r.summary is None
    page = check_page(r.report(tmp_path / "r.html"))
    text = " ".join(page.text)
    assert "impedance_cosim.simulate: observer ok" in text
    assert "No summary: 'plant.contact_force'." in text
    assert page.images() == [] and "No figures: the run has no summary." in text
    assert page.row("contact force")[3] == "not in this run"
