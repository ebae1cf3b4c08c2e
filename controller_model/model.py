"""The controller: reduced-order velocity observer (eq. 9) + impedance law (eq. 10), sampled.

Plain numeric code behind the ImpedanceController FMU. It runs at its own period Ts
(sample_period) with a zero-order hold on its outputs:

- sample k happens at t_k = start_time + k * Ts (k an integer counter, never an accumulated sum);
- sample 0 is computed when the model is built (FMI initialization), from the inputs given then,
  with the observer at its start value yhat0;
- do_step(t, h, u) processes every not yet processed sample with t <= t_k < t + h (times compared
  with a tolerance of 1e-9 Ts). The sample at t_k == t uses the inputs u just given; samples
  strictly inside the step (only when the master's step is longer than Ts) reuse the same u
  (counted in `held_input_samples`, nothing is logged). After do_step(t, h) the outputs are those
  of the latest sample before t + h, held until the next one. (The inputs given to the first
  do_step, at start_time, are not used: sample 0 was already taken at initialization.)

So with h = Ts, the torque available after do_step(t_k, Ts) was computed from the inputs at t_k;
a master that steps the controller before the plant in each macro step (Gauss-Seidel) applies
that torque to the plant over [t_k, t_k+1], the zero-order hold the observer assumes. A Jacobi
master delays the torque by one period, and the observer's tau_{i-1} is then not what the plant
received over [t_i-1, t_i].

The observer always runs and the backward difference is always computed; the parameter
velocity_source only selects which joint-velocity estimate feeds the impedance law.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from impedance_cosim.fmi.model import FmuModel, ModelError, build_params, check_finite_inputs
from impedance_cosim.fmi.variables import (
    SAMPLED_INPUTS,
    Enumeration,
    ModelExchange,
    Variable,
    parameters_of,
    vector,
)
from impedance_cosim.physics.arm import Arm, ArmParams, _p, check_fields
from impedance_cosim.physics.linalg3 import Vec3, matTvec, matvec, solve

TWO_PI = 2.0 * math.pi
SINGULAR_TOL = 1e-6  # |det J| below SINGULAR_TOL * a1 * a2 (i.e. |sin q2| < 1e-6) is singular
TIME_TOL = 1e-9  # sample-time comparisons, relative to the sample period
VELOCITY_SOURCES = ("observer", "difference", "measured")
OBSERVER_DISCRETIZATIONS = ("euler", "implicit", "exponential")
VELOCITY_SOURCE = Enumeration(
    "VelocitySource",
    "Joint velocity fed to the impedance law",
    (
        ("observer", "Reduced-order observer, eq. (9) (the paper)"),
        ("difference", "Backward difference of the measured joint angles (Fig. 4 baseline)"),
        ("measured", "The measured joint velocity, inputs qd_meas1..3 (ideal baseline)"),
    ),
)


# --- parameters ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrajectoryParams:
    """The virtual trajectory of section 5: an ellipse truncated by (and pushed into) the wall."""

    traj_cx: float = _p(0.5, "m", "Virtual-trajectory ellipse centre, x", tunable=True)
    traj_cy: float = _p(0.0, "m", "Virtual-trajectory ellipse centre, y", tunable=True)
    traj_ax: float = _p(0.2, "m", "Virtual-trajectory ellipse semi-axis along x", 0.0, tunable=True)
    traj_ay: float = _p(0.5, "m", "Virtual-trajectory ellipse semi-axis along y", 0.0, tunable=True)
    traj_f: float = _p(
        0.1, "Hz", "Virtual-trajectory frequency (one ellipse per 1/f)", 0.0, tunable=True
    )
    traj_phi: float = _p(0.0, "rad", "Virtual end-effector orientation (constant)", tunable=True)
    wall_x: float = _p(
        0.65, "m", "Where the ellipse's x reaches this, x_v switches into the wall", tunable=True
    )
    wall_depth: float = _p(
        0.00196,
        "m",
        "Depth of the switched x_v inside the wall (target force = k * depth)",
        0.0,
        tunable=True,
    )

    def validate(self) -> None:
        """Raise ValueError naming a non-finite or out-of-range setting."""
        check_fields(self)


B_DEFAULT = 2.0 * math.sqrt(1000.0)  # section 5: B = 2 sqrt(1000) I


@dataclass(frozen=True)
class ControllerParams:
    """Observer and impedance gains, sampling, velocity source and torque limits (section 5)."""

    K1: float = _p(
        50.0, "1/s", "Observer gain, joint 1 (K = diag(K1, K2, K3) > 0)", 0.0, tunable=True
    )
    K2: float = _p(50.0, "1/s", "Observer gain, joint 2", 0.0, tunable=True)
    K3: float = _p(50.0, "1/s", "Observer gain, joint 3", 0.0, tunable=True)
    G1: float = _p(
        1000.0, "N/m", "Impedance stiffness along x (G = diag(G1, G2, G3) > 0)", 0.0, tunable=True
    )
    G2: float = _p(1000.0, "N/m", "Impedance stiffness along y", 0.0, tunable=True)
    G3: float = _p(
        1000.0, "N.m/rad", "Impedance stiffness about the orientation phi", 0.0, tunable=True
    )
    B1: float = _p(
        B_DEFAULT,
        "N.s/m",
        "Impedance damping along x (B = diag(B1, B2, B3) > 0)",
        0.0,
        tunable=True,
    )
    B2: float = _p(B_DEFAULT, "N.s/m", "Impedance damping along y", 0.0, tunable=True)
    B3: float = _p(B_DEFAULT, "N.m.s/rad", "Impedance damping about phi", 0.0, tunable=True)
    sample_period: float = _p(1 / 400, "s", "Controller sample period (outputs held between)", 0.0)
    velocity_source: int = _p(
        1,
        "",
        "Joint velocity fed to the impedance law: 1 observer (eq. 9), 2 difference (backward"
        " difference of the measured angles) or 3 measured (inputs qd_meas1..3)",
        enumeration=VELOCITY_SOURCE,
    )
    observer_discretization: str = _p(
        "euler",
        "",
        "Observer update: euler (eq. 9 as printed, explicit; in the paper's loop at 400 Hz"
        " stable for K Ts <= 0.91), implicit (the -K yhat term implicit) or exponential (-K yhat"
        " integrated exactly over the sample; both stable for every K > 0)",
    )
    yhat0_1: float = _p(0.0, "rad/s", "Observer start value yhat(0), joint 1")
    yhat0_2: float = _p(0.0, "rad/s", "Observer start value yhat(0), joint 2")
    yhat0_3: float = _p(0.0, "rad/s", "Observer start value yhat(0), joint 3")
    limit_torque: bool = _p(False, "", "Clip the torque to +-tau_max (the observer uses the clip)")
    tau_max1: float = _p(200.0, "N.m", "Torque limit, joint 1 (when limit_torque)", 0.0)
    tau_max2: float = _p(100.0, "N.m", "Torque limit, joint 2 (when limit_torque)", 0.0)
    tau_max3: float = _p(50.0, "N.m", "Torque limit, joint 3 (when limit_torque)", 0.0)
    max_samples_per_step: int = _p(
        100_000,
        "",
        "Work bound of one communication step: most samples it may take; a longer step is"
        " refused (fmi2Discard)",
        1,
    )

    POSITIVE = (
        "K1", "K2", "K3", "G1", "G2", "G3", "B1", "B2", "B3",
        "sample_period", "tau_max1", "tau_max2", "tau_max3",
    )  # fmt: skip

    def validate(self) -> None:
        """Raise ValueError naming a gain or period that is not > 0, a non-finite value or an
        unknown velocity source (check_fields only checks min as >=)."""
        for name in self.POSITIVE:
            value = getattr(self, name)
            if math.isfinite(value) and not value > 0.0:
                raise ValueError(f"parameter {name} must be > 0 (got {value})")
        check_fields(self)
        try:
            VELOCITY_SOURCE.item(self.velocity_source)
        except ValueError as exc:
            raise ValueError(f"parameter velocity_source {exc}") from None
        if self.observer_discretization not in OBSERVER_DISCRETIZATIONS:
            raise ValueError(
                "parameter observer_discretization must be one of"
                f" {', '.join(OBSERVER_DISCRETIZATIONS)} (got {self.observer_discretization!r})"
            )


def _source_by_value(parameters: dict[str, Any]) -> dict[str, Any]:
    """velocity_source given by item name (for callers of the plain model) as its value."""
    source = parameters.get("velocity_source")
    if not isinstance(source, str):
        return parameters
    try:
        return {**parameters, "velocity_source": VELOCITY_SOURCE.value(source)}
    except ValueError as exc:
        raise ValueError(f"parameter velocity_source {exc}") from None


# --- virtual trajectory (section 5) -------------------------------------------------------------


def virtual_trajectory(p: TrajectoryParams, t: float) -> tuple[Vec3, Vec3, Vec3]:
    """Virtual pose x_v(t), velocity and acceleration: the ellipse, with x switched to
    wall_x + wall_depth (zero x-velocity and x-acceleration) wherever the ellipse's x >= wall_x."""
    w = TWO_PI * p.traj_f
    theta = w * t - 0.5 * math.pi
    s, c = math.sin(theta), math.cos(theta)
    x = p.traj_cx + p.traj_ax * s
    y = p.traj_cy + p.traj_ay * c
    yd = -p.traj_ay * w * s
    ydd = -p.traj_ay * w * w * c
    if x >= p.wall_x:  # in contact: the target lies wall_depth inside the wall
        return (p.wall_x + p.wall_depth, y, p.traj_phi), (0.0, yd, 0.0), (0.0, ydd, 0.0)
    xd = p.traj_ax * w * c
    xdd = -p.traj_ax * w * w * s
    return (x, y, p.traj_phi), (xd, yd, 0.0), (xdd, ydd, 0.0)


