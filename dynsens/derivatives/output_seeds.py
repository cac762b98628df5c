r"""The adjoint seeds of the outputs: ∂(wᵀv)/∂state and ∂_x(wᵀv) at one instant.

A response's gradient is a weighted sum of its outputs' total gradients,
dJ/dx = Σ_i W_iᵀ ∇v(t_i) with ∇v = ∂v/∂s ∇s + ∂_x v (:meth:`.responses.Response.adjoint_weights`).
The adjoint needs the transposed products (∂v/∂s)ᵀ W_i and (∂_x v)ᵀ W_i, for r responses at once.
Outputs are only available as complex-safe functions v(t, s, params), so:

* the state part is taken by complex step along the state components the output depends on
  (exact to round-off, whatever the partials method);
* the design part uses the run's own design partials (the same perturbed designs and
  difference quotients as the direct mode) along the design variables the output depends on
  explicitly; outputs declared ``linear`` have none.

Which rows of an output depend on which state components and design variables is its
pattern: declared by the model where it knows it (:class:`~dynsens.models.base.OutputPattern`,
e.g. an element's outputs read its own DOFs and parameters), else found once per output by
complex steps along every state component and every design variable at the first state it is
needed at and at two random perturbations of it (generic points).  A dependence that vanishes
at all three points (a branch, e.g. a contact, inactive there) would be missed: the shipped
outputs have none, and the adjoint-against-direct tests on every shipped case would show one.

The probes of a declared pattern are coloured, as sparse Jacobians are (Curtis, Powell & Reid
1974): components (or design variables) on which no row depends together are stepped in one
probe, and each row reads its derivative along its one component of the probe's colour.  An output of k elements
that each read a few DOFs and their own design variables then costs a few probes per instant
(the colours), not the size of the state plus the number of design variables.  A row depends
on one member of a colour only, so its value in the probe is the one it has when that member is
stepped alone: colouring gives the same numbers.  A probed pattern is not coloured (one probe
per component and per variable): what the probes did not see would mix into another column.
Outputs that evaluate batches take all the probes of a block of instants in one call.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..models.base import Model, Output, OutputPattern, StepState
from .partials import DesignPartials, colour_columns

# imaginary step of the state derivatives (complex step: no cancellation, any small size)
STATE_STEP = 1e-30
# relative sizes of the perturbations of the probe states that find undeclared dependencies (the
# state itself, and two random perturbations of it: a dependence that vanishes at one point, a
# derivative zero at rest, shows at the others)
PROBE_SIZES = (0.0, 1e-3, 0.3)
PROBE_CHUNK = 256
# most states in one call of a batched output (instants × probes)
BLOCK_STATES = 4096
# most entries of the dense per-block Jacobian (instants × state components × rows) of a block
BLOCK_ENTRIES = 1 << 22


class _Coloured:
    """The probes of one part (state or design) of an output's derivatives: its columns (flat
    state components or design variables), which rows depend on each, and their colours."""

    def __init__(self, cols: np.ndarray, mask: np.ndarray, groups: list[list[int]] | None):
        self.cols = cols                                    # (P,) the columns
        groups = groups if groups is not None else [[c] for c in range(cols.size)]
        self.groups = groups                                # column positions per colour
        self.colour = np.zeros(cols.size, int)              # colour of each column
        for g, members in enumerate(groups):
            self.colour[members] = g
        # (P, k): the rows each column's probe is read at; a colour of one column keeps all
        # (nothing else was stepped with it)
        alone = np.array([len(groups[g]) == 1 for g in self.colour], bool)
        self.mask = mask | alone[:, None]

    @classmethod
    def of(cls, rows: np.ndarray, cols: np.ndarray, k: int, coloured: bool) -> _Coloured:
        """From the (row, column) pairs of a pattern with k rows; one probe per column unless
        ``coloured``."""
        used = np.unique(cols)
        pos = np.searchsorted(used, cols)
        mask = np.zeros((used.size, k), bool)
        mask[pos, rows] = True
        groups = colour_columns([np.flatnonzero(m) for m in mask], used.size) if coloured else None
        return cls(used, mask, groups)

    @property
    def n(self) -> int:
        """Number of probes (colours)."""
        return len(self.groups)

    def columns(self, per_colour: np.ndarray) -> np.ndarray:
        """(..., P, k) derivatives of every column from those of its colour (..., n, k)."""
        return np.where(self.mask, per_colour[..., self.colour, :], 0.0)


class _Dependence:
    """What one output depends on, and the probes that find its derivatives."""

    def __init__(self, state: _Coloured, design: _Coloured, batch: list[Any], stacked: Any):
        self.state = state          # flat indices into the stacked state (q, q̇, q̈, λ, p, ṗ)
        self.design = design        # the design variables of the differences
        self.batch = batch          # the parameter sets of the design probes (partials' layout)
        self.stacked = stacked      # the same, stacked (None when the model does not stack)
        self.copies: dict[int, Any] = {}    # the batch stacked B times, by B (:meth:`stacked_copies`)

    def stacked_copies(self, model: Any, B: int) -> Any:
        """The output's design probes' parameter sets stacked B times by ``model`` (kept per B)."""
        if B not in self.copies:
            self.copies[B] = model.stack_parameters(self.batch * B)
        return self.copies[B]

    @property
    def probes(self) -> int:
        """Output evaluations per instant: the state's colours and the design batch."""
        return (self.state.n if self.state.cols.size else 0) + len(self.batch)


