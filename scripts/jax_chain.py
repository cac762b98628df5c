r"""The Duffing chain as a compiled JAX scan: the peer of issue 35's target table.

The physics and the scheme of ``yardstick_chain.py`` (Newmark β = ¼, γ = ½, Δt = 1 ms; the
accelerations are the unknowns, Newton on R(a) = m a + D v + f_int(q) − f_ext(t) with the
tridiagonal S = m I + γ Δt D + β Δt² K_t, tolerance ‖Δa‖ ≤ 1e-10 · max(‖a‖, largest ‖a‖ so far),
as dynsens), written once in JAX: the whole time loop is one ``jax.lax.scan`` under ``jax.jit``,
each step's Newton iteration a ``lax.while_loop``.  Derivatives are those of the converged steps
(implicit differentiation, ``lax.custom_root``: the tangent solve is one tridiagonal solve with
the Newton matrix, recovered from three products of the linearized residual, columns coloured
mod 3), so forward (``jax.jacfwd``) and reverse mode (``jax.grad``) both give dynsens' discrete
derivative, not the derivative of a truncated iteration.

Designs: the shared (m, c, k, k3) of ``make_cases.duffing_chain`` (``per_element=False``) or one
linear stiffness k_i per spring with m = 1, c = 2, k3 = 1e6 (``bench_peers.chain_case``'s
per-element chain).  The response is the tip displacement at the last step (m).

JAX is optional (``pip install 'dynsens[peers]'``); :data:`AVAILABLE` says whether it imported.
Usage: python scripts/jax_chain.py [--n 10] [--steps 2000]   (prints the tip and its gradient)
"""
from __future__ import annotations

import argparse
import os
from typing import Any, Callable

# one XLA thread: CPU time is then comparable with dynsens' single-threaded BLAS
os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import numpy as np  # noqa: E402
import yardstick_chain as ys  # noqa: E402

try:  # optional peer
    import jax
    import jax.numpy as jnp
    from jax import lax
    jax.config.update("jax_enable_x64", True)
    AVAILABLE = True
except ImportError:  # pragma: no cover - depends on the environment
    AVAILABLE = False

MISSING = "JAX not installed (pip install 'dynsens[peers]')"
MAX_NEWTON = 25
PER_ELEMENT_BASE = (1.0, 2.0, 1.0e6)    # m (kg), c (N s/m), k3 (N/m³) of the per-element chain


def _spread(e: Any) -> Any:
    """Nodal forces of element forces e (N,): +e_i on u_i, −e_i on u_{i−1}."""
    return e - jnp.concatenate([e[1:], jnp.zeros(1, dtype=e.dtype)])


def _element_params(x: Any, n: int, per_element: bool) -> tuple[Any, Any, Any, Any]:
    """(mass, c, k, k3), each broadcastable to (n,), for the design x."""
    if per_element:
        m, c, k3 = PER_ELEMENT_BASE
        return m, c, x, k3
    return x[0], x[1], x[2], x[3]


