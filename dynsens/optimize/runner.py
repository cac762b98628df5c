"""Running the starts: the first at x0, the rest from a Latin hypercube, in worker processes or on
a Dask cluster (:mod:`dynsens.executor`); the final table and verdict."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, cast

import h5py
import numpy as np

from ..case.load import Case
from ..executor import make_executor, remember_case
from ..io.hdf5 import OutputExistsError
from ..io.paths import holds_writer_lock
from .jobs import StartJob, StartOutcome, run_start
from .methods import check_method
from .problem import OptimizationError, ScaledProblem, _fmt, _spec, build_problem, scaled_evaluation, simulate
from .store import validate_resume_file
from .summary import removed_members
from .store import (_init_file, _outcome_attrs, _outcome_from_file, _problem_attrs, _problem_from_file,
                    _set_attrs, _start_group, _store_optimum, _write_row, set_status)

# --------------------------------------------------------------------------------------
# the driver
# --------------------------------------------------------------------------------------
@dataclass
class OptimizationResult:
    """All starts of a run and the best one."""

    path: Path
    problem: ScaledProblem
    starts: list[StartOutcome]
    best: int

    @property
    def best_outcome(self) -> StartOutcome:
        """The best start (lowest objective among the feasible ones)."""
        return self.starts[self.best]

    @property
    def converged(self) -> bool:
        """SLSQP reported success for the best start."""
        return self.best_outcome.success

    @property
    def feasible(self) -> bool:
        """The best design satisfies every constraint within FEAS_TOL."""
        return self.best_outcome.feasible


def start_points(case: Case, n: int, seed: int, x0: np.ndarray) -> np.ndarray:
    """``n`` start designs (n, m): ``x0``, then a Latin hypercube sample in the bounds."""
    pts = [np.asarray(x0, dtype=float)]
    if n > 1:
        lo, up = case.lower, case.upper
        bad = [nm for nm, a, b in zip(case.design_names, lo, up) if not (np.isfinite(a) and np.isfinite(b))]
        if bad:
            raise OptimizationError(f"--starts {n} needs finite bounds for every design variable "
                                    f"(unbounded: {', '.join(bad)})")
        from scipy.stats import qmc
        gen = np.random.default_rng(seed)   # the same sample as rng=seed on SciPy >= 1.15
        try:
            lhs = qmc.LatinHypercube(d=len(lo), rng=gen)
        except TypeError:  # SciPy < 1.15 calls the argument seed
            lhs = qmc.LatinHypercube(d=len(lo), seed=gen)
        sample = lhs.random(n - 1)
        pts += list(lo + sample * (up - lo))
    return np.array(pts)


def resolve_x0(case: Case, x0: Mapping[str, float] | None, base: np.ndarray | None = None) -> np.ndarray:
    """The case's initial design (or ``base``) with ``x0`` entries replaced; checks names and bounds."""
    x = (case.x0 if base is None else np.asarray(base, dtype=float)).copy()
    names = case.design_names
    for name, v in (x0 or {}).items():
        # a family's name addresses all its members A[...]
        targets = [names.index(name)] if name in names else \
            [j for j, n in enumerate(names) if n.startswith(f"{name}[") and n.endswith("]")]
        if not targets:
            shown = ", ".join(names[:20]) + (f" ... ({len(names)} in all)" if len(names) > 20 else "")
            raise OptimizationError(f"-x {name}={v}: unknown design variable {name!r} (nor a family) "
                                    f"(design variables: {shown})")
        for j in targets:
            lo, up = case.lower[j], case.upper[j]
            if not (np.isfinite(v) and lo <= v <= up):
                raise OptimizationError(f"-x {name}={v:g} is outside the bounds of design variable "
                                        f"{names[j]!r}: [{lo:g}, {up:g}]")
            x[j] = float(v)
    return x


