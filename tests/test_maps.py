"""Sweep maps are readable: titled with what the metric is and its unit (not its column name),
and large enough to read at a glance."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import pytest

from impedance_cosim.apps.sweep.maps import plot_map
from impedance_cosim.apps.sweep.metrics import METRIC_TITLES, METRICS, metric_title


def _rows() -> list[dict]:
    return [
        {"system.rate": r, "controller.G1": g, "status": "ok" if r > 100 else "diverged",
         "t_end_s": 0.4, "settled_force_N": 19.6 + r / 1000 + g / 1e4}
        for r in (100, 200, 400, 800) for g in (500, 1000, 2000)
    ]  # fmt: skip


def test_every_metric_has_a_title_with_its_unit() -> None:
    assert set(METRIC_TITLES) == set(METRICS)
    for m in METRICS:
        assert metric_title(m) != m and metric_title(m).endswith(")"), m
    assert metric_title("nosuch") == "nosuch"


@pytest.mark.parametrize("axes", [["system.rate"], ["system.rate", "controller.G1"]])
def test_a_map_is_at_least_600_by_400_px_and_titled_in_words(
    tmp_path: Path, axes: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import matplotlib.figure

    titles: list[str] = []
    for name in ("suptitle", "colorbar"):
        original = getattr(matplotlib.figure.Figure, name)

        def spy(self, *a, _original=original, **k):
            titles.append(str(a[0] if a and isinstance(a[0], str) else k.get("label", "")))
            return _original(self, *a, **k)

        monkeypatch.setattr(matplotlib.figure.Figure, name, spy)
    rows = _rows() if len(axes) == 2 else [r for r in _rows() if r["controller.G1"] == 500]
    png = tmp_path / "map.png"
    plot_map(rows, axes, "settled_force_N", png)
    height, width = mpimg.imread(png).shape[:2]
    assert width >= 600 and height >= 400, (width, height)
    if len(axes) == 2:
        assert any("settled contact force (N)" in t for t in titles), titles


@pytest.mark.parametrize("axes", [["controller.K"], ["controller.K", "system.rate"]])
def test_a_metric_no_run_has_is_a_map_that_says_so(tmp_path: Path, axes: list[str]) -> None:
    """A random sweep over a log-spaced axis whose runs all end before contact: no value of the
    settled force anywhere (matplotlib refused to log-scale an empty axis: exit 2)."""
    rows = [{"controller.K": k, "system.rate": 200 + 40 * i, "status": "ok",
             "settled_force_N": None}
            for i, k in enumerate((5.0, 20.0, 80.0, 300.0, 500.0))]  # fmt: skip
    png = tmp_path / "empty.png"
    plot_map(rows, axes, "settled_force_N", png, mode="random")
    assert mpimg.imread(png).shape[1] >= 600


def _colour_share(png: Path, rgb: tuple[int, int, int]) -> float:
    """The share of a PNG's pixels that are exactly rgb (0-255)."""
    import numpy as np

    image = (mpimg.imread(png)[..., :3] * 255).round().astype(int)
    return float(np.all(image == rgb, axis=-1).mean())


def test_a_missing_value_is_grey_not_the_colour_of_not_bounded(tmp_path: Path) -> None:
    """Issue 35, item 5: the README's sweep (every run bounded, none in contact within 2 s) drew
    all its cells black, the colour the caption gives to "not bounded". A cell without a value
    is grey and hatched and says so; only runs that did not stay bounded are black."""
    axes = ["controller.K", "system.scenario"]
    grid = [(k, s) for k in (25.0, 50.0, 100.0) for s in ("observer", "difference")]
    png = tmp_path / "missing.png"
    rows = [{"controller.K": k, "system.scenario": s, "status": "ok", "settled_force_N": None}
            for k, s in grid]  # fmt: skip
    plot_map(rows, axes, "settled_force_N", png)
    assert _colour_share(png, (0, 0, 0)) < 0.02  # text only, no black cell
    assert _colour_share(png, (217, 217, 217)) > 0.15  # the grey of "no value"

    unbounded = tmp_path / "unbounded.png"
    rows = [{**r, "status": "diverged", "t_end_s": 0.5} for r in rows]
    plot_map(rows, axes, "settled_force_N", unbounded)
    assert _colour_share(unbounded, (0, 0, 0)) > 0.15
    assert _colour_share(unbounded, (217, 217, 217)) < 0.01


def test_the_caption_names_only_the_kinds_of_cells_drawn(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import matplotlib.figure

    titles: list[str] = []
    original = matplotlib.figure.Figure.suptitle

    def spy(self, t, **k):
        titles.append(t)
        return original(self, t, **k)

    monkeypatch.setattr(matplotlib.figure.Figure, "suptitle", spy)
    rows = _rows()
    rows[-1] = {**rows[-1], "status": "ok", "settled_force_N": None}
    plot_map(rows, ["system.rate", "controller.G1"], "settled_force_N", tmp_path / "m.png")
    plot_map([r for r in rows if r["status"] == "ok" and r["settled_force_N"] is not None],
             ["system.rate", "controller.G1"], "settled_force_N", tmp_path / "n.png")  # fmt: skip
    assert "not bounded" in titles[0] and "no value" in titles[0]
    assert "not bounded" not in titles[1] and "no value" in titles[1]  # the 100 row: no run
