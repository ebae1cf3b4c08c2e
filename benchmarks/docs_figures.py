"""Which command writes each figure and table committed under docs/ (WRITERS, the one list that
docs/figures.md shows and tests/test_docs_figures.py checks), and regenerating them.

    python benchmarks/docs_figures.py run          # Figs. 1-4 and fig4_jacobi.png (about 1 min)
    python benchmarks/docs_figures.py mujoco       # Fig. 1 with MujocoPlant overlaid (~10 s)
    python benchmarks/docs_figures.py              # every docs file (stability ~3 min, the sweep
                                                   # study ~10 min on 2 cores)

Each command runs into a scratch folder (stability and the study write docs/ directly, as their
pages say); the file it writes there is copied to docs/ under the committed name.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"


@dataclass(frozen=True)
class Writer:
    """A command (argv after `impedance-cosim`, without --out) and the file it writes in its
    --out folder that docs/<name> is."""

    group: str
    argv: tuple[str, ...]
    writes: str
    script: str | None = None  # a benchmark script instead, told the file's path by --figure

    def command(self, out: str = "OUT") -> str:
        if self.script:
            return shlex.join(
                ["python", self.script, *self.argv, "--figure", f"{out}/{self.writes}"]
            )
        return shlex.join(["impedance-cosim", *self.argv, "--out", out])

    def program(self, out: str) -> list[str]:
        """The argv that runs it with this interpreter, writing into the folder out."""
        if self.script:
            return [sys.executable, str(REPO / self.script), *self.argv, "--figure",
                    str(Path(out) / self.writes)]  # fmt: skip
        return [sys.executable, "-m", "impedance_cosim", *self.argv, "--out", out]


RUN = ("run", "--no-progress")
JACOBI = ("run", "--algorithm", "jacobi", "--no-progress")
STABILITY = ("stability",)
STUDY = ("sweep", "--study")
WRITERS: dict[str, Writer] = {
    **{
        name: Writer("run", RUN, name)
        for name in (
            "fig1_position_force.png",
            "fig2_observer.png",
            "fig3_velocity_tracking.png",
            "fig4_observer_vs_difference.png",
        )
    },  # fmt: skip
    "fig4_jacobi.png": Writer("run", JACOBI, "fig4_observer_vs_difference.png"),
    **{
        name: Writer("stability", STABILITY, name)
        for name in (
            "boundaries.csv",
            "boundaries.png",
            "linear.csv",
            "spectral_radius.png",
            "fig4_conditions.csv",
            "fig4_candidates.png",
            "observer_discretization.csv",
        )
    },  # fmt: skip
    **{
        name: Writer("study", STUDY, name)
        for name in (
            "map_delay.csv",
            "map_delay.png",
            "map_gain.csv",
            "map_gain.png",
            "map_mismatch.csv",
            "map_mismatch.png",
            "map_mismatch_settled_force_N.png",
            "map_mismatch_tracking_error_in_contact_m.png",
            "map_noise.csv",
            "map_noise.png",
            "map_noise_settled_force_N.png",
            "map_quantization.csv",
            "map_quantization.png",
        )
    },  # fmt: skip
    "fig1_mujoco_overlay.png": Writer(
        "mujoco", (), "fig1_mujoco_overlay.png", script="benchmarks/mujoco_compare.py"
    ),
}


def regenerate(groups: set[str]) -> None:
    """Run each group's commands (once per command) and copy their files into docs/."""
    commands: dict[tuple[str | None, tuple[str, ...]], list[str]] = {}
    for name, w in WRITERS.items():
        if w.group in groups:
            commands.setdefault((w.script, w.argv), []).append(name)
    for names in commands.values():
        with tempfile.TemporaryDirectory(prefix="impcosim_docs_") as tmp:
            print(f"$ {WRITERS[names[0]].command(tmp)}", flush=True)
            done = subprocess.run(WRITERS[names[0]].program(tmp), check=False)
            if done.returncode not in (0, 3):  # 3: a run diverged (fig4_jacobi: the point)
                raise SystemExit(f"exit status {done.returncode}: {WRITERS[names[0]].command()}")
            for name in names:
                shutil.copyfile(Path(tmp) / WRITERS[name].writes, DOCS / name)
                print(f"  docs/{name}")


if __name__ == "__main__":
    chosen = set(sys.argv[1:]) or {w.group for w in WRITERS.values()}
    unknown = chosen - {w.group for w in WRITERS.values()}
    if unknown:
        raise SystemExit(f"unknown group(s) {sorted(unknown)}: run, stability, study, mujoco")
    regenerate(chosen)
