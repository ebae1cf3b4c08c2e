"""Progress of runs and sweeps on stderr, one look for both (tqdm: bar, rate, ETA).

On a terminal a tqdm bar; when the stream is not a terminal (a log, a pipe, CI), one plain line
in tqdm's format every `every` seconds and a last one at the end, so logs show progress without
carriage returns; nothing at all when disabled (`--no-progress`)."""

from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:  # tqdm loads when a bar or a line is shown (a run without one never needs it)
    from tqdm import tqdm


class Progress:
    """Progress of `total` units of work (steps of a run, runs of a sweep)."""

    def __init__(
        self,
        total: int,
        desc: str,
        unit: str,
        enabled: bool = True,
        stream: TextIO | None = None,
        delay: float = 1.0,
        every: float = 10.0,
    ) -> None:
        self.total, self.desc, self.unit = total, desc, unit
        self.stream = stream if stream is not None else sys.stderr
        self.enabled, self.delay, self.every = enabled, delay, every
        self.start = time.perf_counter()
        self.n, self.postfix = 0, ""
        self._last_line = self.start + delay - every  # first plain line once `delay` has passed
        self._printed, self._printed_n = False, -1
        self._bar: tqdm | None = None
        if enabled and _is_terminal(self.stream):
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit=unit, file=self.stream, delay=delay,
                             dynamic_ncols=True, leave=True)  # fmt: skip

    def update(self, n: int, postfix: str = "") -> None:
        """n units done so far (absolute); postfix: extra text, e.g. the real-time factor."""
        if not self.enabled:
            return
        self.n, self.postfix = n, postfix
        if self._bar is not None:
            if postfix:
                self._bar.set_postfix_str(postfix, refresh=False)
            self._bar.update(n - self._bar.n)
            return
        now = time.perf_counter()
        if now - self._last_line >= self.every:
            self._last_line = now
            self._line(now)

    def close(self) -> None:
        """Finish the bar (or print the last plain line if any was printed)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self.enabled and self._printed and self.n != self._printed_n:
            self._line(time.perf_counter())
        self.enabled = False

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _line(self, now: float) -> None:
        from tqdm import tqdm

        text = tqdm.format_meter(self.n, self.total, now - self.start, prefix=self.desc,
                                 unit=self.unit, postfix=self.postfix or None, ncols=0)  # fmt: skip
        try:
            self.stream.write(text + "\n")
            self.stream.flush()
        except (OSError, ValueError):  # a closed or broken stream must not end the run
            self.enabled = False
        self._printed, self._printed_n = True, self.n


def _is_terminal(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


class StepProgress(Progress):
    """A simulation's progress in fixed steps of h from t0 (the master's run), shown once it has
    taken more than a second, with the simulated time and the real-time factor."""

    DELAY, EVERY = 1.0, 10.0  # s: nothing before DELAY; in a log, a line every EVERY

    def __init__(self, steps: int, name: str, t0: float, h: float, stream: TextIO) -> None:
        super().__init__(steps, name, "step", stream=stream, delay=self.DELAY, every=self.EVERY)
        self.t0, self.h = t0, h

    def update_steps(self, i: int) -> None:
        """i steps done."""
        if not self.enabled:
            return
        elapsed = time.perf_counter() - self.start
        factor = i * self.h / elapsed if elapsed > 0 else 0.0
        self.update(i, f"t={self.t0 + i * self.h:.2f} s, {factor:.1f}x real time")
