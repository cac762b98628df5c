"""Sensitivities that trail the state by a block of steps equal those computed step by step.

The run keeps the converged linearization and factor of every step taken; once per block the
explicit design partials of all its steps take one batched residual call
(``Model.residual_batch_steps``) and the sensitivity solves follow in step order.  A trail of one
step is the step-by-step reference.  Tolerance 1e-12 relative: the same arithmetic (the batched
residual is bitwise the per-state one, tested below).  Whole-run gradients of the trailing
path are checked against complex step by the existing sensitivity, mechanism and stiff-case
tests, which run with the default trail.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import dynsens
import dynsens.derivatives.direct as direct
import dynsens.timeloop.march as march
from conftest import CASES
from dynsens.models.base import Model, StepState
from dynsens.derivatives.partials import DesignPartials

FIELDS = ("q", "qd", "qdd", "lam", "p", "pd")


def _run(case, trail: int, monkeypatch):
    monkeypatch.setattr(direct, "TRAIL_STEPS", trail)
    monkeypatch.setattr(direct, "SPARSE_TRAIL_STEPS", trail)
    plan = replace(case.plan, sensitivities=True, history=FIELDS, sensitivity_history=True)
    return march.integrate(case.model, case.x0, case.scheme, plan, case.new_response_set(),
                           design_names=case.design_names, design_scale=case.scale)


def _same(a, b, what, tol=1e-12):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, what
    if b.size == 0:
        return
    scale = max(np.max(np.abs(b)), 1e-300)
    assert np.max(np.abs(a - b)) <= tol * scale, what


@pytest.mark.parametrize("name, over", [
    # the chain over 0.3 s of its 2 s: 300 steps end in a partial trail of 7 and of 128
    # (300 = 42·7 + 6 = 2·128 + 44) after the load pulse (0.1 s); trailing against step by step
    # is a per-step identity, not a property of the run's length
    ("duffing_chain", ["integrator.t_end=0.3"]),            # structural, vectorized block partials
    ("duffing_chain", ["integrator.t_end=0.3", "model.linear_algebra=sparse"]),  # batched sparse products
    ("sdof_step", ["integrator.t_end=2"]),                  # linear, one factor for the whole run
    ("sdof_step", ["integrator.t_end=2.0015",               # transition matrices of a dissipative
                   "integrator.scheme=generalized_alpha"]), # scheme, and a shortened last step
    ("truss_impact", []),                                   # bars, column colouring of the partials
    ("hydraulic_lever", []),                                # event: the block ends at the event step
    ("slider_crank", ["integrator.t_end=0.3"]),             # time-dependent constraint coefficients
    ("four_bar", ["integrator.t_end=0.3"]),                 # closed-form torque, added per step
    ("hydraulic_lever", ["model.forces[0].frame=body", "integrator.t_end=0.3"]),  # follower force:
])                                                          # state-by-state fallback
def test_trailing_sensitivities_match_step_by_step(name, over, monkeypatch):
    case = dynsens.load_case(CASES / f"{name}.yaml", over)
    ref = _run(case, 1, monkeypatch)
    for trail in (7, 128):
        res = _run(case, trail, monkeypatch)
        if case.model.traits.constant_matrices:
            # constant-matrix steps of a block advance by their transition matrix (one solve
            # builds it); the reference of one-step blocks solves every step
            solves = {"solves", "solve_columns"}
            assert res.counters["solves"] < ref.counters["solves"]
            assert {k: v for k, v in res.counters.items() if k not in solves} == \
                {k: v for k, v in ref.counters.items() if k not in solves}
        else:
            assert res.counters == ref.counters
        for f, v in ref.sensitivity_history.items():
            _same(res.sensitivity_history[f], v, f"{name}: ∇{f} with a trail of {trail}")
        for r, rv in ref.responses.items():
            if rv.gradient is not None:
                _same(res.responses[r].gradient, rv.gradient, f"{name}: ∇{r} with a trail of {trail}")


def test_trail_length_follows_the_memory_it_holds():
    """Dense models trail up to TRAIL_STEPS steps while their held matrices stay within
    TRAIL_BYTES; sparse models up to SPARSE_TRAIL_STEPS, counted at SPARSE_ROW_ENTRIES per row."""
    small = dynsens.load_case(CASES / "tyrolean_weir.yaml").model.traits
    assert direct.trail_length(small, 4) == direct.TRAIL_STEPS
    big = replace(small, n_q=500, n_lam=0, n_p=0)      # 8 MB of matrices per step
    assert 1 < direct.trail_length(big, 4) < direct.TRAIL_STEPS
    assert direct.trail_length(replace(small, sparse=True), 4) == direct.SPARSE_TRAIL_STEPS
    sparse = replace(small, n_q=20_000, n_lam=0, n_p=0, sparse=True)     # 10 MB a step
    assert 1 < direct.trail_length(sparse, 4) < direct.SPARSE_TRAIL_STEPS
    assert direct.trail_length(replace(sparse, n_q=200_000), 4) == 1


@pytest.mark.parametrize("name", ["tyrolean_weir", "slider_crank", "hydraulic_lever", "pendulum_3d",
                                  "four_bar", "duffing_chain", "truss_impact"])
@pytest.mark.parametrize("method", ["forward", "complex"])
def test_block_residuals_equal_the_per_state_ones(name, method):
    """``residual_batch_steps`` (one call for K states × B parameter sets) against one
    ``residual_batch`` per state, at states along a run (the compiled multibody kernel takes
    each step's time inputs; structural models broadcast the states against the sets)."""
    case = dynsens.load_case(CASES / f"{name}.yaml", ["integrator.t_end=0.2"])
    res = dynsens.run_case(case, sensitivities=False, history=FIELDS)
    idx = [1, len(res.time) // 2, len(res.time) - 1]
    states = [StepState(*(res.history[f][i] for f in FIELDS)) for i in idx]
    batch = DesignPartials(case.model, case.x0, method, None, case.scale)._residual_batch
    block = case.model.residual_batch_steps(res.time[idx], states, batch)
    per_state = Model.residual_batch_steps(case.model, res.time[idx], states, batch)
    assert block.shape == per_state.shape == (3, case.model.traits.n_z, len(batch))
    _same(block, per_state, f"{name} ({method} partials)")
