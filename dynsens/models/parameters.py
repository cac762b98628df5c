"""The numeric entries of a case: numbers or expressions of the design variables, evaluated
together for one design (complex-safe), with the indices the model builders keep."""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import ProblemCollector
from ..expressions.restricted import Expression, ExpressionError, compile_expression

Array = np.ndarray


def finite_float(value: int | float) -> float | None:
    """A YAML number as a finite float; None for NaN, ±inf and an integer beyond the float range
    (YAML reads ``1000...0`` of 400 digits as an exact Python int, which ``float`` cannot hold)."""
    try:
        v = float(value)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None


def number_text(value: Any) -> str:
    """``repr(value)`` for a message, an integer of more than 20 digits shortened to its size."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10 ** 20:
        return f"an integer of {len(str(abs(value)))} digits ({'-' if value < 0 else ''}{str(abs(value))[:6]}...)"
    return repr(value)


class ParameterTable:
    """Numeric entries of a case (numbers or design expressions), evaluated together.

    Builders call :meth:`add` for each numeric entry they read and keep the returned
    index; :meth:`evaluate` returns all values for one design (complex-safe).
    """

    def __init__(self, design_names: Sequence[str]):
        self.design_names = tuple(design_names)
        self._known = frozenset(design_names)
        # the case's initial design by name, set by the case loader (None: not built from a case)
        self.nominal: dict[str, float] | None = None
        self._constants: list[complex | float] = []
        self._exprs: list[tuple[int, Expression]] = []
        # the last fully evaluated design and its entries, and per design variable the
        # positions in _exprs of the expressions naming it (for perturbed designs)
        self._base: tuple[Array, Array] | None = None
        self._naming: list[set[int]] | None = None
        self._position: dict[str, int] = {}    # design variable name -> position in x (with _naming)
        # range rules checked on the evaluated values (literals are checked when read):
        # (entry index, "positive" | "nonnegative", YAML path); vectors that must not vanish
        self._paths: list[str] = []
        self._rules: list[tuple[int, str, str]] = []
        self._nonzero: list[tuple[tuple[int, ...], str, str]] = []
        # two points (coordinate entries) that must not coincide: (a, b, path, what)
        self._apart: list[tuple[tuple[int, ...], tuple[int, ...], str, str]] = []
        # hollow sections whose wall must leave a hole: (wall index, {width name: index}, path)
        self._walls: list[tuple[int, dict[str, int], str]] = []
        # bar pretensions that must leave a positive free length, N0 > −E A: (N0, E, A, path)
        self._pretensions: list[tuple[int, int, int, str]] = []
        # symmetric matrices that must be positive definite: (index matrix, path, what)
        self._definite: list[tuple[tuple[tuple[int, ...], ...], str, str]] = []

    def __len__(self) -> int:
        return len(self._constants)

    def add(self, value: Any, path: str, problems: ProblemCollector, *,
            positive: bool = False, nonnegative: bool = False, default: float | None = None) -> int:
        """Register one numeric entry found at YAML ``path``; returns its index (-1 on error)."""
        self._base = self._naming = None
        if value is None and default is not None:
            value = default
        idx = len(self._constants)
        if isinstance(value, bool) or value is None:
            problems.add(path, f"expected a number or an expression, found {value!r}")
            return -1
        if isinstance(value, (int, float)):
            v = finite_float(value)
            if v is None:
                problems.add(path, f"expected a finite number, found {number_text(value)}")
                return -1
            if positive and v <= 0:
                problems.add(path, f"must be > 0, found {value!r}")
                return -1
            if nonnegative and v < 0:
                problems.add(path, f"must be >= 0, found {value!r}")
                return -1
            self._constants.append(v)
            self._paths.append(path)
            return idx
        if isinstance(value, str):
            try:
                expr = compile_expression(value, self._known)
            except ExpressionError as exc:
                problems.add(path, str(exc))
                return -1
            self._constants.append(0.0)
            self._paths.append(path)
            self._exprs.append((idx, expr))
            if positive or nonnegative:
                self._rules.append((idx, "positive" if positive else "nonnegative", path))
            return idx
        problems.add(path, f"expected a number or an expression, found {type(value).__name__} {value!r}")
        return -1

    def add_many(self, values: Any, path: str, problems: ProblemCollector, length: int | None = None,
                 **kw: Any) -> list[int]:
        """Register a list of numeric entries (e.g. a coordinate triple)."""
        if not isinstance(values, (list, tuple)):
            problems.add(path, f"expected a list of numbers, found {values!r}")
            return [-1] * (length or 0)
        if length is not None and len(values) != length:
            problems.add(path, f"expected {length} entries, found {len(values)}")
            return [-1] * length
        return [self.add(v, f"{path}[{i}]", problems, **kw) for i, v in enumerate(values)]

    def require_nonzero(self, indices: Sequence[int], path: str, what: str) -> None:
        """Entries ``indices`` (e.g. an axis) must not all be zero at any design."""
        if all(i >= 0 for i in indices):
            self._nonzero.append((tuple(indices), path, what))

    def require_apart(self, a: Sequence[int], b: Sequence[int], path: str, what: str) -> None:
        """Points ``a`` and ``b`` (coordinate entries, e.g. a bar's end nodes) must not coincide at
        any design: an element of zero length has no direction (its strain divides by it)."""
        if all(i >= 0 for i in (*a, *b)):
            self._apart.append((tuple(a), tuple(b), path, what))

    def require_wall(self, wall: int, widths: Mapping[str, int], path: str) -> None:
        """A hollow section's wall thickness (entry ``wall``) must leave a hole at every design:
        2·t < each outer width in ``widths`` (name -> entry, e.g. {"D": i} for a tube)."""
        if wall >= 0 and all(i >= 0 for i in widths.values()):
            self._walls.append((wall, dict(widths), path))

    def require_pretension(self, force: int, modulus: int, area: int, path: str) -> None:
        """A bar's initial tension (entry ``force``) must exceed −E A at every design, so that
        its free length L0 = Li E A/(E A + N0) is positive and finite."""
        if min(force, modulus, area) >= 0:
            self._pretensions.append((force, modulus, area, path))

    def require_positive_definite(self, matrix: Sequence[Sequence[int]], path: str, what: str) -> None:
        """The symmetric matrix of entries ``matrix`` (an index per row and column, e.g. an
        inertia tensor) must be positive definite at every design."""
        if all(i >= 0 for row in matrix for i in row):
            self._definite.append((tuple(tuple(row) for row in matrix), path, what))

    def check(self, x: Array) -> list[tuple[str, str]]:
        """(YAML path, problem) for every entry that has no finite value at the real design ``x``
        or breaks its range rule (> 0, >= 0, a vector not zero); empty when all hold."""
        x = np.real(np.asarray(x, dtype=complex if np.iscomplexobj(x) else float))
        env = dict(zip(self.design_names, x))
        values, out, bad = self._evaluated(env)
        out += self._derivative_problems(env, bad)
        # the rules, each on the entries that have a value (an entry in ``bad`` is reported above)
        for rule in (self._range_problems, self._nonzero_problems, self._apart_problems, self._definite_problems,
                     self._wall_problems, self._pretension_problems):
            out += rule(values, bad, env)
        return out

    def _evaluated(self, env: dict[str, float]) -> tuple[Array, list[tuple[str, str]], set[int]]:
        """(the entries' values at ``env``, (path, problem) of those with none, their indices)."""
        values = np.array(self._constants, dtype=float)
        out: list[tuple[str, str]] = []
        bad: set[int] = set()
        # an expression written many times (every element's "k") is evaluated once
        outcome: dict[str, float | str] = {}
        for i, expr in self._exprs:
            if expr.text not in outcome:
                try:
                    outcome[expr.text] = float(np.real(expr.evaluate(env)))
                except ExpressionError as exc:
                    outcome[expr.text] = str(exc)
            result = outcome[expr.text]
            if isinstance(result, str):
                out.append((self._paths[i], result))
                bad.add(i)
            else:
                values[i] = result
        return values, out, bad

    def _derivative_problems(self, env: dict[str, float], bad: set[int]) -> list[tuple[str, str]]:
        """(path, problem) of each expression with no finite derivative at ``env``; adds it to ``bad``."""
        out = []
        derivative: dict[str, str | None] = {}
        for i, expr in self._exprs:
            if expr.symbols and i not in bad:
                if expr.text not in derivative:
                    derivative[expr.text] = expr.derivative_problem(env)
                why = derivative[expr.text]
                if why:
                    out.append((self._paths[i], why))
                    bad.add(i)
        return out

    def _range_problems(self, values: Array, bad: set[int], env: dict[str, float]) -> list[tuple[str, str]]:
        """Entries that must be > 0 (``positive``) or >= 0 and are not."""
        out = []
        exprs = dict(self._exprs)
        for i, rule, path in self._rules:
            v = values[i]
            if i not in bad and (v <= 0 if rule == "positive" else v < 0):
                where = "".join(f", {n} = {env[n]:.6g}" for n in sorted(exprs[i].symbols))
                out.append((path, f"expected {'> 0' if rule == 'positive' else '>= 0'}, found {v:.6g} "
                                  f"(expression '{exprs[i].text}'{where})"))
        return out

    def _nonzero_problems(self, values: Array, bad: set[int], env: dict[str, float]) -> list[tuple[str, str]]:
        """Vectors (an axis, a direction) that must not be zero and are."""
        return [(path, f"expected a nonzero {what}, found {values[list(idx)].tolist()}")
                for idx, path, what in self._nonzero
                if not bad.intersection(idx) and not np.any(values[list(idx)])]

    def _apart_problems(self, values: Array, bad: set[int], env: dict[str, float]) -> list[tuple[str, str]]:
        """Elements whose two end points coincide (zero length)."""
        return [(path, f"expected two distinct end points (a {what} of zero length has no direction), found both "
                       f"at {values[list(a)].tolist()}")
                for a, b, path, what in self._apart
                if not bad.intersection((*a, *b)) and np.array_equal(values[list(a)], values[list(b)])]

    def _definite_problems(self, values: Array, bad: set[int], env: dict[str, float]) -> list[tuple[str, str]]:
        """Symmetric matrices (an inertia tensor) that must be positive definite and are not."""
        out = []
        for matrix, path, what in self._definite:
            if not bad.intersection(i for row in matrix for i in row):
                A = values[np.array(matrix)]
                lowest = float(np.linalg.eigvalsh(A)[0])
                if lowest <= 0:
                    out.append((path, f"expected a positive definite {what}, found {A.tolist()} "
                                      f"(lowest eigenvalue {lowest:.6g})"))
        return out

    def _wall_problems(self, values: Array, bad: set[int], env: dict[str, float]) -> list[tuple[str, str]]:
        """Hollow sections whose wall is too thick for their outer widths (no hole left)."""
        out = []
        for wall, widths, path in self._walls:
            if bad.intersection([wall, *widths.values()]):
                continue
            t = values[wall]
            thick = {n: values[i] for n, i in widths.items() if 2 * t > values[i]}
            if thick:
                found = ", ".join(f"{n} = {v:.6g}" for n, v in thick.items())
                out.append((path, f"expected a wall t <= {' and '.join(f'{n}/2' for n in widths)} "
                                  f"(a section that exists), found t = {t:.6g} with {found}"))
        return out

    def _pretension_problems(self, values: Array, bad: set[int], env: dict[str, float]) -> list[tuple[str, str]]:
        """Bar pretensions N0 <= −E A (no positive free length)."""
        out = []
        for force, modulus, area, path in self._pretensions:
            if bad.intersection([force, modulus, area]):
                continue
            EA = values[modulus] * values[area]
            if values[force] <= -EA:
                out.append((path, f"expected an initial force > -E A = {-EA:.6g} (a positive free length), "
                                  f"found {values[force]:.6g}"))
        return out

    def depends_on_design(self, index: int) -> bool:
        """True when entry ``index`` is an expression of design variables."""
        return any(i == index and e.symbols for i, e in self._exprs)

    def _expressions_naming(self) -> list[set[int]]:
        """For each design variable, the positions in ``_exprs`` of the expressions naming it."""
        if self._naming is None:
            index = self._position = {name: j for j, name in enumerate(self.design_names)}
            self._naming = [set() for _ in self.design_names]
            for k, (_, expr) in enumerate(self._exprs):
                for name in expr.symbols:
                    if name in index:
                        self._naming[index[name]].add(k)
        return self._naming

    def design_dependents(self) -> list[list[int]]:
        """For each design variable, the entries whose expressions name it."""
        return [sorted(self._exprs[k][0] for k in ks) for ks in self._expressions_naming()]

    def evaluate(self, x: Array) -> Array:
        """All entries for design ``x`` (m,); complex when ``x`` is complex.

        A design that differs from the last fully evaluated one in a few variables (a
        perturbed design of the partials) re-evaluates only the expressions naming them."""
        dtype = np.result_type(x.dtype, float)
        base = self._base
        # (not from complex entries to a real design: they were computed in complex arithmetic)
        if base is not None and base[0].shape == x.shape and \
                (np.iscomplexobj(x) or not np.iscomplexobj(base[1])):
            changed = np.flatnonzero(x != base[0])
            if changed.size <= max(1, x.size // 8):
                out = base[1].astype(dtype)
                if changed.size:
                    naming = self._expressions_naming()
                    ks = sorted(set().union(*(naming[j] for j in changed)))
                    exprs = [self._exprs[k] for k in ks]
                    # the values of the symbols these expressions name, not of all m variables
                    # (one perturbed design per variable: m² entries otherwise)
                    position = self._position
                    names = set().union(*(e.symbols for _, e in exprs)) & position.keys()
                    _evaluate_into(out, exprs, {n: x[position[n]] for n in names})
                return out
        out = np.array(self._constants, dtype=dtype)
        if self._exprs:
            _evaluate_into(out, self._exprs, dict(zip(self.design_names, x)))
        self._base = (np.array(x, copy=True), out.copy())
        return out


def _evaluate_into(out: Array, exprs: Sequence[tuple[int, Expression]], env: Mapping[str, Any]) -> None:
    """out[i] = expression value for every (i, expression), each distinct text evaluated once
    (a case names one design variable in many entries: every element's "k")."""
    values: dict[str, Any] = {}
    for i, expr in exprs:
        if expr.text not in values:
            values[expr.text] = expr.evaluate(env)
        out[i] = values[expr.text]
