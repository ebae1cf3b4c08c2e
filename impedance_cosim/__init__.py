"""Impedance control without velocity measurements, as FMI co-simulation components.

This package's model modules (arm, wall, ode, linalg3, fmi) are bundled into the FMUs and must
import nothing beyond the standard library (and pythonfmu in fmi.slave).
"""

__version__ = "0.1.0"
