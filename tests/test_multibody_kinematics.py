"""Multibody building blocks against complex-step derivatives.

Every joint's Φ, J_Φ (through J_Φᵀλ), Φ̇ and Φ̈ (hence F_c), the inertia terms, every force
element's generalized force and ``linearize()`` are compared with complex-step derivatives
of the model's own complex-safe functions, at random (not normalised, not assembled) states.
Tolerances: 1e-12 relative (complex step is exact to round-off).
"""
from __future__ import annotations

import numpy as np
import pytest

from dynsens.errors import ProblemCollector
from dynsens.models.base import StepState
from dynsens.models.parameters import ParameterTable
from dynsens.models.multibody.assembly import jacobian_rows
from dynsens.models.multibody.bodies import Ctx
from dynsens.models.registry import build_model

H = 1e-30
RTOL = 1e-12

JOINTS = [
    {"name": "rev", "type": "revolute", "point": [0.3, 0.1, -0.2], "axis": [0.2, 0.3, 1.0]},
    {"name": "pri", "type": "prismatic", "point": [0.1, 0.2, 0.0], "axis": [1.0, 0.2, 0.1]},
    {"name": "sph", "type": "spherical", "point": [0.2, -0.1, 0.3]},
    {"name": "cyl", "type": "cylindrical", "point": [0.0, 0.1, 0.1], "axis": [0.1, 1.0, 0.2]},
    {"name": "fix", "type": "fixed", "point": [0.2, 0.2, 0.2], "axis": [0.3, -0.2, 1.0]},
    {"name": "pin", "type": "planar_pin", "marker_1": "m1", "marker_2": "m2", "axis": [0.0, 0.1, 1.0]},
]
DRIVERS = [
    {"name": "drv_rev", "type": "driving", "joint": "rev", "rate": 1.3, "amplitude": 0.2,
     "frequency": 0.7, "phase": 0.1},
    {"name": "drv_pri", "type": "driving", "joint": "pri", "rate": "0.4*w", "amplitude": 0.05,
     "frequency": 1.1},
    {"name": "drv_cyl", "type": "driving", "joint": "cyl", "coordinate": "angle", "rate": -0.7},
    {"name": "drv_body", "type": "driving", "body": "b2", "coordinate": "y", "rate": 0.3,
     "amplitude": 0.1, "frequency": 2.0},
]


def _spec(joints, forces=()):
    bodies = {
        "ground": {"markers": {"g": [0.5, -0.4, 0.2]}},
        "b1": {"mass": 1.5, "inertia": [0.1, 0.2, 0.15, 0.01, -0.02, 0.03], "position": [0.1, 0.0, 0.2],
               "orientation": {"axis": [1, 2, 3], "angle": 0.4},
               "markers": {"m1": [0.1, -0.2, 0.05]}},
        "b2": {"mass": "w", "inertia": [0.3, 0.1, 0.2], "position": [0.4, 0.3, -0.1],
               "orientation": {"axis": [-1, 0.5, 2], "angle": 1.1},
               "markers": {"m2": [-0.2, 0.1, 0.3], "tip": [0.3, 0.0, 0.0]}},
    }
    js = [dict(j, body_1="b1", body_2="b2") if j.get("type") != "driving" else dict(j) for j in joints]
    return {"type": "multibody", "gravity": [0, -9.81, 0.5], "bodies": bodies, "joints": js,
            "forces": list(forces)}


def _build(spec):
    pc = ProblemCollector()
    model = build_model(spec, "model", ParameterTable(["w"]), pc)
    assert not pc.problems, pc.problems
    return model


