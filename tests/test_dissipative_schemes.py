"""HHT-α and generalized-α: order, spectral properties against closed forms, sensitivities."""
import numpy as np
import pytest

import dynsens
from dynsens.integrators.newmark import make_scheme
from dynsens.models.base import StepState
from conftest import CASES
from helpers import complex_step_gradients, rel_err

E = np.zeros(0)


def amplification(scheme, omega_dt):
    """One-step map of the undamped oscillator q̈ + ω²q = 0 (ω = 1, Δt = Ω) on (q, q̇, a)."""
    h = omega_dt
    c_q, c_qd, _ = scheme.coefficients(h)
    cols = []
    for e in np.eye(3):
        q, qd, a = e
        s = StepState(np.array([q]), np.array([qd]), np.array([-q]), E, E, E)  # q̈ = −q at t_n
        aux = scheme.start(s)._replace(a=np.array([a]))
        pred = scheme.predict(s, aux, h)
        qdd = -pred.q / (1.0 + c_q)                 # solve q̈ + q = 0 at t_{n+1}
        s1 = scheme.correct(pred, qdd, E, E, h)
        a1 = scheme.advance(pred, s1).a
        cols.append([s1.q[0], s1.qd[0], a1[0]])
    return np.array(cols).T


def spectral_radius(scheme, omega_dt):
    return max(abs(np.linalg.eigvals(amplification(scheme, omega_dt))))


def damping_and_period(scheme, omega_dt):
    """Algorithmic damping ratio ξ̄ and period ratio T̄/T from the principal eigenvalues."""
    lam = np.linalg.eigvals(amplification(scheme, omega_dt))
    lam = lam[np.argmax(np.abs(lam.imag))]
    omega_bar = abs(np.angle(lam)) / omega_dt
    xi = -np.log(abs(lam)) / (omega_dt * omega_bar) * omega_bar / np.hypot(omega_bar, np.log(abs(lam)) / omega_dt)
    return xi, 1.0 / omega_bar


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8, 1.0])
def test_generalized_alpha_spectral_radius_at_infinity(rho):
    assert spectral_radius(make_scheme("generalized_alpha", rho_inf=rho), 1e9) == pytest.approx(rho, abs=1e-4)


@pytest.mark.parametrize("alpha", [0.05, 0.1, 1 / 3])
def test_hht_spectral_radius_at_infinity(alpha):
    # published: ρ∞ = (1 − α)/(1 + α) for HHT-α (Hilber, Hughes & Taylor 1977, α ≥ 0 here)
    assert spectral_radius(make_scheme("hht", alpha=alpha), 1e6) == pytest.approx((1 - alpha) / (1 + alpha), abs=1e-4)


def test_trapezoidal_rule_period_and_no_damping():
    scheme = make_scheme("newmark")
    for om in (0.01, 0.3, 1.0, 3.0):
        xi, period_ratio = damping_and_period(scheme, om)
        assert abs(xi) < 1e-12 and spectral_radius(scheme, om) == pytest.approx(1.0, abs=1e-12)
        # closed form of the trapezoidal rule: T̄/T = Ω / (2 atan(Ω/2))
        assert period_ratio == pytest.approx(om / (2 * np.arctan(om / 2)), rel=1e-10)


def test_newmark_gamma_damping_first_order():
    # published: Newmark with γ > ½, β = (γ + ½)²/4 damps as ξ̄ ≈ (γ − ½)Ω/2 for small Ω
    g = 0.6
    with pytest.warns(UserWarning):
        scheme = make_scheme("newmark", 0.25 * (g + 0.5) ** 2, g)
    xi, _ = damping_and_period(scheme, 1e-3)
    assert xi == pytest.approx((g - 0.5) * 1e-3 / 2, rel=1e-2)


@pytest.mark.parametrize("name,kw", [("generalized_alpha", {"rho_inf": 0.7}), ("hht", {"alpha": 0.1})])
def test_second_order_schemes_damp_low_frequencies_at_third_order(name, kw):
    scheme = make_scheme(name, **kw)
    oms = np.array([0.02, 0.04, 0.08])
    xis = np.array([damping_and_period(scheme, om)[0] for om in oms])
    period_err = np.array([damping_and_period(scheme, om)[1] - 1 for om in oms])
    assert np.polyfit(np.log(oms), np.log(xis), 1)[0] == pytest.approx(3.0, abs=0.1)
    assert np.polyfit(np.log(oms), np.log(period_err), 1)[0] == pytest.approx(2.0, abs=0.1)


def _run_sdof(dt, scheme_over):
    case = dynsens.load_case(CASES / "sdof_step.yaml", [
        f"integrator.dt={dt}", "integrator.t_end=2.0", "design.variables[1].value=0.0"] + scheme_over)
    return dynsens.run_case(case, sensitivities=False).history["q"][-1, 0]


@pytest.mark.parametrize("over", [["integrator.scheme=generalized_alpha", "integrator.rho_inf=0.6"],
                                  ["integrator.scheme=hht", "integrator.alpha=0.1"]])
def test_dissipative_schemes_are_second_order(over):
    exact = 10 / 50 * (1 - np.cos(5.0 * 2.0))
    dts = np.array([0.02, 0.01, 0.005, 0.0025])
    errs = np.array([abs(_run_sdof(dt, over) - exact) for dt in dts])
    assert np.polyfit(np.log(dts), np.log(errs), 1)[0] == pytest.approx(2.0, abs=0.15)


def test_generalized_alpha_sensitivities_match_complex_step():
    case = dynsens.load_case(CASES / "duffing_chain.yaml", [
        "integrator.t_end=0.5", "integrator.scheme=generalized_alpha", "integrator.rho_inf=0.5",
        "sensitivity.partials=complex"])
    res = dynsens.run_case(case)
    ref = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert rel_err(r.gradient, ref[name]) < 1e-10
