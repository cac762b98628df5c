"""The N-four-bar mechanism (IFToMM multibody benchmark A02) through its singular configurations.

The shipped case (cases/n_four_bar.yaml, scripts/make_n_four_bar.py) has N = 3 loops of spatial
revolutes; each loop's three out-of-plane equations are redundant and left out.  All bars turn
alike (the loops stay parallelograms), so the crank angle θ obeys the reduced equation

    I θ̈ + c cos θ = 0,   I = (N + 1) m L²/3 + N m_c L²,   c = g L ((N + 1) m/2 + N m_c)

(cranks of mass m pinned at one end, couplers of mass m_c translating), θ(0) = π/2,
θ̇(0) = −v0/L: an independent reference integrated by scipy (DOP853, rtol 1e-12).  Within the
1.5 s of the case the bars are horizontal (sin θ = 0: N + 1 freedoms instead of 1) twice.
"""
from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import dynsens
import scripts_path  # noqa: F401  (scripts/ on the path)
import make_n_four_bar  # noqa: E402
from conftest import CASES
from helpers import complex_step_gradients, rel_err

G_ACC, BAR = 9.81, 1.0


def _reference(t, n, m, v0, m_c=1.0):
    inertia = (n + 1) * m * BAR ** 2 / 3 + n * m_c * BAR ** 2
    c = G_ACC * BAR * ((n + 1) * m / 2 + n * m_c)
    sol = solve_ivp(lambda _, y: [y[1], -c / inertia * np.cos(y[0])], (0.0, t[-1]), [np.pi / 2, -v0 / BAR],
                    method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)
    return sol.sol(t)[0]


def _crank_angle(q):
    """θ of crank 0 (its body x axis from the global x axis, about z), unwrapped."""
    e = q[:, 3:7]
    return np.unwrap(2.0 * np.arctan2(e[:, 3], e[:, 0]))


def _energy(model, x, q, qd):
    """Kinetic plus potential energy (J) of all bodies at every recorded step."""
    prm = model.parameters(np.asarray(x, float))
    total = np.zeros(q.shape[0])
    for i, bp in enumerate(prm.bodies):
        r, rd = q[:, 7 * i:7 * i + 3], qd[:, 7 * i:7 * i + 3]
        e, ed = q[:, 7 * i + 3:7 * i + 7], qd[:, 7 * i + 3:7 * i + 7]
        e0, e1, e2, e3 = e.T
        G = np.stack([np.stack([-e1, e0, e3, -e2], -1), np.stack([-e2, -e3, e0, e1], -1),
                      np.stack([-e3, e2, -e1, e0], -1)], 1)                       # (k, 3, 4)
        w = 2.0 * np.einsum("kij,kj->ki", G, ed)                                   # body axes
        J = np.real(np.asarray(bp.inertia, float))
        m = float(np.real(bp.mass))
        total += 0.5 * m * np.sum(rd * rd, axis=1) + 0.5 * np.einsum("ki,ij,kj->k", w, J, w) + m * G_ACC * r[:, 1]
    return total


@pytest.fixture(scope="module")
def case():
    return dynsens.load_case(CASES / "n_four_bar.yaml")


@pytest.fixture(scope="module")
def direct(case):
    """The whole case with direct sensitivities and its state histories, made once: the motion
    checked against the reduced equation is that of the run whose gradients are checked (the
    sensitivities trail the state and do not feed back into it)."""
    return dynsens.run_case(case, history=("q", "qd"))


def test_the_case_is_the_generator_output():
    assert make_n_four_bar.dump(make_n_four_bar.n_four_bar()) == (CASES / "n_four_bar.yaml").read_text(encoding="utf-8")


def test_three_out_of_plane_equations_per_loop_are_left_out(case):
    m = case.model
    assert sorted({lab for _, lab, _ in m.redundant}) == ["u.w", "v.w", "z"]
    assert len(m.redundant) == 3 * 3 and m.traits.n_q == 7 * 7
    assert m.traits.n_lam == 5 * 10 + 7 - 9


def test_crank_angle_follows_the_reduced_equation_through_two_singular_crossings(case, direct):
    res = direct
    assert res.status == "completed" and res.counters["step_cuts"] == 0
    q, qd, t = res.history["q"], res.history["qd"], res.time
    ref = _reference(t, 3, 1.0, 1.0)
    crossings = t[np.flatnonzero(np.diff(np.sign(np.sin(ref))))]
    assert len(crossings) >= 2, crossings                       # ≈ 0.716 s and 1.233 s
    # the trapezoidal rule's O(Δt²) phase error: 6e-6 rad at the end of 1.5 s
    err = np.abs(_crank_angle(q) - ref)
    assert err.max() < 2e-5, err.max()
    # every bar turns with crank 0 (the loops stay parallelograms past the crossings)
    for b in range(1, 4):
        assert np.max(np.abs(_crank_angle(q[:, 7 * b:]) - _crank_angle(q))) < 1e-6
    # energy is conserved to the scheme's accuracy; a branch switch at a crossing would not be
    E = _energy(case.model, case.x0, q, qd)
    assert np.max(np.abs(E - E[0])) < 1e-4 * abs(E[0]) + 1e-3, np.max(np.abs(E - E[0]))
    assert res.monitors["constraint_position"].max() < 1e-4


def test_sensitivities_through_the_crossings_match_complex_step(case, direct):
    adjoint_case = copy.copy(case)
    adjoint_case.plan = replace(case.plan, method="adjoint")
    adjoint = dynsens.run_case(adjoint_case)
    assert adjoint.method == "adjoint"
    cs = complex_step_gradients(case)
    for name, r in direct.responses.items():
        assert rel_err(r.gradient, cs[name]) < 1e-7, (name, r.gradient, cs[name])
        assert rel_err(adjoint.responses[name].gradient, r.gradient) < 1e-10, name


def test_dense_and_sparse_linear_algebra_give_the_same_run():
    out = {}
    for la in ("dense", "sparse"):
        c = dynsens.load_case(CASES / "n_four_bar.yaml", [f"model.linear_algebra={la}", "integrator.t_end=0.8"])
        assert c.model.traits.sparse == (la == "sparse")
        out[la] = dynsens.run_case(c)
    for name, r in out["dense"].responses.items():
        s = out["sparse"].responses[name]
        assert abs(s.value - r.value) <= 1e-12 * abs(r.value), name
        assert rel_err(s.gradient, r.gradient) < 1e-10, name


def test_generated_n_loops_have_the_published_size():
    raw = make_n_four_bar.n_four_bar(40, t_end=0.002)
    assert len(raw["model"]["bodies"]) == 81 and len(raw["model"]["joints"]) == 121
    case = dynsens.load_case_dict(raw, source="n_four_bar_40.yaml")
    tr = case.model.traits
    assert tr.n_q == 567 and tr.n_lam == 5 * 121 + 81 - 3 * 40 and tr.sparse      # auto: sparse
