"""The paper's Fig. 4 (numerical differentiation destabilises the loop) put to the test: candidate
conditions under which it could have happened, each run with the observer and with the backward
difference in the loop, and measured like the figure (onset, oscillation period, growth).

The paper gives no numbers for Fig. 4 beyond "0.25 sec of collected data" with oscillations that
"continue to amplify"; our copy of the paper has no image of the panel. A condition reproduces
Fig. 4 when the difference's loop oscillates and diverges while the observer's stays stable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

# PUMA 560 joint encoders: 250-line (1000 counts after quadrature) motor encoders behind gear
# ratios of about 62.6, 107.4 and 53.7 (Armstrong, Khatib & Burdick 1986): 1.0e-4, 5.9e-5 and
# 1.2e-4 rad per count at the joints. One q_quant for all joints: the order, 1e-4 rad.
PUMA_ENCODER_RAD = 1e-4


@dataclass(frozen=True)
class Condition:
    """One candidate explanation: master algorithm and parameter overrides."""

    name: str
    label: str
    algorithm: str = "gauss-seidel"
    overrides: dict[str, Any] = field(default_factory=dict)


CONDITIONS = (
    Condition("baseline", "sample-and-hold, adaptive plant, ideal encoders"),
    Condition("delay", "(a) one-sample delay (Jacobi)", "jacobi"),
    Condition(
        "euler",
        "(b) plant: one explicit Euler step per period",
        overrides={"plant.euler_substeps": 1},
    ),  # fmt: skip
    Condition(
        "encoder", "(c) PUMA encoders (1e-4 rad)", overrides={"plant.q_quant": PUMA_ENCODER_RAD}
    ),  # fmt: skip
    Condition(
        "encoder_noise",
        "(c') PUMA encoders + 1e-4 rad noise",
        overrides={"plant.q_quant": PUMA_ENCODER_RAD, "plant.q_noise": 1e-4},
    ),  # fmt: skip
    Condition(
        "euler_delay",
        "(a)+(b) Euler plant and one-sample delay",
        "jacobi",
        {"plant.euler_substeps": 1},
    ),  # fmt: skip
)
SOURCES = ("observer", "difference")
ONSET_M_S = 1e-3  # an oscillation is visible once its sample-to-sample part exceeds 1 mm/s


LINEAR_M_S = 0.1  # period and growth are measured while the deviation stays below 0.1 m/s


def oscillation(t: np.ndarray, dev: np.ndarray) -> dict[str, Any]:
    """Of a diverging run's deviation from the stable reference run (x-velocity): onset (from when
    |dev|, its max over 4 samples, stays above ONSET_M_S), and in its linear regime (onset until
    |dev| first reaches LINEAR_M_S) the period in samples (twice the mean spacing of sign
    changes) and the growth per sample (log-linear fit of the peaks of |dev| between sign
    changes); None where not defined."""
    out: dict[str, Any] = {"onset_s": None, "period_samples": None, "growth_per_sample": None}
    env = np.array([np.abs(dev[max(0, i - 3) : i + 1]).max() for i in range(len(dev))])
    if len(dev) < 8 or env[-1] <= ONSET_M_S:
        return out
    below = np.flatnonzero(env <= ONSET_M_S)
    i0 = int(below[-1]) + 1 if len(below) else 0
    out["onset_s"] = float(t[i0])
    big = np.flatnonzero(np.abs(dev[i0:]) >= LINEAR_M_S)
    i1 = i0 + int(big[0]) if len(big) else len(dev)
    seg = dev[i0:i1]
    flips = np.flatnonzero(np.sign(seg[1:]) != np.sign(seg[:-1])) + 1
    if len(flips) >= 3:
        out["period_samples"] = float(2.0 * np.mean(np.diff(flips)))
        peaks = [a + int(np.argmax(np.abs(seg[a:b]))) for a, b in zip(flips[:-1], flips[1:])]
        slope = np.polyfit(np.array(peaks, float), np.log(np.abs(seg[peaks])), 1)[0]
        out["growth_per_sample"] = float(math.exp(slope))
    return out


def run_condition(
    system,
    condition: Condition,
    source: str,
    rate: float = 400.0,
    stop: float = 20.0,
    reference: np.ndarray | None = None,
) -> dict[str, Any]:
    """One run (native master) of a condition with a velocity source: the table row and the
    signals the figure needs (time, true and fed-back x-velocity). reference: the x-velocity of
    a stable run (the oscillation is the deviation from it)."""
    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions

    overrides = {**condition.overrides, "controller.sample_period": 1.0 / rate}
    options = RunOptions(parameter_set=source, algorithm=condition.algorithm, overrides=overrides,
                         step_size=1.0 / rate, stop_time=stop)  # fmt: skip
    r = Master(system, options).run()
    t, xd, xd_hat = r["time"], r["plant.xd"], r["controller.xd_hat"]
    finite = np.isfinite(xd) & (np.abs(xd) < 1e3)
    t, xd, xd_hat = t[finite], xd[finite], xd_hat[finite]
    row = {"condition": condition.name, "velocity": source, "status": r.status,
           "t_end_s": float(r.data[-1, 0])}  # fmt: skip
    if r.ok or reference is None:
        row.update(dict.fromkeys(("onset_s", "period_samples", "growth_per_sample")))
    else:
        row.update(oscillation(t, xd - reference[: len(xd)]))
    return {"row": row, "t": t, "xd": xd, "xd_hat": xd_hat}


def run_all(ssp: str | Path, conditions=CONDITIONS) -> list[dict[str, Any]]:
    """Every condition x velocity source, in order."""
    from impedance_cosim.cosim.ssp.read import read_ssp

    system = read_ssp(ssp)
    runs = []
    baseline = run_condition(system, conditions[0], "observer")
    for c in conditions:
        obs = run_condition(system, c, "observer")
        ref = obs if obs["row"]["status"] == "ok" else baseline  # the stable reference
        runs += [obs, *(run_condition(system, c, s, reference=ref["xd"]) for s in SOURCES[1:])]
    return runs


COLUMNS = ["condition", "velocity", "status", "t_end_s", "onset_s", "period_samples",
           "growth_per_sample"]  # fmt: skip


def plot(runs: list[dict[str, Any]], path: Path, conditions=CONDITIONS) -> None:
    """Fig. 4 per condition: x-velocity, truth vs the estimate fed back, over the first 0.25 s
    (the paper shows 0.25 s of data), observer in the loop (left) and difference (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from impedance_cosim.util.atomic import atomic_write

    fig, axes = plt.subplots(len(conditions), 2, figsize=(10, 2.0 * len(conditions)),
                             squeeze=False)  # fmt: skip
    by = {(r["row"]["condition"], r["row"]["velocity"]): r for r in runs}
    for i, c in enumerate(conditions):
        for j, source in enumerate(SOURCES):
            ax, r = axes[i][j], by[(c.name, source)]
            row = r["row"]
            t_end = row["t_end_s"]
            sel = r["t"] <= 0.25
            ax.plot(r["t"][sel], r["xd"][sel], "k-", lw=1, label="actual")
            ax.plot(r["t"][sel], r["xd_hat"][sel], "r--", lw=0.8,
                    label="observed" if source == "observer" else "numerical diff.")  # fmt: skip
            status = "stable" if row["status"] == "ok" else f"diverges at {t_end:.3f} s"
            ax.set_title(f"{c.label}: {source}, {status}", fontsize=8)
            ax.tick_params(labelsize=7)
            if i == 0:
                ax.legend(fontsize=7, loc="upper left")
            if i == len(conditions) - 1:
                ax.set_xlabel("t (s)", fontsize=8)
            if j == 0:
                ax.set_ylabel("xd (m/s)", fontsize=8)
    fig.tight_layout()
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)
