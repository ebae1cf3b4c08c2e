"""The robot description files against our model: MuJoCo loading the MJCF (and Pinocchio loading
the URDF) must give arm.py's H(q), g(q), C(q, qd) qd, J(q), forward kinematics and forward
dynamics at random states. An independent check of our dynamics (other libraries' rigid-body
algorithms on the bodies alone) and of the files. Needs the `robotics` extra (mujoco, pin).

    python -m impedance_cosim.packaging.robot_check [--poses N]   # prints the largest differences
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from impedance_cosim.physics.arm import Arm, ArmParams

TERMS = ("H", "g", "Cqd", "J", "fk", "qdd")  # the compared quantities, in this order


def random_states(n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """n random (q, qd, tau): angles over the whole circle, velocities to 3 rad/s, torques to
    50 N m (the paper's loop uses less)."""
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-math.pi, math.pi, 3), rng.uniform(-3.0, 3.0, 3),
             rng.uniform(-50.0, 50.0, 3)) for _ in range(n)]  # fmt: skip


def _ours(arm: Arm, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> dict[str, np.ndarray]:
    qt, qdt = tuple(q), tuple(qd)
    return {
        "H": np.array(arm.inertia(qt)),
        "g": np.array(arm.gravity(qt)),
        "Cqd": np.array(arm.coriolis(qt, qdt)) @ qd,
        "J": np.array(arm.jacobian(qt)),
        "fk": np.array(arm.kinematics(qt)),
        "qdd": np.array(arm.forward_dynamics(qt, qdt, tuple(tau))),
    }


def _difference(name: str, theirs: np.ndarray, ours: np.ndarray) -> float:
    diff = np.asarray(theirs, dtype=float) - ours
    if name == "fk":  # the angle phi modulo a turn
        diff[2] = (diff[2] + math.pi) % (2.0 * math.pi) - math.pi
    return float(np.abs(diff).max())


def mujoco_terms(
    model: Any, data: Any, q: np.ndarray, qd: np.ndarray, tau: np.ndarray
) -> dict[str, np.ndarray]:
    """Our terms as MuJoCo computes them for the MJCF model at one state."""
    import mujoco

    m, d = model, data
    tool = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "tool")
    d.qpos[:], d.qvel[:], d.qfrc_applied[:] = q, 0.0, 0.0
    mujoco.mj_forward(m, d)
    full, gravity = np.zeros((3, 3)), np.zeros(3)
    mujoco.mj_fullM(m, d, full)  # with the joints' armature
    mujoco.mj_rne(m, d, 0, gravity)  # zero velocity, no acceleration term: g(q)
    jacp, jacr = np.zeros((3, 3)), np.zeros((3, 3))
    mujoco.mj_jacSite(m, d, jacp, jacr, tool)
    pos, rot = d.site_xpos[tool].copy(), d.site_xmat[tool].reshape(3, 3)
    out_of_plane = max(abs(pos[2]), np.abs(jacp[2]).max(), np.abs(jacr[:2]).max())
    fk = np.array([pos[0], pos[1], math.atan2(rot[1, 0], rot[0, 0])])
    d.qvel[:], d.qfrc_applied[:] = qd, tau
    mujoco.mj_forward(m, d)  # qacc with the joints' damping as passive force
    bias = np.zeros(3)
    mujoco.mj_rne(m, d, 0, bias)  # C(q, qd) qd + g(q)
    return {"H": full, "g": gravity, "Cqd": bias - gravity,
            "J": np.vstack([jacp[0], jacp[1], jacr[2]]), "fk": fk, "qdd": d.qacc.copy(),
            "out_of_plane": np.array([out_of_plane])}  # fmt: skip


def mujoco_differences(
    mjcf_path: Path, params: ArmParams | None = None, poses: int = 200, seed: int = 1
) -> dict[str, float]:
    """The largest |MuJoCo - arm.py| of each term over `poses` random states (plus
    out_of_plane: the tool's largest z position or velocity, which must be 0)."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(mjcf_path))
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT  # the free arm (qdd)
    data = mujoco.MjData(model)
    return largest_differences(lambda q, qd, tau: mujoco_terms(model, data, q, qd, tau),
                        params, poses, seed)  # fmt: skip


def pinocchio_model(urdf_path: Path, params: ArmParams | None = None) -> Any:
    """Pinocchio's model of the URDF, completed with what URDF cannot say: the motor inertias
    (model.armature, kg m^2) and gravity along -y (model.gravity)."""
    import pinocchio as pin

    p = params if params is not None else ArmParams()
    model = pin.buildModelFromUrdf(str(urdf_path))
    model.armature = np.array([p.Im1, p.Im2, p.Im3])
    model.gravity = pin.Motion(np.array([0.0, -p.g, 0.0]), np.zeros(3))
    return model


def pinocchio_q(q: np.ndarray) -> np.ndarray:
    """Pinocchio's configuration of our joint angles: a URDF continuous joint is (cos q, sin q)."""
    return np.ravel([(math.cos(a), math.sin(a)) for a in q])


