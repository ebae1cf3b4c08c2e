"""Real-time options: each is applied for the run and undone after it, refused with a note (not an
error) when the OS says no, and named in one line when given without --realtime or out of range."""

from __future__ import annotations

import errno
import os

import pytest

from impedance_cosim.cli import main
from impedance_cosim.cosim.master import realtime
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.master.realtime import RealtimeOptions
from impedance_cosim.cosim.ssp.read import read_ssp


def test_pinning_is_applied_and_undone():
    before = os.sched_getaffinity(0)
    cpu = min(before)
    with realtime.applied(RealtimeOptions(cpu=cpu)) as notes:
        assert os.sched_getaffinity(0) == {cpu}
    assert os.sched_getaffinity(0) == before
    assert notes == [f"pinned to CPU {cpu}"]
    with realtime.applied(RealtimeOptions(cpu=4096)) as notes:
        assert os.sched_getaffinity(0) == before
    assert notes[0].startswith("not pinned: CPU 4096 is not one of")


def test_fifo_is_applied_and_undone_or_refused_with_a_note(monkeypatch):
    policy = os.sched_getscheduler(0)
    with realtime.applied(RealtimeOptions(fifo_priority=10)) as notes:
        inside = os.sched_getscheduler(0)
    assert os.sched_getscheduler(0) == policy
    if notes == ["SCHED_FIFO priority 10"]:
        assert inside == os.SCHED_FIFO
    else:  # not permitted here: the note says so and nothing changed
        assert "SCHED_FIFO refused" in notes[0] and inside == policy

    def refuse(*_args):
        raise PermissionError(errno.EPERM, os.strerror(errno.EPERM))

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with realtime.applied(RealtimeOptions(fifo_priority=10)) as notes:
        assert os.sched_getscheduler(0) == policy
    assert notes == [
        "SCHED_FIFO refused (Operation not permitted; needs CAP_SYS_NICE or RLIMIT_RTPRIO):"
        " normal priority"
    ]


def test_memory_lock_refused_is_a_note(monkeypatch):
    class Libc:
        def mlockall(self, _flags):
            import ctypes

            ctypes.set_errno(errno.EPERM)
            return -1

    monkeypatch.setattr(realtime, "_libc", Libc)
    with realtime.applied(RealtimeOptions(lock_memory=True)) as notes:
        pass
    assert notes[0].startswith("memory not locked: mlockall: Operation not permitted")


def test_a_realtime_run_reports_its_options(native_dir):
    system = read_ssp(native_dir.parent / "PaperScenario-native.ssp")
    cpu = min(os.sched_getaffinity(0))
    options = RealtimeOptions(cpu=cpu, spin_s=0.0)
    result = Master(system, RunOptions(stop_time=0.05, realtime=options)).run()
    assert result.ok and len(result.data) == 21
    assert result.info["realtime"]["notes"] == [f"pinned to CPU {cpu}"]
    assert result.info["realtime"]["steps"] == 20
    assert result.wall_time >= 0.05 - 0.0025  # paced to the wall clock
    assert os.sched_getaffinity(0) != {cpu} or len(os.sched_getaffinity(0)) == 1


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--rt-fifo", "10"], "--rt-fifo only apply with --realtime"),
        (["--rt-cpu", "0", "--rt-lock-memory"], "--rt-lock-memory, --rt-cpu only apply with"),
        (["--realtime", "--rt-fifo", "500"], "SCHED_FIFO priority must be 1..99 (got 500)"),
        (["--realtime", "--rt-spin", "-1"], "busy-wait must be 0 <= spin < 1 s (got -1.0)"),
    ],
)
def test_bad_realtime_options_are_one_line(native_dir, tmp_path, capsys, extra, message):
    ssp = native_dir.parent / "PaperScenario-native.ssp"
    args = ["run", "--ssp", str(ssp), "--stop", "0.05", "--out", str(tmp_path), "--no-figures"]
    assert main([*args, *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
