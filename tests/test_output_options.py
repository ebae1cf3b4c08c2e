"""`--output-interval` (every k-th row to the file, the summary from every step) and
`--result-format mat` (the Dymola/OpenModelica result file, read back with buildingspy: the
same float64 bits as the CSV)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from impedance_cosim.cli import main


def run(native_ssp, out, *extra: str) -> int:
    return main(["run", "--ssp", str(native_ssp), "--stop", "4.5", "--no-figures", "--no-report",
                 "--no-progress", "--out", str(out), *extra])  # fmt: skip


def csv_columns(path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text().splitlines()
    return lines[0].split(","), np.array([[float(v) for v in li.split(",")] for li in lines[1:]])


def test_output_interval_writes_every_kth_row_and_summarizes_every_step(native_ssp, tmp_path):
    assert run(native_ssp, tmp_path / "full") == 0
    assert run(native_ssp, tmp_path / "every4", "--output-interval", "0.01") == 0
    full = (tmp_path / "full" / "observer.csv").read_text().splitlines()
    every4 = (tmp_path / "every4" / "observer.csv").read_text().splitlines()
    assert every4 == [full[0], *full[1::4]] and len(every4) == 1 + 451
    # the impact peak needs every step: the summaries are the same
    summary = [json.loads((tmp_path / d / "observer_summary.json").read_text())
               for d in ("full", "every4")]  # fmt: skip
    assert summary[0] == summary[1] and summary[0]["impact_peak_N"] > 40
    entry = json.loads((tmp_path / "every4" / "run.json").read_text())["runs"][0]
    assert entry["results"] == {"file": "observer.csv", "format": "csv", "rows": 451,
                                "output_interval_s": 0.01}  # fmt: skip
    assert entry["rows"] == 1801  # the run's own rows


@pytest.mark.parametrize("interval", ["0.003", "0.001"])
def test_an_interval_not_a_multiple_of_the_step_is_bad_input(native_ssp, tmp_path, capsys,
                                                             interval: str) -> None:  # fmt: skip
    assert run(native_ssp, tmp_path / "out", "--output-interval", interval) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"impedance-cosim run: error: --output-interval {interval} s is not a multiple"
                   " of the step 0.0025 s (e.g. 0.0025, 0.005, 0.01)"]  # fmt: skip
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("interval", ["0.4", "5", "1"])
def test_an_interval_that_does_not_divide_the_run_is_bad_input(native_ssp, tmp_path, capsys,
                                                               interval) -> None:  # fmt: skip
    """The row at the stop time would be lost (4.5 s every 0.4 s ends at 4.4 s): refused."""
    assert run(native_ssp, tmp_path / "out", "--output-interval", interval) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"impedance-cosim run: error: --output-interval {interval} s does not divide"
                   " the run length 4.5 s (--stop): the row at the stop time would be"
                   " lost"]  # fmt: skip
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "extra,message",
    [
        (
            ["--stop", "1", "--output-interval", "0.3"],
            "--output-interval 0.3 s does not divide the run length 1 s (--stop)",
        ),
        (["--stop", "1e-300"], "the run length 1e-300 s is shorter than one 0.0025 s step"),
    ],
)
def test_swap_shares_the_time_checks(native_ssp, native_dir, tmp_path, capsys, extra, message):
    assert main(["swap", "--ssp", str(native_ssp), "--replace",
                 f"controller={native_dir / 'ImpedanceController.fmu'}", "--no-progress",
                 "--out", str(tmp_path / "out"), *extra]) == 2  # fmt: skip
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("impedance-cosim swap: error: ") and message in line, line
    assert not (tmp_path / "out").exists()


def test_an_interrupt_while_the_mat_file_is_written_keeps_the_rows(
    native_ssp, tmp_path, capsys, monkeypatch
) -> None:
    """Ctrl-C as the finished run's .mat is written (the writer raises KeyboardInterrupt): the
    rows go to observer.mat.partial, the line says so, run.json.partial records the run, and
    the earlier run's files are left as they were (on main: nothing kept, "runs": [])."""
    import scipy.io
    from scipy.io import loadmat

    out = tmp_path / "out"
    assert run(native_ssp, out, "--result-format", "mat") == 0
    before = (out / "observer.mat").read_bytes()
    real, calls = scipy.io.savemat, []

    def interrupted_once(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(path, *args, **kwargs)

    monkeypatch.setattr(scipy.io, "savemat", interrupted_once)
    capsys.readouterr()
    assert run(native_ssp, out, "--result-format", "mat") == 130
    partial = out / "observer.mat.partial"
    (line,) = capsys.readouterr().err.strip().splitlines()  # nothing of the earlier run removed
    mat = out / "observer.mat"
    assert line == (f"impedance-cosim run: interrupted (SIGINT) while writing {mat}; the 1801"
                    f" rows (to t=4.5 s) are in {partial}")  # fmt: skip
    assert (out / "observer.mat").read_bytes() == before
    assert (out / "observer_summary.json").is_file()  # the earlier run's, kept
    assert loadmat(partial)["data_2"].shape[1] == 1801
    entry = json.loads((out / "run.json.partial").read_text())["runs"][0]
    assert (
        entry["status"] == "interrupted"
        and entry["rows"] == 1801
        and str(partial) in entry["error"]
    )


def test_an_interrupt_as_the_csv_is_renamed_into_place_keeps_run_json(
    native_ssp, tmp_path, capsys, monkeypatch
):
    """Ctrl-C right after the finished run's CSV is renamed into place: the CSV is whole and
    run.json records the run (on main it said "runs": [])."""
    from impedance_cosim.util import atomic

    real = atomic.replace

    def then_interrupted(tmp, target):
        real(tmp, target)
        if str(target).endswith("observer.csv"):
            raise KeyboardInterrupt

    monkeypatch.setattr(atomic, "replace", then_interrupted)
    out = tmp_path / "out"
    assert run(native_ssp, out) == 130
    (line,) = capsys.readouterr().err.strip().splitlines()
    kept = out / "observer.csv.partial"  # the command did not complete
    assert line == f"impedance-cosim run: interrupted (SIGINT); 1801 rows kept in {kept}"
    assert len((out / "observer.csv.partial").read_text().splitlines()) == 1 + 1801
    entry = json.loads((out / "run.json.partial").read_text())["runs"][0]
    assert entry["status"] == "interrupted" and entry["rows"] == 1801


@pytest.mark.parametrize("interval", [[], ["--output-interval", "0.005"]])
def test_mat_results_read_back_with_buildingspy_bit_for_bit(native_ssp, tmp_path, interval):
    from buildingspy.io.outputfile import Reader

    assert run(native_ssp, tmp_path / "csv", *interval) == 0
    assert run(native_ssp, tmp_path / "mat", "--result-format", "mat", *interval) == 0
    names, data = csv_columns(tmp_path / "csv" / "observer.csv")
    mat = Reader(str(tmp_path / "mat" / "observer.mat"), "dymola")
    assert set(names[1:]) <= set(mat.varNames())
    for k, name in enumerate(names[1:], start=1):
        time, values = mat.values(name)
        assert time.tobytes() == data[:, 0].tobytes(), name
        assert values.tobytes() == data[:, k].tobytes(), name
    entry = json.loads((tmp_path / "mat" / "run.json").read_text())["runs"][0]
    parameter = next(iter(entry["parameters"]["controller"].items()))
    assert mat.max(f"controller.{parameter[0]}") == pytest.approx(float(parameter[1]))
    assert entry["results"]["file"] == "observer.mat" and "csv" not in entry
    assert not (tmp_path / "mat" / "observer.csv").exists()


def test_mat_descriptions_carry_the_units(native_ssp, tmp_path):
    import scipy.io

    assert run(native_ssp, tmp_path, "--result-format", "mat", "--stop", "0.1") == 0
    mat = scipy.io.loadmat(tmp_path / "observer.mat", chars_as_strings=False)
    assert ["".join(r).rstrip() for r in mat["Aclass"]] == ["Atrajectory", "1.1", "", "binTrans"]
    names = ["".join(c).rstrip() for c in zip(*mat["name"], strict=True)]
    texts = dict(zip(names, ["".join(c).rstrip() for c in zip(*mat["description"], strict=True)],
                     strict=True))  # fmt: skip
    assert texts["time"] == "Time [s]" and texts["plant.contact_force"].endswith("[N]")
