"""Issue 35's target table: dynsens against its targets and its peers, side by side in one run.

Rows (``--rows``, default all, in this order):

  p1-10, p1-100, p1-1000  the Duffing chain P1 (``make_cases.duffing_chain``, four design
                          variables m, c, k, k3, ``--steps`` steps of 1 ms, response tip_end,
                          forward partials, no histories): primal and primal + gradient (direct)
                          within 3× of the compiled JAX scan, gradient ratio ≤ 1.3
  adjoint-1000            the chain with m = N = 1000 per-element stiffnesses
                          (``bench_peers.chain_case``), one response (tip_end), the adjoint:
                          primal + gradient ≤ 2× the primal, no slower than JAX's reverse mode
  weir                    cases/tyrolean_weir.yaml as shipped: primal + gradient (direct) ≤ 1.0 s,
                          adjoint ≤ 1.2× direct
  fourbar                 the N-four-bar with 40 loops (``make_n_four_bar``, sparse), 20 s at
                          1 ms with both design sensitivities: ≤ 60 s (``--quick``: 2 s, the
                          target scaled to 6 s, and the table says so)
  large                   the 10 000-DOF sparse chain with ten design variables
                          (``bench_large.large_case``, 1 000 steps): primal + gradient ≤ 7 s
                          (``--quick``: 100 steps, target scaled to 0.7 s)

Peers, run in the same process and interleaved with dynsens in every repeat: the minimal numpy
loop of ``yardstick_chain.py`` (LAPACK tridiagonal LU; P1 rows) and the compiled JAX scan of
``jax_chain.py`` (P1: ``jit`` primal and ``jacfwd``; adjoint row: ``grad``).  JAX is optional: when
it is missing its columns say so and its targets are not judged.

CPU seconds (``time.process_time``: every thread of the process; BLAS and XLA single-threaded),
medians of ``--repeats`` interleaved repeats.  Compilation is excluded: every variant (numba's
kernels, JAX's jit) runs once untimed before the timed repeats.  The machine, and ``uptime``
before and after, are printed with the table.  The JAX chain's tip and gradient are checked
against dynsens' (relative difference in the notes; above 1e-6 it is flagged).

Usage: python scripts/bench_targets.py [--rows ROW ...] [--repeats 3] [--steps 2000] [--quick]
(``make bench`` runs it with the defaults.)
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

import dynsens  # noqa: E402  (first: it sets BLAS single-threaded before numpy loads)
import jax_chain  # noqa: E402
import numpy as np  # noqa: E402
import yardstick_chain as ys  # noqa: E402
from bench_large import large_case  # noqa: E402
from bench_peers import chain_case  # noqa: E402
from make_n_four_bar import n_four_bar  # noqa: E402

ROWS = ("p1-10", "p1-100", "p1-1000", "adjoint-1000", "weir", "fourbar", "large")
AGREEMENT = 1e-6        # largest relative difference of the JAX chain to dynsens before it is flagged
WEIR = ROOT / "cases" / "tyrolean_weir.yaml"


@dataclass
class Target:
    """One line of the table: what is aimed at, what was measured, whether it is met."""

    name: str
    goal: str
    measured: str
    met: bool | None          # None: not judged (a peer is missing)


@dataclass
class Row:
    """One benchmark row: its targets, its CPU seconds by variant and its notes."""

    label: str
    targets: list[Target] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- timing
def cpu_medians(runs: dict[str, Callable[[], Any]], repeats: int, warm: bool = True
                ) -> tuple[dict[str, float], dict[str, Any]]:
    """Median CPU seconds per variant and each variant's last result.

    Every variant runs once untimed first (compilation, first-call costs; ``warm=False``: the
    caller has warmed them), then ``repeats`` rounds in which the variants take turns, so that a
    busy machine loads them alike.
    """
    last = {label: fn() for label, fn in runs.items()} if warm else {}
    times: dict[str, list[float]] = {label: [] for label in runs}
    for _ in range(repeats):
        for label, fn in runs.items():
            t0 = time.process_time()
            last[label] = fn()
            times[label].append(time.process_time() - t0)
    return {label: statistics.median(v) for label, v in times.items()}, last


def rel_diff(a: Any, b: Any) -> float:
    """Largest absolute difference of a and b over the largest |b| (0 for b = 0)."""
    a, b = np.atleast_1d(np.real(a)), np.atleast_1d(np.real(b))
    scale = float(np.max(np.abs(b)))
    return float(np.max(np.abs(a - b))) / scale if scale else float(np.max(np.abs(a)))


def agreement_note(what: str, value: float, ref_value: float, grad: np.ndarray, ref_grad: np.ndarray) -> str:
    """The JAX chain against dynsens, flagged above :data:`AGREEMENT`."""
    dv, dg = rel_diff(value, ref_value), rel_diff(grad, ref_grad)
    flag = "" if max(dv, dg) <= AGREEMENT else f" **MISMATCH above {AGREEMENT:g}**"
    return f"{what}: JAX tip_end vs dynsens {dv:.1e}, gradient {dg:.1e} (relative){flag}"


def fmt_ratio(r: float) -> str:
    return f"{r:.2f}×"


# --------------------------------------------------------------------------- rows
def p1_case(n: int, steps: int) -> Any:
    """P1: the Duffing chain of N = n masses over ``steps`` steps, four design variables, its one
    response tip_end."""
    d = ys.dynsens_case_dict(n, steps)
    d["responses"] = [r for r in d["responses"] if r["name"] == "tip_end"]
    return dynsens.load_case_dict(d)


def p1_row(n: int, steps: int, repeats: int) -> Row:
    """P1 at N = n: dynsens, the numpy loop and the JAX scan, primal and primal + gradient."""
    case = p1_case(n, steps)
    runs: dict[str, Callable[[], Any]] = {
        "dynsens primal": lambda: dynsens.run_case(case, sensitivities=False, history=()),
        "dynsens + gradient": lambda: dynsens.run_case(case, sensitivities=True, history=()),
        "numpy loop primal": lambda: ys.run(n, steps, solver="tridiagonal", gradient=False),
        "numpy loop + gradient": lambda: ys.run(n, steps, solver="tridiagonal", gradient=True),
    }
    jax = jax_chain.JaxChain(n, steps) if jax_chain.AVAILABLE else None
    if jax is not None:
        runs["JAX primal"] = lambda: jax.primal(ys.X0)
        runs["JAX + gradient (jacfwd)"] = lambda: jax.forward(ys.X0)
    t, last = cpu_medians(runs, repeats)
    row = Row(f"P1 N = {n}", seconds=t)
    p, g = t["dynsens primal"], t["dynsens + gradient"]
    if jax is not None:
        pairs = (("primal", p, t["JAX primal"]), ("primal + gradient", g, t["JAX + gradient (jacfwd)"]))
        for name, mine, peer in pairs:
            row.targets.append(Target(f"P1 N = {n}, {name}", "≤ 3× JAX scan",
                                      f"{mine:.3f} s, {fmt_ratio(mine / peer)} JAX", mine / peer <= 3.0))
        note_agreement(row, f"P1 N = {n}", last["dynsens + gradient"], last["JAX + gradient (jacfwd)"])
    else:
        for name, mine in (("primal", p), ("primal + gradient", g)):
            row.targets.append(Target(f"P1 N = {n}, {name}", "≤ 3× JAX scan",
                                      f"{mine:.3f} s; {jax_chain.MISSING}", None))
    row.targets.append(Target(f"P1 N = {n}, gradient ratio", "≤ 1.3", f"{g / p:.2f}", g / p <= 1.3))
    return row


def note_agreement(row: Row, label: str, run: Any, jax_result: tuple[Any, Any]) -> None:
    """Add to ``row`` the note comparing dynsens's tip_end (``run``) with JAX's (value, gradient)."""
    res = run.responses["tip_end"]
    value, grad = jax_result
    row.notes.append(agreement_note(label, value, res.value, grad, np.asarray(res.gradient)))


def adjoint_row(n: int, steps: int, repeats: int) -> Row:
    """m = N = n per-element stiffnesses, tip_end by the adjoint, against the primal and JAX's grad."""
    d = chain_case(n, steps * ys.DT, per_element=True)
    d["responses"] = [r for r in d["responses"] if r["name"] == "tip_end"]
    d["output"] = {"history": "none"}
    d["sensitivity"]["method"] = "adjoint"
    case = dynsens.load_case_dict(d)
    runs: dict[str, Callable[[], Any]] = {
        "dynsens primal": lambda: dynsens.run_case(case, sensitivities=False, history=()),
        "dynsens + gradient (adjoint)": lambda: dynsens.run_case(case, sensitivities=True, history=()),
    }
    jax = jax_chain.JaxChain(n, steps, per_element=True) if jax_chain.AVAILABLE else None
    x0 = np.asarray(case.x0, dtype=float)
    if jax is not None:
        runs["JAX primal"] = lambda: jax.primal(x0)
        runs["JAX + gradient (grad)"] = lambda: jax.reverse(x0)
    t, last = cpu_medians(runs, repeats)
    row = Row(f"adjoint m = N = {n}", seconds=t)
    p, a = t["dynsens primal"], t["dynsens + gradient (adjoint)"]
    row.targets.append(Target(f"m = N = {n}, adjoint", "≤ 2× primal", f"{a:.3f} s, {fmt_ratio(a / p)} primal",
                              a / p <= 2.0))
    if jax is not None:
        peer = t["JAX + gradient (grad)"]
        row.targets.append(Target(f"m = N = {n}, adjoint vs JAX reverse mode", "≤ 1× JAX grad",
                                  f"{fmt_ratio(a / peer)} JAX ({peer:.3f} s)", a / peer <= 1.0))
        note_agreement(row, f"m = N = {n}", last["dynsens + gradient (adjoint)"], last["JAX + gradient (grad)"])
    else:
        row.targets.append(Target(f"m = N = {n}, adjoint vs JAX reverse mode", "≤ 1× JAX grad",
                                  jax_chain.MISSING, None))
    return row


