"""Beam members sized as engineers size them (issue 33): flexural buckling and the beam-column
interaction of AISC 360-16 (ANSI/AISC 360-16, Specification for Structural Steel Buildings,
§H1.1 Eq. H1-1a/b; elastic Euler load P_e = π²EI/(KL)²) against hand computations; the member
post-check of a beam frame; one error for a response on an element kind it does not support;
and the sensitivities of the new responses against the complex step of the whole run and the
adjoint.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import dynsens
from dynsens import CaseError
from dynsens.case.load import load_case_dict
from dynsens.errors import ProblemCollector
from dynsens.responses.member_stability import interaction_forms, interaction_ratio
from dynsens.models.base import StepState
from dynsens.postcheck import check_members
from helpers import assert_gradients_match_complex_step_and_adjoint
from test_beams import portal_frame, static_solution

E, FY = 210000.0, 235.0                    # MPa
L = 3000.0                                 # mm
D, T = 100.0, 5.0                          # tube, mm
A_HAND = np.pi / 4 * (D ** 2 - (D - 2 * T) ** 2)          # 1492.3 mm²
I_HAND = np.pi / 64 * (D ** 4 - (D - 2 * T) ** 4)         # 1.688e6 mm⁴
W_HAND = I_HAND / (D / 2)


def column(P: float, H: float, *, K: float = 2.0, ramp: float | None = None) -> dict:
    """A tube cantilever column along y (clamped base a, free top b; one beam element), an axial
    load P (N, compression) and a lateral load H (N) at the top; responses at K (cantilever: 2)."""
    fn = "constant" if ramp is None else {"type": "ramp", "t0": 0.0, "t1": ramp}
    return {
        "name": "column",
        "model": {"type": "structural", "dim": 2,
                  "nodes": {"a": {"coords": [0.0, 0.0], "fixed": "all"}, "b": {"coords": [0.0, L]}},
                  "elements": [{"type": "beam", "name": "col", "nodes": ["a", "b"], "E": E, "density": 7.85e-9,
                                "section": {"shape": "tube", "D": D, "t": T}}],
                  # near-critical damping of the (load-softened) sway and the axial mode
                  "damping": {"rayleigh": {"alpha": 96.0, "beta": 1e-3}},
                  "loads": [{"node": "b", "direction": "y", "value": -P, "function": fn},
                            {"node": "b", "direction": "x", "value": H, "function": fn}]},
        "integrator": {"dt": 1e-3, "t_end": 1e-3 if ramp is None else 5 * ramp},
        "sensitivity": {"enabled": False},
        "responses": [
            {"name": "buckling", "type": "buckling_ratio", "aggregate": "max", "effective_length_factor": K},
            {"name": "interaction", "type": "interaction_ratio", "aggregate": "max", "yield_stress": FY,
             "effective_length_factor": K},
        ],
    }


def h1_1(p: float, m: float) -> float:
    """AISC 360-16 Eq. H1-1a (P_r/P_c ≥ 0.2) or H1-1b (below), as the code selects them."""
    return p + 8 / 9 * m if p >= 0.2 else p / 2 + m


def hand_static_check(P: float, H: float, K: float, q: dict[str, float]) -> tuple[float, float, float, float]:
    """(buckling ratio, p, m, H1-1) of the static cantilever by statics of its deformed shape: the
    tip at (u_x, L + u_y) carries (H, −P); the base moment |M| = P u_x + H (L + u_y), the tip's is
    zero; N the tip force along the chord.  P_c = min(π²EI/(KL)², F_y A), M_c = F_y W."""
    ux, uy = q["b.x"], q["b.y"]
    chord = np.hypot(ux, L + uy)
    N = (H * ux - P * (L + uy)) / chord
    M = P * ux + H * (L + uy)
    Pe = np.pi ** 2 * E * I_HAND / (K * L) ** 2
    buckling = -N / Pe
    p = -N / min(Pe, FY * A_HAND)
    m = M / (FY * W_HAND)
    return buckling, p, m, h1_1(p, m)


@pytest.mark.parametrize("P, H, regime", [(50e3, 500.0, "a"), (8e3, 1500.0, "b")])
def test_cantilever_column_buckling_and_interaction_equal_the_hand_computation(P, H, regime) -> None:
    """Static equilibrium (the model's own Newton), checked at that one state: the buckling ratio
    −N(KL)²/(π²EI) and the interaction equal the statics above, and u = the H1-1 value of the
    governing equation (a: p ≥ 0.2; b: p < 0.2)."""
    K = 2.0
    case = load_case_dict(column(P, H, K=K))
    q = static_solution(case, load_steps=5)
    state = dict(zip(case.model.dof_labels(), q))
    buckling, p, m, code = hand_static_check(P, H, K, state)
    assert (p >= 0.2) == (regime == "a")
    chk = check_members(case, result=SimpleNamespace(history={"q": q[None, :]}))
    assert chk.names == ("col",)
    assert chk.buckling[0] == pytest.approx(buckling, rel=1e-10)
    assert chk.interaction[0] == pytest.approx(code, rel=1e-10)
    # no stress_ratio response: the stresses are not checked
    assert np.isnan(chk.tension[0]) and np.isnan(chk.compression[0])
    # the Euler load of this column at K = 2 is below the squash load: buckling governs P_c
    assert np.pi ** 2 * E * I_HAND / (K * L) ** 2 < FY * A_HAND


def test_quasi_static_run_reaches_the_hand_values_and_the_responses_equal_the_post_check() -> None:
    """A slow ramp with heavy damping ends near the static state: the sampled maxima of the
    responses equal the post-check of the same run (independent paths: the response's linear
    forms fed step by step, the post-check over the stored history) and the statics by hand
    to the run's distance from equilibrium."""
    P, H, K = 50e3, 500.0, 2.0
    case = load_case_dict(column(P, H, K=K, ramp=0.1))
    res = dynsens.run_case(case, history=("q",))
    chk = check_members(case, result=res)
    r = {k: float(np.real(v.value)) for k, v in res.responses.items()}
    assert r["buckling"] == pytest.approx(chk.buckling[0], rel=1e-12)
    assert r["interaction"] == pytest.approx(chk.interaction[0], rel=1e-12)
    static = load_case_dict(column(P, H, K=K))                     # the same loads, held constant
    state = dict(zip(static.model.dof_labels(), static_solution(static, load_steps=5)))
    buckling, _, _, code = hand_static_check(P, H, K, state)
    assert r["buckling"] == pytest.approx(buckling, rel=2e-3)
    assert r["interaction"] == pytest.approx(code, rel=2e-3)


def test_effective_length_factor_scales_the_buckling_ratio_by_K_squared() -> None:
    raw = column(50e3, 50.0, ramp=0.1)          # a small sway: P·δ below 1e-3 of the axial ratio
    raw["responses"] = [
        {"name": "k1", "type": "buckling_ratio", "aggregate": "max"},
        {"name": "k2", "type": "buckling_ratio", "aggregate": "max", "effective_length_factor": 2.0},
        {"name": "k07", "type": "buckling_ratio", "aggregate": "max", "effective_length_factor": 0.7}]
    r = {k: float(np.real(v.value)) for k, v in dynsens.run_case(load_case_dict(raw)).responses.items()}
    assert r["k2"] == pytest.approx(4.0 * r["k1"], rel=1e-13)
    assert r["k07"] == pytest.approx(0.49 * r["k1"], rel=1e-13)
    assert r["k1"] == pytest.approx(50e3 * L ** 2 / (np.pi ** 2 * E * I_HAND), rel=2e-3)


def test_continuous_interaction_agrees_with_H1_1_in_its_verdict_and_on_the_curve() -> None:
    """u = max(p + 8/9 m, p/2 + m) from the linear forms: ≤ 1 exactly where H1-1 holds, equal to
    H1-1's value where the selected equation is the larger (every point with H1-1 = 1 among them)."""
    rng = np.random.default_rng(3)
    forms = interaction_forms(1.0, FY)
    for _ in range(2000):
        p, m = rng.uniform(0, 1.3, size=2)
        # a member state with these ratios: b = p (compression, buckling governs), σ± at end 1
        sigma_a = -0.1 * p * FY                   # squash ratio 0.1 p < p: buckling governs
        v = np.array([p, p, sigma_a + m * FY, sigma_a - m * FY, sigma_a, sigma_a])
        u = float(interaction_ratio(v, forms))
        assert u == pytest.approx(max(p + 8 / 9 * m, p / 2 + m), rel=1e-13)
        code = h1_1(p, m)
        assert (u <= 1.0) == (code <= 1.0)
        if (p >= 0.2) == (p >= 2 * m / 9):
            assert u == pytest.approx(code, rel=1e-13)
    # on the curve: the two lines meet at (m, p) = (0.9, 0.2)
    v = np.array([0.2, 0.2, 0.9 * FY - 0.02 * FY, -0.9 * FY - 0.02 * FY, 0.0, 0.0])
    assert float(interaction_ratio(v, forms)) == pytest.approx(1.0, rel=1e-13)
    # the resistance factor divides the ratio; tension uses F_y A
    assert float(interaction_ratio(v, interaction_forms(1.0, FY, 0.9))) == pytest.approx(1 / 0.9, rel=1e-13)
    tension = np.array([-0.3, -0.3, 0.5 * FY, 0.5 * FY, 0.5 * FY, 0.5 * FY])
    assert float(interaction_ratio(tension, forms)) == pytest.approx(0.5, rel=1e-13)


def space_column(b: float, h: float) -> dict:
    """A 3D rectangle column along x (clamped at a; small rotations, the linear beam), compressed
    at b: the weaker axis buckles.  (Under pure compression the corotational 3D beam's Newton
    iteration stalls at a residual of ~2e-8, above the default tolerance: not this test's subject.)"""
    return {
        "name": "column3d",
        "model": {"type": "structural", "dim": 3,
                  "nodes": {"a": {"coords": [0.0, 0.0, 0.0], "fixed": "all"}, "b": {"coords": [L, 0.0, 0.0]}},
                  "elements": [{"type": "beam", "name": "col", "nodes": ["a", "b"], "E": E, "G": 81000.0,
                                "density": 7.85e-9, "section": {"shape": "rectangle", "b": b, "h": h}}],
                  "damping": {"rayleigh": {"alpha": 136.0, "beta": 1e-3}},
                  "loads": [{"node": "b", "direction": "x", "value": -1e3,
                             "function": {"type": "ramp", "t0": 0.0, "t1": 0.05}}]},
        "integrator": {"dt": 1e-3, "t_end": 0.15},
        "sensitivity": {"enabled": False},
        "responses": [{"name": "buckling", "type": "buckling_ratio", "aggregate": "max"}],
    }


def test_space_beam_buckles_about_its_weaker_axis() -> None:
    """3D beams give −N/P_e about both axes; the ratio is the weaker axis' P L²/(π² E min(I_y, I_z))."""
    b, h = 20.0, 50.0
    weak = h * b ** 3 / 12
    case = load_case_dict(space_column(b, h))
    value = float(np.real(dynsens.run_case(case).responses["buckling"].value))
    assert value == pytest.approx(1e3 * L ** 2 / (np.pi ** 2 * E * weak), rel=2e-3)


# ------------------------------------------------------------------ the post-check of a frame
def frame_with_stability() -> dict:
    raw = portal_frame()
    beams = ["col_a", "col_b", "girder_1", "girder_2"]
    raw["responses"] += [
        {"name": "buckling_ks", "type": "buckling_ratio", "elements": beams, "effective_length_factor": 2.0,
         "rho": 20.0},
        {"name": "interaction_ks", "type": "interaction_ratio", "yield_stress": FY, "rho": 20.0,
         "effective_length_factor": 2.0},
        {"name": "interaction_max", "type": "interaction_ratio", "yield_stress": "470/2", "aggregate": "max",
         "elements": ["col_a", "col_b"], "effective_length_factor": 2.0, "resistance_factor": 0.9},
    ]
    return raw


def test_post_check_of_a_beam_frame_at_every_stored_step() -> None:
    """Every member's ratios by hand from the stored history of end forces (N, M1, M2), section
    by section: σ = N/A ± M/W, −N(KL)²/(π²EI), H1-1 as u; and the bar's as before."""
    case = load_case_dict(frame_with_stability())
    res = dynsens.run_case(case, history=("q",))
    chk = check_members(case, result=res)
    assert chk.names == ("brace", "col_a", "col_b", "girder_1", "girder_2")
    assert chk.steps == len(res.history["q"])
    model, params = case.model, case.model.parameters(case.x0)
    q = res.history["q"]
    z = np.zeros_like(q)
    states = StepState(q, z, z, np.zeros((len(q), 0)), np.zeros((len(q), 0)), np.zeros((len(q), 0)))
    sections = {"col_a": ("tube", 80.0, 5.0), "col_b": ("tube", 80.0, 5.0)}
    for k, name in enumerate(chk.names[1:], start=1):
        forces = model.output({"element": name, "kind": "force"}, "test", ProblemCollector("test"))
        N, M1, M2 = np.real(forces.fn(0.0, states, params)).T           # (steps,) each
        i = model.beams.names.index(name)
        A, I, c, Lb = (float(np.real(params[f"beam_{x}"][i])) for x in ("A", "I", "c", "L"))
        if name in sections:                                            # the tube by hand
            _, Dt, tt = sections[name]
            assert A == pytest.approx(np.pi / 4 * (Dt ** 2 - (Dt - 2 * tt) ** 2), rel=1e-14)
            assert I == pytest.approx(np.pi / 64 * (Dt ** 4 - (Dt - 2 * tt) ** 4), rel=1e-14)
        W = I / c
        sigma = np.concatenate([N / A + M1 / W, N / A - M1 / W, N / A + M2 / W, N / A - M2 / W])
        assert chk.tension[k] == pytest.approx(sigma.max() / 235.0, rel=1e-12)
        assert chk.compression[k] == pytest.approx(-sigma.min() / 235.0, rel=1e-12)
        b = -N * (2.0 * Lb) ** 2 / (np.pi ** 2 * E * I)
        assert chk.buckling[k] == pytest.approx(b.max(), rel=1e-12)
        p = np.maximum(b, np.abs(N) / (FY * A))
        m = np.maximum(np.abs(M1), np.abs(M2)) / (FY * W)
        u = np.maximum(p + 8 / 9 * m, p / 2 + m)
        assert chk.interaction[k] == pytest.approx(u.max() / 0.9, rel=1e-12)   # the smallest φ of the case
    assert np.isnan(chk.interaction[0]) and np.isnan(chk.buckling[0])        # a bar without inertia
    # the response's sampled maximum over the columns is the post-check's (φ = 0.9 both)
    assert float(np.real(res.responses["interaction_max"].value)) == pytest.approx(chk.interaction[1:3].max(),
                                                                                   rel=1e-12)
    assert chk.largest == pytest.approx(max(np.nanmax(getattr(chk, k)) for k in
                                            ("tension", "compression", "buckling", "interaction")))
    assert chk.worst()[1] in ("tension", "compression", "buckling", "interaction")


# ------------------------------------------------------------------ errors
def load_problems(raw) -> str:
    with pytest.raises(CaseError) as err:
        load_case_dict(raw)
    return str(err.value)


def test_a_response_on_an_element_kind_it_does_not_support_is_one_error_naming_both() -> None:
    raw = portal_frame()
    raw["responses"] = [{"name": "brace_check", "type": "interaction_ratio", "yield_stress": FY, "rho": 10.0,
                         "elements": ["col_a", "brace"]}]
    msg = load_problems(raw)
    assert "(1 problem)" in msg
    assert "responses[0].elements: interaction_ratio of response 'brace_check' applies to beams, " \
           "not to bars (brace)" in msg
    # a bar without a second moment of area: one problem at the response's own key
    raw["responses"] = [{"name": "bars_buckle", "type": "buckling_ratio", "aggregate": "max"}]
    msg = load_problems(raw)
    assert "(1 problem)" in msg and "responses[0].elements: buckling needs the bar's 'inertia'" in msg
    # springs carry no buckling: named with the response, once, at its type
    raw = portal_frame()
    raw["model"]["elements"].append({"type": "spring", "name": "bumper", "dofs": ["m.y", "ground"], "k": 10.0})
    raw["responses"] = [{"name": "bumper_buckle", "type": "buckling_ratio", "aggregate": "max",
                         "elements": ["bumper", "col_a"]}]
    msg = load_problems(raw)
    assert "(1 problem)" in msg
    assert "responses[0].type: buckling_ratio of response 'bumper_buckle' reads 'buckling': springs " \
           "report only 'force', not 'buckling': bumper" in msg


@pytest.mark.parametrize("change, path, needle", [
    ({"yield_stress": -1.0}, "responses[0].yield_stress", "expected a positive number"),
    ({"resistance_factor": 1.5}, "responses[0].resistance_factor", "expected a factor in (0, 1]"),
    ({"effective_length_factor": 0.0}, "responses[0].effective_length_factor", "expected a positive number"),
    ({"elements": ["col_x"]}, "responses[0].elements", "unknown element 'col_x'"),
    ({"rho": None, "aggregate": "max", "extra": 1}, "responses[0].extra", "extra"),
])
def test_interaction_entries_are_checked_with_their_key_path(change, path, needle) -> None:
    raw = portal_frame()
    entry = {"name": "u", "type": "interaction_ratio", "yield_stress": FY, "rho": 10.0}
    entry.update(change)
    raw["responses"] = [{k: v for k, v in entry.items() if v is not None}]
    msg = load_problems(raw)
    assert f"{path}:" in msg and needle in msg


def test_interaction_on_a_model_without_beams_and_K_on_bars_only_are_refused() -> None:
    raw = portal_frame()
    raw["model"]["elements"] = [e for e in raw["model"]["elements"] if e["type"] != "beam"]
    raw["model"]["elements"][0]["inertia"] = 1000.0
    raw["responses"] = [{"name": "u", "type": "interaction_ratio", "yield_stress": FY, "rho": 10.0},
                        {"name": "b", "type": "buckling_ratio", "rho": 10.0, "effective_length_factor": 2.0}]
    msg = load_problems(raw)
    assert "responses[0].type: interaction_ratio of response 'u' applies to beams; the model " \
           "(StructuralModel) has none" in msg
    assert "responses[1].effective_length_factor: applies to beams" in msg


# ------------------------------------------------------------------ sensitivities
def test_stability_gradients_equal_complex_step_of_the_whole_run_and_the_adjoint() -> None:
    """Sections, a coordinate and E of the frame are design variables; KS and sampled maxima."""
    raw = frame_with_stability()
    raw["responses"] = [r for r in raw["responses"] if r["type"] in ("buckling_ratio", "interaction_ratio")]
    case = load_case_dict(raw)
    res = dynsens.run_case(case)
    assert all(np.isfinite(np.real(r.value)) and np.any(r.gradient != 0) for r in res.responses.values())
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-8, rtol_adjoint=1e-10)


