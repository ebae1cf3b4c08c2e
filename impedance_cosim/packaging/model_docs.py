"""What each model is, with its equations, for the FMU documentation (documentation.py).

The equations are the paper's (Impedance Control Without Using Velocity Measurements), corrected
per shared/paper/ERRATA.md, in plain HTML with Unicode; the numbers are the FMU's own parameter
start values (the section 5 values), read from its modelDescription.
"""

from __future__ import annotations

import html


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

PLANT = """
<p>The plant: the arm above against a stiff frictionless wall, with joint encoders and a wrist
force/torque sensor. Joint torques τ₁..τ₃ in; measured joint angles and wrist force/torque out,
plus truth signals (angles, velocities, end-effector pose and velocity, contact force,
penetration) for analysis.</p>
{arm}
<p><b>Wall</b> (fills x ≥ x<sub>w</sub>, pushes only while penetrated, never pulls):</p>
<p class="eq">F<sub>ext</sub> = (f<sub>x</sub>, 0, 0), &nbsp;
f<sub>x</sub> = max(0, k (x − x<sub>w</sub>) + d ẋ) for x &gt; x<sub>w</sub>, else 0</p>
<p>Numbers: {wall} (the target force of the paper's scenario is 10⁴ N/m × 0.00196 m =
19.6 N).</p>
<p><b>Sensors.</b> Encoders: q<sub>meas</sub> = Q(q + n), n Gaussian with standard deviation
<code>q_noise</code> (seeded by <code>noise_seed</code>, reproducible), Q rounding to multiples of
<code>q_quant</code>; both 0 (off) by default. Wrist sensor: (fx, fy, n) = F<sub>ext</sub>, the
force the end effector exerts on the environment (F<sub>au</sub> of the controller), fy = n = 0
for the frictionless point contact.</p>
<p><b>Initial state.</b> At rest at the pose (x0, y0, phi0) = (0.3 m, 0 m, 0 rad) by inverse
kinematics, elbow above the shoulder-wrist line when <code>elbow_up</code> (q₂ &lt; 0).</p>
<p><b>In robotics tools.</b> The same arm as MJCF (MuJoCo) and URDF, written from these
parameters by <code>impedance-cosim build</code> (fmus/robot/puma3.xml, puma3.urdf): link i's
frame on joint i, x along the link, every joint about +z; I<sub>u</sub> as the inertia about each
link's centre of mass (r<sub>x</sub>, r<sub>y</sub>); I<sub>m</sub> as rotor inertia (MJCF
<code>armature</code>; URDF has none: Pinocchio's <code>model.armature</code>); F as joint damping;
gravity (0, −g, 0) (URDF: set after loading); the tool point as site/frame <code>tool</code>; the
wall as a fixed body at x<sub>w</sub>; the elbow-up start as MJCF keyframe
<code>elbow_up</code>. Checked against this model to 10⁻¹⁰ (the project's docs/robotics.md).</p>
<p><b>Integration.</b> Each doStep holds the torque and integrates (1) with an adaptive
Dormand-Prince 5(4) (tolerances <code>rtol</code>, <code>atol</code>) that stops exactly where the
contact closes or opens, so results do not depend on the communication step.</p>
"""

CONTROLLER = """
<p>The controller: the reduced-order velocity observer, eq. (9), and the impedance law, eq. (10),
sampled every Δ = <code>sample_period</code> (the paper: 400 Hz), outputs held between samples
(zero-order hold). Measured joint angles q and wrist force/torque F<sub>au</sub> = (fx, fy, n) in;
joint torques out. It never sees the joint velocity (unless <code>velocity_source</code> =
measured, a baseline for comparisons). It carries its own copy of the arm model (its own
parameters, so model mismatch can be studied):</p>
{arm}
<p><b>Virtual trajectory</b> (section 5): the ellipse</p>
<p class="eq">x<sub>v</sub>(t) = (c<sub>x</sub> + a<sub>x</sub> sin(2πft − π/2),
c<sub>y</sub> + a<sub>y</sub> cos(2πft − π/2), φ<sub>v</sub>)</p>
<p>with x switched to x<sub>w</sub> + depth (zero x-velocity and acceleration) wherever the
ellipse's x ≥ x<sub>w</sub>. Numbers: {traj}.</p>
<p><b>Observer</b>, eq. (9), with ŷ<sub>i</sub> the joint-velocity estimate at sample i:</p>
<p class="eq">ŷ<sub>i</sub> = ŷ<sub>i−1</sub> + K(q<sub>i</sub> − q<sub>i−1</sub>)
+ Δ H⁻¹(q<sub>i−1</sub>)[τ<sub>i−1</sub> − C(q<sub>i−1</sub>, ŷ<sub>i−1</sub>)ŷ<sub>i−1</sub>
− Fŷ<sub>i−1</sub> − g(q<sub>i−1</sub>) − Jᵀ(q<sub>i−1</sub>)F<sub>au,i−1</sub>]
− ΔKŷ<sub>i−1</sub> &nbsp; (9)</p>
<p>τ<sub>i−1</sub> is the torque applied over the last period. K = diag(K1, K2, K3);
ŷ(0) = (yhat0_1, yhat0_2, yhat0_3). Backward difference (Fig. 4's baseline, always computed):
q̇<sub>diff,i</sub> = (q<sub>i</sub> − q<sub>i−1</sub>)/Δ.</p>
<p><b>Impedance law</b>, eq. (10), with e = x − x<sub>v</sub> and the observed Cartesian
velocity J(q)ŷ (C<sub>x</sub> evaluated at ŷ, errata):</p>
<p class="eq">τ = Jᵀ F<sub>e</sub>, &nbsp;
F<sub>e</sub> = F<sub>au</sub> + H<sub>x</sub>ẍ<sub>v</sub>
+ C<sub>x</sub>(q, ŷ)ẋ<sub>v</sub> + F<sub>x</sub>ẋ<sub>v</sub> + g<sub>x</sub>(q)
− B(Jŷ − ẋ<sub>v</sub>) − Ge &nbsp; (10)</p>
<p>computed in joint space (Jᵀ H<sub>x</sub> = H J⁻¹ etc.). Eq. (10) needs J⁻¹: at a singular J
(|sin q₂| &lt; 10⁻⁶) initialization still succeeds, whatever finite inputs the host gave (zeros
are q₂ = 0), with τ = g(q), gravity compensation only, as sample 0 and a warning in the log; a
step that samples at a singular pose is refused (its time and q in the message).
G = diag(G1, G2, G3), B = diag(B1, B2, B3). Numbers: {gains}. The velocity fed to the law is
chosen by <code>velocity_source</code>: observer (the paper), difference or measured.
Optional torque limits (<code>limit_torque</code>): the observer then uses the clipped torque.</p>
"""

