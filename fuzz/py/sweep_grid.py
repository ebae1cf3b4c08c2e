#!/usr/bin/env python3
"""Fuzz target: the sweep's --grid / --random item parser (impedance_cosim/apps/sweep/plan.py
parse_axis, parse_value). Only SweepError may come out, with a message; a grid is a
non-empty list of at most MAX_RUNS values, a range two finite ordered bounds."""

from __future__ import annotations

import math
import sys

import _common  # noqa: F401 - sys.path

from impedance_cosim.apps.sweep import plan


def entry(data: bytes) -> None:
    item = data.decode("utf-8", "replace")
    try:
        name, values = plan.parse_axis(item)
    except plan.SweepError as exc:
        assert str(exc), repr(exc)
        return
    assert name and name == name.strip()
    if isinstance(values, tuple):
        kind, low, high = values
        assert kind in ("range", "logrange") and math.isfinite(low) and low < high
    else:
        assert 1 <= len(values) <= plan.MAX_RUNS


if __name__ == "__main__":
    _common.main(entry)
    sys.exit(0)
