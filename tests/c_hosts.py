"""The plain C FMI hosts (tests/c_host/*.c) for the tests of the native FMUs: built with gcc
against fmpy's FMI headers, and the arguments host.c and host3.c share."""

from __future__ import annotations

import subprocess
from pathlib import Path

import fmpy

from impedance_cosim.cosim.system.paper import CONNECTIONS


def build_host(source: Path, exe: Path, *flags: str) -> Path:
    """SOURCE compiled (C99, every warning an error; FLAGS, else -O2) into EXE."""
    headers = Path(fmpy.__file__).parent / "c-code"
    subprocess.run(["gcc", "-std=c99", *(flags or ["-O2"]), "-Wall", "-Wextra", "-Werror",
                    f"-I{headers}", str(source), "-ldl", "-o", str(exe)], check=True)  # fmt: skip
    return exe


def links_and_record(vrs: dict[str, dict[str, int]]) -> list[str]:
    """The host's arguments for the system's connections, controller (A) and plant (B), and the
    signals to record (plant x, y, contact force; controller torques); VRS: each part's value
    references by name."""
    letter = {"controller": "A", "plant": "B"}
    links = ",".join(
        f"{letter[se]}{vrs[se][sc]}>{letter[ee]}{vrs[ee][ec]}" for se, sc, ee, ec in CONNECTIONS
    )
    record = ",".join([f"B{vrs['plant'][n]}" for n in ("x", "y", "contact_force")]
                      + [f"A{vrs['controller'][f'tau{i}']}" for i in (1, 2, 3)])  # fmt: skip
    return [links, record]
