r"""The residual contract every model implements (building block 1: governing equation).

A model is a residual :math:`F_R(z; q, \dot q, p, t, x) = 0` in the per-step unknowns
``z = [q̈; λ; ṗ]`` (method.md §1):

* ``q`` (n_q,) second-order coordinates, with velocities ``qd`` and accelerations ``qdd``;
* ``lam`` (n_lam,) Lagrange multipliers of the constraints (``n_lam = 0`` for structures);
* ``p`` (n_p,) first-order states (e.g. hydraulic pressures) with rates ``pd``.

Implementer contract
--------------------
Required (abstract):

1. ``traits`` declares sizes and what the integrator may leave out (linear, constant
   matrices, damping, sparsity).  It is read once, when the run is planned.
2. ``parameters(x)`` evaluates every design-dependent system parameter for the design
   ``x`` (m,).  It must be complex-safe: the integrator calls it with perturbed and with
   complex designs to form the partial derivatives :math:`\partial_x F_R` numerically
   ("semi-analytical").  The returned object is opaque to the integrator.
3. ``initial_state(params)`` returns ``(q0, qd0, p0)``; its design derivative is taken
   numerically unless the model defines ``initial_state_gradient(params0, partials)``
   (:mod:`dynsens.derivatives.partials`; a model's method may return None: numerically then).
4. ``residual(t, s, params)`` returns F_R (n_z,) for a :class:`StepState` ``s``.
5. ``linearize(t, s, params)`` returns the exact partial derivatives of F_R with respect
   to z, q, q̇ and p (:class:`Linearization`); the integrator forms the iteration matrix
   from them.  Blocks that are structurally zero are ``None``.
6. ``output(spec, path, problems)`` resolves a quantity named in a case (a dof's
   displacement, an element force, a joint reaction...) into an :class:`Output`.
7. All code in 2.-6. and in the batch evaluations below must be complex-safe (no ``abs``,
   no ``np.real`` on results, comparisons on real parts only) so that complex step runs end
   to end.

Optional, with defaults here (each method's docstring says what it must return):

8. ``initial_guess(params)``: (λ0, ṗ0) to start the initial solve (zeros).
9. Batches for the design partials: ``stack_parameters(params_list)`` (None: not
   stacked), ``residual_batch(t, s, params_list)`` (n_z, B) and ``residual_batch_steps(ts,
   states, params_list)`` (K, n_z, B) (one :meth:`~Model.residual` per set and state), and
   ``design_pattern()``, the rows each design variable's partial can touch (None: unknown).
10. ``structural_mass(params)``: total mass, for the mass response (not defined).
11. Per accepted step: ``project(t, s, params)`` (the state the run continues from and the
    map the derivative modes need; s itself), ``check_state(t, s, params)`` (ModelError out
    of range; nothing) and ``monitors(t, s, params)`` (scalar diagnostics; none).
12. ``compiled_step(newton, refactor)``: the compiled Newton iteration of a step where the
    model has one (None); ``compiled_blocks``: whether its compiled steps also run in blocks
    of steps (False).
13. Messages and reports: ``diagnose_singular``, ``describe_equation``, ``dof_labels``;
    ``displacement_scale`` for the runaway monitor.
14. Read where a model has them (by ``getattr``, not declared here): ``initial_state_gradient``
    (3.), ``constraint_levels`` and ``kinematics`` (the drift of the sensitivities,
    :mod:`dynsens.derivatives.constraint_drift`), ``redundant`` and ``multiplier_labels`` (the
    multipliers' names in the results).

Invariants the callers keep, and the caches rely on
---------------------------------------------------
A. A state's arrays are never modified in place: the solver, the step sequences and the
   derivative modes make a new array for every iterate and every accepted state.  A cache may
   therefore reuse work for the same array objects (``is``), or for equal contents
   (``tobytes()``) when it keeps the arrays it compares.
B. A parameter set (the object ``parameters(x)`` returned) keeps its identity and its values
   for a run: it is formed once per design and never changed.  Derived data may be kept with
   it, in a declared cache field of its own (never as extra keys in its tables), and caches may
   be keyed by its identity.
C. A list of parameter sets passed to the batch evaluations is the same list object for a
   whole run (the design partials' perturbed sets), so stacked parameters can be kept on the
   list's identity.
D. An identity-keyed entry keeps the objects whose ``id`` it uses alive, so the identity
   cannot pass to a new object while the entry exists.
E. No module keeps state on another object: a model's caches are its own, declared (for
   the multibody model one :class:`~dynsens.models.multibody.run_cache.RunCache`, each field
   with the rule that replaces it); tests/test_no_reach_ins.py checks it.

The caches that rely on A.-D. (keyed by identity ``is``/``id`` or by bytes):

* multibody, :class:`~dynsens.models.multibody.run_cache.RunCache` (``model.cache``):
  ``initial`` (set), ``evaluation`` (kinematics, λ, p, ṗ; bytes), ``linearization``
  (evaluation), ``stacked`` (list), ``constraint_levels`` (q, q̇, set), ``solved`` (q);
* multibody kinematics, :class:`~dynsens.models.multibody.kernel_compiled.KinCache`: by
  q, q̇, q̈ and kernel parameters, then by their bytes;
* multibody parameter sets, :class:`~dynsens.models.multibody.bodies.ParamsCache` (point
  tensors, kernel parameters per layout, size) and
  :class:`~dynsens.models.multibody.kernel.KParamsCache` (coefficients and time inputs at
  the last t, steady inputs and compiled forms per dtype): kept with the set (B.);
* multibody compiled step (:mod:`~dynsens.models.multibody.compiled_step`): the design's
  fields by set; reaction split (:mod:`~dynsens.models.multibody.reaction_split`): sets
  grouped by identity within one call; term kinematics and forces per call by term
  (:class:`~dynsens.models.multibody.bodies.Ctx`);
* structural models: stacked parameters by list (:mod:`dynsens.models.structural.model`), the
  compiled spring step's design by set (:mod:`dynsens.models.structural.step`);
* derivative modes: stacked directions by the block's state list and stacked parameter
  copies per block length (:mod:`dynsens.derivatives.partials`), output seeds' stacked copies per
  length (:mod:`dynsens.derivatives.output_seeds`), the direct mode's transition matrices by
  linearization and factorization (:mod:`dynsens.derivatives.direct`), checkpoints' seen
  objects (:mod:`dynsens.derivatives.checkpoints`);
* designs by bytes of x: :mod:`dynsens.openmdao` and :mod:`dynsens.optimize.problem`
  (one simulation per design).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import numpy as np
import scipy.sparse as sp

from ..errors import ProblemCollector

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


# a dense linearization with a known pattern forms S at the pattern's positions only when they
# are fewer than 1/PATTERN_SHARE of the entries (measured on the chain's band: the whole-matrix
# sums are cheaper below about 50 × 50, half the time at 100 × 100; BENCHMARKS.md)
PATTERN_SHARE = 16


@dataclass(frozen=True)
class Linearization:
    """Partial derivatives of F_R at one state.  ``None`` marks a structurally zero block.

    R_z (n_z, n_z) = ∂F_R/∂z, R_q (n_z, n_q) = ∂F_R/∂q, R_qd (n_z, n_q) = ∂F_R/∂q̇,
    R_p (n_z, n_p) = ∂F_R/∂p.  ``dense_pattern``: for dense blocks, the flat (row-major)
    positions outside which every block is zero by construction, the same array object for as
    long as that holds (the solver then keeps its band plan without scanning the matrix).
    """

    R_z: Matrix
    R_q: Matrix | None = None
    R_qd: Matrix | None = None
    R_p: Matrix | None = None
    dense_pattern: np.ndarray | None = None

    def iteration_matrix(self, c_q: float, c_qd: float, c_p: float, n_q: int) -> Matrix:
        """S = dF_R/dz when q = q_pred + c_q q̈, q̇ = q̇_pred + c_qd q̈, p = p_pred + c_p ṗ (method.md §3)."""
        n_z = self.R_z.shape[0]
        pattern = self.dense_pattern
        if pattern is not None and PATTERN_SHARE * pattern.size < n_z * n_z and self.R_p is None and n_q == n_z:
            return self._iteration_matrix_on_pattern(c_q, c_qd, pattern)
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

    def _iteration_matrix_on_pattern(self, c_q: float, c_qd: float, pattern: np.ndarray) -> Array:
        """:meth:`iteration_matrix` of dense blocks that are zero outside the flat positions
        ``pattern``: the same sums (c_q R_q + c_qd R_qd) + R_z, formed at those positions only."""
        coupled = None
        if self.R_q is not None and c_q != 0.0:
            coupled = c_q * self.R_q.take(pattern)
        if self.R_qd is not None and c_qd != 0.0:
            term = c_qd * self.R_qd.take(pattern)
            coupled = term if coupled is None else coupled + term
        if coupled is None:
            return self.R_z
        values = coupled + self.R_z.take(pattern)
        n = self.R_z.shape[0]
        S = np.zeros(n * n, values.dtype)
        S[pattern] = values
        return S.reshape(n, n)

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
class OutputPattern:
    """What each of an output's k rows can depend on, as (row, column) pairs of a superset of
    the true dependence: ``state`` columns index the flat state (q, q̇, q̈, λ, p, ṗ stacked),
    ``design`` columns the design variables.  The adjoint's output seeds colour their probes by
    it (:mod:`dynsens.derivatives.output_seeds`): a pair left out would mix two derivatives."""

    state_rows: Array
    state_cols: Array
    design_rows: Array
    design_cols: Array


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
    ``pattern`` (None: unknown) gives the output's :class:`OutputPattern`; it is called once
    per run, when the design variables are known.
    """

    fn: OutputFn
    labels: tuple[str, ...]
    unit: str = ""
    linear: bool = False
    batched: bool = False
    autonomous: bool = False
    pattern: Callable[[], OutputPattern] | None = None


