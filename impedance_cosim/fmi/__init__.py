"""The shared FMI layer: variable tables, the model contract and the pythonfmu glue."""
