"""The HDF5 result file: the only module that writes or reads it.

Layout (a contract; see the README):

* root attributes ``dynsens_version``, ``created`` (ISO 8601 UTC), ``case`` (YAML text),
  ``case_source``, ``status``, ``message``;
* ``/time`` (N,) s;
* ``/state/{q,qd,qdd,lam,p,pd}`` (N, n) — only the requested histories;
* ``/sensitivity/{...}`` (N, n, m) — only with ``output.sensitivity_history``;
* ``/monitors/<name>`` (N,) — per-step diagnostics such as constraint drift;
* ``/design/names``, ``/design/values`` (m,), ``/design/lower``, ``/design/upper``;
* ``/responses/<name>/value`` () and ``/responses/<name>/gradient`` (m,), attributes
  ``unit`` and ``missing`` (empty when present); a KS response also carries ``sampled_max``
  (or ``sampled_min``), ``samples``, ``ks_gap_bound`` = ln(N)/rho and, when that bound is
  more than a few percent of the value, ``warning``;
* ``/stats`` attributes: steps, newton_iterations, factorizations, residual_evaluations,
  ..., wall_time_s.

Files are written to a temporary file in the same folder and renamed into place, so a
crash never leaves a complete-looking file behind.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterator

import h5py
import numpy as np

from .. import __version__
from ..errors import DynsensError


class OutputExistsError(DynsensError, FileExistsError):
    """The output file exists and ``--overwrite`` was not given."""


@contextlib.contextmanager
def atomic_h5(path: str | Path, overwrite: bool = False) -> Iterator[h5py.File]:
    """Open a temporary HDF5 file next to ``path``; rename it into place on success."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path} exists: pass --overwrite to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


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


def write_design(f: h5py.File, names: tuple[str, ...], values: np.ndarray,
                 lower: np.ndarray | None = None, upper: np.ndarray | None = None) -> None:
    """``/design`` group."""
    g = f.create_group("design")
    g.create_dataset("names", data=np.array(names, dtype=h5py.string_dtype()))
    g.create_dataset("values", data=np.real(values))
    if lower is not None and upper is not None:
        g.create_dataset("lower", data=lower)
        g.create_dataset("upper", data=upper)


def write_result(path: str | Path, result: Any, case: Any, overwrite: bool = False) -> None:
    """Write one simulation result (a :class:`~dynsens.march.RunResult`) atomically."""
    missing = [n for n, r in result.responses.items() if r.missing]
    status = result.status if not missing else f"{result.status}; missing responses: {', '.join(missing)}"
    with atomic_h5(path, overwrite) as f:
        write_header(f, case.text, case.source, status, result.message)
        f.create_dataset("time", data=result.time)
        if result.history:
            g = f.create_group("state")
            for k, v in result.history.items():
                g.create_dataset(k, data=v, compression="gzip" if v.size > 10000 else None)
            g.attrs["q_labels"] = np.array(result.labels.get("q", []), dtype=h5py.string_dtype())
        if result.sensitivity_history:
            g = f.create_group("sensitivity")
            for k, v in result.sensitivity_history.items():
                g.create_dataset(k, data=v, compression="gzip" if v.size > 10000 else None)
        if result.monitors:
            g = f.create_group("monitors")
            for k, v in result.monitors.items():
                g.create_dataset(k, data=v)
        write_design(f, case.design_names, result.x, case.lower, case.upper)
        write_responses(f.create_group("responses"), result.responses)
        st = f.create_group("stats")
        for k, v in result.counters.items():
            st.attrs[k] = v
        st.attrs["wall_time_s"] = result.wall_time


def write_responses(g: h5py.Group, responses: dict[str, Any]) -> None:
    """``/responses/<name>/{value, gradient}`` with ``unit`` and ``missing`` attributes."""
    for name, r in responses.items():
        rg = g.create_group(name)
        rg.create_dataset("value", data=float(np.real(r.value)))
        if r.gradient is not None:
            rg.create_dataset("gradient", data=np.real(r.gradient))
        rg.attrs["unit"] = r.unit
        rg.attrs["missing"] = r.missing or ""
        for key, v in r.extra.items():   # e.g. a KS value's sampled maximum and warning
            rg.attrs[key] = v


def read_result(path: str | Path) -> dict[str, Any]:
    """Read a result file into plain Python/numpy objects (for scripts and tests)."""
    out: dict[str, Any] = {}
    with h5py.File(path, "r") as f:
        out["attrs"] = dict(f.attrs)
        out["time"] = f["time"][()] if "time" in f else None
        for grp in ("state", "sensitivity", "monitors"):
            if grp in f:
                out[grp] = {k: v[()] for k, v in f[grp].items()}
        out["design"] = {k: v[()] for k, v in f["design"].items()} if "design" in f else {}
        if "names" in out["design"]:
            out["design"]["names"] = [n.decode() if isinstance(n, bytes) else n for n in out["design"]["names"]]
        out["responses"] = {}
        if "responses" in f:
            for name, rg in f["responses"].items():
                out["responses"][name] = {
                    "value": rg["value"][()], "gradient": rg["gradient"][()] if "gradient" in rg else None,
                    "unit": rg.attrs.get("unit", ""), "missing": rg.attrs.get("missing", "")}
        out["stats"] = dict(f["stats"].attrs) if "stats" in f else {}
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
        g = f.require_group(group)
        for k, v in rows.items():
            v = np.asarray(v)
            if k not in g:
                g.create_dataset(k, data=v[None], maxshape=(None,) + v.shape, chunks=True)
            else:
                ds = g[k]
                ds.resize(ds.shape[0] + 1, axis=0)
                ds[-1] = v
        f.flush()
