"""Where a step's time goes: orchestration, model arithmetic, linear algebra (cProfile).

Each run is profiled once after an unprofiled warm-up (no compilation inside).  The profile is
split by entry points, with inclusive times:

* linear algebra — the calls into ``dynsens/solver/linalg.py`` and ``banded.py`` (factorizing
  and solving, with the LAPACK / SuperLU calls beneath them) from outside those modules;
* model arithmetic — the calls into ``dynsens/models/`` from outside it (residuals, tangents,
  iteration-matrix assembly, outputs, compiled kernels beneath them);
* orchestration — the rest of the run (the time loop, Newton's bookkeeping, predictors and
  correctors, responses, sensitivity recursion bookkeeping);
* compiled step — a step's Newton iterations when they run compiled (a mechanism's,
  ``dynsens/models/multibody/compiled_step.py``, or a spring network's,
  ``dynsens/models/structural/step.py``: model arithmetic and the factorization inside one
  call, with the step's Python set-up and the conversion of its results, the linearization the
  sensitivities read included); not part of the model-arithmetic column.

Profiling inflates per-call overhead (orchestration most), so the split is indicative; the
totals per step are those of the profiled run.  To compare trees, run this file with
PYTHONPATH pointing at each tree in turn.
Usage: python scripts/profile_step.py [--chain-steps 2000] [--weir]
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import dynsens  # noqa: E402
import yardstick_chain as ys  # noqa: E402

LINALG = (os.path.join("dynsens", "solver", "linalg.py"), os.path.join("dynsens", "solver", "banded.py"))
MODELS = os.path.join("dynsens", "models") + os.sep
COMPILED_STEP = (os.path.join("dynsens", "models", "multibody", "compiled_step.py"),
                 os.path.join("dynsens", "models", "structural", "step.py"))


def _inside(filename: str, where: tuple[str, ...] | str) -> bool:
    return any(w in filename for w in ((where,) if isinstance(where, str) else where))


def split(stats: pstats.Stats) -> dict[str, float]:
    """Inclusive seconds entering each group from outside it, and the total."""
    groups = {"linear algebra": LINALG, "compiled step": COMPILED_STEP, "model arithmetic": MODELS}
    out = {k: 0.0 for k in groups}
    for (fname, _line, _func), (_cc, _nc, _tt, _ct, callers) in stats.stats.items():  # type: ignore[attr-defined]
        for name, where in groups.items():
            if not _inside(fname, where) or (name == "model arithmetic" and _inside(fname, COMPILED_STEP)):
                continue
            for (cfile, _cl, _cf), (_c1, _c2, _t, ct) in callers.items():
                if not _inside(cfile, where):
                    out[name] += ct
    out["total"] = stats.total_tt  # type: ignore[attr-defined]
    out["orchestration"] = out["total"] - out["linear algebra"] - out["model arithmetic"] - out["compiled step"]
    return out


def profile(label: str, case: dynsens.Case, sensitivities: bool) -> None:
    dynsens.run_case(case, sensitivities=sensitivities, history=())    # warm-up
    prof = cProfile.Profile()
    prof.enable()
    res = dynsens.run_case(case, sensitivities=sensitivities, history=())
    prof.disable()
    s = split(pstats.Stats(prof))
    steps = max(res.counters.get("steps", 1), 1)
    us = {k: 1e6 * v / steps for k, v in s.items()}
    print(f"| {label} | {'+ gradient' if sensitivities else 'primal'} | {us['total']:.0f} | "
          + " | ".join(f"{us[k]:.0f} ({100 * s[k] / s['total']:.0f} %)"
                       for k in ("orchestration", "model arithmetic", "linear algebra", "compiled step")) + " |",
          flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--chain-steps", type=int, default=2000)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 1000])
    ap.add_argument("--weir", action="store_true", help="profile the weir too (cases/tyrolean_weir.yaml)")
    args = ap.parse_args()
    print(f"dynsens from {Path(dynsens.__file__).parent}\n")
    print("| case | run | µs per step (profiled) | orchestration | model arithmetic | linear algebra "
          "| compiled step |")
    print("|---|---|---|---|---|---|---|")
    cases = [(f"chain N = {n}", ys.dynsens_case(n, args.chain_steps)) for n in args.sizes]
    if args.weir:
        cases.append(("tyrolean_weir", dynsens.load_case(str(HERE.parent / "cases" / "tyrolean_weir.yaml"))))
    for label, case in cases:
        for sens in (False, True):
            profile(label, case, sens)


if __name__ == "__main__":
    main()
