"""The applications on top of the runtime: run, hardware bridge and robot, sweeps, stability
study, analysis and figures."""
