"""The HDF5 result file: the only module that writes or reads it.

Layout (a contract; see docs/outputs.md):

* root attributes ``dynsens_version``, ``created`` (ISO 8601 UTC), ``case`` (YAML text),
  ``case_source``, ``status``, ``message``, and what produced the file: ``provenance_versions``
  (JSON), ``provenance_git``, ``provenance_command``, ``provenance_host``,
  ``provenance_timezone``, ``case_sha256`` (:mod:`dynsens.io.provenance`);
* ``/time`` (N,) s, a dimension scale, like ``/dof``, ``/multiplier``, ``/pressure``,
  ``/design_variable`` and ``/<quantity>_component`` (see :mod:`dynsens.io.series`);
* ``/<quantity>`` (N,) or (N, k): the recorded quantities (``output.quantities``), attributes
  ``units`` and ``long_name``; ``/quantity_gradients/<quantity>`` (N, [k,] m) on request;
* ``/state/{q,qd,qdd,lam,p,pd}`` (N, n) — only the requested histories;
* ``/sensitivity/{...}`` (N, n, m) — only with ``output.sensitivity_history``;
* ``/monitors/<name>`` (N,) — per-step diagnostics such as constraint drift;
* ``/design/names``, ``/design/values`` (m,), ``/design/lower``, ``/design/upper``;
* ``/responses/<name>/value`` () and ``/responses/<name>/gradient`` (m,), attributes
  ``unit`` (and ``units``, the netCDF name) and ``missing`` (empty when present); a KS response
  also carries ``sampled_max`` (or ``sampled_min``), ``samples``, ``ks_gap_bound`` = ln(N)/rho
  and, when that bound is more than a few percent of the value, ``warning``;
* ``/stats`` attributes: steps, newton_iterations, factorizations, residual_evaluations,
  ..., wall_time_s; with sensitivities also ``derivative_method`` (direct | adjoint) and
  ``derivative_method_reason``.

Files are written to a temporary file in the same folder and renamed into place, so a
crash never leaves a complete-looking file behind.
"""
from __future__ import annotations

import contextlib
import json
import datetime as _dt
from pathlib import Path
from typing import Any, Callable, Iterator

import h5py
import numpy as np

from .. import __version__
from ..errors import DynsensError
from .paths import OutputExistsError, atomic_path  # noqa: F401  (OutputExistsError: re-exported)
from .provenance import provenance
from .series import attach, decode, read_series, write_series


@contextlib.contextmanager
def atomic_h5(path: str | Path, overwrite: bool = False) -> Iterator[h5py.File]:
    """Open a temporary HDF5 file next to ``path``; rename it into place on success (with the
    umask's permissions), remove it on any failure or interruption."""
    with atomic_path(path, overwrite) as tmp:
        with h5py.File(tmp, "w") as f:
            yield f


def _real(v: Any) -> Any:
    return np.real(v) if v is not None else v


