"""Direct differentiation (method.md §4): the sensitivities follow the steps forward.

Per step record: predict the sensitivity matrices with the scheme, form the pseudo load P at
the converged state (explicit design partials plus ``lin.state_product`` of the predicted
sensitivities), solve S ∇z = −P with the record's factor, correct.  The sensitivities trail
the state by a block of records, so that the explicit design partials of a whole block take one
batched residual call (``Model.residual_batch_steps``); the arithmetic per step is the same.
Small constant-matrix models advance the block by the transition matrix of that very step:
X' = T X + U ∂_xF_R on the stacked sensitivity state X, T and U being the step applied to unit
columns, so a step costs one small product instead of a solve.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..integrators.newmark import Aux, Newmark
from ..models.base import Model, StepState
from .partials import DesignPartials, initial_state_gradient, pseudo_load
from ..solver.linalg import Counters
from ..solver.newton import StepSolver
from ..timeloop.stepping import StepRecord, split_unknowns
from .direct_step import PythonDirectStep, block_kind, direct_step, run_block
from .finite import check_block

if TYPE_CHECKING:  # pragma: no cover
    from ..responses.response_set import ResponseSet
    from ..responses.base import ResponseValue
    from .mode import MassOf

TRAIL_STEPS = 128
TRAIL_BYTES = 32 * 2**20
# sparse models: a short trail (their factors' fill is not known before the run), each step
# counted at a generous number of stored entries per row
SPARSE_TRAIL_STEPS = 8
SPARSE_ROW_ENTRIES = 64
# Largest sensitivity state (∇q, ∇q̇, ∇q̈, ∇λ, ∇p, ∇ṗ and the scheme's ∇a, ∇b stacked) for
# which constant-matrix steps advance by a transition matrix (its product costs n_x² m; above
# this size the step's own solve is cheaper)
TRANSITION_MAX = 32


def trail_length(traits: Any, m: int) -> int:
    """Steps the sensitivities may trail the state: up to TRAIL_STEPS, while the held dense
    linearizations and factors (≈ 4 n_z² + 6 m n_z numbers per step) stay within TRAIL_BYTES;
    sparse models up to SPARSE_TRAIL_STEPS, counting SPARSE_ROW_ENTRIES numbers per row for
    their blocks and factor (a block of steps shares one call of the design partials: 10 % of
    a gradient run of the chain at N = 1 000, BENCHMARKS.md)."""
    if traits.sparse:
        per_step = 8 * (SPARSE_ROW_ENTRIES * traits.n_z + 6 * m * traits.n_z)
        return max(1, min(SPARSE_TRAIL_STEPS, TRAIL_BYTES // per_step))
    per_step = 8 * (4 * traits.n_z * traits.n_z + 6 * m * traits.n_z)
    return max(1, min(TRAIL_STEPS, TRAIL_BYTES // per_step))


class DirectMode:
    """The sensitivity state ∇s (n, m per leaf) carried forward over the step records (a
    :class:`~dynsens.derivatives.mode.DerivativeMode`)."""

    name = "direct"
    steps_ahead = True       # it reads the records (their factors too), not the solver between steps

    def __init__(self, model: Model, scheme: Newmark, solver: StepSolver, partials: DesignPartials,
                 counters: Counters, design_names: tuple[str, ...] = (), reason: str = ""):
        self.model, self.scheme, self.solver, self.partials = model, scheme, solver, partials
        self.counters = counters
        self.reason = reason               # why the run differentiates directly
        self.design_names = design_names   # named in the message of a non-finite sensitivity
        tr = model.traits
        self.n_q, self.n_lam, self.n_z = tr.n_q, tr.n_lam, tr.n_z
        self.trail_length = trail_length(tr, partials.m)
        self.trail: list[StepRecord] = []
        sizes = [tr.n_q, tr.n_q, tr.n_q, tr.n_lam, tr.n_p, tr.n_p, tr.n_q, tr.n_p]
        ends = np.cumsum(sizes).tolist()
        self._pieces = [slice(a, b) for a, b in zip([0] + ends[:-1], ends)]
        self._n_x = sum(sizes)
        self._use_transitions = tr.constant_matrices and self._n_x <= TRANSITION_MAX
        self._transitions: dict[tuple[int, int, float], tuple[Any, Any, np.ndarray, np.ndarray]] = {}
        self.ds: StepState | None = None
        self.daux: Aux | None = None
        self._ops = PythonDirectStep(scheme, solver.solve_sensitivity, tr.n_q, tr.n_lam,
                                     lambda projection, ds: projection.apply(ds, partials))

    def start(self, rec: StepRecord) -> StepState:
        """∇s at t0: the design derivative of the initial state, and ∇z0 from the initial solve."""
        model, partials = self.model, self.partials
        dq0, dqd0, dp0 = initial_state_gradient(model, partials)
        P = pseudo_load(model, rec.t, rec.state, rec.lin, dq0, dqd0, dp0, partials)
        self.counters.sensitivity_residual_evaluations += partials.evaluations_per_call
        assert rec.factor is not None
        dqdd, dlam, dpd = split_unknowns(self.solver.solve_sensitivity(rec.factor, P), self.n_q, self.n_lam)
        self.ds = StepState(dq0, dqd0, dqdd, dlam, dp0, dpd)
        self.daux = self.scheme.start(self.ds)
        check_block(self.model, [rec], [self.ds], self.ds, None, self.design_names)
        return self.ds

    def bind_responses(self, responses: ResponseSet, params: Any) -> None:
        """The responses take the design partials: they differentiate their outputs forward."""
        responses.start(params, self.partials, None, self.n_z)

    def finish_responses(self, responses: ResponseSet, design: dict[str, Any], m: int,
                         mass: MassOf) -> dict[str, ResponseValue]:
        """The responses' values and the gradients they accumulated forward."""
        return responses.finish(design, m, mass)

    def take_step(self, records: list[StepRecord]) -> None:
        """Add the records of a grid step to the trail (their sensitivities follow at
        :meth:`catch_up`)."""
        self.trail.extend(records)

    def catch_up(self) -> list[StepState | None]:
        """Sensitivities of the trailing records, in order (the trail is emptied)."""
        trail, self.trail = self.trail, []
        ds_of: list[StepState | None] = [None] * len(trail)
        if not trail or self.ds is None or self.daux is None:
            return ds_of
        design_part = self.partials.residual_partials_steps(np.array([r.t for r in trail]),
                                                            [r.solved for r in trail])
        self.counters.sensitivity_residual_evaluations += self.partials.evaluations_per_call * len(trail)
        ds, daux = self.ds, self.daux
        kind = None if self._use_transitions else block_kind(self.scheme, trail, ds, design_part)
        compiled = kind is not None
        if compiled:          # the whole block compiled (:mod:`.direct_step`)
            states, ds, daux = run_block(self.scheme, trail, ds, daux, design_part, self.n_q, self.n_lam, kind)
            ds_of = list(states)
            self.counters.solves += len(trail)
            self.counters.solve_columns += len(trail) * self.partials.m
        k = len(trail) if compiled else 0
        while k < len(trail):
            rec = trail[k]
            end = k + 1
            while self._use_transitions and rec.projection is None and end < len(trail) and \
                    trail[end].lin is rec.lin and trail[end].factor is rec.factor and trail[end].h == rec.h:
                end += 1
            if end - k == 1:
                ds, daux = self._step(ds, daux, design_part[k], rec.lin, rec.factor, rec.h, rec.projection)
                ds_of[k] = ds if rec.projection is None or rec.projection.feedback else \
                    rec.projection.apply(ds, self.partials)     # only the reported state is projected
            else:
                T, U = self._transition(rec.lin, rec.factor, rec.h)
                W = U @ design_part[k:end]
                X = np.concatenate([*ds, *daux])
                for j in range(end - k):
                    X = T @ X + W[j]
                    ds_of[k + j] = self._unpack(X)[0]
                ds, daux = self._unpack(X)
            k = end
        check_block(self.model, trail, ds_of, [*ds, *daux], design_part, self.design_names)
        self.ds, self.daux = ds, daux
        return ds_of

    def _step(self, ds: StepState, daux: Aux, design_part: np.ndarray, lin: Any, factor: Any,
              h: float, projection: Any = None) -> tuple[StepState, Aux]:
        """One sensitivity step (method.md §4, :func:`.direct_step.direct_step`): predict ∇,
        pseudo load, S ∇z = −P, correct (and the derivative of the step's projection, when the
        model projects its end states)."""
        return direct_step(self._ops, (lin, factor, h, projection), ds, daux, design_part)

    def _unpack(self, X: np.ndarray) -> tuple[StepState, Aux]:
        parts = [X[sl] for sl in self._pieces]
        return StepState(*parts[:6]), Aux(*parts[6:])

    def _transition(self, lin: Any, factor: Any, h: float) -> tuple[np.ndarray, np.ndarray]:
        key = (id(lin), id(factor), h)
        if key not in self._transitions:    # (the entry holds lin and factor: their ids stay theirs)
            n_x, n_z = self._n_x, self.n_z
            ds_T, daux_T = self._step(*self._unpack(np.eye(n_x)), np.zeros((n_z, n_x)), lin, factor, h)
            ds_U, daux_U = self._step(*self._unpack(np.zeros((n_x, n_z))), np.eye(n_z), lin, factor, h)
            self._transitions[key] = (lin, factor, np.concatenate([*ds_T, *daux_T]),
                                      np.concatenate([*ds_U, *daux_U]))
        return self._transitions[key][2], self._transitions[key][3]
