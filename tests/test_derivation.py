"""The generated arm terms (Python and C) are the committed output of the symbolic derivation."""

from __future__ import annotations

import pytest

pytest.importorskip("sympy")

from impedance_cosim.derivation import generate  # noqa: E402


def test_generated_files_are_up_to_date():
    """Regenerating from impedance_cosim/derivation.py gives the committed files byte for byte."""
    for path, content in generate().items():
        assert path.read_text() == content, (
            f"{path.name} is stale: python -m impedance_cosim.derivation"
        )