# --- observer, eq. (9) ----------------------------------------------------------------------------


def observer_update(
    arm: Arm,
    yhat_prev: Vec3,
    q_prev: Vec3,
    q_now: Vec3,
    tau_prev: Vec3,
    f_prev: Vec3,
    K: Vec3,
    dt: float,
    discretization: str = "euler",
) -> Vec3:
    """One step of the discrete velocity observer, eq. (9): yhat_i from yhat_i-1 and q_i-1, q_i.

    yhat_i = yhat_i-1 + K (q_i - q_i-1) - dt K yhat_i-1
             + dt H^-1(q_i-1) [tau_i-1 - C(q_i-1, yhat_i-1) yhat_i-1 - F yhat_i-1 - g(q_i-1)
                               - J^T(q_i-1) F_au,i-1]

    That is explicit Euler of yhat' = K (qdot - yhat) + acc, stable only for K dt < 2.
    discretization = implicit takes the -K yhat term at yhat_i:
    yhat_i = (yhat_i-1 + K (q_i - q_i-1) + dt acc) / (1 + dt K); exponential integrates it
    exactly with qdot = (q_i - q_i-1) / dt and acc held over the sample:
    yhat_i = a yhat_i-1 + (1 - a) ((q_i - q_i-1) / dt + acc / K), a = exp(-K dt).
    Both keep |yhat's own pole| < 1 for every K > 0, and equal eq. (9) to first order in K dt.
    """
    # The bracket is evaluated at the previous sample: explicit Euler of the integral in eq. (7)
    # over [t - dt, t]. tau_prev is the torque actually applied (held) over that interval (the
    # clipped one when limits are on), f_prev the wrist force measured at its start.
    jtf = matTvec(arm.jacobian(q_prev), f_prev)
    net = (tau_prev[0] - jtf[0], tau_prev[1] - jtf[1], tau_prev[2] - jtf[2])
    acc = arm.forward_dynamics(q_prev, yhat_prev, net)  # H^-1 [tau - C y - F y - g - J^T F], (5)
    if discretization != "euler":
        out = []
        for i in range(3):
            dq = q_now[i] - q_prev[i]
            if discretization == "implicit":
                out.append((yhat_prev[i] + K[i] * dq + dt * acc[i]) / (1.0 + dt * K[i]))
            else:
                a = math.exp(-K[i] * dt)
                out.append(a * yhat_prev[i] + (1.0 - a) * (dq / dt + acc[i] / K[i]))
        return (out[0], out[1], out[2])
    return (
        yhat_prev[0] + K[0] * (q_now[0] - q_prev[0]) + dt * acc[0] - dt * K[0] * yhat_prev[0],
        yhat_prev[1] + K[1] * (q_now[1] - q_prev[1]) + dt * acc[1] - dt * K[1] * yhat_prev[1],
        yhat_prev[2] + K[2] * (q_now[2] - q_prev[2]) + dt * acc[2] - dt * K[2] * yhat_prev[2],
    )


