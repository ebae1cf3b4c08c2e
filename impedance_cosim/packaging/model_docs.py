"""What each model is, with its equations, for the FMU documentation (documentation.py).

The equations are the paper's (Impedance Control Without Using Velocity Measurements), corrected
per shared/paper/ERRATA.md, in plain HTML with Unicode; the numbers are the FMU's own parameter
start values (the section 5 values), read from its modelDescription.
"""

from __future__ import annotations

import html
from pathlib import Path


def _nums(starts: dict[str, dict[str, str]], names: list[str]) -> str:
    """'a1 = 0.432 m, ...' from the variables' start values and units."""
    out = []
    for n in names:
        v = starts.get(n)
        if v is None:
            continue
        unit = f" {v['unit']}" if v["unit"] and v["unit"] != "1" else ""
        out.append(f"<code>{html.escape(n)}</code> = {html.escape(v['start'])}{unit}")
    return ", ".join(out)


ARM_NAMES = ["a1", "a2", "a3", "m1", "m2", "m3", "rx1", "ry1", "rx2", "rx3", "Iu1", "Iu2", "Iu3",
             "Im1", "Im2", "Im3", "f1", "f2", "f3", "g"]  # fmt: skip

ARM = """
<p>The arm: a 3-DOF planar PUMA-560 subset in the vertical x-y plane (paper, section 5), gravity
along −y, relative joint angles q = (q₁, q₂, q₃), end-effector pose x = (x, y, φ). Equation (1):</p>
<p class="eq">H(q) q̈ + C(q, q̇) q̇ + F q̇ + g(q) = τ − Jᵀ(q) F<sub>ext</sub> &nbsp; (1)</p>
<p>with c₁ = cos q₁, c₁₂ = cos(q₁+q₂), c₁₂₃ = cos(q₁+q₂+q₃), c₂₃ = cos(q₂+q₃), s likewise:</p>
<p class="eq">x = a₁c₁ + a₂c₁₂ + a₃c₁₂₃, &nbsp; y = a₁s₁ + a₂s₁₂ + a₃s₁₂₃, &nbsp;
φ = q₁ + q₂ + q₃, &nbsp; ẋ = J(q) q̇</p>
<p class="eq">H₁₁ = I<sub>m1</sub> + I<sub>u1</sub> + I<sub>u2</sub> + I<sub>u3</sub>
+ m₁(r<sub>x1</sub>² + r<sub>y1</sub>²) + m₂(a₁² + r<sub>x2</sub>² + 2a₁r<sub>x2</sub>c₂)
+ m₃(a₁² + a₂² + r<sub>x3</sub>² + 2a₁a₂c₂ + 2a₁r<sub>x3</sub>c₂₃ + 2a₂r<sub>x3</sub>c₃)<br>
H₁₂ = I<sub>u2</sub> + I<sub>u3</sub> + m₂(r<sub>x2</sub>² + a₁r<sub>x2</sub>c₂)
+ m₃(a₂² + r<sub>x3</sub>² + a₁a₂c₂ + a₁r<sub>x3</sub>c₂₃ + 2a₂r<sub>x3</sub>c₃)<br>
H₁₃ = I<sub>u3</sub> + m₃(r<sub>x3</sub>² + a₁r<sub>x3</sub>c₂₃ + a₂r<sub>x3</sub>c₃)<br>
H₂₂ = I<sub>m2</sub> + I<sub>u2</sub> + I<sub>u3</sub> + m₂r<sub>x2</sub>²
+ m₃(a₂² + r<sub>x3</sub>² + 2a₂r<sub>x3</sub>c₃)<br>
H₂₃ = I<sub>u3</sub> + m₃(r<sub>x3</sub>² + a₂r<sub>x3</sub>c₃), &nbsp;
H₃₃ = I<sub>m3</sub> + I<sub>u3</sub> + m₃r<sub>x3</sub>², &nbsp; H symmetric</p>
<p class="eq">g₁ = m₁g(r<sub>x1</sub>c₁ − r<sub>y1</sub>s₁) + m₂g(a₁c₁ + r<sub>x2</sub>c₁₂)
+ m₃g(a₁c₁ + a₂c₁₂ + r<sub>x3</sub>c₁₂₃), &nbsp;
g₂ = m₂g r<sub>x2</sub>c₁₂ + m₃g(a₂c₁₂ + r<sub>x3</sub>c₁₂₃), &nbsp;
g₃ = m₃g r<sub>x3</sub>c₁₂₃</p>
<p class="eq">J = [−(a₁s₁ + a₂s₁₂ + a₃s₁₂₃), −(a₂s₁₂ + a₃s₁₂₃), −a₃s₁₂₃;
a₁c₁ + a₂c₁₂ + a₃c₁₂₃, a₂c₁₂ + a₃c₁₂₃, a₃c₁₂₃; 1, 1, 1], &nbsp;
F = diag(f₁, f₂, f₃)</p>
<p>C(q, q̇) is the Christoffel form of H (the printed C₁₁ is wrong, errata:
C₁₁ = −m₂a₁r<sub>x2</sub>q̇₂s₂ − m₃[a₁a₂q̇₂s₂ + a₁r<sub>x3</sub>(q̇₂+q̇₃)s₂₃
+ a₂r<sub>x3</sub>q̇₃s₃]). Corrections to the printed model (errata): the first inertia triple
is the link inertias I<sub>u1..3</sub>, the second the motor inertias I<sub>m1..3</sub> on the
diagonal of their own joint; H₂₂ and H₃₃ use I<sub>m2</sub> and I<sub>m3</sub>. All terms are
generated from one symbolic Lagrangian derivation and checked against independent ones.</p>
<p>Section 5 numbers (parameter start values): {arm}.</p>
"""


MODELS = Path(__file__).resolve().parents[2]  # beside impedance_cosim: plant_model/, ...
# the numbers each page may show ({arm} is the arm's section, shared by every model)
NUMBERS = {
    "wall": ["wall_x", "wall_k", "wall_d"],
    "traj": ["traj_cx", "traj_cy", "traj_ax", "traj_ay", "traj_f", "traj_phi", "wall_x",
             "wall_depth"],
    "gains": ["K1", "K2", "K3", "G1", "G2", "G3", "B1", "B2", "B3", "sample_period"],
}  # fmt: skip


def model_file(model_name: str, suffix: str) -> str | None:
    """The text of <model folder>/<model name><suffix> (a model's own documentation sources live
    beside its Python model and reference result), or None where the model has none."""
    for path in sorted(MODELS.glob(f"*_model/{model_name}{suffix}")):
        return path.read_text(encoding="utf-8")
    return None


def model_section(model_name: str, starts: dict[str, dict[str, str]]) -> str:
    """The 'what the model is' part of index.html for a model, with its numbers: its page source
    with {arm}, {wall}, {traj}, {gains} filled in, and {plant} with PumaPlant's page (the pages of
    the plants that have PumaPlant's interface build on it)."""
    source = model_file(model_name, ".html")
    if source is None:
        return ""
    values = {key: _nums(starts, names) for key, names in NUMBERS.items()}
    values["arm"] = ARM.format(arm=_nums(starts, ARM_NAMES))
    if "{plant}" in source:
        values["plant"] = model_section("PumaPlant", starts)
    return source.format(**values)
