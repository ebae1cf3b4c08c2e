"""The closed loop linearised as a discrete-time map per sample, from the system's own models.

The state at a sample instant t_k (before the controller samples) is
x = (q, qd) of the plant and (yhat, q_prev, tau_prev, f_prev) of the controller: 18 numbers.
Under Jacobi the torque the plant receives over [t_k, t_k+1] is tau_prev (one sample late);
under Gauss-Seidel it is the one computed at t_k, so the same 18 numbers are a complete state
for both timings. One sample of the loop (impedance_cosim.cosim.master.plain_loop.loop_step on the
plain Python PlantModel and ControllerModel, ideal encoders) maps x_k to x_k+1; its Jacobian, by
central differences, is the linearised sampled-data loop at that operating point. Its spectral
radius above 1 means the loop is locally unstable there.

Algorithm "jacobi-linear": Jacobi with the master's input extrapolation
(cosim/master/extrapolation.py): the controller samples y(t_k) + h dy/dt(t_k), the plant's output
derivatives taken with the torque it held over the last sample (as the native plant reports them),
so that torque joins the state (21 numbers); dy/dt by a central difference of the outputs along the
plant's own state derivative.

The trajectory is time-varying (the virtual ellipse moves): the Jacobian at a point is the frozen
map of that sample, and the points used are one in free motion and one in settled contact.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from controller_model.model import ControllerModel
from impedance_cosim.cosim.master.plain_loop import loop_step, run_models, wiring
from plant_model.model import PlantModel

# Where the loop is linearised: a point in free motion and one in settled contact (s; the paper
# scenario touches the wall from 3.85 s, and the force has settled by 5.5 s).
POINTS = {"free": 1.0, "contact": 5.5}
WARMUP = 4  # samples of the loop at the analysed rate before the linearisation point
PLANT_TOL = {"rtol": 1e-12, "atol": 1e-14}  # tight, so differences are not integrator noise
H_GUESS = 1e-4  # s, the plant integrator's first step guess for every evaluation of the map
RATE_EPS = 1e-7  # s, the central difference of the outputs along the state derivative


def jacobian(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, rel: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian of f at x (step rel * max(1, |x_j|) per component)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for j in range(len(x)):
        d = rel * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += d
        xm[j] -= d
        cols.append((f(xp) - f(xm)) / (2 * d))
    return np.column_stack(cols)


def spectral_radius(a: np.ndarray) -> float:
    """max |eigenvalue|."""
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def dominant(a: np.ndarray) -> tuple[float, float | None]:
    """|lambda| of the dominant eigenvalue and its period in samples (2 pi / |arg lambda|; None
    for a real eigenvalue)."""
    lam = np.linalg.eigvals(a)
    z = lam[np.argmax(np.abs(lam))]
    angle = abs(math.atan2(z.imag, z.real))
    return float(abs(z)), (2 * math.pi / angle if angle > 1e-9 else None)


def output_rates(plant: PlantModel, tau: Sequence[float]) -> np.ndarray:
    """d/dt of the plant's outputs (ideal sensors) at its state, torque tau held, contact mode
    fixed: what fmi2GetRealOutputDerivatives of the native plant gives."""
    saved = plant.q, plant.qd, plant.q_meas
    x = np.array([*plant.q, *plant.qd])
    f = np.array(plant._rhs(tuple(tau), plant.in_contact)(tuple(x)))

    def at(s: float) -> np.ndarray:
        y = x + s * f
        plant.q, plant.qd = tuple(y[:3]), tuple(y[3:])
        plant.q_meas = plant.q
        return np.array(plant.outputs())

    rates = (at(RATE_EPS) - at(-RATE_EPS)) / (2 * RATE_EPS)
    plant.q, plant.qd, plant.q_meas = saved
    return rates


def step(plant: PlantModel, controller: ControllerModel, t: float, h: float, algorithm: str,
         p_out: tuple) -> tuple:  # fmt: skip
    """loop_step, and for "jacobi-linear" the extrapolated Jacobi step (module docstring); the
    plant keeps the torque it held as `tau_held`."""
    if algorithm != "jacobi-linear":
        return loop_step(plant, controller, t, h, algorithm, p_out)
    feed, tau_idx = wiring()
    held = controller.outputs()
    rates = output_rates(plant, plant.tau_held)
    controller.do_step(t, h, tuple(p_out[j] + h * rates[j] for j in feed))
    plant.tau_held = tuple(held[j] for j in tau_idx)
    plant.do_step(t, h, plant.tau_held)
    return plant.outputs()


class LoopMap:
    """x_k -> x_k+1 of the closed loop at the controller's next sample k (module docstring)."""

    def __init__(self, plant: PlantModel, controller: ControllerModel, algorithm: str):
        self.plant, self.controller, self.algorithm = plant, controller, algorithm
        self.k = controller.k_next
        self.h = controller.ctrl.sample_period
        self.mode = plant.in_contact

    def state(self) -> np.ndarray:
        p, c = self.plant, self.controller
        held = p.tau_held if self.algorithm == "jacobi-linear" else ()
        return np.array([*p.q, *p.qd, *c.yhat, *c.q_prev, *c.tau_prev, *c.f_prev, *held])

    def load(self, x: Sequence[float]) -> None:
        """Put the models in state x at sample k (contact mode and integrator guess fixed)."""
        p, c = self.plant, self.controller
        t = c.start_time + self.k * self.h
        p.t, p.q, p.qd = t, tuple(x[0:3]), tuple(x[3:6])
        p.q_meas, p.in_contact, p.h = p.q, self.mode, H_GUESS
        c.t, c.k_next = t, self.k
        c.yhat, c.q_prev = tuple(x[6:9]), tuple(x[9:12])
        c.tau_prev, c.f_prev = tuple(x[12:15]), tuple(x[15:18])
        c.out = (*x[12:15], *c.out[3:])  # the held torque is the latest sample's
        p.tau_held = tuple(x[18:21]) if self.algorithm == "jacobi-linear" else None

    def __call__(self, x: Sequence[float]) -> np.ndarray:
        self.load(x)
        t = self.controller.start_time + self.k * self.h
        step(self.plant, self.controller, t, self.h, self.algorithm, self.plant.outputs())
        return self.state()