def tip_end_function(n: int, steps: int, per_element: bool = False) -> Callable[[Any], Any]:
    """The compiled map design x -> tip displacement u_N at t = steps · Δt (m).

    Parameters
    ----------
    n : number of masses.
    steps : number of Newmark steps of Δt = 1 ms.
    per_element : design k_1..k_n (True) or (m, c, k, k3) (False).
    """
    if not AVAILABLE:
        raise RuntimeError(MISSING)
    dt, beta, gamma = ys.DT, ys.BETA, ys.GAMMA
    h2b, hg = beta * dt * dt, gamma * dt
    times = dt * jnp.arange(1, steps + 1)
    probes = (jnp.arange(n)[None, :] % 3 == jnp.arange(3)[:, None]).astype(jnp.float64)

    def tip_force(t: Any) -> Any:
        return jnp.where((t > 0.0) & (t < 0.1), 100.0 * jnp.sin(jnp.pi * t / 0.1) ** 2, 0.0)

    def step_residual(params: tuple[Any, ...], qp: Any, vp: Any, fext: Any, a: Any) -> Any:
        m, c, k, k3 = params
        q, v = qp + h2b * a, vp + hg * a
        dq = jnp.diff(q, prepend=0.0)
        dv = jnp.diff(v, prepend=0.0)
        return m * a + _spread(k * dq + k3 * dq ** 3 + c * dv) - fext

    def newton_matrix(params: tuple[Any, ...], qp: Any, a: Any) -> tuple[Any, Any, Any]:
        """Sub-, main and super-diagonal of S at a (the form of ``tridiagonal_solve``)."""
        m, c, k, k3 = params
        dq = jnp.diff(qp + h2b * a, prepend=0.0)
        e = jnp.broadcast_to(hg * c + h2b * (k + 3.0 * k3 * dq * dq), (n,))
        diag = m + e + jnp.concatenate([e[1:], jnp.zeros(1)])
        off = -e[1:]
        return jnp.concatenate([jnp.zeros(1), off]), diag, jnp.concatenate([off, jnp.zeros(1)])

    def tridiag_solve(dl: Any, d: Any, du: Any, b: Any) -> Any:
        return lax.linalg.tridiagonal_solve(dl, d, du, b[:, None])[:, 0]

    def tangent_solve(g: Callable[[Any], Any], y: Any) -> Any:
        # S from three products of the linearized residual: column j of S has rows j−1..j+1,
        # so columns j ≡ r (mod 3) do not overlap in the product with probe r
        cols = jnp.stack([g(p) for p in probes])            # (3, n): S @ probe_r
        j = jnp.arange(n)
        d = cols[j % 3, j]
        dl = jnp.where(j > 0, cols[(j - 1) % 3, j], 0.0)
        du = jnp.where(j < n - 1, cols[(j + 1) % 3, j], 0.0)
        return tridiag_solve(dl, d, du, y)

    def step(carry: tuple[Any, ...], t: Any, params: tuple[Any, ...]) -> tuple[tuple[Any, ...], None]:
        q, v, a, scale = carry
        qp = q + dt * v + (0.5 - beta) * dt * dt * a
        vp = v + (1.0 - gamma) * dt * a
        fext = jnp.zeros(n).at[-1].set(tip_force(t))
        residual = lambda a_: step_residual(params, qp, vp, fext, a_)  # noqa: E731

        def newton(f: Callable[[Any], Any], a0: Any) -> Any:
            def cond(state: tuple[Any, ...]) -> Any:
                return ~state[1] & (state[2] < MAX_NEWTON)

            def body(state: tuple[Any, ...]) -> tuple[Any, ...]:
                a_, _, it, sc = state
                da = tridiag_solve(*newton_matrix(params, qp, a_), -f(a_))
                a_ = a_ + da
                na = jnp.linalg.norm(a_)
                sc = jnp.maximum(sc, na)
                return a_, jnp.linalg.norm(da) <= ys.RTOL * sc, it + 1, sc

            init = (a0, jnp.array(False), jnp.array(0), lax.stop_gradient(scale))
            return lax.while_loop(cond, body, init)[0]

        a_new = lax.custom_root(residual, a, newton, tangent_solve)
        scale = jnp.maximum(scale, lax.stop_gradient(jnp.linalg.norm(a_new)))
        return (qp + h2b * a_new, vp + hg * a_new, a_new, scale), None

    def tip_end(x: Any) -> Any:
        params = _element_params(x, n, per_element)
        zero = jnp.zeros(n, dtype=jnp.result_type(x))
        carry, _ = lax.scan(lambda c, t: step(c, t, params), (zero, zero, zero, jnp.array(0.0)), times)
        return carry[0][-1]

    return tip_end


class JaxChain:
    """The compiled primal, forward-mode and reverse-mode gradient of the chain's tip.

    Each call blocks until JAX has finished, so that it can be timed; :meth:`warm_up` compiles
    all three before any timing.
    """

    def __init__(self, n: int, steps: int, per_element: bool = False):
        f = tip_end_function(n, steps, per_element)
        self._primal = jax.jit(f)
        # the value comes with the derivative, in one compiled call
        self._forward = jax.jit(jax.jacfwd(lambda x: (f(x), f(x)), has_aux=True))
        self._reverse = jax.jit(jax.value_and_grad(f))

    def primal(self, x: np.ndarray) -> float:
        """Tip displacement at t_end (m)."""
        return float(self._primal(jnp.asarray(x)).block_until_ready())

    def forward(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Tip displacement and its gradient by forward mode (``jacfwd``), one compiled call."""
        g, value = jax.block_until_ready(self._forward(jnp.asarray(x)))
        return float(value), np.asarray(g)

    def reverse(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Tip displacement and its gradient by reverse mode (``value_and_grad``), one compiled call."""
        value, g = jax.block_until_ready(self._reverse(jnp.asarray(x)))
        return float(value), np.asarray(g)

    def warm_up(self, x: np.ndarray, modes: tuple[str, ...] = ("forward", "reverse")) -> None:
        """Compile the primal and the named gradient modes (untimed)."""
        self.primal(x)
        for mode in modes:
            getattr(self, mode)(x)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=10)
    ap.add_argument("--steps", type=int, default=2000)
    args = ap.parse_args()
    chain = JaxChain(args.n, args.steps)
    value, g_fwd = chain.forward(ys.X0)
    _, g_rev = chain.reverse(ys.X0)
    print(f"tip_end = {value:.12g} m; jacfwd {g_fwd}; grad {g_rev}")


if __name__ == "__main__":
    main()
