"""The plant: the PUMA-subset arm touching the wall, with its joint and wrist sensors.

Plain numeric code behind the PumaPlant FMU. State: joint angles and velocities, the contact
mode, the integrator's step-size guess and the sensor-noise generator. Each do_step integrates
eq. (1) with the torque held constant, using adaptive Dormand-Prince 5(4) and stopping exactly
where the contact closes or opens, so the result does not depend on the communication step.
(euler_substeps = n > 0 instead takes n explicit Euler steps per communication step: a
reproduction aid for the paper's Fig. 4, docs/stability.md, never a default.)
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from impedance_cosim.fmi.model import (
    FmuModel,
    ModelError,
    build_params,
    check_finite_outputs,
    check_step,
)
from impedance_cosim.fmi.variables import (
    ModelExchange,
    Partials,
    Variable,
    parameters_of,
    vector,
)
from impedance_cosim.physics.arm import Arm, ArmParams, UnreachablePoseError, _p, check_fields
from impedance_cosim.physics.ode import IntegrationError, euler_step, integrate
from impedance_cosim.physics.wall import WallParams, contact_event, contact_force_law, wall_force


def end_effector_x(p: ArmParams) -> Callable[..., tuple[float, float]]:
    """ee_x(q1, q2, q3, qd1, qd2, qd3) -> the end effector's x and x-velocity (all the wall
    needs), bound to the link lengths of p (it runs at every right-hand side and event check)."""
    a1, a2, a3 = p.a1, p.a2, p.a3

    def ee_x(q1: float, q2: float, q3: float, qd1: float, qd2: float, qd3: float):
        q12 = q1 + q2
        q123 = q12 + q3
        s1, s12, s123 = a1 * math.sin(q1), a2 * math.sin(q12), a3 * math.sin(q123)
        x = a1 * math.cos(q1) + a2 * math.cos(q12) + a3 * math.cos(q123)
        return x, -(s1 + s12 + s123) * qd1 - (s12 + s123) * qd2 - s123 * qd3

    return ee_x


@dataclass(frozen=True)
class PlantSetup:
    """Initial condition, sensor model and integrator settings of the plant."""

    x0: float = _p(0.3, "m", "Initial end-effector x (arm at rest)")
    y0: float = _p(0.0, "m", "Initial end-effector y (arm at rest)")
    phi0: float = _p(0.0, "rad", "Initial end-effector orientation (arm at rest)")
    elbow_up: bool = _p(True, "", "Initial elbow: true = above the shoulder-wrist line (q2 < 0)")
    euler_substeps: int = _p(
        0,
        "",
        "Plant integrator (co-simulation): 0 = adaptive Dormand-Prince 5(4), the default; n > 0 ="
        " n explicit Euler steps per communication step, no event location (a reproduction aid"
        " for the paper's Fig. 4, not accurate)",
        0,
    )
    q_quant: float = _p(
        0.0,
        "rad",
        "Joint encoder resolution (0: none; Model Exchange: ideal encoders, 0 only)",
        0.0,
    )
    q_noise: float = _p(
        0.0,
        "rad",
        "Std. dev. of Gaussian joint-angle noise (0: none; Model Exchange: ideal encoders, 0 only)",
        0.0,
    )
    noise_seed: int = _p(1, "", "Seed of the joint-angle noise generator (reproducible runs)")
    rtol: float = _p(1e-9, "1", "Integrator relative tolerance", 1e-14)
    atol: float = _p(1e-11, "1", "Integrator absolute tolerance (rad, rad/s)", 1e-16)
    max_rhs_evaluations: int = _p(
        200_000,
        "",
        "Work bound of one communication step: most evaluations of eq. (1) (about 6 per"
        " integrator step); a step needing more is refused (fmi2Discard)",
        1,
    )

    def validate(self) -> None:
        """Raise ValueError naming a bad setting."""
        check_fields(self)
        if self.euler_substeps > MAX_EULER_SUBSTEPS:
            raise ValueError(
                f"parameter euler_substeps must be <= {MAX_EULER_SUBSTEPS}"
                f" (got {self.euler_substeps})"
            )


INPUTS = ("tau1", "tau2", "tau3")
MAX_EULER_SUBSTEPS = 1_000_000  # per communication step (euler_substeps)
H0 = 1e-3  # s, the integrator's first step guess


def _partials() -> Partials:
    """What each output and state derivative of the native plant depends on (exactly: the
    directional derivatives of native/plant/model.c; tests/test_partials.py checks the pattern)
    and how: "constant" where the partial derivative is a constant (an angle on its own state),
    "dependent" otherwise. The wrist force fy and moment n are zero: no dependency at all."""
    q, qd = ("q1_true", "q2_true", "q3_true"), ("qd1", "qd2", "qd3")

    def on(names, kind="dependent"):
        return tuple((n, kind) for n in names)

    deps = {f"q{i}": on([q[i - 1]], "constant") for i in (1, 2, 3)}
    deps.update({"fx": on(q + qd), "fy": (), "n": ()})
    deps.update({q[i]: on([q[i]], "constant") for i in range(3)})
    deps.update({qd[i]: on([qd[i]], "constant") for i in range(3)})
    deps.update({"x": on(q), "y": on(q), "phi": on(q, "constant")})
    deps.update({"xd": on(q + qd), "yd": on(q + qd), "phid": on(qd, "constant")})
    deps.update({"contact_force": on(q + qd), "penetration": on(q)})
    deps.update({f"der({q[i]})": on([qd[i]], "constant") for i in range(3)})
    deps.update({f"der({s})": on(q + qd + INPUTS) for s in qd})
    return Partials(tuple(deps.items()), max_output_derivative_order=1)


class PlantModel(FmuModel):
    """Arm + wall + sensors (see module docstring)."""

    MODEL_NAME = "PumaPlant"
    DESCRIPTION = (
        "3-DOF planar PUMA-560 subset against a stiff frictionless wall (Impedance Control"
        " Without Using Velocity Measurements, section 5): joint torques in; joint angles and"
        " wrist force/torque out, plus truth signals for analysis"
    )
    OUTPUT_DEPENDENCIES = ""  # outputs depend on the state only: no direct feedthrough
    # The native flavour also offers Model Exchange (native/src/fmi2_me.c): these continuous
    # states, their der() variables, and one event indicator (the contact's switching function).
    # The tolerance a host's solver should use (the plant's own integrator runs at rtol 1e-9).
    DEFAULT_EXPERIMENT = {**FmuModel.DEFAULT_EXPERIMENT, "tolerance": 1e-9}
    MODEL_EXCHANGE = ModelExchange(
        states=("q1_true", "q2_true", "q3_true", "qd1", "qd2", "qd3"),
        event_indicators=1,
        partials=_partials(),
    )

    @classmethod
    def variables(cls) -> list[Variable]:
        return [
            *parameters_of(ArmParams()),
            *parameters_of(WallParams()),
            *parameters_of(PlantSetup()),
            *vector(list(INPUTS), "input", "N.m", "Joint {i} motor torque"),
            *vector(["q1", "q2", "q3"], "output", "rad", "Joint {i} angle, measured (encoder)"),
            Variable("fx", "output", 0.0, "Wrist F/T sensor: force on the environment, x", "N"),
            Variable("fy", "output", 0.0, "Wrist F/T sensor: force on the environment, y", "N"),
            Variable("n", "output", 0.0, "Wrist F/T sensor: moment about the tool point", "N.m"),
            *vector(["q1_true", "q2_true", "q3_true"], "output", "rad", "Joint {i} angle, truth"),
            *vector(["qd1", "qd2", "qd3"], "output", "rad/s", "Joint {i} velocity, truth"),
            Variable("x", "output", 0.0, "End-effector x, truth", "m"),
            Variable("y", "output", 0.0, "End-effector y, truth", "m"),
            Variable("phi", "output", 0.0, "End-effector orientation, truth", "rad"),
            Variable("xd", "output", 0.0, "End-effector x velocity, truth", "m/s"),
            Variable("yd", "output", 0.0, "End-effector y velocity, truth", "m/s"),
            Variable("phid", "output", 0.0, "End-effector angular velocity, truth", "rad/s"),
            Variable("contact_force", "output", 0.0, "Normal force on the wall (>= 0)", "N"),
            Variable("penetration", "output", 0.0, "Depth of the tool point in the wall", "m"),
        ]

    def __init__(self, parameters: dict[str, Any], start_time: float = 0.0, inputs=None) -> None:
        try:
            self.arm = Arm(build_params(ArmParams, parameters))
            self._ee_x_flat = end_effector_x(self.arm.params)
            self.wall = build_params(WallParams, parameters)
            self.wall.validate()
            self.setup = build_params(PlantSetup, parameters)
            self.setup.validate()
            s = self.setup
            q = self.arm.inverse_kinematics((s.x0, s.y0, s.phi0), s.elbow_up)
        except UnreachablePoseError as exc:
            raise ModelError(f"initial pose: {exc}") from None
        except ValueError as exc:
            raise ModelError(str(exc)) from None
        except ArithmeticError as exc:  # finite but huge: the arm's terms overflow (fuzz finding)
            raise ModelError(f"the parameters are out of range: {exc}") from None
        self.t = float(start_time)
        self.q = q
        self.qd = (0.0, 0.0, 0.0)
        x, xd = self._ee_x(q, self.qd)
        self.in_contact = contact_event(self.wall, x, xd, False) > 0.0
        self.h = H0
        self.rng = random.Random(s.noise_seed)
        try:
            self.q_meas = self._measure(q)
        except (OverflowError, ValueError) as exc:
            raise ModelError(f"joint angle measurement failed: {exc}") from None

    # --- equations ----------------------------------------------------------------------------

    def _ee_x(self, q, qd) -> tuple[float, float]:
        """End-effector x and x-velocity (all the wall needs)."""
        return self._ee_x_flat(*q, *qd)

    def _count_evaluation(self, counter: list[float]) -> None:
        """One evaluation of the dynamics, counted against the communication step's budget
        (max_rhs_evaluations): IntegrationError once it is spent."""
        counter[0] -= 1
        if counter[0] < 0:
            raise IntegrationError(
                f"more than {self.setup.max_rhs_evaluations} evaluations of the dynamics in"
                " one communication step (parameter max_rhs_evaluations): take a smaller step"
            )

    def _rhs(self, tau, in_contact: bool, budget: list[int] | None = None):
        """y' = f(y) for y = (q, qd) with the torque held and the contact mode fixed, eq. (1).
        budget[0], when given, counts the evaluations left in this communication step
        (max_rhs_evaluations)."""
        terms, wall, ee_x = self.arm.terms, self.wall, self._ee_x_flat
        forward_dynamics, jacobian = terms.forward_dynamics, terms.jacobian
        tau1, tau2, tau3 = tau
        counter = budget if budget is not None else [math.inf]

        def f(y):
            self._count_evaluation(counter)
            q1, q2, q3, qd1, qd2, qd3 = y
            if in_contact:
                x, xd = ee_x(q1, q2, q3, qd1, qd2, qd3)
                fx = contact_force_law(wall, x, xd)
                j = jacobian((q1, q2, q3))[0]  # J^T (fx, 0, 0) = fx * first row of J
                qdd = forward_dynamics(
                    q1, q2, q3, qd1, qd2, qd3, tau1 - fx * j[0], tau2 - fx * j[1], tau3 - fx * j[2]
                )
            else:
                qdd = forward_dynamics(q1, q2, q3, qd1, qd2, qd3, tau1, tau2, tau3)
            return (qd1, qd2, qd3, *qdd)

        return f

    def _event(self, in_contact: bool):
        wall, ee_x = self.wall, self._ee_x_flat

        def g(y):
            x, xd = ee_x(*y)
            return contact_event(wall, x, xd, in_contact)

        return g

    def _euler_steps(
        self, tau, mode: bool, y: tuple, h: float, n: int, budget: list[int]
    ) -> tuple[tuple, bool]:
        """euler_substeps = n: n explicit Euler steps y + (h/n) f(y), each in the contact mode
        at its start; the mode switches after a step if its switching function turned positive
        (no event location: a 1990s-style shortcut). Each step is one evaluation of budget."""
        dt = h / n
        for _ in range(n):
            y = euler_step(self._rhs(tau, mode, budget), y, dt)
            if self._event(mode)(y) > 0.0:
                mode = not mode
        return y, mode

    def _measure(self, q) -> tuple[float, float, float]:
        """Joint encoders: truth + Gaussian noise, then quantized to the resolution."""
        s = self.setup
        out = []
        for qi in q:
            if s.q_noise > 0.0:
                qi += self.rng.gauss(0.0, s.q_noise)
            if s.q_quant > 0.0:
                qi = round(qi / s.q_quant) * s.q_quant
            out.append(qi)
        return (out[0], out[1], out[2])

    # --- FmuModel -------------------------------------------------------------------------------

    def do_step(self, t: float, h: float, inputs: tuple) -> None:
        check_step(t, h, self.t, "plant", INPUTS, inputs)
        t_end = t + h
        y = (*self.q, *self.qd)
        t_cur, mode, hh, switches = t, self.in_contact, self.h, 0
        budget = [self.setup.max_rhs_evaluations]
        try:
            if self.setup.euler_substeps > 0:
                n = self.setup.euler_substeps
                y, mode = self._euler_steps(inputs, mode, y, h, n, budget)
            while self.setup.euler_substeps == 0:
                t_cur, y, hh, hit = integrate(
                    self._rhs(inputs, mode, budget), t_cur, y, t_end, hh,
                    self.setup.rtol, self.setup.atol, self._event(mode),
                )  # fmt: skip
                if not hit:
                    break
                mode, switches = not mode, switches + 1
                if switches > 1000:
                    raise IntegrationError("contact chattering: more than 1000 switches in a step")
        except (IntegrationError, ZeroDivisionError, OverflowError, ValueError) as exc:
            raise ModelError(f"plant integration failed: {exc}") from None
        try:
            q_meas = self._measure(y[:3])
        except (OverflowError, ValueError) as exc:
            raise ModelError(f"joint angle measurement failed: {exc}") from None
        before = (self.t, self.q, self.qd, self.in_contact, self.h, self.q_meas)
        self.t, self.q, self.qd = t_end, y[:3], y[3:]
        self.in_contact, self.h = mode, hh
        self.q_meas = q_meas
        try:
            check_finite_outputs(type(self), self.outputs())
        except ModelError:
            self.t, self.q, self.qd, self.in_contact, self.h, self.q_meas = before
            raise

    def outputs(self) -> tuple:
        q, qd = self.q, self.qd
        pose = self.arm.kinematics(q)
        j = self.arm.jacobian(q)
        xdot = (
            j[0][0] * qd[0] + j[0][1] * qd[1] + j[0][2] * qd[2],
            j[1][0] * qd[0] + j[1][1] * qd[1] + j[1][2] * qd[2],
            j[2][0] * qd[0] + j[2][1] * qd[1] + j[2][2] * qd[2],
        )
        fx = wall_force(self.wall, pose[0], xdot[0])
        pen = max(0.0, pose[0] - self.wall.wall_x)
        return (*self.q_meas, fx, 0.0, 0.0, *q, *qd, *pose, *xdot, fx, pen)

    def get_state(self) -> dict[str, Any]:
        version, internal, gauss_next = self.rng.getstate()
        return {
            "t": self.t,
            "q": list(self.q),
            "qd": list(self.qd),
            "in_contact": self.in_contact,
            "h": self.h,
            "q_meas": list(self.q_meas),
            "rng": [version, list(internal), gauss_next],
        }

    def set_state(self, state: dict[str, Any]) -> None:
        self.t = state["t"]
        self.q = tuple(state["q"])
        self.qd = tuple(state["qd"])
        self.in_contact = state["in_contact"]
        self.h = state["h"]
        self.q_meas = tuple(state["q_meas"])
        version, internal, gauss_next = state["rng"]
        self.rng.setstate((version, tuple(internal), gauss_next))

    # --- analysis helpers -------------------------------------------------------------------

    def energy(self) -> float:
        """Total mechanical energy T + V (+ wall spring energy while penetrated)."""
        pen = max(0.0, self.arm.kinematics(self.q)[0] - self.wall.wall_x)
        spring = 0.5 * self.wall.wall_k * pen * pen
        return self.arm.kinetic_energy(self.q, self.qd) + self.arm.potential_energy(self.q) + spring
