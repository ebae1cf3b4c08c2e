"""The arm, the wall and the integrator: plain numeric code, no FMI (shipped inside the Python
FMUs)."""
