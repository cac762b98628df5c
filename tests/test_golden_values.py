"""Every shipped case's responses, gradients (direct and adjoint), final state and counters over
its first steps are bit-identical to the values stored in tests/golden_values.json
(scripts/golden_values.py): a restructuring of the code shows that no number moved.  A change
that is meant to move numbers rewrites the file (``python scripts/golden_values.py --write``)
and says why in its commit and, for users, in CHANGELOG.md."""
from __future__ import annotations

import json

import pytest

import scripts_path  # noqa: F401  (puts scripts/ on the path)
from golden_values import CASES, GOLDEN, case_values, methods


@pytest.mark.parametrize("path", sorted(CASES.glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_case_values_are_bit_identical_to_the_stored_ones(path) -> None:
    stored = json.loads(GOLDEN.read_text(encoding="utf-8"))
    for method in methods(path):
        key = f"{path.stem}/{method}"
        assert key in stored, f"{key} has no stored values: run scripts/golden_values.py --write"
        now = case_values(path, method)
        for field in ("status", "method", "steps", "counters", "final_q"):
            assert now[field] == stored[key][field], f"{key}: {field}"
        assert now["responses"] == stored[key]["responses"], f"{key}: responses"
