"""Results: in memory and as CSV (result), as a MATLAB result file (mat), and how they were made
(provenance, run.json)."""
