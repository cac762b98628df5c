"""The primal stepper: one :class:`StepRecord` per accepted step (method.md §2–3).

A step predicts from the previous state, solves the step equation F_R(z) = 0 by Newton and
corrects; a model may then project the end state onto its constraints (``Model.project``).
When Newton fails, the step is halved (up to ``max_step_cuts`` times) and its two halves are
taken in turn; every accepted sub-step is a record of its own.  A record holds what the
derivative modes need of the step — time, step size, converged state, the linearization and
factor that the sensitivity solve uses — so the direct mode can trail the state and the adjoint
mode can sweep back over the records without touching the Newton loop.  With adaptive steps
(:mod:`.step_sequence`) a step is first a :class:`Trial` that the step controller accepts
(:meth:`PrimalStepper.commit`) or rejects (:meth:`PrimalStepper.discard`: no record, the Newton
solver's memory as before it).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConvergenceError, NonFiniteError
from ..integrators.newmark import Aux, Newmark, Prediction
from ..models.base import Model, StepState
from .runaway import RunawayMonitor
from .step_blocks import GridAhead, StepBlocks
from ..solver.newton import StepOutcome, StepSolver

HISTORY_FIELDS = ("q", "qd", "qdd", "lam", "p", "pd")


@dataclass(frozen=True)
class StepRecord:
    """One accepted step (or the initial solve at t0, with h = 0).

    Attributes
    ----------
    step : the grid step it belongs to (0 for the initial solve); sub-steps of a step cut share
        the step of the grid step they make up.
    t, h : time at the end of the step and its size (s).
    state : the converged state at t.
    lin, factor : the linearization and factor of S the sensitivity solve of this step uses
        (None when no derivatives are computed).
    iterations : Newton iterations taken.
    projection : when the model projects its end states (``Model.project``), the projection:
        ``raw`` the solved state, ``projected`` the consistent one, ``feedback`` whether the run
        continues from the projected state (then ``state`` is it) or from the solved one (then
        only what the run reports is projected); None otherwise.
    """

    step: int
    t: float
    h: float
    state: StepState
    lin: Any
    factor: Any
    iterations: int
    projection: Any = None

    @property
    def solved(self) -> StepState:
        """The state the step's equations hold at (before a projection): where the design
        partials of its residual are taken."""
        return self.state if self.projection is None else self.projection.raw

    @property
    def reported(self) -> StepState:
        """The state the run reports (histories, outputs, responses, events, monitors)."""
        return self.state if self.projection is None else self.projection.projected


def split_unknowns(z: np.ndarray, n_q: int, n_lam: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q̈, λ, ṗ) blocks of the per-step unknowns z (vectors or (n_z, m) matrices)."""
    return z[:n_q], z[n_q:n_q + n_lam], z[n_q + n_lam:]


def equation_offsets(model: Model) -> dict[str, int]:
    """Where each field of a StepState starts among the step equations z = (q̈, λ, ṗ)."""
    tr = model.traits
    return {"q": 0, "qd": 0, "qdd": 0, "lam": tr.n_q, "p": tr.n_q + tr.n_lam, "pd": tr.n_q + tr.n_lam}


def check_finite(s: StepState, t: float, step: int, model: Model) -> None:
    """Raise NonFiniteError naming the first non-finite entry of s (at time t, s), by its
    equation's coordinate and YAML entries (:meth:`Model.describe_equation`)."""
    # one sum: NaN or Inf anywhere makes it non-finite; then find the entry (an overflowing
    # sum of finite entries finds none and passes)
    if np.isfinite(np.concatenate(s).sum()):
        return
    offset = equation_offsets(model)
    for name, v in zip(HISTORY_FIELDS, s):
        if v.size and not np.all(np.isfinite(v)):
            k = int(np.flatnonzero(~np.isfinite(v))[0])
            where = model.describe_equation(offset[name] + k)
            raise NonFiniteError(
                f"NaN/Inf first appeared in {name} of {where} at t = {t:.6g} s (step {step}): "
                "reduce the time step or check parameters and loads")


