"""The controller model: virtual trajectory, impedance law (eq. 10) against a literal Cartesian
numpy implementation and the computed-torque feed-forward, observer (eq. 9) on an exactly known
plant motion, sampling independent of the communication step, state round trip, bad inputs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from controller_model.impedance_law import impedance_law, wrap_angle
from controller_model.model import INPUT_START, Q_START, ControllerModel
from controller_model.observer import observer_update
from controller_model.parameters import TrajectoryParams
from controller_model.virtual_trajectory import virtual_trajectory
from impedance_cosim.fmi.fmi2_description import model_description
from impedance_cosim.fmi.model import ModelError
from impedance_cosim.fmi.units import UNITS
from impedance_cosim.physics.arm import Arm, ArmParams

ARM = Arm()
TRAJ = TrajectoryParams()
TS = 1 / 400
RNG = np.random.default_rng(7)
G = (1000.0, 1000.0, 1000.0)
B = (2 * math.sqrt(1000.0),) * 3
ZERO = (0.0, 0.0, 0.0)


def random_states(n: int) -> list[tuple]:
    """Random (q, qd) away from the elbow singularities (|sin q2| > 0.2)."""
    out = []
    while len(out) < n:
        q = tuple(RNG.uniform(-math.pi, math.pi, 3))
        if abs(math.sin(q[1])) > 0.2:
            out.append((q, tuple(RNG.uniform(-2, 2, 3))))
    return out


STATES = random_states(20)


def ellipse(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The unswitched ellipse of section 5 and its derivatives, written out independently."""
    w = 2 * math.pi * 0.1
    th = w * t - math.pi / 2
    pose = np.array([0.5 + 0.2 * math.sin(th), 0.5 * math.cos(th), 0.0])
    vel = np.array([0.2 * w * math.cos(th), -0.5 * w * math.sin(th), 0.0])
    acc = np.array([-0.2 * w * w * math.sin(th), -0.5 * w * w * math.cos(th), 0.0])
    return pose, vel, acc


def mats(arm: Arm, q, qd):
    """H, C(q, qd), F, g, J, Jdot(q, qd) as numpy arrays."""
    p = arm.params
    return (
        np.array(arm.inertia(q)),
        np.array(arm.coriolis(q, qd)),
        np.diag([p.f1, p.f2, p.f3]),
        np.array(arm.gravity(q)),
        np.array(arm.jacobian(q)),
        np.array(arm.jacobian_dot(q, qd)),
    )


# --- virtual trajectory ------------------------------------------------------------------------


def test_trajectory_starts_at_the_papers_initial_pose():
    pose, vel, acc = virtual_trajectory(TRAJ, 0.0)
    assert pose == pytest.approx((0.3, 0.0, 0.0), abs=1e-15)
    assert vel == pytest.approx((0.0, 0.5 * 2 * math.pi * 0.1, 0.0), abs=1e-15)


def test_trajectory_derivatives_match_finite_differences():
    d = 1e-5
    for t in np.linspace(0.0, 20.0, 81):
        pose, vel, acc = (np.array(v) for v in virtual_trajectory(TRAJ, t))
        if abs(pose[0] - TRAJ.wall_x) < 0.01 or pose[0] > TRAJ.wall_x:
            continue  # near or in the switched part
        pp, vp, _ = (np.array(v) for v in virtual_trajectory(TRAJ, t + d))
        pm, vm, _ = (np.array(v) for v in virtual_trajectory(TRAJ, t - d))
        assert np.allclose(vel, (pp - pm) / (2 * d), atol=1e-8)
        assert np.allclose(acc, (vp - vm) / (2 * d), atol=1e-8)


