#!/usr/bin/env python3
"""Fuzz target: the SSP 2.0 reader (read_ssp on PaperScenario-fmi3-ssp2.ssp with one .ssd or .ssv
replaced by the fuzz bytes; see _ssp.py)."""

from __future__ import annotations

from _ssp import Target

TARGET = Target("PaperScenario-fmi3-ssp2.ssp")
entry = TARGET.entry
TARGET.fuzz_if_run(__name__)
