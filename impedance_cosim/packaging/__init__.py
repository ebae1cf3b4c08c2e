"""Building the FMUs and the system archives: Python and native FMUs, documentation, reference
results, distribution."""
