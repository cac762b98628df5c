"""Natural modes and linear buckling (dynsens.analysis.modes) against closed forms and differences.

Closed forms: cantilever frequencies f_i = (β_i L)²/(2π L²)·√(EI/ρA), β₁L = 1.8751041,
β₂L = 4.6940911 (Euler–Bernoulli; e.g. Blevins, Formulas for Natural Frequency and Mode Shape,
table 8-1); Euler's column loads π²EI/(4L²) (fixed–free) and π²EI/L² (pinned–pinned).
Gradients: against central differences of the whole analysis, and the closed forms' own
derivatives (f ∝ h for a rectangle of height h bending about its width; P_cr ∝ b).
"""
from __future__ import annotations

import copy
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

import dynsens.cli.modes  # noqa: F401  (registers the command)
from dynsens.analysis.modes import AnalysisError, buckling, modes
from dynsens.case.load import load_case, load_case_dict
from dynsens.cli.main import cli

REPO = Path(__file__).resolve().parents[1]
E, RHO, L, N_EL = 2.1e5, 7.85e-9, 1000.0, 20          # MPa, t/mm³, mm


def column(b: float = 20.0, h: float = 40.0, pinned: bool = False, load: float = -1000.0,
           n: int = N_EL) -> dict:
    """A vertical column of co-rotational beams along y, clamped at the foot (or pinned at both
    ends), axial tip load ``load`` (N) and design variables b, h (mm) of its rectangle."""
    nodes = {f"n{i}": {"coords": [0.0, L * i / n]} for i in range(n + 1)}
    nodes["n0"]["fixed"] = ["x", "y"] if pinned else "all"
    if pinned:
        nodes[f"n{n}"]["fixed"] = ["x"]
    elements = [{"type": "beam", "name": f"e{i}", "nodes": [f"n{i}", f"n{i + 1}"], "E": E, "density": RHO,
                 "mass": "consistent", "section": {"shape": "rectangle", "b": "b", "h": "h"}} for i in range(n)]
    return {
        "name": "column",
        "design": {"variables": [{"name": "b", "value": b, "lower": 1.0, "upper": 100.0},
                                 {"name": "h", "value": h, "lower": 1.0, "upper": 100.0}]},
        "model": {"type": "structural", "dim": 2, "nodes": nodes, "elements": elements,
                  "loads": [{"node": f"n{n}", "direction": "y", "value": load, "function": "constant"}]},
        "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1e-3, "t_end": 0.01},
        "responses": [{"name": "tip", "type": "value", "quantity": {"dof": f"n{n}.y", "kind": "displacement"}}],
    }


def central(fn, x: np.ndarray, rel: float = 1e-5) -> np.ndarray:  # type: ignore[no-untyped-def]
    cols = []
    for j in range(x.size):
        h = rel * abs(x[j])
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        cols.append((fn(xp) - fn(xm)) / (2 * h))
    return np.array(cols).T


def test_cantilever_frequencies_and_their_gradient_against_the_closed_form() -> None:
    b, h = 20.0, 40.0
    case = load_case_dict(column(b, h))
    m = modes(case, count=4)
    # the bending modes in the plane: I = b h³/12 about the axis normal to the plane
    A, I = b * h, b * h ** 3 / 12
    exact = np.array([1.8751041, 4.6940911]) ** 2 / (2 * np.pi * L ** 2) * np.sqrt(E * I / (RHO * A))
    np.testing.assert_allclose(m.frequencies[:2], exact, rtol=1e-5)
    # f ∝ h and independent of b: the closed form's gradient
    np.testing.assert_allclose(m.gradient[:2, 1], m.frequencies[:2] / h, rtol=1e-7)
    assert np.all(np.abs(m.gradient[:, 0]) <= 1e-9 * m.frequencies)
    # and the whole analysis differenced, every mode (the axial one included); the eigensolver's
    # round-off (~1e-10 of f, K spans axial and bending stiffness) sets the step: 1e-3 relative
    # (f is linear in h, so the difference has no truncation error there)
    fd = central(lambda x: modes(case, x, count=4, sensitivities=False).frequencies, case.x0, rel=1e-4)
    np.testing.assert_allclose(m.gradient[:, 1], fd[:, 1], rtol=1e-5)
    np.testing.assert_allclose(m.gradient[:, 0], fd[:, 0], atol=1e-6 * m.frequencies.max() / b)
    assert not m.repeated.any()
    # mass-normalized shapes
    shapes = m.shapes
    from dynsens.models.base import StepState, as_dense
    q = np.zeros(shapes.shape[0])
    z = np.zeros(0)
    M = as_dense(case.model.linearize(0.0, StepState(q, q, q, z, z, z), case.model.parameters(case.x0)).R_z)
    np.testing.assert_allclose(shapes.T @ M @ shapes, np.eye(4), atol=1e-10)


