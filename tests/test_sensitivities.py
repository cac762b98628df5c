"""Direct-differentiation gradients of every structural case against complex step of the whole run."""
import pytest

import dynsens
from conftest import CASES
from helpers import complex_step_gradients, rel_err

STRUCTURAL = {"sdof_step": ["integrator.t_end=3"], "duffing_chain": ["integrator.t_end=0.6"],
              "truss_impact": ["integrator.t_end=0.02"]}
# forward partials: truncation of ∂_x F_R ~ 1e-8; complex partials: round-off
TOL = {"forward": 1e-6, "central": 1e-8, "complex": 1e-10}


@pytest.mark.parametrize("name", sorted(STRUCTURAL))
@pytest.mark.parametrize("partials", ["forward", "central", "complex"])
def test_gradients_match_complex_step(name, partials):
    case = dynsens.load_case(CASES / f"{name}.yaml", STRUCTURAL[name] + [f"sensitivity.partials={partials}"])
    res = dynsens.run_case(case)
    ref = complex_step_gradients(case)
    for resp, r in res.responses.items():
        assert rel_err(r.gradient, ref[resp]) < TOL[partials], (resp, r.gradient, ref[resp])


def test_reused_factor_stays_below_partials_error():
    """Reusing the last Newton factor instead of S at convergence errs far below forward partials (~1e-8)."""
    over = STRUCTURAL["duffing_chain"] + ["sensitivity.partials=complex"]
    exact = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", over + ["sensitivity.matrix=converged"]))
    reuse = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", over + ["sensitivity.matrix=reuse"]))
    for name, r in exact.responses.items():
        assert rel_err(reuse.responses[name].gradient, r.gradient) < 1e-10
    assert reuse.counters["factorizations"] < exact.counters["factorizations"]


@pytest.mark.parametrize("name", ["duffing_chain", "four_bar"])
def test_forward_partials_reuse_an_older_factor_within_their_own_error(name):
    """With forward partials (error ~3e-8 relative) a step accepted on a round-off residual keeps
    the factor one correction old when that correction is below the partials' error: fewer
    factorizations than with complex partials, and a gradient that moves less than the forward
    partials' own error against complex step of the whole run."""
    over = {"duffing_chain": ["integrator.t_end=0.6"], "four_bar": ["integrator.t_end=0.5"]}[name]
    forward = over + ["sensitivity.partials=forward"]
    case = dynsens.load_case(CASES / f"{name}.yaml", forward)
    reuse = dynsens.run_case(case)
    exact = dynsens.run_case(dynsens.load_case(CASES / f"{name}.yaml", forward + ["sensitivity.matrix=converged"]))
    strict = dynsens.run_case(dynsens.load_case(CASES / f"{name}.yaml", over + ["sensitivity.partials=complex"]))
    ref = complex_step_gradients(case)
    for resp, r in exact.responses.items():
        own = rel_err(r.gradient, ref[resp])
        assert rel_err(reuse.responses[resp].gradient, r.gradient) <= max(own, 1e-12), resp
        assert rel_err(reuse.responses[resp].gradient, ref[resp]) < TOL["forward"], resp
    assert reuse.counters["factorizations"] < strict.counters["factorizations"] - 50


def test_sparse_and_dense_agree():
    over = STRUCTURAL["duffing_chain"] + ["sensitivity.partials=complex"]
    dense = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", over + ["model.linear_algebra=dense"]))
    sparse = dynsens.run_case(dynsens.load_case(CASES / "duffing_chain.yaml", over + ["model.linear_algebra=sparse"]))
    for name, r in dense.responses.items():
        assert abs(sparse.responses[name].value - r.value) <= 1e-10 * abs(r.value)
        assert rel_err(sparse.responses[name].gradient, r.gradient) < 1e-10


def test_initial_state_sensitivity():
    """A design-dependent initial displacement propagates into the gradient (∇q0 ≠ 0)."""
    case = dynsens.load_case(CASES / "sdof_step.yaml", [
        "integrator.t_end=1", "model.initial={displacement: {u: '0.01*k'}}", "sensitivity.partials=complex"])
    res = dynsens.run_case(case)
    ref = complex_step_gradients(case)
    assert rel_err(res.responses["q_end"].gradient, ref["q_end"]) < 1e-10
