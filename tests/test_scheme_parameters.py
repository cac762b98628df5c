"""Scheme parameters: HHT's α in both sign conventions (the same scheme), out-of-range α refused
with the conversion spelled out, and parameters a scheme does not use refused at load."""
from __future__ import annotations

import pytest

import dynsens
from conftest import CASES
from dynsens.errors import CaseError
from dynsens.integrators.newmark import make_scheme


@pytest.mark.parametrize("alpha", [0.0, 0.05, 0.2, 1 / 3])
def test_hht_alpha_in_either_sign_convention_is_the_same_scheme(alpha):
    a, b = make_scheme("hht", alpha=alpha), make_scheme("hht", alpha=-alpha)
    assert (a.beta, a.gamma, a.alpha_m, a.alpha_f) == (b.beta, b.gamma, b.alpha_m, b.alpha_f)
    assert a.alpha_f == pytest.approx(alpha) and a.gamma == pytest.approx(0.5 + alpha)


def test_hht_runs_agree_in_both_conventions():
    over = ["integrator.t_end=0.5", "integrator.scheme=hht"]
    r1 = dynsens.run_case(dynsens.load_case(CASES / "sdof_step.yaml", over + ["integrator.alpha=0.1"]))
    r2 = dynsens.run_case(dynsens.load_case(CASES / "sdof_step.yaml", over + ["integrator.alpha=-0.1"]))
    for name, r in r1.responses.items():
        assert r2.responses[name].value == r.value
        assert (r2.responses[name].gradient == r.gradient).all()


@pytest.mark.parametrize("alpha", [0.4, -0.5])
def test_hht_alpha_out_of_range_spells_the_conventions(alpha):
    with pytest.raises(CaseError) as exc:
        dynsens.load_case(CASES / "sdof_step.yaml", ["integrator.scheme=hht", f"integrator.alpha={alpha}"])
    msg = str(exc.value)
    assert "|alpha| <= 1/3" in msg and "[0, 1/3]" in msg and "alpha_HHT = -alpha in [-1/3, 0]" in msg


@pytest.mark.parametrize("over, named", [
    (["integrator.scheme=hht", "integrator.beta=0.3"], "integrator.beta"),
    (["integrator.scheme=hht", "integrator.gamma=0.6", "integrator.alpha=0.1"], "integrator.gamma"),
    (["integrator.scheme=generalized_alpha", "integrator.beta=0.25", "integrator.gamma=0.5"],
     "integrator.beta, integrator.gamma"),
    (["integrator.scheme=generalized_alpha", "integrator.alpha=0.1"], "integrator.alpha"),
    (["integrator.alpha=0.1"], "integrator.alpha"),                 # newmark
    (["integrator.scheme=hht", "integrator.rho_inf=0.5"], "integrator.rho_inf"),
])
def test_parameters_a_scheme_ignores_are_errors(over, named):
    with pytest.raises(CaseError) as exc:
        dynsens.load_case(CASES / "sdof_step.yaml", over)
    msg = str(exc.value)
    assert f"{named} given, but the" in msg and "does not use" in msg, msg


@pytest.mark.parametrize("over, named", [(["integrator.beta=1e300"], "integrator.beta = 1e+300"),
                                         (["integrator.beta=1.5"], "integrator.beta = 1.5"),
                                         (["integrator.gamma=2.0"], "integrator.gamma = 2.0")])
def test_newmark_parameters_above_one_are_refused(over, named):
    """β = 1e300 used to run to a finite, meaningless answer (q̈ lost to round-off in q_pred + βΔt²q̈,
    gradient and finite differences disagreeing entirely): β, γ > 1 are load errors."""
    with pytest.raises(CaseError) as exc:
        dynsens.load_case(CASES / "sdof_step.yaml", over)
    assert named in str(exc.value) and "must be <= 1" in str(exc.value)
    make_scheme("newmark", beta=1.0, gamma=1.0)      # the edge of the range is allowed (with warnings)
