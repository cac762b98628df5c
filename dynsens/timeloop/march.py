"""The time loop: one routine for the primal state and its design sensitivities.

The paper's flowchart (method.md §2–4): the primal stepper (:mod:`.stepping`) predicts, solves
F_R(z) = 0 by Newton and corrects, and hands back one record per accepted step (its converged
state, linearization and factor); a derivative mode consumes the records — the direct mode
(:mod:`.derivatives.direct`) carries the sensitivities forward, trailing the state by a block
of steps, the adjoint mode (:mod:`.derivatives.adjoint`) keeps them and sweeps back over them
once the responses know their weights; the outputs of every grid step go to the responses.
The loop talks to the mode only through the :class:`~.derivatives.mode.DerivativeMode`
protocol (a run without derivatives has its primal-only mode), so it never asks which mode
runs (tests/test_mode_free_loop.py).  What a case does not need is decided once in
:class:`RunPlan` and never re-tested inside the loop's numerics.
"""
from __future__ import annotations

import functools
import time as _time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..derivatives.adjoint import AdjointMode
from ..derivatives.checkpoints import DEFAULT_MEMORY_BUDGET, RecordStore
from ..derivatives.direct import DirectMode
from ..derivatives.mode import DerivativeMode, PrimalOnlyMode
from ..errors import CaseError
from ..integrators.newmark import Newmark
from ..models.base import Model, StepState
from ..responses.response_set import ResponseSet
from ..responses.base import EventHit, EventTime, ResponseValue
from ..derivatives.partials import DesignPartials
from ..solver.linalg import Counters
from ..solver.newton import NewtonSettings, StepSolver
from .step_sequence import AdaptiveSettings, AdaptiveSteps, FixedGrid, ReplayedSteps, StepSequence
from .stepping import HISTORY_FIELDS, PrimalStepper, StepRecord


@dataclass(frozen=True)
class RunPlan:
    """What a run computes and stores, fixed before the first step.

    Attributes
    ----------
    t0, t_end, dt : start, end time and step size (s).
    newton : tolerances of the Newton iteration.
    sensitivities : compute design sensitivities (direct differentiation).
    partials : ``forward`` | ``central`` | ``complex`` for the design partials.
    partials_step : relative perturbation of the design partials (None: per-method default).
    sensitivity_matrix : ``reuse`` (default: the factor of the last Newton iteration, taken one
        correction before convergence; its error is of the size of that correction: the Newton
        tolerance, or, with forward partials, up to their own error ≈ 3e-8 relative, when Newton
        stops on a round-off residual; tests/test_sensitivities.py shows the gradient moves less
        than the partials' own error) or ``converged`` (re-linearize and factor S at the
        converged state: exact, one more factorization per step for nonlinear models).
    history : which state histories to store (subset of q, qd, qdd, lam, p, pd).
    sensitivity_history : store the sensitivity histories of the same fields.
    max_step_cuts : how often a step whose Newton iteration fails is halved before the run
        stops (responses and histories keep the regular grid; the sub-steps are internal).
    method : ``direct`` | ``adjoint`` | ``auto``: how the sensitivities are computed
        (:func:`choose_method` decides ``auto``).
    memory_budget : bytes of step records the adjoint keeps; beyond it, checkpoints and
        recomputed segments.
    adaptive : adaptive steps (``integrator.adaptive``; dt is the first trial step), or None for
        the fixed grid of dt.
    replay_times : the grid times of another run (t0 first) to step through as they are
        (:class:`~dynsens.timeloop.step_sequence.ReplayedSteps`), or None.
    """

    t0: float
    t_end: float
    dt: float
    newton: NewtonSettings = field(default_factory=NewtonSettings)
    sensitivities: bool = True
    partials: str = "forward"
    partials_step: float | None = None
    sensitivity_matrix: str = "reuse"
    history: tuple[str, ...] = ("q", "qd", "qdd")
    sensitivity_history: bool = False
    max_step_cuts: int = 6
    method: str = "direct"
    memory_budget: float = DEFAULT_MEMORY_BUDGET
    adaptive: AdaptiveSettings | None = None
    replay_times: tuple[float, ...] | None = None

    @functools.cached_property
    def n_steps(self) -> int:
        """Number of steps of the fixed grid (the last one is shortened to land on t_end); the
        nominal count of an adaptive run.  (Kept: the fixed grid reads it twice a step.)"""
        return max(1, int(np.ceil((self.t_end - self.t0) / self.dt - 1e-9)))

    def step_size(self, i: int) -> float:
        """Size of step i (1-based), s."""
        last = self.t_end - self.t0 - (self.n_steps - 1) * self.dt
        if i < self.n_steps or abs(last - self.dt) <= 1e-9 * self.dt:
            return self.dt
        return last


