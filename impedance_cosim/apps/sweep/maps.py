"""Maps of a sweep: one metric over the swept axes as a curve, heatmaps or a scatter, with the
runs that did not stay bounded marked (PNG files, written through a temporary name)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.apps.sweep.metrics import metric_title

DEFAULT_PLOTS = (
    "peak_torque_N_m",
    "settled_force_N",
    "impact_peak_N",
    "observer_error_rms_after_2s_m_s",
    "tracking_error_in_contact_m",
)


NO_VALUE = "0.85"  # the colour of a cell without a value (never black: black is "not bounded")


def save_figure(fig: Any, path: Path, **kwargs: Any) -> None:
    """fig.savefig to a temporary name beside path, then renamed into place."""
    from impedance_cosim.util.atomic import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=".tmp" + path.suffix) as tmp:  # a failure names path
        fig.savefig(tmp, **kwargs)


def _short(name: str) -> str:
    return name.removeprefix("system.")


def label(v: Any) -> str:
    """A swept value as shown in maps and messages (floats to 3 significant digits)."""
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def plot_map(
    rows: list[dict],
    axes: Sequence[str],
    metric: str,
    path: Path,
    title: str | None = None,
    log: bool | None = None,
    mode: str = "grid",
) -> None:
    """One metric over the swept axes: a curve (one axis), heatmaps (x = axes[0], y = axes[1],
    panel rows = axes[2], panel columns = axes[3]) or a scatter (random sweeps). Runs that did not
    stay bounded are black cells / red crosses labelled with the time they stopped; a bounded run
    without a value of the metric (e.g. no contact before the stop time) is a grey hatched cell
    labelled "-", never the colour of "not bounded"."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes = [a for a in axes if len({label(r[a]) for r in rows}) > 1] or list(axes[:1])
    norm, log = _norm(rows, metric, log)
    title = title or metric_title(metric)
    if len(axes) == 1 or mode == "random":
        fig = _curve_or_scatter(plt, rows, axes, metric, norm, log, title)
    else:
        fig = _heatmaps(plt, rows, axes, metric, norm, title)
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def _norm(rows: list[dict], metric: str, log: bool | None):
    """(the colour scale of the metric's values, whether it is logarithmic): logarithmic when
    not given and every value is positive over more than a factor 30."""
    from matplotlib.colors import LogNorm, Normalize

    values = [r.get(metric) for r in rows if r.get("status") == "ok" and r.get(metric) is not None]
    positive = [v for v in values if v > 0]
    if log is None:
        log = bool(positive) and len(positive) == len(values) and max(values) / min(values) > 30
    lo, hi = (
        (min(positive or [1e-12]), max(positive or [1.0]))
        if log
        else (min(values or [0.0]), max(values or [1.0]))
    )
    norm = LogNorm(lo, max(hi, lo * 1.001)) if log else Normalize(lo, hi if hi > lo else lo + 1)
    return norm, log


def _order(rows: list[dict], name: str) -> list[Any]:
    """The values of an axis in the order the rows first show them."""
    seen: dict[str, Any] = {}
    for r in rows:
        seen.setdefault(label(r[name]), r[name])
    return list(seen.values())


def _curve_or_scatter(plt, rows: list[dict], axes: list[str], metric: str, norm, log: bool,
                      title: str):  # fmt: skip
    """One axis: the metric as a curve, unbounded runs as red dotted lines; a random sweep: a
    scatter over the first two axes, unbounded runs as red crosses."""
    what = metric_title(metric)
    fig, ax = plt.subplots(figsize=(7.2, 4.8), constrained_layout=True)
    x = axes[0]
    ok = [r for r in rows if r.get("status") == "ok" and r.get(metric) is not None]
    bad = [r for r in rows if r.get("status") != "ok"]
    if len(axes) == 1:
        ax.plot([r[x] for r in ok], [r[metric] for r in ok], "o-", ms=4)
        ax.set_ylabel(what)
        if log:
            ax.set_yscale("log")
        for r in bad:
            ax.axvline(r[x], color="r", lw=0.8, ls=":")
            ax.annotate(f"x {r['status']}", (r[x], 0.02), xycoords=("data", "axes fraction"),
                        color="r", fontsize=7, rotation=90)  # fmt: skip
    else:
        y = axes[1]
        sc = ax.scatter([r[x] for r in ok], [r[y] for r in ok], c=[r[metric] for r in ok],
                        norm=norm, cmap="viridis", s=25)  # fmt: skip
        ax.scatter([r[x] for r in bad], [r[y] for r in bad], marker="x", color="r", s=30,
                   label="not bounded")  # fmt: skip
        fig.colorbar(sc, ax=ax, label=what)
        ax.set_ylabel(y)
        if bad:
            ax.legend(fontsize=8)
    numeric = [r[x] for r in rows if isinstance(r[x], int | float) and r[x] > 0]
    if not ok:  # nothing to draw (e.g. no run reached the wall before its stop time)
        ax.text(0.5, 0.5, f"no run has a value of this metric ({len(rows)} runs)",
                ha="center", va="center", transform=ax.transAxes)  # fmt: skip
    elif numeric and len(numeric) == len(rows) and max(numeric) / min(numeric) > 20:
        ax.set_xscale("log")
    ax.set_xlabel(x)
    ax.set_title(title, fontsize=10)
    return fig


