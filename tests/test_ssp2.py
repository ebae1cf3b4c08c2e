"""The SSP 2.0 edition of the FMI 3.0 archive (PaperScenario-fmi3-ssp2.ssp): it validates against
the SSP 2.0 XSDs (pyssp-standard's, through xmlschema: another validator than the reader's lxml),
our reader takes it (typed connectors, the Clock connector and its connection, the FMU
checksums), our master gives the same CSV bytes from it as from the SSP 1.0 archive in every
scenario, and a broken 2.0 SSD is one SspError naming the file and the element (exit 2)."""

from __future__ import annotations

import hashlib
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import xmlschema

from impedance_cosim.cosim.fmus import fmi3 as fmu3
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.results.result import write_csv
from impedance_cosim.cosim.ssp.read import SspError, read_ssp
from impedance_cosim.cosim.ssp.ssp2 import SRMD, schema_dir
from impedance_cosim.cosim.system.paper import SCENARIOS, ssd_name

REPO = Path(__file__).resolve().parents[1]
SSD = "SystemStructure.ssd"


@pytest.fixture(scope="module")
def editions(fmi3_dir: Path) -> tuple[Path, Path]:
    """(the SSP 1.0 archive, its SSP 2.0 edition), both built by build_fmi3."""
    return (
        fmi3_dir.parent / "PaperScenario-fmi3.ssp",
        fmi3_dir.parent / "PaperScenario-fmi3-ssp2.ssp",
    )


def _xml_members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist() if n.endswith((".ssd", ".ssv"))}


def test_the_2_0_archive_validates_against_the_ssp_2_0_xsds(editions):
    """Every SSD and SSV (version 2.0) against pyssp-standard's SSP 2.0 XSDs, each SRMD against
    SRMD11.xsd (XSD 1.1); the same validator refuses a connector of an unknown type."""
    _, ssp2 = editions
    folder = schema_dir()
    ssd_xsd = xmlschema.XMLSchema10(str(folder / "SystemStructureDescription.xsd"))
    ssv_xsd = xmlschema.XMLSchema10(str(folder / "SystemStructureParameterValues.xsd"))
    srmd_xsd = xmlschema.XMLSchema11(str(folder.parent / "SRMD11.xsd"))
    files = _xml_members(ssp2)
    assert sorted(n for n in files if n.endswith(".ssd")) == sorted(ssd_name(s) for s in SCENARIOS)
    assert len([n for n in files if n.endswith(".ssv")]) == 2 * len(SCENARIOS)
    for name, data in files.items():
        text = data.decode()
        assert 'version="2.0"' in text.split(">", 2)[1], name
        (ssd_xsd if name.endswith(".ssd") else ssv_xsd).validate(text)
    from lxml import etree

    root = etree.fromstring(files[SSD])
    srmds = list(root.iter(f"{SRMD}SimulationResourceMetaData"))
    assert len(srmds) == 2
    for srmd in srmds:
        srmd_xsd.validate(etree.tostring(srmd).decode())
    broken = files[SSD].replace(b'<ssc:Float64 unit="N.m" />', b"<ssc:Float128 />", 1)
    assert broken != files[SSD]
    assert not ssd_xsd.is_valid(broken.decode())


def test_the_2_0_ssd_has_typed_and_clock_connectors_and_fmu_checksums(editions):
    """Float64/Int32 connectors, the controller's sample_clock a Clock connector connected to
    the system's, the clocked connectors associated to it; SRMD checksums = SHA3-256 of the FMUs."""
    _, ssp2 = editions
    with read_ssp(ssp2) as system:
        assert system.version == "2.0"
        controller = system.component("controller")
        assert controller.source == "resources/ImpedanceControllerClocked.fmu"
        c = controller.connectors
        assert (c["q1"].type, c["q1"].unit, c["q1"].clocks) == ("Float64", "rad", ("sample_clock",))
        assert (c["tau1"].type, c["tau1"].clocks) == ("Float64", ("sample_clock",))
        assert c["velocity_source"].type == "Int32"
        assert (c["sample_clock"].type, c["sample_clock"].kind) == ("Clock", "input")
        assert c["sample_clock"].interval == "fixed"
        assert system.system_connectors["sample_clock"].type == "Clock"
        assert system.clock_connections == [("controller", "sample_clock", "", "sample_clock")]
        assert system.component("plant").connectors["q1"].clocks == ()
        assert len(system.connections) == 12
    with zipfile.ZipFile(ssp2) as z:
        ssd = z.read(SSD).decode()
        for member in ("resources/PumaPlant.fmu", "resources/ImpedanceControllerClocked.fmu"):
            assert f'checksum="{hashlib.sha3_256(z.read(member)).hexdigest()}"' in ssd


