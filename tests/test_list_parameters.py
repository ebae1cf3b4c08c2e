"""`run --list-parameters` lists every name `--set` accepts, with the scenario's values: each
listed name is accepted by the master with its listed value, and every FMU parameter is listed."""

from __future__ import annotations

import subprocess
import sys

import pytest

from impedance_cosim.apps.parameters import parameter_lines
from impedance_cosim.cosim.fmus.files import model_description
from impedance_cosim.cosim.master.master import Master, MasterError
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp


@pytest.fixture(scope="module")
def system(ssp_path):
    s = read_ssp(ssp_path)
    yield s
    s.close()


def _rows(lines: list[str]) -> dict[str, list[str]]:
    return {line.split()[0]: line.split() for line in lines[1:]}


def test_every_parameter_is_listed_with_the_scenarios_value(system):
    rows = _rows(parameter_lines(system, "difference"))
    for comp in system.components:
        for v in model_description(comp.fmu).modelVariables:
            if v.causality == "parameter":
                assert f"{comp.name}.{v.name}" in rows, v.name
    assert rows["controller.velocity_source"][3:5] == ["2", "(scenario)"]
    assert rows["controller.K"][1:4] == ["shorthand", "sets", "K1,"]


def test_every_listed_name_is_accepted_by_set_with_its_value(system):
    rows = _rows(parameter_lines(system, "observer"))
    for name, cells in rows.items():
        if cells[1] == "shorthand":
            member = cells[3].rstrip(",")
            value = rows[f"{name.split('.')[0]}.{member}"][3]
        else:
            value = cells[3]
        Master(
            system, RunOptions(parameter_set="observer", overrides={name: value}, stop_time=0.0025)
        )


def test_an_unknown_scenario_is_refused(system):
    with pytest.raises(MasterError, match="no parameter set 'nosuch'"):
        parameter_lines(system, "nosuch")


def test_the_cli_lists_and_runs_nothing(ssp_path, tmp_path):
    out = tmp_path / "never"
    done = subprocess.run(
        [sys.executable, "-m", "impedance_cosim", "run", "--ssp", str(ssp_path),
         "--list-parameters", "--out", str(out)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "controller.G1" in done.stdout and "plant.wall_k" in done.stdout
    assert not out.exists()
