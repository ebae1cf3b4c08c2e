"""What every alternative plant FMU (MujocoPlant, PinocchioPlant: PumaPlant's interface on another
physics library, for `swap --replace plant=...`) must do alike: name its missing package in one
line (alone and in a swap), run alone as PumaPlant's reference, restore its state bit for bit."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from fmpy_cli import fmpy_cli
from fmu_steps import output_names, rows_after

from impedance_cosim.cosim.results.result import read_csv

CLI = [sys.executable, "-m", "impedance_cosim.cli"]
# FMU, the module its library imports, its pip requirement, reference tolerance (MuJoCo's RK4
# against our Dormand-Prince; Pinocchio: the same integrator, dynamics equal to rounding)
PLANTS = {
    "MujocoPlant": ("mujoco", "mujoco==4.0.0", 1e-7),
    "PinocchioPlant": ("pinocchio", "pin==4.1.0", 1e-9),
}
pytestmark = pytest.mark.parametrize("plant", list(PLANTS))

CHILD = """
import sys
sys.modules[sys.argv[2]] = None  # as if the package were not installed
from fmpy import simulate_fmu
try:
    simulate_fmu(sys.argv[1], stop_time=0.01)
except Exception as exc:
    print("failed:", type(exc).__name__)
    sys.exit(1)
"""


def test_without_its_package_the_fmu_says_so(fmu_dir: Path, plant: str):
    module, requirement, _ = PLANTS[plant]
    done = subprocess.run([sys.executable, "-c", CHILD, str(fmu_dir / f"{plant}.fmu"), module],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 1, (done.stdout, done.stderr)
    lines = [line for line in done.stderr.splitlines() if f"{plant} needs" in line]
    assert len(lines) == 1 and f"pip install {requirement}" in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def test_swap_without_its_package_fails_in_one_line(fmu_dir, ssp_path, tmp_path, plant: str):
    """The swap where the package cannot be imported: exit status 1, one error line naming it."""
    module, requirement, _ = PLANTS[plant]
    hidden = tmp_path / "hidden" / module
    hidden.mkdir(parents=True)
    (hidden / "__init__.py").write_text(f'raise ImportError("No module named {module} (hidden)")')
    env = {**os.environ, "PYTHONPATH": str(hidden.parent)}
    argv = [*CLI, "swap", "--ssp", str(ssp_path), "--replace", f"plant={fmu_dir}/{plant}.fmu",
            "--stop", "0.1", "--out", str(tmp_path / "out"), "--no-figures", "--no-report",
            "--no-progress"]  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 1, done.stderr
    errors = [line for line in done.stderr.splitlines() if "error:" in line]
    assert errors[-1].startswith("impedance-cosim swap: error: ") and "Traceback" not in done.stderr
    assert f"{plant} needs the Python package {requirement.split('==')[0]}" in errors[-1]


@pytest.mark.slow
def test_default_experiment_matches_pumaplants_reference(fmu_dir, tmp_path, plant: str):
    """`fmpy simulate` on its own (the 20 s default experiment: the arm falls, swings, hangs):
    PumaPlant's reference result (PumaPlant_ref.csv)."""
    from impedance_cosim.packaging.regression import REFERENCES, compare
    from impedance_cosim.packaging.regression import read_csv as read_reference

    out = tmp_path / "out.csv"
    fmpy_cli(["simulate", str(fmu_dir / f"{plant}.fmu"), "--output-interval", "0.0025",
              "--output-file", str(out)], check=True, timeout=300)  # fmt: skip
    rows = read_csv(out)
    ref = read_reference(next(p for p in REFERENCES if p.name == "PumaPlant_ref.csv"))
    assert len(rows["time"]) == 8001
    assert compare({k: v[::40] for k, v in rows.items()}, ref, rtol=PLANTS[plant][2]) == []


def test_state_restore_in_contact_is_bit_identical(fmu_dir: Path, plant: str):
    """Pushed into the wall (noisy encoders): step, save, step, restore, step again, also into a
    second instance through serialization: identical outputs."""
    from impedance_cosim.cosim.fmus.fmi2 import FmuInstance

    def started(name):
        fmu = FmuInstance(fmu_dir / f"{plant}.fmu", name)
        fmu.setup(0.0)
        fmu.set({"x0": 0.649, "q_noise": 1e-4})
        fmu.enter_initialization()
        fmu.exit_initialization()
        fmu.set({"tau1": 30.0, "tau2": 20.0, "tau3": 1.0})
        return fmu

    fmu = started("a")
    outputs = output_names(fmu)
    for i in range(40):
        fmu.step(i / 400, 1 / 400)
    state = fmu.get_state()
    blob = fmu.serialize_state(state)
    first = rows_after(fmu, outputs)
    assert max(r[outputs.index("contact_force")] for r in first) > 1.0  # in contact
    fmu.set_state(state)
    assert rows_after(fmu, outputs) == first
    other = started("b")
    other.set_state(other.deserialize_state(blob))
    assert rows_after(other, outputs) == first
    fmu.free_state(state)
    for f in (fmu, other):
        f.terminate()
        f.free()
