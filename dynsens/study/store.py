"""The study file: planned designs, one row appended per finished design, and reading it back.

Only the calling process writes.  Every change (a row, the status) is made to a copy of the
file that then replaces it (``os.replace``), so the file on disk is always a complete study:
a kill, even in the middle of writing, loses only the designs in flight.  The copy costs
little: a study file holds no time histories.
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import h5py
import numpy as np

from ..case.load import Case
from ..io.hdf5 import append_row as append_h5_row
from ..io.hdf5 import atomic_h5, write_design, write_header
from .sampling import StudyError

ROWS = "study/rows"


def _str(v: str) -> np.ndarray:
    return np.array(v, dtype=h5py.string_dtype())


def _text(v: Any) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def create_study_file(path: Path, case: Case, designs: np.ndarray, sample: str, seed: int | None,
                      gradients: bool, overwrite: bool) -> None:
    """Write the header, the design bounds and the planned designs (atomically)."""
    units = {n: "" for n in case.response_names}
    with atomic_h5(path, overwrite) as f:
        write_header(f, case.text, case.source, "running", "")
        write_design(f, case.design_names, case.x0, case.lower, case.upper)
        g = f.create_group("study")
        g.create_dataset("designs", data=np.asarray(designs, dtype=float))
        g.attrs.update({"sample": sample, "seed": -1 if seed is None else int(seed), "gradients": bool(gradients),
                        "n_designs": int(len(designs)), "response_names": json.dumps(list(case.response_names)),
                        "response_units": json.dumps(units), "runs": 1})


@contextlib.contextmanager
def _updated(path: Path) -> Iterator[h5py.File]:
    """Change a copy of ``path``; the copy replaces ``path`` only when the change is complete."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        shutil.copyfile(path, tmp)
        shutil.copymode(path, tmp)      # mkstemp made it 0600: keep the file's own permissions
        with h5py.File(tmp, "a") as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def set_response_units(path: Path, units: dict[str, str]) -> None:
    """Units of the responses (known once the first design has run)."""
    with _updated(path) as f:
        f["study"].attrs["response_units"] = json.dumps(units)


def append_row(path: Path, row: dict[str, Any]) -> None:
    """Append one finished design (see :func:`dynsens.study.runner.evaluate_design`)."""
    data = {k: (_str(v) if isinstance(v, str) else np.asarray(v)) for k, v in row.items()
            if k != "units" and v is not None}
    with _updated(path) as f:
        append_h5_row(f.require_group(ROWS), data)


def set_status(path: Path, status: str, message: str) -> None:
    """Root ``status``/``message``: running, completed or interrupted."""
    with _updated(path) as f:
        f.attrs["status"] = status
        f.attrs["message"] = message


def _n_rows(g: h5py.Group | None) -> int:
    return 0 if g is None or "index" not in g else int(g["index"].shape[0])


def prepare_resume(path: Path, case: Case, sample: str | None, seed: int | None,
                   gradients: bool) -> tuple[np.ndarray, set[int], int, str, int | None]:
    """Check that ``path`` continues this study and count this run.

    Returns the planned designs, the indices already done, the number of this run
    (0 for the first), the sample specification and the seed.
    """
    if not path.exists():
        raise StudyError(f"--resume: {path} does not exist (run without --resume to start)")
    try:
        h5py.File(path, "r").close()
    except OSError as exc:
        raise StudyError(f"--resume: cannot open {path}: {exc}") from None
    with _updated(path) as f:
        if "study" not in f or "designs" not in f["study"]:
            raise StudyError(f"--resume: {path} is not a dynsens study file")
        if _text(f.attrs.get("case", "")) != case.text:
            raise StudyError(f"--resume: {path} was made from a different case (or other --set options): "
                             "give the same case file and --set options")
        a = f["study"].attrs
        stored = _text(a["sample"])
        if sample is not None and sample != stored:
            raise StudyError(f"--resume: {path} was sampled with --sample {stored}; found --sample {sample}")
        s = int(a["seed"])
        if seed is not None and seed != s:
            raise StudyError(f"--resume: {path} used --seed {s}; --seed cannot change it")
        if bool(a["gradients"]) != gradients:
            was = "with" if bool(a["gradients"]) else "without"
            raise StudyError(f"--resume: {path} was computed {was} --gradients; give the same option")
        g = f.get(ROWS)
        done = set(int(i) for i in g["index"][()]) if _n_rows(g) else set()
        run = int(a.get("runs", 1))
        a["runs"] = run + 1
        designs = f["study/designs"][()]
    return designs, done, run, stored, (None if s < 0 else s)


