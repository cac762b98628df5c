"""Primal steps taken ahead in compiled blocks (dynsens/timeloop/step_blocks.py) against the same
steps taken one at a time.

A run on a fixed grid, without derivatives, with direct differentiation or with the adjoint (its
segments recomputed from checkpoints included), of a model whose step is compiled (a spring
network), takes its steps in blocks of up to 64 in one compiled call.  Each
comparison runs the case twice: as shipped, and with the blocks switched off, where every step
goes through the per-step stepper and its compiled Newton iteration.  Both must agree bit for
bit — histories, responses and their gradients, counters, the time of an event that ends the
run, the message of a step that fails — and the blocks must have run (the test counts them).
"""
from __future__ import annotations

import os

import numpy as np
import pytest

import dynsens
from dynsens.errors import ConvergenceError
from dynsens.solver import _jit
from dynsens.timeloop.step_blocks import BLOCK_STEPS, StepBlocks
from dynsens.timeloop.stepping import PrimalStepper
from helpers import assert_identical_runs
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from make_cases import duffing_chain

compiled_only = pytest.mark.skipif(
    not _jit.enabled(), reason=f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL')}: no compiled step")


def _chain(n: int = 30, t_end: float = 0.3, linear_algebra: str = "sparse") -> dict:
    d = duffing_chain(n, t_end=t_end)
    d["model"]["linear_algebra"] = linear_algebra
    d["output"]["history"] = ["q", "qd", "qdd"]
    return d


def _network() -> dict:
    """A dense network that is no chain (the Python path's dense LU), Rayleigh damping, initial
    conditions and a pulse load that starts and ends inside blocks."""
    d = _chain(12, linear_algebra="dense")
    d["model"]["elements"] += [
        {"type": "spring", "name": "across2", "dofs": ["u2", "u4"], "k": 80.0, "k3": 2.0e4},
        {"type": "spring", "name": "s_extra", "dofs": ["u6", "ground"], "k": 300.0, "k3": 1.0e5}]
    d["model"]["damping"] = {"rayleigh": {"alpha": 0.3, "beta": 1.0e-4}}
    d["model"]["initial"] = {"displacement": {"u3": 0.01}, "velocity": {"u12": -0.2}}
    d["model"]["loads"].append({"dof": "u7", "value": -40.0,
                                "function": {"type": "pulse", "t0": 0.0505, "duration": 0.05}})
    return d


def _one_at_a_time(m: pytest.MonkeyPatch) -> None:
    m.setattr(PrimalStepper, "run_ahead", lambda self, ahead: None)


MODES = {"primal": (False, []), "direct": (True, []), "adjoint": (True, ["sensitivity.method=adjoint"])}


def _runs(monkeypatch: pytest.MonkeyPatch, case: dynsens.Case, sensitivities: bool = False, **kw
          ):  # type: ignore[no-untyped-def]
    """(the run in blocks, the run step by step, blocks run, steps the blocks took)."""
    fills: list[int] = []
    original = StepBlocks._fill

    def counted(self, *a):  # type: ignore[no-untyped-def]
        before = len(self.queue)
        took = original(self, *a)
        fills.append(len(self.queue) - before)
        return took
    with monkeypatch.context() as m:
        m.setattr(StepBlocks, "_fill", counted)
        blocks = dynsens.run_case(case, sensitivities=sensitivities, **kw)
    with monkeypatch.context() as m:
        _one_at_a_time(m)
        m.setattr(StepBlocks, "_fill", counted)
        fills_before = len(fills)
        steps = dynsens.run_case(case, sensitivities=sensitivities, **kw)
        assert len(fills) == fills_before           # (off: no block at all)
    return blocks, steps, len(fills), sum(fills)


@compiled_only
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("build, sets", [
    (_chain, []),                                                   # tridiagonal band
    (lambda: _chain(10, linear_algebra="dense"), []),               # dense LU (P1 at N = 10)
    (_network, []),
    (lambda: _chain(10, t_end=0.2005), ["integrator.dt=0.001"]),    # a last, shorter step
    (_chain, ["integrator.scheme=newmark", "integrator.beta=0.3", "integrator.gamma=0.6"]),
    (_network, ["sensitivity.matrix=converged"]),                   # S factored again at the converged state
    (_chain, ["sensitivity.partials=complex"]),
    (_network, ["integrator.scheme=hht", "integrator.alpha=0.1"]),
    (_chain, ["integrator.scheme=generalized_alpha", "integrator.rho_inf=0.6"]),
], ids=["chain", "dense-chain", "dense-network", "short-last-step", "newmark-damped", "converged-matrix",
        "complex-partials", "hht", "generalized-alpha"])
def test_blocks_equal_the_steps_one_at_a_time(monkeypatch, build, sets, mode):
    sensitivities, more = MODES[mode]
    case = dynsens.load_case_dict(build(), "chain.yaml", sets + more)
    blocks, steps, n_blocks, taken = _runs(monkeypatch, case, sensitivities)
    assert_identical_runs(blocks, steps)
    for name in blocks.monitors:
        np.testing.assert_array_equal(blocks.monitors[name], steps.monitors[name], err_msg=name)
    n_steps = blocks.counters["steps"]
    assert blocks.time[-1] == steps.time[-1] and blocks.status == steps.status == "completed"
    assert n_blocks == -(-n_steps // BLOCK_STEPS) and taken == n_steps     # every step in a block


@compiled_only
@pytest.mark.parametrize("mode", MODES)
def test_a_step_a_block_cannot_take_is_cut_by_the_stepper(monkeypatch, mode):
    """Two Newton iterations allowed: the steps that need a third stop their block, the stepper
    halves them (step cuts), and the next block starts after them."""
    sensitivities, more = MODES[mode]
    case = dynsens.load_case_dict(_chain(), "chain.yaml", ["integrator.solver.max_iterations=2"] + more)
    blocks, steps, n_blocks, taken = _runs(monkeypatch, case, sensitivities)
    assert_identical_runs(blocks, steps)
    cuts = blocks.counters["step_cuts"]
    assert cuts > 0 and n_blocks > -(-blocks.counters["steps"] // BLOCK_STEPS)
    assert 0 < taken < blocks.counters["steps"]


@compiled_only
@pytest.mark.parametrize("mode", MODES)
def test_an_event_inside_a_block_ends_the_run_at_the_same_step(monkeypatch, mode):
    d = _chain(10, t_end=0.5)
    # the tip swings out to 0.119 and back: it falls through 0.1 at t ≈ 0.45 s (step ≈ 450)
    d["events"] = [{"name": "down", "quantity": {"dof": "u10", "kind": "displacement"}, "value": 0.1,
                    "direction": "falling"}]
    d["responses"].append({"name": "t_down", "type": "event_time", "event": "down"})
    sensitivities, more = MODES[mode]
    case = dynsens.load_case_dict(d, "chain.yaml", more)
    blocks, steps, _, taken = _runs(monkeypatch, case, sensitivities)
    assert blocks.status == steps.status == "terminated" and blocks.message == steps.message
    assert_identical_runs(blocks, steps)
    n = blocks.counters["steps"]
    assert n % BLOCK_STEPS and taken > n       # the event's block ran on past it: those steps are dropped


@compiled_only
@pytest.mark.parametrize("sets", [["integrator.solver.max_iterations=1", "integrator.max_step_cuts=0"]])
def test_a_step_that_fails_fails_alike(monkeypatch, sets):
    case = dynsens.load_case_dict(_chain(), "chain.yaml", sets)
    errors = []
    for off in (False, True):
        with monkeypatch.context() as m:
            if off:
                _one_at_a_time(m)
            with pytest.raises(ConvergenceError) as err:
                dynsens.run_case(case, sensitivities=False)
            errors.append((str(err.value), err.value.residual_history))
    assert errors[0] == errors[1]


@compiled_only
def test_the_adjoint_recomputes_its_segments_in_blocks(monkeypatch):
    """A memory budget of a few records: the sweep drops segments and takes their steps again from
    their checkpoints, in blocks (the queue of the forward run is stale there and dropped)."""
    case = dynsens.load_case_dict(_chain(), "chain.yaml", ["sensitivity.method=adjoint",
                                                           "sensitivity.memory_budget=20 kB"])
    blocks, steps, n_blocks, taken = _runs(monkeypatch, case, True)
    assert_identical_runs(blocks, steps)
    recomputed = blocks.counters["recomputed_steps"]
    assert recomputed > 0 and recomputed == steps.counters["recomputed_steps"]
    assert taken >= blocks.counters["steps"] + recomputed


@compiled_only
@pytest.mark.parametrize("sets, kw", [
    (["integrator.adaptive={rtol: 1.0e-6, atol: 1.0e-9}"], {"sensitivities": False}),
    (["integrator.adaptive={rtol: 1.0e-6, atol: 1.0e-9}"], {"sensitivities": True}),
    (["integrator.adaptive={rtol: 1.0e-6, atol: 1.0e-9}", "integrator.scheme=hht"], {"sensitivities": True}),
], ids=["adaptive", "adaptive-direct", "adaptive-hht-direct"])
def test_no_blocks_where_a_step_must_be_taken_as_it_comes(monkeypatch, sets, kw):
    case = dynsens.load_case_dict(_chain(), "chain.yaml", sets)
    filled: list[bool] = []
    original = StepBlocks._fill
    with monkeypatch.context() as m:
        m.setattr(StepBlocks, "_fill", lambda self, *a: filled.append(original(self, *a)) or filled[-1])
        dynsens.run_case(case, **kw)
    assert not any(filled) and len(filled) <= 1      # asked once at most, never served


@compiled_only
@pytest.mark.parametrize("sensitivities", [False, True])
def test_a_mechanism_takes_its_steps_one_at_a_time(monkeypatch, sensitivities):
    """A model family that declares no compiled blocks (a mechanism): never asked for one."""
    from pathlib import Path
    made: list[int] = []
    original = StepBlocks.__init__
    with monkeypatch.context() as m:
        m.setattr(StepBlocks, "__init__", lambda self, *a: made.append(1) or original(self, *a))
        case = dynsens.load_case(Path(__file__).resolve().parent.parent / "cases" / "slider_crank.yaml",
                                 ["integrator.t_end=0.05"])
        dynsens.run_case(case, sensitivities=sensitivities)
    assert made == []



@compiled_only
@pytest.mark.parametrize("mode", MODES)
def test_a_replayed_grid_runs_in_blocks(monkeypatch, mode):
    """The steps of an adaptive run replayed (as the finite differences of `check-gradients`
    replay them), then on past its end with its last step size: in blocks, as one at a time."""
    import dataclasses
    from dynsens.timeloop.step_sequence import replaying
    sensitivities, more = MODES[mode]
    adaptive = dynsens.load_case_dict(_chain(10), "chain.yaml", ["integrator.adaptive={rtol: 1.0e-5, atol: 1.0e-8}"])
    times = dynsens.run_case(adaptive, sensitivities=False).time
    base = dynsens.load_case_dict(_chain(10, t_end=0.35), "chain.yaml", more)
    case = dataclasses.replace(base, plan=replaying(base.plan, times))
    blocks, steps, n_blocks, taken = _runs(monkeypatch, case, sensitivities)
    assert_identical_runs(blocks, steps)
    np.testing.assert_array_equal(blocks.time, steps.time)
    assert blocks.time[-1] == 0.35 and n_blocks >= 2 and taken == blocks.counters["steps"]


@compiled_only
@pytest.mark.parametrize("mode", ["primal", "direct"])
def test_a_block_holds_no_more_than_its_byte_budget(monkeypatch, mode):
    """The states and factors a block keeps stay within BLOCK_BYTES: a large model takes fewer
    steps a block (here a budget of 20 kB: a few steps of the 30-mass chain), the same numbers."""
    from dynsens.timeloop import step_blocks
    sensitivities, more = MODES[mode]
    case = dynsens.load_case_dict(_chain(), "chain.yaml", more)
    n = 30
    # the state; with sensitivities K_t and the LU (S itself is not kept), q, q̇, q̈, du2, the test, pivots
    per_step = 8 * 4 * n + ((2 * (3 * n - 2) + 3 * n + (n - 2) + 3) * 8 + 4 * n if sensitivities else 0)
    monkeypatch.setattr(step_blocks, "BLOCK_BYTES", 20_000)
    blocks, steps, n_blocks, taken = _runs(monkeypatch, case, sensitivities)
    assert_identical_runs(blocks, steps)
    size = min(BLOCK_STEPS, 20_000 // per_step)
    assert size < BLOCK_STEPS and n_blocks == -(-blocks.counters["steps"] // size)


@compiled_only
def test_a_run_with_sensitivities_whose_factor_is_large_takes_single_steps(monkeypatch):
    """Above FACTOR_BYTES_MAX a step's factor is not copied out of a block: the run with
    sensitivities takes its steps one at a time (asked once), its primal run still in blocks."""
    from dynsens.timeloop import step_blocks
    monkeypatch.setattr(step_blocks, "FACTOR_BYTES_MAX", 1_000)      # the 30-mass chain's: ~3 kB
    case = dynsens.load_case_dict(_chain(), "chain.yaml")
    filled: list[bool] = []
    original = StepBlocks._fill
    monkeypatch.setattr(StepBlocks, "_fill", lambda self, *a: filled.append(original(self, *a)) or filled[-1])
    dynsens.run_case(case, sensitivities=True)
    assert filled == [False]
    dynsens.run_case(case, sensitivities=False)
    assert filled[1:] and all(filled[1:])


def test_every_model_family_declares_whether_its_steps_run_in_blocks():
    """Blocks or single steps are declared by each model family in its own class body (the base
    class's False is the contract's default, not a declaration)."""
    import dynsens.models.multibody.model as multibody
    import dynsens.models.structural.model as structural
    from dynsens.models.base import Model
    families, todo = [], list(Model.__subclasses__())
    while todo:
        cls = todo.pop()
        todo.extend(cls.__subclasses__())
        if cls.__module__.startswith("dynsens."):
            families.append(cls)
    assert {structural.StructuralModel, multibody.MultibodyModel} <= set(families)
    undeclared = [cls.__name__ for cls in families if not isinstance(cls.__dict__.get("compiled_blocks"), bool)]
    assert undeclared == []
    assert structural.StructuralModel.compiled_blocks and not multibody.MultibodyModel.compiled_blocks
