"""The co-simulation runtime: SSP reader, system description, the master and its loops, FMU
loading, results, other engines."""
