"""`impedance-cosim stability`: where the loop stays stable (bisected boundaries, the linearised
loop, Fig. 4's conditions), built on the sweep's runs (apps.sweep): see docs/stability.md."""
