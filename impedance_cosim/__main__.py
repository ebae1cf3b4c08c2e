"""`python -m impedance_cosim`: the same as the `impedance-cosim` command."""

from impedance_cosim.cli import entry

entry()
