r"""The compiled evaluation of :mod:`.kernel`'s kinematics, and the cache of kinematics per model.

:class:`CompiledKin` is :class:`.kernel.Kin` evaluated by the compiled kernel (:mod:`.compiled`)
for states and parameter sets in double precision, real or complex; :class:`KinCache` keeps the
last few evaluations of a model and chooses the kernel once per model (``DYNSENS_KERNEL``);
large blocks of states take their arrays from a :class:`BufferPool`.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import compiled as cc
from .kernel import KParams, Kin, Layout

Array = np.ndarray


class BufferPool:
    """Flat arrays kept for the kinematics of blocks of states (many states and parameter sets
    per call, megabytes per block).  Allocated afresh every block, such arrays are returned to
    the operating system and mapped again, page by page, at the next block; kept, they are
    written in place.  A buffer is handed out again only when no array made from it is alive
    (its reference count is back to the pool's own), so the reuse cannot be observed."""

    def __init__(self, limit: int = 4):
        self.limit = limit
        # the count of a buffer nothing else refers to, measured as take() measures it (the
        # interpreter's own references differ between versions)
        self._buffers: list[Array] = [np.empty(0)]
        self._free_refs = self._refs(0)
        self._buffers.clear()

    def _refs(self, i: int) -> int:
        return sys.getrefcount(self._buffers[i])

    def take(self, size: int, dtype: Any) -> Array:
        """A flat array of ``size`` entries of ``dtype`` (contents undefined)."""
        dtype = np.dtype(dtype)
        for i in range(len(self._buffers)):
            if self._buffers[i].dtype != dtype or self._refs(i) > self._free_refs:
                continue
            if self._buffers[i].size < size:     # free but too small: replace it
                self._buffers[i] = np.empty(size, dtype)
            return self._buffers[i][:size]
        buf = np.empty(size, dtype)
        if len(self._buffers) < self.limit:      # beyond the limit: an ordinary array
            self._buffers.append(buf)
        return buf[:size]


# batch entries from which a kinematics call takes its arrays from the model's pool (a block of
# steps with its parameter sets; single states and small batches allocate, cheaply)
POOL_MIN_ENTRIES = 64


def _is_block(n_states: int, n_sets: int) -> bool:
    """Whether kinematics of n_states states and n_sets parameter sets form a pooled block."""
    return max(n_states, n_sets) >= POOL_MIN_ENTRIES


def _writeable(a: Array) -> Array:
    """``a``, or a copy of it where it is read-only (the same numbers)."""
    return a if a.flags.writeable else a.copy()


class CompiledKin(Kin):
    """:class:`Kin` of states and parameter sets (real or complex) evaluated by the compiled
    kernel (:mod:`.compiled`); same attributes and shapes (leading axis B = max(Bs, Bp)).  With
    a ``pool``, a large batch takes its arrays from it (:class:`BufferPool`)."""

    def __init__(self, lay: Layout, kp: KParams, q: Array, qd: Array, qdd: Array,
                 pool: BufferPool | None = None, computed: tuple | None = None):
        self.lay, self.kp = lay, kp
        self.dtype = dt = np.result_type(q, qd, qdd, kp.pv)          # float64 or complex128
        self.arrays = lay.compiled_arrays()
        self.params = compiled_params(kp, dt)
        # contiguous, writeable, in one dtype: one compiled specialization per dtype (numba types a
        # read-only view, e.g. a broadcast state, as another array: tests/test_one_signature.py)
        q, qd, qdd = (_writeable(np.ascontiguousarray(a, dt)) for a in (q, qd, qdd))
        self.q, self.qd = q, qd
        if computed is None:
            computed = self._compute(q, qd, qdd, pool)
        (self.Lp, self.Lr, self.C, self.PV, self.ABV, self.X, self.N) = computed
        self.AV, self.BV = self.ABV[:, 0], self.ABV[:, 1]
        self._rows = None

    def _compute(self, q: Array, qd: Array, qdd: Array, pool: BufferPool | None) -> tuple:
        """The compiled kernel's arrays at the states (a large batch's in arrays of the pool)."""
        lay, cl, ck, dt = self.lay, self.arrays, self.params, self.dtype
        args = (q, qd, qdd, cl.pb, cl.is_point, ck.Ts4, cl.side_ptr, cl.side_prim, cl.side_coef, ck.cAB,
                cl.norm_body)
        B = max(q.shape[0], ck.Ts4.shape[0])
        if pool is None or not _is_block(q.shape[0], ck.Ts4.shape[0]):
            return cc.kinematics(*args)  # type: ignore[no-any-return]
        n_b, n_t, n_prod = lay.n_b, lay.n_t, ck.cAB.shape[2]
        shapes = [(B, 3, n_b, 4), (B, 3, n_b, 3), (B, n_t, 3, 4, 3), (B, n_t, 3, 3),
                  (B, 2, n_prod, 3, 3), (B, n_prod, 3), (B, cl.norm_body.shape[0], 3)]
        sizes = [int(np.prod(sh)) for sh in shapes]
        flat = pool.take(sum(sizes), dt)
        ends = np.cumsum(sizes)
        out = tuple(flat[e - n:e].reshape(sh) for e, n, sh in zip(ends, sizes, shapes))
        cc.kinematics_into(*args, *out)
        return out


@dataclass
class CompiledParams:
    """Parameter sets in the form of the compiled kernel (leading axis B), in one dtype."""

    Ts4: Array           # (B, n_t, 3, 4, 4)
    cAB: Array           # (B, 2, n_prod, 3) constant parts of both sides
    mass: Array          # (B, n_b)
    J: Array             # (B, n_b, 3, 3)
    ax_c: Array          # (B, n_ax, n_c) the axial elements' constants, zero-padded
    rot_c: Array         # (B, n_rot, 3) the rotational spring-dampers' k, c, θ_0


def compiled_params(kp: KParams, dtype: Any) -> CompiledParams:
    """:class:`CompiledParams` of the parameter sets in ``dtype`` (float64 or complex128; cached
    on kp per dtype)."""
    cache = kp.cache.compiled
    hit = cache.get(np.dtype(dtype).char)
    if hit is None:
        ax_c = np.zeros((kp.B, len(kp.ec), max([10] + [c.shape[-1] for c in kp.ec])), dtype)
        for i, c in enumerate(kp.ec):
            ax_c[:, i, :c.shape[-1]] = c
        hit = cache[np.dtype(dtype).char] = CompiledParams(
            np.ascontiguousarray(kp.Ts4, dtype), np.ascontiguousarray(np.stack([kp.cA, kp.cB], axis=1), dtype),
            np.ascontiguousarray(kp.mass, dtype), np.ascontiguousarray(kp.J, dtype), ax_c,
            np.ascontiguousarray(kp.rc, dtype))
    return hit


_COMPILED_DTYPES = (np.dtype(np.float64), np.dtype(np.complex128))


def _use_compiled(kp: KParams, q: Array, qd: Array, qdd: Array) -> bool:
    """States (Bs, n_q) and parameter sets in double precision, real or complex: the compiled
    kernel serves."""
    return (q.dtype in _COMPILED_DTYPES and qd.dtype in _COMPILED_DTYPES and qdd.dtype in _COMPILED_DTYPES
            and kp.pv.dtype in _COMPILED_DTYPES)


class KinCache:
    """The last few :class:`Kin` by state and parameter identity, then by state content
    (residual and linearize, outputs and monitors are evaluated at the same states).  State
    arrays are treated as immutable: the solver creates new ones for every iterate."""

    def __init__(self, lay: Layout, size: int = 4):
        self.lay, self.size = lay, size
        self.compiled = cc.enabled()        # decided once per model (DYNSENS_KERNEL)
        # (key, the state's arrays, Kin); a kept entry's key is formed when first compared
        self._items: list[tuple[tuple[Any, ...] | None, tuple[Array, Array, Array], Kin]] = []
        self.pool = BufferPool()

    def put(self, kp: KParams, q: Array, qd: Array, qdd: Array, computed: tuple) -> None:
        """Keep the kinematics at one state (each (n_q,)) that the compiled kernel ``computed``
        (:func:`.compiled.kinematics`' arrays) as :meth:`get` would have made them."""
        if self.compiled:
            self._insert(kp, q, qd, qdd, computed)

    def get(self, kp: KParams, q: Array, qd: Array, qdd: Array) -> Kin:
        """Kin at states (each (n_q,) or (Bs, n_q)) for parameters kp."""
        # the same array objects (the solver's state of this step) first: no hashing; an
        # entry keeps its arrays alive, so their identities cannot be reused meanwhile
        for _, src, kin in self._items:
            if src[0] is q and src[1] is qd and src[2] is qdd and kin.kp is kp:
                return kin
        key = self._key(kp, q, qd, qdd)
        for i, (k, src, kin) in enumerate(self._items):
            if k is None:
                k = self._key(kin.kp, *src)
                self._items[i] = (k, src, kin)
            if k == key and kin.kp is kp:
                return kin
        return self._insert(kp, q, qd, qdd, None, key)

    @staticmethod
    def _key(kp: KParams, q: Array, qd: Array, qdd: Array) -> tuple[Any, ...]:
        q2 = q if q.ndim == 2 else q[None]
        return (id(kp), q2.shape, q2.dtype.char, qd.dtype.char, qdd.dtype.char,
                q.tobytes(), qd.tobytes(), qdd.tobytes())

    def _insert(self, kp: KParams, q: Array, qd: Array, qdd: Array, computed: tuple | None,
                key: tuple[Any, ...] | None = None) -> Kin:
        q2 = q if q.ndim == 2 else q[None]
        qd2 = qd if qd.ndim == 2 else qd[None]
        qdd2 = qdd if qdd.ndim == 2 else qdd[None]
        if _is_block(q2.shape[0], kp.B):
            # an earlier block's states are not evaluated again: release their arrays to the pool
            self._items = [it for it in self._items if not _is_block(it[2].q.shape[0], it[2].kp.B)]
        kin = CompiledKin(self.lay, kp, q2, qd2, qdd2, self.pool, computed) \
            if self.compiled and _use_compiled(kp, q2, qd2, qdd2) else Kin(self.lay, kp, q2, qd2, qdd2)
        if key is None and computed is None:
            key = self._key(kp, q, qd, qdd)
        self._items.insert(0, (key, (q, qd, qdd), kin))
        del self._items[self.size:]
        return kin
