"""The paper's scenario with our plant and with MuJoCo's (fmus/MujocoPlant.fmu), side by side
(not a test: prints numbers; docs/mujoco.md quotes them).

Both runs are the paper's 20 s observer scenario through the same master, controller and
parameters, the plant swapped (`impedance-cosim swap --replace plant=fmus/MujocoPlant.fmu`). It
prints how close the free motion before the first contact is (MuJoCo's RK4 at its timestep
against our Dormand-Prince at rtol 1e-9), the paper's numbers with each plant, and what makes
them differ: MuJoCo's contact force against our wall law at the same penetration, and its wrist
sensor against its contact force. --figure draws the paper's Fig. 1 with both plants overlaid.

    python benchmarks/mujoco_compare.py [--figure docs/fig1_mujoco_overlay.png] [--stop 20]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import impedance_cosim as ic
from impedance_cosim.apps.analysis import at_samples, contact_phases
from impedance_cosim.cosim.leave import exit_process
from impedance_cosim.packaging.build import DEFAULT_OUT

WALL_X, WALL_K = 0.65, 1.0e4  # the paper's wall (observer_plant.ssv)
KEYS = ("impact_peak_N", "impact_peak_time_s", "settled_force_N",
        "tracking_error_before_contact_m", "observer_error_max_m_s")  # fmt: skip


def run_both(ssp: Path, fmu: Path, stop: float, timestep: float | None) -> tuple:
    """The observer scenario with PumaPlant and with MujocoPlant (optionally its timestep)."""
    ours = ic.simulate("observer", ssp=ssp, stop_time=stop).check()
    extra = {"plant.timestep": timestep} if timestep else {}
    theirs = ic.simulate("observer", ssp=ssp, stop_time=stop, fmu_files={"plant": fmu},
                         overrides=extra).check()  # fmt: skip
    return ours, theirs


def free_motion(ours, theirs) -> tuple[float, float, float]:
    """Before our first contact: max |q diff| (rad), max |x, y diff| (m), and that time (s)."""
    t = ours["time"]
    phases = contact_phases(ours.signals)
    end = phases[0][0] if phases else t[-1]
    w = t < end
    dq = max(np.abs(ours[f"plant.q{i}_true"][w] - theirs[f"plant.q{i}_true"][w]).max()
             for i in (1, 2, 3))  # fmt: skip
    dx = max(np.abs(ours[k][w] - theirs[k][w]).max() for k in ("plant.x", "plant.y"))
    return float(dq), float(dx), float(end)


def print_table(ours, theirs) -> None:
    """The paper's numbers with each plant and their difference."""
    nan = float("nan")  # a number a short run has not got (no contact, not settled)
    a, b = (
        {"peak_torque_N_m": [nan] * 3, **{k: nan for k in KEYS}, **r.summary}
        for r in (ours, theirs)
    )
    rows = [
        ("impact peak force [N]", a["impact_peak_N"], b["impact_peak_N"], "{:.3f}"),
        ("impact peak time [s]", a["impact_peak_time_s"], b["impact_peak_time_s"], "{:.4f}"),
        ("settled contact force [N]", a["settled_force_N"], b["settled_force_N"], "{:.4f}"),
        ("max penetration [mm]", 1e3 * ours["plant.penetration"].max(),
         1e3 * theirs["plant.penetration"].max(), "{:.5f}"),
        ("tracking error before contact [mm]", 1e3 * a["tracking_error_before_contact_m"],
         1e3 * b["tracking_error_before_contact_m"], "{:.5f}"),
        ("observer error max [m/s]", a["observer_error_max_m_s"], b["observer_error_max_m_s"],
         "{:.6f}"),
    ]  # fmt: skip
    rows += [(f"peak |tau{i + 1}| [N m]", a["peak_torque_N_m"][i], b["peak_torque_N_m"][i],
              "{:.4f}") for i in range(3)]  # fmt: skip
    print(f"{'':36} {'PumaPlant':>12} {'MujocoPlant':>12} {'difference':>11}")
    for name, x, y, fmt in rows:
        print(f"{name:36} {fmt.format(x):>12} {fmt.format(y):>12} {y - x:11.2e}")
    for label, s in (("PumaPlant", a), ("MujocoPlant", b)):
        phases = ", ".join(f"{p:.4f}-{q:.4f}" for p, q in s["contact_phases_s"])
        print(f"contact phases ({label}): {phases} s")


