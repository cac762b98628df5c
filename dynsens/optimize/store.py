"""The optimization file: rows appended per iteration, start attributes, the stored optimum."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping

import h5py
import numpy as np

from ..case.load import Case
from ..io.hdf5 import append_rows, atomic_h5, write_design, write_header
# one writer per output file: shared with the study (re-exported here, where it began)
from ..io.paths import OutputLockedError, holds_writer_lock, lock_path, writer_lock  # noqa: F401
from ..io.series import make_scale, write_series
from ..simulation import run_case
from .jobs import StartOutcome
from .problem import FEAS_TOL, SIM_ERRORS, ConstraintTerm, OptimizationError, ScaledProblem


# --------------------------------------------------------------------------------------
# the output file (written only by the calling process)
# --------------------------------------------------------------------------------------
def _str(v: str) -> np.ndarray:
    return np.array(v, dtype=h5py.string_dtype())


def _start_group(k: int) -> str:
    return f"optimization/start_{k}"


def _write_row(path: Path, msg: dict[str, Any]) -> None:
    group = f"{_start_group(msg['start'])}/{'history' if msg['kind'] == 'iteration' else 'evaluations'}"
    rows = {}
    for k, v in msg["row"].items():
        if v is None:
            continue
        rows[k] = _str(v) if isinstance(v, str) else np.asarray(v, dtype=float if k not in
                                                                ("iteration", "segment", "n_sim", "failed")
                                                                else None)
    if msg["kind"] == "evaluation":
        rows["failed"] = np.asarray(bool(msg["row"]["failed"]))
    else:
        rows["failed"] = np.asarray(int(msg["row"]["failed"]))
    append_rows(path, group, rows)


def _set_attrs(path: Path, group: str, attrs: Mapping[str, Any]) -> None:
    with h5py.File(path, "a") as f:
        g = f.require_group(group) if group else f
        for k, v in attrs.items():
            g.attrs[k] = v
        f.flush()


def set_status(path: str | Path, status: str, message: str) -> None:
    """Root ``status``/``message`` of an optimization file (e.g. ``interrupted`` after Ctrl-C)."""
    _set_attrs(Path(path), "", {"status": status, "message": message})


def _outcome_attrs(o: StartOutcome) -> dict[str, Any]:
    return {"finished": True, "success": o.success, "status": o.status, "message": o.message, "nit": o.nit,
            "nfev": o.n_sim, "n_failed": o.n_failed, "x_opt": o.x, "f_opt": o.f, "g_opt": o.g,
            "responses_opt": o.responses, "max_violation": o.max_violation, "feasible": o.feasible,
            "wall_time": o.wall_time, "slsqp_nit": o.slsqp_nit}


def _outcome_from_file(f: h5py.File, k: int) -> StartOutcome:
    a = f[_start_group(k)].attrs
    return StartOutcome(k, a["x_start"], a["x_opt"], float(a["f_opt"]), a["g_opt"], a["responses_opt"],
                        float(a["max_violation"]), bool(a["feasible"]), bool(a["success"]), int(a["status"]),
                        str(a["message"]), int(a["nit"]), int(a["nfev"]), int(a["n_failed"]),
                        float(a["wall_time"]), slsqp_nit=int(a.get("slsqp_nit", 0)))


def _init_file(path: Path, case: Case, x_ref: np.ndarray, overwrite: bool) -> None:
    with atomic_h5(path, overwrite) as f:
        write_header(f, case.text, case.source, "running", "")
        if case.design_names:
            make_scale(f, "design_variable", list(case.design_names))
        write_design(f, case.design_names, x_ref, case.lower, case.upper)
        f["design"].create_dataset("x0", data=x_ref)
        opt = f.create_group("optimization")
        # units for summaries and plots (the case's own; empty where it names none)
        opt.attrs["design_units"] = json.dumps(list(case.design_units))
        opt.attrs["response_units"] = json.dumps(case.response_units)


def _problem_attrs(problem: ScaledProblem) -> dict[str, Any]:
    return {"objective": problem.objective, "f_ref": problem.f_ref,
            "constraints": json.dumps([c.__dict__ for c in problem.constraints]),
            "constraint_labels": json.dumps(list(problem.constraint_labels)),
            "response_names": json.dumps(list(problem.response_names)),
            "g_scale": np.array([c.divisor for c in problem.constraints], dtype=float),
            "feas_tol": FEAS_TOL}


def _problem_from_file(f: h5py.File, case: Case) -> ScaledProblem:
    a = f["optimization"].attrs
    terms = tuple(ConstraintTerm(**c) for c in json.loads(a["constraints"]))
    return ScaledProblem(case.design_names, case.lower, case.upper, case.scale, str(a["objective"]),
                         float(a["f_ref"]), terms, tuple(json.loads(a["response_names"])))


def _store_run(path: Path, case: Case, x: np.ndarray, group: str) -> bool:
    """Simulate ``case`` at ``x`` (no sensitivities) and store its time series (time, state
    histories, monitors, recorded quantities, on named dimensions) and response values in
    ``group``; False when the design cannot be simulated."""
    hist = tuple(case.plan.history) or ("q",)
    try:
        r = run_case(case, x, sensitivities=False, history=hist, record=True)
    except SIM_ERRORS:
        return False
    with h5py.File(path, "a") as f:
        if group in f:
            del f[group]
        g = f.create_group(group)
        g.create_dataset("x", data=np.asarray(x, dtype=float))
        write_series(g, r, case.design_names)
        g.attrs["status"], g.attrs["message"] = r.status, getattr(r, "ended_by", r.message)
        g.attrs["events"] = json.dumps(r.events)
        rg = g.create_group("responses")
        for n, rv in r.responses.items():
            rg.attrs[n] = float(np.real(rv.value)) if not rv.missing else np.nan
        f.flush()
    return True


def _store_optimum(path: Path, case: Case, x: np.ndarray) -> None:
    """The best design's run in ``/optimization/optimum`` and the start design's in
    ``/optimization/initial`` (for the start-vs-optimum plots and ``dynsens export``); with load
    cases, each one's in ``/optimization/load_cases/<name>/{optimum, initial}``."""
    from ..case.load_cases import LoadCaseSet
    runs = ({n: (c, f"optimization/load_cases/{n}/") for n, c in case.cases.items()}
            if isinstance(case, LoadCaseSet) else {"": (case, "optimization/")})
    with h5py.File(path, "r") as f:
        x0 = f["design/x0"][()] if "design/x0" in f else None
    for one, prefix in runs.values():
        _store_run(path, one, x, prefix + "optimum")
        if x0 is not None:
            _store_run(path, one, x0, prefix + "initial")


