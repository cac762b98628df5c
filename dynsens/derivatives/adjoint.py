r"""The discrete adjoint (method.md §7): the direct recursion transposed, over the same records.

One step of the direct mode is linear in the stacked sensitivity state X = (∇s, ∇a, ∇b):
predict, pseudo load P = ∂_xF_R + R_q ∇q^pred + R_q̇ ∇q̇^pred + R_p ∇p^pred, S ∇z = −P with the
record's factor, correct, advance.  The adjoint runs the transpose of exactly these maps
backwards over the same step records (same linearization, same factor, transposed solve), one
column per response:

    z̄ = correctᵀ/advanceᵀ of the state's bar,   μ = −S⁻ᵀ z̄,
    bar of the predicted state += (R_q, R_q̇, R_p)ᵀ μ,   x̄ += ∂_xF_Rᵀ μ,   bar of X_{i−1} = predictᵀ(…)

plus the responses' seeds at the grid instants (:mod:`.output_seeds`).  One backward step is
:func:`.adjoint_step.adjoint_step`, defined once: run as Python for any record, compiled over
runs of dense or chain records; this module adds the seeds, the initial step, the design term
and the records' bookkeeping.  A step whose end state
the model projected onto its constraints transposes that projection first (its design term
joins x̄; dynsens/models/multibody/projection.py).  At t0 the initial solve
and the design derivative of the initial state (the mechanism's assembly included) close the
sweep.  So the adjoint gradient equals the direct one to round-off, whatever the step sizes,
step cuts or reused factors.  ∂_xF_Rᵀ μ of a block of records takes one batched residual call
(column colouring included); the r response columns share it.

The records of the forward run are kept while they fit ``memory_budget``; beyond it only
checkpoints are kept and the segments between them are recomputed, bit-identically, during
the sweep (:mod:`.checkpoints`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..integrators.newmark import Aux, Newmark
from ..models.base import Model, Output, StepState
from ..responses.base import OutputTrace
from .partials import DesignPartials, initial_state_gradient
from ..solver.linalg import Counters
from ..timeloop.stepping import StepRecord
from . import adjoint_step
from .checkpoints import RecordStore
from .direct import trail_length
from .finite import check_adjoint_gradient, check_adjoint_step
from .output_seeds import OutputSeeds

if TYPE_CHECKING:  # pragma: no cover
    from ..responses.response_set import ResponseSet
    from ..responses.base import ResponseValue
    from .mode import MassOf


# records whose output seeds are taken together (held a little longer during the sweep)
SEED_BLOCK = 64


class AdjointMode:
    """Keeps the step records of the forward run and sweeps back over them at the end (a
    :class:`~dynsens.derivatives.mode.DerivativeMode`)."""

    name = "adjoint"
    trail_length = 1   # nothing trails: the responses take the values of every step at once
    steps_ahead = True     # it reads the records; a recomputed segment starts from its checkpoint

    def __init__(self, model: Model, scheme: Newmark, partials: DesignPartials, counters: Counters,
                 outputs: list[Output], store: RecordStore, grid_time: Callable[[int], float],
                 reason: str = ""):
        self.model, self.scheme, self.partials, self.counters = model, scheme, partials, counters
        self.reason = reason           # why the run takes the adjoint
        tr = model.traits
        self.n_q, self.n_lam, self.n_p = tr.n_q, tr.n_lam, tr.n_p
        # records whose design term ∂_xF_Rᵀ μ takes one batched residual call: the call holds
        # one residual per parameter set of the batch for each record (not m sensitivity
        # columns, as the direct mode's trail does), so the trail's memory rule counts those sets
        self.block = trail_length(tr, partials.evaluations_per_call)
        self.seeds = OutputSeeds(model, outputs, partials)
        self.store = store             # the records (all, or checkpoints and recomputation)
        self.grid_time = grid_time     # time (s) of grid step k, as the forward loop had it
        self._pending = 0
        self._projection_xbar = np.zeros((partials.m, 0))   # x̄ of the steps' projections (sweep)
        # the start's transposed map, bound once; the steps' are those of :mod:`.adjoint_step`
        self._start_transposed = scheme.start_transpose
        self._ops = adjoint_step.PythonAdjointStep(scheme, self._solve)

    # ------------------------------------------------------------------ forward: keep records
    def start(self, rec: StepRecord) -> None:
        """The initial record (the gradient of the initial state is taken in the sweep)."""
        self.store.add_initial(rec)

    def bind_responses(self, responses: ResponseSet, params: Any) -> None:
        """The responses keep the trace of their outputs (their adjoint weights need it) and
        take no design partials."""
        responses.start(params, None, self.model.stack_parameters([params]), self.model.traits.n_z, trace=True)

    def finish_responses(self, responses: ResponseSet, design: dict[str, Any], m: int,
                         mass: MassOf) -> dict[str, ResponseValue]:
        """The responses' values, and their gradients by the backward sweep (:meth:`gradients`)."""
        return responses.finish(design, m, mass, adjoint=self.gradients)

    def take_step(self, records: list[StepRecord]) -> None:
        """The records of one grid step of the forward run."""
        self.store.add_step(records)
        self._pending += len(records)

    def catch_up(self) -> list[StepState | None]:
        """No sensitivities go forward: the responses take values only."""
        out: list[StepState | None] = [None] * self._pending
        self._pending = 0
        return out

    # ------------------------------------------------------------------ backward sweep
    def gradients(self, trace: OutputTrace, weights: dict[str, dict[int, np.ndarray]]
                  ) -> dict[str, np.ndarray]:
        """dJ/dx (m,) of every response from its adjoint weights over the trace's instants."""
        names = list(weights)
        r, m = len(names), self.partials.m
        if r == 0:
            return {}
        K = len(trace.t)
        stacked: dict[int, np.ndarray] = {}
        for col, name in enumerate(names):
            for oid, W in weights[name].items():
                stacked.setdefault(oid, np.zeros(W.shape + (r,)))[:, :, col] += W
        if self.store.n_grid != K:
            raise RuntimeError(f"adjoint: {K} output instants for {self.store.n_grid} grid steps")
        xbar = np.zeros((m, r))
        # the instants where each output has a weight (one test per output, not one per instant)
        weighted: dict[int, np.ndarray] = {oid: np.any(W.reshape(W.shape[0], -1), axis=1)
                                           for oid, W in stacked.items()}

        def seeds(grid: list[tuple[int, StepRecord]]) -> dict[int, np.ndarray]:
            """∂J/∂y (flat state) at grid instants, adding their ∂_x J to x̄."""
            nonlocal xbar
            ks, recs, ws = [], [], []
            for k, rec in grid:
                w = {oid: W[k] for oid, W in stacked.items() if weighted[oid][k]}
                if w:
                    ks.append(k)
                    recs.append(rec)
                    ws.append(w)
            if not ks:
                return {}
            found = self.seeds.seeds_block([self.grid_time(k) for k in ks], [rec.reported for rec in recs], ws, r)
            for _, xpart in found:
                xbar += xpart
            return {k: self._reported_seed(rec, ybar) for k, rec, (ybar, _) in zip(ks, recs, found)}

        xbar += self._sweep(seeds, names)
        self.counters.backward_output_evaluations += self.seeds.evaluations
        # (the forward run's peak; a recomputed segment holds at most half the budget again)
        self.counters.extra["adjoint_records_peak_bytes"] = self.store.peak
        return {name: xbar[:, col] for col, name in enumerate(names)}

    def _sweep(self, seeds: Callable[[list[tuple[int, StepRecord]]], dict[int, np.ndarray]],
               names: list[str]) -> np.ndarray:
        """Σ over the records of ∂_xF_Rᵀ μ, plus the initial state's term: x̄ (m, r), one column
        per response of ``names``.  The records come in blocks (their seeds take a few batched
        output calls per block).  A non-finite μ stops the sweep at its step."""
        r = len(names)
        sizes = [self.n_q] * 3 + [self.n_lam] + [self.n_p] * 2
        ends = np.cumsum(sizes).tolist()
        fields = list(zip([0] + ends[:-1], ends))
        bar = [np.zeros((n, r)) for n in sizes]                   # q, q̇, q̈, λ, p, ṗ
        aux = [np.zeros((self.n_q, r)), np.zeros((self.n_p, r))]  # a, b
        xbar = np.zeros((self.partials.m, r))
        self._projection_xbar = np.zeros((self.partials.m, r))
        queue: list[tuple[float, Any, np.ndarray, int]] = []

        def flush() -> None:
            nonlocal xbar
            if queue:
                xbar += self.partials.residual_partials_transposed_steps(
                    np.array([q[0] for q in queue]), [q[1] for q in queue], np.stack([q[2] for q in queue]))
                self.counters.backward_residual_evaluations += self.partials.evaluations_per_call * len(queue)
                if not np.all(np.isfinite(xbar)):     # find the first step of the block to blame
                    t, _, _, step = next((q for q in reversed(queue) if not np.all(np.isfinite(
                        self.partials.residual_partials_transposed_steps(
                            np.array([q[0]]), [q[1]], q[2][None])))), queue[-1])
                    check_adjoint_gradient(xbar, names, f"at step {step} (t = {t:.6g} s), in the design "
                                                        "derivative of the residual")
                queue.clear()

        def take(rec: StepRecord, mu: np.ndarray, finite: bool = False) -> None:
            if not finite:                  # (a compiled block checks its μ at once)
                check_adjoint_step(rec, mu, names)
            queue.append((rec.t, rec.solved, mu, rec.step))
            if len(queue) >= self.block:
                flush()

        def sweep(block: list[tuple[int, StepRecord, int | None]]) -> None:
            ybars = seeds([(k, rec) for _, rec, k in block if k is not None])
            # the steps (all records but the initial one, the sweep's last) compiled where
            # :mod:`.adjoint_step` serves them, each record's seed added first
            steps = [rec for idx, rec, _ in block if idx != 0]
            kind = adjoint_step.block_kind(self.scheme, steps, bar)
            if kind is not None:
                found = [ybars.get(k) if k is not None else None for _, _, k in block[:len(steps)]]
                stacked = np.zeros((len(steps), sum(sizes), r))
                for k, ybar in enumerate(found):
                    if ybar is not None:
                        stacked[k] = ybar
                bar[:], aux[:], mus, finite = adjoint_step.run_block(
                    self.scheme, steps, bar, aux, stacked, np.array([y is not None for y in found]), self.n_q,
                    kind)
                self.counters.backward_solves += len(steps)
                for rec, mu in zip(steps, mus):
                    # counted where each factor's own solve counts it (a recomputed segment's
                    # factors count apart from the run's)
                    rec.factor.counters.solves += 1
                    rec.factor.counters.solve_columns += r
                    take(rec, mu, finite)
                block = block[len(steps):]
            for idx, rec, grid_k in block:
                ybar = ybars.get(grid_k) if grid_k is not None else None
                if ybar is not None:
                    for f, (a, b) in enumerate(fields):
                        bar[f] += ybar[a:b]
                take(rec, self._initial_step(rec, bar, aux) if idx == 0 else self._step(rec, bar, aux))

        block: list[tuple[int, StepRecord, int | None]] = []
        for item in self.store.backward():
            block.append(item)
            if len(block) >= SEED_BLOCK or item[0] == 0:
                sweep(block)
                block = []
        flush()
        dq0, dqd0, dp0 = initial_state_gradient(self.model, self.partials)
        xbar = xbar + self._projection_xbar + dq0.T @ bar[0] + dqd0.T @ bar[1] + dp0.T @ bar[4]
        check_adjoint_gradient(xbar, names, "in the design derivative of the initial state (step 0)")
        return xbar

    def _reported_seed(self, rec: StepRecord, ybar: np.ndarray) -> np.ndarray:
        """A seed on the reported state as one on the record's state: through the transposed
        projection when only the reported state was projected (its design term joins x̄)."""
        proj = rec.projection
        if proj is None or proj.feedback:
            return ybar
        n_q = self.n_q
        out = ybar.copy()
        out[:n_q], out[n_q:2 * n_q], x_part = proj.transpose(ybar[:n_q], ybar[n_q:2 * n_q], self.partials)
        self._projection_xbar += x_part
        return out

    def _solve(self, rec: StepRecord, zbar: np.ndarray) -> np.ndarray:
        """μ = −S⁻ᵀ z̄ with the record's factor."""
        self.counters.backward_solves += 1
        return rec.factor.solve_transposed(-zbar)

    def _initial_step(self, rec: StepRecord, bar: list[np.ndarray], aux: list[np.ndarray]) -> np.ndarray:
        """Transpose of the initial solve S0 ∇z0 = −(∂_xF_R + R_q ∇q0 + R_q̇ ∇q̇0 + R_p ∇p0) and
        of the start of the scheme's a0 = q̈0, b0 = ṗ0; leaves the bars of ∇q0, ∇q̇0, ∇p0."""
        bar[:] = self._start_transposed(Aux(*aux), StepState(*bar))
        mu = self._solve(rec, np.concatenate([bar[2], bar[3], bar[5]]))
        bar[0], bar[1], bar[4] = self._ops.state_transpose(rec, mu, (bar[0], bar[1], bar[4]))
        return mu

    def _step(self, rec: StepRecord, bar: list[np.ndarray], aux: list[np.ndarray]) -> np.ndarray:
        """Transpose of one direct step (predict, pseudo load, solve, correct, advance): the
        bars of step i become those of step i − 1, in place; returns μ of the step
        (:func:`.adjoint_step.adjoint_step` with the Python operations, after the transpose of
        the step's projection when the run continued from the projected state)."""
        if rec.projection is not None and rec.projection.feedback:   # the projection came last: first here
            bar[0], bar[1], x_part = rec.projection.transpose(bar[0], bar[1], self.partials)
            self._projection_xbar += x_part
        bar[:], aux[:], mu = adjoint_step.adjoint_step(self._ops, rec, tuple(bar), tuple(aux))
        return mu
