"""The paper's system, defined once (paper: components, connections, scenarios, its SSP 1.0 files)
and as SSP 2.0 (ssp2)."""
