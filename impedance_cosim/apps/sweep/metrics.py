"""What a sweep measures per run: analysis.summary()'s numbers flattened, plus the tracking error
in contact, the time of first contact and the x-velocity jitter in free motion. None where a
metric is not defined (e.g. no contact) or not finite."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from impedance_cosim.cosim.master.master import RunResult

METRICS = (
    "t_end_s",
    "contact_start_s",
    "impact_peak_N",
    "impact_peak_time_s",
    "settled_force_N",
    "tracking_error_before_contact_m",
    "tracking_error_in_contact_m",
    "observer_error_max_m_s",
    "observer_error_rms_after_2s_m_s",
    "peak_torque_N_m",
    "peak_torque1_N_m",
    "peak_torque2_N_m",
    "peak_torque3_N_m",
    "xd_jitter_m_s",
)

# What each metric is, with its unit, for the maps' titles and colour bars.
METRIC_TITLES = {
    "t_end_s": "time the run ended (s)",
    "contact_start_s": "time of first contact (s)",
    "impact_peak_N": "impact peak of the contact force (N)",
    "impact_peak_time_s": "time of the impact peak (s)",
    "settled_force_N": "settled contact force (N)",
    "tracking_error_before_contact_m": "tracking error before contact (m)",
    "tracking_error_in_contact_m": "largest tracking error in contact, |e_y| (m)",
    "observer_error_max_m_s": "largest observer error (m/s)",
    "observer_error_rms_after_2s_m_s": "observer error, RMS after 2 s (m/s)",
    "peak_torque_N_m": "peak joint torque (N m)",
    "peak_torque1_N_m": "peak torque, joint 1 (N m)",
    "peak_torque2_N_m": "peak torque, joint 2 (N m)",
    "peak_torque3_N_m": "peak torque, joint 3 (N m)",
    "xd_jitter_m_s": "x-velocity jitter in free motion (m/s)",
}


def metric_title(metric: str) -> str:
    """A metric as a reader sees it ("settled contact force (N)"); unknown names as they are."""
    return METRIC_TITLES.get(metric, metric)


def _finite(v: Any) -> Any:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def run_metrics(s: RunResult) -> dict[str, Any]:
    """The metrics of a finished run (see the module docstring)."""
    from impedance_cosim.apps import analysis

    values = analysis.summary(s)
    t, force = s["time"], s["plant.contact_force"]
    out: dict[str, Any] = {m: None for m in METRICS}
    out["t_end_s"] = float(t[-1])
    for key in (
        "impact_peak_N",
        "impact_peak_time_s",
        "settled_force_N",
        "tracking_error_before_contact_m",
        "observer_error_max_m_s",
        "observer_error_rms_after_2s_m_s",
    ):
        out[key] = _finite(values.get(key))
    phases = values["contact_phases_s"]
    out["contact_start_s"] = float(phases[0][0]) if phases else None
    touching = force > 0
    if touching.any():
        ey = analysis.at_samples(s, "controller.e_y")
        out["tracking_error_in_contact_m"] = _finite(np.abs(ey[touching]).max())
    torques = values["peak_torque_N_m"]
    for i, v in enumerate(torques, start=1):
        out[f"peak_torque{i}_N_m"] = _finite(v)
    out["peak_torque_N_m"] = _finite(max(torques))
    free = t >= 2.0
    for a, b in phases:
        free &= (t < a - 0.5) | (t > b + 0.5)
    pairs = free[:-1] & free[1:]
    if pairs.sum() > 10:
        out["xd_jitter_m_s"] = _finite(np.std(np.diff(s["plant.xd"])[pairs]))
    return out
