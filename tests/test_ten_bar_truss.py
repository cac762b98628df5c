"""The ten-bar cantilever truss: dynsens' optimizers reach the published minimum weights.

Source: R. T. Haftka and Z. Gürdal, *Elements of Structural Optimization*, 3rd rev. ed.,
Kluwer, 1992, pp. 238 and 244 (the truss of V. B. Venkayya, "Design of optimum structures",
Computers & Structures 1 (1971) 265–309).  Two spans of 360 in, nodes 5 and 6 held, 100 kips
down at the lower free nodes 2 and 4; E = 10⁷ psi, 0.1 lb/in³, areas ≥ 0.1 in², |σ| ≤ 25 ksi
in every member.  Published optima:

* stress limits alone: 1593.2 lb, A = 7.94, 0.1, 8.06, 3.94, 0.1, 0.1, 5.74, 5.57, 5.57, 0.1 in²;
* with |v| ≤ 2 in at nodes 1–4 as well: 5060.85 lb, A = 30.52, 0.1, 23.20, 15.22, 0.1, 0.55,
  7.46, 21.04, 21.53, 0.1 in².

The problem data, member numbering and these figures were checked against the reproduction of
the book's tables in the NASTRAN_CoFE documentation ("10-bar Truss Sizing",
vtpasquale.github.io/NASTRAN_CoFE, with its input file tenBar.dat); the book itself was not at
hand.

The case (cases/ten_bar_truss.yaml) runs the static problem on the transient solver: loads and
limits scaled by 10⁻⁶, one Newmark step far longer than the longest natural period.  The first
test shows that this is linear statics, against an independent small-displacement stiffness
model written here.  Tolerances: the weight within half a unit of the last published digit
(0.05 lb and 0.005 lb); the areas within 0.01 in²: half a unit of the second decimal plus the
spread of the optimizers' stopping points along the optimum's flat directions (measured up to
0.008 in² between designs whose weights differ by less than 0.002 lb).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

import dynsens
from dynsens.case.load import load_case_dict
from helpers import ipopt_missing

CASE = Path(__file__).resolve().parents[1] / "cases" / "ten_bar_truss.yaml"
EPS = 1e-6                          # the case's scale of loads and limits
E, DENSITY, LOAD = 1e7, 0.1, 1e5    # psi, lb/in³, lb
SIGMA_ALLOW, V_ALLOW = 25000.0, 2.0  # psi, in

# Haftka & Gürdal's numbering: nodes 1..6, members 1..10 as (node, node)
NODES = np.array([[720.0, 360.0], [720.0, 0.0], [360.0, 360.0], [360.0, 0.0], [0.0, 360.0], [0.0, 0.0]])
MEMBERS = [(5, 3), (3, 1), (6, 4), (4, 2), (3, 4), (1, 2), (5, 4), (6, 3), (3, 2), (4, 1)]

PUBLISHED = {   # weight (lb), its last digit's unit, areas (in²)
    "stress": (1593.2, 0.1, [7.94, 0.1, 8.06, 3.94, 0.1, 0.1, 5.74, 5.57, 5.57, 0.1]),
    "stress+displacement": (5060.85, 0.01, [30.52, 0.1, 23.20, 15.22, 0.1, 0.55, 7.46, 21.04, 21.53, 0.1]),
}
AREA_TOL = 0.01


def linear_statics(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Member stresses (psi), vertical displacements of nodes 1–4 (in) and weight (lb) of the
    truss with areas ``A`` (in²) under the full load, small displacements."""
    K = np.zeros((12, 12))
    rows = []
    for (a, b), area in zip(MEMBERS, A):
        d = NODES[b - 1] - NODES[a - 1]
        L = float(np.hypot(*d))
        B = np.concatenate([-d, d]) / L                 # axial elongation per unit end displacement
        dofs = [2 * a - 2, 2 * a - 1, 2 * b - 2, 2 * b - 1]
        K[np.ix_(dofs, dofs)] += E * area / L * np.outer(B, B)
        rows.append((dofs, B, L))
    F = np.zeros(12)
    F[[3, 7]] = -LOAD                                  # nodes 2 and 4, downward
    u = np.zeros(12)
    u[:8] = np.linalg.solve(K[:8, :8], F[:8])          # nodes 5 and 6 held
    sigma = np.array([E * (B @ u[dofs]) / L for dofs, B, L in rows])
    weight = DENSITY * sum(area * L for area, (_, _, L) in zip(A, rows))
    return sigma, u[[1, 3, 5, 7]], float(weight)


def raw_case(variant: str) -> dict[str, Any]:
    """The case as a mapping; ``stress`` drops the displacement limits (constraints 10..13)."""
    raw = yaml.safe_load(CASE.read_text(encoding="utf-8"))
    if variant == "stress":
        raw["optimization"]["constraints"] = raw["optimization"]["constraints"][:10]
    return raw


