"""What the native plant's exact Jacobian (fmi2GetDirectionalDerivative, Model Exchange) does to an
implicit solver's cost, against the solver's own finite differences (not a test: prints a table).

The ME plant is stepped through fmpy (FMU2Model: fmi2SetContinuousStates, fmi2GetDerivatives) by
scipy's BDF and Radau, pressed into a stiff wall (wall_k large, starting in contact, the torques
held, the contact kept all along: checked). For each solver: jac = the FMU's directional
derivatives (one call per state) or none (scipy's finite differences, which cost right-hand-side
evaluations); steps, right-hand-side evaluations (ours, counted), Jacobian evaluations, LU
decompositions, wall time (best of --repeat) and the end state's difference to a tight reference.

fmpy's own CVode (fmpy.sundials.CVodeSolver, 0.3.32) cannot use the Jacobian: it creates a dense
linear solver (SUNLinSol_Dense) and never calls CVodeSetJacFn (its ctypes bindings have that
function only as a comment), so CVODE always forms its difference-quotient Jacobian. The last two
rows run fmpy's CVodeSolver on the same problem as it is, and with CVodeSetJacFn bound here (from
fmpy's bundled SUNDIALS 7 library) to hand CVODE the FMU's Jacobian.

    python benchmarks/jacobian.py                    # wall_k 1e7, wall_d 2e4, 0.5 s, best of 5
    python benchmarks/jacobian.py --wall-d 0 --stop 1   # undamped: the tool bounces off
"""

from __future__ import annotations

import argparse
import ctypes
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model
from scipy.integrate import solve_ivp

from impedance_cosim.physics.arm import Arm

REPO = Path(__file__).resolve().parent.parent
STATES = ("q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3")
X0 = 0.6500001  # m: the tool starts 0.1 um inside the wall at x = 0.65 m (so in contact)
PUSH = (50.0, 15.0)  # N: the torques held press the tool into the wall (x) and slide it along (y)


def torques() -> tuple[float, float, float]:
    """g(q0) + J(q0)^T (PUSH, 0) at the start pose, from the Python arm (default parameters)."""
    arm = Arm()
    q = arm.inverse_kinematics((X0, 0.0, 0.0))
    j, g = arm.jacobian(q), arm.gravity(q)
    return tuple(g[i] + j[0][i] * PUSH[0] + j[1][i] * PUSH[1] for i in range(3))


TAU = torques()


class Plant:
    """The ME plant as f(t, x) and its Jacobian df/dx, counting evaluations."""

    def __init__(self, fmu: Path, **params: float) -> None:
        md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        ident = md.modelExchange.modelIdentifier
        self.f = FMU2Model(guid=md.guid, unzipDirectory=extract(str(fmu)),
                           modelIdentifier=ident, instanceName="j")  # fmt: skip
        self.f.instantiate()
        self.f.setupExperiment(startTime=0.0)
        self.f.enterInitializationMode()
        for k, v in params.items():
            self.f.setReal([self.vr[k]], [v])
        self.f.setReal([self.vr[n] for n in ("tau1", "tau2", "tau3")], list(TAU))
        self.f.exitInitializationMode()
        while self.f.newDiscreteStates()[0]:
            pass
        self.f.enterContinuousTimeMode()
        self.x_buf = (ctypes.c_double * 6)()
        self.dx_buf = (ctypes.c_double * 6)()
        self.f.fmi2GetContinuousStates(self.f.component, self.x_buf, 6)
        self.x0 = np.array(self.x_buf)
        self.ders = (ctypes.c_uint * 6)(*(self.vr[f"der({s})"] for s in STATES))
        self.nfev = self.njev = 0

    def _set(self, t: float, x: np.ndarray) -> None:
        self.f.fmi2SetTime(self.f.component, t)
        self.x_buf[:] = x
        self.f.fmi2SetContinuousStates(self.f.component, self.x_buf, 6)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        self.nfev += 1
        self._set(t, x)
        self.f.fmi2GetDerivatives(self.f.component, self.dx_buf, 6)
        return np.array(self.dx_buf)

    def jac(self, t: float, x: np.ndarray) -> np.ndarray:
        self.njev += 1
        self._set(t, x)
        out = np.empty((6, 6))
        one, col = (ctypes.c_double * 1)(1.0), (ctypes.c_double * 6)()
        for k, s in enumerate(STATES):
            known = (ctypes.c_uint * 1)(self.vr[s])
            self.f.fmi2GetDirectionalDerivative(self.f.component, self.ders, 6, known, 1, one, col)
            out[:, k] = col
        return out

    def indicator(self) -> float:
        z = (ctypes.c_double * 1)()
        self.f.fmi2GetEventIndicators(self.f.component, z, 1)
        return z[0]


