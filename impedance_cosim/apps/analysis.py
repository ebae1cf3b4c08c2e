"""Results of a run: the numbers of the summary, and the paper's figures (1-4).

Signals are looked up by name in any mapping name -> array ("time", "plant.x", ...), so a
RunResult, a dict from run_models or a CSV read back all work.

Timing of sampled signals: the controller's outputs are recorded after each step, so the value
in row j+1 was computed at the sample t_j and held over [t_j, t_j+1). `at_samples` moves them
back to their sample time; comparisons with the plant's truth (observer error, tracking) use it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from impedance_cosim.physics.arm import ArmParams

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Signals = Mapping[str, np.ndarray]
TARGET_FORCE = 1e4 * 0.00196


def torque_name(s: Signals, i: int) -> str:
    """The controller's joint i torque: controller.tau<i>, or controller.tau[<i>] where it is
    an FMI 3.0 array (the array edition, fmus/fmi3/arrays/)."""
    name = f"controller.tau{i}"
    try:
        s[name]  # any mapping: a RunResult has no `in`
    except KeyError:
        return f"controller.tau[{i}]"
    return name


def at_samples(s: Signals, name: str) -> np.ndarray:
    """A controller output at the sample times (row j+1 moved to row j; last row repeated)."""
    v = s[name]
    return np.append(v[1:], v[-1])


def cartesian_velocity(s: Signals, prefix: str) -> np.ndarray:
    """J(q) v for the joint-velocity signals prefix1..3 (e.g. "controller.qd_obs"), with the
    plant's true angles (the figures compare estimates with the truth)."""
    q = np.column_stack([s[f"plant.q{i}_true"] for i in (1, 2, 3)])
    v = np.column_stack([at_samples(s, f"{prefix}{i}") for i in (1, 2, 3)])
    return np.matmul(jacobians(ArmParams(), q), v[:, :, None])[:, :, 0]


def jacobians(p: ArmParams, q: np.ndarray) -> np.ndarray:
    """J(q) for every row of q (n x 3) at once: arm_terms.jacobian's expressions on arrays
    (the per-row loop took half of a sweep run's time)."""
    q1, q2, q3 = q.T
    x0 = q1 + q2
    x1 = q3 + x0
    x2 = p.a3 * np.sin(x1)
    x3 = p.a2 * np.sin(x0) + x2
    x4 = p.a3 * np.cos(x1)
    x5 = p.a2 * np.cos(x0) + x4
    jac = np.empty((len(q1), 3, 3))  # filled in place: a stack of stacks copied it twice
    jac[:, 0] = np.stack((-p.a1 * np.sin(q1) - x3, -x3, -x2), axis=-1)
    jac[:, 1] = np.stack((p.a1 * np.cos(q1) + x5, x5, x4), axis=-1)
    jac[:, 2] = 1.0
    return jac


def contact_phases(s: Signals) -> list[tuple[float, float]]:
    """(start, end) times of the intervals with a contact force."""
    t, touching = s["time"], s["plant.contact_force"] > 0
    edges = np.flatnonzero(np.diff(touching.astype(int)))
    starts = list(t[edges[np.diff(touching.astype(int))[edges] > 0] + 1])
    ends = list(t[edges[np.diff(touching.astype(int))[edges] < 0]])
    if touching[0]:
        starts.insert(0, t[0])
    if touching[-1]:
        ends.append(t[-1])
    return list(zip(starts, ends, strict=False))


SETTLE_WINDOW_S = (0.6, 0.1)  # the window: from 0.6 s to 0.1 s before the contact ends
SETTLE_BAND = 0.05  # settled: the window's two halves' means within 5 % of the window's mean


def settled_force(t: np.ndarray, force: np.ndarray, end: float) -> float | None:
    """The settled force of a contact that ends at `end`: the mean over the window SETTLE_WINDOW_S
    before the end, when the force is in contact all over the window and the means of its two
    halves agree within SETTLE_BAND (sensor noise averages out, a transient or a drift does not);
    None otherwise (e.g. a run stopped during the impact, or a contact too short)."""
    f = force[(t >= end - SETTLE_WINDOW_S[0]) & (t <= end - SETTLE_WINDOW_S[1])]
    if len(f) < 4 or f.min() <= 0:
        return None
    mean, half = float(f.mean()), len(f) // 2
    if abs(f[:half].mean() - f[half:].mean()) > SETTLE_BAND * mean:
        return None
    return mean