def test_space_beam_interaction_adds_both_bending_ratios_as_H1_1_does() -> None:
    """The linear 3D cantilever column (clamped at a; along x; h = 50 along global z by the default
    orientation, b = 20 along y) under P and tip loads H_y, H_z: N = −P, base moments H_y L about
    the weak axis (I = h b³/12, W = I/(b/2)) and H_z L about the strong one (b h³/12, h/2); H1-1
    with ΣM_r/M_c = M_weak/(F_y W_weak) + M_strong/(F_y W_strong) and P_c of the weaker axis."""
    from test_beams3d import static
    b, h, P, Hy, Hz, K = 20.0, 50.0, 1.5e3, 20.0, 30.0, 2.0
    raw = space_column(b, h)
    raw["model"]["loads"] = [{"node": "b", "direction": d, "value": v, "function": "constant"}
                             for d, v in (("x", -P), ("y", Hy), ("z", Hz))]
    raw["responses"] = [{"name": "u", "type": "interaction_ratio", "yield_stress": FY, "aggregate": "max",
                         "effective_length_factor": K}]
    case = load_case_dict(raw)
    q = np.array(list(static(case).values()))
    chk = check_members(case, result=SimpleNamespace(history={"q": q[None, :]}))
    weak, strong = h * b ** 3 / 12, b * h ** 3 / 12
    p = max(P * (K * L) ** 2 / (np.pi ** 2 * E * weak), P / (FY * b * h))
    m = Hy * L / (FY * weak / (b / 2)) + Hz * L / (FY * strong / (h / 2))
    assert p >= 0.2 and p >= 2 * m / 9                      # H1-1a governs: u is its value
    assert chk.interaction[0] == pytest.approx(h1_1(p, m), rel=1e-10)
    assert chk.buckling[0] == pytest.approx(P * (K * L) ** 2 / (np.pi ** 2 * E * weak), rel=1e-10)


