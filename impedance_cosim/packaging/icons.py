"""model.png icons of the FMUs (FMI 2.0: an optional model.png at the archive root), drawn with
matplotlib. The bytes are reproducible: no text (no font dependence), no date, no Software
tag."""

from __future__ import annotations

import functools
import io
import math

SIZE_IN, DPI = 1.28, 100  # 128 x 128 pixels


def _figure():
    from matplotlib.figure import Figure  # no pyplot: no global state, no GUI backend

    fig = Figure(figsize=(SIZE_IN, SIZE_IN), dpi=DPI)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    ax.set_aspect("equal")
    return fig, ax


def _png(fig) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    return buf.getvalue()


def _arm(ax, with_wall: bool = True) -> None:
    """The 3-link arm at the paper's start pose (0.3 m, 0 m, 0 rad) and the wall at 0.65 m."""
    from matplotlib.patches import Rectangle

    from impedance_cosim.physics.arm import Arm, ArmParams

    p = ArmParams()
    q = Arm(p).inverse_kinematics((0.3, 0.0, 0.0), elbow_up=True)
    pts, angle, x, y = [(0.0, 0.0)], 0.0, 0.0, 0.0
    for length, qi in zip((p.a1, p.a2, p.a3), q):
        angle += qi
        x, y = x + length * math.cos(angle), y + length * math.sin(angle)
        pts.append((x, y))
    xs, ys = zip(*pts)
    ax.add_patch(Rectangle((-0.12, -0.5), 0.24, 0.08, color="0.35"))  # base
    ax.plot([0.0, 0.0], [-0.42, 0.0], color="0.35", lw=3)
    ax.plot(xs, ys, color="#1f5fa8", lw=4, solid_capstyle="round")
    ax.plot(xs[:-1], ys[:-1], "o", color="#f0a020", ms=5)
    if with_wall:
        ax.add_patch(Rectangle((0.65, -0.5), 0.12, 1.0, facecolor="0.8", edgecolor="0.3",
                               hatch="///", lw=1))  # fmt: skip
    ax.set_xlim(-0.2, 0.8)
    ax.set_ylim(-0.55, 0.45)


def _plant() -> bytes:
    fig, ax = _figure()
    _arm(ax)
    return _png(fig)


def _controller() -> bytes:
    from matplotlib.patches import Ellipse, FancyArrow, Rectangle

    fig, ax = _figure()
    ax.add_patch(Rectangle((0.15, 0.15), 0.7, 0.7, facecolor="#e8eef8", edgecolor="#1f5fa8", lw=2))
    ax.add_patch(Ellipse((0.45, 0.5), 0.3, 0.5, fill=False, edgecolor="#1f5fa8", lw=2))
    ax.plot([0.57, 0.57], [0.25, 0.75], color="0.3", lw=2)  # the wall cutting the ellipse
    for y in (0.35, 0.5, 0.65):
        ax.add_patch(FancyArrow(0.0, y, 0.13, 0.0, width=0.015, color="0.3"))
        ax.add_patch(FancyArrow(0.86, y, 0.12, 0.0, width=0.015, color="#f0a020"))
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.0)
    return _png(fig)


def _bridge() -> bytes:
    from matplotlib.patches import FancyArrow

    fig, ax = _figure()
    _arm(ax, with_wall=False)
    ax.add_patch(FancyArrow(0.45, 0.32, 0.25, 0.0, width=0.03, color="#f0a020"))
    ax.add_patch(FancyArrow(0.72, 0.2, -0.25, 0.0, width=0.03, color="#1f5fa8"))
    return _png(fig)


@functools.cache
def icon_png(model_name: str) -> bytes:
    """The model.png of a model (a plain block for an unknown one)."""
    draw = {"PumaPlant": _plant, "ImpedanceController": _controller, "BridgePlant": _bridge}
    return draw.get(model_name, _controller)()