@pytest.mark.parametrize("variant", list(PUBLISHED))
def test_the_quasi_static_run_is_linear_statics(variant: str) -> None:
    """At the published design: stresses, displacements, weight and their gradients equal the
    linear static solution (gradients: central differences of it)."""
    A = np.array(PUBLISHED[variant][2])
    case = load_case_dict(raw_case(variant))
    res = dynsens.run_case(case, A)
    r = {k: (float(np.real(v.value)), np.real(v.gradient)) for k, v in res.responses.items()}
    sigma, v, weight = linear_statics(A)
    assert r["mass"][0] == pytest.approx(weight, rel=1e-13)
    got_sigma = np.array([r[f"s{i}"][0] for i in range(1, 11)]) / EPS
    got_v = np.array([r[f"v{i}"][0] for i in range(1, 5)]) / EPS
    np.testing.assert_allclose(got_sigma, sigma, rtol=0, atol=1e-7 * SIGMA_ALLOW)
    np.testing.assert_allclose(got_v, v, rtol=0, atol=1e-7 * V_ALLOW)
    h = 1e-6 * A
    d_sigma = np.empty((10, 10))
    d_v = np.empty((4, 10))
    for j in range(10):
        e = np.zeros(10)
        e[j] = h[j]
        (sp, vp, _), (sm, vm, _) = linear_statics(A + e), linear_statics(A - e)
        d_sigma[:, j], d_v[:, j] = (sp - sm) / (2 * h[j]), (vp - vm) / (2 * h[j])
    grad_sigma = np.array([r[f"s{i}"][1] for i in range(1, 11)]) / EPS
    grad_v = np.array([r[f"v{i}"][1] for i in range(1, 5)]) / EPS
    np.testing.assert_allclose(grad_sigma, d_sigma, rtol=0, atol=1e-6 * np.abs(d_sigma).max())
    np.testing.assert_allclose(grad_v, d_v, rtol=0, atol=1e-6 * np.abs(d_v).max())


# The displacement problem has a second local minimum, 5076.67 lb (see the last test); from the
# case's uniform start MMA (and trust-constr) end there.  MMA's start below lies in the published
# minimum's basin (measured: from A6 = 4..5 in², not from 2 or 8).  Its ftol is the relative
# change of the weight (the case's 1e-10 lies below the size of its last steps).  trust-constr is
# not tested: it reaches 5060.85 lb from A6 = 1 only, and stalls 0.03 % above 1593.2 lb
# (docs/optimization.md).  IPOPT's ftol is its KKT tolerance: with the limited-memory Hessian
# the displacement problem reaches 5060.85 lb from the uniform start at 1e-6 in 29 iterations,
# and not at 1e-8 in 200.
RUNS = [   # method, variant, start, ftol (None: the case's)
    ("SLSQP", "stress", {"A": 20.0}, None),
    ("SLSQP", "stress+displacement", {"A": 20.0}, None),
    ("MMA", "stress", {"A": 20.0}, 1e-8),
    ("MMA", "stress+displacement", {"A": 20.0, "A[bar6]": 5.0}, 1e-8),
    ("IPOPT", "stress", {"A": 20.0}, 1e-8),
    ("IPOPT", "stress+displacement", {"A": 20.0}, 1e-6),
]


_NO_IPOPT = pytest.mark.skipif(ipopt_missing(), reason="cyipopt / Ipopt not installed")


@pytest.mark.parametrize("method, variant, start, ftol",
                         [pytest.param(*run, marks=[_NO_IPOPT] if run[0] == "IPOPT" else [], id=f"{run[0]}-{run[1]}")
                          for run in RUNS])
def test_optimizers_reach_the_published_optimum(method: str, variant: str, start: dict, ftol: float | None) -> None:
    weight, unit, areas = PUBLISHED[variant]
    raw = raw_case(variant)
    raw["optimization"]["method"] = method
    res = dynsens.optimize(raw, x0=start, ftol=ftol, maxiter=200, verify=False)
    assert res.success and res.feasible, res.message
    assert abs(res.fun - weight) <= 0.5 * unit, (res.fun, weight)
    np.testing.assert_allclose(res.x, areas, rtol=0, atol=AREA_TOL)
    # the optimum satisfies the published limits in the independent linear model too
    sigma, v, w = linear_statics(res.x)
    assert np.abs(sigma).max() <= SIGMA_ALLOW * (1 + 1e-6)
    if variant != "stress":
        assert np.abs(v).max() <= V_ALLOW * (1 + 1e-6)
    assert w == pytest.approx(res.fun, rel=1e-12)


def test_the_displacement_problem_has_a_second_local_minimum() -> None:
    """MMA from A6 = 1 ends at 5076.67 lb with A6 at its bound, a local minimum the published
    one does not show: SLSQP on the independent linear model, started there, stays there."""
    from scipy.optimize import minimize

    raw = raw_case("stress+displacement")
    raw["optimization"]["method"] = "MMA"
    res = dynsens.optimize(raw, x0={"A": 20.0, "A[bar6]": 1.0}, ftol=1e-8, maxiter=200, verify=False)
    assert res.success and res.feasible, res.message
    assert res.fun > PUBLISHED["stress+displacement"][0] + 10.0
    assert res.x[5] == pytest.approx(0.1, abs=1e-6)                    # A6 at its bound

    def limits(A: np.ndarray) -> np.ndarray:
        sigma, v, _ = linear_statics(A)
        return np.concatenate([1 - sigma / SIGMA_ALLOW, 1 + sigma / SIGMA_ALLOW, 1 - v / V_ALLOW, 1 + v / V_ALLOW])

    ref = minimize(lambda A: linear_statics(A)[2] / res.fun, res.x, method="SLSQP", bounds=[(0.1, None)] * 10,
                   constraints=[{"type": "ineq", "fun": limits}], options={"ftol": 1e-10, "maxiter": 200})
    assert ref.success, ref.message
    assert ref.fun == pytest.approx(1.0, abs=1e-6)          # the weight stays where MMA put it
    np.testing.assert_allclose(res.x, ref.x, rtol=0, atol=AREA_TOL)