class PrimalStepper:
    """Takes the steps of one run and hands back their records.

    Parameters
    ----------
    model, scheme, solver : the residual, the integration scheme and the Newton solver.
    params : the model's parameters of the design.
    max_step_cuts : how often a failing step is halved before the run stops.
    counters : the run's work counters (step cuts).
    """

    def __init__(self, model: Model, scheme: Newmark, solver: StepSolver, params: Any,
                 max_step_cuts: int, counters: Any):
        self.model, self.scheme, self.solver, self.params = model, scheme, solver, params
        self.max_step_cuts = max_step_cuts
        self.counters = counters
        self.labels = model.dof_labels()
        self.aux: Aux | None = None
        self.runaway: RunawayMonitor | None = None
        self.blocks: StepBlocks | None = None

    def run_ahead(self, ahead: GridAhead) -> None:
        """Let the steps of the grid ``ahead`` (:meth:`.step_sequence.StepSequence.ahead`) be
        taken ahead in compiled blocks where the model declares them (``Model.compiled_blocks``;
        :mod:`.step_blocks`)."""
        if getattr(self.model, "compiled_blocks", False) and self.solver.has_compiled_step:
            self.blocks = StepBlocks(self, ahead)

    def initial(self, t0: float) -> StepRecord:
        """The initial state and its consistent accelerations (coefficients 0: S0 = ∂F_R/∂z)."""
        model, tr = self.model, self.model.traits
        q0, qd0, p0 = model.initial_state(self.params)
        lam_guess, pd_guess = model.initial_guess(self.params)
        dtype = np.result_type(q0, qd0, p0, float)
        z0 = np.concatenate([np.zeros(tr.n_q, dtype), np.asarray(lam_guess, dtype),
                             np.asarray(pd_guess, dtype)])
        pred = Prediction(q0, qd0, p0, q0[:0], p0[:0])

        def correct0(pr: Prediction, qdd: np.ndarray, lam: np.ndarray, pd: np.ndarray) -> StepState:
            return StepState(pr.q, pr.qd, qdd, lam, pr.p, pd)

        out = self.solver.solve_step(t0, 0, pred, z0, self.params, (0.0, 0.0, 0.0), correct0)
        check_finite(out.state, t0, 0, model)
        self.runaway = RunawayMonitor(model, out.state, model.displacement_scale(self.params, out.lin))
        self.aux = self.scheme.start(out.state)
        return StepRecord(0, t0, 0.0, out.state, out.lin, out.factor, out.iterations)

    def snapshot(self, s: StepState) -> tuple[StepState, Aux, Any]:
        """A checkpoint after a grid step that ended in the state s: the state, the scheme's
        algorithmic accelerations and the solver's convergence memory."""
        assert self.aux is not None
        return s, self.aux, self.solver.snapshot()

    def restore(self, checkpoint: tuple[StepState, Aux, Any]) -> StepState:
        """Return to a :meth:`snapshot`; the state to advance from."""
        s, self.aux, snap = checkpoint
        self.solver.restore(snap)
        self.runaway = None     # a segment taken again repeats steps the forward run has watched
        return s

    def advance(self, i: int, t_prev: float, h: float, s: StepState) -> list[StepRecord]:
        """Grid step i from the state s at t_prev by h (s): its records (more than one after
        step cuts), the last one ending at t_prev + h."""
        if self.blocks is not None:
            record = self.blocks.take(i, t_prev, h, s)
            if record is not None:
                return [record]
        records: list[StepRecord] = []
        assert self.aux is not None, "initial() first"
        self.aux = self._take(i, t_prev, h, 0, s, self.aux, records)
        return records

    def _take(self, i: int, t_prev: float, h: float, cuts: int, s: StepState, aux: Aux,
              records: list[StepRecord]) -> Aux:
        """One step; on Newton failure, its two halves (recursively)."""
        try:
            out, pred = self._solve(i, t_prev, h, s, aux)
        except ConvergenceError as exc:
            if cuts >= self.max_step_cuts:
                if self.max_step_cuts:
                    exc.args = (f"{exc.args[0]} (after {cuts} step cuts down to Δt = {h:.3g} s)",)
                raise
            self.counters.step_cuts += 1
            half = 0.5 * h
            aux = self._take(i, t_prev, half, cuts + 1, s, aux, records)
            return self._take(i, t_prev + half, half, cuts + 1, records[-1].state, aux, records)
        record = self._accept(i, t_prev + h, h, out)
        records.append(record)
        return self.scheme.advance(pred, record.state)

    def _solve(self, i: int, t_prev: float, h: float, s: StepState, aux: Aux) -> tuple[StepOutcome, Prediction]:
        """Predict, solve F_R(z) = 0 by Newton and correct: the step from t_prev by h (s)."""
        scheme = self.scheme
        t = t_prev + h
        pred = scheme.predict(s, aux, h)
        z_guess = np.concatenate([s.qdd, s.lam, s.pd])

        def correct(pr: Prediction, qdd: np.ndarray, lam: np.ndarray, pd: np.ndarray) -> StepState:
            return scheme.correct(pr, qdd, lam, pd, h)

        out = self.solver.solve_step(t, i, pred, z_guess, self.params, scheme.coefficients(h), correct)
        if not out.finite:        # (a compiled step has looked already)
            check_finite(out.state, t, i, self.model)
        return out, pred

    def _accept(self, i: int, t: float, h: float, out: StepOutcome) -> StepRecord:
        """The record of a step taken: the end state projected when the model projects (the
        record's ``state`` is the one the run continues from), the model's range and the runaway
        monitor checked."""
        s_new, projection = self.model.project(t, out.state, self.params)
        if self.runaway is not None:
            self.runaway.observe(t, i, s_new)
        self.model.check_state(t, s_new, self.params)
        return StepRecord(i, t, h, s_new, out.lin, out.factor, out.iterations, projection)

    # ------------------------------------------------------------------ adaptive steps
    def trial(self, i: int, t_prev: float, h: float, s: StepState) -> Trial:
        """A trial of grid step i from the state s at t_prev by h (s), not yet accepted: the
        step controller judges its local error, then :meth:`commit` or :meth:`discard`.  A
        failing Newton iteration (or a non-finite state) raises with the solver as before."""
        assert self.aux is not None, "initial() first"
        snap = self.solver.snapshot()
        try:
            out, pred = self._solve(i, t_prev, h, s, self.aux)
        except (ConvergenceError, NonFiniteError):
            self.solver.restore(snap)
            raise
        return Trial(i, t_prev + h, h, out, pred, self.aux, self.scheme.advance(pred, out.state), snap)

    def commit(self, trial: Trial) -> StepRecord:
        """Accept a trial: its record, and the scheme moves on from the state it continues from
        (the projected one when the model projects its states)."""
        rec = self._accept(trial.step, trial.t, trial.h, trial.out)
        self.aux = (trial.aux_new if rec.state is trial.out.state
                    else self.scheme.advance(trial.pred, rec.state))
        return rec

    def discard(self, trial: Trial) -> None:
        """Reject a trial: no record, and the Newton solver's memory returns to before it (so a
        run replaying the accepted steps repeats them bit for bit)."""
        self.solver.restore(trial.solver_snapshot)


@dataclass(frozen=True)
class Trial:
    """A solved step awaiting the step controller's verdict: grid step, end time t and size h
    (s), the solver's outcome and prediction, the scheme's algorithmic accelerations before and
    after it (after: from the solved state, which the error estimate judges) and the solver's
    memory before it."""

    step: int
    t: float
    h: float
    out: StepOutcome
    pred: Prediction
    aux_prev: Aux
    aux_new: Aux
    solver_snapshot: Any