def test_trajectory_switches_into_the_wall():
    ts = np.linspace(0.0, 20.0, 2001)
    inside = 0
    for t in ts:
        pose, vel, acc = virtual_trajectory(TRAJ, t)
        e_pose, e_vel, e_acc = ellipse(t)
        if e_pose[0] >= 0.65:
            inside += 1
            assert pose[0] == 0.65196 and vel[0] == 0.0 and acc[0] == 0.0
        else:
            assert np.allclose(pose, e_pose, atol=1e-14) and np.allclose(vel, e_vel, atol=1e-14)
            assert np.allclose(acc, e_acc, atol=1e-14)
        # y and phi always follow the ellipse
        assert (pose[1], vel[1], acc[1]) == pytest.approx(tuple(e[1] for e in ellipse(t)))
        assert pose[2] == vel[2] == acc[2] == 0.0
    assert inside > 0
    pose5, vel5, acc5 = virtual_trajectory(TRAJ, 5.0)
    assert (pose5[0], vel5[0], acc5[0]) == (0.65196, 0.0, 0.0)


def test_trajectory_switch_times_are_the_wall_crossings():
    """The ellipse's x is 0.65 where sin(2 pi f t - pi/2) = 0.75: once entering, once leaving the
    wall in each period."""
    w = 2 * math.pi * 0.1
    t_in = (math.asin(0.75) + math.pi / 2) / w
    t_out = (math.pi - math.asin(0.75) + math.pi / 2) / w
    for period in (0.0, 10.0):
        for t_cross, before_free in ((t_in + period, True), (t_out + period, False)):
            before = virtual_trajectory(TRAJ, t_cross - 1e-6)[0][0]
            after = virtual_trajectory(TRAJ, t_cross + 1e-6)[0][0]
            free, wall = (before, after) if before_free else (after, before)
            assert wall == 0.65196
            assert free == pytest.approx(0.65, abs=1e-6) and free < 0.65


# --- impedance law, eq. (10) ------------------------------------------------------------------


def test_law_on_the_trajectory_is_the_computed_torque_feed_forward():
    """e = 0 and yhat = the true qd with J qd = xv_dot: tau = H qdd + C qd + F qd + g + J^T F_au,
    J qdd + Jdot qd = xv_ddot."""
    for q, qd in STATES:
        h, c, f, g, j, jdot = mats(ARM, q, qd)
        xv = ARM.kinematics(q)
        xv_dot = j @ qd
        xv_ddot = RNG.uniform(-3, 3, 3)
        f_au = RNG.uniform(-20, 20, 3)
        qdd = np.linalg.solve(j, xv_ddot - jdot @ qd)
        ref = h @ qdd + c @ qd + f @ qd + g + j.T @ f_au
        tau = torque(ARM, q, qd, tuple(f_au), xv, tuple(xv_dot), tuple(xv_ddot), G, B)
        assert np.allclose(tau, ref, rtol=1e-10, atol=1e-9)


def torque(*args):
    """The joint torque of eq. (10) alone (impedance_law also returns e and J yhat)."""
    return impedance_law(*args)[0]


def cartesian_law(arm, q, yhat, f_au, xv, xv_dot, xv_ddot, Gd, Bd):
    """Eq. (10) literally: F_e = F_au + H_x xv_dd + C_x(q, yhat) xv_d + F_x xv_d + g_x
    - B (J yhat - xv_d) - G e, tau = J^T F_e."""
    h, c, f, g, j, jdot = mats(arm, q, yhat)
    ji = np.linalg.inv(j)
    hx = ji.T @ h @ ji
    cx = ji.T @ (c - h @ ji @ jdot) @ ji
    fx = ji.T @ f @ ji
    gx = ji.T @ g
    e = np.array(arm.kinematics(q)) - np.array(xv)
    e[2] = (e[2] + math.pi) % (2 * math.pi) - math.pi
    f_e = (
        f_au
        + hx @ xv_ddot
        + cx @ xv_dot
        + fx @ xv_dot
        + gx
        - np.diag(Bd) @ (j @ yhat - xv_dot)
        - np.diag(Gd) @ e
    )
    return j.T @ f_e


