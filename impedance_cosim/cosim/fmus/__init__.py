"""Loading and driving FMUs: FMI 2.0 (fmi2) and FMI 3.0 (fmi3) instances over fmpy, the checks on
an FMU file (files), instances reused from run to run (pool)."""
