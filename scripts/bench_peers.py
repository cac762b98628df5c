"""Time dynsens against what a user would otherwise do to get the same gradient.

Peers, each for the primal run and for primal + gradient of one response:

  dynsens DDM        one run with direct-differentiation sensitivities (the case's partials)
  dynsens FD fwd     forward differences of the whole simulation, m + 1 runs
  dynsens FD cen     central differences of the whole simulation, 2m + 1 runs
  dynsens CS         complex step of the whole simulation, 1 + m runs (m complex); it is also
                     the reference of the discrete gradient (errors of the "discrete" column)
  solve_ivp FD fwd   the same Duffing chain as a first-order ODE, scipy Radau with analytic
                     sparse Jacobian, m + 1 runs (chains only)
  CasADi fsens       the same ODE as a CasADi CVODES integrator (BDF/Newton), primal call
                     plus forward sensitivities in m directions (chains only; optional
                     extra ``pip install 'dynsens[peers]'``, skipped with a message)

Cases: Duffing chains with N = 10, 100, 1000 masses (scripts/make_cases.duffing_chain), with
the 4 shared design variables (m, c, k, k3) and with m = N per-element linear stiffnesses
k_1..k_N; and cases/slider_crank.yaml (4 variables).  Response: the tip displacement at
t_end (``tip_end``; slider crank: ``slider_x_end``).

Two error columns (relative 2-norm error of the gradient):

  discrete     against the complex step of dynsens's own Newmark solution: the error of the
               differentiation method alone (dynsens rows only)
  continuous   against a tight-tolerance solution of the ODE and its forward sensitivity
               equations (DOP853, rtol 1e-12): includes each method's time-discretization
               error, so dynsens, solve_ivp and CasADi are compared at equal footing.

The tolerances of solve_ivp and CasADi are calibrated per N (on the 4-variable chain): the
loosest rtol in 1e-3 ... 1e-10 whose gradient error (solve_ivp: forward differences with
relative step sqrt(rtol); CasADi: forward sensitivities) against the continuous reference is no
larger than dynsens's at its Newmark Δt ("equal accuracy").

Wall times are medians over interleaved repeats, single-threaded BLAS.  Runs that would take
more than a few minutes (m = N = 100, 1000 with per-run peers, CasADi with 1000 directions)
are timed on a sample of columns and extrapolated linearly; such entries are marked "≈".

Usage::

    python scripts/bench_peers.py [--quick] [--out results/bench_peers.md]
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_MAIN_FREE"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Callable  # noqa: E402

import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import dynsens  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from make_cases import duffing_chain  # noqa: E402

try:  # optional peer
    import casadi as ca  # noqa: E402
except ImportError:  # pragma: no cover - depends on the environment
    ca = None

FD_STEP = {"forward": 1e-8, "central": 1e-5}   # relative steps (best of 1e-5..1e-8 on N = 10)
CS_STEP = 1e-20
RTOLS = [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]
SAMPLE = 5           # columns sampled for errors (and extrapolated timings) when m > 10
SLOW_RUN = 30.0      # s: a single run above this is repeated only once


# --------------------------------------------------------------------------- the chain
def chain_case(n: int, t_end: float, per_element: bool) -> dict:
    """Duffing chain case dict, optionally with one stiffness design variable per spring.

    Parameters
    ----------
    n : number of masses.
    t_end : end time (s).
    per_element : replace the 4 shared variables (m, c, k, k3) by k_1..k_n; the other
        parameters are fixed at the shared variables' initial values (same physics).

    Returns
    -------
    dict
        Case dict for :func:`dynsens.load_case_dict`.
    """
    d = duffing_chain(n, t_end)
    if not per_element:
        return d
    x0 = {v["name"]: v["value"] for v in d["design"]["variables"]}
    k = d["design"]["variables"][2]
    d["name"] = "duffing_chain_per_element"
    d["design"]["variables"] = [{"name": f"k_{i + 1}", "value": x0["k"], "lower": k["lower"],
                                 "upper": k["upper"]} for i in range(n)]
    for e in d["model"]["elements"]:
        if e["type"] == "mass":
            e["mass"] = x0["m"]
        elif e["type"] == "damper":
            e["c"] = x0["c"]
        elif e["type"] == "spring":
            e["k"] = "k_" + e["name"][1:]
            e["k3"] = x0["k3"]
    return d


@dataclass
class ChainODE:
    """The Duffing chain as a first-order ODE y = [u, v] (2n,), vectorized, complex-safe.

    Mass i is joined to mass i - 1 (ground for i = 1) by a spring f = k_i δ + k3_i δ³ and a
    damper c_i δ̇ with δ = u_i - u_{i-1}; a pulse 100 sin²(π t / 0.1) N, 0 < t < 0.1 s, acts
    on the last mass -- the physics of ``duffing_chain``.

    Parameters
    ----------
    n : number of masses.
    per_element : design x is k_1..k_n (True) or (m, c, k, k3) (False).
    """

    n: int
    per_element: bool
    base: tuple[float, float, float, float] = (1.0, 2.0, 1.0e3, 1.0e6)

    def params(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """Element arrays (mass, c, k, k3), each (n,) or (n, B) for x (m,) or (m, B)."""
        x = np.asarray(x)
        shape = (self.n,) + x.shape[1:]
        if self.per_element:
            return tuple(np.full(shape, b, dtype=x.dtype) for b in (self.base[0], self.base[1])) + \
                (x, np.full(shape, self.base[3], dtype=x.dtype))
        return tuple(np.broadcast_to(x[j], shape) for j in range(4))

    @staticmethod
    def load(t: float) -> float:
        """Tip force (N) at time t (s)."""
        return 100.0 * np.sin(np.pi * t / 0.1) ** 2 if 0.0 < t < 0.1 else 0.0

    def rhs(self, t: float, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """dy/dt for y (2n,) or (2n, B) and design x (m,) or (m, B)."""
        n = self.n
        mass, c, k, k3 = self.params(x)
        u, v = y[:n], y[n:]
        d = np.diff(u, axis=0, prepend=np.zeros_like(u[:1]))
        dd = np.diff(v, axis=0, prepend=np.zeros_like(v[:1]))
        f = k * d + k3 * d ** 3 + c * dd
        a = np.concatenate([f[1:], np.zeros_like(f[:1])]) - f
        a[-1] = a[-1] + self.load(t)
        return np.concatenate([v, a / mass])

    def jac(self, t: float, y: np.ndarray, x: np.ndarray) -> sp.csc_matrix:
        """Sparse Jacobian ∂(dy/dt)/∂y (2n, 2n) of a single trajectory."""
        n = self.n
        mass, c, k, k3 = (np.asarray(a, dtype=float) for a in self.params(x))
        u = y[:n]
        d = np.diff(u, prepend=0.0)
        kt = k + 3.0 * k3 * d ** 2
        # a_i = (f_{i+1} - f_i)/m_i, f_i depends on u_i, u_{i-1}
        def tri(e: np.ndarray) -> sp.csc_matrix:
            main = -e.copy()
            main[:-1] -= e[1:]
            return sp.diags([main, e[1:], e[1:]], [0, 1, -1], format="csc")
        inv_m = sp.diags(1.0 / mass)
        Z = sp.csc_matrix((n, n))
        return sp.bmat([[Z, sp.identity(n, format="csc")],
                        [inv_m @ tri(kt), inv_m @ tri(c)]], format="csc")


def continuous_reference(ode: ChainODE, x: np.ndarray, cols: np.ndarray, t_end: float
                         ) -> tuple[float, np.ndarray]:
    """Tip displacement at t_end and its derivatives wrt x[cols], tight tolerance.

    Integrates the ODE together with its forward sensitivity equations; the right-hand side
    of the sensitivity equations, ∂f/∂y s_j + ∂f/∂x_j, is the complex step of f along
    (s_j, e_j), exact to round-off.  DOP853, rtol 1e-12 (the chain is not stiff).
    """
    n2, k = 2 * ode.n, len(cols)
    E = np.zeros((x.size, k))
    E[cols, np.arange(k)] = 1.0
    h = 1e-30

    def f(t: float, w: np.ndarray) -> np.ndarray:
        y, S = w[:n2], w[n2:].reshape(n2, k)
        yy = y[:, None] + 1j * h * S
        xx = x[:, None] + 1j * h * E
        dS = np.imag(ode.rhs(t, yy, xx)) / h
        return np.concatenate([ode.rhs(t, y, x), dS.ravel()])

    sol = solve_ivp(f, (0.0, t_end), np.zeros(n2 * (k + 1)), method="DOP853",
                    rtol=1e-12, atol=1e-15, t_eval=[t_end])
    w = sol.y[:, -1]
    return float(w[ode.n - 1]), w[n2:].reshape(n2, k)[ode.n - 1]


def ivp_tip(ode: ChainODE, x: np.ndarray, t_end: float, rtol: float) -> float:
    """Tip displacement at t_end by scipy Radau with the analytic sparse Jacobian."""
    sol = solve_ivp(lambda t, y: ode.rhs(t, y, x), (0.0, t_end), np.zeros(2 * ode.n), method="Radau",
                    rtol=rtol, atol=rtol * 1e-3, jac=lambda t, y: ode.jac(t, y, x))
    if not sol.success:
        raise RuntimeError(f"solve_ivp failed: {sol.message}")
    return float(sol.y[ode.n - 1, -1])


def ivp_fd(ode: ChainODE, x: np.ndarray, t_end: float, rtol: float, cols: np.ndarray
           ) -> tuple[float, np.ndarray, list[float]]:
    """Tip value, forward-difference gradient along x[cols] (relative step sqrt(rtol)) and run times.

    The step is sqrt(rtol) because the adaptive step selection makes the solution a noisy
    function of x at the level of rtol; smaller steps amplify that noise.
    """
    v0 = ivp_tip(ode, x, t_end, rtol)
    g, t = [], []
    for j in cols:
        h = np.sqrt(rtol) * abs(x[j])
        xp = x.copy()
        xp[j] += h
        dt_, v = timed(lambda: ivp_tip(ode, xp, t_end, rtol))
        t.append(dt_)
        g.append((v - v0) / h)
    return v0, np.array(g), t


class CasadiChain:
    """The chain ODE as a CasADi CVODES integrator with forward sensitivities.

    Parameters
    ----------
    ode : the chain (physics and design mapping).
    t_end : end time (s).
    rtol : relative tolerance (abstol = 1e-3 rtol).
    """

    def __init__(self, ode: ChainODE, t_end: float, rtol: float):
        n = ode.n
        m = n if ode.per_element else 4
        X, P, T = ca.SX.sym("x", 2 * n), ca.SX.sym("p", m), ca.SX.sym("t")
        u, v = X[:n], X[n:]
        d = u - ca.vertcat(0, u[:n - 1])
        dd = v - ca.vertcat(0, v[:n - 1])
        if ode.per_element:
            mass, c, k, k3 = ode.base[0], ode.base[1], P, ode.base[3]
        else:
            mass, c, k, k3 = P[0], P[1], P[2], P[3]
        f = k * d + k3 * d ** 3 + c * dd
        load = ca.vertcat(ca.SX.zeros(n - 1, 1),
                          ca.if_else(ca.logic_and(T > 0, T < 0.1), 100 * ca.sin(ca.pi * T / 0.1) ** 2, 0))
        a = (ca.vertcat(f[1:], 0) - f + load) / mass
        dae = {"x": X, "p": P, "t": T, "ode": ca.vertcat(v, a)}
        self.n, self.m = n, m
        self.F = ca.integrator("F", "cvodes", dae, 0.0, t_end,
                               {"reltol": rtol, "abstol": rtol * 1e-3, "max_num_steps": 10 ** 7})
        self._fwd: dict[int, Any] = {}
        self.x0 = np.zeros(2 * n)

    def primal(self, x: np.ndarray) -> tuple[float, Any]:
        """Tip displacement at t_end and the full final state (CasADi DM)."""
        xf = self.F(x0=self.x0, p=x)["xf"]
        return float(xf[self.n - 1]), xf

    def gradient(self, x: np.ndarray, cols: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Primal call plus forward sensitivities of the tip along e_j, j in cols (default all)."""
        cols = np.arange(self.m) if cols is None else cols
        k = len(cols)
        if k not in self._fwd:
            self._fwd[k] = self.F.forward(k)
        value, xf = self.primal(x)
        seeds = np.zeros((self.m, k))
        seeds[cols, np.arange(k)] = 1.0
        out = self._fwd[k](x0=self.x0, p=x, out_xf=xf, fwd_p=seeds)
        return value, np.asarray(out["fwd_xf"])[self.n - 1]


