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


def test_a_read_only_state_adds_no_compiled_kinematics():
    """A state that arrives as a read-only view (a broadcast batch, as the Python force elements'
    batched path makes) is evaluated by the kinematics already compiled for writeable arrays."""
    from dynsens.models.multibody.kernel import kernel_params
    from dynsens.models.multibody.kernel_compiled import CompiledKin
    case = dynsens.load_case(CASES / "bricard.yaml")
    model = case.model
    params = model.parameters(case.x0)
    q0, qd0, _ = model.initial_state(params)
    kp = kernel_params(model.layout, params)
    writeable = CompiledKin(model.layout, kp, q0[None, :], qd0[None, :], np.zeros((1, q0.size)))
    views = [np.broadcast_to(v, (1, q0.size)) for v in (q0, qd0, np.zeros(q0.size))]   # contiguous
    assert views[1].flags.c_contiguous and not views[1].flags.writeable
    read_only = CompiledKin(model.layout, kp, *views)
    np.testing.assert_array_equal(read_only.Lp[0], writeable.Lp[0])
    assert _duplicates() == {}
