"""Build everything: the Python FMUs, the native FMUs (when a C compiler is present), the system
archives per scenario and the FMI 3.0 edition. Above build and build3, so neither imports the
other's caller."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from impedance_cosim.packaging.build import (
    DEFAULT_OUT,
    FMUS,
    NATIVE,
    build_fmu,
    build_native_fmu,
    build_ssp,
)


def build_all(out_dir: Path = DEFAULT_OUT, only: list[str] | None = None) -> list[Path]:
    """Build the named FMUs (default: all, then the system archive) and return their paths."""
    keys = only or list(FMUS)
    unknown = [k for k in keys if k not in FMUS]
    if unknown:
        raise ValueError(f"unknown FMU {unknown}; choose from {sorted(FMUS)}")
    built = [build_fmu(FMUS[k], out_dir) for k in keys]
    native = [k for k in keys if (NATIVE / k / "model.c").is_file()]
    if native and shutil.which(os.environ.get("CC", "gcc")) is None:
        print("warning: no C compiler (gcc or $CC): the native FMUs are not built", file=sys.stderr)
        native = []
    built += [build_native_fmu(FMUS[k], Path(out_dir) / "native") for k in native]
    if not only:
        from impedance_cosim.cosim.system import SCENARIOS

        flavours = [("PaperScenario", None)]
        if native:
            flavours.append(("PaperScenario-native", Path(out_dir) / "native"))
        for name, fmu_dir in flavours:
            built.append(build_ssp(out_dir, name, fmu_dir))
            for s in SCENARIOS:  # one archive per scenario, for engines without SSP variants
                built.append(build_ssp(out_dir, f"{name}-{s}", fmu_dir, scenario=s))
        if native:
            from impedance_cosim.packaging.build3 import build_fmi3  # the FMI 3.0 edition

            built += build_fmi3(out_dir)
    return built