def write_header(f: h5py.File, case_text: str, case_source: str, status: str, message: str) -> None:
    """Root attributes common to every dynsens file."""
    f.attrs["dynsens_version"] = __version__
    f.attrs["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    f.attrs["case"] = case_text
    f.attrs["case_source"] = case_source
    f.attrs["status"] = status
    f.attrs["message"] = message
    f.attrs.update(provenance(case_text))


def write_design(f: h5py.File, names: tuple[str, ...], values: np.ndarray,
                 lower: np.ndarray | None = None, upper: np.ndarray | None = None) -> None:
    """``/design`` group."""
    g = f.create_group("design")
    g.create_dataset("names", data=np.array(names, dtype=h5py.string_dtype()))
    g.create_dataset("values", data=np.real(values))
    if lower is not None and upper is not None:
        g.create_dataset("lower", data=lower)
        g.create_dataset("upper", data=upper)
    if names and "design_variable" in f:
        for k in ("names", "values", "lower", "upper"):
            if k in g:
                attach(g[k], f["design_variable"])


def _status(result: Any) -> str:
    missing = [n for n, r in result.responses.items() if r.missing]
    return result.status if not missing else f"{result.status}; missing responses: {', '.join(missing)}"


def write_result(path: str | Path, result: Any, case: Any, overwrite: bool = False) -> None:
    """Write one simulation result (a :class:`~dynsens.timeloop.march.RunResult`) atomically."""
    with atomic_h5(path, overwrite) as f:
        write_header(f, case.text, case.source, _status(result), result.message)
        write_series(f, result, case.design_names)
        write_design(f, case.design_names, result.x, case.lower, case.upper)
        _write_run(f, result, case)


def _write_run(g: h5py.Group, result: Any, case: Any) -> None:
    """``responses``, ``stats`` and the redundant joint equations of one run into group ``g``."""
    write_responses(g.create_group("responses"), result.responses)
    st = g.create_group("stats")
    for k, v in result.counters.items():
        st.attrs[k] = v
    st.attrs["wall_time_s"] = result.wall_time
    dropped = redundant_equations(case.model)
    if dropped:
        g.attrs["redundant_equations"] = json.dumps(dropped)
        g.attrs["dependent_joints"] = json.dumps(list(getattr(case.model, "dependent_joints", [])))
    if getattr(result, "method", ""):
        st.attrs["derivative_method"] = result.method
        st.attrs["derivative_method_reason"] = result.method_reason


def write_load_case_results(path: str | Path, results: dict[str, Any], cases: Any,
                            overwrite: bool = False) -> None:
    """Write the runs of a case's load cases (a `~dynsens.case.load_cases.LoadCaseSet`) atomically:
    the root has the header and ``/design``; each load case's run has the usual layout (time
    histories, ``responses``, ``stats``) under ``/load_cases/<name>``, with its ``status`` and
    ``message`` as attributes.  The root ``status`` is the load cases' common status, or each
    load case's (``impact: completed; gust: terminated``)."""
    statuses = {n: _status(r) for n, r in results.items()}
    common = set(statuses.values())
    first = next(iter(cases.cases.values()))
    with atomic_h5(path, overwrite) as f:
        write_header(f, cases.text, cases.source, common.pop() if len(common) == 1 else
                     "; ".join(f"{n}: {s}" for n, s in statuses.items()),
                     f"{len(results)} load cases")
        f.attrs["load_cases"] = json.dumps(list(results))
        write_design(f, first.design_names, next(iter(results.values())).x, first.lower, first.upper)
        top = f.create_group("load_cases")
        for name, result in results.items():
            g = top.create_group(name)
            g.attrs["status"] = statuses[name]
            g.attrs["message"] = result.message
            g.attrs["case"] = cases.cases[name].text
            write_series(g, result, first.design_names)
            _write_run(g, result, cases.cases[name])


def redundant_equations(model: Any) -> list[str]:
    """``JOINT.EQUATION`` of the joint equations a multibody model left out as redundant (empty
    for any other model)."""
    return [f"{joint}.{label}" for joint, label, _ in getattr(model, "redundant", None) or []]


def write_responses(g: h5py.Group, responses: dict[str, Any]) -> None:
    """``/responses/<name>/{value, gradient}`` with ``unit`` and ``missing`` attributes."""
    for name, r in responses.items():
        rg = g.create_group(name)
        rg.create_dataset("value", data=float(np.real(r.value)))
        if r.gradient is not None:
            gd = rg.create_dataset("gradient", data=np.real(r.gradient))
            run = g.parent     # the run's group holds its design_variable scale
            if "design_variable" in run and len(gd) == len(run["design_variable"]):
                attach(gd, run["design_variable"])
        rg.attrs["unit"] = r.unit
        rg.attrs["units"] = r.unit
        rg.attrs["missing"] = r.missing or ""
        for key, v in r.extra.items():   # e.g. a KS value's sampled maximum and warning
            rg.attrs[key] = v


def read_result_dict(path: str | Path, group: str = "/") -> dict[str, Any]:
    """Read a result file into plain Python/numpy objects (behind :func:`dynsens.read_result`);
    ``group`` names a run stored inside an optimization file (``optimization/optimum``)."""
    with h5py.File(path, "r") as f:
        if group not in f:
            raise DynsensError(f"{path} has no group {group!r}")
        g = f[group]
        out: dict[str, Any] = read_series(g)
        out["attrs"] = {**dict(f.attrs), **dict(g.attrs)}
        out["design"] = {k: v[()] for k, v in f["design"].items()} if "design" in f else {}
        if "names" in out["design"]:
            out["design"]["names"] = decode(out["design"]["names"])
        out["responses"] = {}
        rs = g["responses"] if "responses" in g else f.get("responses")
        if g.name != "/" and "responses" in g and not len(rs):   # a stored run: values as attributes
            out["responses"] = {n: {"value": v, "gradient": None, "unit": "", "missing": ""}
                                for n, v in rs.attrs.items()}
        elif rs is not None:      # the file's run, or a load case's (/load_cases/<name>)
            for name, rg in rs.items():
                out["responses"][name] = {
                    "value": rg["value"][()], "gradient": rg["gradient"][()] if "gradient" in rg else None,
                    "unit": rg.attrs.get("unit", ""), "missing": rg.attrs.get("missing", "")}
        st = g["stats"] if "stats" in g else f.get("stats")
        out["stats"] = dict(st.attrs) if st is not None else {}
    return out


def append_rows(path: str | Path, group: str, rows: dict[str, np.ndarray],
                init: Callable[[h5py.File], None] | None = None) -> None:
    """Append one row to each dataset of ``group`` (resizable along axis 0), flushing at once.

    Used for histories that must survive an interruption (optimization).  The first call
    creates the file through ``init`` (written atomically); later calls extend it in place.
    """
    path = Path(path)
    if not path.exists():
        with atomic_h5(path) as f:
            if init is not None:
                init(f)
    with h5py.File(path, "a") as f:
        append_row(f.require_group(group), rows)
        f.flush()


def append_row(g: h5py.Group, row: dict[str, Any]) -> None:
    """Append ``row`` (name -> value) to the resizable datasets of ``g``, creating them on first use."""
    for k, v in row.items():
        v = np.asarray(v)
        if k not in g:
            g.create_dataset(k, data=v[None], maxshape=(None,) + v.shape, chunks=True)
        else:
            ds = g[k]
            ds.resize(ds.shape[0] + 1, axis=0)
            ds[-1] = v