def contact_model(theirs) -> None:
    """Why the contact numbers differ: MuJoCo's contact force against k pen at the same state,
    the part of it contact_solref's last term predicts (i a / ((1 - i) Ā), a the tool's
    acceleration into the wall, here from the 400 Hz samples), and the wrist sensor against
    the contact force."""
    import mujoco

    from impedance_cosim.packaging.mujoco_mjcf import mujoco_mjcf

    force, pen = theirs["plant.contact_force"], theirs["plant.penetration"]
    w = pen > 1e-4  # in contact, over 1 N
    if not w.any():
        return
    law = WALL_K * pen[w]
    rel = (force[w] - law) / law
    print(f"MuJoCo contact force / (k pen) - 1 in contact: {rel.min():.2e} to {rel.max():.2e}"
          f" (median {np.median(rel):.2e})")  # fmt: skip
    model = mujoco.MjModel.from_xml_string(mujoco_mjcf())
    data = mujoco.MjData(model)
    i, inverse_mass = model.pair_solimp[0][0], model.body_invweight0[model.body("hand").id, 0]
    model.pair_solref[0] = (-(1 - i) * WALL_K * inverse_mass, 0.0)
    term = []
    for k in np.flatnonzero(w):  # each state in contact again, with the torque of its step
        data.qpos[:] = [theirs[f"plant.q{j}_true"][k] for j in (1, 2, 3)]
        data.qvel[:] = [theirs[f"plant.qd{j}"][k] for j in (1, 2, 3)]
        data.qfrc_applied[:] = [theirs[f"controller.tau{j}"][k] for j in (1, 2, 3)]
        mujoco.mj_forward(model, data)
        a1 = data.efc_J.reshape(data.nefc, model.nv)[0] @ data.qacc  # its normal acceleration
        term.append(-i * a1 / ((1 - i) * inverse_mass))
    excess = force[w] - law
    left = np.abs(excess - np.array(term)).max()
    print(f"MuJoCo contact force - k pen: {np.abs(excess).max() * 1e3:.3f} mN max; less"
          f" -i a1 / ((1 - i) A) at each state: {left * 1e3:.1e} mN max")  # fmt: skip
    sensor = np.abs(theirs["plant.fx"] - force).max()
    print(f"wrist sensor fx - contact force: {sensor:.1e} N max;"
          f" fy {np.abs(theirs['plant.fy']).max():.1e} N, n {np.abs(theirs['plant.n']).max():.1e}"
          " N m max")  # fmt: skip


