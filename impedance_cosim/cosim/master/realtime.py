"""The real-time step loop of the master, what it can ask of the OS to keep its deadlines, and
the statistics of a real-time run (deadline misses, jitter, step duration).

Step i starts at the wall-clock time t0 + i h: sleep until `spin_s` before it, then busy-wait (a
sleep overshoots by up to a scheduler tick); a late step is never skipped, the next one starts at
once (the schedule is absolute, so the loop catches up). The garbage collector is paused.

Options (RealtimeOptions), each applied for the run and undone after it; one that the OS refuses
(no permission, no such CPU) is a note in the run's statistics, not an error:
- lock_memory: mlockall(MCL_CURRENT | MCL_FUTURE), no page faults to disk (needs CAP_IPC_LOCK or
  a large enough RLIMIT_MEMLOCK);
- fifo_priority: SCHED_FIFO at this priority (1..99) for the stepping thread, ahead of every
  normal process (needs CAP_SYS_NICE or RLIMIT_RTPRIO; the kernel's RT throttling still leaves
  others 5% of the CPU);
- cpu: pin the stepping thread to this CPU (sched_setaffinity);
- spin_s: busy-wait this long before each step's start (0: sleep only)."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

SPIN_S = 0.0005  # default busy-wait before each step's start
MCL_CURRENT, MCL_FUTURE = 1, 2


@dataclass(frozen=True)
class RealtimeOptions:
    """What the real-time loop asks of the OS (see module docstring)."""

    lock_memory: bool = False
    fifo_priority: int | None = None
    cpu: int | None = None
    spin_s: float = SPIN_S

    def __post_init__(self) -> None:
        if self.fifo_priority is not None and not 1 <= self.fifo_priority <= 99:
            raise ValueError(f"SCHED_FIFO priority must be 1..99 (got {self.fifo_priority})")
        if self.cpu is not None and self.cpu < 0:
            raise ValueError(f"CPU number must be >= 0 (got {self.cpu})")
        if not 0 <= self.spin_s < 1:
            raise ValueError(f"busy-wait must be 0 <= spin < 1 s (got {self.spin_s})")


def _libc() -> Any:
    return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)


def _lock_memory(stack: contextlib.ExitStack, notes: list[str]) -> None:
    try:
        libc = _libc()
        if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
            errno = ctypes.get_errno()
            notes.append(f"memory not locked: mlockall: {os.strerror(errno)} (needs CAP_IPC_LOCK"
                         " or a larger RLIMIT_MEMLOCK)")  # fmt: skip
            return
    except (OSError, AttributeError) as exc:  # no libc or no mlockall (not Linux)
        notes.append(f"memory not locked: mlockall unavailable ({exc})")
        return
    stack.callback(libc.munlockall)
    notes.append("memory locked (mlockall)")


def _fifo(priority: int, stack: contextlib.ExitStack, notes: list[str]) -> None:
    if not hasattr(os, "sched_setscheduler"):
        notes.append("SCHED_FIFO not available on this OS: normal priority")
        return
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        notes.append(f"SCHED_FIFO refused ({exc.strerror}; needs CAP_SYS_NICE or RLIMIT_RTPRIO):"
                     " normal priority")  # fmt: skip
        return
    stack.callback(os.sched_setscheduler, 0, policy, param)
    notes.append(f"SCHED_FIFO priority {priority}")


def _pin(cpu: int, stack: contextlib.ExitStack, notes: list[str]) -> None:
    if not hasattr(os, "sched_setaffinity"):
        notes.append("CPU pinning not available on this OS: not pinned")
        return
    allowed = os.sched_getaffinity(0)
    if cpu not in allowed:
        notes.append(f"not pinned: CPU {cpu} is not one of this process's {sorted(allowed)}")
        return
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError as exc:
        notes.append(f"not pinned to CPU {cpu} ({exc.strerror})")
        return
    stack.callback(os.sched_setaffinity, 0, allowed)
    notes.append(f"pinned to CPU {cpu}")


@contextlib.contextmanager
def applied(options: RealtimeOptions) -> Iterator[list[str]]:
    """Apply the options for the body, undo them after; yields the notes (what was done, what
    was refused and why)."""
    notes: list[str] = []
    with contextlib.ExitStack() as stack:
        if options.lock_memory:
            _lock_memory(stack, notes)
        if options.cpu is not None:
            _pin(options.cpu, stack, notes)
        if options.fifo_priority is not None:
            _fifo(options.fifo_priority, stack, notes)
        yield notes


def paced_steps(
    step: Callable[[int], tuple[int, str | None]],
    n: int,
    h: float,
    timing: np.ndarray,
    spin_s: float = SPIN_S,
    stopped: Callable[[], bool] = lambda: False,
    progress: Callable[[int], None] | None = None,
) -> tuple[int, str | None]:
    """Steps 0 .. n-1, step(i) -> (rows filled, error), each started at its wall-clock time;
    fills timing[i + 1] = (start - scheduled, duration, completion - deadline); returns (rows
    filled including the initial one, error or None)."""
    clock = time.perf_counter
    rows, error = 1, None
    collecting = gc.isenabled()
    gc.disable()
    try:
        t_wall0 = clock()
        for i in range(n):
            if stopped():
                break
            scheduled = t_wall0 + i * h
            remaining = scheduled - clock()
            if remaining > spin_s:
                time.sleep(remaining - spin_s)
            while clock() < scheduled:
                pass
            began = clock()
            done, error = step(i)
            ended = clock()
            timing[i + 1] = (began - scheduled, ended - began, ended - scheduled - h)
            rows += done
            if error:
                break
            if progress:
                progress(i + 1)
    finally:
        if collecting:
            gc.enable()
    return rows, error


FLAGS = {"lock_memory": "--rt-lock-memory", "fifo_priority": "--rt-fifo", "cpu": "--rt-cpu",
         "spin_s": "--rt-spin"}  # fmt: skip


def add_options(p: Any) -> None:
    """The real-time options of `run` and `swap` (they need --realtime)."""
    p.add_argument(FLAGS["lock_memory"], action="store_true",
                   help="real time: lock the process's memory (mlockall)")  # fmt: skip
    p.add_argument(FLAGS["fifo_priority"], type=int, metavar="PRIORITY", default=None,
                   help="real time: step under SCHED_FIFO at this priority (1..99)")  # fmt: skip
    p.add_argument(FLAGS["cpu"], type=int, metavar="CPU", default=None,
                   help="real time: pin the stepping thread to this CPU")  # fmt: skip
    p.add_argument(FLAGS["spin_s"], type=float, metavar="SECONDS", default=None,
                   help=f"real time: busy-wait before each step (default {SPIN_S} s)")  # fmt: skip


def realtime_setting(args: Any) -> bool | RealtimeOptions:
    """Master's `realtime` argument from the command line: False, True or RealtimeOptions;
    ValueError (one line) for a real-time option without --realtime or out of range."""
    given = {
        "lock_memory": getattr(args, "rt_lock_memory", False) or None,
        "fifo_priority": getattr(args, "rt_fifo", None),
        "cpu": getattr(args, "rt_cpu", None),
        "spin_s": getattr(args, "rt_spin", None),
    }
    given = {k: v for k, v in given.items() if v is not None}
    if not getattr(args, "realtime", False):
        if given:
            raise ValueError(f"{', '.join(FLAGS[k] for k in given)} only apply with --realtime")
        return False
    return RealtimeOptions(**given) if given else True


def realtime_stats(timing: np.ndarray, h: float) -> dict[str, Any]:
    """Statistics of the steps' timing rows (RT_COLUMNS): deadline misses (a step completed after
    its deadline), start jitter (actual - scheduled start) p50/p99/max, step duration p99/max,
    worst lateness; times in seconds."""
    if not len(timing):
        return {"steps": 0, "rate_hz": 1.0 / h, "deadline_misses": 0}
    start, compute, late = timing[:, 0], timing[:, 1], timing[:, 2]
    return {
        "steps": len(timing),
        "rate_hz": 1.0 / h,
        "deadline_misses": int(np.count_nonzero(late > 0.0)),
        "jitter_p50_s": float(np.percentile(start, 50)),
        "jitter_p99_s": float(np.percentile(start, 99)),
        "jitter_max_s": float(start.max()),
        "compute_p50_s": float(np.percentile(compute, 50)),
        "compute_p99_s": float(np.percentile(compute, 99)),
        "compute_max_s": float(compute.max()),
        "lateness_max_s": float(late.max()),
    }


def format_realtime(stats: dict[str, Any]) -> str:
    """The real-time statistics as summary lines."""
    if not stats.get("steps"):
        return "real time: no step taken"
    ms = 1e3
    return (
        f"real time at {stats['rate_hz']:g} Hz: {stats['deadline_misses']} deadline misses in"
        f" {stats['steps']} steps\n"
        f"start jitter: p50 {ms * stats['jitter_p50_s']:.3f} ms, p99"
        f" {ms * stats['jitter_p99_s']:.3f} ms, max {ms * stats['jitter_max_s']:.3f} ms\n"
        f"step duration: p50 {ms * stats['compute_p50_s']:.3f} ms, p99"
        f" {ms * stats['compute_p99_s']:.3f} ms, max {ms * stats['compute_max_s']:.3f} ms"
        f" (worst slack {-ms * stats['lateness_max_s']:.3f} ms)"
    ) + "".join(f"\nreal time: {note}" for note in stats.get("notes", []))