def diverged_summary(result: Any) -> dict[str, Any]:
    """The summary of a diverged run (results.Divergence): where it left the bound, and the span
    of its rows; the paper's numbers are not measured on a diverging loop."""
    d = result.divergence
    t = result["time"]
    return {"status": "diverged", "duration_s": float(t[-1] - t[0]) if len(t) else 0.0,
            "diverged_at_s": d.t, "diverged_signal": d.signal, "diverged_value": d.value,
            "divergence_limit": d.limit, "diverged": str(d)}  # fmt: skip


def summary(s: Signals) -> dict[str, Any]:
    """The numbers that tell the paper's story (see README): contact force (impact peak, settled
    value), tracking error before contact, observer error, peak torques."""
    t = s["time"]
    force = s["plant.contact_force"]
    out: dict[str, Any] = {"duration_s": float(t[-1] - t[0])}
    phases = contact_phases(s)
    out["contact_phases_s"] = [(round(a, 4), round(b, 4)) for a, b in phases]
    if phases:
        a, b = phases[0]
        out["impact_peak_N"] = float(force.max())
        out["impact_peak_time_s"] = float(t[np.argmax(force)])
        settled = settled_force(t, force, b)
        if settled is not None:
            out["settled_force_N"] = settled
    ex, ey = at_samples(s, "controller.e_x"), at_samples(s, "controller.e_y")
    first = phases[0][0] if phases else t[-1]
    before = (t >= min(2.0, first)) & (t < first)
    if before.any():
        out["tracking_error_before_contact_m"] = float(np.hypot(ex, ey)[before].max())
    obs = cartesian_velocity(s, "controller.qd_obs")
    err = np.hypot(obs[:, 0] - s["plant.xd"], obs[:, 1] - s["plant.yd"])[:-1]
    out["observer_error_max_m_s"] = float(err.max())
    late = err[t[:-1] >= 2.0]
    if late.size:
        out["observer_error_rms_after_2s_m_s"] = float(np.sqrt(np.mean(late**2)))
    out["peak_torque_N_m"] = [float(np.abs(s[torque_name(s, i)]).max()) for i in (1, 2, 3)]
    return out


def format_summary(values: dict[str, Any]) -> str:
    """The summary as a few readable lines."""
    if values.get("status") == "diverged":
        return values["diverged"]
    lines = []
    phases = values.get("contact_phases_s", [])
    if phases:
        text = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in phases)
        lines.append(f"contact with the wall: {text}")
        lines.append(
            f"impact peak force: {values['impact_peak_N']:.1f} N at t = "
            f"{values['impact_peak_time_s']:.2f} s"
        )
        if "settled_force_N" in values:
            lines.append(
                f"settled contact force: {values['settled_force_N']:.2f} N"
                f" (target {TARGET_FORCE:.1f} N)"
            )
        else:
            a, b = phases[0]
            lines.append(f"settled contact force: not settled (contact {a:.2f}-{b:.2f} s)")
    else:
        lines.append("no contact with the wall")
    if "tracking_error_before_contact_m" in values:
        lines.append(
            "tracking error before contact (from 2 s): "
            f"{1e3 * values['tracking_error_before_contact_m']:.2f} mm max"
        )
    text = f"observer error |J yhat - xdot|: {values['observer_error_max_m_s']:.4f} m/s max"
    if "observer_error_rms_after_2s_m_s" in values:
        text += f", {values['observer_error_rms_after_2s_m_s']:.5f} m/s rms after 2 s"
    lines.append(text)
    lines.append(
        "peak joint torques: " + ", ".join(f"{v:.1f}" for v in values["peak_torque_N_m"]) + " N m"
    )
    return "\n".join(lines)


# --- figures ----------------------------------------------------------------------------------


