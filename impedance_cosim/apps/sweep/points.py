"""The points of a sweep (one per run) from its axes: every combination of a grid, or a seeded
random sample (--random). An axis is a list of values, or (kind, low, high) for a range."""

from __future__ import annotations

import itertools
import math
import random
from typing import Any


def grid_points(axes: dict[str, Any]) -> list[dict[str, Any]]:
    """Every combination of the axes' values."""
    return [dict(zip(axes, combo)) for combo in itertools.product(*axes.values())]


def random_points(axes: dict[str, Any], runs: int, seed: int) -> list[dict[str, Any]]:
    """Seeded random points: ranges drawn (log-)uniformly, value lists by choice."""
    rng = random.Random(seed)
    points = []
    for _ in range(runs):
        point = {}
        for name, values in axes.items():
            if isinstance(values, tuple):
                kind, lo, hi = values
                v = (
                    math.exp(rng.uniform(math.log(lo), math.log(hi)))
                    if kind == "logrange"
                    else rng.uniform(lo, hi)
                )
                if name in ("system.rate", "system.encoder_bits"):
                    v = int(round(v))  # whole Hz: a whole number of steps per second
                point[name] = v
            else:
                point[name] = rng.choice(values)
        points.append(point)
    return points