@holds_writer_lock
def optimize_case(case: Case, output: str | Path, *, starts: int | None = None, seed: int | None = None,
                  x0: Mapping[str, float] | None = None, maxiter: int | None = None,
                  ftol: float | None = None, workers: int | None = None, scheduler: str | None = None,
                  resume: bool = False, overwrite: bool = False,
                  on_message: Callable[[dict[str, Any]], None] | None = None,
                  on_start_done: Callable[[StartOutcome], None] | None = None) -> OptimizationResult:
    """Optimize ``case`` with SLSQP from one or more starts; history to ``output`` (HDF5).

    Parameters
    ----------
    case : a case with an ``optimization`` section.
    output : OPT.h5 path; created atomically, then appended after every iteration.
    starts : number of starts (default 1): the first at x0, the rest a Latin hypercube
        sample in the bounds (``scipy.stats.qmc.LatinHypercube``, ``seed``).
    seed : seed of the Latin hypercube (default: drawn and stored in the file).
    x0 : design values (case units) replacing the case's initial design; must be in the bounds.
    maxiter, ftol : SLSQP settings (default: the case's ``optimization`` section).
    workers : worker processes for several starts (default min(starts, CPUs)); 1 runs in-process.
    scheduler : address of a Dask distributed scheduler; starts run there instead.
    resume : continue the unfinished starts recorded in ``output``.
    overwrite : replace an existing ``output``.
    on_message : called in this process with every evaluation/iteration message once written.
    on_start_done : called with each finished start.

    Raises
    ------
    OptimizationError
        No optimization section, start outside the bounds, the reference start cannot be
        simulated, inconsistent ``--resume``.
    """
    spec = _spec(case)
    path = Path(output)
    maxiter = int(maxiter if maxiter is not None else spec.maxiter)
    ftol = float(ftol if ftol is not None else spec.ftol)
    if maxiter < 1 or not 0 < ftol < np.inf:
        raise OptimizationError(f"expected maxiter >= 1 and ftol > 0, found {maxiter} and {ftol:g}")
    outcomes: dict[int, StartOutcome] = {}
    jobs: list[StartJob] = []
    if resume:
        problem, pts, jobs, outcomes = _resume_jobs(path, case, starts, seed, x0, maxiter, ftol)
    else:
        if path.exists() and not overwrite:
            raise OutputExistsError(f"{path} exists: pass --overwrite to replace it, or --resume to continue it")
        n = int(starts or 1)
        if n < 1:
            raise OptimizationError(f"--starts must be >= 1, found {n}")
        x_ref = resolve_x0(case, x0)
        if seed is None:
            seed = int(cast(int, np.random.SeedSequence().entropy) % (2 ** 31))
        pts = start_points(case, n, seed, x_ref)
        _init_file(path, case, x_ref, overwrite)
        # the reference start is simulated here: it fixes the normalizations (one simulation,
        # handed to start 0 so that it is not repeated)
        res0, msg0, wall0 = simulate(case, x_ref)
        ref_values = {n: (float(np.real(r.value)) if not r.missing else np.nan)
                      for n, r in res0.responses.items()} if res0 is not None else \
            {n: np.nan for n in case.response_names}
        problem = build_problem(case, ref_values)
        check_method(spec.method, problem)
        ev0 = scaled_evaluation(problem, x_ref, res0, msg0, wall0)
        _set_attrs(path, "optimization", {**_problem_attrs(problem), "maxiter": maxiter, "ftol": ftol,
                                          "starts": n, "seed": seed, "x_starts": pts})
        for k, xs in enumerate(pts):
            _set_attrs(path, _start_group(k), {"x_start": xs, "finished": False})
        if ev0.failed:
            msg = {"start": 0, "kind": "evaluation", "seq": 0,
                   "row": {"x": ev0.x, "u": problem.to_u(ev0.x), "f": np.nan,
                           "g": np.full(len(problem.constraints), np.nan), "failed": True,
                           "message": ev0.message, "wall_time": ev0.wall_time, "iteration": 0}}
            _write_row(path, msg)
            text = f"the start design x0 = {_fmt(x_ref)} cannot be simulated: {ev0.message}"
            _set_attrs(path, _start_group(0), {"finished": True, "success": False, "message": text})
            set_status(path, "failed", text)
            raise OptimizationError(text)
        for k, xs in enumerate(pts):
            jobs.append(StartJob(k, case.text, case.source, problem, xs, maxiter, ftol,
                                 seed_eval=ev0 if k == 0 else None, method=spec.method))
    remember_case(case)
    if resume:
        _set_attrs(path, "", {"status": "running", "message": ""})
        _set_attrs(path, "optimization", {"maxiter": maxiter, "ftol": ftol})
    expected = {j.index: 0 for j in jobs}
    pending: dict[int, dict[int, dict[str, Any]]] = {j.index: {} for j in jobs}

    def handle(msg: dict[str, Any]) -> None:
        k = msg["start"]
        pending[k][msg["seq"]] = msg
        while expected[k] in pending[k]:
            m_ = pending[k].pop(expected[k])
            expected[k] += 1
            _write_row(path, m_)
            if on_message is not None:
                on_message(m_)

    def finish(o: StartOutcome) -> None:
        for m_ in o.messages:            # anything the live stream has not delivered yet
            if m_["seq"] >= expected[o.index]:
                handle(m_)
        _set_attrs(path, _start_group(o.index), _outcome_attrs(o))
        outcomes[o.index] = o
        if on_start_done is not None:
            on_start_done(o)

    try:
        if jobs:
            with make_executor(workers, scheduler, tasks=len(jobs)) as executor:
                executor.run(run_start, jobs, lambda i, o: finish(o), handle)
    except KeyboardInterrupt:
        set_status(path, "interrupted", "interrupted: continue with --resume")
        raise
    except BaseException as exc:
        set_status(path, "failed", f"{type(exc).__name__}: {exc}")
        raise
    result = _finalize(path, case, problem, [outcomes[k] for k in sorted(outcomes)])
    return result


