"""The co-simulation master (master), its run options (options) and its stepping loops: the
compiled C loop (c_loop), real time (realtime), event-exact stepping (events), input
extrapolation (extrapolation), the checks before a run (setup), and the plain-model loop it is
checked against (plain_loop)."""
