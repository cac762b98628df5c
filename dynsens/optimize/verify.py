"""Verification of a design beyond the run that computed it.

An optimizer sees the constraints on one time grid and one window.  A constraint whose peak
moves when the step is halved, or that is still rising when the window ends, can pass there
and fail in the structure.  :func:`verify_design` runs the design again

* ``case``: as the case says (the optimizer's run);
* ``dt/R``: with the time step divided by ``refine`` (adaptive runs: tolerances by R², the
  error of a second-order scheme falling as h²);
* ``horizon``: with the window extended, by its own length at a time, until every peak-type
  constraint response (maximum, minimum, KS, stress, buckling and displacement ratios) changes
  by less than the feasibility tolerance, or to a stated end time;
* ``tail``: with the window cut at (1 − ``tail``) of its length, to tell whether a constrained
  peak lies in the last part of the window,

and checks every constraint in every run, and, for structural models with bars, every member's
stress and buckling ratio at every stored step (:mod:`dynsens.postcheck`).  A design *passes*
when every constraint holds (scaled g ≥ −``FEAS_TOL``) and every member ratio is ≤ 1 + 1e-3 in
the ``dt/R`` and ``horizon`` runs.  A peak in the tail is a warning, not a failure, when the
extended window shows that it holds.

Responses that are defined on the window itself (a value at t_end, an integral, an event time,
a mass) keep their meaning only on the case's window: they are checked at the refined step,
not on the extended horizon.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ..case.load import Case
from ..errors import DynsensError
from ..postcheck import MemberCheck, check_members, has_member_limits
from ..responses.sizing import Aggregate, MagnitudeAggregate
from ..simulation import run_case
from .problem import FEAS_TOL, OptimizationError, ScaledProblem, build_problem

MEMBER_TOL = 1e-3         # member ratios up to 1 + MEMBER_TOL pass (as dynsens.postcheck)
MAX_EXTENSIONS = 4        # the horizon grows to at most (1 + MAX_EXTENSIONS) windows
FULL_TABLE = 20           # more constraints than this: the summary lists the failing and the tightest


@dataclass
class RunInfo:
    """One verification run: its name, step (s), window end (s), wall time (s) and how it ended."""

    name: str
    dt: float
    t_end: float
    wall_time: float
    message: str
    failed: bool = False


@dataclass
class ConstraintCheck:
    """One constraint bound in every verification run.

    values : response value per run name (its unit; NaN where not run or not applicable);
    margins : scaled g per run (≥ 0 holds; the optimizer's scaling);
    status : ``ok``, ``violated``, ``late peak`` (holds, but its peak lies in the tail of the
        window), or ``failed`` (a run could not be completed).
    """

    label: str
    response: str
    peak_type: bool
    values: dict[str, float]
    margins: dict[str, float]
    status: str
    note: str = ""
    case_peak: float = float("nan")     # the case run's sampled peak (its value where not a KS)
    divisor: float = 1.0                # the optimizer's scale of the bound (response unit)


@dataclass
class Verification:
    """The verification of one design (see the module docstring)."""

    x: np.ndarray
    refine: int
    runs: list[RunInfo]
    constraints: list[ConstraintCheck]
    members: dict[str, MemberCheck] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    rounds: list[dict[str, Any]] = field(default_factory=list)   # optimization rounds (verified.py)

    @property
    def passed(self) -> bool:
        """Every constraint holds and every member ratio ≤ 1 + MEMBER_TOL in every run."""
        return (all(c.status in ("ok", "late peak") for c in self.constraints)
                and all(m.largest <= 1.0 + MEMBER_TOL for m in self.members.values())
                and not any(r.failed for r in self.runs))


def _variant(case: Case, *, dt_factor: float = 1.0, t_end: float | None = None) -> Case:
    """``case`` with its step divided by ``dt_factor`` and/or its window ending at ``t_end``."""
    plan = case.plan
    changes: dict[str, Any] = {}
    if dt_factor != 1.0:
        if plan.adaptive is not None:
            a = plan.adaptive
            changes["adaptive"] = replace(a, rtol=a.rtol / dt_factor ** 2, atol=a.atol / dt_factor ** 2,
                                          dt_max=a.dt_max / dt_factor)
        changes["dt"] = plan.dt / dt_factor
    if t_end is not None:
        changes["t_end"] = float(t_end)
    return replace(case, plan=replace(plan, **changes)) if changes else case


def peak_type_responses(case: Case) -> set[str]:
    """Names of the responses that aggregate over the window (max, min, KS, ratios)."""
    rs = case.new_response_set(record=False)
    return {r.name for r in rs.responses if isinstance(r, (Aggregate, MagnitudeAggregate))}


def _has_members(case: Case) -> bool:
    """Whether the case has members to post-check (bars or beams) and limits to check them by:
    a stress ratio's limits, or a buckling or interaction ratio among its responses."""
    from ..models.structural.model import StructuralModel
    model = case.model
    if not isinstance(model, StructuralModel):
        return False
    if not (model.bar_names or len(model.beams.names) or len(model.frames.names)):
        return False
    return has_member_limits(case)


@dataclass
class VerificationRun:
    """One run's record: how it ended, its response values and sampled peaks, its member check."""

    info: RunInfo
    responses: dict[str, float]
    peaks: dict[str, float]          # the sampled extreme of a KS (its value for the others)
    members: MemberCheck | None


def _run(case: Case, x: np.ndarray, name: str, members: bool) -> VerificationRun:
    t0 = time.perf_counter()
    try:
        res = run_case(case, x, sensitivities=False, history=("q",) if members else ())
    except DynsensError as exc:
        info = RunInfo(name, case.plan.dt, case.plan.t_end, time.perf_counter() - t0,
                       f"{type(exc).__name__}: {exc}", failed=True)
        return VerificationRun(info, {}, {}, None)
    values = {k: (float(np.real(v.value)) if not v.missing else float("nan")) for k, v in res.responses.items()}
    # a KS grows with the number of samples it sums (up to ln(N)/rho), so a longer window or a
    # finer step raises it without any larger peak: where the peaks are compared, compare the
    # sampled extremes
    peaks = {k: float(v.extra.get("sampled_max", v.extra.get("sampled_min", values[k])))
             if v.extra else values[k] for k, v in res.responses.items()}
    chk = check_members(case, x, result=res) if members else None
    info = RunInfo(name, case.plan.dt, case.plan.t_end, time.perf_counter() - t0, res.message)
    return VerificationRun(info, values, peaks, chk)


def _margin(term: Any, value: float) -> float:
    """The optimizer's g; an equality's |g| counts against it."""
    g = term.scaled(value)
    return -abs(g) if term.kind == "eq" else g


def verify_design(case: Case, x: Any = None, *, refine: int = 2, horizon: float | str | None = "auto",
                  tail: float = 0.1, problem: ScaledProblem | None = None) -> Verification:
    """Run ``case`` at design ``x`` (default x0) at a refined step and on a longer window.

    Parameters
    ----------
    refine : the step of the ``refined`` run is dt/refine (an integer ≥ 2).
    horizon : ``"auto"`` (extend by the window's length until the peak-type constraint
        responses settle, at most ``MAX_EXTENSIONS`` times), an end time (s), or None (no
        extended run).
    tail : share of the window whose peaks are reported as late (0 < tail < 1; 0: no tail run).
    problem : the optimizer's scaled problem (its constraint scaling); default: built from the
        case's own run at ``x``.

    Raises DynsensError when the case has no ``optimization`` section or its own run fails.
    """
    check_verification_settings(refine, tail)
    x = case.x0 if x is None else np.asarray(x, dtype=float)
    base = base_run(case, x)
    if problem is None:
        problem = build_problem(case, base.responses)
    return verify_from(case, x, base, problem, refine=refine, horizon=horizon, tail=tail)


def check_verification_settings(refine: int, tail: float) -> None:
    """OptimizationError unless ``refine`` ≥ 2 and 0 ≤ ``tail`` < 1."""
    if refine < 2:
        raise OptimizationError(f"the verification's refine must be an integer >= 2, found {refine}")
    if not 0.0 <= tail < 1.0:
        raise OptimizationError(f"the verification's tail must lie in [0, 1), found {tail}")


def base_run(case: Case, x: np.ndarray, what: str = "the design") -> VerificationRun:
    """The ``case`` run of the verification (the case as it stands at ``x``); OptimizationError
    when it fails (``what`` names the design, or the load case, in the message)."""
    base = _run(case, x, "case", _has_members(case))
    if base.info.failed:
        raise OptimizationError(f"{what} cannot be verified: its own run failed: {base.info.message}")
    return base


def verify_from(case: Case, x: np.ndarray, base: VerificationRun, problem: ScaledProblem, *, refine: int,
                horizon: float | str | None, tail: float) -> Verification:
    """The verification runs after the case's own run ``base``, and every constraint of
    ``problem`` checked in them (see :func:`verify_design`)."""
    members = base.members is not None
    peaks = peak_type_responses(case)
    runs: dict[str, VerificationRun] = {"case": base,
                                        "refined": _run(_variant(case, dt_factor=refine), x, "refined", members)}
    warnings: list[str] = []
    plan = case.plan
    window = plan.t_end - plan.t0
    constrained_peaks = [c for c in problem.constraints if c.response in peaks]
    if horizon is not None and constrained_peaks:
        runs["horizon"] = _extend(case, x, base, constrained_peaks, horizon, members, warnings)
    if tail > 0 and constrained_peaks:
        cut = plan.t0 + (1.0 - tail) * window
        runs["tail"] = _run(_variant(case, t_end=cut), x, "tail", False)
    checks = [_check(term, runs, term.response in peaks, tail) for term in problem.constraints]
    for r in runs.values():
        if r.info.failed:
            warnings.append(f"the {r.info.name} run failed: {r.info.message}")
    member_checks = {k: r.members for k, r in runs.items() if r.members is not None}
    return Verification(np.asarray(x, dtype=float), refine, [r.info for r in runs.values()], checks,
                        member_checks, warnings)


def _extend(case: Case, x: np.ndarray, base: VerificationRun, terms: list[Any], horizon: float | str,
            members: bool, warnings: list[str]) -> VerificationRun:
    """The ``horizon`` run: a stated end time, or windows added until the peaks settle."""
    plan = case.plan
    if horizon != "auto":
        t_end = float(horizon)
        if not t_end > plan.t_end:
            raise OptimizationError(f"the verification horizon {t_end:g} s must lie beyond t_end = {plan.t_end:g} s")
        return _run(_variant(case, t_end=t_end), x, "horizon", members)
    window = plan.t_end - plan.t0
    prev = base
    for k in range(1, MAX_EXTENSIONS + 1):
        run = _run(_variant(case, t_end=plan.t_end + k * window), x, "horizon", members)
        if run.info.failed:
            return run
        settled = all(abs(run.peaks[t.response] - prev.peaks[t.response]) <= FEAS_TOL * t.divisor
                      for t in terms)
        if settled:
            return run
        prev = run
    warnings.append(f"the constrained peaks still change at {prev.info.t_end:g} s "
                    f"({1 + MAX_EXTENSIONS} windows): the structure has not settled")
    return prev


def _check(term: Any, runs: dict[str, VerificationRun], peak_type: bool, tail: float) -> ConstraintCheck:
    """The constraint ``term`` in every run: the case's run as the optimizer saw it, the others by
    their sampled peaks (a KS rises with its number of samples, so a finer step or a longer
    window would raise it with no larger peak; the requirement is on the peak)."""
    values: dict[str, float] = {}
    margins: dict[str, float] = {}
    for name, r in runs.items():
        if name in ("horizon", "tail") and not peak_type:
            continue
        v = (r.responses if name == "case" else r.peaks).get(term.response, float("nan"))
        values[name] = v
        margins[name] = _margin(term, v) if np.isfinite(v) else float("nan")
    judged = ("case", "refined", "horizon")
    if any(runs[n].info.failed for n in judged if n in margins):
        return ConstraintCheck(term.label, term.response, peak_type, values, margins, "failed",
                               "a verification run failed")
    notes = []
    status = "ok"
    bad = [(margins[n], n) for n in judged if n in margins and np.isfinite(margins[n]) and margins[n] < -FEAS_TOL]
    if bad:
        status = "violated"
        g, n = min(bad)
        notes.append(f"violated in the {n} run (scaled margin {g:.3g})")
    if "tail" in margins and np.isfinite(margins["tail"]) and term.kind != "eq":
        # the sampled extreme over the full window is beyond the one over the window less its
        # tail: the constrained peak lies in the last part of the window
        full, cut = runs["case"].peaks[term.response], runs["tail"].peaks.get(term.response, np.nan)
        beyond = (full - cut) if term.kind == "upper" else (cut - full)
        if np.isfinite(beyond) and beyond > FEAS_TOL * term.divisor:
            notes.append(f"its peak lies in the last {100 * tail:.0f} % of the window")
            if status == "ok":
                status = "late peak"
    return ConstraintCheck(term.label, term.response, peak_type, values, margins, status, "; ".join(notes),
                           runs["case"].peaks.get(term.response, float("nan")), term.divisor)


def format_verification(v: Verification, verdict: bool = True) -> str:
    """The verification as a table and plain sentences, for the terminal (``verdict``: end with
    the sentence whether the design passes)."""
    head = {"case": "case", "refined": f"dt/{v.refine}", "horizon": "horizon", "tail": "no tail"}
    lines = ["verification runs: " + "; ".join(
        f"{head[r.name]}: dt = {r.dt:.4g} s, t_end = {r.t_end:.4g} s ({r.wall_time:.1f} s"
        + (", FAILED" if r.failed else "") + ")" for r in v.runs)]
    lines += _constraint_table(v, head)
    for run, m in v.members.items():
        member, kind, ratio = m.worst()
        lines.append(f"members ({head[run]}): largest ratio {ratio:.4f} ({member}, {kind}) over {m.steps} steps"
                     + ("" if m.largest <= 1 + MEMBER_TOL else f"; {m.count_above(1 + MEMBER_TOL)} member(s) above 1"))
    lines += [f"warning: {w}" for w in v.warnings]
    late = [c.label for c in v.constraints if c.status == "late peak"]
    if late:
        lines.append("warning: the peak of " + ", ".join(late) + " lies in the last part of the window")
    if not verdict:
        return "\n".join(lines)
    lines.append("The design PASSES the verification." if v.passed else
                 "The design does NOT pass the verification: a constraint that holds only on the optimizer's "
                 "time grid and window is not a result (see docs/optimization.md).")
    return "\n".join(lines)


def _constraint_table(v: Verification, head: dict[str, str]) -> list[str]:
    """Lines of the table of the constraints' peaks per run (of a long one, those that matter)."""
    names = [r.name for r in v.runs]
    width = max([len(c.label) for c in v.constraints] + [10])
    lines = [f"{'constraint':<{width}}  " + "  ".join(f"{head[n]:>12}" for n in names) + "  change  status",
             "(case: the response as optimized; the other runs: its sampled peak, see docs/optimization.md; change: "
             "the largest change of the peak against the case's run, in % of the bound's scale)"]
    shown = _shown_constraints(v.constraints)
    for c in shown:
        cells = [f"{val:>12.6g}" if val is not None and np.isfinite(val) else f"{'-':>12}"
                 for val in (c.values.get(n) for n in names)]
        mark = c.status.upper() if c.status != "ok" else "ok"
        lines.append(f"{c.label:<{width}}  " + "  ".join(cells) + f"  {100 * _peak_change(c):5.1f}%  {mark}"
                     + (f" ({c.note})" if c.note else ""))
    if len(shown) < len(v.constraints):
        lines.append(f"({len(v.constraints) - len(shown)} more constraints hold in every run with larger margins)")
    return lines


def _shown_constraints(constraints: list[ConstraintCheck]) -> list[ConstraintCheck]:
    """All constraints, or of more than FULL_TABLE (a sizing case has one per member group) those
    that matter: the ones not ok and the five of the smallest margins."""
    if len(constraints) <= FULL_TABLE:
        return constraints
    order = sorted(constraints, key=lambda c: min([g for g in c.margins.values() if np.isfinite(g)] or [np.inf]))
    keep = {id(c) for c in constraints if c.status != "ok"} | {id(c) for c in order[:5]}
    return [c for c in constraints if id(c) in keep]


def _peak_change(c: ConstraintCheck) -> float:
    """The largest change of the peak in the refined and horizon runs against the case's run,
    as a fraction of the bound's scale (0 when the case has none)."""
    ref = c.case_peak
    later = [c.values[n] for n in ("refined", "horizon") if n in c.values and np.isfinite(c.values[n])]
    return max((abs(w - ref) for w in later), default=0.0) / c.divisor if np.isfinite(ref) else 0.0


def excesses(v: Any, problem: ScaledProblem) -> dict[int, float]:
    """For each constraint term (its index) the verification ``v`` (a `Verification`, or one over
    load cases: its ``constraints`` in the optimizer's order) found violated: how far its worst
    run goes beyond the bound, in the response's unit (> 0)."""
    out: dict[int, float] = {}
    for i, (term, c) in enumerate(zip(problem.constraints, v.constraints)):
        if c.status != "violated" or term.kind == "eq":
            continue
        worst = min(g for g in c.margins.values() if np.isfinite(g))
        out[i] = -worst * term.divisor
    return out


def store_verification(path: Any, v: Any, rounds: list[dict[str, Any]] | None = None,
                       write: Callable[[Any, Any], None] | None = None) -> None:
    """Write ``v`` into the HDF5 file at ``path`` as the group ``/verification`` (replaced), by
    ``write(group, v)`` (default :func:`write_verification`), with :func:`write_rounds` when the
    bounds were tightened."""
    import h5py
    with h5py.File(path, "a") as f:
        if "verification" in f:
            del f["verification"]
        g = f.create_group("verification")
        (write or write_verification)(g, v)
        if rounds:
            write_rounds(g, rounds)


def write_verification(g: Any, v: Verification) -> None:
    """Write ``v`` into the (empty) HDF5 group ``g``.

    Attributes: ``passed``, ``refine``, ``warnings`` (JSON), ``x``; datasets ``runs/{name, dt,
    t_end, wall_time, failed, message}``, ``constraints/{label, status, note}`` and one
    ``constraints/value_<run>`` and ``constraints/margin_<run>`` per run (NaN where not
    applicable), ``members/<run>/{tension, compression, buckling}`` and ``interaction`` where a
    beam has one (per member, the largest ratio over the stored steps) with attribute ``names``.
    """
    import json

    import h5py
    text = h5py.string_dtype()
    g.attrs.update({"passed": v.passed, "refine": v.refine, "warnings": json.dumps(v.warnings),
                    "x": np.asarray(v.x, dtype=float)})
    r = g.create_group("runs")
    r.create_dataset("name", data=np.array([i.name for i in v.runs], dtype=text))
    r.create_dataset("dt", data=np.array([i.dt for i in v.runs], dtype=float))
    r.create_dataset("t_end", data=np.array([i.t_end for i in v.runs], dtype=float))
    r.create_dataset("wall_time", data=np.array([i.wall_time for i in v.runs], dtype=float))
    r.create_dataset("failed", data=np.array([i.failed for i in v.runs]))
    r.create_dataset("message", data=np.array([i.message for i in v.runs], dtype=text))
    write_constraint_table(g.create_group("constraints"), v.constraints, [i.name for i in v.runs])
    for run, m in v.members.items():
        mg = g.create_group(f"members/{run}")
        mg.attrs["names"] = np.array(m.names, dtype=text)
        mg.attrs["steps"] = m.steps
        for kind in ("tension", "compression", "buckling"):
            mg.create_dataset(kind, data=np.asarray(getattr(m, kind), dtype=float))
        if np.isfinite(m.interaction).any():       # only beams with a yield stress have one
            mg.create_dataset("interaction", data=np.asarray(m.interaction, dtype=float))


def write_constraint_table(c: Any, constraints: list[ConstraintCheck], runs: list[str]) -> None:
    """Datasets ``label``, ``status``, ``note`` and ``value_<run>``, ``margin_<run>`` per run
    (NaN where the constraint has no value in that run) into the HDF5 group ``c``."""
    import h5py
    text = h5py.string_dtype()
    c.create_dataset("label", data=np.array([k.label for k in constraints], dtype=text))
    c.create_dataset("status", data=np.array([k.status for k in constraints], dtype=text))
    c.create_dataset("note", data=np.array([k.note for k in constraints], dtype=text))
    for run in runs:
        c.create_dataset(f"value_{run}", data=np.array([k.values.get(run, np.nan) for k in constraints]))
        c.create_dataset(f"margin_{run}", data=np.array([k.margins.get(run, np.nan) for k in constraints]))


def write_rounds(g: Any, rounds: list[dict[str, Any]]) -> None:
    """``rounds/{bounds, f, passed, x, nit, n_sim, wall_time}`` into the HDF5 group ``g``: one row
    per optimization round (the bounds of every constraint term, the optimum and its verdict)."""
    rg = g.create_group("rounds")
    rg.create_dataset("bounds", data=np.array([row["bounds"] for row in rounds], dtype=float))
    rg.create_dataset("f", data=np.array([row["f"] for row in rounds], dtype=float))
    rg.create_dataset("passed", data=np.array([row["passed"] for row in rounds]))
    rg.create_dataset("x", data=np.array([row["x"] for row in rounds], dtype=float))
    for key in ("nit", "n_sim", "wall_time"):
        rg.create_dataset(key, data=np.array([row[key] for row in rounds]))