@dataclass
class RunResult:
    """Everything one run produced."""

    x: np.ndarray
    time: np.ndarray
    history: dict[str, np.ndarray]
    sensitivity_history: dict[str, np.ndarray]
    monitors: dict[str, np.ndarray]
    responses: dict[str, ResponseValue]
    counters: dict[str, int]
    wall_time: float
    status: str
    message: str
    labels: dict[str, list[str]]
    method: str = ""          # the derivative mode that ran (direct | adjoint), "" without
    method_reason: str = ""   # why it was chosen


class RunStore:
    """The histories and monitors of a run at the grid steps, in arrays sized for the steps
    expected (doubled when an adaptive run takes more)."""

    def __init__(self, plan: RunPlan, model: Model, params: Any, s0: StepState, m: int,
                 sensitivities: bool, n_steps: int):
        n = n_steps + 1
        self.model, self.params = model, params
        self.fields = [f for f in plan.history if f in HISTORY_FIELDS]
        self.times = np.empty(n)
        self.hist = {f: np.empty((n, getattr(s0, f).shape[0]), dtype=getattr(s0, f).dtype)
                     for f in self.fields}
        self.store_sens = plan.sensitivity_history and sensitivities
        self.shist = {f: np.empty((n, getattr(s0, f).shape[0], m)) for f in self.fields} \
            if self.store_sens else {}
        self.monitor_names = list(model.monitors(plan.t0, s0, params))
        self.mons = {k: np.empty(n) for k in self.monitor_names}
        self.last = 0

    def _grow(self) -> None:
        """Twice the room (an adaptive run past its expected step count)."""
        def double(a: np.ndarray) -> np.ndarray:
            return np.concatenate([a, np.empty_like(a)])
        self.times = double(self.times)
        for d in (self.hist, self.shist, self.mons):
            for f in d:
                d[f] = double(d[f])

    def record(self, k: int, t: float, s: StepState) -> None:
        """The state s of grid step k at time t (s)."""
        if k >= self.times.shape[0]:
            self._grow()
        self.times[k] = t
        self.last = k
        for f in self.fields:
            self.hist[f][k] = getattr(s, f)
        if self.monitor_names:
            for name, val in self.model.monitors(t, s, self.params).items():
                self.mons[name][k] = val

    def result(self, x: np.ndarray, responses: dict[str, ResponseValue], counters: dict[str, int],
               wall_time: float, status: str, message: str, labels: list[str], method: str,
               reason: str) -> RunResult:
        """The run's result, histories cut at the last grid step taken."""
        n = self.last + 1
        return RunResult(
            x=x, time=self.times[:n], history={f: v[:n] for f, v in self.hist.items()},
            sensitivity_history={f: v[:n] for f, v in self.shist.items()},
            monitors={k: v[:n] for k, v in self.mons.items()}, responses=responses, counters=counters,
            wall_time=wall_time, status=status, message=message, labels={"q": labels}, method=method,
            method_reason=reason)

    def record_sensitivities(self, k: int, ds: StepState | None) -> None:
        """The sensitivities of grid step k (when they are stored)."""
        if self.store_sens and ds is not None:
            for f in self.fields:
                self.shist[f][k] = getattr(ds, f)