def test_the_1_0_archives_are_unchanged(editions):
    """The SSP 1.0 FMI 3.0 archive still holds the committed 1.0 SSDs and SSVs of ssp/."""
    ssp1, _ = editions
    for name, data in _xml_members(ssp1).items():
        assert data == (REPO / "ssp" / Path(name).name).read_bytes(), name
        assert b'version="1.0"' in data


def test_both_editions_have_the_same_parameter_sets(editions):
    with read_ssp(editions[0]) as one, read_ssp(editions[1]) as two:
        assert list(one.parameter_sets) == list(two.parameter_sets) == list(SCENARIOS)
        for name, params in one.parameter_sets.items():
            values = [(p.name, p.value, p.unit) for p in params]
            assert values == [(p.name, p.value, p.unit) for p in two.parameter_sets[name]]


def _csv(path: Path, scenario: str, tmp: Path, **kw) -> bytes:
    with read_ssp(path) as system:
        run = Master(system, RunOptions(parameter_set=scenario, **kw)).run()
    assert run.error is None or run.divergence is not None, run.error
    out = tmp / f"{path.stem}-{scenario}.csv"
    write_csv(out, run.names, run.data)
    return out.read_bytes()


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_both_editions_give_the_same_csv_in_every_scenario(
    editions, scenario, algorithm, tmp_path, monkeypatch
):
    """1 s of each scenario: the 2.0 edition (clocked controller, ticked by our master) writes
    the same CSV bytes as the 1.0 archive (Co-Simulation controller)."""
    ticks = []
    step = fmu3.ClockedInstance.step

    def counting(self, t, h):
        step(self, t, h)
        ticks.append(self.ticks)

    monkeypatch.setattr(fmu3.ClockedInstance, "step", counting)
    one = _csv(editions[0], scenario, tmp_path, algorithm=algorithm, stop_time=1.0)
    assert ticks == []
    two = _csv(editions[1], scenario, tmp_path, algorithm=algorithm, stop_time=1.0)
    assert ticks and ticks[-1] == len(two.splitlines()) - 2  # a tick per step (rows - header - t0)
    assert one == two


def test_both_editions_give_the_same_csv_over_the_paper_s_20_s(editions, tmp_path):
    one = _csv(editions[0], "observer", tmp_path)
    two = _csv(editions[1], "observer", tmp_path)
    assert len(one.splitlines()) == 8002
    assert one == two


def _broken(ssp2: Path, out: Path, old: bytes, new: bytes, member: str = SSD) -> Path:
    with zipfile.ZipFile(ssp2) as zin, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == member:
                assert old in data, old
                data = data.replace(old, new, 1)
            z.writestr(info.filename, data)
    return out


CLOCK_TO_TAU = (
    b'startElement="controller" startConnector="sample_clock" endConnector="sample_clock"',
    b'startElement="controller" startConnector="sample_clock" endElement="plant"'
    b' endConnector="tau1"',
)
BROKEN = {
    "wrong version": (
        b'version="2.0"',
        b'version="3.0"',
        r"SystemStructure\.ssd: SystemStructureDescription version '3\.0' is not supported",
    ),
    "unknown connector type": (
        b'<ssc:Float64 unit="N.m" />',
        b"<ssc:Float128 />",
        r"malformed SSD in \S+: SystemStructure\.ssd \(line \d+\): Element 'ssc:Float128'",
    ),
    "clock connection to a non-clock": (
        *CLOCK_TO_TAU,
        r"connection controller\.sample_clock -> plant\.tau1: a Clock connector can only be"
        r" connected to a Clock connector \(got Clock -> Float64\)",
    ),
    "clock connection to a system non-clock": (
        b'<ssc:Clock intervalVariability="fixed" priority="0" />',
        b'<ssc:Float64 unit="s" />',
        r"connection controller\.sample_clock -> system\.sample_clock: a Clock connector can"
        r" only be connected to a Clock connector \(got Clock -> Float64\)",
    ),
    "association to no clock": (
        b'<ssd:Clock name="sample_clock" />',
        b'<ssd:Clock name="no_clock" />',
        r"component 'controller': connector '\w+' is associated to clock 'no_clock'",
    ),
    "checksum mismatch": (
        b'checksum="',
        b'checksum="00',
        r"component 'plant': PumaPlant\.fmu does not match the checksum of its MetaData",
    ),
}


