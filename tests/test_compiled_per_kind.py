"""The compiled multibody kernel against the numpy reference, one element kind at a time.

tests/test_compiled_kernel.py compares both kernels on the shipped mechanisms; this file builds
a small mechanism around each joint type, each force law and the actuator, so that an element
no shipped case uses is compared too.  At random states (off any solution, so every term of the
residual is of its own size), real and complex (a complex parameter set and complex states, as
complex-step partials evaluate them): the residual F_R and the exact linearization blocks
R_z, R_q, R_q̇, R_p agree to 1e-12 relative to each block's scale, and so does the constraint
Jacobian J_Φ the projection takes from the compiled kernel — dense, and on the sparse path's
pattern — with the term-by-term rows of the assembly (two configurations at once, as the
projection batches them).
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

import dynsens
from dynsens.models.base import StepState
from dynsens.models.multibody import compiled
from dynsens.models.multibody.assembly import jacobian_rows
from dynsens.models.multibody.kernel import Layout
from dynsens.models.multibody.kernel_compiled import CompiledKin
from dynsens.models.multibody import projection
from dynsens.models.multibody.projection import _jacobians

pytestmark = pytest.mark.skipif(not compiled.HAVE_NUMBA, reason="numba is not installed")

TOL = 1e-12
BASE = {
    "name": "kind",
    "design": {"variables": [{"name": "m", "value": 2.0, "lower": 1.0, "upper": 4.0},
                             {"name": "k", "value": 300.0, "lower": 100.0, "upper": 900.0}]},
    "model": {
        "type": "multibody",
        "gravity": [0.0, -9.81, 0.0],
        "bodies": {
            "a": {"mass": "m", "inertia": [0.1, 0.2, 0.3], "position": [0.5, 0.2, 0.1],
                  "markers": {"tip": [0.3, 0.1, 0.0]}},
            "b": {"mass": 1.5, "inertia": [0.05, 0.07, 0.09], "position": [1.2, -0.3, 0.2],
                  "markers": {"eye": [0.1, 0.05, 0.0]}},
        },
        "points": {"A": [0.0, 0.0, 0.0], "C": [0.9, 0.4, 0.0]},
        "joints": [],
    },
    "integrator": {"scheme": "newmark", "beta": 0.25, "gamma": 0.5, "dt": 1.0e-3, "t_end": 0.01},
    "sensitivity": {"enabled": True, "partials": "complex"},
    "responses": [{"name": "ya", "type": "value", "quantity": {"body": "a", "kind": "position"},
                   "component": "a.y"}],
}


def _joint(kind: str, **extra) -> dict:
    j = {"name": "j", "type": kind, "body_1": "ground", "body_2": "a", "point": [0.4, 0.1, 0.0]}
    j.update(extra)
    return j


JOINTS = {
    "revolute": [_joint("revolute", axis=[0, 0, 1])],
    "prismatic": [_joint("prismatic", axis=[1, 0, 0])],
    "spherical": [_joint("spherical")],
    "cylindrical": [_joint("cylindrical", axis=[0, 1, 0])],
    "fixed": [_joint("fixed")],
    "planar_pin": [_joint("planar_pin", axis=[0, 0, 1])],
    "distance": [{"name": "j", "type": "distance", "body_1": "a", "body_2": "b",
                  "marker_1": "tip", "marker_2": "eye", "length": 0.7}],
    "driving (joint angle)": [_joint("revolute", axis=[0, 0, 1]),
                              {"name": "drive", "type": "driving", "joint": "j", "rate": 2.0,
                               "amplitude": 0.1, "frequency": 3.0}],
    "driving (body coordinate)": [{"name": "drive", "type": "driving", "body": "a", "coordinate": "x",
                                   "rate": 0.5}],
}
SPRING = {"type": "spring_damper", "name": "s", "body_1": "a", "body_2": "b", "point_1": [0.1, 0.0, 0.0],
          "stiffness": "k", "cubic_stiffness": 1.0e3, "damping": 4.0, "free_length": 0.6}
CYLINDER = {"type": "hydraulic_cylinder", "name": "cyl", "body_1": "ground", "point_1": [0.0, -0.5, 0.0],
            "body_2": "a", "bore": 0.063, "rod": 0.036, "length_0": 0.7, "stroke_max": 0.4,
            "bulk_modulus": 1.0e9, "dead_volume_1": 2.0e-4, "dead_volume_2": 2.0e-4,
            "tank_conductance": 1.0e-10, "tank_pressure": 1.0e5, "damping": 50.0, "pump_flow": 1.0e-4,
            "pump_function": {"type": "smoothstep", "t0": 0.0, "t1": 0.02}, "initial_pressures": [2.0e6, 1.0e6]}
FORCES = {
    "gravity": [],
    "point_force": [{"type": "point_force", "name": "f", "body": "a", "point": [0.2, 0.1, 0.0],
                     "force": [3.0, -2.0, 1.0], "function": {"type": "harmonic", "frequency": 2.0}}],
    "point_force (body frame)": [{"type": "point_force", "name": "f", "body": "a", "point": [0.2, 0.1, 0.0],
                                  "force": [3.0, -2.0, 1.0], "frame": "body"}],
    "torque": [{"type": "torque", "name": "tq", "body": "b", "torque": [0.5, -1.0, 2.0],
                "function": {"type": "ramp", "t0": 0.0, "t1": 0.05}}],
    "torque (body frame)": [{"type": "torque", "name": "tq", "body": "b", "torque": [0.5, -1.0, 2.0],
                             "frame": "body"}],
    "spring_damper": [SPRING],
    "rotational_spring_damper": [{"type": "rotational_spring_damper", "name": "rs", "body_1": "a",
                                  "body_2": "b", "axis": [0.2, 0.3, 1.0], "stiffness": "k", "damping": 0.3,
                                  "free_angle": 0.1}],
    "hydraulic_cylinder": [CYLINDER],
}


def _case(joints: list, forces: list, kernel: str, monkeypatch, linear_algebra: str = "dense") -> dynsens.Case:
    d = copy.deepcopy(BASE)
    d["model"]["linear_algebra"] = linear_algebra
    d["model"]["joints"] = copy.deepcopy(joints) or [{"name": "jb", "type": "spherical", "body_1": "ground",
                                                       "body_2": "b", "point": [1.2, 0.0, 0.2]}]
    d["model"]["forces"] = copy.deepcopy(forces)
    d["model"].pop("points")
    monkeypatch.setenv("DYNSENS_KERNEL", kernel)
    return dynsens.load_case_dict(d)


def _close(a, b, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    scale = max(float(np.max(np.abs(b))), 1e-300)
    err = float(np.max(np.abs(a - b))) / scale
    assert err < TOL, f"{what}: compiled differs from numpy by {err:.2e} (relative to {scale:.3g})"


def _compare(joints: list, forces: list, label: str, monkeypatch) -> None:
    ref = _case(joints, forces, "numpy", monkeypatch)
    sparse = _case(joints, forces, "compiled", monkeypatch, "sparse")
    monkeypatch.setattr(projection, "SPARSE_MIN_EQ", 0)     # sparse J_Φ for these small models too
    cmp_ = _case(joints, forces, "compiled", monkeypatch)
    tr = ref.model.traits
    rng = np.random.default_rng(abs(hash(label)) % 2 ** 32)
    for is_complex in (False, True):
        x = ref.x0 + (1e-3j * np.eye(ref.x0.size)[0] if is_complex else 0.0)
        pr, pc = ref.model.parameters(x), cmp_.model.parameters(x)
        q0 = np.asarray(ref.model.initial_state(pr)[0])
        for trial in range(3):
            def rnd(n: int, scale: float = 1.0, cplx: bool = is_complex) -> np.ndarray:
                v = scale * rng.standard_normal(n)
                return v + 1e-3j * rng.standard_normal(n) if cplx else v
            s = StepState(q0 + rnd(tr.n_q, 1e-2), rnd(tr.n_q), rnd(tr.n_q), rnd(tr.n_lam, 10.0),
                          rnd(tr.n_p, 1e6) + 2e6, rnd(tr.n_p, 1e6))
            t = 0.013 * (trial + 1)
            what = f"{label} ({'complex' if is_complex else 'real'}, t = {t})"
            assert isinstance(cmp_.model.kinematics(s, pc), CompiledKin), f"{label}: not compiled"
            assert not isinstance(ref.model.kinematics(s, pr), CompiledKin)
            _close(cmp_.model.residual(t, s, pc), ref.model.residual(t, s, pr), f"F_R of {what}")
            lc, lr = cmp_.model.linearize(t, s, pc), ref.model.linearize(t, s, pr)
            for block in ("R_z", "R_q", "R_qd", "R_p"):
                a, b = getattr(lc, block), getattr(lr, block)
                assert (a is None) == (b is None), block
                if b is not None:
                    _close(a, b, f"{block} of {what}")
            Q = np.stack([s.q, q0 + rnd(tr.n_q, 1e-2)], axis=1)
            rows = jacobian_rows(ref.model.eqs, Q, pr, t).transpose(2, 0, 1)
            _close(_jacobians(cmp_.model, t, Q, pc).dense, rows, f"J_Φ of {what}")
            on_pattern = _jacobians(sparse.model, t, Q, sparse.model.parameters(x)).sparse
            _close(np.stack([J.toarray() for J in on_pattern]), rows, f"sparse J_Φ of {what}")


@pytest.mark.parametrize("kind", list(JOINTS))
def test_joint_kind_compiled_matches_numpy(kind, monkeypatch) -> None:
    _compare(JOINTS[kind], [], f"joint {kind}", monkeypatch)


@pytest.mark.parametrize("kind", list(FORCES))
def test_force_kind_compiled_matches_numpy(kind, monkeypatch) -> None:
    _compare([{"name": "jb", "type": "spherical", "body_1": "ground", "body_2": "b",
               "point": [1.2, 0.0, 0.2]}], FORCES[kind], f"force {kind}", monkeypatch)


def test_every_joint_type_is_covered() -> None:
    from dynsens.models.multibody.joints import JOINT_TYPES
    covered = {k.split(" ")[0] for k in JOINTS}
    assert covered == set(JOINT_TYPES)


def test_every_compiled_force_law_is_covered() -> None:
    """Every law that declares the compiled kernels serve it is run here (a new law declares
    ``compiled = False`` and runs the Python path: :mod:`dynsens.models.multibody.force_law`)."""
    from dynsens.models.multibody.force_law import load_laws
    covered = {k.split(" ")[0] for k in FORCES if k != "gravity"}
    assert covered == {t for t, law in load_laws().items() if law.compiled}


def test_every_force_law_declares_whether_it_runs_compiled() -> None:
    """Compiled or Python only is declared by each law in its own class body: every shipped law
    has the declaration, and a law without it is refused at registration."""
    from dynsens.models.multibody.force_law import FORCE_LAWS, ForceLaw, load_laws, register_law
    for law in load_laws().values():
        assert isinstance(type(law).__dict__.get("compiled"), bool), type(law).__name__

    class Undeclared(ForceLaw):
        type, order = "undeclared", 99

    with pytest.raises(TypeError, match="Undeclared.*must declare `compiled = True`"):
        register_law(Undeclared)
    assert "undeclared" not in FORCE_LAWS


def test_unknown_law_is_refused_when_the_kernel_is_set_up(monkeypatch) -> None:
    """An axial element whose law_kind the compiled kernel does not know (here a spring-damper
    relabelled 7, beside a cylinder so that every index the cylinder's law would read stays in
    bounds) is refused when the kernel layout is set up, with the element and the known laws
    named: never evaluated with the cylinder's (or any other element's) law."""
    case = _case([], [CYLINDER, SPRING], "compiled", monkeypatch)
    m = case.model
    assert m.layout.compiled_laws     # the cylinder and the spring are both compiled laws
    axial = list(m.layout.axial)
    odd = copy.copy(next(el for el in axial if el.law_kind == compiled.SPRING))
    odd.law_kind = 7
    relabelled = [odd if el.law_kind == compiled.SPRING else el for el in axial]
    with pytest.raises(TypeError) as exc:
        Layout(m.layout.n_b, m.eqs, relabelled, [f.point for f in m.point_forces])
    msg = str(exc.value)
    assert f"'{odd.name}' declares law_kind 7" in msg
    assert f"knows {compiled.SPRING} (spring) and {compiled.CYLINDER} (cylinder)" in msg


def test_unknown_law_relabelled_after_set_up_raises_in_the_kernel(monkeypatch) -> None:
    """The same element relabelled after the layout was set up: the compiled residual raises
    instead of applying the cylinder's law to it (the fall-through this guards against)."""
    case = _case([], [CYLINDER, SPRING], "compiled", monkeypatch)
    for el in case.model.springs:
        el.law_kind = 7
    prm = case.model.parameters(case.x0)
    tr = case.model.traits
    rng = np.random.default_rng(3)
    q0 = np.asarray(case.model.initial_state(prm)[0])
    s = StepState(q0 + 1e-2 * rng.standard_normal(tr.n_q), rng.standard_normal(tr.n_q),
                  rng.standard_normal(tr.n_q), rng.standard_normal(tr.n_lam),
                  2e6 + rng.standard_normal(tr.n_p), rng.standard_normal(tr.n_p))
    with pytest.raises(ValueError, match="unknown law kind"):
        case.model.residual(0.01, s, prm)
