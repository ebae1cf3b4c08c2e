"""The robot process's options that need more than a type: injected faults (--fault) and the
ranges of its numbers (--tick, --max-step), checked with one line naming the option."""

from __future__ import annotations

import math
from dataclasses import dataclass

FAULTS = ("drop", "late", "seq", "exit", "reset")
TICK_RANGE = (1e-5, 0.1)  # s
MAX_STEP_RANGE = (1e-6, 10.0)  # s


@dataclass(frozen=True)
class Fault:
    """An injected fault at the STEP with sequence `seq`: drop (never answer), late (answer after
    `arg` seconds), seq (answer with the sequence number + 1000), exit (the process exits at
    once, without answering), reset (forget the session first, as a restarted robot would)."""

    kind: str
    seq: int
    arg: float = 0.0

    @classmethod
    def parse(cls, text: str) -> Fault:
        kind, _, rest = text.partition("@")
        seq, _, arg = rest.partition(":")
        usage = f"--fault expects drop@N, late@N:SECONDS, seq@N, exit@N or reset@N (got {text!r})"
        if kind not in FAULTS or not seq.isdigit() or not 0 < int(seq) < 2**32:
            raise ValueError(usage)
        try:
            value = float(arg or 0.0)
        except ValueError:
            raise ValueError(usage) from None
        if not 0.0 <= value <= 60.0:
            raise ValueError(f"--fault {text!r}: the delay must be 0-60 s")
        return cls(kind, int(seq), value)


def check_range(name: str, value: float, low: float, high: float) -> float:
    """value if it is a finite number in [low, high], else ValueError naming the option."""
    if not (isinstance(value, (int, float)) and math.isfinite(value) and low <= value <= high):
        raise ValueError(f"{name} must be a number from {low:g} to {high:g} (got {value!r})")
    return float(value)