def test_joint_space_law_equals_cartesian_form():
    for q, yhat in STATES:
        xv = np.array(ARM.kinematics(q)) + RNG.uniform(-0.05, 0.05, 3)
        xv_dot, xv_ddot = RNG.uniform(-1, 1, 3), RNG.uniform(-3, 3, 3)
        f_au = RNG.uniform(-20, 20, 3)
        gains, damp = tuple(RNG.uniform(100, 2000, 3)), tuple(RNG.uniform(10, 100, 3))
        tau = torque(
            ARM, q, yhat, tuple(f_au), tuple(xv), tuple(xv_dot), tuple(xv_ddot), gains, damp
        )
        ref = cartesian_law(ARM, q, np.array(yhat), f_au, xv, xv_dot, xv_ddot, gains, damp)
        assert np.allclose(tau, ref, rtol=1e-9, atol=1e-8)


def test_law_uses_the_controllers_own_model():
    """A different controller model changes the torque (model mismatch can be studied)."""
    q, qd = STATES[0]
    args = (q, qd, (0.0, 0.0, 0.0), ARM.kinematics(q), (0.1, 0.2, 0.0), (0.5, 0.1, 0.0), G, B)
    other = Arm(ArmParams(m2=7.0))
    assert not np.allclose(torque(ARM, *args), torque(other, *args))
    ref = cartesian_law(other, q, np.array(qd), np.zeros(3), *map(np.array, args[3:6]), G, B)
    assert np.allclose(torque(other, *args), ref, rtol=1e-9)


def test_law_term_signs():
    """In Cartesian force F_e = J^-T tau: a position error delta in x adds -G1 delta, an observed
    velocity excess delta in x adds -B1 delta, a measured force adds +F_au."""
    delta = 0.01
    gains, damp = (800.0, 900.0, 1000.0), (50.0, 60.0, 70.0)
    for q, _ in STATES[:5]:
        j = np.array(ARM.jacobian(q))
        x = ARM.kinematics(q)

        def f_e(xv=x, yhat=ZERO, f_au=ZERO, q=q, j=j):
            tau = torque(ARM, q, yhat, f_au, xv, ZERO, (0.2, -0.1, 0.3), gains, damp)
            return np.linalg.solve(j.T, tau)

        base = f_e()
        assert np.allclose(f_e(xv=(x[0] - delta, x[1], x[2])) - base, [-800 * delta, 0, 0])
        assert np.allclose(f_e(xv=(x[0], x[1], x[2] - delta)) - base, [0, 0, -1000 * delta])
        yhat = tuple(np.linalg.solve(j, [delta, 0.0, 0.0]))  # J yhat - xv_dot = (delta, 0, 0)
        assert np.allclose(f_e(yhat=yhat) - base, [-50 * delta, 0, 0])
        assert np.allclose(f_e(f_au=(3.0, -4.0, 0.5)) - base, [3.0, -4.0, 0.5])
        # the orientation error is wrapped: a target 2 pi away is the same target
        assert np.allclose(f_e(xv=(x[0], x[1], x[2] + 2 * math.pi)), base, atol=1e-9)


def test_wrap_angle():
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-0.3 + 4 * math.pi) == pytest.approx(-0.3)


@pytest.mark.parametrize("q2", [0.0, math.pi, -math.pi, 1e-8])
def test_law_refuses_a_singular_jacobian(q2):
    with pytest.raises(ModelError, match="singular"):
        torque(ARM, (0.3, q2, 0.2), ZERO, ZERO, (0.5, 0.0, 0.0), ZERO, ZERO, G, B)


# --- observer, eq. (9) ------------------------------------------------------------------------


def plant_motion(dt: float, duration: float, qd0, f_ext=(0.0, 0.0, 0.0)):
    """Exact samples of a plant motion under a zero-order-held torque (gravity compensation plus
    smooth excitation, sampled at each t_i), with a constant wrist force f_ext."""
    f_ext = np.array(f_ext)
    y = np.array([*Q_START, *qd0], dtype=float)
    qs, qds, taus = [y[:3].copy()], [y[3:].copy()], []

    def rhs(_t, s, tau):
        q = tuple(s[:3])
        net = tau - np.array(ARM.jacobian(q)).T @ f_ext
        return [*s[3:], *ARM.forward_dynamics(q, tuple(s[3:]), tuple(net))]

    for i in range(round(duration / dt)):
        t = i * dt
        g = ARM.gravity(tuple(y[:3]))
        tau = (
            g[0] + 20 * math.sin(2 * math.pi * t),
            g[1] + 10 * math.cos(3 * t),
            g[2] + 3 * math.sin(5 * t),
        )
        taus.append(tau)
        sol = solve_ivp(rhs, (0, dt), y, method="DOP853", rtol=1e-12, atol=1e-12, args=(tau,))
        y = sol.y[:, -1]
        qs.append(y[:3].copy())
        qds.append(y[3:].copy())
    return np.array(qs), np.array(qds), taus


