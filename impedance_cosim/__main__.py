"""`python -m impedance_cosim`: the same as the `impedance-cosim` command."""

import sys

from impedance_cosim.cli import main

sys.exit(main())
