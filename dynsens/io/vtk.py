"""ParaView output: a result file as a VTU time series with a ``.pvd`` collection (through meshio).

:func:`export_vtk` writes, into a folder ``DIR``, for every run the file stores (one for a
simulation, ``start`` and ``optimum`` for an optimization):

* ``DIR/<stem>.pvd``: the collection ParaView opens (File > Open), one ``DataSet`` per instant
  and part, with its time in seconds;
* ``DIR/<stem>/<stem>_<part>_<k>.vtu``: one unstructured grid per stored instant ``k`` (every
  one, or every ``every``-th and the last) and part (see :mod:`dynsens.io.scene` for the
  parts, points, cells and fields).

The files of a run are written into a temporary folder next to ``DIR/<stem>`` and renamed into
place when all are written; the ``.pvd`` comes last, so an interrupted export never leaves a
collection pointing at missing or stale files.  Existing outputs are replaced only with
``overwrite``.  meshio is an optional dependency (``pip install 'dynsens[vtk]'``).
"""
from __future__ import annotations

import contextlib
import shutil
import tempfile
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from .paths import OutputExistsError, atomic_write_text, check_output_folder, current_umask, safe_stem
from .reader import MissingExtraError
from .scene import Part, Scene, read_scene, stored_runs


def need_meshio() -> Any:
    """The meshio module, or a MissingExtraError naming the extra."""
    try:
        import meshio
    except ImportError:
        raise MissingExtraError("the ParaView output needs meshio: pip install 'dynsens[vtk]'") from None
    return meshio


def run_stem(path: str | Path, label: str) -> str:
    """File stem of one exported run: the result file's stem, with ``_start`` / ``_optimum``
    for the runs of an optimization file."""
    stem = safe_stem(Path(path).stem)
    return f"{stem}_{label}" if label else stem


def vtk_targets(path: str | Path, folder: str | Path, labels: list[str]) -> list[Path]:
    """The ``.pvd`` files and data folders an export of ``labels`` writes into ``folder``."""
    out = []
    for label in labels:
        stem = run_stem(path, label)
        out += [Path(folder) / f"{stem}.pvd", Path(folder) / stem]
    return out


def export_vtk(path: str | Path, folder: str | Path, overwrite: bool = False, every: int = 1) -> list[Path]:
    """Write every run of result file ``path`` as a ParaView time series into ``folder``: every
    ``every``-th stored instant, the last always; returns the ``.pvd`` files.  Raises
    OutputExistsError before writing anything when an output exists and not ``overwrite``."""
    meshio = need_meshio()
    runs = stored_runs(path)
    check_output_folder(folder, vtk_targets(path, folder, list(runs)), overwrite, option="--vtk")
    written = []
    for label, group in runs.items():
        scene = read_scene(path, group, label)
        written.append(write_scene(scene, Path(folder), run_stem(path, label), overwrite, meshio, every))
    return written


def write_scene(scene: Scene, folder: Path, stem: str, overwrite: bool = False, meshio: Any = None,
                every: int = 1) -> Path:
    """``folder/<stem>.pvd`` and ``folder/<stem>/*.vtu`` of one scene (atomically), every
    ``every``-th instant and the last; returns the ``.pvd``."""
    meshio = meshio or need_meshio()
    if not (isinstance(every, int) and every >= 1):
        raise ValueError(f"every: expected an integer >= 1, found {every!r}")
    n = len(scene.time)
    instants = sorted(set(range(0, n, every)) | ({n - 1} if n else set()))
    pvd, data = folder / f"{stem}.pvd", folder / stem
    if not overwrite and (pvd.exists() or data.exists()):
        raise OutputExistsError(f"{pvd if pvd.exists() else data} exists: pass --overwrite to replace it")
    folder.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{stem}.", suffix=".tmp", dir=folder))
    entries = []
    try:
        width = len(str(max(n - 1, 0)))
        for k in instants:
            t = scene.time[k]
            for j, part in enumerate(scene.parts):
                name = f"{stem}_{part.name}_{k:0{width}d}.vtu"
                meshio.write(tmp / name, _mesh(meshio, part, k), file_format="vtu")
                entries.append(f'    <DataSet timestep="{float(t)!r}" part="{j}" name={quoteattr(part.name)} '
                               f'file={quoteattr(f"{stem}/{name}")}/>')
        tmp.chmod(0o777 & ~current_umask())   # mkdtemp makes 0700
        if pvd.exists():          # the old collection goes first: it never points at new files
            pvd.unlink()
        if data.exists():
            shutil.rmtree(data)
        tmp.rename(data)
    except BaseException:
        with contextlib.suppress(OSError):
            shutil.rmtree(tmp)
        raise
    text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
            "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n")
    return atomic_write_text(pvd, text, overwrite=True)


def _mesh(meshio: Any, part: Part, k: int) -> Any:
    """The meshio Mesh of ``part`` at instant ``k``: line cells, then vertex cells."""
    blocks = []
    if len(part.lines):
        blocks.append(("line", part.lines))
    if len(part.vertices):
        blocks.append(("vertex", part.vertices.reshape(-1, 1)))
    points = np.ascontiguousarray(part.points[k], dtype=float)
    point_data = {name: np.ascontiguousarray(v[k], dtype=float) for name, v in part.point_data.items()}

    n_lines = len(part.lines)

    def split(v: np.ndarray) -> list[np.ndarray]:
        """One array per cell block (meshio's layout of cell data)."""
        values = np.asarray(v[k], dtype=float)
        return [b for b, size in ((values[:n_lines], n_lines), (values[n_lines:], len(part.vertices))) if size]
    cell_data = {name: split(v) for name, v in part.cell_data.items()}
    return meshio.Mesh(points, blocks, point_data=point_data, cell_data=cell_data)