@dataclass
class StudyTable:
    """A study read back: one entry per finished design, sorted by design index.

    ``x`` (k, m) designs in the case's units; ``values`` (k, n_r) responses (NaN where a
    design failed or a response is missing); ``gradients`` (k, n_r, m) or None;
    ``failed`` (k,) the simulation raised; ``message`` (k,) why it failed or which responses
    are missing (empty otherwise); ``wall_time`` (k,) s; ``run`` (k,) 0 for the first
    invocation, +1 per ``--resume``; ``worker`` (k,) host:pid that computed the row.
    """

    path: Path
    case_source: str
    case_text: str
    status: str
    sample: str
    seed: int | None
    design_names: tuple[str, ...]
    response_names: tuple[str, ...]
    response_units: dict[str, str]
    lower: np.ndarray
    upper: np.ndarray
    designs: np.ndarray
    index: np.ndarray
    x: np.ndarray
    values: np.ndarray
    gradients: np.ndarray | None
    failed: np.ndarray
    message: np.ndarray
    wall_time: np.ndarray
    run: np.ndarray
    worker: np.ndarray

    @property
    def pending(self) -> np.ndarray:
        """Indices of planned designs without a row yet."""
        return np.setdiff1d(np.arange(len(self.designs)), self.index)

    def columns(self) -> dict[str, np.ndarray]:
        """The table as plain columns: design variables, responses, ``d<response>/d<variable>``, status."""
        out: dict[str, np.ndarray] = {"design": self.index}
        for j, n in enumerate(self.design_names):
            out[n] = self.x[:, j]
        for i, n in enumerate(self.response_names):
            out[n] = self.values[:, i]
        if self.gradients is not None:
            for i, r in enumerate(self.response_names):
                for j, n in enumerate(self.design_names):
                    out[f"d{r}/d{n}"] = self.gradients[:, i, j]
        out.update(failed=self.failed, message=self.message, wall_time=self.wall_time, run=self.run,
                   worker=self.worker)
        return out

    def to_dataframe(self) -> Any:
        """A pandas DataFrame indexed by design (needs pandas: ``pip install 'dynsens[study]'``)."""
        try:
            import pandas as pd
        except ImportError:
            raise StudyError("to_dataframe needs pandas: pip install 'dynsens[study]' "
                             "(or use .columns() for plain numpy columns)") from None
        cols = self.columns()
        return pd.DataFrame(cols).set_index("design")


def read_study(path: str | Path) -> StudyTable:
    """Read a study file written by ``dynsens study`` (also while it is still running)."""
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise StudyError(f"cannot read {path}: {exc}") from None
    with f:
        if "study" not in f:
            raise StudyError(f"{path} is not a dynsens study file (no /study group)")
        a = f["study"].attrs
        rnames = tuple(json.loads(_text(a["response_names"])))
        names = tuple(_text(n) for n in f["design/names"][()])
        m, nr = len(names), len(rnames)
        g = f.get(ROWS)
        n = _n_rows(g)

        def col(key: str, shape: tuple[int, ...], dtype: Any = float) -> np.ndarray:
            if g is None or key not in g or n == 0:
                return np.zeros((0,) + shape, dtype=dtype)
            return g[key][:n]
        index = col("index", (), int).astype(int)
        order = np.argsort(index, kind="stable")
        grads = col("gradients", (nr, m)) if bool(a["gradients"]) else None
        table = StudyTable(
            path=path, case_source=_text(f.attrs.get("case_source", "")), case_text=_text(f.attrs.get("case", "")),
            status=_text(f.attrs.get("status", "")),
            sample=_text(a["sample"]), seed=None if int(a["seed"]) < 0 else int(a["seed"]),
            design_names=names, response_names=rnames,
            response_units=json.loads(_text(a.get("response_units", "{}"))),
            lower=f["design/lower"][()], upper=f["design/upper"][()], designs=f["study/designs"][()],
            index=index[order], x=col("x", (m,))[order], values=col("values", (nr,))[order],
            gradients=None if grads is None else grads[order], failed=col("failed", (), bool)[order],
            message=np.array([_text(v) for v in col("message", (), object)[order]], dtype=object),
            wall_time=col("wall_time", ())[order], run=col("run", (), int)[order],
            worker=np.array([_text(v) for v in col("worker", (), object)[order]], dtype=object))
    return table
