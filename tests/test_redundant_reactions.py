"""Reactions of a redundant set do not depend on the order of the joints in the file.

Bricard's mechanism (cases/bricard.yaml, IFToMM A04) has one dependent equation among its 30;
which one is left out of Φ follows the joints' order (J6.v.w in the file's order, J1.v.w
reversed, J3.v.w for the permutation below).  Before the minimum-norm split the reactions were
those of the kept equations: reversing the joints moved J1_force_ks from 36.23 N to 47.21 N for
the same motion.  Now the dependent joints report the minimum-norm multipliers over all their
equations (docs/multibody.md, "redundant joints"; dynsens/models/multibody/reaction_split.py): the same
reaction history in every order (to the Newton tolerance of the motion, which itself differs by
~4e-6 m between orders after 1 s), its minimum-norm property checked against an SVD of the full
constraint Jacobian, and its gradients (direct and adjoint) against central differences.
"""
from __future__ import annotations

import copy
import json
from dataclasses import replace

import numpy as np
import pytest
import yaml

import dynsens
from conftest import CASES
from dynsens.models.base import StepState
from dynsens.models.multibody.assembly import jacobian_rows
from dynsens.models.multibody.reaction_split import split_of
from helpers import pendulum_with_coaxial_hinges, rel_err

ORDERS = {"file": [0, 1, 2, 3, 4, 5], "reversed": [5, 4, 3, 2, 1, 0],
          "permutation": [3, 0, 5, 1, 4, 2]}            # numpy default_rng(0).permutation(6) is another
DROPPED = {"file": "J6.v.w", "reversed": "J1.v.w", "permutation": "J3.v.w"}
QUANTITIES = [
    {"name": "J1_force", "quantity": {"joint": "J1", "kind": "reaction_force"}, "unit": "N"},
    {"name": "J4_moment", "quantity": {"joint": "J4", "kind": "reaction_moment"}, "unit": "N*m"},
    {"name": "J6_frame", "quantity": {"joint": "J6", "kind": "reaction_force_joint_frame"}, "unit": "N"},
    {"name": "J2_multipliers", "quantity": {"joint": "J2", "kind": "multipliers"}},
]


def _bricard(order: str, t_end: float | None = None) -> dict:
    raw = yaml.safe_load((CASES / "bricard.yaml").read_text())
    raw["model"]["joints"] = [raw["model"]["joints"][i] for i in ORDERS[order]]
    raw["output"] = {"quantities": copy.deepcopy(QUANTITIES)}
    if t_end is not None:
        raw["integrator"]["t_end"] = t_end
    return raw


@pytest.fixture(scope="module")
def runs():
    out = {}
    for order in ORDERS:
        case = dynsens.load_case_dict(_bricard(order))
        assert [f"{j}.{lab}" for j, lab, _ in case.model.redundant] == [DROPPED[order]]
        out[order] = (case, dynsens.run_case(case, sensitivities=False, history=("q",)))
    return out


@pytest.mark.parametrize("order", ["reversed", "permutation"])
def test_the_reactions_of_bricard_are_the_same_in_every_order_of_the_joints(runs, order):
    """J1's reaction history, J4's moment, J6's joint-frame force, J2's multipliers and
    J1_force_ks agree with the file's order (before: J1_force_ks 36.23 N against 47.21 N)."""
    _, ref = runs["file"]
    _, res = runs[order]
    assert res.status == ref.status == "completed"
    # the motion: the same to the Newton tolerance (which equation is left out does not move it)
    assert np.max(np.abs(res.history["q"] - ref.history["q"])) < 1e-5
    for name, tol in (("J1_force", 1e-5), ("J4_moment", 1e-5), ("J6_frame", 1e-5), ("J2_multipliers", 1e-5)):
        a, b = res.quantities[name].value, ref.quantities[name].value
        assert res.quantities[name].components == ref.quantities[name].components, name
        assert np.max(np.abs(a - b)) <= tol * np.max(np.abs(b)), (name, np.max(np.abs(a - b)))
    ks, ks_ref = res.responses["J1_force_ks"].value, ref.responses["J1_force_ks"].value
    assert abs(ks - ks_ref) <= 1e-6 * ks_ref, (ks, ks_ref)
    assert ks_ref == pytest.approx(34.852, abs=5e-3)            # the documented value (README)


def test_the_multipliers_of_a_dependent_joint_cover_all_its_equations(runs):
    """J6's multipliers list its five equations, the left-out J6.v.w included, in every order."""
    for order, (case, _) in runs.items():
        out = dynsens.models.multibody.outputs.resolve_output(
            case.model, {"joint": "J6", "kind": "multipliers"}, "q", dynsens.errors.ProblemCollector())
        assert out.labels == ("J6.x", "J6.y", "J6.z", "J6.u.w", "J6.v.w"), order


