"""HIL-style runs: the swap check and command, the bridge plant against the robot process
(lock-step equals the in-process plant; every failure stops the run cleanly, bounded in time),
the real-time master. Every robot process is killed at the end of its test."""

from __future__ import annotations

import re
import shutil
import socket
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import run_bridge_in_child

from bridge_model import protocol
from impedance_cosim.apps.hil import replacement_problems
from impedance_cosim.apps.robot import Fault
from impedance_cosim.cli import main
from impedance_cosim.cosim.master import realtime
from impedance_cosim.cosim.master.master import RT_COLUMNS, Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results import result as results
from impedance_cosim.cosim.ssp.read import read_ssp

TOKEN = protocol.new_token()
KEY = protocol.token_key(TOKEN)


@pytest.fixture(scope="module")
def system(ssp_path):
    return read_ssp(ssp_path)


@pytest.fixture(scope="module")
def bridge(fmu_dir) -> Path:
    return fmu_dir / "BridgePlant.fmu"


# A run that is not about timeouts must not fail because the machine is slow.
PATIENT = {"plant.timeout_s": 20.0, "plant.init_timeout_s": 60.0}


def bridged(system, bridge, port, stop, **kw):
    overrides = {"plant.robot_port": port, "plant.robot_token": TOKEN, **PATIENT,
                 **kw.pop("overrides", {})}  # fmt: skip
    master = Master(
        system, RunOptions(stop_time=stop, fmu_files={"plant": bridge}, overrides=overrides, **kw)
    )
    return master.run()


# --- the bridge's interface and protocol ---------------------------------------------------------


def test_bridge_has_the_plants_interface(fmu_dir):
    """The built bridge FMU declares PumaPlant's variables first, with the same value references,
    causality, units and start values (plus its own link parameters and outputs)."""
    from fmpy import read_model_description

    def table(path):
        md = read_model_description(str(path))
        return [(v.name, v.valueReference, v.causality, v.type, v.unit, v.start)
                for v in md.modelVariables]  # fmt: skip

    plant, bridge = table(fmu_dir / "PumaPlant.fmu"), table(fmu_dir / "BridgePlant.fmu")
    assert bridge[: len(plant)] == plant
    assert {"robot_port", "timeout_s", "link_rtt"} <= {v[0] for v in bridge[len(plant) :]}


def test_protocol_round_trip_and_rejections():
    data = protocol.pack(KEY, protocol.STEP, 7, 2**63 + 5, 0.25, 0.0025, (1.0, -2.5, 3e-300),
                         echo_ns=5)  # fmt: skip
    assert len(data) == protocol.HEADER.size + 3 * 8 + protocol.MAC_SIZE
    msg = protocol.Message(data, KEY)
    assert (msg.kind, msg.seq, msg.session, msg.t, msg.h, msg.values, msg.echo_ns) == (
        protocol.STEP, 7, 2**63 + 5, 0.25, 0.0025, (1.0, -2.5, 3e-300), 5,
    )  # fmt: skip
    error = protocol.pack(KEY, protocol.ERROR, 3, 1, 0, 0, text="no plant", code=protocol.REFUSED)
    assert (protocol.Message(error, KEY).text, protocol.Message(error, KEY).code) == (
        "no plant", protocol.REFUSED,
    )  # fmt: skip
    other = protocol.token_key(protocol.new_token())

    def resign(body: bytes) -> bytes:  # a validly signed datagram with a doctored header
        return body + protocol._mac(KEY, body)

    body = data[: -protocol.MAC_SIZE]
    for bad, why in [
        (data[:40], "shorter than header and MAC"),
        (data + bytes(protocol.MAX_DATAGRAM), "longer than"),
        (data[:-1] + bytes([data[-1] ^ 1]), "MAC does not verify"),
        (data[:20] + bytes([data[20] ^ 1]) + data[21:], "MAC does not verify"),
        (protocol.pack(other, protocol.STEP, 7, 1, 0.25, 0.0025, (1.0,)), "MAC does not verify"),
        (resign(b"XXXX" + body[4:]), "bad magic"),
        (resign(body[:4] + (1).to_bytes(2, "little") + body[6:]), "protocol version 1"),
        (resign(body[:-8]), "with count 3"),
    ]:
        with pytest.raises(protocol.ProtocolError, match=why):
            protocol.Message(bad, KEY)


def test_token_files_must_be_private(tmp_path):
    key = protocol.write_token_file(tmp_path / "token")
    assert (tmp_path / "token").stat().st_mode & 0o777 == 0o600
    assert protocol.read_token_file(tmp_path / "token") == key and len(key) == 64
    with pytest.raises(ValueError, match="exists"):
        protocol.write_token_file(tmp_path / "token")  # never overwritten
    (tmp_path / "token").chmod(0o644)
    with pytest.raises(ValueError, match="mode 644 lets others read it"):
        protocol.read_token_file(tmp_path / "token")
    (tmp_path / "short").write_text("abc")
    (tmp_path / "short").chmod(0o600)
    with pytest.raises(ValueError, match="32-256 printable ASCII"):
        protocol.read_token_file(tmp_path / "short")
    with pytest.raises(ValueError, match="No such file"):
        protocol.read_token_file(tmp_path / "missing")


