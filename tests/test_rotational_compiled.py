"""Rotational spring-dampers in the compiled multibody kernel, against the Python element.

The law (:func:`.rotational.rotational_law`) is written once and run by Python and by numba;
the kernel applies it through two products of its own (u1·u2, v1·u2).  The reference here is
the term-by-term element (:class:`.rotational.RotationalSpringDamper`), which applies its
generalized force T ∂θ/∂q through the directions' own transposed Jacobians:

* the compiled law equals the Python law (real and complex), and its partials equal complex
  step of its own weights (relative 1e-12);
* on a spatial pair (skew axis) and on a planar chain, at random states off any solution, real
  and complex: the kernel's force (its residual minus that of the same model without the
  springs) equals −Q_ext of the elements; its R_q and R_q̇ contributions equal complex step of
  the elements' Q_ext (relative 1e-10), dense and on the sparse path; its design partials (k,
  c, θ_0 as design variables) equal complex step of the elements' Q_ext in the parameters;
* the gradient of a 3-link chain's response equals complex step of the whole run (relative
  1e-8), direct and adjoint, dense and sparse.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import dynsens
from dynsens.models.base import StepState
from dynsens.models.multibody import compiled
from dynsens.models.multibody.bodies import Ctx
from dynsens.models.multibody.compiled_step import step_factory
from dynsens.models.multibody.kernel_compiled import CompiledKin
from dynsens.models.multibody.rotational import LAW_SIZE, rotational_law
from helpers import complex_step_gradients, rel_err

pytestmark = pytest.mark.skipif(not compiled.enabled(), reason="the compiled kernel is switched off")

H = 1e-30          # complex step


def test_compiled_law_equals_the_python_law_and_its_partials_complex_step() -> None:
    rng = np.random.default_rng(7)
    for is_complex in (False, True):
        for _ in range(20):
            args = list(rng.standard_normal(7))
            args[0] += 1.5                                     # away from x = y = 0
            if is_complex:
                args = [a + 1e-3j * rng.standard_normal() for a in args]
            py = rotational_law(*[np.asarray(a) for a in args])
            nb = compiled._rotational(*args)
            assert len(py) == len(nb) == LAW_SIZE
            for a, b in zip(py, nb):
                assert abs(a - b) <= 1e-14 * max(1.0, abs(a)), (a, b)
        # ∂w_x, ∂w_y in x, y, ẋ, ẏ (entries 5–12) against complex step of the weights (3, 4)
        args = [1.3, -0.4, 0.7, 0.2, 3.0, 0.5, 0.1]
        for j in range(4):
            pert = [complex(a) for a in args]
            pert[j] += 1j * H
            w = rotational_law(*pert)
            exact = rotational_law(*args)
            assert np.imag(w[3]) / H == pytest.approx(exact[5 + j], rel=1e-12, abs=1e-14)
            assert np.imag(w[4]) / H == pytest.approx(exact[9 + j], rel=1e-12, abs=1e-14)
        th = np.arctan2(-0.4, 1.3)
        T = -(3.0 * (th - 0.1) + 0.5 * (1.3 * 0.2 + 0.4 * 0.7) / (1.3 ** 2 + 0.4 ** 2))
        assert exact[0] == pytest.approx(th, rel=1e-15) and exact[2] == pytest.approx(T, rel=1e-14)


# ------------------------------------------------------------------ cases
DESIGN = [{"name": "k", "value": 30.0, "lower": 1.0, "upper": 100.0},
          {"name": "c", "value": 0.4, "lower": 0.0, "upper": 1.0},
          {"name": "th0", "value": 0.1, "lower": -0.5, "upper": 0.5}]


def _pair() -> dict:
    """Two bodies on a spherical joint, a rotational spring about a skew axis (spatial)."""
    return {
        "name": "pair", "design": {"variables": copy.deepcopy(DESIGN)},
        "model": {"type": "multibody", "gravity": [0.0, -9.81, 0.0],
                  "bodies": {"a": {"mass": 2.0, "inertia": [0.1, 0.2, 0.3], "position": [0.5, 0.2, 0.1]},
                             "b": {"mass": 1.5, "inertia": [0.05, 0.07, 0.09], "position": [1.2, -0.3, 0.2]}},
                  "joints": [{"name": "ja", "type": "spherical", "body_1": "ground", "body_2": "a",
                              "point": [0.4, 0.1, 0.0]},
                             {"name": "jb", "type": "spherical", "body_1": "a", "body_2": "b",
                              "point": [1.0, 0.0, 0.2]}],
                  "forces": [{"type": "rotational_spring_damper", "name": "rs", "body_1": "a", "body_2": "b",
                              "axis": [0.2, 0.3, 1.0], "stiffness": "k", "damping": "c", "free_angle": "th0"}]},
        "integrator": {"scheme": "newmark", "dt": 1.0e-3, "t_end": 0.01},
        "sensitivity": {"enabled": True, "partials": "complex"},
        "responses": [{"name": "yb", "type": "value", "quantity": {"body": "b", "kind": "position"},
                       "component": "b.y"}],
    }


def _chain(n: int, steps: int = 10, dt: float = 2.0e-3) -> dict:
    """A planar chain of n links hinged end to end (the first to the ground), a rotational
    spring-damper at every hinge, gravity; released straight."""
    ell = 1.0 / n
    m = ell
    bodies = {f"l{i + 1}": {"mass": m, "inertia": [m * 1e-5, m * ell ** 2 / 12, m * ell ** 2 / 12],
                            "position": [(i + 0.5) * ell, 0.0, 0.0]} for i in range(n)}
    joints, forces = [], []
    for i in range(n):
        b1, b2 = ("ground" if i == 0 else f"l{i}"), f"l{i + 1}"
        joints.append({"name": f"h{i + 1}", "type": "revolute", "body_1": b1, "body_2": b2,
                       "point": [i * ell, 0.0, 0.0], "axis": [0, 0, 1]})
        forces.append({"type": "rotational_spring_damper", "name": f"s{i + 1}", "body_1": b1, "body_2": b2,
                       "axis": [0, 0, 1], "stiffness": "k", "damping": "c", "free_angle": "th0"})
    return {
        "name": "chain", "design": {"variables": copy.deepcopy(DESIGN)},
        "model": {"type": "multibody", "gravity": [0.0, -9.81, 0.0], "bodies": bodies, "joints": joints,
                  "forces": forces},
        "integrator": {"scheme": "newmark", "dt": dt, "t_end": steps * dt},
        "sensitivity": {"enabled": True, "partials": "complex"},
        "responses": [{"name": "tip_y", "type": "value", "quantity": {"body": f"l{n}", "kind": "position"},
                       "component": f"l{n}.y"},
                      {"name": "s1_torque", "type": "value", "quantity": {"element": "s1", "kind": "torque"}}],
    }


def _without_springs(raw: dict) -> dict:
    bare = copy.deepcopy(raw)
    bare["model"]["forces"] = [f for f in bare["model"]["forces"] if f["type"] != "rotational_spring_damper"]
    bare["responses"] = [r for r in bare["responses"] if "element" not in r["quantity"]]
    return bare


def _q_ext(model, q, qd, prm) -> np.ndarray:
    """Q_ext (n_q,) of the model's rotational spring-dampers, term by term (the Python element)."""
    dt = np.result_type(q, qd, prm.pv, float)
    out = np.zeros((q.size, 1), dt)
    ctx = Ctx(q[:, None], qd[:, None], np.zeros((q.size, 1)), prm, 0.0)
    for el in model.rotational:
        el.add(ctx, out)
    return out[:, 0]


