"""What the paper states about its simulation (section 5, Figs. 1-4), where it says so, and how
a run's record (run.json's entry: parameters, summary) shows the same quantity: the left and
right columns of report.html's table."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from impedance_cosim.apps.analysis import TARGET_FORCE
from impedance_cosim.cosim.system.paper import PAPER_PARAMETERS

Run = Mapping[str, Any]


@dataclass(frozen=True)
class Claim:
    """One thing the paper states about its simulation, where it says so, and what a run shows
    for it (measured(main run, all runs) -> text, None when the run has nothing to say)."""

    quantity: str
    paper: str
    source: str
    measured: Callable[[Run, Sequence[Run]], str | None]


def _param(run: Run, name: str) -> Any:
    comp, _, var = name.partition(".")
    return run["parameters"][comp][var]


def _as_paper(run: Run, names: Sequence[str], text: str) -> str:
    """text, and whether the run's values of names are the paper's."""
    same = all(_param(run, n) == PAPER_PARAMETERS[n] for n in names)
    return f"{text} ({'as in the paper' if same else 'NOT the paper'})"


def _rate(run: Run, _runs: Sequence[Run]) -> str:
    return f"{1 / run['step_size']:.4g} Hz ({run['algorithm']})"


def _gains(run: Run, _runs: Sequence[Run]) -> str:
    names = [f"controller.{sym}{i}" for sym in "KGB" for i in (1, 2, 3)]
    values = {sym: [f"{_param(run, f'controller.{sym}{i}'):.4g}" for i in (1, 2, 3)]
              for sym in "KGB"}  # fmt: skip
    text = "; ".join(f"{k} = {', '.join(dict.fromkeys(v))}" for k, v in values.items())
    return _as_paper(run, names, text)


def _wall(run: Run, _runs: Sequence[Run]) -> str:
    names = ["plant.wall_x", "plant.wall_k", "controller.wall_depth"]
    x, k, depth = (_param(run, n) for n in names)
    return _as_paper(run, names, f"x = {x} m, {k:g} N/m, {depth} m inside")


def _start(run: Run, _runs: Sequence[Run]) -> str:
    names = ["plant.x0", "plant.y0"]
    return _as_paper(run, names, f"({_param(run, names[0])} m, {_param(run, names[1])} m)")


def _settled(run: Run, _runs: Sequence[Run]) -> str:
    s = run["summary"]
    if "settled_force_N" not in s:
        phases = s.get("contact_phases_s") or []
        if not phases:
            return "no contact with the wall in this run"
        a, b = phases[0]
        return f"not settled (contact {a:.2f}-{b:.2f} s)"
    f = s["settled_force_N"]
    return f"{f:.2f} N settled ({100 * (f - TARGET_FORCE) / TARGET_FORCE:+.1f} %)"


def _impact(run: Run, _runs: Sequence[Run]) -> str:
    s = run["summary"]
    if "impact_peak_N" not in s:
        return "no contact with the wall in this run"
    phases = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in s["contact_phases_s"])
    return f"peak {s['impact_peak_N']:.1f} N at {s['impact_peak_time_s']:.2f} s; contact {phases}"


def _observer(run: Run, _runs: Sequence[Run]) -> str:
    s = run["summary"]
    rms = s.get("observer_error_rms_after_2s_m_s")
    tail = "" if rms is None else f", rms after 2 s {rms:.5f} m/s"
    return f"max {s['observer_error_max_m_s']:.4f} m/s{tail}"


def _tracking(run: Run, _runs: Sequence[Run]) -> str:
    e = run["summary"]["tracking_error_before_contact_m"]
    return f"position error before contact (from 2 s): {1e3 * e:.2f} mm max"


def _torques(run: Run, _runs: Sequence[Run]) -> str:
    return "peaks " + ", ".join(f"{v:.1f}" for v in run["summary"]["peak_torque_N_m"]) + " N m"


def _difference(_run: Run, runs: Sequence[Run]) -> str | None:
    diff = [r for r in runs if r.get("parameters", {}).get("controller", {}).get(
        "velocity_source") in (2, "difference")]  # fmt: skip
    if not diff:
        return None
    return "; ".join(
        f"{r.get('scenario')} ({r.get('algorithm')}, {r.get('stop_time')} s): "
        + ("stays bounded" if r.get("status") == "ok" else f"{r.get('status')}: {r.get('error')}")
        for r in diff
    )


_P = PAPER_PARAMETERS
# fmt: off
PAPER: tuple[Claim, ...] = (  # what section 5 and Figs. 1-4 state: the one place in the code
    Claim("update frequency", f"{1 / _P['controller.sample_period']:.0f} Hz", "section 5", _rate),
    Claim("gains", "observer K = 50 I; controller G = 1000 I, B = 2 sqrt(1000) I", "section 5",
          _gains),
    Claim("wall", f"x = {_P['plant.wall_x']} m, stiffness {_P['plant.wall_k']:g} N/m, virtual "
          f"trajectory {_P['controller.wall_depth']} m inside", "section 5", _wall),
    Claim("start pose", f"end effector at ({_P['plant.x0']} m, {_P['plant.y0']} m)",
          "section 5, Fig. 1a", _start),
    Claim("contact force", f"{TARGET_FORCE:.1f} N (10^4 N/m x 0.00196 m)", "section 5, Fig. 1d",
          _settled),
    Claim("impact", "a tracking overshoot at contact (no value given)", "Fig. 1b, 1d", _impact),
    Claim("observer error", "tends to zero in x and y", "Fig. 2c, 2d", _observer),
    Claim("tracking", "follows the desired path; velocity errors from start-up, impact and "
          "separation", "Fig. 1a, Fig. 3", _tracking),
    Claim("joint torques", "well within a PUMA-560's capability (no values given)", "Fig. 1c",
          _torques),
    Claim("numerical differentiation in the loop", "unstable: the oscillations amplify",
          "Fig. 4b", _difference),
)
# fmt: on
PARAMETER_CLAIMS = (_rate, _gains, _wall, _start)  # what a run was given, not what it measured
