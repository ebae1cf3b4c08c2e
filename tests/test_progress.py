"""The shared progress display (impedance_cosim.util.progress): tqdm on a terminal, plain lines in
a log, nothing when disabled or when the work ends before the delay."""

from __future__ import annotations

import io

from impedance_cosim.util.progress import Progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def drive(stream, **kw) -> str:
    p = Progress(50, "observer", "step", stream=stream, **kw)
    for i in range(51):
        p.update(i, f"t={i / 400:.3f} s, 30.0x real time")
    p.close()
    return stream.getvalue()


def test_plain_lines_when_not_a_terminal():
    text = drive(io.StringIO(), delay=0.0, every=0.0)
    lines = text.splitlines()
    assert "\r" not in text and len(lines) >= 2
    assert lines[-1].startswith("observer: 100%") and "50/50" in lines[-1]
    assert "30.0x real time" in lines[-1]


def test_a_bar_on_a_terminal():
    text = drive(Terminal(), delay=0.0)
    assert "\r" in text and "50/50" in text and "real time" in text


def test_nothing_when_disabled_or_quick():
    assert drive(io.StringIO(), enabled=False, delay=0.0, every=0.0) == ""
    assert drive(io.StringIO(), delay=60.0) == ""  # ended before the delay: no line at all
    assert drive(Terminal(), delay=60.0) == ""


def test_a_broken_stream_does_not_end_the_work():
    stream = io.StringIO()
    stream.close()
    p = Progress(3, "sweep", "run", stream=stream, delay=0.0, every=0.0)
    p.update(1)
    p.update(3)
    p.close()  # no exception
