"""Time series of one run in an HDF5 group, readable by netCDF tools (xarray, h5netcdf).

Every array hangs on named dimensions: HDF5 dimension scales (the netCDF-4 convention) for
``time`` (s), ``dof`` (the coordinate labels), ``multiplier``, ``pressure``,
``design_variable`` (the design names) and ``<name>_component`` for a recorded quantity with
several components.  Arrays carry ``units`` and ``long_name`` attributes where the case gives
them.  The scales sit in the group itself, so a child group (``state``, ``sensitivity``,
``monitors``, ``quantity_gradients``) sees them as netCDF sees a parent's dimensions.
"""
from __future__ import annotations

from typing import Any, Sequence

import h5py
import numpy as np

from ..timeloop.records import RecordedQuantity

# the dimension of each state field's second axis
STATE_DIMS = {"q": "dof", "qd": "dof", "qdd": "dof", "lam": "multiplier", "p": "pressure", "pd": "pressure"}
_TEXT = h5py.string_dtype()


def _gzip(v: np.ndarray) -> str | None:
    return "gzip" if v.size > 10000 else None


def make_scale(g: h5py.Group, name: str, values: Sequence[Any] | np.ndarray, units: str = "") -> h5py.Dataset:
    """A dimension scale ``g/name`` (a netCDF coordinate variable)."""
    arr = np.asarray(values)
    ds = g.create_dataset(name, data=arr.astype(_TEXT) if arr.dtype.kind in "USO" else arr)
    ds.make_scale(name)
    if units:
        ds.attrs["units"] = units
    return ds


def attach(ds: h5py.Dataset, *scales: h5py.Dataset) -> h5py.Dataset:
    """Hang the axes of ``ds`` on ``scales``, in order."""
    for axis, sc in enumerate(scales):
        ds.dims[axis].attach_scale(sc)
    return ds


def _describe(ds: h5py.Dataset, units: str, long_name: str) -> None:
    if units:
        ds.attrs["units"] = units
    if long_name:
        ds.attrs["long_name"] = long_name


def write_series(g: h5py.Group, result: Any, design_names: Sequence[str]) -> None:
    """``time``, state and sensitivity histories, monitors and recorded quantities of ``result``
    (a :class:`~dynsens.simulation.SimulationResult` or RunResult) into group ``g``."""
    time = make_scale(g, "time", np.real(result.time), "s")
    time.attrs["long_name"] = "time"
    n = len(result.time)
    scales: dict[str, h5py.Dataset] = {}

    def scale(dim: str, size: int, labels: Sequence[str] | None = None) -> h5py.Dataset:
        if dim not in scales:
            scales[dim] = make_scale(g, dim, list(labels) if labels is not None and len(labels) == size
                                     else np.arange(size))
        return scales[dim]

    m = len(design_names)
    if m:
        scale("design_variable", m, design_names)
    if result.history:
        st = g.create_group("state")
        for k, v in result.history.items():
            ds = st.create_dataset(k, data=v, compression=_gzip(v))
            attach(ds, time, scale(STATE_DIMS[k], v.shape[1], result.labels.get("q") if STATE_DIMS[k] == "dof"
                                   else None))
        st.attrs["q_labels"] = np.array(result.labels.get("q", []), dtype=_TEXT)
    if result.sensitivity_history:
        sg = g.create_group("sensitivity")
        for k, v in result.sensitivity_history.items():
            ds = sg.create_dataset(k, data=v, compression=_gzip(v))
            attach(ds, time, scale(STATE_DIMS[k], v.shape[1], result.labels.get("q") if STATE_DIMS[k] == "dof"
                                   else None), scales["design_variable"])
    if result.monitors:
        mg = g.create_group("monitors")
        for k, v in result.monitors.items():
            attach(mg.create_dataset(k, data=v), time)
    quantities: dict[str, RecordedQuantity] = getattr(result, "quantities", {}) or {}
    g.attrs["quantities"] = np.array(list(quantities), dtype=_TEXT)   # the case's order
    for name, rq in quantities.items():
        if len(rq.value) != n:    # cannot happen: the recorder sees every grid step
            raise ValueError(f"recorded quantity {name} has {len(rq.value)} instants, the run {n}")
        dims = [time] + ([scale(f"{name}_component", len(rq.components), rq.components)] if rq.components else [])
        ds = attach(g.create_dataset(name, data=rq.value, compression=_gzip(rq.value)), *dims)
        _describe(ds, rq.unit, rq.label)
        if rq.gradient is not None:
            qg = g.require_group("quantity_gradients")
            gd = attach(qg.create_dataset(name, data=rq.gradient, compression=_gzip(rq.gradient)),
                        *dims, scales["design_variable"])
            _describe(gd, f"{rq.unit} per unit of the design variable" if rq.unit else "",
                      f"d({rq.label})/dx")


def read_series(g: h5py.Group) -> dict[str, Any]:
    """The arrays :func:`write_series` wrote into ``g`` (plain numpy, strings decoded)."""
    out: dict[str, Any] = {"time": g["time"][()] if "time" in g else None, "quantities": {},
                           "quantity_gradients": {}, "units": {}, "labels": {}, "components": {}}
    for grp in ("state", "sensitivity", "monitors"):
        if grp in g:
            out[grp] = {k: v[()] for k, v in g[grp].items()}
    out["dof_labels"] = decode(g["state"].attrs.get("q_labels", [])) if "state" in g else []
    order = decode(g.attrs.get("quantities", []))
    for k in order + sorted(set(g) - set(order)):
        v = g[k]
        if not isinstance(v, h5py.Dataset) or v.is_scale or v.ndim == 0 or not on_time(v):
            continue
        out["quantities"][k] = v[()]
        out["units"][k] = str(v.attrs.get("units", ""))
        out["labels"][k] = str(v.attrs.get("long_name", k))
        if v.ndim == 2 and f"{k}_component" in g:
            out["components"][k] = decode(g[f"{k}_component"][()])
    if "quantity_gradients" in g:
        out["quantity_gradients"] = {k: v[()] for k, v in g["quantity_gradients"].items()}
    return out


def on_time(ds: h5py.Dataset) -> bool:
    """Whether the first axis of ``ds`` hangs on a ``time`` scale."""
    return any(sc.name.rsplit("/", 1)[-1] == "time" for sc in ds.dims[0].values())


def decode(values: Any) -> list[str]:
    """Strings of an HDF5 text array."""
    return [v.decode() if isinstance(v, bytes) else str(v) for v in values]
