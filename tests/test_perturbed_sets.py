"""The design partials' perturbed parameter sets, evaluated when read.

Each design variable's perturbed set is the model's parameters at x + h_j e_j (forward, central's
+ and −, complex's imaginary step), the same numbers as the whole list evaluated up front; a
run whose partials take coloured perturbations, and whose model's initial state does not depend
on the design, reads none of them (m = 1 000 per-element stiffnesses: 1 000 parameter
evaluations, ~0.1 s of an adjoint run, BENCHMARKS.md).  The structural model's initial-state
gradient is zero without initial conditions, and otherwise the numerical one, as before.
"""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from bench_peers import chain_case
from make_cases import duffing_chain
from dynsens.derivatives.partials import DesignPartials, PerturbedSets, initial_state_gradient
from dynsens.models.structural.model import StructuralModel


def _same_params(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("method", ["forward", "central", "complex"])
def test_each_perturbed_set_is_the_models_parameters_at_its_step(method):
    case = dynsens.load_case_dict(duffing_chain(6, t_end=0.01), "chain.yaml")
    partials = DesignPartials(case.model, case.x0, method)
    m, h, x = partials.m, partials.h, partials.x
    eye = np.eye(m)
    plus = [x + (1j * h[j] if method == "complex" else h[j]) * eye[j] for j in range(m)]
    for j in reversed(range(m)):          # any order: each set is its own evaluation
        _same_params(partials._plus[j], case.model.parameters(plus[j]))
        if method == "central":
            _same_params(partials._minus[j], case.model.parameters(x - h[j] * eye[j]))
    assert len(partials._plus) == m
    assert partials._plus[1:3] == [partials._plus[1], partials._plus[2]]
    assert partials._plus[-1] is partials._plus[m - 1]
    with pytest.raises(IndexError):
        partials._plus[m]


def test_a_perturbed_set_is_evaluated_once_and_only_when_read(monkeypatch):
    case = dynsens.load_case_dict(duffing_chain(6, t_end=0.01), "chain.yaml")
    calls: list[int] = []
    model = case.model
    original = type(model).parameters
    monkeypatch.setattr(type(model), "parameters", lambda self, x: calls.append(1) or original(self, x))
    sets = PerturbedSets(model, case.x0, np.full(case.x0.size, 1e-6))
    assert not calls
    first = sets[2]
    assert len(calls) == 1 and sets[2] is first and len(calls) == 1


def _per_element(n: int, method: str) -> dynsens.Case:
    d = chain_case(n, 0.05, per_element=True)
    d["responses"] = [r for r in d["responses"] if r["name"] == "tip_end"]
    d["output"] = {"history": "none"}
    d["sensitivity"]["method"] = method
    return dynsens.load_case_dict(d)


def test_a_coloured_adjoint_run_evaluates_no_set_per_variable(monkeypatch):
    """m = 60 per-element stiffnesses by the adjoint: the design and its few colours' sets,
    nothing per variable; the gradient is the direct mode's, whose uncoloured batch reads every
    variable's set."""
    calls: list[int] = []
    original = StructuralModel.parameters
    monkeypatch.setattr(StructuralModel, "parameters", lambda self, x: calls.append(1) or original(self, x))
    adjoint = dynsens.run_case(_per_element(60, "adjoint"), sensitivities=True, history=())
    assert adjoint.method == "adjoint"
    assert len(calls) < 10, len(calls)
    calls.clear()
    direct = dynsens.run_case(_per_element(60, "direct"), sensitivities=True, history=())
    assert len(calls) > 60
    g, ref = adjoint.responses["tip_end"].gradient, direct.responses["tip_end"].gradient
    np.testing.assert_allclose(g, ref, rtol=1e-6, atol=1e-9 * np.max(np.abs(ref)))


def _generic(model, partials):  # type: ignore[no-untyped-def]
    """The numerical initial-state gradient, without the model's own method."""
    n = model.traits.n_q

    def flat(params):  # type: ignore[no-untyped-def]
        return np.concatenate(model.initial_state(params))
    d = partials.of(flat)
    return d[:n], d[n:2 * n], d[2 * n:]


@pytest.mark.parametrize("initial", [None, {"displacement": {"u3": "1e-5 * k"}, "velocity": {"u6": -0.2}}],
                         ids=["at-rest", "design-dependent"])
def test_the_structural_initial_state_gradient(initial):
    """Zero, with no set evaluated, for a model at rest; the numerical derivative (the generic
    path's numbers) when initial conditions are given, here one that depends on k."""
    d = duffing_chain(6, t_end=0.01)
    if initial is not None:
        d["model"]["initial"] = initial
    case = dynsens.load_case_dict(d, "chain.yaml")
    model = case.model
    partials = DesignPartials(model, case.x0, "forward")
    read = set(partials._plus._sets)               # (what the partials' own batch read)
    found = initial_state_gradient(model, partials)
    if initial is None:
        assert set(partials._plus._sets) == read    # none read for it
        assert [a.shape for a in found] == [(6, partials.m), (6, partials.m), (0, partials.m)]
        assert not any(np.any(a) for a in found)
    else:
        assert model.initial_state_gradient(partials.params0, partials) is None
    for a, b in zip(found, _generic(model, partials)):
        np.testing.assert_array_equal(a, b)
    if initial is not None:
        k = case.design_names.index("k")
        assert found[0][2, k] == pytest.approx(1e-5, rel=1e-6)      # u3 = 1e-5 k: the third DOF