def _resume_jobs(path: Path, case: Case, starts: int | None, seed: int | None, x0: Mapping[str, float] | None,
                 maxiter: int, ftol: float) -> tuple[ScaledProblem, np.ndarray, list[StartJob],
                                                     dict[int, StartOutcome]]:
    if not path.exists():
        raise OptimizationError(f"--resume: {path} does not exist (run without --resume to start)")
    jobs: list[StartJob] = []
    done: dict[int, StartOutcome] = {}
    validate_resume_file(path, len(case.design))
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise OptimizationError(f"--resume: cannot read {path}: {exc}") from None
    with f:
        if "optimization" not in f or "f_ref" not in f["optimization"].attrs:
            raise OptimizationError(f"--resume: {path} is not a dynsens optimization file "
                                    "(or it was interrupted before its first design was simulated)")
        if str(f.attrs.get("case", "")) != case.text:
            raise OptimizationError(f"--resume: {path} was made from a different case (or other --set "
                                    "options): give the same case file and --set options")
        a = f["optimization"].attrs
        n = int(a["starts"])
        if starts is not None and int(starts) != n:
            raise OptimizationError(f"--resume: {path} has {n} start(s); --starts {starts} cannot change that")
        if seed is not None and int(seed) != int(a["seed"]):
            raise OptimizationError(f"--resume: {path} used --seed {int(a['seed'])}; --seed cannot change it")
        if x0:
            raise OptimizationError("--resume continues from the recorded designs: -x/--x0 cannot be combined "
                                    "with it")
        problem = _problem_from_file(f, case)
        method = _spec(case).method
        check_method(method, problem)
        pts = np.asarray(a["x_starts"], dtype=float)
        for k in range(n):
            g = f.get(_start_group(k))
            if g is not None and bool(g.attrs.get("finished", False)) and "x_opt" in g.attrs:
                done[k] = _outcome_from_file(f, k)
                continue
            h = g.get("history") if g is not None else None
            if h is not None and h["x"].shape[0] > 0:
                jobs.append(StartJob(k, case.text, case.source, problem, h["x"][-1], maxiter, ftol,
                                     iteration0=int(h["iteration"][-1]), segment=int(h["segment"][-1]) + 1,
                                     elapsed0=float(h["elapsed"][-1]), resume=True, method=method))
            else:
                jobs.append(StartJob(k, case.text, case.source, problem, pts[k], maxiter, ftol, method=method))
    return problem, pts, jobs, done


def _finalize(path: Path, case: Case, problem: ScaledProblem, outs: list[StartOutcome]) -> OptimizationResult:
    """Summary table, the best design's time histories, final status."""
    def rank(o: StartOutcome) -> tuple[int, float, float]:
        ok = np.isfinite(o.f)
        return (0 if o.feasible else 1 if ok else 2, o.f if o.feasible else o.max_violation,
                o.f if ok else np.inf)
    best = min(range(len(outs)), key=lambda i: rank(outs[i]))
    res = OptimizationResult(path, problem, outs, outs[best].index)
    res.best = best
    b = outs[best]
    with h5py.File(path, "a") as f:
        if "optimization/summary" in f:
            del f["optimization/summary"]
        s = f.create_group("optimization/summary")
        s.create_dataset("start", data=np.array([o.index for o in outs]))
        s.create_dataset("x", data=np.array([o.x for o in outs], dtype=float))
        s.create_dataset("f", data=np.array([o.f for o in outs], dtype=float))
        s.create_dataset("max_violation", data=np.array([o.max_violation for o in outs], dtype=float))
        s.create_dataset("success", data=np.array([o.success for o in outs]))
        s.create_dataset("feasible", data=np.array([o.feasible for o in outs]))
        s.create_dataset("nit", data=np.array([o.nit for o in outs]))
        s.create_dataset("n_sim", data=np.array([o.n_sim for o in outs]))
        s.create_dataset("message", data=np.array([o.message for o in outs], dtype=h5py.string_dtype()))
        s.attrs["best"] = b.index
        removed = removed_members(problem.names, np.asarray(b.x, dtype=float), problem.lower, problem.upper)
        if removed:     # per design family, the members of the best design at their lower bound
            r = s.create_group("removed")
            for family, members in removed.items():
                r.create_dataset(family, data=np.array(members, dtype=object), dtype=h5py.string_dtype())
        f.flush()
    if np.isfinite(b.f):
        _store_optimum(path, case, b.x)
    status = "converged" if b.success else "failed"
    msg = (f"start {b.index}: {b.message}; " + ("feasible" if b.feasible else
                                                  f"infeasible (max violation {b.max_violation:.3g})"))
    set_status(path, status, msg)
    return res
