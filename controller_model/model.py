"""The controller: reduced-order velocity observer (eq. 9) + impedance law (eq. 10), sampled.

Plain numeric code behind the ImpedanceController FMU: this module samples and holds; the parts
are observer.py (eq. 9), impedance_law.py (eq. 10), virtual_trajectory.py (section 5) and
parameters.py. It runs at its own period Ts
(sample_period) with a zero-order hold on its outputs:

- sample k happens at t_k = start_time + k * Ts (k an integer counter, never an accumulated sum);
- sample 0 is computed when the model is built (FMI initialization), from the inputs given then,
  with the observer at its start value yhat0. A host may give any finite inputs then (FMI 2.0
  and 3.0, attribute initial: "The environment decides when to use the start value of a variable
  with causality = input"; loop-cutting hosts give 0,
  the stretched-arm singularity q2 = 0). Where eq. (10) is undefined (J singular) sample 0 holds
  gravity compensation only, tau = g(q) (clipped like any torque), the other outputs as usual,
  and `init_warnings` says so (the FMU logs it as a warning); a later sample at a singular pose
  fails the step (ModelError naming the pose; the FMU adds the step time);
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
from typing import Any

from controller_model.impedance_law import SingularPoseError, gravity_hold_terms, impedance_law
from controller_model.observer import observer_update
from controller_model.parameters import (
    VELOCITY_SOURCE,
    ControllerParams,
    TrajectoryParams,
    source_by_value,
)
from controller_model.virtual_trajectory import virtual_trajectory
from impedance_cosim.fmi.model import (
    FmuModel,
    ModelError,
    build_params,
    check_finite_inputs,
    check_finite_outputs,
    check_step,
)
from impedance_cosim.fmi.variables import (
    SAMPLED_INPUTS,
    ModelExchange,
    Variable,
    parameters_of,
    vector,
)
from impedance_cosim.physics.arm import Arm, ArmParams
from impedance_cosim.physics.linalg3 import Vec3

TIME_TOL = 1e-9  # sample-time comparisons, relative to the sample period

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
            parameters = source_by_value(parameters)
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
        try:
            sample0 = self._sample(0, self.yhat0, z, z, z, q, f, qd_meas)
        except SingularPoseError as exc:  # any finite inputs initialize (module docstring)
            sample0 = self._sample(0, self.yhat0, z, z, z, q, f, qd_meas, law=False)
            self.init_warnings = (
                f"{exc}: at initialization (t={self.start_time}) the torque is gravity"
                " compensation only, tau = g(q); a step that samples at a singular pose is"
                " refused",
            )
        self.yhat, self.q_prev, self.tau_prev, self.f_prev, self.out = sample0
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
        law: bool = True,
    ) -> tuple[Vec3, Vec3, Vec3, Vec3, tuple]:
        """Sample k from the previous sample's state and this sample's inputs, without touching
        self: returns (yhat, q, applied tau, F_au, outputs). law False: gravity compensation
        instead of eq. (10) (sample 0 at a singular pose)."""
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
        if law:
            tau, e, xd_hat = impedance_law(
                self.arm, q, qd_hat, f, xv, xv_dot, xv_ddot, self.G, self.B
            )
        else:
            tau, e, xd_hat = gravity_hold_terms(self.arm, q, qd_hat, xv)
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
        check_step(t, h, self.t, "controller")
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
        check_finite_outputs(type(self), state[4])
        self.yhat, self.q_prev, self.tau_prev, self.f_prev, self.out = state
        self.k_next = k
        self.held_input_samples += held
        self.t = t_end

    def tune(self, parameters: dict[str, Any]) -> None:
        """New gains (K, G, B), force setpoint (wall_depth) and trajectory, from the next sample
        on (the observer and the held torque keep their state)."""
        try:
            parameters = source_by_value(parameters)
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