def _axes(rows: int, cols: int, title: str):
    """A figure of rows x cols axes, made without pyplot (no backend switch, no global state:
    safe inside a notebook or a program with its own plots)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 7.5), layout="constrained")
    fig.suptitle(title)
    return fig, fig.subplots(rows, cols).ravel()


def _finish(fig: Figure, path: Path | None) -> Figure:
    """Save the figure to path (when given) and return it (a notebook shows it)."""
    if path is not None:  # whole or not there; a failure names path (util.atomic)
        from impedance_cosim.util.atomic import atomic_path

        with atomic_path(path, suffix=".tmp" + Path(path).suffix) as tmp:
            fig.savefig(tmp, dpi=FIG4_DPI)
    return fig


def figure_1(s: Signals, path: Path | None = None) -> Figure:
    """Fig. 1: (a) desired vs actual path, (b) contact detail, (c) joint torques, (d) force."""
    fig, ax = _axes(2, 2, "Fig. 1 - position and force tracking")
    t = s["time"]
    xv, yv = at_samples(s, "controller.x_v"), at_samples(s, "controller.y_v")
    ax[0].plot(xv, yv, "k-", lw=1, label="virtual trajectory $x_v$")
    ax[0].plot(s["plant.x"], s["plant.y"], "r--", lw=1, label="end effector")
    ax[0].axvline(0.65, color="0.5", lw=2, label="wall")
    ax[0].set(xlabel="x [m]", ylabel="y [m]", title="(a) desired vs actual position")
    ax[0].set_aspect("equal", adjustable="datalim")
    ax[0].legend(fontsize=8)
    phases = contact_phases(s)
    a, b = (phases[0][0] - 0.3, phases[0][1] + 0.3) if phases else (t[0], t[-1])
    w = (t >= a) & (t <= b)
    ax[1].step(t[w], xv[w], "k-", where="post", lw=1, label="virtual $x_v$")
    ax[1].plot(t[w], s["plant.x"][w], "r--", lw=1, label="actual x")
    ax[1].axhline(0.65, color="0.5", lw=2, label="wall")
    ax[1].set(xlabel="t [s]", ylabel="x [m]", title="(b) displacement during the first contact")
    ax[1].legend(fontsize=8)
    for i, c in zip((1, 2, 3), ("C0", "C1", "C2"), strict=True):
        ax[2].step(t, at_samples(s, torque_name(s, i)), where="post", color=c, lw=0.8,
                   label=f"$\\tau_{i}$")  # fmt: skip
    ax[2].set(xlabel="t [s]", ylabel="torque [N m]", title="(c) applied joint torques")
    ax[2].legend(fontsize=8)
    ax[3].plot(t, s["plant.contact_force"], "r-", lw=1, label="contact force")
    ax[3].axhline(TARGET_FORCE, color="k", lw=0.8, ls=":", label="target 19.6 N")
    ax[3].set(xlabel="t [s]", ylabel="force [N]", title="(d) desired vs actual contact force")
    ax[3].legend(fontsize=8)
    return _finish(fig, path)


def figure_2(s: Signals, path: Path | None = None) -> Figure:
    """Fig. 2: observed vs actual Cartesian velocity (a, b) and observer error (c, d)."""
    fig, ax = _axes(2, 2, "Fig. 2 - velocity observer (eq. 9)")
    t = s["time"]
    obs = cartesian_velocity(s, "controller.qd_obs")
    for k, axis in enumerate("xy"):
        actual = s[f"plant.{axis}d"]
        ax[k].plot(t, actual, "k-", lw=1, label="actual")
        ax[k].plot(t[:-1], obs[:-1, k], "r--", lw=1, label="observed")
        ax[k].set(xlabel="t [s]", ylabel=f"{axis}-velocity [m/s]",
                  title=f"({'ab'[k]}) actual vs observed {axis}-velocity")  # fmt: skip
        ax[k].legend(fontsize=8)
        ax[k + 2].plot(t[:-1], obs[:-1, k] - actual[:-1], "b-", lw=0.8)
        ax[k + 2].set(xlabel="t [s]", ylabel="error [m/s]",
                      title=f"({'cd'[k]}) observer error, {axis}-direction")  # fmt: skip
    return _finish(fig, path)


def figure_3(s: Signals, path: Path | None = None) -> Figure:
    """Fig. 3: desired vs actual velocity (a, b) and velocity tracking error (c, d)."""
    fig, ax = _axes(2, 2, "Fig. 3 - velocity tracking")
    t = s["time"]
    for k, axis in enumerate("xy"):
        desired = at_samples(s, f"controller.{axis}d_v")
        actual = s[f"plant.{axis}d"]
        ax[k].plot(t, desired, "k-", lw=1, label="desired (virtual)")
        ax[k].plot(t, actual, "r--", lw=1, label="actual")
        ax[k].set(xlabel="t [s]", ylabel=f"{axis}-velocity [m/s]",
                  title=f"({'ab'[k]}) desired vs actual {axis}-velocity")  # fmt: skip
        ax[k].legend(fontsize=8)
        ax[k + 2].plot(t[:-1], (actual - desired)[:-1], "b-", lw=0.8)
        ax[k + 2].set(xlabel="t [s]", ylabel="error [m/s]",
                      title=f"({'cd'[k]}) velocity tracking error, {axis}-direction")  # fmt: skip
    return _finish(fig, path)


FIG4_WIDTH_INCHES, FIG4_ROW_INCHES, FIG4_DPI = 11.0, 3.4, 110  # (every figure's dpi)


def condition_label(algorithm: str | None, overrides: Mapping[str, Any] | None = None) -> str:
    """The loop's timing condition in words (the figures' titles): sample-and-hold (Gauss-Seidel)
    or one sample of delay (Jacobi), and the plant's one explicit Euler step when set."""
    text = ("one-sample delay (Jacobi)" if algorithm == "jacobi"
            else "sample-and-hold (Gauss-Seidel)")  # fmt: skip
    if str((overrides or {}).get("plant.euler_substeps", "")) in ("1", "1.0"):
        text += ", plant: one Euler step per period"
    return text