def _close(a, b, tol: float, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    scale = max(float(np.max(np.abs(b))), 1e-300)
    err = float(np.max(np.abs(a - b))) / scale
    assert err < tol, f"{what}: kernel differs from the element by {err:.2e} (relative to {scale:.3g})"


def _dense(A):
    return A.toarray() if hasattr(A, "toarray") else np.asarray(A)


@pytest.mark.filterwarnings("ignore:.*used by no element")      # (the model without the springs)
@pytest.mark.parametrize("build", [_pair, lambda: _chain(3)], ids=["spatial pair", "planar chain"])
@pytest.mark.parametrize("linear_algebra", ["dense", "sparse"])
def test_kernel_force_jacobians_and_design_partials_equal_the_element(build, linear_algebra) -> None:
    raw = build()
    raw["model"]["linear_algebra"] = linear_algebra
    case = dynsens.load_case_dict(raw)
    bare = dynsens.load_case_dict(_without_springs(raw))
    m, mb = case.model, bare.model
    assert m.rotational and not m.other_forces                 # served by the kernel, not as Python forces
    if linear_algebra == "dense":
        assert step_factory(m, newton=True, refactor=True) is not None   # and by the compiled step
    tr = m.traits
    rng = np.random.default_rng(11)
    for is_complex in (False, True):
        x = case.x0 + (1e-9j * np.eye(case.x0.size)[0] if is_complex else 0.0)
        prm, prm_b = m.parameters(x), mb.parameters(x)
        q0 = np.asarray(m.initial_state(prm)[0])
        for trial in range(2):
            # complex states as complex step forms them: small imaginary parts (θ's atan2 carries
            # its perturbation to first order only, in both the kernel and the element)
            def rnd(n: int, scale: float = 1.0, cplx: bool = is_complex) -> np.ndarray:
                v = scale * rng.standard_normal(n)
                return v + 1e-9j * rng.standard_normal(n) if cplx else v
            s = StepState(q0 + rnd(tr.n_q, 3e-2), rnd(tr.n_q), rnd(tr.n_q), rnd(tr.n_lam, 10.0),
                          np.zeros(0), np.zeros(0))
            t = 0.01 * (trial + 1)
            what = f"{'complex' if is_complex else 'real'} state {trial}"
            assert isinstance(m.kinematics(s, prm), CompiledKin)
            Q = _q_ext(m, s.q, s.qd, prm)
            force = -(m.residual(t, s, prm) - mb.residual(t, s, prm_b))[:tr.n_q]
            _close(force, Q, 1e-12, f"Q_ext, {what}")
            lin, lin_b = m.linearize(t, s, prm), mb.linearize(t, s, prm_b)
            Kq = -(_dense(lin.R_q) - _dense(lin_b.R_q))[:tr.n_q]
            Kqd = -(_dense(lin.R_qd) - _dense(lin_b.R_qd))[:tr.n_q]
            if is_complex:      # central differences of the element (complex data)
                e = 1e-6
                ref_q = np.stack([(_q_ext(m, s.q + e * d, s.qd, prm) - _q_ext(m, s.q - e * d, s.qd, prm)) / (2 * e)
                                  for d in np.eye(tr.n_q)], axis=1)
                ref_qd = np.stack([(_q_ext(m, s.q, s.qd + e * d, prm) - _q_ext(m, s.q, s.qd - e * d, prm)) / (2 * e)
                                   for d in np.eye(tr.n_q)], axis=1)
                tol = 1e-7
            else:               # complex step of the element
                ref_q = np.stack([np.imag(_q_ext(m, s.q + 1j * H * d, s.qd, prm)) / H for d in np.eye(tr.n_q)], axis=1)
                ref_qd = np.stack([np.imag(_q_ext(m, s.q, s.qd + 1j * H * d, prm)) / H for d in np.eye(tr.n_q)],
                                  axis=1)
                tol = 1e-10
            _close(Kq, ref_q, tol, f"∂Q_ext/∂q, {what}")
            _close(Kqd, ref_qd, tol, f"∂Q_ext/∂q̇, {what}")
        if is_complex:
            continue
        # design partials of the kernel's force (a batch of complex-perturbed parameter sets, as
        # the complex partials form them) against complex step of the element in the parameters
        sets = [m.parameters(case.x0 + 1j * H * d) for d in np.eye(case.x0.size)]
        sets_b = [mb.parameters(case.x0 + 1j * H * d) for d in np.eye(case.x0.size)]
        Rd = -np.imag(m.residual_batch(0.02, s, sets) - mb.residual_batch(0.02, s, sets_b))[:tr.n_q] / H
        ref = np.stack([np.imag(_q_ext(m, s.q.astype(complex), s.qd.astype(complex), p)) / H for p in sets], axis=1)
        assert np.all(np.max(np.abs(ref), axis=0) > 0)         # k, c and θ_0 all act
        _close(Rd, ref, 1e-10, "∂Q_ext/∂(k, c, θ_0)")


@pytest.mark.parametrize("method, linear_algebra", [("direct", "dense"), ("adjoint", "dense"),
                                                    ("direct", "sparse")])
def test_chain_gradient_matches_complex_step_of_the_run(method, linear_algebra) -> None:
    """d(tip y, first spring's torque)/d(k, c, θ_0) of a 3-link chain over 25 steps against
    complex step of the whole run: relative 1e-8."""
    raw = _chain(3, steps=25)
    raw["model"]["linear_algebra"] = linear_algebra
    raw["sensitivity"]["method"] = method
    case = dynsens.load_case_dict(raw)
    res = dynsens.run_case(case)
    assert res.status == "completed" and res.method == method
    cs = complex_step_gradients(case)
    for name, r in res.responses.items():
        assert np.all(np.abs(cs[name]) > 0), name
        assert rel_err(r.gradient, cs[name]) < 1e-8, (name, r.gradient, cs[name])