def run_observer(qs, taus, dt, f_ext=(0.0, 0.0, 0.0), K=(50.0, 50.0, 50.0)):
    yhat = (0.0, 0.0, 0.0)
    out = [np.array(yhat)]
    for i in range(1, len(qs)):
        yhat = observer_update(
            ARM, yhat, tuple(qs[i - 1]), tuple(qs[i]), taus[i - 1], tuple(f_ext), K, dt
        )
        out.append(np.array(yhat))
    return np.array(out)


@pytest.mark.parametrize("f_ext", [(0.0, 0.0, 0.0), (15.0, -10.0, 2.0)])
def test_observer_converges_to_the_true_velocity(f_ext):
    """From yhat0 = 0 with |qd(0)| = 1.41 rad/s: after 0.5 s the error is below 1 % of its initial
    value (measured 0.51 %). What remains is an O(dt) floor (7.2e-3 rad/s at dt = 1/400 s):
    yhat_i - qd_i = (dt/2) qdd_i to within 8 % (the observer estimates the velocity half a sample
    ahead); it halves with dt."""
    qd0 = (0.8, -0.6, 1.0)
    floors = []
    for dt in (TS, TS / 2):
        qs, qds, taus = plant_motion(dt, 1.0, qd0, f_ext)
        yhat = run_observer(qs, taus, dt, f_ext)
        err = np.linalg.norm(qds - yhat, axis=1)
        late = np.arange(len(err)) * dt >= 0.5
        assert err[0] == pytest.approx(np.linalg.norm(qd0))
        assert err[late].max() < 0.01 * err[0]
        # the floor is the half-sample lead: (dt/2) qdd, qdd under the torque held before t_i
        idx = np.flatnonzero(late)
        qdd = np.array(
            [
                ARM.forward_dynamics(
                    tuple(qs[i]),
                    tuple(qds[i]),
                    tuple(np.array(taus[i - 1]) - np.array(ARM.jacobian(tuple(qs[i]))).T @ f_ext),
                )
                for i in idx
            ]
        )
        lead = yhat[idx] - qds[idx]
        assert np.abs(lead - dt / 2 * qdd).max() < 0.15 * np.abs(dt / 2 * qdd).max()
        floors.append(err[late].max())
    assert floors[0] / floors[1] == pytest.approx(2.0, rel=0.1)


def test_observer_with_zero_gain_is_explicit_euler_of_the_model():
    for q, yhat in STATES:
        q_now = tuple(np.add(q, RNG.uniform(-0.01, 0.01, 3)))
        tau, f_au = RNG.uniform(-50, 50, 3), RNG.uniform(-20, 20, 3)
        h, c, f, g, j, _ = mats(ARM, q, yhat)
        ref = np.array(yhat) + TS * np.linalg.solve(h, tau - c @ yhat - f @ yhat - g - j.T @ f_au)
        got = observer_update(ARM, yhat, q, q_now, tuple(tau), tuple(f_au), (0.0,) * 3, TS)
        assert np.allclose(got, ref, rtol=1e-12, atol=1e-12)


def test_observer_gain_terms():
    """The K terms: + K (q_i - q_i-1) - dt K yhat_i-1, per joint (K diagonal)."""
    q, yhat = STATES[1]
    q_now = tuple(np.add(q, (0.01, -0.02, 0.03)))
    args = (tuple(RNG.uniform(-50, 50, 3)), (1.0, 2.0, 3.0))
    base = np.array(observer_update(ARM, yhat, q, q_now, *args, (0.0,) * 3, TS))
    K = (10.0, 20.0, 30.0)
    got = np.array(observer_update(ARM, yhat, q, q_now, *args, K, TS))
    expect = np.array(K) * (np.subtract(q_now, q) - TS * np.array(yhat))
    assert np.allclose(got - base, expect, atol=1e-12)