def _end_text(s: Signals) -> str:
    """How a run ended, for a title: 'diverges at t = ... s' or 'bounded to ... s'."""
    d = getattr(s, "divergence", None)
    if d is not None:
        return f"diverges at t = {d.t:.4g} s"
    return f"bounded to {s['time'][-1]:.4g} s"


def figure_4(pairs: Sequence[tuple[str, Signals, Signals]], path: Path | None = None) -> Figure:
    """Fig. 4: x-velocity, the truth vs the estimate fed back, with the observer (left) and with
    numerical differentiation (right) in the loop, one row per condition (label, observer run,
    difference run). A row where a run diverged shows the rows up to the divergence (symlog
    scale: the growth stays visible), a stable row the whole run; each title says its range."""
    from matplotlib.figure import Figure

    height = 1.0 + FIG4_ROW_INCHES * len(pairs)
    fig = Figure(figsize=(FIG4_WIDTH_INCHES, height), layout="constrained")
    heading = "Fig. 4 - observer vs numerical differentiation in the loop"
    if len(pairs) == 1:
        heading += f"\n{pairs[0][0]}"
    fig.suptitle(heading)
    axes = fig.subplots(len(pairs), 2, squeeze=False)
    for i, (label, observer_run, difference_run) in enumerate(pairs):
        runs = ((observer_run, "controller.qd_obs", "observer"),
                (difference_run, "controller.qd_diff", "numerical differentiation"))  # fmt: skip
        ends = [getattr(r, "divergence", None) for r, _, _ in runs]
        t_end = min(
            [d.t for d in ends if d is not None] or [min(r["time"][-1] for r, _, _ in runs)]
        )
        for k, (s, prefix, name) in enumerate(runs):
            ax = axes[i][k]
            t = s["time"][:-1]
            w = t <= t_end
            est = cartesian_velocity(s, prefix)[:-1, 0]
            ax.plot(t[w], s["plant.xd"][:-1][w], "k-", lw=1, label="actual")
            short = "numerical diff." if k else name
            ax.plot(t[w], est[w], "r--", lw=0.8, label=f"{short} (fed back)")
            scale = ""
            if ends[k] is not None:  # linear near zero, logarithmic beyond 1 m/s
                ax.set_yscale("symlog", linthresh=1.0)
                scale = " (symlog)"
            letter = "abcdefgh"[2 * i + k]
            ax.set_title(f"{label}\n({letter}) {short} in the loop, t = {t[0]:.4g}-{t_end:.4g} s:"
                         f" {_end_text(s)}", fontsize=9)  # fmt: skip
            ax.set(xlabel="t [s]", ylabel=f"x-velocity [m/s]{scale}")
            # where the curves are not: growth fills the right, free motion the upper half
            loc = "lower left" if not any(ends) else "upper left" if ends[k] else "lower right"
            ax.legend(fontsize=8, loc=loc)
    return _finish(fig, path)