def _random_state(model, seed=0, normalise=False):
    rng = np.random.default_rng(seed)
    n_q = model.traits.n_q
    q = rng.normal(size=n_q)
    if normalise:
        for i in range(n_q // 7):
            e = q[7 * i + 3:7 * i + 7]
            q[7 * i + 3:7 * i + 7] = e / np.linalg.norm(e)
    return (q, rng.normal(size=n_q), rng.normal(size=n_q), rng.normal(size=model.traits.n_lam),
            rng.normal(size=model.traits.n_p) + 2.0, rng.normal(size=model.traits.n_p))


def _phi(model, eqs, q, qd, qdd, prm, t):
    ctx = Ctx(q.reshape(q.shape[0], -1), qd.reshape(q.shape[0], -1), qdd.reshape(q.shape[0], -1), prm, t)
    return [v[:, 0] for v in model.constraint_values(ctx, eqs)]


def _close(a, b, rtol=RTOL):
    a, b = np.asarray(a), np.asarray(b)
    assert np.linalg.norm(a - b) <= rtol * max(np.linalg.norm(b), 1.0), (a, b)


@pytest.mark.parametrize("normalise", [False, True])
def test_joint_equations_match_complex_step(normalise):
    model = _build(_spec(JOINTS + DRIVERS))
    prm = model.parameters(np.array([2.0]))
    q, qd, qdd, *_ = _random_state(model, 1, normalise)
    t = 0.37
    assert [j.name for j in model.joints] == [j["name"] for j in JOINTS + DRIVERS]
    for jt in model.joints:
        eqs = jt.eqs
        phi, phid, phidd = _phi(model, eqs, q, qd, qdd, prm, t)
        # J_Φ (from J_Φᵀλ with unit λ) against complex step of Φ(q)
        J = jacobian_rows(eqs, q, prm, t)
        Jcs = np.stack([np.imag(_phi(model, eqs, q + 1j * H * e, qd, qdd, prm, t)[0]) / H
                        for e in np.eye(q.size)], axis=1)
        _close(J, Jcs)
        # Φ̇ = dΦ/dτ along (q + τ q̇, t + τ);  Φ̈ = dΦ̇/dτ along (q + τq̇, q̇ + τq̈, t + τ)
        _close(phid, np.imag(_phi(model, eqs, q + 1j * H * qd, qd, qdd, prm, t + 1j * H)[0]) / H)
        _close(phidd, np.imag(_phi(model, eqs, q + 1j * H * qd, qd + 1j * H * qdd, qdd, prm,
                                   t + 1j * H)[1]) / H)
        # F_c = J q̈ − Φ̈ is what remains without q̈
        Fc = J @ qdd - phidd
        _close(Fc, -_phi(model, eqs, q, qd, 0 * qdd, prm, t)[2])
        assert len(eqs) == {"revolute": 5, "prismatic": 5, "spherical": 3, "cylindrical": 4,
                            "fixed": 6, "planar_pin": 2, "driving": 1}[jt.kind]


def test_inertia_terms_are_lagranges_equations():
    """Row 1 with λ = 0 and no forces is d/dt ∂T/∂q̇ − ∂T/∂q for T = 2ṗᵀGᵀJ'Gṗ + ½mṙᵀṙ."""
    spec = _spec([])
    spec["gravity"] = [0, 0, 0]
    model = _build(spec)
    prm = model.parameters(np.array([2.0]))
    q, qd, qdd, lam, p, pd = _random_state(model, 2)
    s = StepState(q, qd, qdd, np.zeros(model.traits.n_lam), p, pd)
    R1 = model.residual(0.0, s, prm)[:q.size]
    M = np.real(model.linearize(0.0, s, prm).R_z[:q.size, :q.size])

    def Mfun(qq):
        """M(q) from residual differences (exact: the residual is linear in q̈)."""
        cols = []
        for e in np.eye(q.size):
            st0 = StepState(qq, np.zeros_like(qd), np.zeros_like(qdd), s.lam, p, pd)
            st1 = StepState(qq, np.zeros_like(qd), e, s.lam, p, pd)
            cols.append(model.residual(0.0, st1, prm)[:q.size] - model.residual(0.0, st0, prm)[:q.size])
        return np.stack(cols, axis=1)

    _close(Mfun(q), M)
    Mdot_qd = np.imag(Mfun(q + 1j * H * qd) @ qd) / H
    dTdq = np.array([np.imag(0.5 * qd @ Mfun(q + 1j * H * e) @ qd) / H for e in np.eye(q.size)])
    _close(R1, M @ qdd + Mdot_qd - dTdq, 1e-11)


def test_force_elements_are_virtual_work():
    forces = [
        {"type": "spring_damper", "name": "spr", "body_1": "ground", "point_1": "g", "body_2": "b2",
         "point_2": "tip", "stiffness": 50.0, "cubic_stiffness": 7.0, "damping": 0.0, "free_length": 0.3},
        {"type": "point_force", "name": "pf", "body": "b1", "point": "m1", "force": [1.0, -2.0, 0.5],
         "function": {"type": "harmonic", "frequency": 1.0}},
        {"type": "point_force", "name": "pfb", "body": "b2", "point": [0.1, 0.2, 0.3], "frame": "body",
         "force": [0.0, 3.0, 1.0]},
        {"type": "torque", "name": "tq", "body": "b1", "torque": [0.2, 0.1, 1.0]},
        {"type": "torque", "name": "tqb", "body": "b2", "torque": [0.5, 0.0, -1.0], "frame": "body"},
    ]
    model = _build(_spec([], forces))
    prm = model.parameters(np.array([2.0]))
    q, qd, *_ = _random_state(model, 3, normalise=True)

    def Q(elements, qq, qqd=qd, t=0.2):
        ctx = Ctx(qq.reshape(-1, 1), qqd.reshape(-1, 1), np.zeros((qq.size, 1)), prm, t)
        out = np.zeros((qq.size, 1), np.result_type(qq, float))
        for el in elements:
            el.add(ctx, out)
        return out[:, 0]

    by_name = {getattr(f, "name", ""): f for f in model.forces}
    # spring: Q = −∂V/∂q, V = ½k e² + ¼k3 e⁴, e = L − L0
    spr = by_name["spr"]

    def V(qq):
        ctx = Ctx(qq.reshape(-1, 1), np.zeros((qq.size, 1)), np.zeros((qq.size, 1)), prm, 0.0)
        e = spr.state(ctx)[0][0, 0] - 0.3
        return 0.5 * 50.0 * e ** 2 + 0.25 * 7.0 * e ** 4
    gradV = np.array([np.imag(V(q + 1j * H * e)) / H for e in np.eye(q.size)])
    _close(Q([spr], q, 0 * qd), -gradV)
    # point forces and torques: Q·δq equals the virtual work f·δP + n·δθ
    dq = np.random.default_rng(4).normal(size=q.size)
    for i in range(2):
        a = 7 * i + 3
        dq[a:a + 4] -= q[a:a + 4] * (q[a:a + 4] @ dq[a:a + 4])   # keep |p| = 1 to first order
    ctx = Ctx(q.reshape(-1, 1), qd.reshape(-1, 1), np.zeros((q.size, 1)), prm, 0.2)
    ctx_d = Ctx((q + 1j * H * dq).reshape(-1, 1), qd.reshape(-1, 1), np.zeros((q.size, 1)), prm, 0.2)
    from dynsens.models.multibody.bodies import angular_velocity
    for name in ("pf", "pfb"):
        f = by_name[name]
        dP = np.imag(f.point.kin(ctx_d)[0][:, 0]) / H
        _close(Q([f], q) @ dq, f.force(ctx)[:, 0] @ dP)
    for name, frame in (("tq", "global"), ("tqb", "body")):
        f = by_name[name]
        a = 7 * f.body + 3
        dtheta = angular_velocity(q[a:a + 4].reshape(4, 1), dq[a:a + 4].reshape(4, 1))[:, 0]
        n = np.array([0.2, 0.1, 1.0]) if frame == "global" else _rot(q[a:a + 4]) @ np.array([0.5, 0.0, -1.0])
        _close(Q([f], q) @ dq, n @ dtheta)


def test_closed_form_torques_match_their_context_form_and_jacobian():
    """Torques (global and body axes) in closed form: Q for a batch of states and parameter
    sets equals the per-state context evaluation, and ∂Q/∂q equals complex step of Q."""
    forces = [
        {"type": "torque", "name": "tq", "body": "b1", "torque": [0.2, 0.1, 1.0],
         "function": {"type": "harmonic", "frequency": "w"}},
        {"type": "torque", "name": "tqb", "body": "b2", "torque": [0.5, "w", -1.0], "frame": "body"},
    ]
    model = _build(_spec([], forces))
    prms = [model.parameters(np.array([w])) for w in (2.0, 2.5, 3.0)]
    states = [_random_state(model, seed, normalise=True) for seed in (3, 4, 5)]
    q, qd = (np.stack([st[i] for st in states], axis=1) for i in (0, 1))   # (n_q, 3): one per set
    t = 0.2
    pv = np.stack([p.pv for p in prms])
    torques = [f for f in model.forces if getattr(f, "name", "") in ("tq", "tqb")]
    assert len(torques) == 2
    for f in torques:
        assert f.closed_form
        batch = np.zeros((3, q.shape[0]))
        f.add_batch(t, q.T, pv, batch)
        for b, prm in enumerate(prms):
            ctx = Ctx(q[:, b:b + 1], qd[:, b:b + 1], np.zeros((q.shape[0], 1)), prm, t)
            ref = np.zeros((q.shape[0], 1))
            f.add(ctx, ref)
            _close(batch[b], ref[:, 0])
            K = np.zeros((q.shape[0], q.shape[0]))
            f.add_jacobian(t, q[:, b], prm.pv, K)
            for j in range(q.shape[0]):
                qc = (q[:, b] + 1j * H * np.eye(q.shape[0])[j])[None]
                Qc = np.zeros((1, q.shape[0]), complex)
                f.add_batch(t, qc, prm.pv[None], Qc)
                _close(K[:, j], np.imag(Qc[0]) / H)
        assert np.any(batch != 0.0)


def _rot(p):
    from dynsens.models.multibody.rotations import rotation_matrix
    return rotation_matrix(p)


HYD = {"type": "hydraulic_cylinder", "name": "cyl", "body_1": "ground", "point_1": "g", "body_2": "b2",
       "point_2": "tip", "bore": 0.1, "rod": 0.05, "length_0": 0.2, "stroke_max": 2.0,
       "bulk_modulus": 1.0e3, "dead_volume_1": 1.0e-3, "dead_volume_2": 1.0e-3,
       "tank_conductance": 0.5, "tank_pressure": 0.1, "damping": 3.0, "pump_flow": "0.01*w",
       "pump_function": {"type": "smoothstep", "t0": 0.0, "t1": 0.5}, "initial_pressures": [1.0, 0.5]}


def test_hydraulic_cylinder_force_and_rates():
    model = _build(_spec([], [HYD]))
    prm = model.parameters(np.array([2.0]))
    cyl = model.cylinders[0]
    q, qd, *_ = _random_state(model, 5, normalise=True)
    p = np.array([[2.0], [0.7]])
    t = 0.3

    def kin(qq, qqd=qd):
        return cyl.kinematics(Ctx(qq.reshape(-1, 1), qqd.reshape(-1, 1), np.zeros((qq.size, 1)), prm, t))

    s, sd, e = kin(q)
    ds = np.array([np.imag(kin(q + 1j * H * v)[0][0, 0]) / H for v in np.eye(q.size)])
    _close(sd[0, 0], ds @ qd)
    ctx = Ctx(q.reshape(-1, 1), qd.reshape(-1, 1), np.zeros((q.size, 1)), prm, t)
    A1, A2 = np.pi / 4 * 0.1 ** 2, np.pi / 4 * (0.1 ** 2 - 0.05 ** 2)
    Fh = 2.0 * A1 - 0.7 * A2 - 3.0 * sd[0, 0]
    _close(cyl.force(ctx, p)[0, 0], Fh)
    out = np.zeros((q.size, 1))
    cyl.add(ctx, p, out)
    _close(out[:, 0], Fh * ds)                       # F_h along the axis = F_h ∂s/∂q
    V1, V2 = 1e-3 + A1 * s[0, 0], 1e-3 + A2 * (2.0 - s[0, 0])
    tau = t / 0.5
    QP = 0.02 * tau * tau * (3 - 2 * tau)
    h1, h2 = cyl.rates(ctx, p)
    _close(h1[0, 0], 1e3 / V1 * (QP - A1 * sd[0, 0]))
    _close(h2[0, 0], 1e3 / V2 * (A2 * sd[0, 0] - 0.5 * (0.7 - 0.1)))


def test_linearize_matches_complex_step_of_residual():
    forces = [HYD, {"type": "spring_damper", "name": "spr", "body_1": "b1", "point_1": "m1", "body_2": "b2",
                    "point_2": "tip", "stiffness": 50.0, "cubic_stiffness": 7.0, "damping": 1.5}]
    spec = _spec(JOINTS[:1] + JOINTS[5:] + DRIVERS[:1], forces)
    spec["stabilization"] = {"alpha": 3.0, "beta": 4.0}
    spec["constraint_scale"] = 7.0
    model = _build(spec)
    prm = model.parameters(np.array([2.0]))
    q, qd, qdd, lam, p, pd = _random_state(model, 6, normalise=True)
    s = StepState(q, qd, qdd, lam, p, pd)
    t = 0.21
    lin = model.linearize(t, s, prm)

    def col(field, k):
        v = [a.astype(complex) for a in s]
        v[field][k] += 1j * H
        return np.imag(model.residual(t, StepState(*v), prm)) / H

    tr = model.traits
    Rz = np.stack([col(2, k) for k in range(tr.n_q)] + [col(3, k) for k in range(tr.n_lam)]
                  + [col(5, k) for k in range(tr.n_p)], axis=1)
    _close(lin.R_z, Rz)
    _close(lin.R_q, np.stack([col(0, k) for k in range(tr.n_q)], axis=1))
    _close(lin.R_qd, np.stack([col(1, k) for k in range(tr.n_q)], axis=1))
    _close(lin.R_p, np.stack([col(4, k) for k in range(tr.n_p)], axis=1))
    # a complex state (complex-step run of a whole simulation) uses central differences
    sc = StepState(*(v + 1j * 1e-20 for v in s))
    lin_c = model.linearize(t, sc, prm)
    assert np.linalg.norm(lin_c.R_q - lin.R_q) <= 1e-6 * np.linalg.norm(lin.R_q)


def test_free_spinning_body_conserves_momentum_and_energy():
    """Torque-free asymmetric body spinning about a non-principal axis, drifting with a COM
    velocity: angular momentum (global) and kinetic energy are conserved by the average-
    acceleration scheme to < 1e-6 relative, the COM moves on a straight line."""
    import dynsens
    J = np.diag([0.2, 0.3, 0.5])
    raw = {
        "design": {"variables": [{"name": "w", "value": 2.0, "lower": 1.0, "upper": 3.0}]},
        "model": {"type": "multibody",
                  "bodies": {"spin": {"mass": 2.0, "inertia": [0.2, 0.3, 0.5], "position": [1, 2, 3],
                                      "orientation": {"euler_parameters": [1, 0.1, -0.2, 0.3]},
                                      "velocity": [0.5, -0.2, 0.1], "angular_velocity": [1.0, "w", 0.5]}},
                  "initial": {"hold": ["spin.x", "spin.angle_z"]}},
        "integrator": {"dt": 1e-3, "t_end": 0.3},
        "sensitivity": {"enabled": False},
        "output": {"history": ["q", "qd"]},
    }
    case = dynsens.load_case_dict(raw)
    res = dynsens.run_case(case)
    q, qd = res.history["q"], res.history["qd"]
    from dynsens.models.multibody.bodies import angular_velocity
    from dynsens.models.multibody.rotations import rotation_matrix
    Ls, Es = [], []
    for k in range(len(res.time)):
        p = q[k, 3:7]
        w = angular_velocity(p.reshape(4, 1), qd[k, 3:7].reshape(4, 1))[:, 0]
        A = rotation_matrix(p)
        Ig = A @ J @ A.T
        Ls.append(Ig @ w)
        Es.append(0.5 * w @ Ig @ w)
    Ls, Es = np.array(Ls), np.array(Es)
    _close(Ls[0], [1.0, 2.0, 0.5] @ (rotation_matrix(q[0, 3:7]) @ J @ rotation_matrix(q[0, 3:7]).T).T, 1e-12)
    assert np.max(np.linalg.norm(Ls - Ls[0], axis=1)) < 1e-6 * np.linalg.norm(Ls[0])
    assert np.max(np.abs(Es - Es[0])) < 1e-6 * Es[0]
    assert np.max(np.abs(q[:, :3] - (np.array([1, 2, 3]) + res.time[:, None] * [0.5, -0.2, 0.1]))) < 1e-12
    assert np.max(np.abs(np.sum(q[:, 3:7] ** 2, axis=1) - 1.0)) < 1e-6
