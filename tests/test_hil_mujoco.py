"""The robot process on MuJoCo (`impedance-cosim robot --plant mujoco`): lock-step through the
bridge equals the run with MujocoPlant.fmu swapped in, bit for bit; `swap --robot-plant mujoco`
is one command; real time runs on the robot's clock. Every robot process is killed at the end of
its test (by its PID); nothing depends on timing beyond generous hang guards."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from bridge_model import protocol
from impedance_cosim.apps.robot_plant import plant_class
from impedance_cosim.cli import main
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results import result as results
from impedance_cosim.cosim.ssp.read import read_ssp

TOKEN = protocol.new_token()
PATIENT = {"plant.timeout_s": 20.0, "plant.init_timeout_s": 60.0}  # a slow machine is no failure


@pytest.fixture(scope="module")
def system(ssp_path):
    return read_ssp(ssp_path)


@pytest.fixture
def robot(robot):
    """start(extra args, realtime=False) -> port of a robot on MuJoCo (conftest's robot)."""

    def start(*extra: str, realtime: bool = False) -> int:
        return robot("--plant", "mujoco", *extra, realtime=realtime, timeout=60.0)

    return start


def bridged(system, fmu_dir, port, stop, **kw):
    overrides = {"plant.robot_port": port, "plant.robot_token": TOKEN, **PATIENT}
    fmu = {"plant": fmu_dir / "BridgePlant.fmu"}
    return Master(
        system, RunOptions(stop_time=stop, fmu_files=fmu, overrides=overrides, **kw)
    ).run()


@pytest.mark.slow
def test_lockstep_bridge_equals_the_mujoco_fmu(system, fmu_dir, robot):
    """Through the first impact (4.5 s): every column of the bridged run equals the run with
    MujocoPlant.fmu in process, bit for bit (the same model, MJCF and calls)."""
    ref = Master(
        system, RunOptions(stop_time=4.5, fmu_files={"plant": fmu_dir / "MujocoPlant.fmu"})
    ).run()
    got = bridged(system, fmu_dir, robot(), 4.5)
    assert ref.ok and got.ok, (ref.error, got.error)
    assert ref["plant.contact_force"].max() > 50.0  # the impact is in it
    for name in ref.names:
        assert np.array_equal(got[name], ref[name]), name
    ours = Master(system, RunOptions(stop_time=4.5)).run()  # and it is MuJoCo's, not our plant
    assert not np.array_equal(got["plant.contact_force"], ours["plant.contact_force"])


@pytest.mark.slow
def test_swap_to_the_mujoco_robot_is_one_command(ssp_path, fmu_dir, tmp_path):
    out = tmp_path / "bridge"
    args = ["--ssp", str(ssp_path), "--stop", "1", "--no-figures", "--no-report", "--no-progress"]
    assert main(["swap", *args, "--replace", f"plant={fmu_dir}/MujocoPlant.fmu", "--out",
                 str(tmp_path / "fmu")]) == 0  # fmt: skip
    cmd = ["swap", *args, "--replace", f"plant={fmu_dir}/BridgePlant.fmu", "--robot", "lockstep",
           "--robot-plant", "mujoco", "--out", str(out), "--set", "plant.timeout_s=20"]  # fmt: skip
    assert main(cmd) == 0
    ref = results.read_csv(tmp_path / "fmu" / "observer.csv")
    got = results.read_csv(out / "observer.csv")
    for name in ref:
        assert np.array_equal(got[name], ref[name]), name


def test_bridge_against_a_realtime_mujoco_robot(system, fmu_dir, robot):
    """Real time: the robot integrates MuJoCo on its own clock in ticks (5 ms here, so a loaded
    machine keeps up) with the torque held, and answers with its latest outputs. Timing-free
    checks only: the run completes, the robot's time never goes back and is always a whole
    number of its ticks (lock-step answers would be at the master's 2.5 ms grid)."""
    result = bridged(system, fmu_dir, robot("--tick", "0.005", realtime=True), 0.25)
    assert result.ok, result.error
    robot_t = result["plant.robot_t"]
    assert np.all(np.diff(robot_t) >= 0)
    ticks = robot_t / 0.005
    assert np.abs(ticks - np.round(ticks)).max() < 1e-6  # lock-step: every 2.5 ms, half ticks


def test_plant_choices_are_checked(monkeypatch):
    """An unknown plant and a missing mujoco are one line each (ValueError: exit 2)."""
    with pytest.raises(ValueError, match="--plant must be one of ours, mujoco"):
        plant_class("drake")
    monkeypatch.setitem(sys.modules, "mujoco", None)
    with pytest.raises(ValueError, match="--plant mujoco needs the Python package mujoco"):
        plant_class("mujoco")


def test_robot_refuses_an_override_mujoco_has_not(capsys):
    """`--set plant.rtol=...` is PumaPlant's integrator: the MuJoCo robot has no such parameter;
    its own timestep it takes."""
    argv = ["robot", "--plant", "mujoco", "--port", "0", "--duration", "0.01"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(protocol.TOKEN_ENV, TOKEN)
        assert main([*argv, "--set", "plant.rtol=1e-6"]) == 2
        assert "the robot has no parameter 'plant.rtol'" in capsys.readouterr().err
        assert main([*argv, "--set", "plant.timestep=1e-4"]) == 0
