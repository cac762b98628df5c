r"""The adjoint seeds of the outputs: ∂(wᵀv)/∂state and ∂_x(wᵀv) at one instant.

A response's gradient is a weighted sum of its outputs' total gradients,
dJ/dx = Σ_i W_iᵀ ∇v(t_i) with ∇v = ∂v/∂s ∇s + ∂_x v (:meth:`.responses.Response.adjoint_weights`).
The adjoint needs the transposed products (∂v/∂s)ᵀ W_i and (∂_x v)ᵀ W_i, for r responses at once.
Outputs are only available as complex-safe functions v(t, s, params), so:

* the state part is taken by complex step along the state components the output depends on
  (exact to round-off, whatever the partials method); the dependency is found once per output,
  by complex steps along every state component at the first state it is needed at and at two
  random perturbations of it (generic points: an output of k components of a few coordinates
  then costs a few evaluations per instant, not the size of the state).  A dependence that
  vanishes at all three points (a branch, e.g. a contact, inactive there) would be missed:
  the shipped outputs have none, and the adjoint-against-direct tests on every shipped case
  would show one;
* the design part uses the run's own design partials (the same perturbed parameter sets and
  difference quotients as the direct mode), restricted to the design variables the output
  depends on explicitly, found the same way; outputs declared ``linear`` have none.

Both are one call per instant for outputs that evaluate batches.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..models.base import Model, Output, StepState
from .partials import DesignPartials

# imaginary step of the state derivatives (complex step: no cancellation, any small size)
STATE_STEP = 1e-30
# relative sizes of the perturbations of the probe states that find the dependencies (the state
# itself, and two random perturbations of it: a dependence that vanishes at one point, a
# derivative zero at rest, shows at the others)
PROBE_SIZES = (0.0, 1e-3, 0.3)
PROBE_CHUNK = 256
# most states in one call of a batched output (instants × directions)
BLOCK_STATES = 4096


class _Dependence:
    """What one output depends on: flat state components and explicit design entries."""

    def __init__(self, state: np.ndarray, batch: list[Any], stacked: Any, cols: np.ndarray,
                 entries: np.ndarray):
        self.state = state          # flat indices into the stacked state (q, q̇, q̈, λ, p, ṗ)
        self.batch = batch          # the partials' parameter sets it needs (reduced)
        self.stacked = stacked      # the same, stacked (None when the model does not stack)
        self.cols = cols            # the design variables of the differences
        self.entries = entries      # the batch entries (into the partials' batch)
        self.copies: dict[int, Any] = {}    # the batch stacked B times, by B (:meth:`stacked_copies`)
        self.pattern = np.zeros((0, state.size), bool)   # which outputs depend on which of ``state``
        self.colour = np.zeros(state.size, int)          # probe colour of each of ``state``

    def stacked_copies(self, model: Any, B: int) -> Any:
        """The output's reduced parameter sets stacked B times by ``model`` (kept per B)."""
        if B not in self.copies:
            self.copies[B] = model.stack_parameters(self.batch * B)
        return self.copies[B]


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
        """∂v/∂y[comps] (k, len(comps)) at the flat state y, by complex step."""
        cols = []
        for start in range(0, comps.size, PROBE_CHUNK):
            c = comps[start:start + PROBE_CHUNK]
            Y = np.repeat(y.astype(complex)[None, :], c.size, axis=0)
            Y[np.arange(c.size), c] += 1j * STATE_STEP
            F = self._eval(o, t, self._split(Y, sizes), [self.params0] * c.size, self.stacked_one)
            cols.append(np.imag(F).T / STATE_STEP)
        return np.concatenate(cols, axis=1) if cols else np.zeros((len(o.labels), 0))

    def _design_values(self, o: Output, t: float, y: np.ndarray, sizes: list[int],
                       dep: _Dependence) -> np.ndarray:
        """v at the state y for each parameter set of the output's reduced batch: (B, k)."""
        B = len(dep.batch)
        Y = np.repeat(y[None, :], B, axis=0)
        return self._eval(o, t, self._split(Y, sizes), dep.batch, dep.stacked)

    def _design_partial(self, F: np.ndarray, dep: _Dependence) -> np.ndarray:
        """∂_x v (k, len(cols)) from the values of the reduced batch (the partials' differences)."""
        p, n = self.partials, dep.cols.size
        if p.method == "forward":
            D = F[1:] - F[:1]
        elif p.method == "central":
            D = F[:n] - F[n:]
        else:
            D = np.imag(F)
        div = 2.0 * p.h[dep.cols] if p.method == "central" else p.h[dep.cols]
        return (D / div[:, None]).T

    # ------------------------------------------------------------------ dependence
    def _dependence(self, oid: int, t: float, y: np.ndarray, sizes: list[int]) -> _Dependence:
        """Found once per output at two perturbed copies of the state y (generic points)."""
        if oid in self._deps:
            return self._deps[oid]
        o, p = self.outputs[oid], self.partials
        every = np.arange(y.size)
        hit = np.zeros(y.size, bool)
        pattern = np.zeros((len(o.labels), y.size), bool)
        probes = []
        for size in PROBE_SIZES:
            yp = np.real(y) + size * (1.0 + np.abs(y)) * self._rng.uniform(-1.0, 1.0, y.size)
            probes.append(yp)
            J = self._state_jacobian(o, t, yp, sizes, every)
            pattern |= J != 0.0                      # NaN counts as a dependence
        hit = np.any(pattern, axis=0)
        state = np.flatnonzero(hit)
        cols = np.zeros(0, int)
        if not o.linear:
            full = _Dependence(state, p._batch, p._stacked, np.arange(p.m), np.arange(len(p._batch)))
            used = np.zeros(p.m, bool)
            for yp in probes:
                D = self._design_partial(self._design_values(o, t, yp, sizes, full), full)
                used |= np.any(D != 0.0, axis=0)
            cols = np.flatnonzero(used)
        entries = self._entries(cols)
        batch = [p._batch[e] for e in entries]
        stacked = self.model.stack_parameters(batch) if cols.size else None
        dep = _Dependence(state, batch, stacked, cols, entries)
        dep.pattern = pattern[:, state]
        dep.colour = probe_colours(dep.pattern)
        self._deps[oid] = dep
        return dep

    def _entries(self, cols: np.ndarray) -> np.ndarray:
        """The partials' batch entries of the design variables ``cols`` (and the base entry of
        forward differences), in the order :meth:`_design_partial` expects."""
        m = self.partials.m
        if not cols.size:
            return np.zeros(0, int)
        if self.partials.method == "forward":
            return np.concatenate([[0], 1 + cols])
        if self.partials.method == "central":
            return np.concatenate([cols, m + cols])
        return cols

    # ------------------------------------------------------------------ the seeds
    def seeds(self, t: float, s: StepState, weights: dict[int, np.ndarray], r: int
              ) -> tuple[np.ndarray, np.ndarray]:
        """(∂J/∂y (n_y, r), ∂_x J (m, r)) at the state s of time t (s) for the weights
        W[oid] (k, r) of the outputs at this instant (y: the flat state q, q̇, q̈, λ, p, ṗ)."""
        return self.seeds_block([t], [s], [weights], r)[0]

    def seeds_block(self, ts: list[float], states: list[StepState], weights: list[dict[int, np.ndarray]],
                    r: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """:meth:`seeds` at several instants; outputs that evaluate batches and do not depend on
        time explicitly take all instants (and directions) in one call."""
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
                if dep.state.size:
                    out[b][0][dep.state] += self._state_jacobian(o, ts[b], y, sizes, dep.state).T @ W
                if dep.cols.size:
                    D = self._design_partial(self._design_values(o, ts[b], y, sizes, dep), dep)
                    out[b][1][dep.cols] += np.real(D).T @ W
        return out

    def _block(self, o: Output, dep: _Dependence, ys: list[np.ndarray], Ws: list[np.ndarray],
               sizes: list[int], out: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """Seeds of a batched, autonomous output at several instants, a few calls in all."""
        D, P = dep.state.size, len(dep.batch)
        per = max(1, BLOCK_STATES // max(D, P, 1))
        for start in range(0, len(ys), per):
            Y0 = np.stack(ys[start:start + per])                                  # (B, n_y)
            W = np.stack(Ws[start:start + per])                                   # (B, k, r)
            B = Y0.shape[0]
            if D:
                # one probe per colour: components of a colour share no output, so each output's
                # imaginary part is its derivative along the one component of the colour it has
                C = int(dep.colour.max()) + 1
                Y = np.repeat(Y0.astype(complex), C, axis=0)                      # (B·C, n_y)
                rows = np.repeat(np.arange(B) * C, D) + np.tile(dep.colour, B)
                Y[rows, np.tile(dep.state, B)] += 1j * STATE_STEP
                F = self._eval(o, 0.0, self._split(Y, sizes), [], self.stacked_one)
                Jc = (np.imag(F) / STATE_STEP).reshape(B, C, -1)                  # (B, C, k)
                J = Jc[:, dep.colour, :] * dep.pattern.T[None]                    # (B, D, k)
                ybar = np.einsum("bdk,bkr->bdr", J, W)
                for b in range(B):
                    out[start + b][0][dep.state] += ybar[b]
            if dep.cols.size:
                Y = np.repeat(Y0, P, axis=0)                                      # (B·P, n_y)
                F = self._eval(o, 0.0, self._split(Y, sizes), [], dep.stacked_copies(self.model, B))
                F = F.reshape(B, P, -1)
                for b in range(B):
                    Dx = self._design_partial(F[b], dep)                          # (k, cols)
                    out[start + b][1][dep.cols] += np.real(Dx).T @ W[b]


def probe_colours(pattern: np.ndarray) -> np.ndarray:
    """A colour per column of the dependence pattern (outputs × components, bool) such that no
    output depends on two components of one colour (greedy, in column order): a complex step
    along all components of a colour at once gives every output's derivative along its one."""
    k, D = pattern.shape
    colour = np.zeros(D, int)
    taken: list[np.ndarray] = []            # the outputs touched by each colour
    for d in range(D):
        rows = pattern[:, d]
        for c, used in enumerate(taken):
            if not np.any(used & rows):
                used |= rows
                colour[d] = c
                break
        else:
            colour[d] = len(taken)
            taken.append(rows.copy())
    return colour