@pytest.mark.parametrize("case", list(BROKEN))
def test_a_broken_2_0_ssd_is_one_error_naming_the_file_and_the_element(editions, tmp_path, case):
    old, new, message = BROKEN[case]
    path = _broken(editions[1], tmp_path / "broken.ssp", old, new)
    with pytest.raises(SspError, match=message) as err:
        read_ssp(path)
    assert "broken.ssp" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("case", ["wrong version", "clock connection to a non-clock"])
def test_the_cli_exits_2_with_one_line_on_a_broken_2_0_ssd(editions, tmp_path, case):
    old, new, message = BROKEN[case]
    path = _broken(editions[1], tmp_path / "broken.ssp", old, new)
    args = ["run", "--stop", "0.1", "--ssp", str(path), "--no-report", "--out", str(tmp_path / "r")]
    done = subprocess.run([sys.executable, "-m", "impedance_cosim.cli", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert "Traceback" not in done.stderr and len(lines) == 1, done.stderr
    assert "broken.ssp" in lines[0]
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (b'implementation="CoSimulation"', b'implementation="ModelExchange"',
         "component plant: implementation ModelExchange: this master runs PumaPlant.fmu as"
         " CoSimulation"),
        (b'implementation="ScheduledExecution"', b'implementation="CoSimulation"',
         "component controller: implementation CoSimulation is not in"
         " ImpedanceControllerClocked.fmu"),
    ],
)  # fmt: skip
def test_an_implementation_the_master_cannot_honour_is_refused(editions, tmp_path, old, new,
                                                               message):  # fmt: skip
    """SSP 2.0's implementation attribute: the FMU must have it and our master must use it."""
    from impedance_cosim.cosim.master.setup import MasterError

    ssp = editions[1]
    for name in [SSD, *(ssd_name(s) for s in SCENARIOS if ssd_name(s) != SSD)]:
        ssp = _broken(ssp, tmp_path / f"{len(name)}-{name}.ssp", old, new, name)
    with read_ssp(ssp) as system, pytest.raises(MasterError, match=message):
        Master(system, RunOptions(stop_time=0.1))


@pytest.mark.parametrize("schema", ["with schema", "without schema"])
@pytest.mark.slow
def test_fuzz_mutated_2_0_archives_end_in_a_description_or_an_ssp_error(
    editions, tmp_path, monkeypatch, schema
):
    """400 mutants of the 2.0 archive (test_ssp_reader's mutations, another seed): each gives a
    SystemDescription or a one-line SspError; without the schema the 2.0 checks stand alone."""
    from test_ssp_reader import _AnythingGoes, mutant_outcomes

    from impedance_cosim.cosim.ssp import ssp1 as ssd
    from impedance_cosim.cosim.ssp import ssp2 as ssd2

    if schema == "without schema":
        monkeypatch.setattr(ssd, "_schema", lambda name: _AnythingGoes())
        monkeypatch.setattr(ssd2, "schema", lambda name: _AnythingGoes())
    outcomes = mutant_outcomes(editions[1], 20261202, tmp_path)
    assert outcomes["ok"] >= 3 and outcomes["SspError"] > 100, outcomes


def test_a_clock_connector_of_another_interval_variability_than_the_fmus_is_refused(
    editions, tmp_path
):
    """A Clock connector (every end of its connections alike) that says `tunable` where the
    FMU's clock is `fixed`: the master names the connector and both values."""
    from impedance_cosim.cosim.master.setup import MasterError

    out = tmp_path / "tunable.ssp"
    fixed, tunable = b'intervalVariability="fixed"', b'intervalVariability="tunable"'
    with zipfile.ZipFile(editions[1]) as zin, zipfile.ZipFile(out, "w") as z:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename.endswith(".ssd"):
                assert fixed in data
                data = data.replace(fixed, tunable)
            z.writestr(info.filename, data)
    with read_ssp(out) as system, pytest.raises(MasterError) as err:
        Master(system, RunOptions(stop_time=0.1))
    assert "controller.sample_clock: intervalVariability fixed in the FMU, tunable in the SSD" in (
        str(err.value)
    )