def weir_row(repeats: int) -> Row:
    """The shipped weir: primal, primal + gradient direct and adjoint."""
    direct = dynsens.load_case(WEIR, ["sensitivity.method=direct"])
    adjoint = dynsens.load_case(WEIR, ["sensitivity.method=adjoint"])
    t, last = cpu_medians({
        "dynsens primal": lambda: dynsens.run_case(direct, sensitivities=False, history=()),
        "dynsens + gradient (direct)": lambda: dynsens.run_case(direct, sensitivities=True, history=()),
        "dynsens + gradient (adjoint)": lambda: dynsens.run_case(adjoint, sensitivities=True, history=()),
    }, repeats)
    row = Row("weir", seconds=t)
    g, a = t["dynsens + gradient (direct)"], t["dynsens + gradient (adjoint)"]
    row.targets.append(Target("weir, primal + gradient", "≤ 1.0 s", f"{g:.3f} s", g <= 1.0))
    row.targets.append(Target("weir, adjoint", "≤ 1.2× direct", f"{a:.3f} s, {fmt_ratio(a / g)} direct", a / g <= 1.2))
    worst = max(rel_diff(last["dynsens + gradient (adjoint)"].responses[k].gradient, r.gradient)
                for k, r in last["dynsens + gradient (direct)"].responses.items())
    row.notes.append(f"weir: adjoint gradients vs direct, largest relative difference {worst:.1e}")
    return row