# --- swap ----------------------------------------------------------------------------------------


def doctored(fmu: Path, tmp_path: Path) -> Path:
    """A copy of the plant FMU with a connector renamed (q1), a unit changed (fx in N.m) and a
    parameter of the paper's set renamed (wall_k)."""
    out = tmp_path / "Doctored.fmu"
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(out, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            if name == "modelDescription.xml":
                xml = data.decode()
                xml = xml.replace('name="q1"', 'name="q1_enc"')
                xml = xml.replace('name="wall_k"', 'name="wall_stiffness"')
                xml = re.sub(r'(name="fx".*?<Real[^>]*unit=")N"', r'\1N.m"', xml, flags=re.S)
                data = xml.encode()
            zout.writestr(name, data)
    return out


def test_swap_check_lists_every_difference(system, fmu_dir, tmp_path):
    bad = doctored(fmu_dir / "PumaPlant.fmu", tmp_path)
    problems = replacement_problems(system, "plant", bad, "observer", {"plant.nope": "1"})
    text = "\n".join(problems)
    assert "plant.q1: no such variable in Doctored.fmu" in text
    assert "plant.fx: unit N.m in the FMU, N in the SSD" in text
    assert "plant.wall_k: no such variable in Doctored.fmu" in text  # a parameter connector
    assert "plant.nope (--set): no such parameter" in text
    assert len(problems) == 4
    assert replacement_problems(system, "plant", fmu_dir / "BridgePlant.fmu") == []
    wrong_causality = replacement_problems(system, "plant", fmu_dir / "ImpedanceController.fmu")
    assert "plant.tau1: causality output in the FMU, input in the SSD" in wrong_causality


def test_swap_refuses_a_mismatch_with_the_full_list(ssp_path, fmu_dir, tmp_path, capsys):
    bad = doctored(fmu_dir / "PumaPlant.fmu", tmp_path)
    code = main(["swap", "--ssp", str(ssp_path), "--replace", f"plant={bad}",
                 "--out", str(tmp_path / "res")])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert "does not fit the system (3)" in err
    for part in ("plant.q1: no such variable", "plant.fx: unit N.m", "plant.wall_k"):
        assert part in err
    assert not (tmp_path / "res" / "observer.csv").exists()  # refused before running


def test_swap_native_and_noisy_plants_give_the_run_format(ssp_path, native_dir, tmp_path):
    if shutil.which("gcc") is None:
        pytest.skip("no C compiler: no native plant")
    base = ["--ssp", str(ssp_path), "--stop", "1", "--no-figures"]
    assert main(["run", *base, "--out", str(tmp_path / "run")]) == 0
    native = ["swap", *base, "--replace", f"plant={native_dir / 'PumaPlant.fmu'}"]
    assert main([*native, "--out", str(tmp_path / "native")]) == 0
    ref = results.read_csv(tmp_path / "run" / "observer.csv")
    got = results.read_csv(tmp_path / "native" / "observer.csv")
    assert list(got) == list(ref)  # the same columns
    for name in ref:
        assert np.array_equal(got[name], ref[name]), name  # the native plant is bit-identical
    noisy = [*native, "--set", "plant.q_noise=1e-4", "--set", "plant.q_quant=1e-4"]
    assert main([*noisy, "--out", str(tmp_path / "noisy")]) == 0
    got = results.read_csv(tmp_path / "noisy" / "observer.csv")
    err = np.abs(got["plant.q1"] - got["plant.q1_true"])
    assert 1e-6 < err.max() < 1e-3
    assert (tmp_path / "noisy" / "observer_summary.json").is_file()


# --- the bridge against the robot process --------------------------------------------------------


@pytest.mark.slow
def test_lockstep_bridge_equals_the_in_process_plant(system, bridge, robot):
    ref = Master(system).run()
    got = bridged(system, bridge, robot(), 20.0)
    assert got.ok, got.error
    assert len(got.data) == len(ref.data) == 8001
    for name in ref.names:
        assert np.allclose(got[name], ref[name], rtol=0, atol=1e-9), name
        assert np.array_equal(got[name], ref[name]), name  # in fact bit for bit
    assert np.allclose(got["plant.robot_t"], got["time"], rtol=0, atol=1e-12)  # t + h
    assert 0 < np.median(got["plant.link_rtt"][1:]) < 0.01


@pytest.mark.slow
def test_swap_to_the_bridge_is_one_command(ssp_path, tmp_path):
    out = tmp_path / "bridge"
    args = ["--ssp", str(ssp_path), "--stop", "1", "--no-figures"]
    assert main(["run", *args, "--out", str(tmp_path / "run")]) == 0
    bridge = Path(ssp_path).parent / "BridgePlant.fmu"
    cmd = ["swap", *args, "--replace", f"plant={bridge}", "--robot", "lockstep", "--out", str(out),
           "--set", "plant.timeout_s=20"]  # fmt: skip
    assert main(cmd) == 0
    ref = results.read_csv(tmp_path / "run" / "observer.csv")
    got = results.read_csv(out / "observer.csv")
    for name in ref:
        assert np.array_equal(got[name], ref[name]), name


TIMEOUT = "timeout after 5000 ms waiting for the reply to STEP sequence 40"
GONE = "not reachable"  # a resend after the robot exited: ICMP port unreachable


@pytest.mark.parametrize(
    "fault,messages",
    [
        ("drop@40", [TIMEOUT]),  # never answered, however often it is sent
        ("late@40:30", [TIMEOUT]),
        ("seq@40", ["reply had sequence 1040, expected 40"]),
        ("exit@40", [TIMEOUT, GONE]),  # which one: whether a resend lands after the exit
    ],
)
@pytest.mark.slow
def test_a_failing_link_stops_the_run_cleanly(system, bridge, robot, fault, messages):
    """Each fault fails step 40 (timeout_s 5 s: a slow machine does not fail an earlier one)."""
    result = bridged(system, bridge, robot(f"--fault={fault}"), 1.0,
                     overrides={"plant.timeout_s": 5.0})  # fmt: skip
    assert not result.ok and any(m in result.error for m in messages), result.error
    assert "plant: fmi2DoStep at t=0.0975 returned Discard" in result.error
    assert len(result.data) == 40  # t = 0 and the 39 steps before the failed one
    assert np.isfinite(result.data).all()


def test_a_robot_killed_mid_run_stops_the_run(system, bridge, robot, monkeypatch):
    """The robot is killed once the master has taken 200 paced steps (an event of the run, not a
    wall-clock moment: a timer missed the run's start on a loaded machine); the next step fails."""
    port = robot()
    paced_steps = realtime.paced_steps

    def killing_after_200(step, n, *rest):
        def counted(i):
            done = step(i)
            if i == 199:
                robot.proc.kill()
                robot.proc.wait()
            return done

        return paced_steps(counted, n, *rest)

    monkeypatch.setattr(realtime, "paced_steps", killing_after_200)
    result = bridged(system, bridge, port, 3.0, realtime=True)
    assert not result.ok
    assert "not reachable" in result.error or "timeout" in result.error, result.error
    assert 20 < len(result.data) < 1000  # about 200 steps in 0.5 s
    assert result.names[-3:] == RT_COLUMNS and "realtime" in result.info


def test_a_robot_that_never_starts_fails_the_initialization(ssp_path, bridge):
    """In a child process: an error during initialization reaches the master as fmi2Fatal, after
    which pythonfmu 0.7 has corrupted the interpreter (a later garbage collection crashes it),
    for every Python FMU (see docs/limitations.md)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # free now, and nobody listens
    ok, rows, error = run_bridge_in_child(ssp_path, bridge, port, TOKEN)
    assert ok == "False" and rows == "0"
    assert f"robot process not reachable at 127.0.0.1:{port}" in error


def test_fault_options_are_checked():
    assert Fault.parse("late@5:0.25") == Fault("late", 5, 0.25)
    with pytest.raises(ValueError, match="--fault expects"):
        Fault.parse("slow@5")


# --- real time -----------------------------------------------------------------------------------


def test_realtime_run_is_paced_and_timed(ssp_path, tmp_path, capsys):
    out = tmp_path / "rt"
    started = time.perf_counter()
    args = ["run", "--ssp", str(ssp_path), "--stop", "0.5", "--realtime", "--no-figures"]
    assert main([*args, "--out", str(out)]) == 0
    assert time.perf_counter() - started >= 0.5
    text = capsys.readouterr().out
    assert "real time at 400 Hz:" in text and "start jitter: p50" in text
    rows = results.read_csv(out / "observer.csv")
    assert len(rows["time"]) == 201
    late = rows["rt.start_late_s"][1:]
    assert (late >= 0).all() and np.median(late) < 1e-3
    assert (rows["rt.compute_s"][1:] > 0).all()


@pytest.mark.slow
def test_bridge_against_a_realtime_robot(system, bridge, robot):
    port = robot(realtime=True)
    result = bridged(system, bridge, port, 1.0, realtime=True)
    assert result.ok, result.error
    robot_t = result["plant.robot_t"]
    assert np.all(np.diff(robot_t) >= 0) and 0.9 < robot_t[-1] < 1.1  # the robot's own clock
    ref = Master(system, RunOptions(stop_time=1.0)).run()
    # held torque applied on arrival, 1 ms ticks: close to the in-process plant, not equal
    assert np.abs(result["plant.x"] - ref["plant.x"]).max() < 5e-3
