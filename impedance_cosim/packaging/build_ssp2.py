"""Build the SSP 2.0 edition of the FMI 3.0 system archive, fmus/PaperScenario-fmi3-ssp2.ssp, and
its array edition PaperScenario-fmi3-arrays-ssp2.ssp (the FMUs of fmus/fmi3/arrays/ wired by
array connectors; cosim/system/ssp2.py writes their SSDs and SSVs), and validate each against
the SSP 2.0 XSDs that pyssp-standard ships (and its SRMD meta data against SSP Traceability's
SRMD schema).
The SSP 1.0 archives are left as they are, for engines that read only 1.0."""

from __future__ import annotations

import functools
import zipfile
from pathlib import Path
from typing import Any

from impedance_cosim.packaging.archive_out import write_zip
from impedance_cosim.packaging.build import DEFAULT_OUT, _info

NAME = "PaperScenario-fmi3-ssp2"
ARRAYS_NAME = "PaperScenario-fmi3-arrays-ssp2"


def build_ssp2(
    out_dir: Path = DEFAULT_OUT, fmu_dir: Path | None = None, arrays: bool = False
) -> Path:
    """Pack the 2.0 SSDs and SSVs with the FMI 3.0 FMUs of fmu_dir (default out_dir/fmi3, with
    arrays out_dir/fmi3/arrays) into out_dir/PaperScenario-fmi3-ssp2.ssp (with arrays: the array
    edition, PaperScenario-fmi3-arrays-ssp2.ssp); refused (ValueError) if it does not validate."""
    from impedance_cosim.cosim.system.ssp2 import ARRAYS2, CLOCKED2, archive_files

    edition = ARRAYS2 if arrays else CLOCKED2
    out_dir = Path(out_dir)
    fmu_dir = Path(fmu_dir or out_dir / "fmi3" / ("arrays" if arrays else ""))
    fmus = {}
    for name, spec in edition.components.items():
        fmu = fmu_dir / spec.fmu
        if not fmu.is_file():
            raise FileNotFoundError(f"{fmu} is missing: build the FMI 3.0 FMUs first")
        fmus[name] = fmu.read_bytes()
    target = out_dir / f"{ARRAYS_NAME if arrays else NAME}.ssp"

    def validate(archive: Path) -> None:
        problems = validation_problems(archive)
        if problems:
            raise ValueError(f"{target.name} does not validate: {problems[0]}")

    with write_zip(target, check=validate) as z:
        for path, data in archive_files(fmus, edition).items():
            z.writestr(_info(path), data)
    return target


@functools.cache
def _srmd_schema() -> Any:
    import xmlschema

    from impedance_cosim.cosim.ssp.ssp2 import schema_dir

    return xmlschema.XMLSchema11(str(schema_dir().parent / "SRMD11.xsd"))


def validation_problems(archive: Path) -> list[str]:
    """Every .ssd and .ssv member of an archive against the SSP 2.0 XSDs, and each inline SRMD
    against SRMD11.xsd: one line per problem (member, line, message); [] if all validate."""
    from lxml import etree

    from impedance_cosim.cosim.ssp.ssp2 import SRMD, schema

    problems = []
    with zipfile.ZipFile(archive) as z:
        for name in z.namelist():
            xsd = {".ssd": "SystemStructureDescription.xsd",
                   ".ssv": "SystemStructureParameterValues.xsd"}.get(Path(name).suffix)  # fmt: skip
            if xsd is None:
                continue
            doc = etree.fromstring(z.read(name))
            checker = schema(xsd)
            if not checker.validate(doc):
                e = checker.error_log[0]
                problems.append(f"{name} (line {e.line}): {e.message}")
            for srmd in doc.iter(f"{SRMD}SimulationResourceMetaData"):
                for error in _srmd_schema().iter_errors(etree.tostring(srmd).decode()):
                    problems.append(f"{name}: SRMD: {error.reason}")
                    break
    return problems
