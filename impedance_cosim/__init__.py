"""Impedance control without velocity measurements, as FMI co-simulation components.

The Python API: `impedance_cosim.simulate(...)` runs a scenario and returns a `Result` (signals,
summary, provenance); `impedance_cosim.sweep(...)` runs it over values of one parameter (see
impedance_cosim/api.py).

This package's model modules (physics, fmi) and this file are bundled into the FMUs and must
import nothing beyond the standard library (and pythonfmu in fmi.fmi2_slave): the API is imported
only when first used (module __getattr__), so `import impedance_cosim` stays light. The version
lives in impedance_cosim/version.py: lower layers read it there, never from this facade.
"""

from impedance_cosim.version import __version__

_API = ("simulate", "sweep", "Result", "RunFailedError", "MasterError", "SspError", "Divergence")
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    """The API's names (simulate, sweep, Result and the errors it raises) from impedance_cosim.api,
    imported on first use."""
    if name in _API:
        from impedance_cosim import api

        return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
