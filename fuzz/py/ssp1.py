#!/usr/bin/env python3
"""Fuzz target: the SSP 1.0 reader (read_ssp on PaperScenario-native.ssp with one .ssd or .ssv
replaced by the fuzz bytes; see _ssp.py)."""

from __future__ import annotations

from _ssp import Target

TARGET = Target("PaperScenario-native.ssp")
entry = TARGET.entry
TARGET.fuzz_if_run(__name__)
