"""Documentation, icon, licence and metadata inside every FMU (Python and native), and the
licence metadata of the project and the system archives."""

from __future__ import annotations

import io
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from html.parser import HTMLParser
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu
from fmpy_cli import fmpy_cli

import impedance_cosim
from impedance_cosim.packaging.build import FMUS, REPO
from impedance_cosim.packaging.documentation import documentation_members

NS_ATTRS = ("author", "version", "copyright", "license")


@pytest.fixture(scope="module")
def fmus(fmu_dir: Path, native_dir: Path) -> list[Path]:
    """Every FMU the build makes: each Python one (FMUS), two native."""
    found = sorted(fmu_dir.glob("*.fmu")) + sorted(native_dir.glob("*.fmu"))
    assert len(found) == len(FMUS) + 2, found
    return found


class Page(HTMLParser):
    """The parts of index.html the tests look at: tags with their attributes, table rows."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.rows: list[list[str]] = []
        self.headings: list[str] = []
        self._cell: list[str] | None = None
        self._heading: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag in ("h2", "h3"):
            self._heading = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append("".join(self._cell).strip())
            self._cell = None
        elif tag in ("h2", "h3") and self._heading is not None:
            self.headings.append("".join(self._heading).strip())
            self._heading = None

    def handle_data(self, data):
        for part in (self._cell, self._heading):
            if part is not None:
                part.append(data)


def page_of(fmu: Path) -> Page:
    with zipfile.ZipFile(fmu) as z:
        page = Page()
        page.feed(z.read("documentation/index.html").decode("utf-8"))
    return page


def variable_rows(page: Page) -> dict[str, list[str]]:
    """Rows of the variable tables (10 cells: name .. description), by variable name."""
    rows = [r for r in page.rows if len(r) == 10 and r[0] != "name"]
    return {r[0]: r for r in rows}


def test_index_lists_every_variable_with_its_unit(fmus):
    for fmu in fmus:
        md = read_model_description(str(fmu))
        rows = variable_rows(page_of(fmu))
        assert len(rows) == len(md.modelVariables), fmu.name
        for v in md.modelVariables:
            row = rows[v.name]
            assert row[1] == str(v.valueReference), (fmu.name, v.name)
            assert row[2:5] == [v.causality, v.variability, v.type], (fmu.name, v.name)
            assert row[5] == (v.unit or ""), (fmu.name, v.name)
            assert row[9] == v.description, (fmu.name, v.name)
            if v.start is not None:
                assert row[8] == str(v.start) or float(row[8]) == float(v.start), v.name
            for k, cell in ((v.min, row[6]), (v.max, row[7])):
                assert cell == ("" if k is None else str(k)) or float(cell) == float(k), v.name
        units = {v.unit for v in md.modelVariables if v.unit}
        assert len(units) > 5, f"{fmu.name}: units missing from the model description"


def test_index_opens_without_network(fmus):
    for fmu in fmus:
        page = page_of(fmu)
        assert page.tags, fmu.name
        names = zipfile.ZipFile(fmu).namelist()
        for tag, attrs in page.tags:
            assert tag not in ("script", "link", "iframe", "object", "embed"), (fmu.name, tag)
            for key in ("src", "href"):
                target = attrs.get(key)
                if target is None:
                    continue
                assert "://" not in target and not target.startswith("//"), (fmu.name, target)
                # a relative reference must resolve to a member of the archive
                resolved = Path("documentation", target).as_posix().replace("documentation/../", "")
                assert resolved in names, (fmu.name, target)
        with zipfile.ZipFile(fmu) as z:
            text = z.read("documentation/index.html").decode()
        assert "url(" not in text and "@import" not in text


def test_index_shows_interfaces_platforms_and_the_papers_numbers(fmus):
    for fmu in fmus:
        page = page_of(fmu)
        cells = {r[0]: r[1] for r in page.rows if len(r) == 2}
        with zipfile.ZipFile(fmu) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
            names = z.namelist()
        for kind in ("ModelExchange", "CoSimulation"):
            el = root.find(kind)
            assert (kind in page.headings) == (el is not None), (fmu.name, kind)
            for key, value in (el.attrib if el is not None else {}).items():
                assert cells[key] == value, (fmu.name, key)
        platforms = {n.split("/")[1] for n in names if n.startswith("binaries/")}
        assert platforms and all(p in cells for p in platforms), (fmu.name, platforms)
        for key in NS_ATTRS:
            assert cells[key] == root.get(key), (fmu.name, key)
        with zipfile.ZipFile(fmu) as z:
            text = z.read("documentation/index.html").decode()
        assert "fmpy simulate" in text
        if root.get("modelName") == "PumaPlant":
            for number in ("<code>a1</code> = 0.432 m", "<code>wall_k</code> = 10000.0 N/m",
                           "<code>Im1</code> = 4.71 kg.m2"):  # fmt: skip
                assert number in text, number
        if root.get("modelName") == "ImpedanceController":
            for number in ("<code>K1</code> = 50.0 1/s", "<code>G1</code> = 1000.0 N/m",
                           "<code>wall_depth</code> = 0.00196 m"):  # fmt: skip
                assert number in text, number


def test_index_follows_the_model_description():
    """The page is generated from the model description given, not from a fixed list."""
    md = ET.Element("fmiModelDescription", {"modelName": "Extra", "author": "someone"})
    ET.SubElement(md, "CoSimulation", {"modelIdentifier": "Extra", "canFoo": "true"})
    mv = ET.SubElement(md, "ModelVariables")
    sv = ET.SubElement(mv, "ScalarVariable", {"name": "zeta", "valueReference": "7",
                       "causality": "parameter", "variability": "fixed",
                       "description": "a test variable"})  # fmt: skip
    ET.SubElement(sv, "Real", {"unit": "N.m", "start": "2.5", "min": "0.0"})
    members = documentation_members(ET.tostring(md), ["binaries/linux64/Extra.so"], "native C99")
    page = Page()
    page.feed(members["documentation/index.html"].decode())
    assert variable_rows(page)["zeta"] == ["zeta", "7", "parameter", "fixed", "Real", "N.m",
                                           "0.0", "", "2.5", "a test variable"]  # fmt: skip
    cells = {r[0]: r[1] for r in page.rows if len(r) == 2}
    assert cells["canFoo"] == "true" and cells["linux64"] == "Extra.so"


def test_model_png_is_a_valid_png(fmus):
    from PIL import Image

    for fmu in fmus:
        with zipfile.ZipFile(fmu) as z:
            data = z.read("model.png")
        assert data.startswith(b"\x89PNG\r\n\x1a\n"), fmu.name
        with Image.open(io.BytesIO(data)) as img:
            img.verify()  # checks the chunks' CRCs
        with Image.open(io.BytesIO(data)) as img:
            img.load()
            assert img.size == (128, 128)
            assert len(img.getcolors(1 << 16)) > 3, f"{fmu.name}: the icon is blank"
        assert b"tIME" not in data and b"tEXt" not in data, "no date or tool name in the icon"


def test_licence_in_every_fmu_equals_the_root_licence(fmus):
    root = (REPO / "LICENSE").read_bytes()
    assert root.startswith(b"BSD 2-Clause License")
    assert b"Copyright (c) 2026, The impedance-cosim authors" in root
    for fmu in fmus:
        with zipfile.ZipFile(fmu) as z:
            assert z.read("documentation/licenses/license.txt") == root, fmu.name


def test_metadata_in_every_model_description(fmus):
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert pyproject["license"] == "BSD-2-Clause"
    assert pyproject["license-files"] == ["LICENSE"]
    assert pyproject["version"] == impedance_cosim.__version__
    for fmu in fmus:
        md = read_model_description(str(fmu))
        assert md.author == "The impedance-cosim authors", fmu.name
        assert md.version == impedance_cosim.__version__, fmu.name
        assert md.copyright == "Copyright (c) 2026, The impedance-cosim authors", fmu.name
        assert md.license.startswith("BSD-2-Clause"), fmu.name


def test_fmpy_validate_passes(fmus):
    for fmu in fmus:
        assert validate_fmu(str(fmu)) == [], fmu.name


def test_system_archives_carry_the_licence_metadata(fmu_dir: Path, native_dir: Path):
    for ssp in (fmu_dir / "PaperScenario.ssp", fmu_dir / "PaperScenario-native.ssp"):
        with zipfile.ZipFile(ssp) as z:
            files = [n for n in z.namelist() if n.endswith((".ssd", ".ssv"))]
            assert len(files) == 9, files  # 3 SSDs (scenario variants), 6 SSVs
            for name in files:
                root = ET.fromstring(z.read(name))
                assert root.get("author") == "The impedance-cosim authors", name
                assert root.get("fileversion") == impedance_cosim.__version__, name
                assert root.get("license") == "BSD-2-Clause", name
                assert "2026" in root.get("copyright", ""), name


@pytest.mark.slow
def test_documented_fmpy_commands_run(fmus, tmp_path: Path):
    """The `fmpy simulate` lines index.html gives work as written (shortened to 0.1 s)."""
    import html
    import re
    import shlex
    import shutil

    ran, expected = 0, 0
    for fmu in fmus:
        if fmu.stem == "BridgePlant":  # needs its robot process: covered by tests/test_hil.py
            continue
        with zipfile.ZipFile(fmu) as z:
            page = z.read("documentation/index.html").decode()
        text = html.unescape(re.sub(r"<[^>]+>", "", page))
        lines = re.findall(r"^fmpy simulate \S+\.fmu.*$", text, re.MULTILINE)
        assert len(lines) >= 2, fmu.name
        # two lines per FMU (plain, with start values), one more where it offers Model Exchange
        expected += 2 + (read_model_description(str(fmu)).modelExchange is not None)
        work = tmp_path / fmu.parent.name / fmu.stem
        work.mkdir(parents=True)
        shutil.copy(fmu, work / fmu.name)
        for line in lines:
            args = shlex.split(line)[1:] + ["--stop-time", "0.1"]
            if "--output-file" not in args:
                args += ["--output-file", "out.csv"]
            done = fmpy_cli(args, cwd=work, capture_output=True, text=True, timeout=120)
            assert done.returncode == 0, (fmu.name, line, done.stderr[-2000:])
            out = next(work.glob("*.csv"))
            assert len(out.read_text().splitlines()) > 10, (fmu.name, line)
            out.unlink()
            ran += 1
    assert ran == expected and ran >= 8