class Model(ABC):
    """Base class of all models; see the module docstring for the contract (methods 1.-13.)
    and the invariants its caches rely on (A.-E.)."""

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

    #: what the message of a singular iteration matrix suggests to check (a model of masses,
    #: stiffnesses and dampers; mechanisms name their joints and poses instead)
    singular_hint = ("check the element parameters and the supports for zero or negative masses or "
                     "stiffnesses, unsupported (rigid-body) degrees of freedom, or stiffness and mass "
                     "terms too far apart in size for double precision (a tiny pivot ratio)")

    #: whether the model's compiled steps also run in compiled blocks of steps
    #: (:mod:`dynsens.timeloop.step_blocks`; declared by the model family, never probed)
    compiled_blocks = False

    def compiled_step(self, newton: bool, refactor: bool) -> Callable[..., Any] | None:
        """A compiled Newton iteration for this model's steps, when it has one
        (:mod:`dynsens.solver.newton_core`): a function of (t, prediction, params, coefficients)
        giving the step's compiled operations, or None for a step it does not serve; None here
        (every step iterates in Python)."""
        return None

    def monitors(self, t: float, s: StepState, params: Any) -> dict[str, float]:
        """Scalar per-step diagnostics stored with the results (e.g. constraint drift)."""
        return {}

    def dof_labels(self) -> list[str]:
        """Names of the coordinates q, used in reports and the HDF5 file."""
        return [f"q{i}" for i in range(self.traits.n_q)]

    def displacement_scale(self, params: Any, lin: Linearization | None) -> float:
        """A size of the coordinates q that the model's data imply (its geometry, the static
        deflection under its loads; 0 when unknown): growth is judged against it as well as
        against the run's early values (:mod:`dynsens.timeloop.runaway`).  ``lin``: at t0."""
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
