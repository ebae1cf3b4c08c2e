"""Generated sources are the committed output of their generators (one source of truth)."""

from __future__ import annotations

import pytest

from impedance_cosim.packaging import cgen


def test_arm_terms_are_up_to_date():
    """impedance_cosim/physics/arm_terms.py and native/src/arm_terms.{c,h} regenerate byte for
    byte from the symbolic derivation (python -m impedance_cosim.physics.derivation)."""
    pytest.importorskip("sympy")
    from impedance_cosim.physics.derivation import generate

    for path, content in generate().items():
        assert path.read_text() == content, f"{path.name} is stale"


def test_native_configs_are_up_to_date():
    """native/<model>/config.h regenerate from the variable tables the Python FMUs use
    (python -m impedance_cosim.packaging.cgen)."""
    for path, content in cgen.generate().items():
        assert path.read_text() == content, f"{path} is stale"