def pinocchio_terms(
    model: Any, data: Any, q: np.ndarray, qd: np.ndarray, tau: np.ndarray
) -> dict[str, np.ndarray]:
    """Our terms as Pinocchio computes them for the URDF model at one state. Its RNEA and ABA
    do not apply model.damping: the viscous friction is subtracted from tau here."""
    import pinocchio as pin

    qp, zero = pinocchio_q(q), np.zeros(3)
    upper = np.triu(pin.crba(model, data, qp))  # with model.armature on the diagonal
    gravity = pin.computeGeneralizedGravity(model, data, qp).copy()
    bias = pin.rnea(model, data, qp, qd, zero).copy()  # C(q, qd) qd + g(q)
    tool = model.getFrameId("tool")
    pin.framesForwardKinematics(model, data, qp)
    frame = data.oMf[tool]
    pos, rot = frame.translation.copy(), frame.rotation.copy()
    jac = pin.computeFrameJacobian(model, data, qp, tool, pin.LOCAL_WORLD_ALIGNED)
    out_of_plane = max(abs(pos[2]), np.abs(jac[2:5]).max())
    qdd = pin.aba(model, data, qp, qd, tau - model.damping * qd).copy()
    return {"H": upper + np.triu(upper, 1).T, "g": gravity, "Cqd": bias - gravity,
            "J": jac[[0, 1, 5]], "fk": np.array([pos[0], pos[1], math.atan2(rot[1, 0], rot[0, 0])]),
            "qdd": qdd, "out_of_plane": np.array([out_of_plane])}  # fmt: skip


def pinocchio_differences(
    urdf_path: Path, params: ArmParams | None = None, poses: int = 200, seed: int = 1
) -> dict[str, float]:
    """The largest |Pinocchio - arm.py| of each term over `poses` random states (plus
    out_of_plane, as mujoco_differences)."""
    model = pinocchio_model(urdf_path, params)
    data = model.createData()
    return largest_differences(lambda q, qd, tau: pinocchio_terms(model, data, q, qd, tau),
                        params, poses, seed)  # fmt: skip


def largest_differences(
    terms: Callable[[np.ndarray, np.ndarray, np.ndarray], dict[str, np.ndarray]],
    params: ArmParams | None,
    poses: int,
    seed: int,
) -> dict[str, float]:
    """The largest |terms(q, qd, tau) - arm.py's| of each term over random states."""
    arm = Arm(params)
    worst = dict.fromkeys((*TERMS, "out_of_plane"), 0.0)
    for q, qd, tau in random_states(poses, seed):
        theirs = terms(q, qd, tau)
        ours = _ours(arm, q, qd, tau)
        for name in TERMS:
            worst[name] = max(worst[name], _difference(name, theirs[name], ours[name]))
        worst["out_of_plane"] = max(worst["out_of_plane"], float(theirs["out_of_plane"][0]))
    return worst


def main(argv: list[str] | None = None) -> int:
    """Write the files for the plant's parameters into a temporary folder and print the
    differences per library and term."""
    from impedance_cosim.packaging.robot_files import MJCF_NAME, URDF_NAME, write_robot_files

    parser = argparse.ArgumentParser(prog="python -m impedance_cosim.packaging.robot_check",
                                     description=__doc__.split("\n\n")[0])  # fmt: skip
    parser.add_argument("--poses", type=int, default=200, help="random states (default 200)")
    args = parser.parse_args(argv)
    if args.poses < 1:
        parser.error(f"--poses must be >= 1 (got {args.poses})")
    try:
        import mujoco  # noqa: F401
        import pinocchio  # noqa: F401
    except ImportError as exc:
        print(f"robot_check: needs mujoco and pin ({exc}): pip install 'impedance-cosim[robotics]'",
              file=sys.stderr)  # fmt: skip
        return 1
    with tempfile.TemporaryDirectory(prefix="impcosim_robot_") as tmp:
        write_robot_files(Path(tmp))
        rows = {
            "MuJoCo (MJCF)": mujoco_differences(Path(tmp) / MJCF_NAME, poses=args.poses),
            "Pinocchio (URDF)": pinocchio_differences(Path(tmp) / URDF_NAME, poses=args.poses),
        }
    print(f"largest difference from arm.py over {args.poses} random states:")
    for library, worst in rows.items():
        print(f"  {library}: " + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