def operating_point(
    t_point: float,
    rate: float,
    algorithm: str,
    plant_parameters: dict[str, Any],
    controller_parameters: dict[str, Any],
    reference: dict[str, np.ndarray],
) -> LoopMap:
    """The loop at rate, WARMUP samples after starting from the reference run's plant state
    (a stable 2 kHz run) with a converged observer (yhat0 = the true velocity); returns the map
    at the sample nearest t_point (the controller's samples count from its start, t0)."""
    h = 1.0 / rate
    k_point = round(t_point * rate)
    t0 = (k_point - WARMUP) * h
    i = int(np.argmin(np.abs(reference["time"] - t0)))
    q = tuple(float(reference[f"plant.q{j}_true"][i]) for j in (1, 2, 3))
    qd = tuple(float(reference[f"plant.qd{j}"][i]) for j in (1, 2, 3))
    plant = PlantModel({**plant_parameters, **PLANT_TOL}, t0, None)
    plant.q, plant.qd, plant.q_meas = q, qd, q
    plant.in_contact = bool(reference["plant.contact_force"][i] > 0.0)
    p_out = plant.outputs()
    feed, _ = wiring()
    yhat0 = {f"yhat0_{j + 1}": qd[j] for j in range(3)}
    params = {**controller_parameters, **yhat0, "sample_period": h}
    controller = ControllerModel(params, t0, tuple(p_out[j] for j in feed))
    plant.tau_held = tuple(controller.outputs()[j] for j in wiring()[1])
    for k in range(WARMUP):
        p_out = step(plant, controller, t0 + k * h, h, algorithm, p_out)
    return LoopMap(plant, controller, algorithm)


def reference_run(plant_parameters: dict[str, Any], controller_parameters: dict[str, Any],
                  stop: float = 6.0) -> dict[str, np.ndarray]:  # fmt: skip
    """The operating trajectory: the loop at 2 kHz, sample-and-hold (stable for every case)."""
    return run_models(plant_parameters, {**controller_parameters, "sample_period": 5e-4},
                      stop_time=stop, step=5e-4)  # fmt: skip


def loop_radius(
    rate: float,
    algorithm: str,
    velocity: str,
    point: str | float = "contact",
    plant_parameters: dict[str, Any] | None = None,
    controller_parameters: dict[str, Any] | None = None,
    reference: dict[str, np.ndarray] | None = None,
) -> tuple[float, float | None]:
    """Dominant |lambda| and its period (samples) of the loop linearised at a point (a name of
    POINTS or a time in s)."""
    pp = plant_parameters or {}
    cp = {**(controller_parameters or {}), "velocity_source": velocity}
    ref = reference if reference is not None else reference_run(pp, {})
    t_point = POINTS[point] if isinstance(point, str) else point
    m = operating_point(t_point, rate, algorithm, pp, cp, ref)
    return dominant(jacobian(m, m.state()))


def critical_rate(
    radius: Callable[[float], float], lo: float = 100.0, hi: float = 1000.0, tol: float = 0.5
) -> float | None:
    """The rate where radius(rate) crosses 1 (unstable at lo, stable at hi), by bisection to
    tol Hz; None when both ends are on the same side."""
    r_lo, r_hi = radius(lo), radius(hi)
    if (r_lo > 1.0) == (r_hi > 1.0):
        return None
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if (radius(mid) > 1.0) == (r_lo > 1.0):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