# --------------------------------------------------------------------------- timing
def timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    """Wall time (s) and result of fn()."""
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def rel_err(g: np.ndarray, ref: np.ndarray) -> float:
    """Relative 2-norm error ||g - ref|| / ||ref||."""
    return float(np.linalg.norm(np.asarray(g) - ref) / np.linalg.norm(ref))


@dataclass
class Row:
    """One table row: a method on a case."""

    case: str
    method: str
    runs: str
    primal: float | None = None
    grad: float | None = None
    err_discrete: float | None = None
    err_cont: float | None = None
    extrapolated: bool = False
    note: str = ""


@dataclass
class CaseResult:
    """Rows and facts of one case."""

    label: str
    n: int | None
    m: int
    steps: int
    t_end: float
    dt: float
    rows: list[Row] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)


def _dyn_value(case: Any, x: np.ndarray, resp: str) -> complex:
    return dynsens.run_case(case, x, sensitivities=False, history=()).responses[resp].value


def bench_dynsens(case: Any, resp: str, repeats: int, cols: np.ndarray, extra: list[tuple[str, Callable[[], Any]]]
                  ) -> dict[str, Any]:
    """Time dynsens primal, DDM, FD and CS; run the ``extra`` peer timings interleaved.

    FD and CS are timed over the sampled columns ``cols`` and extrapolated to all m columns
    when ``cols`` is a strict subset.
    """
    x0, m = case.x0, case.x0.size
    scale = np.maximum(np.abs(x0), np.abs(case.scale) * 1e-3)
    full = len(cols) == m
    t: dict[str, list[float]] = {"primal": [], "ddm": []}
    t.update({name: [] for name, _ in extra})
    dynsens.run_case(case, sensitivities=False, history=())   # warm-up
    for _name, fn in extra:
        fn()
    res: dict[str, Any] = {}
    for r in range(repeats):
        dt_, out = timed(lambda: dynsens.run_case(case, sensitivities=False, history=()))
        t["primal"].append(dt_)
        res["value"] = out.responses[resp].value
        dt_, out = timed(lambda: dynsens.run_case(case, sensitivities=True, history=()))
        t["ddm"].append(dt_)
        res["ddm"] = np.asarray(out.responses[resp].gradient)
        res["counters_ddm"], res["ddm_wall"] = out.counters, out.wall_time
        for name, fn in extra:
            t[name].append(timed(fn)[0])
        if r == 0 and t["ddm"][0] > SLOW_RUN:
            break
    med = {k: statistics.median(v) for k, v in t.items() if v}
    res["n_repeats"] = {k: len(v) for k, v in t.items()}
    # whole-simulation differences and complex step: one pass (each is a sum of many runs)
    eye = np.eye(m)
    f0 = res["value"]
    tf, gf, tc, gc, ts, gs = [], [], [], [], [], []
    for j in cols:
        h = FD_STEP["forward"] * scale[j]
        dt_, v = timed(lambda: _dyn_value(case, x0 + h * eye[j], resp))
        tf.append(dt_)
        gf.append((v - f0) / h)
        h = FD_STEP["central"] * scale[j]
        dt1, vp = timed(lambda: _dyn_value(case, x0 + h * eye[j], resp))
        dt2, vm = timed(lambda: _dyn_value(case, x0 - h * eye[j], resp))
        tc.append(dt1 + dt2)
        gc.append((vp - vm) / (2 * h))
        h = CS_STEP * scale[j]
        dt_, v = timed(lambda: _dyn_value(case, x0 + 1j * h * eye[j], resp))
        ts.append(dt_)
        gs.append(np.imag(v) / h)
    per = m / len(cols)
    res["fd_fwd"] = med["primal"] + per * sum(tf)
    res["fd_cen"] = med["primal"] + per * sum(tc)
    res["cs"] = med["primal"] + per * sum(ts)
    res["g_fd_fwd"], res["g_fd_cen"], res["g_cs"] = map(np.array, (gf, gc, gs))
    res["extrapolated"] = not full
    res.update(med=med)
    return res