def four_bar_row(t_end: float, quick: bool) -> Row:
    """The 40-loop N-four-bar over t_end at 1 ms with both sensitivities (sparse), one timed run."""
    def case(horizon: float) -> Any:
        raw = n_four_bar(40, t_end=horizon)
        raw["model"]["linear_algebra"] = "sparse"
        return dynsens.load_case_dict(raw, source="n_four_bar_40.yaml")
    dynsens.run_case(case(0.02), sensitivities=True, history=())      # compile, untimed
    full = case(t_end)
    t, last = cpu_medians({"dynsens + gradient": lambda: dynsens.run_case(full, sensitivities=True, history=())},
                          1, warm=False)
    goal = 60.0 * t_end / 20.0
    label = f"N-four-bar 40 loops, {t_end:g} s" + (" (--quick: 2 s of the 20 s, target scaled)" if quick else "")
    row = Row(label, seconds=t)
    s = t["dynsens + gradient"]
    row.targets.append(Target(f"{label}, with sensitivities", f"≤ {goal:g} s", f"{s:.1f} s", s <= goal))
    res = last["dynsens + gradient"]
    row.notes.append(f"N-four-bar: status {res.status}, {res.counters['steps']} steps, one timed run after an "
                     "untimed 20 ms run of the same model (compilation)")
    return row