def figure(ours, theirs, path: Path) -> None:
    """The paper's Fig. 1 (path, first contact, torques, contact force) with both plants."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5))
    ax = axes.ravel()
    t = ours["time"]
    xv, yv = at_samples(ours.signals, "controller.x_v"), at_samples(ours.signals, "controller.y_v")
    ax[0].plot(xv, yv, "k-", lw=1, label="virtual trajectory $x_v$")
    phases = contact_phases(ours.signals)
    a, b = (phases[0][0] - 0.3, phases[0][1] + 0.3) if phases else (t[0], t[-1])
    w = (t >= a) & (t <= b)
    ax[1].step(t[w], xv[w], "k-", where="post", lw=1, label="virtual $x_v$")
    styles = (("PumaPlant (ours)", ours, "C3", "-", 1.6), ("MujocoPlant", theirs, "k", "--", 0.9))
    for label, r, c, ls, lw in styles:
        ax[0].plot(r["plant.x"], r["plant.y"], color=c, ls=ls, lw=lw, label=label)
        ax[1].plot(t[w], r["plant.x"][w], color=c, ls=ls, lw=lw, label=label)
        for i, joint in zip((1, 2, 3), ("C0", "C1", "C2"), strict=True):
            ax[2].plot(t, r[f"controller.tau{i}"], color=joint if r is ours else "k", ls=ls,
                       lw=lw, label=f"$\\tau_{i}$ {label}")  # fmt: skip
        ax[3].plot(t, r["plant.contact_force"], color=c, ls=ls, lw=lw, label=label)
    ax[0].axvline(WALL_X, color="0.5", lw=2, label="wall")
    ax[1].axhline(WALL_X, color="0.5", lw=2, label="wall")
    diff = ax[3].twinx()
    diff.plot(t, theirs["plant.contact_force"] - ours["plant.contact_force"], color="C2", lw=0.7)
    diff.set_ylabel("MujocoPlant - PumaPlant [N]", color="C2")
    diff.tick_params(axis="y", colors="C2")
    ax[3].axhline(19.6, color="k", lw=0.8, ls=":", label="target 19.6 N")
    ax[0].set(xlabel="x [m]", ylabel="y [m]", title="(a) desired vs actual position")
    ax[0].set_aspect("equal", adjustable="datalim")
    ax[1].set(xlabel="t [s]", ylabel="x [m]", title="(b) displacement during the first contact")
    ax[2].set(xlabel="t [s]", ylabel="torque [N m]", title="(c) joint torques tau1..tau3")
    ax[3].set(xlabel="t [s]", ylabel="force [N]", title="(d) contact force")
    for axis in ax:
        axis.grid(alpha=0.3)
        axis.legend(fontsize=7, loc="upper left" if axis is ax[3] else "best")
    fig.suptitle("Fig. 1 with our plant and MuJoCo's (the wall at x = 0.65 m, MuJoCo contact)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"figure: {path}")


def compare(ssp: Path, fmu: Path, stop: float = 20.0, timestep: float | None = None,
            figure_path: Path | None = None) -> None:  # fmt: skip
    """Run both plants and print everything above (and draw the figure if figure_path)."""
    ours, theirs = run_both(ssp, fmu, stop, timestep)
    dq, dx, end = free_motion(ours, theirs)
    print(f"{stop:g} s paper scenario (observer), PumaPlant vs MujocoPlant"
          f" (timestep {timestep or 2.5e-4:g} s)")  # fmt: skip
    print(f"free motion before the first contact (0-{end:.4f} s): max |q diff| {dq:.1e} rad,"
          f" max |x, y diff| {dx:.1e} m")  # fmt: skip
    print_table(ours, theirs)
    contact_model(theirs)
    gap = np.abs(ours["plant.contact_force"] - theirs["plant.contact_force"])
    at = ours["time"][np.argmax(gap)]
    print(f"largest contact force difference over the run: {gap.max() * 1e3:.3f} mN at {at:.4f} s")
    if figure_path:
        figure(ours, theirs, figure_path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ssp", type=Path, default=DEFAULT_OUT / "PaperScenario.ssp")
    parser.add_argument("--fmu", type=Path, default=DEFAULT_OUT / "MujocoPlant.fmu")
    parser.add_argument("--stop", type=float, default=20.0)
    parser.add_argument("--timestep", type=float, default=None, help="MujocoPlant's timestep")
    parser.add_argument("--figure", type=Path, default=None, help="draw Fig. 1 overlaid here")
    args = parser.parse_args()
    compare(args.ssp, args.fmu, args.stop, args.timestep, args.figure)
    exit_process(0)  # as our commands leave: pythonfmu's exit abort (docs/limitations.md)


if __name__ == "__main__":
    main()