class GridFeed:
    """Hands the grid steps to the responses once the derivative mode has their sensitivities
    (the direct mode trails the state by up to ``trail_length`` steps; without derivatives,
    every step goes at once).  Sub-steps of step cuts go to the mode, not to the responses."""

    def __init__(self, mode: DerivativeMode, responses: ResponseSet, store: RunStore):
        self.mode, self.responses, self.store = mode, responses, store
        self.length = mode.trail_length
        self._take_step, self._catch_up = mode.take_step, mode.catch_up     # (bound once: per step)
        self.marks: list[tuple[int, float, StepState, float, EventHit | None, int]] = []
        self.taken = 0

    def start(self, t0: float, s0: StepState, ds0: StepState | None) -> None:
        """The initial state (and its sensitivities) at t0 (s): stored and to the responses."""
        self.store.record(0, t0, s0)
        self.store.record_sensitivities(0, ds0)
        self.responses.push(0, t0, s0, ds0, 0.0, self.responses.watch(t0, s0))

    def add(self, i: int, t: float, h: float, records: list[StepRecord], event: EventHit | None) -> None:
        """Grid step i (ending at t, s; size h) made of ``records``, and what the events said."""
        self._take_step(records)
        self.taken += len(records)
        self.marks.append((i, t, records[-1].reported, h, event, self.taken - 1))
        if event is not None or len(self.marks) >= self.length:
            self.catch_up()

    def catch_up(self) -> None:
        """Sensitivities of the records taken so far, then the marked grid steps to the responses."""
        ds_of = self._catch_up()
        for i, t, s, h, event, k in self.marks:
            ds = ds_of[k] if k >= 0 else None
            self.store.record_sensitivities(i, ds)
            self.responses.push(i, t, s, ds, h, event)
        self.marks.clear()
        self.taken = 0


def _mass(model: Model, params: Any, partials: DesignPartials | None
          ) -> Callable[[], tuple[Any, np.ndarray | None]]:
    """The structural mass and its gradient (by the design partials), when a response asks."""
    def mass() -> tuple[Any, np.ndarray | None]:
        value = model.structural_mass(params)
        grad = partials.of(lambda prm: np.atleast_1d(model.structural_mass(prm)))[0] \
            if partials is not None else None
        return value, grad
    return mass


def _solver(model: Model, plan: RunPlan, counters: Counters, partials: DesignPartials | None) -> StepSolver:
    """The Newton solver of the run: what it factorizes and keeps follows the plan."""
    tr, sens = model.traits, partials is not None
    return StepSolver(model, plan.newton, counters, newton=not tr.linear, refactor=not tr.constant_matrices,
                      need_converged_factor=sens and plan.sensitivity_matrix == "converged",
                      sensitivities=sens,
                      reuse_tolerance=partials.relative_error if partials is not None else 0.0)


METHODS = ("direct", "adjoint", "auto")


def adjoint_obstacles(plan: RunPlan, responses: ResponseSet) -> list[str]:
    """What keeps the adjoint from serving this run (empty: nothing)."""
    why = responses.adjoint_unsupported()
    if plan.sensitivity_history:
        why.append("output.sensitivity_history (the adjoint computes no sensitivity states)")
    recorder = getattr(responses, "recorder", None)
    if recorder is not None and recorder.gradient_outputs:
        why.append("recorded quantities with sensitivity: true (their gradient histories are sensitivity states)")
    return why


def choose_method(plan: RunPlan, responses: ResponseSet, m: int) -> tuple[str, str]:
    """The derivative mode of a run and why (method.md §6–7).

    Direct differentiation costs, per step, m solve columns and m directions of the pseudo load
    and outputs; the adjoint r transposed-solve columns (r: responses that read outputs or an
    event time; mass and expressions of responses need no sweep) plus its fixed costs: the
    outputs' seeds, the transposed sweep and the records it keeps (or recomputes).  ``auto``
    takes the adjoint when it covers the case and m ≥ 4 (r + 1): the paper's rule of thumb
    (adjoint when the design variables outnumber the functions) with the fixed costs priced from
    the measured chain runs of BENCHMARKS.md ("Where `auto` switches")."""
    r = sum(1 for rsp in responses.responses if rsp.output_ids or isinstance(rsp, EventTime))
    why_not = adjoint_obstacles(plan, responses)
    if plan.method == "direct":
        return "direct", "sensitivity.method: direct"
    if plan.method == "adjoint":
        if why_not:
            raise CaseError(f"sensitivity.method: adjoint does not cover this case yet ({'; '.join(why_not)}); "
                            "use sensitivity.method: direct (or auto)")
        return "adjoint", "sensitivity.method: adjoint"
    if why_not:
        return "direct", f"auto: the adjoint does not cover {'; '.join(why_not)}"
    if m >= 4 * (r + 1):
        return "adjoint", f"auto: {r} functions against {m} design variables (m >= 4(r + 1))"
    return "direct", f"auto: {r} functions against {m} design variables (m < 4(r + 1))"


