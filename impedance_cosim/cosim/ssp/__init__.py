"""Reading SSP 1.0 and 2.0 archives into plain data (read), with the elements of each version
(ssp1, ssp2) and the archive's own safety checks (archive)."""