def calibrate(ode: ChainODE, t_end: float, ref_value: float, ref_grad: np.ndarray, dyn_value_err: float,
              dyn_grad_err: float) -> dict[str, Any]:
    """Loosest rtol of solve_ivp + FD and of CasADi whose gradient error matches dynsens's."""
    x0 = np.array(ode.base)
    out: dict[str, Any] = {}
    for rtol in RTOLS:
        v, g = ivp_fd(ode, x0, t_end, rtol, np.arange(x0.size))[:2]
        e = rel_err(g, ref_grad)
        out["ivp_rtol"], out["ivp_grad_err"] = rtol, e
        out["ivp_value_err"] = abs(v - ref_value) / abs(ref_value)
        if e <= dyn_grad_err:
            break
    if ca is not None:
        for rtol in RTOLS:
            cc = CasadiChain(ode, t_end, rtol)
            v, g = cc.gradient(x0)
            e = rel_err(g, ref_grad)
            out["casadi_rtol"], out["casadi_grad_err"] = rtol, e
            out["casadi_value_err"] = abs(v - ref_value) / abs(ref_value)
            if e <= dyn_grad_err:
                break
    return out


def sample_cols(m: int, quick: bool) -> np.ndarray:
    """All columns for m ≤ 10, else SAMPLE evenly spread ones (first and last included)."""
    if m <= 10:
        return np.arange(m)
    return np.unique(np.linspace(0, m - 1, 2 if quick else SAMPLE).round().astype(int))


