"""The compiled multibody kernel against the numpy kernel (the reference), at states along real
runs of every shipped mechanism: residual, exact linearization, batched residuals of perturbed
designs and batched output kinematics agree to round-off (1e-12 relative to each quantity's
scale), for real and for complex-step data.  Whole-run gradients of the compiled path are
checked against complex step of the whole run by the mechanism and weir tests, which run
compiled (the default)."""
from __future__ import annotations

import numpy as np
import pytest

import dynsens
from conftest import CASES
from dynsens.models.base import Linearization, StepState
from dynsens.models.multibody import compiled
from dynsens.models.multibody.kernel import Kin
from dynsens.models.multibody.kernel_compiled import CompiledKin

pytestmark = pytest.mark.skipif(not compiled.HAVE_NUMBA, reason="numba is not installed")

FIELDS = ("q", "qd", "qdd", "lam", "p", "pd")
MECHANISMS = [("slider_crank", 0.3), ("four_bar", 0.3), ("hydraulic_lever", 0.3),
              ("pendulum_3d", 0.3), ("tyrolean_weir", 0.3), ("bricard", 0.3), ("rheonomic", 0.3),
              ("torsional_pair", 0.3), ("point_pendulum", 0.3)]
TOL = 1e-12


def _close(a, b, what):
    a, b = np.asarray(a), np.asarray(b)
    scale = max(np.max(np.abs(b)), 1e-300)
    err = np.max(np.abs(a - b)) / scale
    assert err < TOL, f"{what}: compiled differs from numpy by {err:.2e} (relative to {scale:.3g})"