# --- the sampled model ------------------------------------------------------------------------


def inputs_at(t: float) -> tuple:
    """Smoothly varying measured angles, wrist force and velocity around the initial pose."""
    return (
        Q_START[0] + 0.1 * math.sin(3 * t),
        Q_START[1] + 0.05 * math.sin(5 * t + 1),
        Q_START[2] - 0.08 * math.sin(2 * t),
        10 * math.sin(4 * t),
        -3.0,
        0.5 * math.cos(t),
        0.3 * math.cos(3 * t),
        0.25 * math.cos(5 * t + 1),
        -0.16 * math.cos(2 * t),
    )


def test_first_output_reflects_the_inputs_at_initialization():
    u = inputs_at(0.3)
    m = ControllerModel({"yhat0_2": 0.1}, 0.3, u)
    xv, xvd, xvdd = virtual_trajectory(TRAJ, 0.3)
    tau = torque(ARM, u[:3], (0.0, 0.1, 0.0), u[3:6], xv, xvd, xvdd, G, B)
    out = m.outputs()
    assert out[:3] == tau
    assert out[3:12] == (0.0, 0.1, 0.0) * 3  # qd_hat, qd_obs, qd_diff all start at yhat0
    assert out[15:21] == (*xv, *xvd)
    assert len(out) == len([v for v in ControllerModel.variables() if v.causality == "output"])


def test_variable_table():
    """Unique names, a description on each, units on every Real, discrete outputs, and a valid
    modelDescription.xml."""
    table = ControllerModel.variables()
    names = [v.name for v in table]
    assert len(names) == len(set(names))
    assert {f for f in ArmParams.__dataclass_fields__} <= set(names)
    for v in table:
        assert v.description
        assert v.type != "Real" or v.unit in UNITS
        assert v.causality != "output" or v.fmi_variability == "discrete"
    xml = model_description("ImpedanceController", "d", "{0}", table, {"stopTime": 1.0}, "test")
    assert b'name="velocity_source"' in xml


def test_default_inputs_are_the_initial_pose_elbow_up():
    assert Arm().kinematics(Q_START) == pytest.approx((0.3, 0.0, 0.0), abs=1e-12)
    assert Q_START[1] < 0
    m = ControllerModel({}, 0.0, None)
    assert m.outputs() == ControllerModel({}, 0.0, INPUT_START).outputs()


@pytest.mark.parametrize("source", ["observer", "difference", "measured"])
@pytest.mark.parametrize("t0,ts,sub", [(0.0, TS, 10), (0.7, 1 / 300, 7)])
def test_torque_samples_do_not_depend_on_the_communication_step(source, t0, ts, sub):
    """h = Ts/sub with inputs held between samples gives bit-identical samples to h = Ts; the output
    after do_step(t_k, h) is sample k, computed from the inputs at t_k. Also for a start time and
    period whose multiples are not exact in binary."""
    n = 60
    params = {"velocity_source": source, "sample_period": ts}
    coarse = ControllerModel(params, t0, inputs_at(t0))
    samples = []  # samples[k]: the output after do_step(t_k, Ts), i.e. sample k
    for k in range(n):
        coarse.do_step(t0 + k * ts, ts, inputs_at(t0 + k * ts))
        samples.append(coarse.outputs())
    fine = ControllerModel(params, t0, inputs_at(t0))
    h = ts / sub
    for j in range(sub * n):
        k = j // sub
        fine.do_step(t0 + j * h, h, inputs_at(t0 + k * ts))
        # the output held after every sub-step of sample interval k is sample k
        assert fine.outputs() == samples[k]
    assert fine.held_input_samples == 0 and fine.k_next == coarse.k_next == n
    assert fine.outputs()[:3] != samples[0][:3]


