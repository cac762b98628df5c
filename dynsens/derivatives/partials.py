r"""Semi-analytical partial derivatives with respect to the design (method.md §4).

The pseudo load of the sensitivity step is

.. math:: P = ∂_x F_R + ∂F_R/∂q\,∇q^{pred} + ∂F_R/∂\dot q\,∇\dot q^{pred} + ∂F_R/∂p\,∇p^{pred}

The state blocks come from the model's exact linearization at the converged state (it
is already assembled for the Newton matrix); the explicit design part ∂_x F_R is taken
numerically from residuals evaluated with perturbed system parameters — the paper's
"semi-analytical" approach.  ``method`` chooses forward differences (m extra residuals
per step, error ~1e-8 relative), central differences (2m, ~1e-10) or complex step (m
complex residuals, exact to round-off; needs complex-safe model code).

The parameters of the perturbed designs are evaluated once per run, not per step.
"""
from __future__ import annotations

import functools

from collections.abc import Sequence
from typing import Any, Callable, Literal, overload

import numpy as np

from ..models.base import Model, StepState

PartialsMethod = Literal["forward", "central", "complex"]
METHODS: tuple[str, ...] = ("forward", "central", "complex")
DEFAULT_STEPS = {"forward": 1e-8, "central": 1e-5, "complex": 1e-20}


class PerturbedSets(Sequence[Any]):
    """The model's parameter sets at x + step_j e_j for each design variable j (m,), each
    evaluated on first access and kept."""

    def __init__(self, model: Model, x: np.ndarray, steps: np.ndarray):
        self.model, self.x, self.steps = model, x, steps
        self._sets: dict[int, Any] = {}

    def __len__(self) -> int:
        return self.x.size

    @overload
    def __getitem__(self, j: int) -> Any: ...

    @overload
    def __getitem__(self, j: slice) -> list[Any]: ...

    def __getitem__(self, j: int | slice) -> Any:
        if isinstance(j, slice):
            return [self[i] for i in range(len(self))[j]]
        j = range(len(self))[j]         # (an index out of range raises IndexError here)
        if j not in self._sets:
            unit = np.zeros(self.x.size)
            unit[j] = 1.0
            self._sets[j] = self.model.parameters(self.x + self.steps[j] * unit)
        return self._sets[j]


