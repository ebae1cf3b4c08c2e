"""The controller's parameters (section 5): the virtual trajectory, the observer and impedance
gains, the sampling, the velocity source fed to the impedance law and the torque limits; each
field becomes an FMU parameter with its unit, range and description."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from impedance_cosim.fmi.variables import Enumeration
from impedance_cosim.physics.arm import _p, check_fields

VELOCITY_SOURCES = ("observer", "difference", "measured")
OBSERVER_DISCRETIZATIONS = ("euler", "implicit", "exponential")
VELOCITY_SOURCE = Enumeration(
    "VelocitySource",
    "Joint velocity fed to the impedance law",
    (
        ("observer", "Reduced-order observer, eq. (9) (the paper)"),
        ("difference", "Backward difference of the measured joint angles (Fig. 4 baseline)"),
        ("measured", "The measured joint velocity, inputs qd_meas1..3 (ideal baseline)"),
    ),
)


# --- parameters ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrajectoryParams:
    """The virtual trajectory of section 5: an ellipse truncated by (and pushed into) the wall."""

    traj_cx: float = _p(0.5, "m", "Virtual-trajectory ellipse centre, x", tunable=True)
    traj_cy: float = _p(0.0, "m", "Virtual-trajectory ellipse centre, y", tunable=True)
    traj_ax: float = _p(0.2, "m", "Virtual-trajectory ellipse semi-axis along x", 0.0, tunable=True)
    traj_ay: float = _p(0.5, "m", "Virtual-trajectory ellipse semi-axis along y", 0.0, tunable=True)
    traj_f: float = _p(
        0.1, "Hz", "Virtual-trajectory frequency (one ellipse per 1/f)", 0.0, tunable=True
    )
    traj_phi: float = _p(0.0, "rad", "Virtual end-effector orientation (constant)", tunable=True)
    wall_x: float = _p(
        0.65, "m", "Where the ellipse's x reaches this, x_v switches into the wall", tunable=True
    )
    wall_depth: float = _p(
        0.00196,
        "m",
        "Depth of the switched x_v inside the wall (target force = k * depth)",
        0.0,
        tunable=True,
    )

    def validate(self) -> None:
        """Raise ValueError naming a non-finite or out-of-range setting."""
        check_fields(self)


B_DEFAULT = 2.0 * math.sqrt(1000.0)  # section 5: B = 2 sqrt(1000) I


@dataclass(frozen=True)
class ControllerParams:
    """Observer and impedance gains, sampling, velocity source and torque limits (section 5)."""

    K1: float = _p(
        50.0, "1/s", "Observer gain, joint 1 (K = diag(K1, K2, K3) > 0)", 0.0, tunable=True
    )
    K2: float = _p(50.0, "1/s", "Observer gain, joint 2", 0.0, tunable=True)
    K3: float = _p(50.0, "1/s", "Observer gain, joint 3", 0.0, tunable=True)
    G1: float = _p(
        1000.0, "N/m", "Impedance stiffness along x (G = diag(G1, G2, G3) > 0)", 0.0, tunable=True
    )
    G2: float = _p(1000.0, "N/m", "Impedance stiffness along y", 0.0, tunable=True)
    G3: float = _p(
        1000.0, "N.m/rad", "Impedance stiffness about the orientation phi", 0.0, tunable=True
    )
    B1: float = _p(
        B_DEFAULT,
        "N.s/m",
        "Impedance damping along x (B = diag(B1, B2, B3) > 0)",
        0.0,
        tunable=True,
    )
    B2: float = _p(B_DEFAULT, "N.s/m", "Impedance damping along y", 0.0, tunable=True)
    B3: float = _p(B_DEFAULT, "N.m.s/rad", "Impedance damping about phi", 0.0, tunable=True)
    sample_period: float = _p(1 / 400, "s", "Controller sample period (outputs held between)", 0.0)
    velocity_source: int = _p(
        1,
        "",
        "Joint velocity fed to the impedance law: 1 observer (eq. 9), 2 difference (backward"
        " difference of the measured angles) or 3 measured (inputs qd_meas1..3)",
        enumeration=VELOCITY_SOURCE,
    )
    observer_discretization: str = _p(
        "euler",
        "",
        "Observer update: euler (eq. 9 as printed, explicit; in the paper's loop at 400 Hz"
        " stable for K Ts <= 0.91), implicit (the -K yhat term implicit) or exponential (-K yhat"
        " integrated exactly over the sample; both stable for every K > 0)",
    )
    yhat0_1: float = _p(0.0, "rad/s", "Observer start value yhat(0), joint 1")
    yhat0_2: float = _p(0.0, "rad/s", "Observer start value yhat(0), joint 2")
    yhat0_3: float = _p(0.0, "rad/s", "Observer start value yhat(0), joint 3")
    limit_torque: bool = _p(False, "", "Clip the torque to +-tau_max (the observer uses the clip)")
    tau_max1: float = _p(200.0, "N.m", "Torque limit, joint 1 (when limit_torque)", 0.0)
    tau_max2: float = _p(100.0, "N.m", "Torque limit, joint 2 (when limit_torque)", 0.0)
    tau_max3: float = _p(50.0, "N.m", "Torque limit, joint 3 (when limit_torque)", 0.0)
    max_samples_per_step: int = _p(
        100_000,
        "",
        "Work bound of one communication step: most samples it may take; a longer step is"
        " refused (fmi2Discard)",
        1,
    )

    POSITIVE = (
        "K1", "K2", "K3", "G1", "G2", "G3", "B1", "B2", "B3",
        "sample_period", "tau_max1", "tau_max2", "tau_max3",
    )  # fmt: skip

    def validate(self) -> None:
        """Raise ValueError naming a gain or period that is not > 0, a non-finite value or an
        unknown velocity source (check_fields only checks min as >=)."""
        for name in self.POSITIVE:
            value = getattr(self, name)
            if math.isfinite(value) and not value > 0.0:
                raise ValueError(f"parameter {name} must be > 0 (got {value})")
        check_fields(self)
        try:
            VELOCITY_SOURCE.item(self.velocity_source)
        except ValueError as exc:
            raise ValueError(f"parameter velocity_source {exc}") from None
        if self.observer_discretization not in OBSERVER_DISCRETIZATIONS:
            raise ValueError(
                "parameter observer_discretization must be one of"
                f" {', '.join(OBSERVER_DISCRETIZATIONS)} (got {self.observer_discretization!r})"
            )


def source_by_value(parameters: dict[str, Any]) -> dict[str, Any]:
    """velocity_source given by item name (for callers of the plain model) as its value."""
    source = parameters.get("velocity_source")
    if not isinstance(source, str):
        return parameters
    try:
        return {**parameters, "velocity_source": VELOCITY_SOURCE.value(source)}
    except ValueError as exc:
        raise ValueError(f"parameter velocity_source {exc}") from None
