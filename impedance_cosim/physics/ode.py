"""Adaptive Dormand-Prince 5(4) integration on plain-float state tuples, with event location.

Used inside the plant's do_step: the communication step is whatever the master chooses, so the
plant integrates with its own error control (rtol, atol) and stops exactly at state events
(contact closing or opening) so a mode switch never happens in the middle of a Runge-Kutta step.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

State = tuple[float, ...]
Rhs = Callable[[State], State]
EventFn = Callable[[State], float]

# Dormand & Prince (1980) RK5(4)7M tableau.
_A2 = 1 / 5
_A3 = (3 / 40, 9 / 40)
_A4 = (44 / 45, -56 / 15, 32 / 9)
_A5 = (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729)
_A6 = (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656)
_B = (35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)  # weights of k1, k3, k4, k5, k6
# Error weights (5th minus 4th order) for k1, k3, k4, k5, k6, k7.
_E = (71 / 57600, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40)

MIN_STEP = 1e-13  # s; a step this small means the solution is blowing up
MAX_STEPS = 200_000  # accepted + rejected steps per integrate() call


class IntegrationError(RuntimeError):
    """The integrator could not meet its tolerance (diverging or non-finite solution)."""


def dopri5_step(f: Rhs, y: State, h: float, k1: State) -> tuple[State, State, State]:
    """One Dormand-Prince step of size h from y (with k1 = f(y)).

    Returns (y_new, err, k7) where err is the local error estimate vector and k7 = f(y_new)
    (first-same-as-last: it is the next step's k1)."""
    return _stepper(len(y))(f, y, h, k1)


@functools.cache
def _stepper(n: int) -> Callable[[Rhs, State, float, State], tuple[State, State, State]]:
    """dopri5_step for states of length n, unrolled: each component's expression is written out
    (no loops or generators per stage, about 1.4x faster for n = 6). Every component is the same
    expression, in the same order, as the tableau applied component by component, so results are
    bit-identical for every n (tests/test_ode.py checks it against a loop-based reference)."""
    rows = [("k2", (_A2,)), ("k3", _A3), ("k4", _A4), ("k5", _A5), ("k6", _A6)]
    ks = ["k1", "k3", "k4", "k5", "k6"]  # the stages the 5th-order weights _B use
    lines = ["def step(f, y, h, k1):", f"    {_names('y', n)}, = y", f"    {_names('k1', n)}, = k1"]
    for r, (stage, coefs) in enumerate(rows):
        consts = [f"A{r}_{j}" for j in range(len(coefs))]
        if r == 0:  # y + h * _A2 * k1
            comps = [f"y_{i} + h * A0_0 * k1_{i}" for i in range(n)]
        else:
            comps = [
                f"y_{i} + h * ({' + '.join(f'{c} * k{j + 1}_{i}' for j, c in enumerate(consts))})"
                for i in range(n)
            ]
        lines.append(f"    {stage} = f(({', '.join(comps)},))")
        lines.append(f"    {_names(stage, n)}, = {stage}")
    b = " + ".join
    y_new = [f"y_{i} + h * ({b(f'B{j} * {k}_{i}' for j, k in enumerate(ks))})" for i in range(n)]
    lines += [f"    y_new = ({', '.join(y_new)},)", "    k7 = f(y_new)"]
    lines.append(f"    {_names('k7', n)}, = k7")
    es = [*ks, "k7"]
    err = [f"h * ({b(f'E{j} * {k}_{i}' for j, k in enumerate(es))})" for i in range(n)]
    lines += [f"    return y_new, ({', '.join(err)},), k7"]
    namespace: dict = {f"A{r}_{j}": c for r, (_, cs) in enumerate(rows) for j, c in enumerate(cs)}
    namespace.update({f"B{j}": c for j, c in enumerate(_B)})
    namespace.update({f"E{j}": c for j, c in enumerate(_E)})
    exec("\n".join(lines), namespace)  # noqa: S102 - source built above from the tableau only
    return namespace["step"]


def _names(stem: str, n: int) -> str:
    return ", ".join(f"{stem}_{i}" for i in range(n))


def euler_step(f: Rhs, y: State, h: float) -> State:
    """One explicit Euler step y + h f(y) (the plant's integrator = euler, a reproduction aid)."""
    k = f(y)
    return tuple(y[i] + h * k[i] for i in range(len(y)))


def error_norm(y: State, y_new: State, err: State, rtol: float, atol: float) -> float:
    """Max-norm of the local error scaled by atol + rtol * |y| (<= 1 means accept)."""
    worst = 0.0
    for yi, yn, ei in zip(y, y_new, err):
        scaled = abs(ei) / (atol + rtol * max(abs(yi), abs(yn)))
        if not scaled <= worst:  # also catches NaN
            worst = scaled if scaled == scaled else math.inf
    return worst


def integrate(
    f: Rhs,
    t0: float,
    y0: Sequence[float],
    t1: float,
    h: float,
    rtol: float,
    atol: float,
    event: EventFn | None = None,
    time_tol: float = 1e-12,
) -> tuple[float, State, float, bool]:
    """Integrate y' = f(y) from t0 to t1, or until event(y) turns positive.

    h is the initial step guess. Returns (t, y, h_next, hit): hit is True when the run stopped
    at an event, located within time_tol on the side where event(y) > 0, so that the caller can
    switch mode and continue from (t, y). Raises IntegrationError on failure."""
    t, y = t0, tuple(y0)
    k1 = f(y)
    g_prev = event(y) if event is not None else -1.0
    steps = 0
    while t1 - t > time_tol:
        steps += 1
        if steps > MAX_STEPS:
            raise IntegrationError(f"more than {MAX_STEPS} steps between t={t0} and t={t1}")
        h_try = min(h, t1 - t)
        y_new, err, k7 = dopri5_step(f, y, h_try, k1)
        norm = error_norm(y, y_new, err, rtol, atol)
        if norm > 1.0:
            if not math.isfinite(norm) and not all(map(math.isfinite, y)):
                raise IntegrationError(f"non-finite state at t={t}")
            h = h_try * max(0.2, 0.9 * norm**-0.2) if math.isfinite(norm) else 0.1 * h_try
            if h < MIN_STEP:
                raise IntegrationError(f"step size underflow at t={t} (h={h:.3g} s)")
            continue
        # Accepted. Propose the next step; a step clipped to reach t1 keeps the larger guess.
        h_next = h_try * min(5.0, 0.9 * norm**-0.2) if norm > 0.0 else 5.0 * h_try
        h = max(h, h_next) if h_try < h else h_next
        if event is not None and g_prev <= 0.0 and event(y_new) > 0.0:
            t_ev, y_ev = _locate(f, y, k1, h_try, g_prev, event, time_tol)
            return t + t_ev, y_ev, h, True
        t = t1 if h_try == t1 - t else t + h_try
        y, k1 = y_new, k7
        g_prev = event(y) if event is not None else -1.0
    return t1, y, h, False


def _locate(
    f: Rhs,
    y: State,
    k1: State,
    h: float,
    g0: float,
    event: EventFn,
    time_tol: float,
) -> tuple[float, State]:
    """Find the event time inside the step [t, t + h] by the Illinois method on the step size,
    re-stepping from y; return (offset into the step, state) just past the crossing (event > 0)."""
    lo, g_lo = 0.0, g0
    hi = h
    y_hi, _, _ = dopri5_step(f, y, hi, k1)
    g_hi = event(y_hi)
    side = 0
    for _ in range(100):
        if hi - lo <= time_tol:
            break
        s = hi - g_hi * (hi - lo) / (g_hi - g_lo)
        if not lo < s < hi:
            s = 0.5 * (lo + hi)
        y_s, _, _ = dopri5_step(f, y, s, k1)
        g_s = event(y_s)
        if g_s > 0.0:
            hi, g_hi, y_hi = s, g_s, y_s
            if side == 1:
                g_lo *= 0.5
            side = 1
        else:
            lo, g_lo = s, g_s
            if side == -1:
                g_hi *= 0.5
            side = -1
    return hi, y_hi
