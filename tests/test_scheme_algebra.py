"""The scheme's algebra (dynsens/integrators/newmark.py): its transposed maps are the transposes
of its forward maps, and its error constants and stability limits are the published closed
forms, shown on the scheme's own maps.

* Transposes: for random u, v, <A u, v> = <u, Aᵀ v> to round-off, for start, predict, correct
  and advance of every member (Newmark, explicit central differences, HHT-α, generalized-α).
* Error constants: one step of q = t³/6 from exact start values errs by C_q h³; C_q = β − 1/6
  for Newmark (Zienkiewicz & Xie 1991), 1/12 + (γ − ½)²/4 for the second-order α-members; the
  γ-rule of first-order states errs by the trapezoid rule's h³ p⃛/12.
* Stability: Ω_crit = 1/sqrt(γ/2 − β) for Newmark with 2β < γ (central differences 2,
  Fox–Goodwin sqrt(6), linear acceleration sqrt(12): Hughes, The Finite Element Method, 1987,
  Table 9.1.1), checked on the spectral radius of the amplification matrix built from the
  scheme's maps; HHT-α (Hilber, Hughes & Taylor 1977) and generalized-α (Chung & Hulbert 1993)
  unconditionally stable, with spectral radius at infinity (1 − α)/(1 + α) and ρ∞.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from dynsens.integrators.newmark import Aux, Newmark, Prediction, make_scheme
from dynsens.models.base import StepState

N_Q, N_LAM, N_P, R = 3, 2, 2, 4      # sizes; R columns (sensitivity or adjoint matrices)
DT = 0.013


def _schemes() -> dict[str, Newmark]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")        # the conditionally stable and damped members warn
        return {"newmark": make_scheme("newmark"),
                "newmark_damped": make_scheme("newmark", 0.3025, 0.6),
                "central_difference": make_scheme("newmark", 0.0, 0.5),
                "hht": make_scheme("hht", alpha=0.1),
                "generalized_alpha": make_scheme("generalized_alpha", rho_inf=0.6)}


SCHEMES = _schemes()


def _state(rng: np.random.Generator) -> StepState:
    n = (N_Q, N_Q, N_Q, N_LAM, N_P, N_P)
    return StepState(*(rng.standard_normal((k, R)) for k in n))


def _aux(rng: np.random.Generator) -> Aux:
    return Aux(rng.standard_normal((N_Q, R)), rng.standard_normal((N_P, R)))


def _dot(xs, ys) -> tuple[float, float]:
    """Σ <x, y> over paired leaves (a scalar leaf, the plain predictor's zero remainder,
    broadcast), and the sum of |x y| as the round-off scale."""
    total = scale = 0.0
    for x, y in zip(xs, ys):
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        total += float(np.sum(x * y))
        scale += float(np.sum(np.abs(x * y)))
    return total, scale


def _assert_adjoint(lhs: tuple[float, float], rhs: tuple[float, float]) -> None:
    (a, sa), (b, sb) = lhs, rhs
    assert abs(a - b) <= 1e-14 * max(sa, sb, 1.0), (a, b)


def _zeros_state() -> StepState:
    return StepState(*(np.zeros((k, R)) for k in (N_Q, N_Q, N_Q, N_LAM, N_P, N_P)))


@pytest.mark.parametrize("name", SCHEMES)
def test_transposed_maps_are_the_transposes(name: str) -> None:
    sc, rng = SCHEMES[name], np.random.default_rng(7)
    for _ in range(5):
        # start: s -> (a0, b0)
        u, v = _state(rng), _aux(rng)
        _assert_adjoint(_dot(sc.start(u), v), _dot(u, sc.start_transpose(v, _zeros_state())))
        # predict: (s, aux) -> (q, q̇, p, a_rest, b_rest)
        u_s, u_a = _state(rng), _aux(rng)
        v_pred = Prediction(*(rng.standard_normal((k, R)) for k in (N_Q, N_Q, N_P, N_Q, N_P)))
        s_bar, aux_bar = sc.predict_transpose(v_pred, DT, np.zeros((N_LAM, R)))
        _assert_adjoint(_dot(sc.predict(u_s, u_a, DT), v_pred), _dot([*u_s, *u_a], [*s_bar, *aux_bar]))
        # correct: (q, q̇, p of the prediction; q̈, λ, ṗ) -> s
        u_pred = Prediction(*(rng.standard_normal((k, R)) for k in (N_Q, N_Q, N_P, N_Q, N_P)))
        u_z = (rng.standard_normal((N_Q, R)), rng.standard_normal((N_LAM, R)), rng.standard_normal((N_P, R)))
        v_s = _state(rng)
        pred_bar, z_bar = sc.correct_transpose(v_s, DT)
        _assert_adjoint(_dot(sc.correct(u_pred, *u_z, DT), v_s),
                        _dot([u_pred.q, u_pred.qd, u_pred.p, *u_z], [*pred_bar, *z_bar]))
        # advance: (a_rest, b_rest of the prediction; s) -> (a, b)
        u_s, v_aux = _state(rng), _aux(rng)
        s_bar, rest_bar = sc.advance_transpose(v_aux, _zeros_state())
        _assert_adjoint(_dot(sc.advance(u_pred, u_s), v_aux),
                        _dot([u_pred.a_rest, u_pred.b_rest, *u_s], [*rest_bar, *s_bar]))


def test_a_wrong_transpose_is_caught() -> None:
    # the check can fail: a predictor transpose that drops the α_m term of a_rest is found
    sc, rng = SCHEMES["generalized_alpha"], np.random.default_rng(3)
    u_s, u_a = _state(rng), _aux(rng)
    v_pred = Prediction(*(rng.standard_normal((k, R)) for k in (N_Q, N_Q, N_P, N_Q, N_P)))
    s_bar, aux_bar = sc.predict_transpose(v_pred, DT, np.zeros((N_LAM, R)))
    wrong = aux_bar._replace(a=aux_bar.a + 0.1 * v_pred.a_rest)
    with pytest.raises(AssertionError):
        _assert_adjoint(_dot(sc.predict(u_s, u_a, DT), v_pred), _dot([*u_s, *u_a], [*s_bar, *wrong]))


# ----------------------------------------------------------------------------- error constants
def _one_step_cubic(sc: Newmark, h: float) -> tuple[float, float]:
    """One step of q = t³/6 (q⃛ = 1) from t = 0 with exact start values: the scheme's q error
    and its new algorithmic acceleration.  The algorithmic acceleration approximates
    q̈(t + (α_m − α_f) h) (module docstring of step_sequence.py), so it starts there."""
    delta = sc.alpha_m - sc.alpha_f
    zero, empty = np.zeros(1), np.zeros(0)
    s = StepState(zero, zero, zero, empty, empty, empty)
    pred = sc.predict(s, Aux(np.array([delta * h]), empty), h)
    s1 = sc.correct(pred, np.array([h]), empty, empty, h)         # q̈(h) = h, exact
    return float(s1.q[0] - h ** 3 / 6), float(sc.advance(pred, s1).a[0])


@pytest.mark.parametrize("name", SCHEMES)
def test_displacement_error_constant_is_the_local_error_of_a_step(name: str) -> None:
    sc, h = SCHEMES[name], 0.01
    c_q, _ = sc.error_constants()
    error, a_new = _one_step_cubic(sc, h)
    assert error == pytest.approx(c_q * h ** 3, rel=1e-10, abs=1e-22)
    # the start value was consistent: the new algorithmic acceleration is q̈(h + (α_m − α_f) h)
    assert a_new == pytest.approx(h * (1 + sc.alpha_m - sc.alpha_f), rel=1e-12)


def test_error_constants_are_the_closed_forms() -> None:
    # Newmark: Zienkiewicz & Xie (1991) β − 1/6 (1/12 for the average-acceleration rule); its
    # γ-rule with γ = ½ is the trapezoid rule, local error h³ p⃛/12
    for beta, gamma in ((0.25, 0.5), (1 / 6, 0.5), (0.0, 0.5), (0.3025, 0.6)):
        c_q, c_p = Newmark(beta=beta, gamma=gamma).error_constants()
        assert c_q == pytest.approx(beta - 1 / 6, abs=1e-15)
        assert c_p == pytest.approx(1 / 12, abs=1e-15)
    # second-order α-members: β = (γ + ½)²/4 gives 1/12 + (γ − ½)²/4
    for sc in (make_scheme("hht", alpha=a) for a in (0.0, 0.1, 1 / 3)):
        assert sc.error_constants()[0] == pytest.approx(1 / 12 + (sc.gamma - 0.5) ** 2 / 4, rel=1e-14)
    for sc in (make_scheme("generalized_alpha", rho_inf=r) for r in (0.0, 0.6, 1.0)):
        assert sc.error_constants()[0] == pytest.approx(1 / 12 + (sc.gamma - 0.5) ** 2 / 4, rel=1e-14)


def test_first_order_error_constant_of_newmark_is_the_trapezoid_rules() -> None:
    # p = t³/6 (ṗ = t²/2, p⃛ = 1) over one step of h from exact values: error C_p h³
    sc, h = SCHEMES["newmark"], 0.01
    empty, zero = np.zeros(0), np.zeros(1)
    s = StepState(empty, empty, empty, empty, zero, zero)
    pred = sc.predict(s, Aux(empty, zero), h)
    s1 = sc.correct(pred, empty, empty, np.array([h * h / 2]), h)
    assert float(s1.p[0] - h ** 3 / 6) == pytest.approx(sc.error_constants()[1] * h ** 3, rel=1e-10)


# ----------------------------------------------------------------------------- stability
def _spectral_radius(sc: Newmark, omega_dt: float) -> float:
    """Spectral radius of the scheme's step on q̈ + ω² q = 0 (h = 1, ω = omega_dt), built from
    its maps applied to the unit vectors of (q, q̇, q̈, a)."""
    empty = np.zeros(0)
    w2 = omega_dt ** 2
    c_q = sc.coefficients(1.0)[0]
    cols = []
    for e in np.eye(4):
        s = StepState(e[0:1], e[1:2], e[2:3], empty, empty, empty)
        pred = sc.predict(s, Aux(e[3:4], empty), 1.0)
        qdd = -w2 * pred.q / (1.0 + w2 * c_q)                    # the equation of motion at t + h
        s1 = sc.correct(pred, qdd, empty, empty, 1.0)
        cols.append([s1.q[0], s1.qd[0], s1.qdd[0], sc.advance(pred, s1).a[0]])
    return float(max(abs(np.linalg.eigvals(np.array(cols).T))))


@pytest.mark.parametrize("beta,gamma,closed_form", [
    (0.0, 0.5, 2.0),                      # central differences
    (1 / 12, 0.5, math.sqrt(6.0)),        # Fox–Goodwin
    (1 / 6, 0.5, math.sqrt(12.0)),        # linear acceleration
    (0.2, 0.6, 1 / math.sqrt(0.1)),       # γ > ½: 1/sqrt(γ/2 − β)
])
def test_conditional_stability_limit_of_newmark(beta: float, gamma: float, closed_form: float) -> None:
    sc = Newmark(beta=beta, gamma=gamma)
    assert not sc.unconditionally_stable
    assert sc.stability_limit() == pytest.approx(closed_form, rel=1e-14)
    assert _spectral_radius(sc, 0.999 * sc.stability_limit()) <= 1.0 + 1e-9
    assert _spectral_radius(sc, 1.001 * sc.stability_limit()) > 1.0 + 1e-6


@pytest.mark.parametrize("name,rho_inf", [
    ("newmark", 1.0), ("hht", (1 - 0.1) / (1 + 0.1)), ("generalized_alpha", 0.6),
])
def test_unconditionally_stable_members(name: str, rho_inf: float) -> None:
    sc = SCHEMES[name]
    assert sc.unconditionally_stable and math.isinf(sc.stability_limit())
    radii = [_spectral_radius(sc, w) for w in np.logspace(-2, 4, 61)]
    assert max(radii) <= 1.0 + 1e-9
    # the high-frequency limit: HHT (1 − α)/(1 + α), generalized-α its ρ∞
    assert _spectral_radius(sc, 1e6) == pytest.approx(rho_inf, abs=1e-4)


def test_newmark_with_gamma_below_half_is_stable_for_no_step() -> None:
    assert Newmark(beta=0.25, gamma=0.4).stability_limit() == 0.0


def test_alpha_member_outside_the_stable_range_has_no_closed_form() -> None:
    with pytest.raises(ValueError, match="no closed form"):
        Newmark(beta=0.1, gamma=0.6, alpha_m=0.0, alpha_f=0.1, name="hht").stability_limit()
