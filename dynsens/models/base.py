r"""The residual contract every model implements (building block 1: governing equation).

A model is a residual :math:`F_R(z; q, \dot q, p, t, x) = 0` in the per-step unknowns
``z = [q̈; λ; ṗ]`` (method.md §1):

* ``q`` (n_q,) second-order coordinates, with velocities ``qd`` and accelerations ``qdd``;
* ``lam`` (n_lam,) Lagrange multipliers of the constraints (``n_lam = 0`` for structures);
* ``p`` (n_p,) first-order states (e.g. hydraulic pressures) with rates ``pd``.

Implementer contract
--------------------
1. ``traits`` declares sizes and what the integrator may leave out (linear, constant
   matrices, damping, sparsity).  It is read once, when the run is planned.
2. ``parameters(x)`` evaluates every design-dependent system parameter for the design
   ``x`` (m,).  It must be complex-safe: the integrator calls it with perturbed and with
   complex designs to form the partial derivatives :math:`\partial_x F_R` numerically
   ("semi-analytical").  The returned object is opaque to the integrator.
3. ``initial_state(params)`` returns ``(q0, qd0, p0)``; its design derivative is taken
   numerically unless the model overrides ``initial_state_gradient``.
4. ``residual(t, s, params)`` returns F_R (n_z,) for a :class:`StepState` ``s``.
5. ``linearize(t, s, params)`` returns the exact partial derivatives of F_R with respect
   to z, q, q̇ and p (:class:`Linearization`); the integrator forms the iteration matrix
   from them.  Blocks that are structurally zero are ``None``.
6. ``output(spec, path, problems)`` resolves a quantity named in a case (a dof's
   displacement, an element force, a joint reaction...) into an :class:`Output`.
7. All code in 2.-6. must be complex-safe (no ``abs``, no ``np.real`` on results,
   comparisons on real parts only) so that complex step runs end to end.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable, Mapping, NamedTuple, Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import ProblemCollector
from ..expressions import Expression, ExpressionError, compile_expression

Array = np.ndarray
Matrix = Any  # np.ndarray or scipy.sparse matrix


class StepState(NamedTuple):
    """State at one time instant.  Leaves are (n,) for the primal, (n, m) for sensitivities."""

    q: Array
    qd: Array
    qdd: Array
    lam: Array
    p: Array
    pd: Array


@dataclass(frozen=True)
class Traits:
    """What a model declares about itself; read once when a run is planned.

    Attributes
    ----------
    n_q, n_lam, n_p : sizes of coordinates, multipliers and first-order states.
    linear : F_R is affine in (z, q, q̇, p): one solve per step, no Newton loop.
    constant_matrices : the Linearization does not depend on state or time:
        assemble and factorize once per time-step size.
    has_damping : False when ∂F_R/∂q̇ is identically zero.
    sparse : the Linearization blocks are scipy.sparse matrices.
    """

    n_q: int
    n_lam: int = 0
    n_p: int = 0
    linear: bool = False
    constant_matrices: bool = False
    has_damping: bool = True
    sparse: bool = False

    @property
    def n_z(self) -> int:
        """Number of per-step unknowns, len([q̈; λ; ṗ])."""
        return self.n_q + self.n_lam + self.n_p


@dataclass(frozen=True)
class Linearization:
    """Partial derivatives of F_R at one state.  ``None`` marks a structurally zero block.

    R_z (n_z, n_z) = ∂F_R/∂z, R_q (n_z, n_q) = ∂F_R/∂q, R_qd (n_z, n_q) = ∂F_R/∂q̇,
    R_p (n_z, n_p) = ∂F_R/∂p.
    """

    R_z: Matrix
    R_q: Matrix | None = None
    R_qd: Matrix | None = None
    R_p: Matrix | None = None

    def iteration_matrix(self, c_q: float, c_qd: float, c_p: float, n_q: int) -> Matrix:
        """S = dF_R/dz when q = q_pred + c_q q̈, q̇ = q̇_pred + c_qd q̈, p = p_pred + c_p ṗ (method.md §3)."""
        n_z = self.R_z.shape[0]
        coupled_q = None
        if self.R_q is not None and c_q != 0.0:
            coupled_q = c_q * self.R_q
        if self.R_qd is not None and c_qd != 0.0:
            coupled_q = c_qd * self.R_qd if coupled_q is None else coupled_q + c_qd * self.R_qd
        coupled_p = c_p * self.R_p if (self.R_p is not None and c_p != 0.0) else None
        if coupled_q is None and coupled_p is None:
            return self.R_z
        n_p = self.R_p.shape[1] if self.R_p is not None else 0
        if sp.issparse(self.R_z):
            blocks = []
            if coupled_q is not None:
                blocks.append(sp.hstack([sp.csr_matrix(coupled_q),
                                         sp.csr_matrix((n_z, n_z - n_q))]))
            if coupled_p is not None:
                blocks.append(sp.hstack([sp.csr_matrix((n_z, n_z - n_p)),
                                         sp.csr_matrix(coupled_p)]))
            S = self.R_z
            for b in blocks:
                S = S + b
            return sp.csc_matrix(S)
        if isinstance(coupled_q, np.ndarray) and coupled_p is None and n_q == n_z and \
                coupled_q.dtype == np.result_type(coupled_q, self.R_z):
            coupled_q += self.R_z     # a new array: S = R_z + coupled_q (the same sums, one pass fewer)
            return coupled_q
        S = np.array(self.R_z, copy=True)
        if coupled_q is not None:
            S[:, :n_q] += coupled_q
        if coupled_p is not None:
            S[:, n_z - n_p:] += coupled_p
        return S

    def state_product(self, dq: Array, dqd: Array, dp: Array) -> Array | None:
        """R_q dq + R_qd dqd + R_p dp for vectors or (n, m) matrices; None when all blocks are zero."""
        out = None
        for block, d in ((self.R_q, dq), (self.R_qd, dqd), (self.R_p, dp)):
            if block is None or d.shape[0] == 0:
                continue
            term = block @ d
            out = term if out is None else out + term
        return out


OutputFn = Callable[..., Array]  # fn(t, state, params); "..." admits lambdas with bound defaults


@dataclass(frozen=True)
class Output:
    """A quantity a response or event can read at every step.

    ``fn(t, state, params)`` returns a complex-safe (k,) array; ``labels`` names its
    k components; ``unit`` is the unit shown in reports.  ``linear`` declares that fn is
    linear in the state and independent of the design, so its gradient is fn applied to
    the sensitivity state (no numerical differentiation needed).  ``batched`` declares that fn
    accepts state leaves with a leading batch axis together with the model's stacked
    parameters (``Model.stack_parameters``), so all gradient directions take one call.
    ``autonomous`` declares that fn depends on time only through the state, so a block of
    steps (a batch of states at different times) is evaluated in one call as well.
    """

    fn: OutputFn
    labels: tuple[str, ...]
    unit: str = ""
    linear: bool = False
    batched: bool = False
    autonomous: bool = False


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
        # range rules checked on the evaluated values (literals are checked when read):
        # (entry index, "positive" | "nonnegative", YAML path); vectors that must not vanish
        self._paths: list[str] = []
        self._rules: list[tuple[int, str, str]] = []
        self._nonzero: list[tuple[tuple[int, ...], str, str]] = []

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
            v = float(value)
            if not np.isfinite(v):
                problems.add(path, f"expected a finite number, found {value!r}")
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

    def check(self, x: Array) -> list[tuple[str, str]]:
        """(YAML path, problem) for every entry that has no finite value at the real design ``x``
        or breaks its range rule (> 0, >= 0, a vector not zero); empty when all hold."""
        x = np.real(np.asarray(x, dtype=complex if np.iscomplexobj(x) else float))
        env = dict(zip(self.design_names, x))
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
        derivative: dict[str, str | None] = {}
        for i, expr in self._exprs:
            if expr.symbols and i not in bad:
                if expr.text not in derivative:
                    derivative[expr.text] = expr.derivative_problem(env)
                why = derivative[expr.text]
                if why:
                    out.append((self._paths[i], why))
                    bad.add(i)
        exprs = dict(self._exprs)
        for i, rule, path in self._rules:
            v = values[i]
            if i not in bad and (v <= 0 if rule == "positive" else v < 0):
                where = "".join(f", {n} = {env[n]:.6g}" for n in sorted(exprs[i].symbols))
                out.append((path, f"expected {'> 0' if rule == 'positive' else '>= 0'}, found {v:.6g} "
                                  f"(expression '{exprs[i].text}'{where})"))
        for idx, path, what in self._nonzero:
            if not bad.intersection(idx) and not np.any(values[list(idx)]):
                out.append((path, f"expected a nonzero {what}, found {values[list(idx)].tolist()}"))
        return out

    def depends_on_design(self, index: int) -> bool:
        """True when entry ``index`` is an expression of design variables."""
        return any(i == index and e.symbols for i, e in self._exprs)

    def _expressions_naming(self) -> list[set[int]]:
        """For each design variable, the positions in ``_exprs`` of the expressions naming it."""
        if self._naming is None:
            index = {name: j for j, name in enumerate(self.design_names)}
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
                    _evaluate_into(out, [self._exprs[k] for k in ks], dict(zip(self.design_names, x)))
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


class Model(ABC):
    """Base class of all models; see the module docstring for the contract."""

    traits: Traits

    @abstractmethod
    def parameters(self, x: Array) -> Any:
        """System parameters for design ``x`` (m,) (complex-safe)."""

    @abstractmethod
    def initial_state(self, params: Any) -> tuple[Array, Array, Array]:
        """Initial coordinates q0 (n_q,), velocities qd0 (n_q,), first-order states p0 (n_p,)."""

    def initial_guess(self, params: Any) -> tuple[Array, Array]:
        """Starting values (lam0, pd0) for the initial solve; zeros unless the model knows better."""
        return np.zeros(self.traits.n_lam), np.zeros(self.traits.n_p)

    @abstractmethod
    def residual(self, t: float, s: StepState, params: Any) -> Array:
        """F_R (n_z,) at time t (s) and state s.  The solver never modifies a state's arrays
        in place, so models may cache work on their identity."""

    def stack_parameters(self, params_list: list[Any]) -> Any | None:
        """Parameter sets stacked along a leading batch axis for vectorized evaluation, or None
        when the model does not evaluate batches (then it is called once per set)."""
        return None

    def residual_batch(self, t: float, s: StepState, params_list: list[Any]) -> Array:
        """F_R at one state for several parameter sets, (n_z, B).

        Used for the numerical design partials (one column per perturbed design).  Models may
        override it with a vectorized evaluation; ``params_list`` is the same list object for
        a whole run, so stacked parameters can be cached on its identity.
        """
        return np.stack([self.residual(t, s, p) for p in params_list], axis=1)

    def residual_batch_steps(self, ts: Array, states: list[StepState], params_list: list[Any]) -> Array:
        """F_R at K states (times ts, s) for several parameter sets, (K, n_z, B).

        The design partials of a block of steps (the sensitivities trail the state by a block).
        Models may override it with one vectorized evaluation; by default one
        :meth:`residual_batch` per state.
        """
        return np.stack([self.residual_batch(t, s, params_list) for t, s in zip(ts, states)])

    def design_pattern(self) -> list[Array] | None:
        """For each design variable, the rows of F_R its explicit partial ∂F_R/∂x_j can touch
        (from the model's connectivity, independent of state and time), or None when unknown.
        Design variables with disjoint rows are then perturbed together (column colouring):
        per-element variables cost a few residuals per step instead of m."""
        return None

    @abstractmethod
    def linearize(self, t: float, s: StepState, params: Any) -> Linearization:
        """Exact partial derivatives of F_R at (t, s)."""

    @abstractmethod
    def output(self, spec: Any, path: str, problems: ProblemCollector) -> Output | None:
        """Resolve a quantity spec from a case; report problems under ``path``."""

    def structural_mass(self, params: Any) -> Any:
        """Total mass of the structure (model mass unit); complex-safe."""
        raise NotImplementedError(f"{type(self).__name__} does not define a structural mass")

    def project(self, t: float, s: StepState, params: Any) -> tuple[StepState, Any]:
        """The end state of an accepted step as the run continues from it, and what the
        derivative modes need of that map (None: s itself, no projection).  A model whose state
        must satisfy constraints may replace s by a consistent state here; the returned object then
        has ``raw`` (the solved state), ``apply(ds, partials)`` (direct mode) and
        ``transpose(q_bar, qd_bar, partials)`` (adjoint): see dynsens/models/multibody/projection.py."""
        return s, None

    def check_state(self, t: float, s: StepState, params: Any) -> None:  # noqa: B027 (optional hook)
        """Raise ModelError when the state leaves the model's range of validity."""

    def diagnose_singular(self, t: float, s: StepState, params: Any, rel_tol: float = 1e-9) -> str:
        """Explain a singular iteration matrix at (t, s), e.g. which joints lost rank to ``rel_tol``
        relative to the largest singular value ('' if unknown)."""
        return ""

    def monitors(self, t: float, s: StepState, params: Any) -> dict[str, float]:
        """Scalar per-step diagnostics stored with the results (e.g. constraint drift)."""
        return {}

    def dof_labels(self) -> list[str]:
        """Names of the coordinates q, used in reports and the HDF5 file."""
        return [f"q{i}" for i in range(self.traits.n_q)]

    def displacement_scale(self, params: Any, lin: Linearization | None) -> float:
        """A size of the coordinates q that the model's data imply (its geometry, the static
        deflection under its loads; 0 when unknown): growth is judged against it as well as
        against the run's early values (:mod:`dynsens.runaway`).  ``lin``: at t0."""
        return 0.0

    def describe_equation(self, k: int) -> str:
        """Equation k of the step unknowns z = (q̈, λ, ṗ) in the case's words: its coordinate
        and, where the model knows them, the YAML entries acting there (for run-time errors)."""
        tr = self.traits
        if k < tr.n_q:
            labels = self.dof_labels()
            return labels[k] if k < len(labels) else f"q[{k}]"
        if k < tr.n_q + tr.n_lam:
            return f"constraint {k - tr.n_q}"
        return f"first-order state p[{k - tr.n_q - tr.n_lam}]"


def as_dense(a: Matrix) -> Array:
    """Dense ndarray view of a dense or sparse matrix."""
    return a.toarray() if sp.issparse(a) else np.asarray(a)
