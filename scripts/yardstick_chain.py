r"""A minimal Newmark / Newton / direct-differentiation loop for the Duffing chain: the yardstick.

The physics of ``scripts/make_cases.duffing_chain`` (N equal masses m, spring i between u_i and
u_{i-1} with f = k δ + k3 δ³, damper c δ̇, u_0 = ground, tip force 100 sin²(π t / 0.1) N for
0 < t < 0.1 s; m, s, kg, N) with the design x = (m, c, k, k3).  Per step (Newmark β, γ; the
accelerations a are the unknowns, the previous ones the Newton guess):

    q = q_pred + β Δt² a,  v = v_pred + γ Δt a,   R(a) = m a + D v + f_int(q) − f_ext(t) = 0
    S = m I + γ Δt D + β Δt² K_t(q)                (tridiagonal)

and the sensitivities X = ∂(q, v, a)/∂x (N, 4) follow each converged step with the factor of
the last Newton iteration (one correction within the Newton tolerance away):

    S X_a = −(∂R/∂x + K_t X_q,pred + D X_v,pred)

Two linear-algebra variants: SuperLU (``splu``) on a CSC pattern fixed once, only its values
refreshed, and LAPACK's tridiagonal LU (gttrf / gttrs).  This is what a plain loop costs; the
benchmark ``scripts/bench_step_cost.py`` runs it beside dynsens in one process.
Usage: python scripts/yardstick_chain.py [--n 10] [--steps 2000]   (checks against dynsens)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

BETA, GAMMA, DT = 0.25, 0.5, 1.0e-3
RTOL = 1e-10            # Newton: ‖Δa‖ ≤ RTOL · max(‖a‖, largest ‖a‖ so far), as dynsens
X0 = np.array([1.0, 2.0, 1.0e3, 1.0e6])   # (m [kg], c [N s/m], k [N/m], k3 [N/m³])


def tip_force(t: float) -> float:
    """Tip load (N) at time t (s)."""
    return 100.0 * np.sin(np.pi * t / 0.1) ** 2 if 0.0 < t < 0.1 else 0.0


def spread(e: np.ndarray) -> np.ndarray:
    """Nodal forces of element forces e (N,): +e_i on u_i, −e_i on u_{i−1}."""
    out = e.copy()
    out[:-1] -= e[1:]
    return out


class SuperLUSolver:
    """S on a CSC pattern built once (diagonal, sub-, super-diagonal slots); splu per factor."""

    def __init__(self, n: int):
        self.n = n
        i = np.arange(n)
        rows = np.concatenate([i, i[1:], i[:-1]])
        cols = np.concatenate([i, i[:-1], i[1:]])
        self.S = sp.csc_matrix((np.arange(1.0, rows.size + 1), (rows, cols)), shape=(n, n))
        self.S.sort_indices()
        # where each diagonal's entries sit in S.data, found once from the tagged values
        where = np.argsort(self.S.data)
        self.slot_d, self.slot_lo, self.slot_up = where[:n], where[n:2 * n - 1], where[2 * n - 1:]

    def factor(self, diag: np.ndarray, off: np.ndarray) -> None:
        """Factorize S with diagonal ``diag`` (n,) and symmetric off-diagonal ``off`` (n−1,)."""
        data = self.S.data
        data[self.slot_d], data[self.slot_lo], data[self.slot_up] = diag, off, off
        self.lu = spla.splu(self.S, permc_spec="NATURAL")   # tridiagonal: no fill, no ordering

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self.lu.solve(rhs)


class TridiagonalSolver:
    """LAPACK gttrf / gttrs: LU of a tridiagonal matrix with partial pivoting, O(n)."""

    def __init__(self, n: int):
        self.n = n

    def factor(self, diag: np.ndarray, off: np.ndarray) -> None:
        self.lu = lapack.dgttrf(off, diag, off)[:5]

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        dl, d, du, du2, ipiv = self.lu
        return lapack.dgttrs(dl, d, du, du2, ipiv, rhs)[0]


SOLVERS = {"superlu": SuperLUSolver, "tridiagonal": TridiagonalSolver}


def run(n: int, steps: int, x: np.ndarray = X0, solver: str = "superlu", gradient: bool = True
        ) -> tuple[np.ndarray, np.ndarray | None, dict[str, int]]:
    """March the chain; return (tip_end, tip_integral), their gradients (2, 4) or None, counters.

    tip_end = u_N(t_end) (m); tip_integral = trapezoidal ∫ u_N dt (m s), as dynsens' responses.
    """
    m, c, k, k3 = (float(v) for v in x)
    lin = SOLVERS[solver](n)
    q, v, a = np.zeros(n), np.zeros(n), np.zeros(n)   # at rest, no load at t0: a0 = 0
    Xq, Xv, Xa = np.zeros((n, 4)), np.zeros((n, 4)), np.zeros((n, 4))
    fext = np.zeros(n)
    scale = 0.0
    integral, Xint = 0.0, np.zeros(4)
    counts = {"newton_iterations": 0, "factorizations": 0}
    h2b, hg = BETA * DT * DT, GAMMA * DT
    for i in range(1, steps + 1):
        t = i * DT
        qp = q + DT * v + (0.5 - BETA) * DT * DT * a
        vp = v + (1.0 - GAMMA) * DT * a
        fext[-1] = tip_force(t)
        tip_before = q[-1]
        for _ in range(25):
            q, v = qp + h2b * a, vp + hg * a
            dq = np.diff(q, prepend=0.0)
            dv = np.diff(v, prepend=0.0)
            R = m * a + spread(k * dq + k3 * dq * dq * dq + c * dv) - fext
            kt = k + 3.0 * k3 * dq * dq
            e = hg * c + h2b * kt                      # per element: its share of S
            diag = m + e
            diag[:-1] += e[1:]
            lin.factor(diag, -e[1:])
            counts["factorizations"] += 1
            da = lin.solve(-R)
            a = a + da
            counts["newton_iterations"] += 1
            na = float(np.linalg.norm(a))
            scale = max(scale, na)
            if np.linalg.norm(da) <= RTOL * max(na, scale):
                break
        else:
            raise RuntimeError(f"Newton did not converge at t = {t:g} s")
        q, v = qp + h2b * a, vp + hg * a
        integral += 0.5 * DT * (tip_before + q[-1])
        if not gradient:
            continue
        Xqp = Xq + DT * Xv + (0.5 - BETA) * DT * DT * Xa
        Xvp = Xv + (1.0 - GAMMA) * DT * Xa
        dq = np.diff(q, prepend=0.0)
        dv = np.diff(v, prepend=0.0)
        # explicit partials ∂R/∂(m, c, k, k3) at the converged state, then the state terms
        P = np.column_stack([a, spread(dv), spread(dq), spread(dq * dq * dq)])
        kt = k + 3.0 * k3 * dq * dq
        P += spread_rows(kt[:, None] * np.diff(Xqp, axis=0, prepend=0.0)) \
            + spread_rows(c * np.diff(Xvp, axis=0, prepend=0.0))
        tip_x_before = Xq[-1].copy()
        Xa = lin.solve(-P)                             # all four columns in one call
        Xq, Xv = Xqp + h2b * Xa, Xvp + hg * Xa
        Xint += 0.5 * DT * (tip_x_before + Xq[-1])
    values = np.array([q[-1], integral])
    return values, (np.vstack([Xq[-1], Xint]) if gradient else None), counts


def spread_rows(E: np.ndarray) -> np.ndarray:
    """:func:`spread` for element values E (N, k): rows are elements."""
    out = E.copy()
    out[:-1] -= E[1:]
    return out


def dynsens_case_dict(n: int, steps: int, partials: str = "forward") -> dict:
    """The same chain as a dynsens case dict (scripts/make_cases.duffing_chain), no histories,
    responses tip_end and tip_integral."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from make_cases import duffing_chain
    d = duffing_chain(n, t_end=steps * DT)
    d["sensitivity"]["partials"] = partials
    d["output"] = {"history": "none"}
    d["responses"] = [r for r in d["responses"] if r["name"] in ("tip_end", "tip_integral")]
    return d