def _heatmaps(plt, rows: list[dict], axes: list[str], metric: str, norm, title: str):
    """Heatmaps of the metric over the first two axes, one panel per value of the third (rows)
    and the fourth (columns; beyond four axes, one panel per remaining combination in a row)."""
    import matplotlib

    x, y = axes[0], axes[1]
    prow = axes[2] if len(axes) > 2 else None
    pcol = axes[3] if len(axes) > 3 else None
    xs, ys = _order(rows, x), _order(rows, y)
    rvals = _order(rows, prow) if prow else [None]
    cvals = _order(rows, pcol) if pcol and not axes[4:] else [None]
    w = max(5.0, 0.5 * len(xs) + 1.6)
    h = max(3.6, 0.36 * len(ys) + 1.4)
    fig, grid = plt.subplots(len(rvals), len(cvals),
                             figsize=(w * len(cvals) + 1.2, h * len(rvals) + 0.6),
                             squeeze=False, constrained_layout=True)  # fmt: skip
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="black")
    image, missing, unbounded = None, False, False
    for ri, rv in enumerate(rvals):
        for ci, cv in enumerate(cvals):
            sel = [r for r in rows if (prow is None or label(r[prow]) == label(rv))
                   and (pcol is None or label(r[pcol]) == label(cv))]  # fmt: skip
            image, panel_missing, panel_unbounded = _panel(
                grid[ri][ci], sel, (x, xs), (y, ys), metric, cmap, norm
            )
            missing, unbounded = missing or panel_missing, unbounded or panel_unbounded
            parts = [f"{_short(prow)}={label(rv)}" if prow else "",
                     f"{_short(pcol)}={label(cv)}" if pcol else ""]  # fmt: skip
            grid[ri][ci].set_title(", ".join(p for p in parts if p), fontsize=9)
    keys = ["black, label in red: not bounded (stopped at that time)"] if unbounded else []
    if missing:
        keys.append('grey, hatched, "-": no value (e.g. no contact before the stop time)')
    fig.suptitle("\n".join([title, *keys]), fontsize=10)
    if image is not None:
        fig.colorbar(image, ax=grid, label=metric_title(metric), shrink=0.8)
    return fig


def _panel(ax, sel: list[dict], xaxis: tuple, yaxis: tuple, metric: str, cmap, norm):
    """One heatmap of the rows sel (xaxis, yaxis: name and values); (its image, whether a cell
    has no value, whether a run was not bounded)."""
    from matplotlib.patches import Rectangle

    (x, xs), (y, ys) = xaxis, yaxis
    m = np.full((len(ys), len(xs)), np.nan)
    text: dict[tuple[int, int], tuple[str, str]] = {}
    novalue = np.ones((len(ys), len(xs)), dtype=bool)  # no run here has a value
    missing = unbounded = False
    xi = {label(v): i for i, v in enumerate(xs)}
    yi = {label(v): i for i, v in enumerate(ys)}
    for r in sel:
        j, i = xi[label(r[x])], yi[label(r[y])]
        if r.get("status") == "ok" and r.get(metric) is not None:
            m[i, j], novalue[i, j] = r[metric], False
            text[i, j] = (f"{r[metric]:.3g}", "white")
        elif r.get("status") == "ok":
            text[i, j] = ("-", "0.3")
        else:
            novalue[i, j], unbounded = False, True
            t_end = r.get("t_end_s")
            text[i, j] = (f"{t_end:.2g}s" if t_end is not None else "fail", "#ff8080")
            m[i, j] = np.nan
    image = ax.imshow(np.ma.masked_invalid(m), origin="lower", aspect="auto", cmap=cmap, norm=norm)
    for i, j in zip(*np.nonzero(novalue), strict=True):  # grey, hatched: no value
        missing = True
        ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, facecolor=NO_VALUE,
                               edgecolor="0.6", hatch="//", lw=0))  # fmt: skip
    if len(xs) <= 14 and len(ys) <= 12:
        for (i, j), (s, colour) in text.items():
            ax.text(j, i, s, ha="center", va="center", fontsize=7, color=colour)
    ax.set_xticks(range(len(xs)), [label(v) for v in xs], fontsize=8, rotation=45)
    ax.set_yticks(range(len(ys)), [label(v) for v in ys], fontsize=8)
    ax.set_xlabel(x, fontsize=9)
    ax.set_ylabel(y, fontsize=9)
    return image, missing, unbounded