def test_the_split_is_the_minimum_norm_multiplier(runs):
    """At a state of the run: the split gives the model's constraint force J_Φᵀλ, and among all
    multipliers that do (λ⁰ + N c, N the left null space of the full Jacobian from its SVD) its
    joint part is the one of least norm — found here by least squares, independently of the
    closed form the model uses."""
    case, _ = runs["reversed"]
    m = case.model
    prm = m.parameters(case.x0)
    short = dynsens.run_case(dynsens.load_case_dict(_bricard("reversed", 0.3)), sensitivities=False,
                             history=("q", "qd", "qdd", "lam"))
    k = -1
    q, lam = short.history["q"][k], short.history["lam"][k]
    split = split_of(m)
    eqs = m.eqs + [eq for _, _, eq in m.redundant]
    J = np.real(jacobian_rows(eqs, q, prm, short.time[k]))
    lam0 = np.r_[lam, np.zeros(len(m.redundant))]
    U, sv, _ = np.linalg.svd(J)
    # one dependency: one singular value at the level of the state's constraint residual
    assert sv[-1] < 1e-6 * sv[0] and sv[-2] > 1e-3 * sv[0], sv[-2:] / sv[0]
    N = U[:, -1:]                                     # J_Φᵀ N ≈ 0
    joint_rows = np.array([not lab.endswith(".normalization") for lab in m.eq_owner] + [True] * len(m.redundant))
    c = np.linalg.lstsq(N[joint_rows], -lam0[joint_rows], rcond=None)[0]
    best = lam0 + N @ c
    owner = m.eq_owner + [f"{j}.{lab}" for j, lab, _ in m.redundant]
    row_of = {o: i for i, o in enumerate(owner)}
    total = np.zeros(m.traits.n_q)
    for jt in m.joints:
        got, force = split.joint(jt, short.time[k], q, lam, prm)
        want = best[[row_of[f"{jt.name}.{lab}"] for lab in split.labels[jt.name]]]
        assert np.max(np.abs(got[0] - want)) <= 1e-9 * np.max(np.abs(best)), jt.name
        total += force[0]
    # the split exerts the model's constraint force (the normalisations' multipliers follow), to
    # the accuracy of the dependency at a state that holds Φ = 0 to the Newton tolerance
    norm = ~joint_rows
    assert np.max(np.abs(total + J[norm].T @ best[norm] - J.T @ lam0)) <= 1e-6 * np.max(np.abs(J.T @ lam0))
    # the model's own split (the left-out equation at zero) has a larger norm
    assert np.linalg.norm(best[joint_rows]) < np.linalg.norm(lam0[joint_rows])


@pytest.mark.parametrize("order", ["file", "reversed"])
def test_the_gradients_of_reaction_responses_match_central_differences(order):
    """J1_force_ks, J1's end force Fy and J4's end moment: direct and adjoint gradients against
    central differences of the whole run (h = 1e-5 × max(1, |x|); their error ~1e-9 here)."""
    raw = _bricard(order, 0.3)
    raw["sensitivity"]["partials"] = "complex"
    raw["responses"] += [
        {"name": "J1_fy_end", "type": "value", "quantity": {"joint": "J1", "kind": "reaction_force"},
         "component": "J1.Fy", "unit": "N"},
        {"name": "J4_mz_end", "type": "value", "quantity": {"joint": "J4", "kind": "reaction_moment"},
         "component": "J4.Mz", "unit": "N*m"}]
    case = dynsens.load_case_dict(raw)
    runs = {}
    for method in ("direct", "adjoint"):
        c = copy.copy(case)
        c.plan = replace(case.plan, method=method)
        runs[method] = dynsens.run_case(c)
        assert runs[method].method == method
    names = ("J1_force_ks", "J1_fy_end", "J4_mz_end")
    fd = {n: np.zeros(case.x0.size) for n in names}
    for j in range(case.x0.size):
        h = 1e-5 * max(1.0, abs(case.x0[j]))
        e = np.zeros(case.x0.size)
        e[j] = h
        plus, minus = (dynsens.run_case(case, case.x0 + s * e, sensitivities=False, history=()) for s in (1, -1))
        for n in names:
            fd[n][j] = (plus.responses[n].value - minus.responses[n].value) / (2 * h)
    for n in names:
        for method, res in runs.items():
            assert rel_err(res.responses[n].gradient, fd[n]) < 1e-6, (n, method, res.responses[n].gradient, fd[n])


def test_the_summary_and_the_file_name_the_dependent_joints(tmp_path):
    import h5py
    from click.testing import CliRunner

    import dynsens.cli.simulate  # noqa: F401
    from dynsens.cli.main import cli
    case = tmp_path / "bricard_reversed.yaml"
    case.write_text(yaml.safe_dump(_bricard("reversed", 0.02)))
    out = tmp_path / "b.h5"
    r = CliRunner().invoke(cli, ["simulate", str(case), "-o", str(out), "--no-sensitivities"])
    assert r.exit_code == 0, r.output
    assert "left out of Phi: J1.v.w" in r.output
    assert "reactions of the dependent joints J6, J5, J4, J3, J2, J1: the minimum-norm multipliers" in r.output
    with h5py.File(out, "r") as f:
        assert json.loads(f.attrs["redundant_equations"]) == ["J1.v.w"]
        assert json.loads(f.attrs["dependent_joints"]) == ["J6", "J5", "J4", "J3", "J2", "J1"]


def test_joints_outside_the_dependent_set_keep_their_reactions():
    """A pendulum held by two coaxial hinges and a second pendulum on its own spherical joint:
    only the hinges are dependent; the other joint's reaction is the model's own multiplier
    (unique), evaluated by the ordinary path."""
    raw = pendulum_with_coaxial_hinges(yaml.safe_load((CASES / "pendulum_3d.yaml").read_text()))
    case = dynsens.load_case_dict(raw)
    m = case.model
    assert m.dependent_joints == ["pivot", "hinge2"]
    assert "other" not in split_of(m).positions
    prm = m.parameters(case.x0)
    q0, qd0, _ = m.initial_state(prm)
    z = np.zeros(m.traits.n_q)
    lam = np.arange(1.0, m.traits.n_lam + 1)
    s = StepState(q0, qd0, z, lam, z[:0], z[:0])
    out = dynsens.models.multibody.outputs.resolve_output(
        m, {"joint": "other", "kind": "multipliers"}, "q", dynsens.errors.ProblemCollector())
    assert np.array_equal(out.fn(0.0, s, prm), lam[list(next(j for j in m.joints if j.name == "other").rows)])
