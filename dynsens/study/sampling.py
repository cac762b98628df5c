"""Designs of a study: ``lhs:N``, ``sobol:N``, ``grid:AxBx…`` or a CSV file, in the case's bounds."""
from __future__ import annotations

import codecs
import csv
import io
import math
from pathlib import Path

import numpy as np

from ..case.load import Case
from ..errors import DynsensError


class StudyError(DynsensError, ValueError):
    """Bad study input: sample specification, CSV file, inconsistent ``--resume``."""


#: most designs a study plans: each is a simulation, and all are held in memory and in the file
MAX_DESIGNS = 10_000_000


def _within_reason(spec: str, n: int) -> None:
    if n > MAX_DESIGNS:
        raise StudyError(f"--sample {spec}: expected at most {MAX_DESIGNS:,} designs (each is a "
                         f"simulation, all held in memory), found {n:,}")


def _finite_bounds(case: Case, spec: str) -> tuple[np.ndarray, np.ndarray]:
    lo, up = case.lower, case.upper
    bad = [n for n, a, b in zip(case.design_names, lo, up) if not (np.isfinite(a) and np.isfinite(b))]
    if bad:
        raise StudyError(f"--sample {spec}: needs finite bounds for every design variable "
                         f"(unbounded in the case: {', '.join(bad)})")
    return lo, up


def _count(spec: str, text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise StudyError(f"--sample {spec}: expected a positive whole number of designs, found {text!r}")
    return n


def _grid(case: Case, spec: str, body: str) -> np.ndarray:
    m = len(case.design_names)
    parts = body.lower().split("x")
    counts = [_count(spec, p) for p in parts]
    if len(counts) == 1:
        counts *= m
    if len(counts) != m:
        raise StudyError(f"--sample {spec}: expected {m} counts (one per design variable: "
                         f"{', '.join(case.design_names)}) or one for all, found {len(counts)}")
    _within_reason(spec, math.prod(counts))
    lo, up = _finite_bounds(case, spec)
    # a count of 1 keeps the variable at the case's value
    axes = [np.array([x0]) if n == 1 else np.linspace(a, b, n)
            for n, a, b, x0 in zip(counts, lo, up, case.x0)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in mesh], axis=1)


def read_designs_csv(case: Case, path: str | Path) -> np.ndarray:
    """Designs from a CSV file with a header of design-variable names (missing columns: the case's x0)."""
    path = Path(path)
    names = case.design_names
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StudyError(f"--sample {path}: cannot read the file ({exc.strerror})") from None
    # UTF-8, or UTF-16 as spreadsheets save it (with a byte-order mark); other encodings refused
    encoding = "utf-16" if data[:2] in (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE) else "utf-8-sig"
    try:
        text = data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise StudyError(f"{path}: expected a UTF-8 text file (or UTF-16 with a byte-order mark), found "
                         f"{data[exc.start:exc.start + 1]!r} at byte {exc.start}, not {exc.encoding}; "
                         "save the file as UTF-8 CSV") from None
    if "\x00" in text:     # UTF-16 without its byte-order mark decodes as UTF-8 with a NUL in every other byte
        raise StudyError(f"{path}: expected a UTF-8 text file (or UTF-16 with a byte-order mark), found NUL "
                         f"bytes (at byte {data.index(0)}): UTF-16 without a byte-order mark?; save the file as "
                         "UTF-8 CSV")
    rows = list(csv.reader(io.StringIO(text, newline="")))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise StudyError(f"{path}: expected a header of design-variable names and one row per design, "
                         "found an empty file")
    header = [c.strip() for c in rows[0]]
    unknown = [h for h in header if h not in names]
    if unknown:
        raise StudyError(f"{path}, header: unknown design variable(s) {', '.join(map(repr, unknown))} "
                         f"(design variables of the case: {', '.join(names)})")
    if len(set(header)) != len(header):
        raise StudyError(f"{path}, header: a design variable appears twice: {', '.join(header)}")
    if len(rows) < 2:
        raise StudyError(f"{path}: expected at least one design below the header, found none")
    x = np.tile(case.x0, (len(rows) - 1, 1))
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise StudyError(f"{path}, line {i}: expected {len(header)} values, found {len(row)}")
        for name, cell in zip(header, row):
            try:
                v = float(cell)
            except ValueError:
                v = float("nan")
            if not np.isfinite(v):
                raise StudyError(f"{path}, line {i}, column {name!r}: expected a finite number, found {cell!r}")
            x[i - 2, names.index(name)] = v
    lo, up = case.lower, case.upper
    out = (x < lo) | (x > up)
    if out.any():
        i, j = map(int, np.argwhere(out)[0])
        raise StudyError(f"{path}, line {i + 2}, column {names[j]!r}: {x[i, j]:g} is outside the case's "
                         f"bounds [{lo[j]:g}, {up[j]:g}]")
    return x


def sample_designs(case: Case, spec: str, seed: int | None) -> np.ndarray:
    """The designs (N, m) of ``--sample SPEC``, in the case's units.

    ``lhs:N`` Latin hypercube and ``sobol:N`` scrambled Sobol' points (``scipy.stats.qmc``,
    ``seed``) mapped into the bounds; ``grid:AxBx…`` a full factorial grid with A points
    for the first variable etc. (``grid:A`` for all; a count of 1 keeps the case's value);
    anything else is read as a CSV file.
    """
    kind, sep, body = spec.partition(":")
    kind = kind.strip().lower()
    if sep and kind in ("lhs", "sobol"):
        from scipy.stats import qmc
        n = _count(spec, body.strip())
        _within_reason(spec, n)
        lo, up = _finite_bounds(case, spec)
        d = len(lo)
        if kind == "lhs":
            u = qmc.LatinHypercube(d=d, rng=seed).random(n)
        else:
            if n & (n - 1):
                raise StudyError(f"--sample {spec}: Sobol' points keep their balance only in powers of 2; "
                                 f"expected N = 2^k, found {n} (e.g. {1 << (n.bit_length() - 1)} or "
                                 f"{1 << n.bit_length()})")
            u = qmc.Sobol(d=d, scramble=True, rng=seed).random_base2(n.bit_length() - 1)
        return lo + u * (up - lo)
    if sep and kind == "grid":
        return _grid(case, spec, body.strip())
    if not Path(spec).exists():
        raise StudyError(f"--sample {spec}: expected lhs:N, sobol:N, grid:AxB... or an existing CSV file")
    return read_designs_csv(case, spec)
