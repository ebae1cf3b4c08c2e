"""Where the Python models spend their time in the 20 s paper scenario (not a test): the plain
closed loop (impedance_cosim.cosim.master.plain_loop, no FMI) under cProfile, grouped by what the
code computes, with the number of plant right-hand-side evaluations per communication step.

    python benchmarks/model_profile.py [--stop 20]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

from impedance_cosim.cosim.master.plain_loop import run_models
from impedance_cosim.physics import ode

GROUPS = {  # (file suffix, function) -> group; everything else is "other"
    "arm dynamics H, C, g, solve (forward_dynamics; plant and observer)": [
        ("arm_terms.py", "forward_dynamics"),
    ],
    "plant: contact (end-effector x, wall force, event)": [
        ("plant_model/model.py", "_ee_x"),
        ("plant_model/model.py", "g"),
    ],
    "plant: integrator (Dormand-Prince stages, error norm, event location)": [
        ("ode.py", "integrate"),
    ],
    "controller: sample (observer, impedance law, trajectory)": [
        ("controller_model/model.py", "do_step"),
    ],
}


def error_norms(stop: float) -> list[float]:
    """The scaled error norm of every Dormand-Prince step the plant tries in the scenario: how
    much of its tolerance a step uses (a step of the communication step's length with a norm far
    below 1 would leave room for a cheaper method; near 1 it does not)."""
    norms: list[float] = []
    original = ode.error_norm

    def recording(*args):
        norms.append(original(*args))
        return norms[-1]

    ode.error_norm = recording
    try:
        run_models(stop_time=stop)
    finally:
        ode.error_norm = original
    return norms


def _timed(method, total: list[float]):
    """method, adding its wall time to total[0]."""

    def timed(self, *args):
        start = time.perf_counter()
        try:
            return method(self, *args)
        finally:
            total[0] += time.perf_counter() - start

    return timed


def fmi_layer(stop: float) -> tuple[float, float]:
    """(stepping s, s inside our Python FMI methods) of the best of 5 master runs (C loop) on the
    Python FMUs: the rest is pythonfmu's C++ layer, the compiled loop and the timers. The FMUs run
    their own module copies (packaging/isolate.py): their ModelSlave is patched once loaded."""
    import sys

    from impedance_cosim.cosim.master.master import Master
    from impedance_cosim.cosim.master.options import RunOptions
    from impedance_cosim.cosim.ssp.read import read_ssp
    from impedance_cosim.packaging.build import DEFAULT_OUT

    system = read_ssp(DEFAULT_OUT / "PaperScenario.ssp")
    Master(system, RunOptions(stop_time=0.01)).run()  # loads the FMUs' modules
    inside = [0.0]
    slaves = [m.ModelSlave for n, m in list(sys.modules.items()) if n.endswith(".fmi.fmi2_slave")]
    for cls in {c for c in slaves if c.__module__.startswith("impedance_cosim_")}:
        for name in ("do_step", "get_real", "set_real"):
            setattr(cls, name, _timed(getattr(cls, name), inside))
    best = (float("inf"), 0.0)
    for _ in range(5):
        inside[0] = 0.0
        result = Master(system, RunOptions(stop_time=stop, loop="c")).run()
        best = min(best, (result.info["stepping_s"], inside[0]))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stop", type=float, default=20.0)
    args = parser.parse_args()
    norms = error_norms(args.stop)
    start = time.process_time()
    run_models(stop_time=args.stop)
    plain = time.process_time() - start
    profile = cProfile.Profile()
    profile.runcall(run_models, stop_time=args.stop)
    stats = pstats.Stats(profile).stats  # (file, line, name) -> (cc, nc, tt, ct, callers)
    total = sum(tt for _, _, tt, _, _ in stats.values())

    def cumulative(file: str, name: str) -> tuple[float, int]:
        found = [(v[3], v[1]) for k, v in stats.items() if k[0].endswith(file) and k[2] == name]
        return (max(found)[0], max(found)[1]) if found else (0.0, 0)

    steps = round(args.stop * 400)
    plant_f = [
        v[1] for k, v in stats.items() if k[0].endswith("plant_model/model.py") and k[2] == "f"
    ]
    rhs = sum(plant_f)
    print(f"{args.stop:g} s scenario, {steps} steps: plain models {plain:.3f} s CPU "
          f"({args.stop / plain:.1f}x real time); under cProfile {total:.2f} s")  # fmt: skip
    print(f"plant right-hand sides: {rhs} ({rhs / steps:.1f} per communication step)")
    accepted = sorted(n for n in norms if n <= 1.0)
    print(f"integrator steps: {len(norms)} ({len(norms) - len(accepted)} rejected); error norm of "
          f"the accepted ones (1 = tolerance): median {accepted[len(accepted) // 2]:.3f}, "
          f"90% {accepted[int(0.9 * len(accepted))]:.3f}")  # fmt: skip
    print(f"{'share of the profiled time (cumulative, groups overlap where nested)':72} {'%':>5}")
    for group, members in GROUPS.items():
        ct = max(cumulative(f, n)[0] for f, n in members)
        print(f"{group:72} {100 * ct / total:5.1f}")
    stepping, inside = fmi_layer(args.stop)
    rest = 1e6 * (stepping - inside) / steps
    print(f"under our master (Python FMUs, C loop, best of 5): stepping {stepping:.3f} s, of which "
          f"{inside:.3f} s in our slaves' do_step/get_real/set_real; the rest (pythonfmu's C++ "
          f"layer, the loop, the timers): {rest:.1f} us per step")  # fmt: skip
    print("\ntop functions by own time:")
    ranked = sorted(stats.items(), key=lambda kv: -kv[1][2])[:12]
    for (file, line, name), (_, calls, tt, _ct, _) in ranked:
        where = "/".join(file.split("/")[-2:])
        print(f"  {100 * tt / total:5.1f}%  {calls:8d} calls  {name} ({where}:{line})")


if __name__ == "__main__":
    main()