# --- impedance law, eq. (10) ----------------------------------------------------------------------


def wrap_angle(a: float) -> float:
    """a wrapped to (-pi, pi], so an orientation error never takes the long way round."""
    w = math.remainder(a, TWO_PI)
    return w + TWO_PI if w <= -math.pi else w


def impedance_terms(
    arm: Arm,
    q: Vec3,
    yhat: Vec3,
    f_au: Vec3,
    xv: Vec3,
    xv_dot: Vec3,
    xv_ddot: Vec3,
    G: Vec3,
    B: Vec3,
) -> tuple[Vec3, Vec3, Vec3]:
    """Joint torque of eq. (10), with the tracking error e = x - x_v and the observed Cartesian
    velocity J yhat it used (outputs of the controller). Raises ModelError when J is singular."""
    det = arm.jacobian_det(q)
    p = arm.params
    if not abs(det) >= SINGULAR_TOL * p.a1 * p.a2:
        raise ModelError(
            f"the Jacobian is singular at q = ({q[0]:.6g}, {q[1]:.6g}, {q[2]:.6g}) rad"
            f" (det J = a1 a2 sin q2 = {det:.3g}): the impedance law needs J^-1"
        )
    j = arm.jacobian(q)
    # Joint-space form of eq. (10), using J^T J^-T = I:
    # J^T (H_x xv_dd + C_x(q, yhat) xv_d) = H qdd_v + C(q, yhat) qd_v, J^T F_x xv_d = F qd_v,
    # J^T g_x = g, with C_x evaluated at the observed velocity (ERRATA).
    qd_v = solve(j, xv_dot)  # (3b)
    jdot_qd = matvec(arm.jacobian_dot(q, yhat), qd_v)
    qdd_v = solve(j, (xv_ddot[0] - jdot_qd[0], xv_ddot[1] - jdot_qd[1], xv_ddot[2] - jdot_qd[2]))
    pose = arm.kinematics(q)
    e = (pose[0] - xv[0], pose[1] - xv[1], wrap_angle(pose[2] - xv[2]))  # e = x - x_v
    xd_hat = matvec(j, yhat)  # observed Cartesian velocity J yhat
    # Cartesian terms that act through J^T: F_au - B (J yhat - xv_d) - G e
    f_c = (
        f_au[0] - B[0] * (xd_hat[0] - xv_dot[0]) - G[0] * e[0],
        f_au[1] - B[1] * (xd_hat[1] - xv_dot[1]) - G[1] * e[1],
        f_au[2] - B[2] * (xd_hat[2] - xv_dot[2]) - G[2] * e[2],
    )
    jtf = matTvec(j, f_c)
    hq = matvec(arm.inertia(q), qdd_v)
    cq = matvec(arm.coriolis(q, yhat), qd_v)
    fq = arm.friction(qd_v)
    g = arm.gravity(q)
    tau = (
        hq[0] + cq[0] + fq[0] + g[0] + jtf[0],
        hq[1] + cq[1] + fq[1] + g[1] + jtf[1],
        hq[2] + cq[2] + fq[2] + g[2] + jtf[2],
    )
    return tau, e, xd_hat


