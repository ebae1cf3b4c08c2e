"""Running our archives in other engines, to cross-check the master: libcosim, ecospy and fmpy
(others), a container FMU (container), the plant's interfaces replayed (replay)."""