class OutputSeeds:
    """Transposed output derivatives for the adjoint sweep, for the outputs of a response set.

    Parameters
    ----------
    model : the model (for stacking parameters).
    outputs : the response set's outputs (ids are list indices).
    partials : the run's design partials (perturbed parameter sets, difference method).
    """

    def __init__(self, model: Model, outputs: list[Output], partials: DesignPartials):
        self.model, self.outputs, self.partials = model, outputs, partials
        self.params0 = partials.params0
        self.stacked_one = model.stack_parameters([partials.params0])
        self._deps: dict[int, _Dependence] = {}
        self.evaluations = 0
        self._rng = np.random.default_rng(20261124)

    # ------------------------------------------------------------------ evaluation helpers
    def _eval(self, o: Output, t: float, leaves: list[np.ndarray], params: list[Any],
              stacked: Any) -> np.ndarray:
        """v at E states (flat leaves (E, n_y) split per field) with E parameter sets: (E, k)."""
        E = leaves[0].shape[0] if leaves else 0
        self.evaluations += E
        if o.batched and stacked is not None:
            return np.asarray(o.fn(t, StepState(*leaves), stacked)).reshape(E, -1)
        return np.stack([np.asarray(o.fn(t, StepState(*(v[e] for v in leaves)), params[e]))
                         for e in range(E)])

    def _split(self, Y: np.ndarray, sizes: list[int]) -> list[np.ndarray]:
        """The six state fields of flat states Y (E, n_y)."""
        key = tuple(sizes)
        if getattr(self, "_slices_key", None) != key:
            ends = np.cumsum(sizes).tolist()
            self._slices = [slice(a, b) for a, b in zip([0] + ends[:-1], ends)]
            self._slices_key = key
        return [Y[:, sl] for sl in self._slices]

    def _state_jacobian(self, o: Output, t: float, y: np.ndarray, sizes: list[int],
                        comps: np.ndarray) -> np.ndarray:
        """∂v/∂y[comps] (k, len(comps)) at the flat state y, one complex step per component."""
        cols = []
        for start in range(0, comps.size, PROBE_CHUNK):
            c = comps[start:start + PROBE_CHUNK]
            Y = np.repeat(y.astype(complex)[None, :], c.size, axis=0)
            Y[np.arange(c.size), c] += 1j * STATE_STEP
            F = self._eval(o, t, self._split(Y, sizes), [self.params0] * c.size, self.stacked_one)
            cols.append(np.imag(F).T / STATE_STEP)
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(o.labels), 0))

    def _state_probes(self, o: Output, t: float, Y0: np.ndarray, sizes: list[int], part: _Coloured
                      ) -> np.ndarray:
        """∂v/∂y[part.cols] (B, P, k) at the flat states Y0 (B, n_y): one complex step per
        colour and state (batched outputs: in one call)."""
        B, C, P = Y0.shape[0], part.n, part.cols.size
        Y = np.repeat(Y0.astype(complex), C, axis=0)                              # (B·C, n_y)
        rows = np.repeat(np.arange(B) * C, P) + np.tile(part.colour, B)
        Y[rows, np.tile(part.cols, B)] += 1j * STATE_STEP
        F = self._eval(o, t, self._split(Y, sizes), [self.params0] * (B * C), self.stacked_one)
        return part.columns((np.imag(F) / STATE_STEP).reshape(B, C, -1))

    def _design_quotients(self, F: np.ndarray, dep: _Dependence) -> np.ndarray:
        """∂_x v (P, k) along the output's design variables from its values (G, k) at the
        probes' parameter sets (the partials' differences, one per colour)."""
        p, part = self.partials, dep.design
        G = part.n
        if p.method == "forward":
            D = F[1:] - F[:1]
        elif p.method == "central":
            D = F[:G] - F[G:]
        else:
            D = np.imag(F)
        div = 2.0 * p.h[part.cols] if p.method == "central" else p.h[part.cols]
        return part.columns(np.real(D)) / div[:, None]

    # ------------------------------------------------------------------ dependence
    def _dependence(self, oid: int, t: float, y: np.ndarray, sizes: list[int]) -> _Dependence:
        """The output's pattern (declared, or found once at the state y and two random
        perturbations of it), its probes' colours and its design probes' parameter sets."""
        if oid in self._deps:
            return self._deps[oid]
        o, p = self.outputs[oid], self.partials
        k = len(o.labels)
        # a declared pattern colours the probes; a probed one does not: a row's dependence the
        # probe points missed is still taken uncoloured wherever another row needs its column,
        # coloured it would mix into the derivative along another member of the colour
        declared = o.pattern is not None
        pattern = o.pattern() if o.pattern is not None else self._probed_pattern(o, t, y, sizes)
        state = _Coloured.of(pattern.state_rows, pattern.state_cols, k, declared)
        design = _Coloured.of(pattern.design_rows, pattern.design_cols, k, declared)
        batch = p.perturbed_sets([[int(design.cols[i]) for i in g] for g in design.groups]) \
            if design.cols.size else []
        stacked = self.model.stack_parameters(batch) if batch else None
        dep = self._deps[oid] = _Dependence(state, design, batch, stacked)
        return dep

    def _probed_pattern(self, o: Output, t: float, y: np.ndarray, sizes: list[int]) -> OutputPattern:
        """The pattern of an output that declares none, by complex steps along every state
        component and by the partials along every design variable at y and two perturbations."""
        p = self.partials
        every = np.arange(y.size)
        state = np.zeros((len(o.labels), y.size), bool)
        design = np.zeros((len(o.labels), p.m), bool)
        probes = []
        for size in PROBE_SIZES:
            yp = np.real(y) + size * (1.0 + np.abs(y)) * self._rng.uniform(-1.0, 1.0, y.size)
            probes.append(yp)
            state |= self._state_jacobian(o, t, yp, sizes, every) != 0.0     # NaN counts as a dependence
        if not o.linear and p.m:
            every_x = _Coloured(np.arange(p.m), np.ones((p.m, len(o.labels)), bool), None)
            full = _Dependence(every_x, every_x, p._batch, p._stacked)
            for yp in probes:
                F = self._eval(o, t, self._split(np.repeat(yp[None, :], len(p._batch), axis=0), sizes),
                               p._batch, p._stacked)
                design |= (self._design_quotients(F, full) != 0.0).T
        s_rows, s_cols = np.nonzero(state)
        d_rows, d_cols = np.nonzero(design)
        return OutputPattern(s_rows, s_cols, d_rows, d_cols)

    # ------------------------------------------------------------------ the seeds
    def seeds(self, t: float, s: StepState, weights: dict[int, np.ndarray], r: int
              ) -> tuple[np.ndarray, np.ndarray]:
        """(∂J/∂y (n_y, r), ∂_x J (m, r)) at the state s of time t (s) for the weights
        W[oid] (k, r) of the outputs at this instant (y: the flat state q, q̇, q̈, λ, p, ṗ)."""
        return self.seeds_block([t], [s], [weights], r)[0]

    def seeds_block(self, ts: list[float], states: list[StepState], weights: list[dict[int, np.ndarray]],
                    r: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """:meth:`seeds` at several instants; outputs that evaluate batches and do not depend on
        time explicitly take all instants (and probes) in one call."""
        sizes = [v.shape[0] for v in states[0]]
        ys = [np.concatenate(s) for s in states]
        out = [(np.zeros((y.size, r)), np.zeros((self.partials.m, r))) for y in ys]
        for oid in sorted({o for w in weights for o in w}):
            o = self.outputs[oid]
            at = [b for b, w in enumerate(weights) if oid in w]
            dep = self._dependence(oid, ts[at[0]], ys[at[0]], sizes)
            if o.batched and o.autonomous and self.stacked_one is not None:
                self._block(o, dep, [ys[b] for b in at], [weights[b][oid] for b in at], sizes,
                            [out[b] for b in at])
                continue
            for b in at:
                W, y = weights[b][oid], ys[b]
                if dep.state.cols.size:
                    # (the layout of the per-component Jacobian's transpose: the same products)
                    J = np.asfortranarray(self._state_probes(o, ts[b], y[None, :], sizes, dep.state)[0])
                    out[b][0][dep.state.cols] += J @ W
                if dep.design.cols.size:
                    F = self._eval(o, ts[b], self._split(np.repeat(y[None, :], len(dep.batch), axis=0), sizes),
                                   dep.batch, dep.stacked)
                    out[b][1][dep.design.cols] += self._design_quotients(F, dep) @ W
        return out

    def _block(self, o: Output, dep: _Dependence, ys: list[np.ndarray], Ws: list[np.ndarray],
               sizes: list[int], out: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """Seeds of a batched, autonomous output at several instants, a few calls in all."""
        D, k = dep.state.cols.size, len(o.labels)
        per = max(1, min(BLOCK_STATES // max(dep.probes, 1), BLOCK_ENTRIES // max(D * k, 1)))
        for start in range(0, len(ys), per):
            Y0 = np.stack(ys[start:start + per])                                  # (B, n_y)
            W = np.stack(Ws[start:start + per])                                   # (B, k, r)
            B = Y0.shape[0]
            if D:
                J = self._state_probes(o, 0.0, Y0, sizes, dep.state)              # (B, D, k)
                ybar = np.einsum("bdk,bkr->bdr", J, W)
                for b in range(B):
                    out[start + b][0][dep.state.cols] += ybar[b]
            if dep.design.cols.size:
                P = len(dep.batch)
                Y = np.repeat(Y0, P, axis=0)                                      # (B·P, n_y)
                F = self._eval(o, 0.0, self._split(Y, sizes), [], dep.stacked_copies(self.model, B))
                F = F.reshape(B, P, -1)
                for b in range(B):
                    out[start + b][1][dep.design.cols] += self._design_quotients(F[b], dep) @ W[b]
