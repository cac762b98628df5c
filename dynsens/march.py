"""The time loop: one routine for the primal state and its design sensitivities.

Per step (method.md §2–4): predict → Newton on F_R(z) = 0 → correct; then, when
sensitivities are requested, predict the sensitivity matrices with the same scheme,
form the pseudo load P at the converged state and solve S ∇z = −P with the factor of
the converged Newton matrix → correct.  The sensitivity steps trail the state steps by a
block (each step keeps its converged linearization and factor), so that the explicit design
partials of a whole block take one batched residual call; the arithmetic per step is the
same (small constant-matrix models advance the block by the transition matrix of that very
step).  What a case does not need is decided once in :class:`RunPlan` and never re-tested
inside the loop's numerics.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .errors import ConvergenceError, NonFiniteError
from .integrators.newmark import Aux, Newmark, Prediction
from .models.base import Model, StepState
from .responses import ResponseSet, ResponseValue
from .sensitivity import DesignPartials, initial_state_gradient, pseudo_load, pseudo_load_with
from .solver.linalg import Counters
from .solver.newton import NewtonSettings, StepSolver

HISTORY_FIELDS = ("q", "qd", "qdd", "lam", "p", "pd")


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

    @property
    def n_steps(self) -> int:
        """Number of steps (the last one is shortened to land on t_end)."""
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


def _split(z: np.ndarray, n_q: int, n_lam: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return z[:n_q], z[n_q:n_q + n_lam], z[n_q + n_lam:]


def _check_finite(s: StepState, t: float, step: int, labels: list[str]) -> None:
    # one sum: NaN or Inf anywhere makes it non-finite; then find the entry (an overflowing
    # sum of finite entries finds none and passes)
    if np.isfinite(np.concatenate(s).sum()):
        return
    for name, v in zip(HISTORY_FIELDS, s):
        if v.size and not np.all(np.isfinite(v)):
            k = int(np.flatnonzero(~np.isfinite(v))[0])
            where = labels[k] if name in ("q", "qd", "qdd") and k < len(labels) else f"{name}[{k}]"
            raise NonFiniteError(
                f"NaN/Inf first appeared in {name} of {where} at t = {t:.6g} s (step {step}): "
                "reduce the time step or check parameters and loads")


TRAIL_STEPS = 128
TRAIL_BYTES = 32 * 2**20
# Largest sensitivity state (∇q, ∇q̇, ∇q̈, ∇λ, ∇p, ∇ṗ and the scheme's ∇a, ∇b stacked) for
# which constant-matrix steps advance by a transition matrix (its product costs n_x² m; above
# this size the step's own solve is cheaper)
TRANSITION_MAX = 32


def _trail_length(traits: Any, m: int) -> int:
    """Steps the sensitivities may trail the state: up to TRAIL_STEPS, while the held dense
    linearizations and factors (≈ 4 n_z² + 6 m n_z numbers per step) stay within TRAIL_BYTES;
    one step (no trail) for sparse models, whose factors are large."""
    if traits.sparse:
        return 1
    per_step = 8 * (4 * traits.n_z * traits.n_z + 6 * m * traits.n_z)
    return max(1, min(TRAIL_STEPS, TRAIL_BYTES // per_step))


def integrate(model: Model, x: np.ndarray, scheme: Newmark, plan: RunPlan,
              responses: ResponseSet, *, design_names: tuple[str, ...] = (),
              design_scale: np.ndarray | None = None,
              progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Run one simulation of ``model`` at design ``x`` (m,) and return its results.

    ``x`` may be complex (complex step of the whole simulation); sensitivities must then
    be off.  Raises ConvergenceError, NonFiniteError or ModelError with context.
    """
    wall0 = _time.perf_counter()
    tr = model.traits
    n_q, n_lam = tr.n_q, tr.n_lam
    counters = Counters()
    sens = plan.sensitivities and np.size(x) > 0
    if sens and np.iscomplexobj(x):
        raise ValueError("sensitivities cannot be computed on a complex design; switch them off")
    partials = DesignPartials(model, np.asarray(x), plan.partials, plan.partials_step,
                              design_scale) if sens else None
    params = partials.params0 if partials is not None else model.parameters(np.asarray(x))
    m = np.size(x)
    solver = StepSolver(model, plan.newton, counters, newton=not tr.linear,
                        refactor=not tr.constant_matrices,
                        need_converged_factor=sens and plan.sensitivity_matrix == "converged",
                        sensitivities=sens,
                        reuse_tolerance=partials.relative_error if partials is not None else 0.0)
    labels = model.dof_labels()
    n_steps = plan.n_steps

    # --- initial state and consistent initial accelerations (coefficients 0: S0 = ∂F_R/∂z)
    q0, qd0, p0 = model.initial_state(params)
    lam_guess, pd_guess = model.initial_guess(params)
    dtype = np.result_type(q0, qd0, p0, float)
    z0 = np.concatenate([np.zeros(n_q, dtype), np.asarray(lam_guess, dtype), np.asarray(pd_guess, dtype)])
    pred = Prediction(q0, qd0, p0, q0[:0], p0[:0])

    def correct0(pr: Prediction, qdd: np.ndarray, lam: np.ndarray, pd: np.ndarray) -> StepState:
        return StepState(pr.q, pr.qd, qdd, lam, pr.p, pd)

    out = solver.solve_step(plan.t0, 0, pred, z0, params, (0.0, 0.0, 0.0), correct0)
    s = out.state
    _check_finite(s, plan.t0, 0, labels)
    ds: StepState | None = None
    if partials is not None:
        dq0, dqd0, dp0 = initial_state_gradient(model, partials)
        P = pseudo_load(model, plan.t0, s, out.lin, dq0, dqd0, dp0, partials)
        counters.sensitivity_residual_evaluations += partials.evaluations_per_call
        assert out.factor is not None
        dz = solver.solve_sensitivity(out.factor, P)
        dqdd, dlam, dpd = _split(dz, n_q, n_lam)
        ds = StepState(dq0, dqd0, dqdd, dlam, dp0, dpd)
    aux = scheme.start(s)
    daux = scheme.start(ds) if ds is not None else None

    # --- storage, decided once
    hist_fields = [f for f in plan.history if f in HISTORY_FIELDS]
    store_sens = plan.sensitivity_history and ds is not None
    times = np.empty(n_steps + 1)
    hist = {f: np.empty((n_steps + 1, getattr(s, f).shape[0]), dtype=getattr(s, f).dtype)
            for f in hist_fields}
    shist = {f: np.empty((n_steps + 1, getattr(s, f).shape[0], m)) for f in hist_fields} if store_sens else {}
    mon_names = list(model.monitors(plan.t0, s, params))
    mons = {k: np.empty(n_steps + 1) for k in mon_names}
    responses.start(params, partials, None if partials is not None else model.stack_parameters([params]),
                    tr.n_z)

    def record(k: int, t: float, st: StepState) -> None:
        times[k] = t
        for f in hist_fields:
            hist[f][k] = getattr(st, f)
        if mon_names:
            for name, val in model.monitors(t, st, params).items():
                mons[name][k] = val

    def record_sensitivities(k: int, dst: StepState) -> None:
        for f in hist_fields:
            shist[f][k] = getattr(dst, f)

    record(0, plan.t0, s)
    if store_sens and ds is not None:
        record_sensitivities(0, ds)
    responses.push(0, plan.t0, s, ds, 0.0, responses.watch(plan.t0, s))
    counters.output_evaluations += 1
    status, message = "completed", f"reached t_end = {plan.t_end:g} s"
    last = 0
    t = plan.t0

    # The sensitivities trail the state by a block of steps: the explicit design partials of
    # the block's converged states take one batched residual call (Model.residual_batch_steps),
    # then each step solves S ∇z = −P with its own converged linearization and factor, in step
    # order (method.md §4).  Sub-steps of step cuts are in the trail; the grid steps are marked.
    def sensitivity_step(ds: StepState, daux: Aux, design_part: np.ndarray, lin: Any, factor: Any,
                         h: float) -> tuple[StepState, Aux]:
        """One sensitivity step (method.md §4): predict ∇, pseudo load, S ∇z = −P, correct."""
        dpred = scheme.predict(ds, daux, h)
        P = pseudo_load_with(design_part, lin, dpred.q, dpred.qd, dpred.p)
        dz = solver.solve_sensitivity(factor, P)
        ds = scheme.correct(dpred, *_split(dz, n_q, n_lam), h)
        return ds, scheme.advance(dpred, ds)

    # Constant matrices (linear models): every step with the same step size applies the same
    # linear map, X' = T X + U ∂_xF_R on the stacked sensitivity state X; T and U are that very
    # step applied to unit columns, so a step costs one small product instead of a solve.
    sizes = [n_q, n_q, n_q, n_lam, tr.n_p, tr.n_p, n_q, tr.n_p]
    ends = np.cumsum(sizes).tolist()
    pieces = [slice(a, b) for a, b in zip([0] + ends[:-1], ends)]
    use_transitions = tr.constant_matrices and sum(sizes) <= TRANSITION_MAX
    transitions: dict[tuple[int, int, float], tuple[Any, Any, np.ndarray, np.ndarray]] = {}

    def unpack(X: np.ndarray) -> tuple[StepState, Aux]:
        parts = [X[sl] for sl in pieces]
        return StepState(*parts[:6]), Aux(*parts[6:])

    def transition(lin: Any, factor: Any, h: float) -> tuple[np.ndarray, np.ndarray]:
        key = (id(lin), id(factor), h)
        if key not in transitions:    # (the entry holds lin and factor: their ids stay theirs)
            n_x = sum(sizes)
            ds_T, daux_T = sensitivity_step(*unpack(np.eye(n_x)), np.zeros((tr.n_z, n_x)), lin, factor, h)
            ds_U, daux_U = sensitivity_step(*unpack(np.zeros((n_x, tr.n_z))), np.eye(tr.n_z), lin, factor, h)
            transitions[key] = (lin, factor, np.concatenate([*ds_T, *daux_T]),
                                np.concatenate([*ds_U, *daux_U]))
        return transitions[key][2], transitions[key][3]

    trail: list[tuple[float, float, StepState, Any, Any]] = []      # (t, h, s, lin, factor)
    marks: list[tuple[int, float, StepState, float, Any, int]] = []  # (i, t, s, h, event, trail index)
    trail_length = _trail_length(tr, m) if partials is not None else 1

    def take_step(i: int, t_prev: float, h: float, cuts: int, s: StepState, aux: Aux
                  ) -> tuple[StepState, Aux]:
        """Advance the state from t_prev by h (s); on Newton failure, halve the step (up to
        plan.max_step_cuts times).  Every step taken joins the sensitivity trail."""
        t = t_prev + h
        pred = scheme.predict(s, aux, h)
        z_guess = np.concatenate([s.qdd, s.lam, s.pd])

        def correct(pr: Prediction, qdd: np.ndarray, lam: np.ndarray, pd: np.ndarray) -> StepState:
            return scheme.correct(pr, qdd, lam, pd, h)

        try:
            out = solver.solve_step(t, i, pred, z_guess, params, scheme.coefficients(h), correct)
        except ConvergenceError as exc:
            if cuts >= plan.max_step_cuts:
                if plan.max_step_cuts:
                    exc.args = (f"{exc.args[0]} (after {cuts} step cuts down to Δt = {h:.3g} s)",)
                raise
            counters.step_cuts += 1
            half = 0.5 * h
            s, aux = take_step(i, t_prev, half, cuts + 1, s, aux)
            return take_step(i, t_prev + half, half, cuts + 1, s, aux)
        s_new = out.state
        _check_finite(s_new, t, i, labels)
        model.check_state(t, s_new, params)
        if partials is not None:
            assert out.factor is not None
            trail.append((t, h, s_new, out.lin, out.factor))
        return s_new, scheme.advance(pred, s_new)

    def catch_up() -> None:
        """Sensitivities of the trailing steps, then the marked grid steps to the responses."""
        nonlocal ds, daux
        ds_of: list[StepState | None] = [None] * len(trail)
        if partials is not None and trail and ds is not None and daux is not None:
            design_part = partials.residual_partials_steps(np.array([e[0] for e in trail]),
                                                           [e[2] for e in trail])
            counters.sensitivity_residual_evaluations += partials.evaluations_per_call * len(trail)
            k = 0
            while k < len(trail):
                _, h, _, lin, factor = trail[k]
                end = k + 1
                while use_transitions and end < len(trail) and trail[end][3] is lin and \
                        trail[end][4] is factor and trail[end][1] == h:
                    end += 1
                if end - k == 1:
                    ds, daux = sensitivity_step(ds, daux, design_part[k], lin, factor, h)
                    ds_of[k] = ds
                else:
                    T, U = transition(lin, factor, h)
                    W = U @ design_part[k:end]
                    X = np.concatenate([*ds, *daux])
                    for j in range(end - k):
                        X = T @ X + W[j]
                        ds_of[k + j] = unpack(X)[0]
                    ds, daux = unpack(X)
                k = end
        for i, t, s, h, event, k in marks:
            dst = ds_of[k] if k >= 0 else None
            if store_sens and dst is not None:
                record_sensitivities(i, dst)
            responses.push(i, t, s, dst, h, event)
        trail.clear()
        marks.clear()

    for i in range(1, n_steps + 1):
        h = plan.step_size(i)
        t_prev, t = t, plan.t0 + (i - 1) * plan.dt + h
        s, aux = take_step(i, t_prev, h, 0, s, aux)
        counters.steps += 1
        record(i, t, s)
        last = i
        counters.output_evaluations += 1
        event = responses.watch(t, s)
        marks.append((i, t, s, h, event, len(trail) - 1))
        if event is not None or len(marks) >= trail_length:
            catch_up()
        if event is not None:
            ev = next(reversed(responses.fired))
            status = "terminated"
            message = f"event '{ev}' at t = {float(np.real(responses.fired[ev].t)):.6g} s"
            break
        if progress is not None:
            progress(i, n_steps)
    catch_up()
    responses.close(t, m)

    def mass() -> tuple[Any, np.ndarray | None]:
        value = model.structural_mass(params)
        grad = partials.of(lambda prm: np.atleast_1d(model.structural_mass(prm)))[0] \
            if partials is not None else None
        return value, grad

    design = dict(zip(design_names, np.asarray(x)))
    values = responses.finish(design, m if sens else 0, mass)
    n = last + 1
    return RunResult(
        x=np.asarray(x), time=times[:n], history={f: v[:n] for f, v in hist.items()},
        sensitivity_history={f: v[:n] for f, v in shist.items()},
        monitors={k: v[:n] for k, v in mons.items()}, responses=values,
        counters=counters.as_dict(), wall_time=_time.perf_counter() - wall0,
        status=status, message=message, labels={"q": labels})