def bench_chain(n: int, t_end: float, per_element: bool, repeats: int, quick: bool,
                tols: dict[int, dict[str, Any]]) -> CaseResult:
    """All peers on one Duffing chain; ``tols`` caches the calibrated tolerances per n."""
    d = chain_case(n, t_end, per_element)
    case = dynsens.load_case_dict(d, overrides=["output.history=none"])
    ode = ChainODE(n, per_element)
    m = case.x0.size
    cols = sample_cols(m, quick)
    label = f"Duffing chain N={n}, " + ("per-element k_i" if per_element else "(m, c, k, k3)")
    cr = CaseResult(label, n, m, case.plan.n_steps, t_end, case.plan.dt)
    x0 = case.x0
    print(f"\n== {label}: m = {m}, {case.plan.n_steps} steps, t_end = {t_end} s", flush=True)

    t_ref, (ref_v, ref_g) = timed(lambda: continuous_reference(ode, x0, cols, t_end))
    cr.info["continuous_reference_s"] = t_ref
    if n not in tols:
        # dynsens accuracy against the continuous solution, then matching peer tolerances
        ode4 = ChainODE(n, False)
        v4, g4 = continuous_reference(ode4, np.array(ode4.base), np.arange(4), t_end)
        c4 = dynsens.load_case_dict(chain_case(n, t_end, False), overrides=["output.history=none"])
        r4 = dynsens.run_case(c4, sensitivities=True, history=())
        dv = abs(r4.responses["tip_end"].value - v4) / abs(v4)
        dg = rel_err(r4.responses["tip_end"].gradient, g4)
        tols[n] = {"dynsens_value_err": dv, "dynsens_grad_err": dg,
                   **calibrate(ode4, t_end, v4, g4, dv, dg)}
        print(f"   calibrated: {tols[n]}", flush=True)
    tol = tols[n]
    cr.info.update(tol)

    # solve_ivp: primal timed with the repeats, FD over the sampled columns
    rtol = tol["ivp_rtol"]
    ivp_primal = lambda: ivp_tip(ode, x0, t_end, rtol)  # noqa: E731
    extra: list[tuple[str, Callable[[], Any]]] = [("ivp_primal", ivp_primal)]
    cc = None
    if ca is not None:
        t_build, cc = timed(lambda: CasadiChain(ode, t_end, tol["casadi_rtol"]))
        cr.info["casadi_build_s"] = t_build
        extra.append(("casadi_primal", lambda: cc.primal(x0)))
        if m <= 100:
            extra.append(("casadi_grad", lambda: cc.gradient(x0)))
        else:
            extra.append(("casadi_grad_sample", lambda: cc.gradient(x0, cols)))
    res = bench_dynsens(case, "tip_end", repeats, cols, extra)
    med = res["med"]
    cr.info["counters_ddm"] = res["counters_ddm"]
    cr.info["repeats"] = res["n_repeats"]
    ext = res["extrapolated"]

    g_cs = res["g_cs"]
    ddm = res["ddm"][cols]
    nm = lambda k: f"{k} runs" + (f" (timed {len(cols)} cols)" if ext else "")  # noqa: E731
    cr.rows += [
        Row(label, "dynsens primal", "1", med["primal"], None, None, None),
        Row(label, "dynsens DDM", "1", med["primal"], med["ddm"], rel_err(ddm, g_cs), rel_err(ddm, ref_g)),
        Row(label, "dynsens FD fwd", nm(f"{m}+1"), med["primal"], res["fd_fwd"],
            rel_err(res["g_fd_fwd"], g_cs), rel_err(res["g_fd_fwd"], ref_g), ext),
        Row(label, "dynsens FD cen", nm(f"2·{m}+1"), med["primal"], res["fd_cen"],
            rel_err(res["g_fd_cen"], g_cs), rel_err(res["g_fd_cen"], ref_g), ext),
        Row(label, "dynsens CS", nm(f"1+{m}"), med["primal"], res["cs"], 0.0, rel_err(g_cs, ref_g), ext),
    ]
    # solve_ivp forward differences (step: sqrt of its rtol, relative)
    v0, gi, t_fd = ivp_fd(ode, x0, t_end, rtol, cols)
    t_ivp_fd = med["ivp_primal"] + m / len(cols) * sum(t_fd)
    cr.rows.append(Row(label, f"solve_ivp Radau FD fwd (rtol {rtol:g})", nm(f"{m}+1"), med["ivp_primal"],
                       t_ivp_fd, None, rel_err(gi, ref_g), ext,
                       f"value err {abs(v0 - ref_v) / abs(ref_v):.1e}"))
    if cc is not None:
        if "casadi_grad" in med:
            tg, extc = med["casadi_grad"], False
            _, gcas = cc.gradient(x0)
            gcas = gcas[cols]
        else:
            # cost of k directions beyond the primal, scaled to m directions
            tg = med["casadi_primal"] + (med["casadi_grad_sample"] - med["casadi_primal"]) * m / len(cols)
            extc = True
            _, gcas = cc.gradient(x0, cols)
        vcas = cc.primal(x0)[0]
        cr.rows.append(Row(label, f"CasADi CVODES fsens (rtol {tol['casadi_rtol']:g})",
                           "1 + m-dir. fsens" + (f" (timed {len(cols)} dirs)" if extc else ""),
                           med["casadi_primal"], tg, None, rel_err(gcas, ref_g), extc,
                           f"value err {abs(vcas - ref_v) / abs(ref_v):.1e}"))
    else:
        cr.info["casadi"] = "skipped: casadi not installed (pip install 'dynsens[peers]')"
    dyn_value_err = abs(res["value"] - ref_v) / abs(ref_v)
    cr.rows[1].note = f"value err {dyn_value_err:.1e}"
    return cr


