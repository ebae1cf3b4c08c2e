"""The controller FMU: velocity observer (eq. 9) + impedance law (eq. 10) + virtual trajectory."""