def read_history(path: str | Path, start: int = 0) -> dict[str, np.ndarray]:
    """The per-iteration history of one start as numpy arrays (strings decoded)."""
    with h5py.File(path, "r") as f:
        h = f[f"{_start_group(start)}/history"]
        out = {k: v[()] for k, v in h.items()}
    if "message" in out:
        out["message"] = np.array([m.decode() if isinstance(m, bytes) else m for m in out["message"]], dtype=object)
    return out


# --------------------------------------------------------------------------------------
# --resume: the file must be whole before anything is continued from it
# --------------------------------------------------------------------------------------
_OPT_ATTRS = ("f_ref", "starts", "seed", "x_starts", "objective", "constraints", "response_names")
_HISTORY = ("x", "iteration", "segment", "elapsed")
_FINISHED = ("x_opt", "f_opt", "g_opt", "responses_opt", "max_violation", "feasible", "success", "status",
             "message", "nit", "nfev", "n_failed", "wall_time", "x_start")


def validate_resume_file(path: Path, m: int) -> None:
    """Raise OptimizationError saying plainly what is damaged when the optimization file ``path``
    cannot be continued (unreadable, missing attributes, histories of unequal length, designs
    of the wrong size or not finite).  ``m``: number of design variables of the case."""
    def damaged(what: str) -> OptimizationError:
        return OptimizationError(f"--resume: {path} is damaged: {what}. Start again without --resume "
                                 "(with --overwrite), or restore the file from a copy")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise damaged(f"it cannot be read as HDF5 ({exc})") from None
    try:
        with f:
            if "optimization" not in f:
                return          # not an optimization file at all: the caller says so
            a = f["optimization"].attrs
            if "f_ref" not in a:
                return          # interrupted before its first design: the caller says so
            missing = [k for k in _OPT_ATTRS if k not in a]
            if missing:
                raise damaged(f"optimization attributes {missing} are missing")
            n = int(a["starts"])
            x_starts = np.asarray(a["x_starts"], dtype=float)
            if n < 1 or x_starts.shape != (n, m) or not np.all(np.isfinite(x_starts)):
                raise damaged(f"expected {n} start designs of {m} values, found x_starts of shape "
                              f"{x_starts.shape}")
            for k in range(n):
                g = f.get(_start_group(k))
                if g is None:
                    continue
                if bool(g.attrs.get("finished", False)) and "x_opt" in g.attrs:
                    lost = [key for key in _FINISHED if key not in g.attrs]
                    if lost:
                        raise damaged(f"start {k} is marked finished but lacks {lost}")
                    continue
                h = g.get("history")
                if h is None:
                    continue
                lost = [key for key in _HISTORY if key not in h]
                if lost:
                    raise damaged(f"the history of start {k} lacks {lost}")
                lengths = {key: h[key].shape[0] for key in _HISTORY}
                if len(set(lengths.values())) != 1:
                    raise damaged(f"the history of start {k} has columns of unequal length {lengths}")
                if lengths["x"]:
                    x_last = np.asarray(h["x"][-1], dtype=float)
                    if x_last.shape != (m,) or not np.all(np.isfinite(x_last)):
                        raise damaged(f"the last design of start {k} is {x_last.tolist()}, expected {m} finite "
                                      "values")
            _read_everything(f)
    except OptimizationError:
        raise
    except (OSError, KeyError, ValueError, TypeError, IndexError, RuntimeError) as exc:
        raise damaged(f"reading it failed ({type(exc).__name__}: {exc})") from None


def _read_everything(f: h5py.File) -> None:
    """Read every attribute and dataset of ``f``: garbage anywhere (a torn tail) shows here as an
    error of the HDF5 library, not later while the resumed run writes into the file."""
    def read(_: str, obj: Any) -> None:
        for key in obj.attrs:
            obj.attrs[key]
        if isinstance(obj, h5py.Dataset):
            obj[()]
    read("", f)
    f.visititems(read)
