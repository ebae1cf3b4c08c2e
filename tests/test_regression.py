"""Fresh results against the reference results kept in the repository (*_ref.csv)."""

from __future__ import annotations

import pytest

from impedance_cosim.packaging.regression import REFERENCES, compare, read_csv


@pytest.mark.parametrize("path", list(REFERENCES), ids=lambda p: p.name)
def test_matches_reference_result(path):
    assert compare(REFERENCES[path](), read_csv(path), rtol=1e-9) == []


def test_comparison_can_fail():
    path = next(iter(REFERENCES))
    ref = read_csv(path)
    changed = {k: v.copy() for k, v in ref.items()}
    changed["x"][100] += 1e-3
    assert any(p.startswith("x:") for p in compare(changed, ref, rtol=1e-9))