def test_steps_longer_than_the_period_reuse_the_inputs():
    """h = 4 Ts: the samples inside the step use the inputs given at its start (counted)."""
    params = {"velocity_source": "difference"}
    long = ControllerModel(params, 0.0, inputs_at(0.0))
    ref = ControllerModel(params, 0.0, inputs_at(0.0))
    for s in range(5):
        u = inputs_at(4 * s * TS)
        long.do_step(4 * s * TS, 4 * TS, u)
        for k in range(4 * s, 4 * s + 4):
            ref.do_step(k * TS, TS, u)
        assert long.outputs() == ref.outputs()
    assert long.held_input_samples == 5 * 3
    # held angles: the backward difference is zero inside a step
    assert long.outputs()[9:12] == (0.0, 0.0, 0.0)


def test_velocity_sources():
    """velocity_source picks what feeds the law; the observer and the difference always run."""
    u0, u1 = inputs_at(0.0), inputs_at(TS)
    diff = tuple((u1[i] - u0[i]) / TS for i in range(3))
    for source in ("observer", "difference", "measured"):
        m = ControllerModel({"velocity_source": source, "yhat0_1": 0.2}, 0.0, u0)
        tau0 = m.outputs()[:3]
        assert m.outputs()[3:6] == (u0[6:9] if source == "measured" else (0.2, 0.0, 0.0))
        m.do_step(0.0, TS, u1)  # sample 0 was taken at initialization: nothing new
        assert m.outputs()[:3] == tau0
        m.do_step(TS, TS, u1)  # sample 1
        out = m.outputs()
        yhat1 = observer_update(
            ARM, (0.2, 0.0, 0.0), u0[:3], u1[:3], tau0, u0[3:6], (50.0,) * 3, TS
        )
        assert out[6:9] == yhat1
        assert out[9:12] == diff
        assert out[3:6] == {"observer": yhat1, "difference": diff, "measured": u1[6:9]}[source]
        j = np.array(ARM.jacobian(u1[:3]))
        assert np.allclose(out[12:15], j @ np.array(out[3:6]), rtol=1e-14, atol=1e-14)


def test_torque_limit_clips_and_the_observer_uses_the_clipped_torque():
    params = {"limit_torque": True, "tau_max1": 5.0, "tau_max2": 4.0, "tau_max3": 3.0}
    m = ControllerModel(params, 0.0, inputs_at(0.0))
    free = ControllerModel({}, 0.0, inputs_at(0.0))
    applied = m.outputs()[:3]
    assert free.outputs()[0] > 5.0  # the limit is active
    assert all(abs(t) <= lim for t, lim in zip(applied, (5.0, 4.0, 3.0)))
    u = inputs_at(0.0)
    m.do_step(0.0, TS, u)
    m.do_step(TS, TS, inputs_at(TS))
    expect = observer_update(
        ARM, (0.0,) * 3, u[:3], inputs_at(TS)[:3], applied, u[3:6], (50.0,) * 3, TS
    )
    assert m.outputs()[6:9] == expect


def test_closed_loop_on_the_trajectory_stays_on_it():
    """Arm (controller model = plant) started on the trajectory, controller stepped before the
    plant (zero-order hold over [t_k, t_k+1]): the tracking error stays below 1 mm (measured
    0.39 mm) and the observer error below 0.01 rad/s over 1 s."""
    xv, xvd, _ = virtual_trajectory(TRAJ, 0.0)
    qd0 = np.linalg.solve(np.array(ARM.jacobian(Q_START)), xvd)
    m = ControllerModel({"yhat0_1": qd0[0], "yhat0_2": qd0[1], "yhat0_3": qd0[2]}, 0.0, None)
    y = np.array([*Q_START, *qd0])
    e_max = obs_max = 0.0

    def rhs(_t, s, tau):
        return [*s[3:], *ARM.forward_dynamics(tuple(s[:3]), tuple(s[3:]), tau)]

    for k in range(400):
        m.do_step(k * TS, TS, (*y[:3], 0.0, 0.0, 0.0, *y[3:]))
        out = m.outputs()
        e_max = max(e_max, np.abs(out[21:24]).max())
        obs_max = max(obs_max, np.abs(np.array(out[6:9]) - y[3:]).max())
        sol = solve_ivp(rhs, (0, TS), y, "DOP853", rtol=1e-10, atol=1e-12, args=(out[:3],))
        y = sol.y[:, -1]
    assert e_max < 1e-3
    assert obs_max < 1e-2


