"""Compile the compiled kernels and steps once, into numba's on-disk cache: ``python -m dynsens.warmup``.

The compiled multibody kernel (``models/multibody/compiled.py``) is compiled on its first use on a
machine, real and complex separately, and so is the compiled step
that calls it (``models/multibody/compiled_step.py``; one signature for every mechanism)
and the compiled step of spring networks (``models/structural/step_kernels.py``; one signature
for every network), and the compiled block of sensitivity steps (``derivatives/direct_step.py``; one
signature for every dense model); all are cached on disk beside the package.  ``make setup`` runs this module
so that a user's first ``dynsens simulate`` takes as long as the second, and so that no reported
timing includes compilation.  It runs a short piece (``--steps`` steps) of each multibody case
with forward partials (real arithmetic), complex partials and a complex-step run of the whole
simulation (complex arithmetic), which reaches every compiled function with every argument type
the runs use, and of the shipped Duffing chain on the sparse path (the spring networks' step).
How long each compilation takes: BENCHMARKS.md ("Figures moved from docstrings").

Usage: python -m dynsens.warmup [CASE.yaml ...] [--steps N]   (default: the shipped mechanisms
and the sparse chain)
"""
from __future__ import annotations

import argparse
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import yaml

from .case.load import Case, load_case, load_case_dict
from .models.multibody.model import MultibodyModel
from .models.structural.model import StructuralModel
from .models.structural.step import serves
from .simulation import run_case

# the shipped mechanisms (together they use every joint, force law and driver the kernel knows,
# and the constraint projection's J_Φ)
DEFAULT_CASES = ("pendulum_3d", "slider_crank", "four_bar", "hydraulic_lever", "tyrolean_weir",
                 "pendulum_projection")
CASES_DIR = Path(__file__).resolve().parent.parent / "cases"
HEARTBEAT = 15.0     # s between the warm-up's "still compiling" lines


def warm_case(case: Case, steps: int = 150) -> float:
    """Compile what ``case`` needs (nothing for structural models); returns the wall time (s).

    Called before every timed run (gradient check, work-precision study, Table 1, benchmarks) so
    that no reported time includes compilation; with a warm cache it costs a fraction of a second.
    """
    from .models.multibody import compiled
    if not compiled.enabled():
        return 0.0
    t0 = time.perf_counter()
    raw = yaml.safe_load(case.text)
    over = [f"integrator.t_end={case.plan.t0 + steps * case.plan.dt!r}", "output.history=none"]
    if isinstance(case.model, StructuralModel):
        # the spring networks' compiled step: real runs only (complex ones iterate in Python)
        if serves(case.model):
            run_case(load_case_dict(raw, case.source, over))
            return time.perf_counter() - t0
        return 0.0
    if not isinstance(case.model, MultibodyModel):
        return 0.0
    for partials in ("forward", "complex"):
        run_case(load_case_dict(raw, case.source, over + [f"sensitivity.partials={partials}"]))
    short = load_case_dict(raw, case.source, over)
    x = short.x0.astype(complex)
    if x.size:
        x[0] += 1e-20j * max(abs(x[0]), 1.0)
    run_case(short, x)
    return time.perf_counter() - t0


@contextmanager
def heartbeat(what: str, every: float = HEARTBEAT, echo: bool = True) -> Iterator[None]:
    """Print ``what`` now and the elapsed time every ``every`` seconds until the block ends: a
    compilation of minutes shows that it is alive."""
    if not echo:
        yield
        return
    print(f"{what} ...", flush=True)
    done = threading.Event()
    t0 = time.perf_counter()

    def tick() -> None:
        while not done.wait(every):
            print(f"  ... {time.perf_counter() - t0:.0f} s (compiling; each kernel is compiled once)", flush=True)
    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def warm(paths: list[Path], steps: int = 150, echo: bool = True) -> float:
    """:func:`warm_case` for each case file, announcing each and its progress; returns the wall
    time (s)."""
    t0 = time.perf_counter()
    for i, path in enumerate(paths, 1):
        with heartbeat(f"warming {path.name} ({i}/{len(paths)})", echo=echo):
            dt = warm_case(load_case(path), steps)
        if echo:
            print(f"warmed {path.name}: {dt:.1f} s", flush=True)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(prog="python -m dynsens.warmup", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cases", nargs="*", type=Path,
                    help="case files (default: the shipped mechanisms and the sparse chain)")
    ap.add_argument("--steps", type=int, default=150, help="steps of each run (default 150)")
    args = ap.parse_args(argv)
    from .models.multibody import compiled
    if not compiled.enabled():
        print("compiled kernel off (numba missing or DYNSENS_KERNEL=numpy): nothing to warm")
        return
    paths = args.cases or [CASES_DIR / f"{n}.yaml" for n in DEFAULT_CASES if (CASES_DIR / f"{n}.yaml").exists()]
    if not paths:
        print("no case files found: pass the cases to warm")
        return
    print(f"compiling dynsens' numba kernels into the on-disk cache, once: typically 2-5 min on 2 cores "
          f"(up to 10 on a busy machine); {len(paths) + (0 if args.cases else 1)} cases", flush=True)
    total = warm(list(paths), args.steps)
    if not args.cases:      # the spring networks' step, on the shipped chain made sparse
        t0 = time.perf_counter()
        with heartbeat("warming duffing_chain.yaml on the sparse path"):
            warm_case(load_case(CASES_DIR / "duffing_chain.yaml", ["model.linear_algebra=sparse"]), args.steps)
        total += time.perf_counter() - t0
        print(f"warmed duffing_chain.yaml on the sparse path: {time.perf_counter() - t0:.1f} s", flush=True)
    print(f"numba cache warm ({total:.1f} s); later runs start at once", flush=True)


if __name__ == "__main__":
    main()
