"""Each compiled function is compiled once per arithmetic (real, complex), not again because an
argument arrives read-only on one path and writeable on another: numba types the two as different
arrays, and the second compilation of the sparse multibody linearization cost about 85 s of the
suite (a driven mechanism's cached time coefficients were read-only, a free one's were not)."""
from __future__ import annotations

import sys
from collections import defaultdict

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.models.base import StepState
from dynsens.models.multibody import compiled

pytestmark = pytest.mark.skipif(not compiled.enabled(), reason="compiled kernel off (numba or DYNSENS_KERNEL)")


def _array_kind(t: object) -> object:
    """An argument type without its read-only and alignment flags."""
    return (str(t.dtype), t.ndim, t.layout) if hasattr(t, "ndim") and hasattr(t, "layout") else str(t)


def _duplicates() -> dict[str, list[str]]:
    """Dispatchers of dynsens holding two signatures that differ only in flags."""
    from numba.core.registry import CPUDispatcher
    out = {}
    for name, mod in list(sys.modules.items()):
        if not name.startswith("dynsens") or mod is None:
            continue
        for key, obj in list(vars(mod).items()):
            if isinstance(obj, CPUDispatcher) and obj.__module__ == name:
                groups = defaultdict(list)
                for sig in obj.signatures:
                    groups[tuple(_array_kind(t) for t in sig)].append(sig)
                bad = [str(s) for g in groups.values() if len(g) > 1 for s in g]
                if bad:
                    out[f"{name}.{key}"] = bad
    return out


def _linearize(name: str, x: np.ndarray) -> None:
    case = dynsens.load_case(CASES / f"{name}.yaml", ["model.linear_algebra=sparse"])
    model, tr = case.model, case.model.traits
    q0, qd0, p0 = model.initial_state(model.parameters(np.real(x)))
    s = StepState(q0, qd0, np.zeros(tr.n_q), np.zeros(tr.n_lam), p0, np.zeros(tr.n_p))
    model.linearize(0.3, s, model.parameters(x))


def test_a_driven_and_a_free_mechanism_share_the_compiled_linearization():
    # pendulum_projection's constraints carry time coefficients and shifts (kept per step time
    # by MultibodyModel.coefficients), bricard's none (constant arrays)
    for name, timed in (("bricard", False), ("pendulum_projection", True)):
        case = dynsens.load_case(CASES / f"{name}.yaml")
        assert bool(case.model.layout.coefs or case.model.layout.shifts) == timed
        x0 = case.x0
        for x in (x0, x0 + 1e-3j):
            _linearize(name, x)
    assert _duplicates() == {}