def run(fmu: Path, method: str, exact: bool, stop: float, params: dict, tol: tuple) -> dict:
    plant = Plant(fmu, **params)
    start = time.perf_counter()
    sol = solve_ivp(plant.rhs, (0.0, stop), plant.x0, method=method, rtol=tol[0], atol=tol[1],
                    jac=plant.jac if exact else None)  # fmt: skip
    wall = time.perf_counter() - start
    kept = True
    for t, x in zip(sol.t, sol.y.T, strict=True):  # still pressing at every step (g = -force)
        plant._set(t, x)
        kept &= plant.indicator() < 0.0
    return {"sol": sol, "wall": wall, "nfev": plant.nfev, "njev": plant.njev, "kept": kept}


def run_cvode(fmu: Path, exact: bool, stop: float, params: dict, rtol: float) -> dict:
    """The same problem under fmpy's CVodeSolver (CVODE BDF, dense linear solver, abstol = rtol
    for these unit nominals); exact: our own CVodeSetJacFn binding hands CVODE the FMU's
    Jacobian, which fmpy never does."""
    from ctypes import CFUNCTYPE, POINTER, byref, c_double, c_int, c_long, c_void_p

    from fmpy.sundials import CVodeSolver
    from fmpy.sundials.libraries import sundials_cvode, sundials_sunmatrixdense
    from fmpy.sundials.nvector_serial import NV_DATA_S
    from fmpy.sundials.sundials_matrix import SUNMatrix
    from fmpy.sundials.sundials_nvector import N_Vector

    plant = Plant(fmu, **params)
    f, comp = plant.f, plant.f.component

    def get_dx(px, n):
        plant.nfev += 1
        f.fmi2GetDerivatives(comp, px, n)

    class Held:  # the torques are set once, before initialization
        def apply(self, t):
            pass

    solver = CVodeSolver(
        nx=6, nz=0, get_x=lambda px, n: f.fmi2GetContinuousStates(comp, px, n),
        set_x=lambda px, n: f.fmi2SetContinuousStates(comp, px, n), get_dx=get_dx,
        get_z=lambda pz, n: None,
        get_nominals=lambda p, n: f.fmi2GetNominalsOfContinuousStates(comp, p, n),
        set_time=lambda t: f.fmi2SetTime(comp, t), input=Held(), startTime=0.0, maxStep=stop,
        relativeTolerance=rtol, maxNumSteps=1_000_000,
    )  # fmt: skip
    data = sundials_sunmatrixdense.SUNDenseMatrix_Data
    data.argtypes, data.restype = [SUNMatrix], POINTER(c_double)
    jac_type = CFUNCTYPE(c_int, c_double, N_Vector, N_Vector, SUNMatrix, c_void_p, N_Vector,
                         N_Vector, N_Vector)  # fmt: skip

    def jac(t, y, _fy, matrix, _user, _t1, _t2, _t3):
        m = plant.jac(t, np.ctypeslib.as_array(NV_DATA_S(y), (6,)))
        np.ctypeslib.as_array(data(matrix), (36,))[:] = m.T.ravel()  # column-major
        return 0

    if exact:
        solver.jac_ = jac_type(jac)  # kept alive with the solver
        set_jac = sundials_cvode.CVodeSetJacFn
        set_jac.argtypes, set_jac.restype = [c_void_p, jac_type], c_int
        if set_jac(solver.cvode_mem, solver.jac_) != 0:
            raise SystemExit("jacobian.py: CVodeSetJacFn failed")
    start = time.perf_counter()
    solver.step(0.0, stop)
    wall = time.perf_counter() - start
    stats = {}
    for name in ("CVodeGetNumSteps", "CVodeGetNumJacEvals", "CVodeGetNumLinSolvSetups"):
        fn, value = getattr(sundials_cvode, name), c_long()
        fn.argtypes, fn.restype = [c_void_p, POINTER(c_long)], c_int
        fn(solver.cvode_mem, byref(value))
        stats[name] = value.value
    x = (c_double * 6)()
    f.fmi2GetContinuousStates(comp, x, 6)
    return {"x": np.array(x), "wall": wall, "nfev": plant.nfev,
            "steps": stats["CVodeGetNumSteps"], "njev": stats["CVodeGetNumJacEvals"],
            "setups": stats["CVodeGetNumLinSolvSetups"]}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu", type=Path, default=REPO / "fmus" / "native" / "PumaPlant.fmu")
    parser.add_argument("--wall-k", type=float, default=1e7, help="wall stiffness, N/m")
    parser.add_argument("--wall-d", type=float, default=2e4, help="wall damping, N s/m")
    parser.add_argument("--stop", type=float, default=0.5, help="simulated time, s")
    parser.add_argument("--repeat", type=int, default=5, help="best of this many (wall time)")
    args = parser.parse_args()
    if not args.fmu.is_file():
        raise SystemExit(f"jacobian.py: {args.fmu} is missing: run `impedance-cosim build` first")
    params = {"wall_k": args.wall_k, "wall_d": args.wall_d, "x0": X0}
    ref = run(args.fmu, "Radau", True, args.stop, params, (1e-11, 1e-13))["sol"].y[:, -1]
    print(
        f"ME plant pressed into the wall: wall_k = {args.wall_k:g} N/m, wall_d ="
        f" {args.wall_d:g} N s/m, {args.stop:g} s,"
        f" torques ({', '.join(f'{t:.2f}' for t in TAU)}) N m held, rtol 1e-6, atol 1e-8"
        " (fmpy FMU2Model, scipy solve_ivp)"
    )
    print(
        f"{'solver':8} {'Jacobian':22} {'steps':>6} {'RHS evals':>10} {'Jac evals':>10}"
        f" {'LU':>5} {'wall s':>8} {'|x - ref|':>10}  contact kept"
    )
    for method in ("BDF", "Radau"):
        for exact in (True, False):
            runs = [run(args.fmu, method, exact, args.stop, params, (1e-6, 1e-8))
                    for _ in range(args.repeat)]  # fmt: skip
            r = runs[0]
            sol = r["sol"]
            label = "exact (FMU)" if exact else "finite differences"
            err = float(np.abs(sol.y[:, -1] - ref).max())
            print(
                f"{method:8} {label:22} {len(sol.t) - 1:6d} {r['nfev']:10d} {sol.njev:10d}"
                f" {sol.nlu:5d} {min(x['wall'] for x in runs):8.3f} {err:10.2e}  {r['kept']}"
            )
    for exact in (True, False):  # LU column: CVODE's linear-solver setups
        runs = [run_cvode(args.fmu, exact, args.stop, params, 1e-6) for _ in range(args.repeat)]
        r = runs[0]
        label = "exact (our binding)" if exact else "difference quotients"
        err = float(np.abs(r["x"] - ref).max())
        print(
            f"{'CVODE':8} {label:22} {r['steps']:6d} {r['nfev']:10d} {r['njev']:10d}"
            f" {r['setups']:5d} {min(x['wall'] for x in runs):8.3f} {err:10.2e}"
        )


if __name__ == "__main__":
    main()