# ------------------------------------------------------------------ verification of a sized beam frame
def test_the_verification_of_an_optimum_post_checks_beams_and_stores_their_interaction(tmp_path) -> None:
    """``verify_design`` (the check an optimum must pass at half the step and on a longer window)
    post-checks the frame's beams as ``check_members`` does, run by run, interaction included,
    and writes every ratio to the file; it used to skip a model whose members are beams."""
    import h5py

    from dynsens.optimize.verify import store_verification, verify_design
    raw = frame_with_stability()
    raw["optimization"] = {"objective": "mass", "constraints": [{"response": "interaction_ks", "upper": 1.0}]}
    case = load_case_dict(raw)
    v = verify_design(case, horizon=None, tail=0.0)
    assert set(v.members) == {"case", "refined"}
    chk = check_members(case, result=dynsens.run_case(case, history=("q",)))
    m = v.members["case"]
    assert m.names == chk.names and "col_a" in m.names
    for kind in ("tension", "compression", "buckling", "interaction"):
        np.testing.assert_array_equal(getattr(m, kind), getattr(chk, kind))
    assert np.isfinite(v.members["refined"].interaction[1:]).all()
    store_verification(tmp_path / "v.h5", v)
    with h5py.File(tmp_path / "v.h5") as f:
        np.testing.assert_array_equal(f["verification/members/case/interaction"][()], chk.interaction)