def test_state_round_trip_is_bit_identical():
    m = ControllerModel({"limit_torque": True}, 0.0, inputs_at(0.0))
    for k in range(10):
        m.do_step(k * TS, TS, inputs_at(k * TS))
    saved = json.loads(json.dumps(m.get_state()))

    def run(model):
        outs = []
        for k in range(10, 30):
            model.do_step(k * TS, TS / 2, inputs_at(k * TS))
            model.do_step(k * TS + TS / 2, TS / 2, inputs_at(k * TS))
            outs.append(model.outputs())
        return outs, model.get_state()

    first = run(m)
    m.set_state(saved)
    assert run(m) == first
    other = ControllerModel({"limit_torque": True}, 0.0, inputs_at(0.0))
    other.set_state(json.loads(json.dumps(saved)))
    assert run(other) == first


# --- bad parameters and inputs ----------------------------------------------------------------


@pytest.mark.parametrize(
    "params,match",
    [
        ({"K2": 0.0}, r"K2 must be > 0 \(got 0.0\)"),
        ({"K1": -5.0}, "K1 must be > 0"),
        ({"G3": 0.0}, "G3 must be > 0"),
        ({"B1": 0.0}, "B1 must be > 0"),
        ({"sample_period": 0.0}, "sample_period must be > 0"),
        ({"sample_period": -0.0025}, "sample_period must be > 0"),
        ({"tau_max2": 0.0}, "tau_max2 must be > 0"),
        ({"K3": math.nan}, "K3 must be finite"),
        ({"velocity_source": "numerical"}, "velocity_source must be one of observer, difference"),
        ({"traj_f": -0.1}, "traj_f"),
        ({"m2": -1.0}, "m2"),
    ],
)
def test_bad_parameters_are_named(params, match):
    with pytest.raises(ModelError, match=match):
        ControllerModel(params, 0.0, None)


def test_singular_configuration_is_refused():
    # (initialization at a singular pose succeeds, gravity only: tests/test_controller_init.py)
    m = ControllerModel({}, 0.0, None)
    m.do_step(0.0, TS, INPUT_START)
    before = m.get_state()
    with pytest.raises(ModelError, match="singular"):
        m.do_step(TS, TS, (0.5, math.pi, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert m.get_state() == before  # a failed step leaves the model at its start


@pytest.mark.parametrize(
    "index,name,source",
    [
        (1, "q2", "observer"),
        (3, "fx", "difference"),
        (5, "n", "observer"),
        (7, "qd_meas2", "measured"),
    ],
)
def test_non_finite_input_is_named(index, name, source):
    m = ControllerModel({"velocity_source": source}, 0.0, None)
    before = m.get_state()
    u = list(INPUT_START)
    u[index] = math.nan
    with pytest.raises(ModelError, match=f"input {name} is not finite"):
        m.do_step(0.0, TS, tuple(u))
    assert m.get_state() == before
    with pytest.raises(ModelError, match=f"input {name} is not finite"):
        ControllerModel({"velocity_source": source}, 0.0, tuple(u))


def test_measured_velocity_is_ignored_unless_used():
    u = list(INPUT_START)
    u[6] = math.inf
    m = ControllerModel({}, 0.0, tuple(u))
    m.do_step(0.0, TS, tuple(u))
    assert all(math.isfinite(v) for v in m.outputs())


def test_step_time_must_match():
    m = ControllerModel({}, 0.0, None)
    with pytest.raises(ModelError, match="controller is at t=0.0"):
        m.do_step(0.1, TS, INPUT_START)
    with pytest.raises(ModelError, match="step must be > 0"):
        m.do_step(0.0, 0.0, INPUT_START)