def test_modes_at_a_deformed_state_take_the_state_sensitivity() -> None:
    """At a state a run reached, the total derivative includes dK/dq·dq/dx (checked against
    central differences of the whole run and analysis)."""
    raw = column(load=-1.4e4)                          # an axial load, a quarter of Euler's
    raw["integrator"]["t_end"] = 0.004
    raw["model"]["damping"] = {"rayleigh": {"alpha": 50.0, "beta": 0.0}}
    # exact state sensitivities (complex partials, the converged matrix) and a tight Newton
    # tolerance, so that the differences of the whole run are the reference
    raw["sensitivity"] = {"partials": "complex", "matrix": "converged"}
    raw["integrator"]["solver"] = {"rtol": 1e-13}
    case = load_case_dict(raw)
    m = modes(case, count=3, time=0.004)
    m0 = modes(case, count=3)
    assert m.time == pytest.approx(0.004) and m.frequencies[0] < 0.95 * m0.frequencies[0]   # softened
    # differences of step 1e-3: the eigensolver's round-off (~1e-9 of f) over smaller steps
    # would swamp the small b-derivatives
    fd = central(lambda x: modes(case, x, count=3, time=0.004, sensitivities=False).frequencies, case.x0, rel=1e-3)
    np.testing.assert_allclose(m.gradient, fd, rtol=1e-5, atol=1e-7 * m.frequencies.max())


def spring_pair(k1: float, k2: float) -> dict:
    return {
        "name": "pair",
        "design": {"variables": [{"name": "k1", "value": k1, "lower": 1.0, "upper": 1e3},
                                 {"name": "k2", "value": k2, "lower": 1.0, "upper": 1e3}]},
        "model": {"type": "structural", "dofs": ["u", "v"],
                  "elements": [{"type": "mass", "name": "mu", "dof": "u", "mass": 2.0},
                               {"type": "mass", "name": "mv", "dof": "v", "mass": 2.0},
                               {"type": "spring", "name": "su", "dofs": ["u", "ground"], "k": "k1"},
                               {"type": "spring", "name": "sv", "dofs": ["v", "ground"], "k": "k2"}]},
        "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1e-2, "t_end": 0.1},
        "responses": [{"name": "u_end", "type": "value", "quantity": {"dof": "u", "kind": "displacement"}}],
    }


