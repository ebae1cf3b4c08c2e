"""The command line: run a scenario end to end, and one-line errors for bad input."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from fmpy.util import read_csv

from impedance_cosim.cli import main


@pytest.mark.slow
def test_run_writes_results_summary_and_figures(ssp_path, tmp_path, capsys):
    out = tmp_path / "res"
    code = main(["run", "--ssp", str(ssp_path), "--stop", "4.5", "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "impact peak force" in text and "settled contact force" in text
    result = read_csv(out / "observer.csv")  # fmpy's reader: fmpy's plotting works on it
    assert len(result) == 1801 and result["time"][-1] == 4.5
    assert result["plant.contact_force"].max() > 40.0
    for name in ("fig1_position_force", "fig2_observer", "fig3_velocity_tracking",
                 "fig4_observer_vs_difference"):  # fmt: skip
        assert (out / f"{name}.png").stat().st_size > 10_000
    assert (out / "difference.csv").is_file() and (out / "observer_summary.json").is_file()


def test_options_reach_the_master(ssp_path, tmp_path):
    out = tmp_path / "res"
    args = ["run", "--ssp", str(ssp_path), "--stop", "0.5", "--step", "0.00125", "--out", str(out)]
    assert main([*args, "--algorithm", "jacobi", "--scenario", "measured", "--no-figures",
                 "--set", "controller.K=80"]) == 0  # fmt: skip
    result = read_csv(out / "measured.csv")
    assert len(result) == 401 and np.array_equal(result["time"], np.arange(401) * 0.00125)


@pytest.mark.slow
def test_diverging_run_keeps_partial_results(ssp_path, tmp_path, capsys):
    out = tmp_path / "res"
    args = ["run", "--ssp", str(ssp_path), "--stop", "5", "--out", str(out), "--set"]
    assert main([*args, "controller.G=1e9", "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "error:" in err
    rows = read_csv(out / "observer.csv.partial")  # the run failed: not under the result's name
    assert (
        2 < len(rows) < 2001 and f"{len(rows)} rows kept in {out / 'observer.csv.partial'}" in err
    )


@pytest.mark.parametrize(
    "args,message",
    [
        (["--set", "controller.Kx=3"], "unknown parameter controller.Kx"),
        (["--set", "controller.Gx=3"], "did you mean controller.G3, controller.G2, controller.G1?"),
        (["--set", "controller.K1"], "--set expects component.variable=value"),
        (["--scenario", "fast"], "no parameter set 'fast'"),
        (["--step", "-1"], "argument --step: must be a finite number > 0"),
    ],
)
def test_bad_options_give_one_line_errors(ssp_path, tmp_path, capsys, args, message):
    try:
        assert main(["run", "--ssp", str(ssp_path), "--out", str(tmp_path), *args]) == 2
    except SystemExit as exc:  # argparse's own checks
        assert exc.code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_malformed_ssd_gives_a_one_line_error(ssp_path, tmp_path, capsys):
    bad = tmp_path / "bad.ssp"
    with zipfile.ZipFile(ssp_path) as zin, zipfile.ZipFile(bad, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            if name == "SystemStructure.ssd":
                data = data.replace(b"<ssd:Elements>", b"<ssd:Elementz>", 1)
            zout.writestr(name, data)
    assert main(["run", "--ssp", str(bad), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "malformed SSD" in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_a_command_fails_when_any_of_its_runs_fails(ssp_path, tmp_path, capsys, monkeypatch):
    """`run` with figures also runs the other scenario of Fig. 4: its failure fails the command."""
    from impedance_cosim.cosim.master.master import Master

    original = Master.run

    def run(self, *args, **kwargs):
        result = original(self, *args, **kwargs)
        if self.parameter_set == "difference":
            result.error = "made to fail by the test"
        return result

    monkeypatch.setattr(Master, "run", run)
    out = tmp_path / "res"
    assert main(["run", "--ssp", str(ssp_path), "--stop", "0.5", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "difference: made to fail by the test" in err[0]
    assert (out / "observer.csv.partial").is_file() and (out / "difference.csv.partial").is_file()
    assert not (out / "observer.csv").exists()  # only a command that completes writes those


def test_results_csv_appears_only_when_closed(tmp_path):
    """The CSV is written under a temporary name and renamed into place when the stream closes
    (also on an exception), so the target name never holds a partial file."""
    from impedance_cosim.cosim.results.result import CsvStream

    path = tmp_path / "r.csv"
    with pytest.raises(RuntimeError), CsvStream(path) as stream:
        stream.write(["time", "x"], np.zeros((0, 2)))
        stream.write(["time", "x"], np.array([[0.0, 0.1], [0.5, 1 / 3]]))
        assert not path.exists() and len(list(tmp_path.glob(".r.csv.*.tmp"))) == 1
        raise RuntimeError("stop")
    assert path.read_text() == f"time,x\n0.0,0.1\n0.5,{1 / 3!r}\n"
    assert list(tmp_path.iterdir()) == [path]


@pytest.mark.parametrize("module", ["impedance_cosim", "impedance_cosim.cli"])
def test_python_dash_m_reports_errors_of_other_modules_in_one_line(module, tmp_path):
    """`python -m` runs the same main: a CliError raised in hil.py is a user error (exit 2), not an
    'internal error' (it was another class when cli.py ran as __main__)."""
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", module, "swap", "--replace", "bogus", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert lines == ["impedance-cosim swap: error: --replace expects component=path/to/file.fmu"
                     " (got 'bogus')"]  # fmt: skip


def test_version(capsys):
    """--version prints the package version and exits 0."""
    import impedance_cosim

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"impedance-cosim {impedance_cosim.__version__}"


def test_ctrl_c_while_starting_is_one_line(monkeypatch, capsys):
    """A Ctrl-C before a command has taken over its signals (the commands' modules loading,
    the arguments being read) is one line and exit status 130, not a traceback."""
    from impedance_cosim import cli
    from impedance_cosim.apps import options

    def interrupted_import(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(options, "add_run_options", interrupted_import)  # inside main()
    monkeypatch.setattr("sys.argv", ["impedance-cosim", "run"])
    with pytest.raises(SystemExit) as stop:
        cli.entry()
    assert stop.value.code == 130
    err = capsys.readouterr().err
    assert err == "impedance-cosim: interrupted (SIGINT) while starting\n"


def test_the_command_line_module_loads_no_command():
    """impedance_cosim.cli imports the commands (numpy, fmpy, dask) only inside main(), so
    entry() is in place before the slow imports start."""
    import subprocess
    import sys

    code = "import sys, impedance_cosim.cli; print(sorted({'numpy', 'fmpy'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("signum", [2, 15])
def test_an_error_raised_while_an_interrupt_unwinds_reports_the_interrupt(signum, capsys):
    """A signal that lands while subprocess starts a compiler can surface as the OSError of its
    clean-up (EBADF: a pipe closed twice), with the interrupt as its context: the command reports
    the interrupt (128 + signal), as for any other interruption, not an error (exit 1)."""
    import argparse
    import errno

    from impedance_cosim.cli import _dispatch

    def build(args):
        try:
            exc = KeyboardInterrupt()
            exc.signum = signum
            raise exc
        except KeyboardInterrupt:
            raise OSError(errno.EBADF, "Bad file descriptor") from None

    args = argparse.Namespace(command="build", func=build)
    assert _dispatch(args) == 128 + signum
    err = capsys.readouterr().err
    assert "interrupted" in err and "Bad file descriptor" not in err, err