def impedance_law(
    arm: Arm,
    q: Vec3,
    yhat: Vec3,
    f_au: Vec3,
    xv: Vec3,
    xv_dot: Vec3,
    xv_ddot: Vec3,
    G: Vec3,
    B: Vec3,
) -> Vec3:
    """tau = J^T F_e, eq. (10), from the measured angles, the velocity estimate yhat and the
    measured wrist force F_au; G, B are the diagonals of the stiffness and damping."""
    return impedance_terms(arm, q, yhat, f_au, xv, xv_dot, xv_ddot, G, B)[0]


# --- the FMU model --------------------------------------------------------------------------------

# Start values of the angle inputs: the paper's initial pose (0.3 m, 0 m, 0 rad), elbow up, so the
# controller alone (zero inputs would be the stretched-arm singularity q2 = 0) runs its default
# experiment. A connected plant overrides them before initialization.
Q_START = Arm().inverse_kinematics((0.3, 0.0, 0.0), elbow_up=True)
INPUTS = ("q1", "q2", "q3", "fx", "fy", "n", "qd_meas1", "qd_meas2", "qd_meas3")
INPUT_START = (*Q_START, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


class ControllerModel(FmuModel):
    """Sampled observer + impedance controller (see module docstring)."""

    MODEL_NAME = "ImpedanceController"
    DESCRIPTION = (
        "Impedance controller with a reduced-order velocity observer (Impedance Control Without"
        " Using Velocity Measurements, eqs. 9 and 10) tracking the truncated-ellipse virtual"
        " trajectory of section 5: joint angles and wrist force/torque in; joint torques out,"
        " sampled and held"
    )
    # The native flavour also offers Model Exchange: no continuous states, a time event at every
    # sample instant (native/controller/model.c, model_me_event_update).
    MODEL_EXCHANGE = ModelExchange(states=())
    # Each output is computed at a sample from that sample's inputs and held until the next one.
    OUTPUT_DEPENDENCIES = SAMPLED_INPUTS

    @classmethod
    def variables(cls) -> list[Variable]:
        # Outputs change only at samples: discrete variability.
        def out(names: list[str], unit: str, description: str) -> list[Variable]:
            return vector(names, "output", unit, description, variability="discrete")

        def o(name: str, unit: str, description: str) -> Variable:
            return Variable(name, "output", 0.0, description, unit, variability="discrete")

        return [
            *parameters_of(ArmParams()),
            *parameters_of(TrajectoryParams()),
            *parameters_of(ControllerParams()),
            *[
                Variable(f"q{i + 1}", "input", Q_START[i], f"Joint {i + 1} angle, measured", "rad")
                for i in range(3)
            ],
            Variable("fx", "input", 0.0, "Wrist F/T sensor: force on the environment, x", "N"),
            Variable("fy", "input", 0.0, "Wrist F/T sensor: force on the environment, y", "N"),
            Variable("n", "input", 0.0, "Wrist F/T sensor: moment about the tool point", "N.m"),
            *vector(
                ["qd_meas1", "qd_meas2", "qd_meas3"],
                "input",
                "rad/s",
                "Joint {i} velocity, measured (used only when velocity_source = measured)",
            ),
            *out(["tau1", "tau2", "tau3"], "N.m", "Joint {i} torque command (held)"),
            *out(
                ["qd_hat1", "qd_hat2", "qd_hat3"],
                "rad/s",
                "Joint {i} velocity estimate fed to the law",
            ),
            *out(
                ["qd_obs1", "qd_obs2", "qd_obs3"], "rad/s", "Joint {i} velocity, observer eq. (9)"
            ),
            *out(
                ["qd_diff1", "qd_diff2", "qd_diff3"],
                "rad/s",
                "Joint {i} velocity, backward difference of the measured angles",
            ),
            o("xd_hat", "m/s", "End-effector x velocity estimate (J qd_hat)"),
            o("yd_hat", "m/s", "End-effector y velocity estimate (J qd_hat)"),
            o("phid_hat", "rad/s", "End-effector angular velocity estimate (J qd_hat)"),
            o("x_v", "m", "Virtual pose, x"),
            o("y_v", "m", "Virtual pose, y"),
            o("phi_v", "rad", "Virtual pose, orientation"),
            o("xd_v", "m/s", "Virtual velocity, x"),
            o("yd_v", "m/s", "Virtual velocity, y"),
            o("phid_v", "rad/s", "Virtual angular velocity"),
            o("e_x", "m", "Tracking error x - x_v"),
            o("e_y", "m", "Tracking error y - y_v"),
            o("e_phi", "rad", "Tracking error phi - phi_v, wrapped to (-pi, pi]"),
        ]

    def __init__(self, parameters: dict[str, Any], start_time: float = 0.0, inputs=None) -> None:
        try:
            self.arm = Arm(build_params(ArmParams, parameters))  # the controller's own model
            self.traj = build_params(TrajectoryParams, parameters)
            self.traj.validate()
            parameters = _source_by_value(parameters)
            self.ctrl = build_params(ControllerParams, parameters)
            self.ctrl.validate()
        except ValueError as exc:
            raise ModelError(str(exc)) from None
        c = self.ctrl
        self.source = VELOCITY_SOURCE.item(c.velocity_source)
        self.K = (c.K1, c.K2, c.K3)
        self.G = (c.G1, c.G2, c.G3)
        self.B = (c.B1, c.B2, c.B3)
        self.yhat0 = (c.yhat0_1, c.yhat0_2, c.yhat0_3)
        self.tau_max = (c.tau_max1, c.tau_max2, c.tau_max3)
        self.start_time = float(start_time)
        q, f, qd_meas = self._split(INPUT_START if inputs is None else inputs)
        # Sample 0, from the inputs at initialization; the observer starts at yhat0.
        z = (0.0, 0.0, 0.0)
        self.yhat, self.q_prev, self.tau_prev, self.f_prev, self.out = self._sample(
            0, self.yhat0, z, z, z, q, f, qd_meas
        )
        self.t = self.start_time
        self.k_next = 1
        self.held_input_samples = 0  # samples taken strictly inside a step, on held inputs

    # --- one sample ---------------------------------------------------------------------------

    def _split(self, inputs: tuple) -> tuple[Vec3, Vec3, Vec3]:
        """Angles, wrist force and (when used) measured velocity; raise ModelError naming a
        non-finite input."""
        measured = self.source == "measured"
        check_finite_inputs(INPUTS if measured else INPUTS[:6], inputs)
        u = [float(v) for v in inputs]
        return (u[0], u[1], u[2]), (u[3], u[4], u[5]), (u[6], u[7], u[8])

    def _sample(
        self,
        k: int,
        yhat_prev: Vec3,
        q_prev: Vec3,
        tau_prev: Vec3,
        f_prev: Vec3,
        q: Vec3,
        f: Vec3,
        qd_meas: Vec3,
    ) -> tuple[Vec3, Vec3, Vec3, Vec3, tuple]:
        """Sample k from the previous sample's state and this sample's inputs, without touching
        self: returns (yhat, q, applied tau, F_au, outputs)."""
        ts = self.ctrl.sample_period
        if k == 0:
            yhat = qd_diff = self.yhat0
        else:
            yhat = observer_update(
                self.arm, yhat_prev, q_prev, q, tau_prev, f_prev, self.K, ts,
                self.ctrl.observer_discretization,
            )  # fmt: skip
            qd_diff = ((q[0] - q_prev[0]) / ts, (q[1] - q_prev[1]) / ts, (q[2] - q_prev[2]) / ts)
        source = self.source
        qd_hat = yhat if source == "observer" else qd_diff if source == "difference" else qd_meas
        xv, xv_dot, xv_ddot = virtual_trajectory(self.traj, self.start_time + k * ts)
        tau, e, xd_hat = impedance_terms(
            self.arm, q, qd_hat, f, xv, xv_dot, xv_ddot, self.G, self.B
        )
        if self.ctrl.limit_torque:
            m = self.tau_max
            tau = (
                min(m[0], max(-m[0], tau[0])),
                min(m[1], max(-m[1], tau[1])),
                min(m[2], max(-m[2], tau[2])),
            )
        out = (*tau, *qd_hat, *yhat, *qd_diff, *xd_hat, *xv, *xv_dot, *e)
        return yhat, q, tau, f, out

    # --- FmuModel -------------------------------------------------------------------------------

    def do_step(self, t: float, h: float, inputs: tuple) -> None:
        q, f, qd_meas = self._split(inputs)
        if not h > 0.0:
            raise ModelError(f"communication step must be > 0 (got {h})")
        if h == math.inf:
            raise ModelError("communication step must be finite (got inf)")
        if abs(t - self.t) > 1e-9 * max(1.0, abs(t)):
            raise ModelError(f"doStep at t={t}, but the controller is at t={self.t}")
        ts = self.ctrl.sample_period
        tol = TIME_TOL * ts
        t_end = t + h
        k, held = self.k_next, 0
        n_max = self.ctrl.max_samples_per_step
        if self.start_time + (k + n_max) * ts < t_end - tol:  # sample k + n_max would be taken
            raise ModelError(
                f"a communication step of {h} s from t={t} would take more than {n_max} samples"
                " (parameter max_samples_per_step): take a smaller step"
            )
        state = (self.yhat, self.q_prev, self.tau_prev, self.f_prev, self.out)
        # Every unprocessed sample t_k < t + h; all use the inputs given at t. Work on locals and
        # commit at the end, so a failed step (ModelError) leaves the model at the step's start.
        while self.start_time + k * ts < t_end - tol:
            if self.start_time + k * ts > t + tol:
                held += 1  # strictly inside the step: the inputs at t are reused
            state = self._sample(k, *state[:4], q, f, qd_meas)
            k += 1
        self.yhat, self.q_prev, self.tau_prev, self.f_prev, self.out = state
        self.k_next = k
        self.held_input_samples += held
        self.t = t_end

    def tune(self, parameters: dict[str, Any]) -> None:
        """New gains (K, G, B), force setpoint (wall_depth) and trajectory, from the next sample
        on (the observer and the held torque keep their state)."""
        try:
            parameters = _source_by_value(parameters)
            traj = build_params(TrajectoryParams, parameters)
            traj.validate()
            ctrl = build_params(ControllerParams, parameters)
            ctrl.validate()
        except ValueError as exc:
            raise ModelError(str(exc)) from None
        for f in dataclasses.fields(ControllerParams):
            if not f.metadata.get("tunable") and getattr(ctrl, f.name) != getattr(
                self.ctrl, f.name
            ):
                raise ModelError(f"parameter {f.name} is fixed: it cannot change during a run")
        self.traj, self.ctrl = traj, ctrl
        self.K = (ctrl.K1, ctrl.K2, ctrl.K3)
        self.G = (ctrl.G1, ctrl.G2, ctrl.G3)
        self.B = (ctrl.B1, ctrl.B2, ctrl.B3)

    def outputs(self) -> tuple:
        return self.out

    def get_state(self) -> dict[str, Any]:
        return {
            "t": self.t,
            "start_time": self.start_time,
            "k_next": self.k_next,
            "held_input_samples": self.held_input_samples,
            "yhat": list(self.yhat),
            "q_prev": list(self.q_prev),
            "tau_prev": list(self.tau_prev),
            "f_prev": list(self.f_prev),
            "out": list(self.out),
        }

    def set_state(self, state: dict[str, Any]) -> None:
        self.t = state["t"]
        self.start_time = state["start_time"]
        self.k_next = state["k_next"]
        self.held_input_samples = state["held_input_samples"]
        self.yhat = tuple(state["yhat"])
        self.q_prev = tuple(state["q_prev"])
        self.tau_prev = tuple(state["tau_prev"])
        self.f_prev = tuple(state["f_prev"])
        self.out = tuple(state["out"])
