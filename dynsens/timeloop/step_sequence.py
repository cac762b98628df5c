r"""The step sequence of a run: the fixed grid of ``integrator.dt``, adaptive steps chosen by a
local error estimate (``integrator.adaptive``), or a replay of the accepted steps of another run.

Every grid step the loop of :func:`dynsens.timeloop.march.integrate` takes is logged as (t_prev, h, t);
the adjoint's recomputed segments and its output instants read them back from the log, so the
three sequences look alike to the derivative modes.

Adaptive steps (method.md §6).  The local error of the Newmark displacement update, for exact
values at the start of the step, is C_q h³ q⃛ + O(h⁴); with q⃛ h ≈ a_{n+1} − a_n this gives the
estimate of Zienkiewicz & Xie (1991), generalized to the α-family:

.. math:: e_q ≈ C_q\,h^2\,(a_{n+1} - a_n),\qquad C_q = β - \tfrac16 + \tfrac{α_m - α_f}{2}

(a: the scheme's algorithmic accelerations, which approximate q̈(t_n + (α_m − α_f)h); plain
Newmark: C_q = β − 1/6, 1/12 for the average-acceleration rule; HHT and generalized-α:
1/12 + (γ − ½)²/4).  First-order states p follow the γ-rule, whose local error is
e_p ≈ C_p h² (b_{n+1} − b_n), C_p = 1/12 − (α_m − α_f)²/2 (the trapezoid rule's 1/12 for
Newmark); the scheme owns these constants
(:meth:`~dynsens.integrators.newmark.Newmark.error_constants`).  The step is accepted when the
weighted RMS norm
‖e / (atol + rtol·max(|y_n|, |y_{n+1}|))‖ ≤ 1; the next step is
h·min(GROW, max(SHRINK, SAFETY·err^{−1/3})) (no growth right after a rejection), within
[dt_min, dt_max].  A rejected step (error too large, or Newton failing: h/4) leaves no record.
A step that still fails at dt_min is a :class:`~dynsens.errors.StepSizeError`.

The gradient is that of the procedure along the accepted sequence: the step sizes are data, held
fixed as the design varies (the error estimate and the controller are not differentiated).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import ConvergenceError, NonFiniteError, StepSizeError
from ..integrators.newmark import Newmark
from ..models.base import StepState
from .stepping import PrimalStepper, StepRecord, Trial

if TYPE_CHECKING:  # pragma: no cover
    from .march import RunPlan

SAFETY = 0.9          # of the step the estimate predicts
GROW = 2.0            # largest growth of the step from one step to the next
SHRINK = 0.2          # largest reduction after a rejection by the error estimate
NEWTON_SHRINK = 0.25  # reduction after a failed Newton iteration
MIN_COEFFICIENT = 1e-3   # |C_q| below this: the estimate does not measure the step's error
INITIAL_ROOM = 4096      # grid steps the histories of an adaptive run are first sized for


@dataclass(frozen=True)
class AdaptiveSettings:
    """``integrator.adaptive``: relative and absolute tolerances of the local error (atol in
    each coordinate's own unit) and the range of step sizes (s)."""

    rtol: float
    atol: float
    dt_min: float
    dt_max: float


def adaptive_problem(scheme: Newmark) -> str | None:
    """Why adaptive steps cannot serve ``scheme`` (None: they can)."""
    if scheme.order != 2:
        return (f"the {scheme.name} scheme with gamma = {scheme.gamma:g} is first-order accurate: its velocity "
                "error per step is O(h^2) and the displacement estimate does not measure it; use a "
                "second-order member (newmark with gamma = 0.5, hht, generalized_alpha)")
    if abs(scheme.error_constants()[0]) < MIN_COEFFICIENT:
        return (f"beta = {scheme.beta:g} makes the displacement error estimate "
                "h^2 (beta - 1/6)(a_n+1 - a_n) vanish (beta = 1/6): use beta = 1/4")
    return None


def error_ratio(settings: AdaptiveSettings, constants: tuple[float, float], s_prev: StepState,
                trial: Trial) -> float:
    """Weighted RMS of the local error estimate of a trial step over its tolerance (≤ 1:
    accepted).  Real parts only: a complex-step run takes the steps of the real run."""
    cq, cp = constants
    h2 = trial.h * trial.h
    s_new = trial.out.state
    ratios = []
    for c, old, new, y0, y1 in ((cq, trial.aux_prev.a, trial.aux_new.a, s_prev.q, s_new.q),
                                (cp, trial.aux_prev.b, trial.aux_new.b, s_prev.p, s_new.p)):
        if np.size(y1):
            e = (c * h2) * np.real(new - old)
            w = settings.atol + settings.rtol * np.maximum(np.abs(np.real(y0)), np.abs(np.real(y1)))
            ratios.append(e / w)
    r = np.concatenate(ratios) if ratios else np.zeros(0)
    return float(np.sqrt(np.mean(r * r))) if r.size else 0.0


class StepSequence:
    """The steps of a run, logged as (t_prev, h, t) per grid step (1-based)."""

    def __init__(self, t0: float, t_end: float):
        self.t0, self.t_end = t0, t_end
        self.log: list[tuple[float, float, float]] = []

    def finished(self) -> bool:
        """Whether the run has reached its end time."""
        raise NotImplementedError

    def take(self, stepper: PrimalStepper, i: int, t_prev: float, s: StepState) -> list[StepRecord]:
        """Grid step i from the state s at t_prev (s): its records; the log gains (t_prev, h, t)."""
        raise NotImplementedError

    def ahead(self, i: int, t_prev: float, count: int) -> list[tuple[float, float]] | None:
        """(t_prev, h) (s) of grid steps i, i + 1, ... (at most ``count``, the first from
        t_prev) as they will be taken unless a step is cut, or None where the sequence cannot
        tell before taking them (adaptive steps): then no step runs ahead."""
        return None

    def grid(self, i: int) -> tuple[float, float]:
        """(t_prev, h) of grid step i exactly as it was taken."""
        return self.log[i - 1][0], self.log[i - 1][1]

    def time(self, k: int) -> float:
        """Time (s) of grid step k (0: the start) as the responses had it."""
        return self.t0 if k == 0 else self.log[k - 1][2]

    def progress(self) -> tuple[int, int]:
        """(done, total) for a progress line."""
        return len(self.log), len(self.log)

    @property
    def expected_steps(self) -> int:
        """Steps expected (storage is sized by it; an adaptive run may grow past it)."""
        return len(self.log)


class FixedGrid(StepSequence):
    """Steps of ``dt`` (the last one shortened to land on t_end); Newton failures cut a step
    into halves that stay inside it (:class:`~dynsens.timeloop.stepping.PrimalStepper`)."""

    def __init__(self, t0: float, t_end: float, dt: float, n_steps: int, step_size: Callable[[int], float]):
        super().__init__(t0, t_end)
        self.dt, self.n_steps, self.step_size = dt, n_steps, step_size

    def finished(self) -> bool:
        return len(self.log) >= self.n_steps

    def take(self, stepper: PrimalStepper, i: int, t_prev: float, s: StepState) -> list[StepRecord]:
        h = self.step_size(i)
        records = stepper.advance(i, t_prev, h, s)
        self.log.append((t_prev, h, self._end(i, h)))
        return records

    def _end(self, i: int, h: float) -> float:
        """The grid time of step i of size h (s): where the next step starts."""
        return self.t0 + (i - 1) * self.dt + h

    def ahead(self, i: int, t_prev: float, count: int) -> list[tuple[float, float]]:
        out = []
        for j in range(i, min(i + count, self.n_steps + 1)):
            h = self.step_size(j)
            out.append((t_prev, h))
            t_prev = self._end(j, h)
        return out

    def progress(self) -> tuple[int, int]:
        return len(self.log), self.n_steps

    @property
    def expected_steps(self) -> int:
        return self.n_steps


class ReplayedSteps(StepSequence):
    """The accepted grid times of another run (``times[0]`` = t0), taken again as they are: the
    step sizes are their differences.  A run replaying an adaptive run's ``time`` takes the
    very same steps; its finite differences or complex step are those of the procedure along
    that sequence.  Past the last time given (a run that an event ended) it goes on with the
    last step size up to t_end, so that a perturbed run still finds its event."""

    def __init__(self, times: tuple[float, ...], t_end: float):
        super().__init__(times[0], max(t_end, times[-1]))
        self.times = times
        self.done = len(times) < 2

    def finished(self) -> bool:
        return self.done

    def take(self, stepper: PrimalStepper, i: int, t_prev: float, s: StepState) -> list[StepRecord]:
        h = self._size(i, t_prev)
        records = stepper.advance(i, t_prev, h, s)
        self.log.append((t_prev, h, records[-1].t))
        self.done = self._last(i, records[-1].t)
        return records

    def _size(self, i: int, t_prev: float) -> float:
        """The size (s) of step i from t_prev: the given grid's, then its last one up to t_end."""
        n = len(self.times) - 1
        if i <= n:
            return self.times[i] - self.times[i - 1]
        return min(self.times[n] - self.times[n - 1], self.t_end - t_prev)

    def _last(self, i: int, t: float) -> bool:
        """Whether step i, ending at t (s), is the last one."""
        return i >= len(self.times) - 1 and self.t_end - t <= 1e-12 * max(abs(self.t_end), 1.0)

    def ahead(self, i: int, t_prev: float, count: int) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for j in range(i, i + count):
            h = self._size(j, t_prev)
            out.append((t_prev, h))
            t_prev = t_prev + h             # (where an uncut step ends: PrimalStepper._solve)
            if self._last(j, t_prev):
                break
        return out

    def progress(self) -> tuple[int, int]:
        return len(self.log), len(self.times) - 1

    @property
    def expected_steps(self) -> int:
        return len(self.times) - 1


def replaying(plan: RunPlan, times: np.ndarray) -> RunPlan:
    """``plan`` stepping through the grid ``times`` (s) of another run instead of its own steps:
    finite differences or complex step of such runs differentiate along that sequence."""
    return replace(plan, replay_times=tuple(float(t) for t in np.real(times)))


class AdaptiveSteps(StepSequence):
    """Steps chosen by the local error estimate (module docstring); the first trial is dt."""

    def __init__(self, t0: float, t_end: float, dt: float, settings: AdaptiveSettings, scheme: Newmark,
                 counters: Any):
        super().__init__(t0, t_end)
        self.settings, self.counters = settings, counters
        self.constants = scheme.error_constants()
        self.h_next = min(max(dt, settings.dt_min), settings.dt_max)
        self.nominal = max(1, int(np.ceil((t_end - t0) / dt - 1e-9)))
        self.done = False
        counters.extra.setdefault("rejected_steps", 0)

    def finished(self) -> bool:
        return self.done

    def _fit(self, t_prev: float, h: float) -> tuple[float, bool]:
        """The step to try from t_prev: h, or the rest of the run when h reaches (or nearly
        reaches: no sliver of a last step) t_end; normalized so that h = (t_prev + h) − t_prev."""
        rest = self.t_end - t_prev
        if h >= rest * (1.0 - 1e-12):
            return rest, True
        if rest - h < 0.25 * h:
            h = 0.5 * rest
        return (t_prev + h) - t_prev, False

    def take(self, stepper: PrimalStepper, i: int, t_prev: float, s: StepState) -> list[StepRecord]:
        st = self.settings
        h, rejected = self.h_next, False
        while True:
            h_try, last = self._fit(t_prev, h)
            at_min = h_try <= st.dt_min * (1.0 + 1e-12)
            try:
                trial = stepper.trial(i, t_prev, h_try, s)
            except (ConvergenceError, NonFiniteError) as exc:
                if at_min:
                    exc.args = (f"{exc.args[0]} (adaptive steps down to integrator.adaptive.dt_min = "
                                f"{st.dt_min:g} s)",)
                    raise
                self.counters.extra["rejected_steps"] += 1
                h, rejected = max(st.dt_min, NEWTON_SHRINK * h_try), True
                continue
            err = error_ratio(st, self.constants, s, trial)
            factor = GROW if err == 0.0 else min(GROW, max(SHRINK, SAFETY * err ** (-1.0 / 3.0)))
            if err <= 1.0:
                record = stepper.commit(trial)
                if rejected:
                    factor = min(factor, 1.0)
                self.h_next = min(max(h_try * factor, st.dt_min), st.dt_max)
                self.done = last
                self.log.append((t_prev, h_try, record.t))
                return [record]
            stepper.discard(trial)
            if at_min:
                raise StepSizeError(
                    f"adaptive steps: the local error estimate is {err:.3g} times its tolerance "
                    f"(rtol = {st.rtol:g}, atol = {st.atol:g}) for a step of integrator.adaptive.dt_min = "
                    f"{st.dt_min:g} s from t = {t_prev:.6g} s (step {i}); the run is stopped, not "
                    "completed: lower dt_min if the motion is meant to be resolved this finely, or "
                    "check the model for a discontinuity or a runaway near this time", t=t_prev, step=i)
            self.counters.extra["rejected_steps"] += 1
            h, rejected = max(st.dt_min, factor * h_try), True

    def progress(self) -> tuple[int, int]:
        t = self.log[-1][2] if self.log else self.t0
        return int(round(self.nominal * (t - self.t0) / (self.t_end - self.t0))), self.nominal

    @property
    def expected_steps(self) -> int:
        # the count is not known beforehand (dt is only the first trial): start small and grow
        return min(self.nominal, INITIAL_ROOM)