def bench_slider_crank(repeats: int, quick: bool) -> CaseResult:
    """dynsens peers on cases/slider_crank.yaml (no ODE peers: a constrained multibody DAE)."""
    case = dynsens.load_case(ROOT / "cases" / "slider_crank.yaml", ["output.history=none"])
    label = f"slider crank ({case.plan.partials} partials)"
    m = case.x0.size
    cr = CaseResult(label, None, m, case.plan.n_steps, case.plan.t_end, case.plan.dt)
    print(f"\n== {label}: m = {m}, {case.plan.n_steps} steps", flush=True)
    res = bench_dynsens(case, "slider_x_end", repeats, np.arange(m), [])
    med, g_cs = res["med"], res["g_cs"]
    cr.info["counters_ddm"] = res["counters_ddm"]
    cr.info["repeats"] = res["n_repeats"]
    cr.rows += [
        Row(label, "dynsens primal", "1", med["primal"]),
        Row(label, "dynsens DDM", "1", med["primal"], med["ddm"], rel_err(res["ddm"], g_cs)),
        Row(label, "dynsens FD fwd", f"{m}+1", med["primal"], res["fd_fwd"], rel_err(res["g_fd_fwd"], g_cs)),
        Row(label, "dynsens FD cen", f"2·{m}+1", med["primal"], res["fd_cen"], rel_err(res["g_fd_cen"], g_cs)),
        Row(label, "dynsens CS", f"1+{m}", med["primal"], res["cs"], 0.0),
    ]
    return cr