def large_row(steps: int, repeats: int, quick: bool) -> Row:
    """The 10 000-DOF sparse chain, ten design variables, primal and primal + gradient."""
    case = large_case(10000, steps)
    t, _ = cpu_medians({
        "dynsens primal": lambda: dynsens.run_case(case, sensitivities=False, history=()),
        "dynsens + gradient": lambda: dynsens.run_case(case, sensitivities=True, history=()),
    }, repeats)
    goal = 7.0 * steps / 1000
    label = f"10 000-DOF sparse, {steps} steps" + (" (--quick, target scaled)" if quick else "")
    row = Row(label, seconds=t)
    g = t["dynsens + gradient"]
    row.targets.append(Target(f"{label}, primal + gradient", f"≤ {goal:g} s", f"{g:.2f} s", g <= goal))
    return row


# --------------------------------------------------------------------------- the table
def machine() -> list[str]:
    """Lines describing the machine and the software."""
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import scipy
    jax_version = jax_chain.jax.__version__ if jax_chain.AVAILABLE else "not installed"
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "?"
    return [f"machine: {cpu}, {os.cpu_count()} cores, {platform.platform()}; tree at commit {commit}",
            f"Python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
            f"dynsens {getattr(dynsens, '__version__', '?')}, JAX {jax_version}; "
            f"DYNSENS_KERNEL={os.environ.get('DYNSENS_KERNEL', '(default)')}"]


def uptime() -> str:
    """The output of ``uptime`` (load averages), or the load averages when it is missing."""
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "load average: " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


def met_text(met: bool | None) -> str:
    return {True: "yes", False: "no", None: "not judged"}[met]


def table(rows: list[Row], header: list[str]) -> str:
    """The target table, the CPU seconds of every variant, the notes (markdown)."""
    out = header + ["", "| target | goal | measured | met |", "|---|---|---|---|"]
    out += [f"| {t.name} | {t.goal} | {t.measured} | {met_text(t.met)} |" for r in rows for t in r.targets]
    out += ["", "CPU seconds, medians (every variant side by side in this run):", "",
            "| row | variant | CPU s |", "|---|---|---|"]
    out += [f"| {r.label} | {v} | {s:.3f} |" for r in rows for v, s in r.seconds.items()]
    if not jax_chain.AVAILABLE:
        out += ["", f"JAX columns: {jax_chain.MISSING}."]
    notes = [n for r in rows for n in r.notes]
    if notes:
        out += ["", "Notes:"] + [f"- {n}" for n in notes]
    return "\n".join(out)


def build_row(name: str, args: argparse.Namespace) -> Row:
    """Measure the row called ``name`` (one of :data:`ROWS`)."""
    if name.startswith("p1-"):
        return p1_row(int(name[3:]), args.steps, args.repeats)
    if name.startswith("adjoint-"):
        return adjoint_row(int(name[8:]), args.steps, args.repeats)
    if name == "weir":
        return weir_row(args.repeats)
    if name == "fourbar":
        return four_bar_row(2.0 if args.quick else 20.0, args.quick)
    return large_row(100 if args.quick else 1000, args.repeats, args.quick)


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", nargs="+", choices=ROWS, default=list(ROWS))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=2000, help="steps of the P1 and adjoint rows (1 ms each)")
    ap.add_argument("--quick", action="store_true", help="shorter four-bar (2 s) and 10 000-DOF (100 steps) rows")
    args = ap.parse_args(argv)
    load_before = uptime()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    rows = []
    for name in args.rows:
        rows.append(build_row(name, args))
        print(f"{name} done", file=sys.stderr, flush=True)
    command = " ".join(["python scripts/bench_targets.py", *(sys.argv[1:] if argv is None else argv)])
    header = [f"Issue 35 targets, {started}: `{command}`",
              *machine(),
              f"uptime before: {load_before}",
              f"uptime after:  {uptime()}",
              f"CPU time (time.process_time), medians of {args.repeats} interleaved repeats "
              f"(four-bar: one run); P1 and adjoint rows {args.steps} steps of 1 ms; compilation excluded "
              "(numba and JAX: every variant run once untimed first)"
              + ("; --quick: shortened rows, targets scaled (marked)" if args.quick else "")]
    text = table(rows, header)
    print(text)
    return text


if __name__ == "__main__":
    main()
