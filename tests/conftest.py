"""Shared fixtures: FMUs built once per test session, and a contact scenario for the plant."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from impedance_cosim.packaging.build import FMUS, NATIVE, build_fmu, build_native_fmu, build_ssp
from impedance_cosim.physics.linalg3 import matvec
from plant_model.model import PlantModel

DT = 1 / 400


REPO = Path(__file__).resolve().parents[1]


def pytest_configure(config: pytest.Config) -> None:
    """Compile each platform's FMU libraries once per set of sources, for every fixture, test
    and `impedance-cosim build` subprocess of this run and later ones (packaging/build_cache.py;
    keyed by the sources' and the compiler's hash, so an edit is always recompiled). A cache
    folder given in the environment is kept; IMPCOSIM_BUILD_CACHE= (empty) turns it off."""
    os.environ.setdefault("IMPCOSIM_BUILD_CACHE", str(REPO / ".cache" / "build"))


CROSS_PLATFORMS = {"win64", "aarch64-linux"}  # built by cross compilers, run under wine/qemu


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test parametrized over a cross platform needs its tools: mark it `tools` (the others
    that need them carry the mark themselves)."""
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        if params.get("platform") in CROSS_PLATFORMS:
            item.add_marker(pytest.mark.tools)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    session.config._impcosim_status = int(exitstatus)  # for pytest_unconfigure


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """Tests load Python FMUs into this process: once pytest has said everything, leave as our
    command does (fmu.exit_process), or pythonfmu 0.7's library destructor corrupts the heap at
    exit (glibc aborts: exit -6 after the last test passed, in some runs)."""
    from impedance_cosim.cosim.fmus.fmi2 import exit_process, fmu_library_loaded

    status = getattr(config, "_impcosim_status", None)
    if status is not None and fmu_library_loaded():
        exit_process(status)


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """All FMUs, freshly built from this checkout."""
    out = tmp_path_factory.mktemp("fmus")
    for spec in FMUS.values():
        build_fmu(spec, out)
    build_ssp(out)
    return out


@pytest.fixture(scope="session")
def ssp_path(fmu_dir: Path) -> Path:
    """The paper's system archive, built from this checkout."""
    return fmu_dir / "PaperScenario.ssp"


@pytest.fixture(scope="session")
def native_dir(fmu_dir: Path) -> Path:
    """The native FMUs (compiled with the machine's C compiler) and their system archive."""
    out = fmu_dir / "native"
    for spec in FMUS.values():
        if (NATIVE / spec.key / "model.c").is_file():  # models with a native flavour
            build_native_fmu(spec, out)
    build_ssp(fmu_dir, "PaperScenario-native", out)
    return out


@pytest.fixture(scope="session")
def native_ssp(native_dir: Path) -> Path:
    """The paper's system archive with the native FMUs, built from this checkout."""
    return native_dir.parent / "PaperScenario-native.ssp"


def benchmark_module(name: str):
    """benchmarks/<name>.py loaded as a module: tests that use what a benchmark script computes
    (its reference solution, its host loop) import it so, the script staying runnable alone."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(REPO / "benchmarks"))  # its own imports of its neighbours
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(REPO / "benchmarks"))
    return module


def output_dict(model) -> dict[str, float]:
    """A model's outputs by name."""
    names = [v.name for v in model.variables() if v.causality == "output"]
    return dict(zip(names, model.outputs(), strict=True))


def contact_torques(seconds: float, parameters: dict | None = None) -> list[tuple]:
    """Torques at 400 Hz of a computed-torque joint controller driving the arm into the wall
    (target 5 cm inside) and out again, switching every 1.5 s: contact closes and opens."""
    plant = PlantModel(parameters or {}, 0.0, None)
    arm = plant.arm
    targets = [arm.inverse_kinematics(p) for p in [(0.70, 0.0, 0.0), (0.55, 0.1, 0.0)]]
    torques = []
    for i in range(round(seconds / DT)):
        qt = targets[int(i * DT / 1.5) % 2]
        acc = tuple(100.0 * (qt[j] - plant.q[j]) - 20.0 * plant.qd[j] for j in range(3))
        ha = matvec(arm.inertia(plant.q), acc)
        grav = arm.gravity(plant.q)
        tau = (grav[0] + ha[0], grav[1] + ha[1], grav[2] + ha[2])
        torques.append(tau)
        plant.do_step(i * DT, DT, tau)
    return torques


def run_bridge_in_child(ssp_path: Path, bridge: Path, port: int, token: str) -> list[str]:
    """A 1 s run of SSP_PATH, its plant the bridge FMU BRIDGE on the robot at 127.0.0.1:PORT with
    TOKEN (0.3 s to initialize), in a child process: an error during initialization reaches the
    master as fmi2Fatal, after which pythonfmu 0.7 has corrupted the interpreter (a later garbage
    collection crashes it; see docs/limitations.md). The run's ok, rows and error, as printed."""
    code = (
        "from impedance_cosim.cosim.master.master import Master\n"
        "from impedance_cosim.cosim.master.options import RunOptions\n"
        "from impedance_cosim.cosim.ssp.read import read_ssp\n"
        f"r = Master(read_ssp({str(ssp_path)!r}), RunOptions(stop_time=1.0, fmu_files={{'plant': "
        f"{str(bridge)!r}}}, overrides={{'plant.robot_port': {port}, "
        f"'plant.robot_token': {token!r}, 'plant.init_timeout_s': 0.3}})).run()\n"
        "print(r.ok, len(r.data), r.error, flush=True)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)  # fmt: skip
    return done.stdout.split(" ", 2)


@pytest.fixture(scope="session")
def fmi3_dir(fmu_dir: Path, native_dir: Path) -> Path:
    """The FMI 3.0 native FMUs (fmus/fmi3/) and PaperScenario-fmi3.ssp next to the others."""
    from impedance_cosim.packaging.build_fmi3 import build_fmi3

    build_fmi3(fmu_dir)
    return fmu_dir / "fmi3"


@pytest.fixture
def robot(request: pytest.FixtureRequest, tmp_path: Path):
    """start(*extra, realtime=False, timeout=20.0) -> port: `impedance-cosim robot` on a free
    loopback port with the test module's TOKEN, its stderr in start.log (start.proc: the process);
    every robot started is stopped afterwards."""
    from impedance_cosim.apps.robot_process import start_robot, stop_robot

    procs = []

    def start(*extra: str, realtime: bool = False, timeout: float = 20.0) -> int:
        start.log = tmp_path / f"robot{len(procs)}.log"
        with open(start.log, "w") as err:
            proc, port = start_robot(request.module.TOKEN, realtime, list(extra),
                                     timeout=timeout, stderr=err)  # fmt: skip
        procs.append(proc)
        start.proc = proc
        return port

    yield start
    for proc in procs:
        stop_robot(proc)