# --------------------------------------------------------------------------- report
def machine() -> dict[str, str]:
    """CPU model, cores and library versions."""
    info = {"cpu": platform.processor() or platform.machine(), "cores": str(os.cpu_count())}
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        for line in out.splitlines():
            key, _, val = line.partition(":")
            if key.strip() == "Model name":
                info["cpu"] = val.strip()
    except OSError:
        pass
    info.update(python=platform.python_version(), numpy=np.__version__, scipy=scipy.__version__,
                casadi=ca.__version__ if ca is not None else "not installed", dynsens=dynsens.__version__,
                date=time.strftime("%Y-%m-%d"))
    return info


def fmt(v: float | None, spec: str = ".3f") -> str:
    """Format a number or an en dash."""
    return "–" if v is None else format(v, spec)


def table(results: list[CaseResult], ref_primal: dict[str, float]) -> str:
    """Markdown table of all rows."""
    lines = ["| case | m | steps | method | runs | primal [s] | primal + gradient [s] | ratio to own primal "
             "| ratio to dynsens primal | grad err (discrete, vs CS) | grad err (continuous) | note |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for cr in results:
        for r in cr.rows:
            approx = "≈" if r.extrapolated else ""
            ratio = r.grad / r.primal if r.grad is not None and r.primal else None
            rdyn = r.grad / ref_primal[cr.label] if r.grad is not None else None
            lines.append(
                f"| {cr.label} | {cr.m} | {cr.steps} | {r.method} | {r.runs} | {fmt(r.primal)} | "
                f"{approx}{fmt(r.grad)} | {approx}{fmt(ratio, '.2f')} | {approx}{fmt(rdyn, '.2f')} | "
                f"{fmt(r.err_discrete, '.1e')} | {fmt(r.err_cont, '.1e')} | {r.note} |")
    return "\n".join(lines)


def main() -> None:
    """Run the benchmark and write the markdown table (and a JSON of the raw numbers)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="N = 10 only, 1 repeat (smoke run)")
    ap.add_argument("--out", default=str(ROOT / "results" / "bench_peers.md"))
    ap.add_argument("--no-slider-crank", action="store_true")
    args = ap.parse_args()
    mach = machine()
    print(f"# {mach}", flush=True)
    if ca is None:
        print("CasADi not installed: the CasADi column is skipped (pip install 'dynsens[peers]')", flush=True)
    plan = [(10, 2.0, 5)] if args.quick else [(10, 2.0, 5), (100, 2.0, 3), (1000, 0.2, 3)]
    wall0 = time.perf_counter()
    results: list[CaseResult] = []
    tols: dict[int, dict[str, Any]] = {}
    for n, t_end, reps in plan:
        for per_element in (False, True):
            results.append(bench_chain(n, t_end, per_element, 1 if args.quick else reps, args.quick, tols))
    if not args.quick and not args.no_slider_crank:
        results.append(bench_slider_crank(3, args.quick))
    ref_primal = {cr.label: cr.rows[0].primal for cr in results}
    text = table(results, ref_primal)
    steps = "\n".join(f"- {cr.label}: m = {cr.m}, Δt = {cr.dt:g} s, t_end = {cr.t_end:g} s, {cr.steps} steps; "
                      f"repeats {cr.info.get('repeats')}" for cr in results)
    cal = "\n".join(f"- N = {n}: dynsens (Newmark) tip value error {t['dynsens_value_err']:.1e}, gradient error "
                    f"{t['dynsens_grad_err']:.1e} vs continuous; solve_ivp rtol {t['ivp_rtol']:g} (FD gradient error "
                    f"{t['ivp_grad_err']:.1e}, value error {t['ivp_value_err']:.1e})"
                    + (f"; CasADi rtol {t['casadi_rtol']:g} (gradient error {t['casadi_grad_err']:.1e})"
                       if "casadi_rtol" in t else "")
                    for n, t in tols.items())
    doc = (f"# Peer comparison ({mach['date']})\n\nMachine: {mach['cpu']}, {mach['cores']} cores; Python "
           f"{mach['python']}, numpy {mach['numpy']}, scipy {mach['scipy']}, casadi {mach['casadi']}, dynsens "
           f"{mach['dynsens']}. Total benchmark wall time {time.perf_counter() - wall0:.0f} s.\n\n{text}\n\n"
           f"Cases:\n{steps}\n\nTolerance calibration (4-variable chain, reused for per-element):\n{cal}\n")
    if ca is None:
        doc += "\nCasADi: skipped (not installed; `pip install 'dynsens[peers]'`).\n"
    print("\n" + doc, flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(doc, encoding="utf-8")
    raw = [{"label": cr.label, "m": cr.m, "steps": cr.steps, "rows": [r.__dict__ for r in cr.rows],
            "info": {k: v for k, v in cr.info.items()}} for cr in results]
    out.with_suffix(".json").write_text(json.dumps({"machine": mach, "cases": raw}, indent=1, default=str),
                                        encoding="utf-8")
    print(f"written: {out} and {out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