def _cases(name, t_end, monkeypatch):
    """(numpy case, compiled case, states along a run)."""
    over = [f"integrator.t_end={t_end}"]
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    ref = dynsens.load_case(CASES / f"{name}.yaml", over)
    monkeypatch.setenv("DYNSENS_KERNEL", "compiled")
    cmp_ = dynsens.load_case(CASES / f"{name}.yaml", over)
    res = dynsens.run_case(ref, sensitivities=False, history=FIELDS)
    n = len(res.time)
    idx = sorted({1, n // 2, n - 1})
    # off the converged solution (relative 1e-3), so that every residual term is of its own size
    rng = np.random.default_rng(1)
    states = [(res.time[i], StepState(*(v + 1e-3 * (1.0 + np.abs(v)) * rng.standard_normal(v.shape)
                                        for v in (res.history[f][i] for f in FIELDS)))) for i in idx]
    return ref, cmp_, states


@pytest.mark.parametrize("name, t_end", MECHANISMS)
def test_residual_and_linearization_match_numpy(name, t_end, monkeypatch):
    ref, cmp_, states = _cases(name, t_end, monkeypatch)
    pr, pc = ref.model.parameters(ref.x0), cmp_.model.parameters(cmp_.x0)
    for t, s in states:
        assert isinstance(cmp_.model.kinematics(s, pc), CompiledKin)
        assert not isinstance(ref.model.kinematics(s, pr), CompiledKin)
        _close(cmp_.model.residual(t, s, pc), ref.model.residual(t, s, pr), f"{name} F_R at t = {t}")
        lc, lr = cmp_.model.linearize(t, s, pc), ref.model.linearize(t, s, pr)
        for block in ("R_z", "R_q", "R_qd", "R_p"):
            a, b = getattr(lc, block), getattr(lr, block)
            assert (a is None) == (b is None), block
            if b is not None:
                _close(a, b, f"{name} {block} at t = {t}")
        # the compiled kernel assembles the iteration matrix too: the same arithmetic as the
        # generic dense assembly, for the step coefficients and for those of the initial solve
        n_q = cmp_.model.traits.n_q
        generic = Linearization(lc.R_z, lc.R_q, lc.R_qd, lc.R_p)
        for coeffs in ((2.5e-7, 1e-3, 1e-3), (0.0, 0.0, 0.0)):
            assert np.array_equal(lc.iteration_matrix(*coeffs, n_q=n_q),
                                  generic.iteration_matrix(*coeffs, n_q=n_q)), coeffs


@pytest.mark.parametrize("name, t_end", MECHANISMS)
def test_batched_residuals_and_outputs_match_numpy(name, t_end, monkeypatch):
    """Design partials evaluate one state for m + 1 parameter sets; output totals evaluate m + 1
    perturbed states for m + 1 parameter sets: both batch shapes agree with the numpy kernel."""
    ref, cmp_, states = _cases(name, t_end, monkeypatch)
    m = ref.x0.size
    xs = [ref.x0] + [ref.x0 + 1e-3 * np.maximum(np.abs(ref.x0), 1.0) * np.eye(m)[j] for j in range(m)]
    pr = [ref.model.parameters(x) for x in xs]
    pc = [cmp_.model.parameters(x) for x in xs]
    rng = np.random.default_rng(0)
    for t, s in states:
        _close(cmp_.model.residual_batch(t, s, pc), ref.model.residual_batch(t, s, pr), f"{name} batch F_R")
        # a batch of perturbed states with the stacked parameter sets (as the output gradients)
        sb = StepState(*(v[None, :] + 1e-4 * (1.0 + np.abs(v[None, :])) * rng.standard_normal((m + 1, v.size))
                         for v in s))
        kc = cmp_.model.kinematics(sb, cmp_.model.stack_parameters(pc))
        kr = ref.model.kinematics(sb, ref.model.stack_parameters(pr))
        assert isinstance(kc, CompiledKin) and type(kr) is Kin
        for attr in ("X", "N", "ABV", "PV"):
            _close(getattr(kc, attr), getattr(kr, attr), f"{name} batched kinematics {attr}")


@pytest.mark.parametrize("name, t_end", [("hydraulic_lever", 0.3), ("tyrolean_weir", 0.3)])
def test_complex_step_data_match_numpy(name, t_end, monkeypatch):
    """Complex parameters and states (complex step of the whole run, complex partials) take the
    compiled kernel too: residual and linearization, real and imaginary parts, as numpy's."""
    ref, cmp_, states = _cases(name, t_end, monkeypatch)
    m = ref.x0.size
    for j in range(m):
        x = ref.x0 + 1e-20j * np.eye(m)[j]
        pr, pc = ref.model.parameters(x), cmp_.model.parameters(x)
        for t, s in states:
            sc = StepState(*(v + 1e-20j * (1.0 + np.abs(v)) for v in s))
            assert isinstance(cmp_.model.kinematics(sc, pc), CompiledKin)
            for part in (np.real, np.imag):
                _close(part(cmp_.model.residual(t, sc, pc)), part(ref.model.residual(t, sc, pr)),
                       f"{name} complex F_R ({part.__name__})")
                lc, lr = cmp_.model.linearize(t, sc, pc), ref.model.linearize(t, sc, pr)
                for block in ("R_z", "R_q", "R_qd", "R_p"):
                    _close(part(getattr(lc, block)), part(getattr(lr, block)), f"{name} complex {block}")


def test_element_without_a_compiled_law_takes_numpy_forces(monkeypatch):
    """An actuator the compiled kernel does not know (law_kind None) is evaluated by its Python
    law on the compiled kinematics, with the same residual and linearization."""
    from dynsens.models.multibody.hydraulics import HydraulicCylinder
    monkeypatch.setattr(HydraulicCylinder, "law_kind", None)
    ref, cmp_, states = _cases("hydraulic_lever", 0.3, monkeypatch)
    assert not cmp_.model.layout.compiled_laws
    pr, pc = ref.model.parameters(ref.x0), cmp_.model.parameters(cmp_.x0)
    for t, s in states:
        ev = cmp_.model._evaluation(t, s, pc)
        assert isinstance(ev.kin, CompiledKin) and not ev.compiled
        _close(cmp_.model.residual(t, s, pc), ref.model.residual(t, s, pr), "F_R, Python law")
        lc, lr = cmp_.model.linearize(t, s, pc), ref.model.linearize(t, s, pr)
        for block in ("R_z", "R_q", "R_qd", "R_p"):
            _close(getattr(lc, block), getattr(lr, block), f"{block}, Python law")


def test_other_forces_jacobians_against_central_differences(monkeypatch):
    """Torques and body-frame point forces (evaluated in Python, one Ctx for a batch of states):
    ∂Q/∂q and ∂Q/∂q̇ are full (n_q, n_q) matrices equal to central differences of Q."""
    from dynsens.models.multibody.residual import other_forces_jacobians, other_forces_q
    ref, _, states = _cases("four_bar", 0.3, monkeypatch)
    model, prm = ref.model, ref.model.parameters(ref.x0)
    assert model.other_forces
    t, s = states[-1]
    Kq, Kqd = other_forces_jacobians(model, t, s.q, s.qd, prm)
    n = model.traits.n_q
    assert Kq.shape == Kqd.shape == (n, n)
    h = 1e-6
    for K, wrt in ((Kq, "q"), (Kqd, "qd")):
        for j in range(n):
            e = h * np.eye(n)[j]
            q_p, q_m = (s.q + e, s.q - e) if wrt == "q" else (s.q, s.q)
            v_p, v_m = (s.qd + e, s.qd - e) if wrt == "qd" else (s.qd, s.qd)
            fd = (other_forces_q(model, t, q_p[None], v_p[None], [prm])[0]
                  - other_forces_q(model, t, q_m[None], v_m[None], [prm])[0]) / (2 * h)
            assert np.allclose(K[:, j], fd, rtol=1e-6, atol=1e-8 * max(1.0, np.max(np.abs(Kq)))), (wrt, j)


def test_switch_off_by_environment(monkeypatch):
    monkeypatch.setenv("DYNSENS_KERNEL", "numpy")
    assert not compiled.enabled()
    monkeypatch.setenv("DYNSENS_KERNEL", "compiled")
    assert compiled.enabled()


def test_buffer_pool_hands_out_only_unreferenced_memory():
    """A pooled buffer is reused only once no array made from it is alive."""
    from dynsens.models.multibody.kernel_compiled import BufferPool
    pool = BufferPool(limit=2)
    a = pool.take(12, float)
    view = a.reshape(3, 4)[:, 1]           # a derived view keeps the buffer in use
    a_id = id(a.base)
    del a
    b = pool.take(12, float)
    assert id(b.base) != a_id
    c = pool.take(12, float)               # both pooled buffers in use: an ordinary array
    assert id(c.base) not in (a_id, id(b.base))
    del view
    d = pool.take(12, complex)             # another dtype never shares a buffer
    assert d.dtype == complex and id(d.base) != a_id
    e = pool.take(24, float)               # free again, grown to the size asked for
    assert e.size == 24 and len(pool._buffers) == 2


@pytest.mark.parametrize("name", ["slider_crank", "tyrolean_weir"])
def test_block_kinematics_from_the_pool_are_exact_and_stay_valid(name, monkeypatch):
    """Block kinematics written into pooled buffers equal freshly allocated ones, a Kin still
    held keeps its values while later blocks are evaluated, and whole runs (real and complex
    partials) give bit-identical gradients with and without the pool."""
    from dynsens.models.multibody import kernel_compiled
    case = dynsens.load_case(CASES / f"{name}.yaml", ["integrator.t_end=0.3"])
    res = dynsens.run_case(case, sensitivities=False, history=FIELDS)
    model = case.model
    kp = model.stack_parameters([model.parameters(case.x0)] * 2)
    blocks = [[res.history[f][i:i + 80] for f in ("q", "qd", "qdd")] for i in (0, 40, 80)]
    held = model._kin.get(kp, *blocks[0])
    assert any(held.C.base is b for b in model._kin.pool._buffers)     # taken from the pool
    first = {k: getattr(held, k).copy() for k in ("Lp", "C", "ABV", "X")}
    for q, qd, qdd in blocks[1:]:
        later = model._kin.get(kp, q, qd, qdd)
        fresh = CompiledKin(model.layout, kp, q, qd, qdd)           # no pool: its own arrays
        for k in first:
            assert np.array_equal(getattr(later, k), getattr(fresh, k)), k
    for k, v in first.items():
        assert np.array_equal(getattr(held, k), v), f"{k} of a held Kin changed"

    for partials in ("forward", "complex"):
        over = ["integrator.t_end=0.3", f"sensitivity.partials={partials}"]
        pooled = dynsens.run_case(dynsens.load_case(CASES / f"{name}.yaml", over))
        monkeypatch.setattr(kernel_compiled, "POOL_MIN_ENTRIES", 10**9)
        plain = dynsens.run_case(dynsens.load_case(CASES / f"{name}.yaml", over))
        monkeypatch.undo()
        for r, v in plain.responses.items():
            assert np.array_equal(pooled.responses[r].gradient, v.gradient), (partials, r)
