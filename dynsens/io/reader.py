"""``dynsens.read_result``: a simulation file as arrays, a pandas DataFrame or an xarray Dataset.

pandas and xarray are optional (``pip install 'dynsens[data]'``); the arrays need neither.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DynsensError
from .hdf5 import read_result_dict
from .series import STATE_DIMS

TABLES = ("quantities", "state", "monitors")


class MissingExtraError(DynsensError, ImportError):
    """An optional package (pandas, xarray) is needed for this call."""


def _need(module: str) -> Any:
    try:
        return __import__(module)
    except ImportError:
        raise MissingExtraError(f"this needs {module}: pip install {module} "
                                "(or pip install 'dynsens[data]')") from None


@dataclass
class Result:
    """The contents of a simulation result file (see docs/outputs.md, "Output files").

    time : (N,) s.  quantities[name] : (N,) or (N, k) recorded quantities, with ``units``,
    ``labels`` (long names) and ``components`` (labels of k components) by name;
    quantity_gradients[name] : (N, [k,] m).  state[field], sensitivity[field] : (N, n[, m]).
    monitors[name] : (N,).  design : names, values, lower, upper.  responses[name] : value,
    gradient, unit, missing.  stats : run statistics.  attrs : the file's root attributes.
    """

    path: Path
    time: np.ndarray
    quantities: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    labels: dict[str, str] = field(default_factory=dict)
    components: dict[str, list[str]] = field(default_factory=dict)
    quantity_gradients: dict[str, np.ndarray] = field(default_factory=dict)
    state: dict[str, np.ndarray] = field(default_factory=dict)
    sensitivity: dict[str, np.ndarray] = field(default_factory=dict)
    monitors: dict[str, np.ndarray] = field(default_factory=dict)
    design: dict[str, Any] = field(default_factory=dict)
    responses: dict[str, dict[str, Any]] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    attrs: dict[str, Any] = field(default_factory=dict)
    dof_labels: list[str] = field(default_factory=list)

    @property
    def status(self) -> str:
        """``completed`` or ``terminated`` (ended by an event), with missing responses named."""
        return str(self.attrs.get("status", ""))

    @property
    def design_names(self) -> list[str]:
        """Names of the design variables (m,)."""
        return list(self.design.get("names", []))


    def _columns(self, table: str) -> dict[str, tuple[np.ndarray, str, str]]:
        """name -> ((N,) values, unit, label) of one table, components spread into columns."""
        cols: dict[str, tuple[np.ndarray, str, str]] = {}
        if table == "quantities":
            for name, v in self.quantities.items():
                unit, label = self.units.get(name, ""), self.labels.get(name, name)
                if v.ndim == 1:
                    cols[name] = (v, unit, label)
                else:
                    comps = self.components.get(name) or [str(j) for j in range(v.shape[1])]
                    for j, c in enumerate(comps):
                        cols[f"{name}[{c}]"] = (v[:, j], unit, f"{label} {c}")
        elif table == "state":
            for fld, v in self.state.items():
                labels = self.dof_labels if STATE_DIMS[fld] == "dof" and len(self.dof_labels) == v.shape[1] \
                    else [str(j) for j in range(v.shape[1])]
                for j, lb in enumerate(labels):
                    cols[f"{fld}[{lb}]"] = (v[:, j], "", f"{fld} {lb}")
        elif table == "monitors":
            cols = {k: (v, "", k) for k, v in self.monitors.items()}
        else:
            raise ValueError(f"table must be one of {TABLES}, found {table!r}")
        return cols

    def to_dataframe(self, table: str = "quantities") -> Any:
        """A pandas DataFrame indexed by time (s): the recorded quantities (default), the state
        histories (``"state"``, one column per coordinate) or the monitors (``"monitors"``);
        ``df.attrs["units"]`` maps columns to units."""
        pd = _need("pandas")
        cols = self._columns(table)
        df = pd.DataFrame({k: v for k, (v, _, _) in cols.items()},
                          index=pd.Index(self.time, name="time"))
        df.attrs["units"] = {k: u for k, (_, u, _) in cols.items()}
        df.attrs["labels"] = {k: lb for k, (_, _, lb) in cols.items()}
        return df

    def to_xarray(self) -> Any:
        """An xarray Dataset on a ``time`` coordinate (s): the recorded quantities (components
        on ``<name>_component``), their gradients as ``d_<name>`` on ``design_variable``, the
        monitors and the state histories (``state_q`` ... on ``dof``), with units attributes."""
        xr = _need("xarray")
        coords: dict[str, Any] = {"time": ("time", self.time, {"units": "s", "long_name": "time"})}
        if self.design_names:
            coords["design_variable"] = self.design_names
        data: dict[str, Any] = {}
        for name, v in self.quantities.items():
            attrs = {"units": self.units.get(name, ""), "long_name": self.labels.get(name, name)}
            dims: tuple[str, ...] = ("time",)
            if v.ndim == 2:
                dims += (f"{name}_component",)
                coords[f"{name}_component"] = self.components.get(name) or list(range(v.shape[1]))
            data[name] = (dims, v, attrs)
            if name in self.quantity_gradients:
                data[f"d_{name}"] = (dims + ("design_variable",), self.quantity_gradients[name],
                                     {"long_name": f"d({attrs['long_name']})/dx"})
        for k, v in self.monitors.items():
            data[f"monitor_{k}"] = (("time",), v, {})
        for fld, v in self.state.items():
            dim = STATE_DIMS[fld]
            if dim == "dof" and len(self.dof_labels) == v.shape[1]:
                coords["dof"] = self.dof_labels
            else:   # multipliers and pressures are numbered in the file: label them by index
                coords.setdefault(dim, list(range(v.shape[1])))
            data[f"state_{fld}"] = (("time", dim), v, {})
        attrs = {k: (v if not isinstance(v, bytes) else v.decode()) for k, v in self.attrs.items()
                 if k in ("status", "message", "case_source", "dynsens_version", "created")}
        return xr.Dataset(data, coords=coords, attrs=attrs)


def read_result(path: str | Path, group: str = "/") -> Result:
    """Read a ``dynsens simulate`` result file (HDF5) into a `Result`; with
    ``group="optimization/optimum"`` (or ``"optimization/initial"``) the run an optimization
    file stores for its best (or start) design."""
    path = Path(path)
    if not path.exists():
        raise DynsensError(f"file not found: {path}")
    d = read_result_dict(path, group)
    return Result(path=path, time=d["time"], quantities=d["quantities"], units=d["units"],
                  labels=d["labels"], components=d["components"],
                  quantity_gradients=d["quantity_gradients"], state=d.get("state", {}),
                  sensitivity=d.get("sensitivity", {}), monitors=d.get("monitors", {}), design=d["design"],
                  responses=d["responses"], stats=d["stats"], attrs=d["attrs"], dof_labels=d["dof_labels"])
