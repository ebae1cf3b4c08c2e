"""The figures of `impedance-cosim stability`: the bisected boundaries (boundaries.png) and the
linearised loop's spectral radius against the sample rate (spectral_radius.png)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from impedance_cosim.apps.stability import bisection as st


def radius_curves(rows: list[dict], path: Path) -> None:
    """Spectral radius against the rate, per timing (panel), source (colour) and point (line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from impedance_cosim.apps import linearize as lin
    from impedance_cosim.util.atomic import atomic_write

    ref = lin.reference_run({}, {})
    rates = np.arange(150.0, 601.0, 10.0)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    colours = dict(zip(st.SOURCES, ("tab:blue", "tab:red", "tab:green")))
    for ax, timing in zip(axes, st.TIMINGS):
        for v in st.SOURCES:
            for point, style in zip(lin.POINTS, ("--", "-")):
                rho = [lin.loop_radius(r, timing, v, point, reference=ref)[0] for r in rates]
                ax.plot(rates, rho, style, color=colours[v], lw=1,
                        label=f"{v}, {point}")  # fmt: skip
            sim = next((r["simulated_Hz"] for r in rows
                        if r["velocity"] == v and r["timing"] == timing), None)  # fmt: skip
            if sim:
                ax.plot([sim], [1.0], "o", color=colours[v], mfc="none", ms=8)
        ax.axhline(1.0, color="k", lw=0.6)
        ax.set_ylim(0.95, 1.25)
        name = "sample-and-hold (Gauss-Seidel)" if timing == "gauss-seidel" else "one-sample delay"
        ax.set_title(f"{name}: spectral radius of the loop", fontsize=9)
        ax.set_xlabel("sample rate (Hz); circles: bisected critical rate (simulation)")
    axes[0].set_ylabel("max |eigenvalue| per sample")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def boundaries_figure(rows: list[dict], path: Path) -> None:
    """Critical rate per sensor condition (source x timing markers), critical K per sensor
    condition (timing x discretization), critical wall stiffness per source and timing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from impedance_cosim.util.atomic import atomic_write

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    sensors = list(st.SENSORS)
    markers = {"gauss-seidel": "o", "jacobi": "s"}
    palette = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple")
    colours = dict(zip(st.SOURCES + st.DISCRETIZATIONS[1:], palette))
    for ax, q in zip(axes, ("rate", "K", "wall_k")):
        series: dict[tuple[str, str], list[tuple[int, float]]] = {}
        lo, hi = st.QUANTITIES[q][0]
        for r in rows:
            if r["quantity"] != q:
                continue
            key = r["discretization"] if q == "K" else r["velocity"]
            x = sensors.index(r["sensor"]) if q != "wall_k" else st.SOURCES.index(r["velocity"])
            if r["critical"] in (None, ""):  # no boundary: a triangle at the bracket's end
                up = str(r["note"]).startswith("stable")
                ax.plot([x], [hi if up else lo], "^" if up else "v", ms=7, mfc="none",
                        color=colours.get(key, "tab:blue"))  # fmt: skip
                continue
            series.setdefault((key, r["timing"]), []).append((x, float(r["critical"])))
        for (key, timing), pts in sorted(series.items()):
            xs, ys = zip(*sorted(pts))
            ax.plot(xs, ys, marker=markers[timing], ls="-" if timing == "gauss-seidel" else ":",
                    color=colours.get(key, "tab:blue"), label=f"{key}, {timing}")  # fmt: skip
        ax.set_title("triangles: stable (up) / unstable (down) over the whole bracket", fontsize=8)
        if q != "wall_k":
            ax.set_xticks(range(len(sensors)), sensors, rotation=30, fontsize=8)
        else:
            ax.set_xticks(range(3), st.SOURCES, fontsize=8)
        if ax.get_legend_handles_labels()[0]:  # a panel of a selection may have no curve
            ax.legend(fontsize=7)
    axes[0].set_ylabel("critical sample rate (Hz): stable above")
    axes[1].set_ylabel("critical observer gain K (1/s) at 400 Hz: stable below")
    axes[1].set_yscale("log")
    axes[2].set_ylabel("critical wall stiffness (N/m) at 400 Hz")
    axes[2].set_yscale("log")
    fig.tight_layout()
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)