def dynsens_case(n: int, steps: int, partials: str = "forward"):
    """:func:`dynsens_case_dict`, loaded."""
    import dynsens
    return dynsens.load_case_dict(dynsens_case_dict(n, steps, partials))


def compare_with_dynsens(n: int, steps: int) -> dict[str, float]:
    """Largest relative differences of values and gradients (both responses, both solvers)
    against dynsens with complex-step design partials (exact to round-off, as the yardstick's
    analytic ones)."""
    import dynsens
    res = dynsens.run_case(dynsens_case(n, steps, "complex"), sensitivities=True, history=())
    ref_v = np.array([res.responses[r].value for r in ("tip_end", "tip_integral")]).real
    ref_g = np.array([res.responses[r].gradient for r in ("tip_end", "tip_integral")]).real
    out = {}
    for solver in SOLVERS:
        val, grad, _ = run(n, steps, solver=solver)
        out[f"{solver} value"] = float(np.max(np.abs(val - ref_v) / np.abs(ref_v)))
        out[f"{solver} gradient"] = float(np.max(np.abs(grad - ref_g)) / np.max(np.abs(ref_g)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=10)
    ap.add_argument("--steps", type=int, default=2000)
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    for key, err in compare_with_dynsens(args.n, args.steps).items():
        print(f"N = {args.n}, {args.steps} steps, {key}: largest relative difference to dynsens {err:.1e}")


if __name__ == "__main__":
    main()