PINOCCHIO = """
<p><b>PinocchioPlant</b> is PumaPlant below with the arm's forward dynamics (ABA), the tool
point's position and Jacobian computed by Pinocchio from the URDF it carries (puma3.urdf, in
resources/…/carried_files.py), its numbers set from the parameters (the motor inertias as
<code>model.armature</code>, gravity along −y): a second, independent plant to swap in. It needs
Pinocchio (<code>pip install pin==4.1.0</code>) and numpy in the Python that runs it; without
them instantiation fails, saying so. The wall, sensors and integrator are PumaPlant's.
Under <code>fmpy simulate</code> the process usually aborts at its exit (glibc: "corrupted
double-linked list") after the result file is complete: pythonfmu 0.7's exit-time defect,
which Pinocchio's libraries make likely; hosts that leave with <code>os._exit</code> after their
clean-up (impedance-cosim swap) are not affected.</p>
"""

MUJOCO = """
<p><b>MujocoPlant</b> has PumaPlant's interface, simulated by MuJoCo from the MJCF it carries
(puma3_mujoco.xml, in resources/…/carried_files.py): RK4 with ceil(h / <code>timestep</code>)
equal steps per communication step, the wall as MuJoCo contact whose direct <code>solref</code>
(−(1−i)·wall_k·Ā, −(1−i)·wall_d·Ā; i = 1e-4 the contact's fixed impedance, Ā MuJoCo's
approximate inverse mass of the hand) makes its force PumaPlant's wall law plus MuJoCo's small
acceleration term (within 2.1 mN in the paper scenario), the wrist force/torque from MuJoCo's
force and torque sensors at site <code>wrist</code>. It needs MuJoCo (<code>pip install
mujoco==4.0.0</code>) and numpy in the Python that runs it; without them instantiation fails,
saying so. The arm and wall below are its numbers; PumaPlant's integrator parameters are not
parameters here.</p>
"""

BRIDGE = """
<p>A hardware-in-the-loop bridge with PumaPlant's interface (the same parameters, inputs and
outputs). It simulates nothing: at initialization it sends the plant parameters to an external
robot process (INIT) and takes the initial outputs from its reply; each doStep sends the joint
torques (STEP, sequence numbers 1, 2, ...) over UDP and returns the outputs the robot reports
after the step. A lost, late or out-of-sequence reply or a robot that is gone makes doStep
return fmi2Discard with the cause logged; every wait is bounded (<code>timeout_s</code>,
<code>init_timeout_s</code>). The plant model the robot runs is PumaPlant's:</p>
{arm}
"""


def model_section(model_name: str, starts: dict[str, dict[str, str]]) -> str:
    """The 'what the model is' part of index.html for a model, with its numbers."""
    arm = ARM.format(arm=_nums(starts, ARM_NAMES))
    if model_name in ("PumaPlant", "PinocchioPlant", "MujocoPlant"):
        page = PLANT.format(arm=arm, wall=_nums(starts, ["wall_x", "wall_k", "wall_d"]))
        intro = {"PinocchioPlant": PINOCCHIO, "MujocoPlant": MUJOCO}.get(model_name, "")
        return intro + page
    if model_name == "ImpedanceController":
        traj = _nums(starts, ["traj_cx", "traj_cy", "traj_ax", "traj_ay", "traj_f", "traj_phi",
                              "wall_x", "wall_depth"])  # fmt: skip
        gains = _nums(starts, ["K1", "K2", "K3", "G1", "G2", "G3", "B1", "B2", "B3",
                               "sample_period"])  # fmt: skip
        return CONTROLLER.format(arm=arm, traj=traj, gains=gains)
    if model_name == "BridgePlant":
        return BRIDGE.format(arm=arm)
    return ""