def step_sequence(plan: RunPlan, scheme: Newmark, counters: Counters) -> StepSequence:
    """The steps a run takes: replayed, adaptive or the fixed grid of dt."""
    if plan.replay_times is not None:
        return ReplayedSteps(plan.replay_times, plan.t_end)
    if plan.adaptive is not None:
        return AdaptiveSteps(plan.t0, plan.t_end, plan.dt, plan.adaptive, scheme, counters)
    return FixedGrid(plan.t0, plan.t_end, plan.dt, plan.n_steps, plan.step_size)


def derivative_mode(model: Model, scheme: Newmark, solver: StepSolver, stepper: PrimalStepper,
                    partials: DesignPartials | None, plan: RunPlan, responses: ResponseSet, counters: Counters,
                    steps: StepSequence, design_names: tuple[str, ...] = ()) -> DerivativeMode:
    """The derivative mode that consumes the step records, chosen by :func:`choose_method` (no
    derivatives without design partials); the adjoint recomputes segments and places its seeds
    by the steps as they were taken."""
    if partials is None:
        return PrimalOnlyMode(model)
    method, reason = choose_method(plan, responses, partials.m)
    if method == "direct":
        return DirectMode(model, scheme, solver, partials, counters, design_names, reason)
    records = RecordStore(stepper, steps.grid, plan.memory_budget, counters)
    return AdjointMode(model, scheme, partials, counters, responses.outputs, records, steps.time, reason)


def integrate(model: Model, x: np.ndarray, scheme: Newmark, plan: RunPlan,
              responses: ResponseSet, *, design_names: tuple[str, ...] = (),
              design_scale: np.ndarray | None = None,
              progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Run one simulation of ``model`` at design ``x`` (m,) and return its results.

    ``x`` may be complex (complex step of the whole simulation); sensitivities must then
    be off.  Raises ConvergenceError, NonFiniteError or ModelError with context.
    """
    wall0, counters, m = _time.perf_counter(), Counters(), np.size(x)
    sens = plan.sensitivities and m > 0
    if sens and np.iscomplexobj(x):
        raise ValueError("sensitivities cannot be computed on a complex design; switch them off")
    partials = DesignPartials(model, np.asarray(x), plan.partials, plan.partials_step,
                              design_scale) if sens else None
    params = partials.params0 if partials is not None else model.parameters(np.asarray(x))
    solver = _solver(model, plan, counters, partials)
    stepper = PrimalStepper(model, scheme, solver, params, plan.max_step_cuts, counters)
    steps = step_sequence(plan, scheme, counters)
    mode = derivative_mode(model, scheme, solver, stepper, partials, plan, responses, counters, steps,
                           design_names)
    if mode.steps_ahead:
        stepper.run_ahead(steps.ahead)                               # compiled blocks of steps

    rec = stepper.initial(plan.t0)                                    # t0: consistent accelerations
    ds = mode.start(rec)
    store = RunStore(plan, model, params, rec.state, m, ds is not None, steps.expected_steps)
    mode.bind_responses(responses, params)
    feed = GridFeed(mode, responses, store)
    feed.start(plan.t0, rec.state, ds)
    counters.output_evaluations += 1
    status, message = "completed", f"reached t_end = {plan.t_end:g} s"
    s, t, i = rec.state, plan.t0, 0
    while not steps.finished():                                     # predict, Newton, correct
        i += 1
        records = steps.take(stepper, i, t, s)
        _, h, t = steps.log[-1]
        s = records[-1].state
        counters.steps += 1
        store.record(i, t, records[-1].reported)
        counters.output_evaluations += 1
        event = responses.watch(t, records[-1].reported)
        feed.add(i, t, h, records, event)                              # sensitivities, responses
        if event is not None:
            ev = next(reversed(responses.fired))
            status = "terminated"
            message = f"event '{ev}' at t = {float(np.real(responses.fired[ev].t)):.6g} s"
            break
        if progress is not None:
            progress(*steps.progress())
    feed.catch_up()
    responses.close(t, m)                                             # responses, gradients
    values = mode.finish_responses(responses, dict(zip(design_names, np.asarray(x))), m if sens else 0,
                                   _mass(model, params, partials))
    return store.result(np.asarray(x), values, counters.as_dict(), _time.perf_counter() - wall0,
                        status, message, stepper.labels, mode.name, mode.reason)