def test_a_repeated_eigenvalue_is_marked_and_its_derivatives_are_directional() -> None:
    case = load_case_dict(spring_pair(100.0, 100.0))
    m = modes(case, count=2)
    assert m.repeated.all()
    # along k1 one of the two eigenvalues moves by 1/m and the other stays: sorted [0, 1/m]
    np.testing.assert_allclose(m.eigenvalue_gradient[:, 0], [0.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(m.eigenvalue_gradient[:, 1], [0.0, 0.5], atol=1e-12)
    split = load_case_dict(spring_pair(100.0, 120.0))
    s = modes(split, count=2)
    assert not s.repeated.any()
    np.testing.assert_allclose(s.eigenvalue_gradient, [[0.5, 0.0], [0.0, 0.5]], atol=1e-12)


@pytest.mark.parametrize("pinned, factor", [(False, 0.25), (True, 1.0)])
def test_euler_column_buckling_load_and_gradient(pinned: bool, factor: float) -> None:
    b, h, P = 20.0, 40.0, 1000.0
    case = load_case_dict(column(b, h, pinned=pinned, load=-P))
    res = buckling(case, count=2)
    I = b * h ** 3 / 12
    euler = factor * np.pi ** 2 * E * I / L ** 2
    # co-rotational beams carry the chord's geometric stiffness: 20 elements are within 0.5 %
    assert res.factors[0] * P == pytest.approx(euler, rel=5e-3)
    coarse = buckling(load_case_dict(column(b, h, pinned=pinned, load=-P, n=10)), count=1, sensitivities=False)
    assert abs(coarse.factors[0] * P - euler) > 2.5 * abs(res.factors[0] * P - euler)    # converges with the mesh
    # P_cr ∝ b (the load factor of the whole column, every mode): the closed form's derivative
    np.testing.assert_allclose(res.gradient[:, 0], res.factors / b, rtol=1e-6)
    fd = central(lambda x: buckling(case, x, count=2, sensitivities=False).factors, case.x0)
    np.testing.assert_allclose(res.gradient, fd, rtol=1e-6)


def test_buckling_of_a_shipped_truss_and_its_gradient() -> None:
    case = load_case(REPO / "cases" / "truss_lightweight.yaml")
    res = buckling(case, count=2)
    assert res.factors[0] > 1.0
    fd = central(lambda x: buckling(case, x, count=2, sensitivities=False).factors, case.x0)
    np.testing.assert_allclose(res.gradient, fd, rtol=1e-5)


def test_what_the_analyses_refuse() -> None:
    with pytest.raises(AnalysisError, match="structural model"):
        modes(load_case(REPO / "cases" / "slider_crank.yaml"))
    with pytest.raises(AnalysisError, match="no buckling"):
        buckling(load_case_dict(spring_pair(100.0, 120.0) | {"model": {
            **spring_pair(100.0, 120.0)["model"], "loads": [{"dof": "u", "value": 1.0, "function": "constant"}]}}))
    raw = copy.deepcopy(spring_pair(100.0, -120.0))
    raw["design"]["variables"][1]["lower"] = -200.0
    with pytest.raises(AnalysisError, match="not positive semi-definite"):
        modes(load_case_dict(raw))


def test_modes_command_prints_and_writes(tmp_path: Path) -> None:
    out = tmp_path / "modes.h5"
    r = CliRunner().invoke(cli, ["modes", str(REPO / "cases" / "truss_lightweight.yaml"), "--buckling", "--count", "3",
                                 "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "natural frequencies" in r.output and "buckling load factors" in r.output
    with h5py.File(out, "r") as f:
        assert f["modes/frequencies"].shape == (3,) and f["modes/gradient"].shape == (3, 3)
        assert f["buckling/factors"].shape[0] >= 1 and f.attrs["status"] == "completed"
    r = CliRunner().invoke(cli, ["modes", str(REPO / "cases" / "truss_lightweight.yaml"), "-o", str(out)])
    assert r.exit_code == 2 and "--overwrite" in r.output
    r = CliRunner().invoke(cli, ["modes", str(REPO / "cases" / "slider_crank.yaml")])
    assert r.exit_code == 2 and "structural model" in r.output and "Traceback" not in r.output


def with_modal_responses(raw: dict) -> dict:
    raw = copy.deepcopy(raw)
    raw["responses"] += [{"name": "f1", "type": "frequency"},
                         {"name": "f_low", "type": "frequency", "modes": 3, "rho": 0.5},
                         {"name": "lam1", "type": "buckling_factor"},
                         {"name": "mass", "type": "mass"}]
    raw["sensitivity"] = {"partials": "complex"}
    return raw


@pytest.mark.parametrize("method", ["direct", "adjoint"])
def test_frequency_and_buckling_responses_equal_the_analysis_and_complex_step(method: str) -> None:
    from helpers import complex_step_gradients

    import dynsens
    raw = with_modal_responses(column())
    raw["sensitivity"]["method"] = method
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    m, b = modes(case, count=3), buckling(case, count=1)
    # (the eigensolver for one mode and for three differ by its round-off, ~1e-9 of f)
    assert res.responses["f1"].value == pytest.approx(m.frequencies[0], rel=1e-8)
    np.testing.assert_allclose(res.responses["f1"].gradient, m.gradient[0], rtol=1e-7, atol=1e-8)
    assert res.responses["lam1"].value == pytest.approx(b.factors[0], rel=1e-8)
    f = m.frequencies
    assert f[0] - np.log(3) / 0.5 <= res.responses["f_low"].value <= f[0]            # a smooth minimum
    cs = complex_step_gradients(case)
    for name in ("f1", "f_low", "lam1"):
        # d/db is zero by the closed form: round-off of the eigensolver (1e-9 of the value) sets atol
        np.testing.assert_allclose(res.responses[name].gradient, cs[name], rtol=1e-7,
                                   atol=1e-8 * abs(res.responses[name].value), err_msg=name)


def test_minimum_mass_column_for_a_frequency_bound() -> None:
    """Minimize the mass of the cantilever subject to f1 >= 50 Hz over its height h (b fixed):
    f1 grows with h, so the bound is active at the optimum."""
    import dynsens
    raw = column()
    raw["design"]["variables"] = [{"name": "h", "value": 40.0, "lower": 10.0, "upper": 100.0}]
    for el in raw["model"]["elements"]:
        el["section"]["b"] = 20.0
    raw["responses"] += [{"name": "f1", "type": "frequency"}, {"name": "mass", "type": "mass"}]
    raw["optimization"] = {"objective": "mass", "constraints": [{"response": "f1", "lower": 50.0}]}
    res = dynsens.optimize(raw, verify=False)
    assert res.success and res.feasible
    assert res.constraints["f1"] == pytest.approx(50.0, rel=1e-5)
    # f1 ∝ h (Euler–Bernoulli; the consistent mass's rotary terms move it by < 1e-4)
    assert res.x[0] == pytest.approx(40.0 * 50.0 / modes(load_case_dict(raw), count=1).frequencies[0], rel=1e-3)


def test_modal_responses_need_a_structural_model_and_their_keys() -> None:
    from dynsens.errors import CaseError
    raw = column()
    raw["responses"].append({"name": "f_low", "type": "frequency", "modes": 3})
    with pytest.raises(CaseError, match=r"responses\[1\].rho: required with modes: 3"):
        load_case_dict(raw)
    raw["responses"][-1] = {"name": "f_low", "type": "frequency", "modes": 0}
    with pytest.raises(CaseError, match=r"responses\[1\].modes: expected an integer >= 1"):
        load_case_dict(raw)
    import yaml
    mech = yaml.safe_load((REPO / "cases" / "slider_crank.yaml").read_text())
    mech["responses"].append({"name": "f1", "type": "frequency"})
    with pytest.raises(CaseError, match="needs a structural model"):
        load_case_dict(mech)
