"""What the sensitivity part of a run costs per step, part by part (issue 35: "the sensitivity part
as lean as the primal ... with per-step costs measured and reported").

For each configuration the script measures, uninstrumented, the primal run and the run with
gradients (medians of ``--repeats``, after one untimed run of each so that compilation is never
in a figure), and then, instrumented, where the gradient's extra time goes:

direct mode
  design partials      ∂_xF_R of a block of steps (``DesignPartials.residual_partials_steps``,
                       one batched residual call per block)
  compiled block       the compiled sensitivity steps (``direct_step.run_block``: predict, pseudo
                       load, solve, correct, advance of a block of records in one call)
  Python steps         the same steps run as Python where no block serves, split into
                       pseudo load (the state part's products), solve, and predict/correct/advance
  output derivatives   the responses' outputs differentiated forward (``DesignPartials.total``)
adjoint mode
  records kept         the forward run's step records kept for the sweep (``RecordStore.add_step``)
  design term          Σ ∂_xF_Rᵀ μ (``residual_partials_transposed_steps``)
  compiled adjoint block  the compiled adjoint steps (``adjoint_step.run_block``: the transposed
                       advance, corrector, solve, products and predictor of a run of records)
  transposed solves    μ = −S⁻ᵀ z̄ where the steps run as Python (``AdjointMode._solve``)
  transposed products  (R_q, R_q̇, R_p)ᵀ μ there (``PythonAdjointStep.state_transpose``, and the
                       initial solve's)
  scheme transposes    the Newmark maps' transposes there (predict, correct, advance, start)
  adjoint seeds        ∂J/∂y at the grid instants (``OutputSeeds.seeds_block``)

Each part is the wall time of its calls (the outermost when they nest), per step of the run; the
rest of the gradient's extra time (the linearizations kept for the sensitivities, the finite
checks, the adjoint step's own bookkeeping, the loop's) is what remains.  The wrappers cost about a
microsecond per call.

    python scripts/profile_sensitivity_parts.py            # P1 N = 10 and 1000, m = N = 1000, the weir
    python scripts/profile_sensitivity_parts.py --rows p1-10 weir --repeats 5

Rows: p1-10, p1-1000 (the Duffing chain P1 of ``bench_targets.py``: four design variables, 2 000
steps, direct and adjoint), adjoint-1000 (m = N = 1000, adjoint), weir (as shipped, direct and
adjoint).
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import dynsens  # noqa: E402  (first: it sets BLAS single-threaded before numpy loads)
import yardstick_chain as ys  # noqa: E402
from bench_peers import chain_case  # noqa: E402
from profile_split import cpu_model  # noqa: E402

WEIR = HERE.parent / "cases" / "tyrolean_weir.yaml"
ROWS = ("p1-10", "p1-1000", "adjoint-1000", "weir")


class Parts:
    """Wall time (s) and calls per part while ``active``; nested calls count for the outermost."""

    def __init__(self) -> None:
        self.active = False
        self.depth = 0
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)

    def reset(self) -> None:
        """Zero the times and counts (before an instrumented run)."""
        self.seconds.clear()
        self.calls.clear()

    def wrap(self, owner: Any, name: str, part: str) -> None:
        """Time ``owner.name`` (a function of a module or class) as ``part``."""
        original = getattr(owner, name)

        def timed(*args: Any, **kwargs: Any) -> Any:
            if not self.active or self.depth:
                return original(*args, **kwargs)
            self.depth += 1
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                self.depth -= 1
                self.seconds[part] += time.perf_counter() - t0
                self.calls[part] += 1
        setattr(owner, name, timed)


PARTS = Parts()
DIRECT_PARTS = ("design partials", "compiled block", "Python steps: pseudo load", "Python steps: solve",
                "Python steps: predict, correct, advance", "output derivatives")
ADJOINT_PARTS = ("records kept", "design term", "compiled adjoint block", "transposed solves",
                 "transposed products", "scheme transposes", "adjoint seeds")


def instrument() -> None:
    """Wrap the functions of each part (before any run)."""
    from dynsens.derivatives import adjoint, adjoint_step, checkpoints, direct, direct_step, output_seeds, partials
    from dynsens.integrators.newmark import Newmark
    P = partials.DesignPartials
    PARTS.wrap(P, "residual_partials_steps", "design partials")
    PARTS.wrap(P, "residual_partials", "design partials")
    PARTS.wrap(P, "total", "output derivatives")
    PARTS.wrap(direct, "run_block", "compiled block")
    step = direct_step.PythonDirectStep
    PARTS.wrap(step, "pseudo_load", "Python steps: pseudo load")
    PARTS.wrap(step, "solve", "Python steps: solve")
    for name in ("predict", "correct", "advance"):
        PARTS.wrap(step, name, "Python steps: predict, correct, advance")
    PARTS.wrap(P, "residual_partials_transposed_steps", "design term")
    PARTS.wrap(adjoint_step, "run_block", "compiled adjoint block")
    PARTS.wrap(adjoint.AdjointMode, "_solve", "transposed solves")
    back = adjoint_step.PythonAdjointStep
    PARTS.wrap(back, "state_transpose", "transposed products")
    for name in ("predict_transpose", "correct_transpose", "advance_transpose"):
        PARTS.wrap(back, name, "scheme transposes")
    PARTS.wrap(Newmark, "start_transpose", "scheme transposes")
    PARTS.wrap(output_seeds.OutputSeeds, "seeds_block", "adjoint seeds")
    PARTS.wrap(checkpoints.RecordStore, "add_step", "records kept")


def configurations(rows: list[str]) -> dict[str, tuple[Any, str]]:
    """(case, derivative mode) of each configuration, by label."""
    out: dict[str, tuple[Any, str]] = {}
    for row in rows:
        if row.startswith("p1-"):
            n = int(row[3:])
            for method in ("direct", "adjoint"):
                d = ys.dynsens_case_dict(n, 2000)           # as bench_targets.p1_case builds it
                d["responses"] = [r for r in d["responses"] if r["name"] == "tip_end"]
                out[f"P1 N = {n}, {method}"] = (
                    dynsens.load_case_dict(d, f"p1_{n}.yaml", [f"sensitivity.method={method}"]), method)
        elif row == "adjoint-1000":
            d = chain_case(1000, 2.0, per_element=True)
            d["responses"] = [r for r in d["responses"] if r["name"] == "tip_end"]
            d["sensitivity"]["method"] = "adjoint"
            out["m = N = 1000, adjoint"] = (dynsens.load_case_dict(d), "adjoint")
        else:
            for method in ("direct", "adjoint"):
                out[f"weir, {method}"] = (dynsens.load_case(WEIR, [f"sensitivity.method={method}"]), method)
    return out


def run(case: Any, sensitivities: bool) -> Any:
    """One run of the case without histories."""
    return dynsens.run_case(case, sensitivities=sensitivities, history=())


def measure(case: Any, method: str, repeats: int) -> dict[str, Any]:
    """Medians (s) of the primal and the gradient run, uninstrumented; the parts' medians of
    instrumented gradient runs; the steps of the run."""
    primal, gradient = [], []
    parts: dict[str, list[float]] = defaultdict(list)
    steps = 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(case, False)
        primal.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        res = run(case, True)
        gradient.append(time.perf_counter() - t0)
        assert res.method == method, (res.method, method)
        steps = res.counters["steps"] + res.counters["step_cuts"]
        PARTS.reset()
        PARTS.active = True
        run(case, True)
        PARTS.active = False
        for part in DIRECT_PARTS + ADJOINT_PARTS:
            parts[part].append(PARTS.seconds.get(part, 0.0))
    med = statistics.median
    return {"primal": med(primal), "gradient": med(gradient), "steps": steps,
            "parts": {p: med(v) for p, v in parts.items()}}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", nargs="+", choices=ROWS, default=list(ROWS))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    instrument()
    configs = configurations(args.rows)
    for case, _ in configs.values():     # compile and fill the caches outside the timed runs
        run(case, False)
        run(case, True)
    print(f"dynsens from {Path(dynsens.__file__).parent}, kernel {os.environ.get('DYNSENS_KERNEL', 'compiled')}")
    print(f"{cpu_model()}, {os.cpu_count()} cores, load "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())} at the start; wall times, medians of {args.repeats}\n")
    print("| run | steps | primal [µs/step] | gradient's extra [µs/step] (ratio) | parts [µs/step] | rest [µs/step] |")
    print("|---|---|---|---|---|---|")
    for label, (case, method) in configs.items():
        m = measure(case, method, args.repeats)
        n = m["steps"]
        extra = m["gradient"] - m["primal"]
        names = DIRECT_PARTS if method == "direct" else ADJOINT_PARTS
        shown = [(p, m["parts"][p]) for p in names if m["parts"][p] > 0.0]
        text = "; ".join(f"{p} {1e6 * s / n:.1f}" for p, s in shown)
        rest = extra - sum(s for _, s in shown)
        print(f"| {label} | {n} | {1e6 * m['primal'] / n:.1f} | {1e6 * extra / n:.1f} "
              f"({m['gradient'] / m['primal']:.2f}) | {text} | {1e6 * rest / n:.1f} |", flush=True)
    print(f"\nload {' '.join(f'{x:.2f}' for x in os.getloadavg())} at the end")


if __name__ == "__main__":
    main()