class DesignPartials:
    """Numerical ∂/∂x at fixed state for one design x (m,).

    Parameters
    ----------
    model : the model whose ``parameters(x)`` are perturbed.
    x : the design (real).
    method : ``forward``, ``central`` or ``complex``.
    rel_step : relative perturbation h_j = rel_step·max(|x_j|, 1e-3·scale_j); default per method.
    scale : typical magnitude of each design variable (the case's ``scale``), used when x_j ≈ 0.
    """

    def __init__(self, model: Model, x: np.ndarray, method: PartialsMethod | str = "forward",
                 rel_step: float | None = None, scale: np.ndarray | None = None):
        if method not in METHODS:
            raise ValueError(f"partials method {method!r}: expected one of {', '.join(METHODS)}")
        self.model = model
        self.method = method
        self.x = np.asarray(x, dtype=float)
        self.m = self.x.size
        rel = DEFAULT_STEPS[method] if rel_step is None else rel_step
        ref = np.abs(self.x)
        if scale is not None:
            ref = np.maximum(ref, 1e-3 * np.abs(scale))
        ref = np.where(ref > 0, ref, 1.0)
        self.h = rel * ref
        self.rel_step = rel
        self.params0 = model.parameters(self.x)
        # each variable's perturbed parameter set, evaluated when first read: a run whose
        # partials take coloured perturbations may never read most of them (m = 1 000 sets of
        # 1 000 parameters: 0.1 s a run)
        self._plus = PerturbedSets(model, self.x, 1j * self.h if method == "complex" else self.h)
        self._minus = PerturbedSets(model, self.x, -self.h)

        # The parameter sets one partials call evaluates (:attr:`_batch`), with the state
        # offset of each entry: entry b is evaluated at s + coef[b]·∇s[:, col[b]] (coef = 0
        # for the unperturbed entry).
        m, h = self.m, self.h
        if method == "forward":
            self._col = np.concatenate([[0], np.arange(m)])
            self._coef: np.ndarray = np.concatenate([[0.0], h])
        elif method == "central":
            self._col = np.concatenate([np.arange(m), np.arange(m)])
            self._coef = np.concatenate([h, -h])
        else:
            self._col = np.arange(m)
            self._coef = 1j * h
        self._states: tuple[StepState, StepState, StepState] | None = None

        # ∂_x F_R: design variables whose rows of F_R are disjoint share one perturbation
        # (column colouring, as for sparse Jacobians) when the model knows its pattern
        pattern = model.design_pattern()
        self.colours = colour_columns(pattern, m)
        self._residual_batch = (self._batch if self.colours is None or pattern is None
                                else self._colour_batch(pattern))

    @functools.cached_property
    def _batch(self) -> list[Any]:
        """The parameter sets of one uncoloured partials call, in a fixed list (models may cache
        stacked parameters on its identity): forward, the design's then each variable's; central,
        all + then all −; complex, the imaginary steps."""
        if self.method == "forward":
            return [self.params0] + list(self._plus)
        if self.method == "central":
            return list(self._plus) + list(self._minus)
        return list(self._plus)

    @functools.cached_property
    def _stacked(self) -> Any:
        """The model's stacked parameters of the whole batch (None when it does not stack them),
        made on first use: the batched outputs of the direct mode read them, the adjoint with
        declared output patterns never does, and for m = 2 252 bars they are ~1 GB and a second
        (BENCHMARKS.md)."""
        return self.model.stack_parameters(self._batch)

    @property
    def relative_error(self) -> float:
        """Expected relative error of the partials (dimensionless): truncation plus round-off,
        h + ε/h for forward and h² + ε/h for central differences of relative step h; 0 for
        complex step (exact to round-off)."""
        eps, h = float(np.finfo(float).eps), self.rel_step
        if self.method == "forward":
            return h + eps / h
        if self.method == "central":
            return h * h + eps / h
        return 0.0

    def _colour_batch(self, pattern: list[np.ndarray]) -> list[Any]:
        """The parameter sets of the coloured perturbations, and the index arrays that put
        each colour's difference quotients back into the columns of its variables."""
        assert self.colours is not None
        m = self.m
        colour_of = np.empty(m, int)
        for c, cols in enumerate(self.colours):
            colour_of[cols] = c
        self._scatter_rows = np.concatenate([pattern[j] for j in range(m)]).astype(int)
        self._scatter_cols = np.concatenate([np.full(len(pattern[j]), j) for j in range(m)]).astype(int)
        self._scatter_colours = colour_of[self._scatter_cols]
        return self.perturbed_sets(self.colours)

    def perturbed_sets(self, groups: list[list[int]]) -> list[Any]:
        """The parameter sets of the perturbations stepping each group of design variables at
        once (by their steps h), in the batch layout :meth:`_differences` reads (forward: the
        unperturbed set first; central: all + then all −; complex: imaginary steps).  A group
        of one variable takes the run's own set of it."""
        model, m, h = self.model, self.m, self.h

        def step(group: list[int]) -> np.ndarray:
            d = np.zeros(m)
            d[group] = h[group]
            return d
        def sets(own: Sequence[Any], sign: complex) -> list[Any]:
            # a group of one variable reuses the run's own set (``own``), others are evaluated
            return [own[g[0]] if len(g) == 1 else model.parameters(self.x + sign * step(g)) for g in groups]
        if self.method == "forward":
            return [self.params0] + sets(self._plus, 1)
        if self.method == "central":
            return sets(self._plus, 1) + sets(self._minus, -1)
        return sets(self._plus, 1j)

    def _differences(self, F: np.ndarray, groups: int) -> np.ndarray:
        """Undivided differences (..., groups) from the values (..., B) of a batch of ``groups``
        perturbations (forward: base first; central: all + then all −; complex: imaginary parts)."""
        if self.method == "forward":
            return F[..., 1:] - F[..., :1]
        if self.method == "central":
            return F[..., :groups] - F[..., groups:]
        return np.imag(F)

    @property
    def _divisor(self) -> np.ndarray:
        """What turns each column's difference into its quotient: h, or 2h for central."""
        return 2.0 * self.h if self.method == "central" else self.h

    def _combine(self, F: np.ndarray) -> np.ndarray:
        """Difference quotients (..., m) from the values (..., B) of the batch entries."""
        return self._differences(F, self.m) / self._divisor

    def residual_partials(self, t: float, s: StepState) -> np.ndarray:
        """∂_x F_R (n_z, m) at fixed state s and time t (s), one batched residual evaluation
        (of m + 1, 2m or m parameter sets, or per colour of design variables)."""
        return self._partials_of(self.model.residual_batch(t, s, self._residual_batch))

    def residual_partials_steps(self, ts: np.ndarray, states: list[StepState]) -> np.ndarray:
        """∂_x F_R (K, n_z, m) at K states (times ts, s): the same partials for a block of
        steps, in one call where the model evaluates blocks (``Model.residual_batch_steps``)."""
        return self._partials_of(self.model.residual_batch_steps(ts, states, self._residual_batch))

    def residual_partials_transposed_steps(self, ts: np.ndarray, states: list[StepState],
                                           mus: np.ndarray) -> np.ndarray:
        """Σ_k ∂_x F_R(t_k, s_k)ᵀ μ_k (m, r) for K states (times ts, s) and adjoint vectors
        ``mus`` (K, n_z, r): the adjoint's explicit design term.  The same batched residual call
        and differences as :meth:`residual_partials_steps`, contracted with μ before the columns
        are formed (with column colouring: each variable takes its own rows of its colour's
        difference), so r functions cost what one does."""
        F = self.model.residual_batch_steps(ts, states, self._residual_batch)   # (K, n_z, B)
        if self.colours is None:
            diff = self._differences(F, self.m)                                 # (K, n_z, m)
            return np.einsum("kzj,kzr->jr", diff, mus) / self._divisor[:, None]
        diff = self._differences(F, len(self.colours))                          # (K, n_z, colours)
        rows = self._scatter_rows
        entries = np.real(diff[:, rows, self._scatter_colours])                  # (K, nnz)
        out = np.zeros((self.m, mus.shape[-1]), dtype=np.result_type(mus, float))
        np.add.at(out, self._scatter_cols, np.einsum("kn,knr->nr", entries, mus[:, rows, :]))
        return out / self._divisor[:, None]

    def _partials_of(self, F: np.ndarray) -> np.ndarray:
        """Difference quotients (..., n_z, m) from residuals (..., n_z, B) of the batch."""
        if self.colours is None:
            return self._combine(F)
        # each variable's rows of its colour's difference are its own column
        diff = self._differences(F, len(self.colours))
        D = np.zeros(F.shape[:-1] + (self.m,))
        r, j = self._scatter_rows, self._scatter_cols
        D[..., r, j] = np.real(diff[..., r, self._scatter_colours]) / self._divisor[j]
        return D

    def total(self, fn: Callable[[StepState, Any], np.ndarray], s: StepState, ds: StepState,
              batched: bool = False) -> np.ndarray:
        """Total derivative d fn(s(x), x)/dx (k, m): directional derivatives along (∇s e_j, e_j).

        With ``batched`` (fn accepts a leading batch axis on the state leaves and stacked
        parameters) all directions are evaluated in one call.
        """
        if batched and self._stacked is not None:
            return self._combine(np.asarray(fn(self._directions(s, ds), self._stacked)).T)
        cols = [np.asarray(fn(StepState(*(v + c * dv[:, j] for v, dv in zip(s, ds))), prm))
                for prm, j, c in zip(self._batch, self._col, self._coef)]
        return self._combine(np.stack(cols, axis=-1))

    def value_and_total(self, fn: Callable[[StepState, Any], np.ndarray], s: StepState, ds: StepState,
                        batched: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """fn(s, params0) (k,) and its total derivative (k, m) (see :meth:`total`).  With forward
        differences of a batched fn both come from one call: its unperturbed entry is the value."""
        if batched and self._stacked is not None and self.method == "forward":
            F = np.asarray(fn(self._directions(s, ds), self._stacked))          # (m + 1, k)
            return F[0], self._combine(F.T)
        return np.asarray(fn(s, self.params0)), self.total(fn, s, ds, batched)

    def _directions(self, s: StepState, ds: StepState) -> StepState:
        """The batch of states s + coef[b]·∇s[:, col[b]] (leaves (B, n)), built once per (s, ∇s):
        all outputs of a step share it (and so the model's kinematics of it)."""
        last = self._states
        if last is not None and last[0] is s and last[1] is ds:
            return last[2]
        states = StepState(*(_along(v, dv, self._col, self._coef) for v, dv in zip(s, ds)))
        self._states = (s, ds, states)
        return states

    @property
    def parameter_set_bytes(self) -> int:
        """Memory (bytes) of one set of the model's stacked parameters (0 when the model does
        not stack them): what a block of output evaluations holds per entry."""
        if self._stacked is None:
            return 0
        held = self._stacked.values() if isinstance(self._stacked, dict) else vars(self._stacked).values()
        arrays = [a for v in held for a in (v if isinstance(v, (list, tuple)) else [v])
                  if isinstance(a, np.ndarray)]
        return sum(a.nbytes for a in arrays) // max(len(self._batch), 1)

    @property
    def block_entries(self) -> int:
        """States per step in :meth:`value_and_total_block`: the batch, plus the unperturbed
        state unless the batch starts with it (forward differences)."""
        return len(self._batch) + (self.method != "forward")

    def value_and_total_block(self, fn: Callable[[StepState, Any], np.ndarray], states: list[StepState],
                              dstates: list[StepState]) -> tuple[np.ndarray, np.ndarray]:
        """Values (K, k) and total derivatives (K, k, m) of a batched fn at K states with their
        sensitivities, in one call: every step's unperturbed state and its directions (the
        same differences as :meth:`value_and_total`).  fn must not depend on time explicitly.
        Calls with the same ``states`` list share its batch of states (and the model's
        kinematics of it)."""
        K, E = len(states), self.block_entries
        F = np.asarray(fn(self._block_directions(states, dstates), self._block_parameters(K)))
        F = F.reshape(K, E, -1).transpose(0, 2, 1)                             # (K, k, E)
        value = F[..., 0].real if self.method == "complex" else F[..., 0]
        return value, self._combine(F[..., 1:] if self.method != "forward" else F)

    def _block_directions(self, states: list[StepState], dstates: list[StepState]) -> StepState:
        """Leaves (K·E, n): for each step, its state and the states along its directions."""
        last = self.__dict__.get("_block_states")
        if last is not None and last[0] is states:
            return last[1]
        K, E = len(states), self.block_entries
        base = self.method != "forward"
        col = np.concatenate([[0], self._col]) if base else self._col
        coef = np.concatenate([[0.0], self._coef]) if base else self._coef
        leaves = (_along(np.array(v), np.array(dv), col, coef)            # (K, n), (K, n, m) -> (K, E, n)
                  for v, dv in zip(zip(*states), zip(*dstates)))
        out = StepState(*(x.reshape(K * E, x.shape[-1]) for x in leaves))
        self._block_states = (states, out)          # keeps the list alive: identity stays unique
        return out

    def _block_parameters(self, K: int) -> Any:
        """The model's stacked parameters of K copies of the block entries (cached per K)."""
        cache = self.__dict__.setdefault("_block_stacks", {})
        if K not in cache:
            entries = self._batch if self.method == "forward" else [self.params0] + self._batch
            cache[K] = self.model.stack_parameters(entries * K)
        return cache[K]

    @property
    def evaluations_per_call(self) -> int:
        """Residual evaluations one :meth:`residual_partials` call costs."""
        return len(self._residual_batch)

    def of(self, fn: Callable[[Any], np.ndarray], base: np.ndarray | None = None) -> np.ndarray:
        """∂fn/∂x (k, m) for fn(params) -> (k,); ``base`` = fn(params0) if already known."""
        cols = []
        if self.method == "forward":
            f0 = fn(self.params0) if base is None else base
            for j in range(self.m):
                cols.append((fn(self._plus[j]) - f0) / self.h[j])
        elif self.method == "central":
            for j in range(self.m):
                cols.append((fn(self._plus[j]) - fn(self._minus[j])) / (2.0 * self.h[j]))
        else:
            for j in range(self.m):
                cols.append(np.imag(fn(self._plus[j])) / self.h[j])
        return np.stack(cols, axis=-1) if cols else np.zeros((np.size(base) if base is not None else 0, 0))



def _along(v: np.ndarray, dv: np.ndarray, col: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """States v + coef[b]·∇v[..., col[b]] for every entry b: (..., B, n) from a state leaf v
    (..., n) and its sensitivities dv (..., n, m)."""
    return v[..., None, :] + np.swapaxes(dv[..., col] * coef, -1, -2)


def colour_columns(pattern: list[np.ndarray] | None, m: int) -> list[list[int]] | None:
    """Groups of columns with pairwise disjoint rows (greedy, largest first), or None when
    there is no pattern or grouping would not save an evaluation."""
    if pattern is None or m < 2:
        return None
    colours: list[list[int]] = []
    used: list[set[int]] = []
    for j in sorted(range(m), key=lambda k: -len(pattern[k])):
        rows = set(pattern[j].tolist())
        for cols, taken in zip(colours, used):
            if not taken & rows:
                cols.append(j)
                taken |= rows
                break
        else:
            colours.append([j])
            used.append(rows)
    return colours if len(colours) < m else None


def initial_state_gradient(model: Model, partials: DesignPartials
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """∇q0, ∇q̇0, ∇p0 (each (n, m)) by differentiating ``model.initial_state`` numerically.

    Models whose initial state comes from a solve (mechanism assembly), or that know it does
    not depend on the design, may override this with ``model.initial_state_gradient(params0,
    partials)`` (None from it: numerically, as here).
    """
    custom = getattr(model, "initial_state_gradient", None)
    found = custom(partials.params0, partials) if custom is not None else None
    if found is not None:
        return found  # type: ignore[no-any-return]
    t = model.traits

    def flat(params: Any) -> np.ndarray:
        q0, qd0, p0 = model.initial_state(params)
        return np.concatenate([q0, qd0, p0])

    d = partials.of(flat)
    return d[:t.n_q], d[t.n_q:2 * t.n_q], d[2 * t.n_q:]


def pseudo_load(model: Model, t: float, s: StepState, lin: Any, dq_pred: np.ndarray,
                dqd_pred: np.ndarray, dp_pred: np.ndarray, partials: DesignPartials) -> np.ndarray:
    """P (n_z, m) of method.md §4 at the converged state s of time t (s)."""
    return pseudo_load_with(partials.residual_partials(t, s), lin, dq_pred, dqd_pred, dp_pred)


def pseudo_load_with(design_part: np.ndarray, lin: Any, dq_pred: np.ndarray, dqd_pred: np.ndarray,
                     dp_pred: np.ndarray) -> np.ndarray:
    """P (n_z, m) from the explicit design part ∂_x F_R (already evaluated, e.g. for a block of
    steps) and the state part R_q ∇q^pred + R_q̇ ∇q̇^pred + R_p ∇p^pred."""
    state_part = lin.state_product(dq_pred, dqd_pred, dp_pred) if lin is not None else None
    return design_part if state_part is None else design_part + state_part
