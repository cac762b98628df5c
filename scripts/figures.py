"""The figures in docs/: rebuild them all (``make figures``) or check cheaply that they are current
(``make figures-check``, run by CI).

    python scripts/figures.py make      # every figure, by the command that makes it (≈ 2 h; --jobs 2: ≈ 1 h)
    python scripts/figures.py make --from NAME   # resume a run that stopped at figure NAME
    python scripts/figures.py make --jobs 2      # two figures at a time
    python scripts/figures.py check     # a few short runs (a few minutes): fails on a stale figure

Comparing the pictures themselves would be fragile (matplotlib's rendering, fonts and PNG
encoder vary between versions and machines) and would need the expensive runs.  Instead every
figure has a *probe*: short runs of the model the figure shows, at the design it shows, whose
responses and gradients are numbers that the figure is drawn from (the semi-analytical
gradients that every point of Fig. 5 divides by, the coarsest step of a work-precision curve,
the first point of an optimization history, the designs a study draws, ...).  ``make figures``
rebuilds the figures and writes the probes' values to ``docs/figures.json``; ``check`` runs the
probes on the current code and fails, naming each figure and its command, when a value moved by
more than ``RTOL`` relative (a vector relative to its largest entry).  A code change that moves
what a figure shows moves its probe, so the figure cannot silently go stale; a change that
leaves every probe unchanged (a refactoring) does not force a rebuild.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "docs" / "figures.json"
# a figure shows three digits at best; the weir's event-located gradients move by up to 5e-5
# between the compiled and the numpy kernel (summation order, a condition number near 1e13), and
# could between machines
RTOL = 1e-3
WEIR = "cases/tyrolean_weir.yaml"
DYNSENS = [sys.executable, "-m", "dynsens"]


@lru_cache(maxsize=None)
def _run(case: str, sensitivities: bool, x: tuple[float, ...] | None = None,
         overrides: tuple[tuple[str, Any], ...] = ()) -> dict[str, Any]:
    """Responses (and gradients) of one run, as lists of floats (runs shared by probes once)."""
    import dynsens
    sim = dynsens.simulate(ROOT / case, None if x is None else np.array(x), sensitivities=sensitivities,
                           history=(), **dict(overrides))
    out: dict[str, Any] = {"values": {k: float(v) for k, v in sorted(sim.values.items())}}
    if sensitivities:
        out["gradients"] = {k: [float(g) for g in v] for k, v in sorted(sim.gradients.items())}
    return out


def _tower_optimum() -> tuple[float, ...]:
    import dynsens
    record = yaml.safe_load((ROOT / "cases" / "records" / "tower_sizing_optimum.yaml").read_text(encoding="utf-8"))
    case = dynsens.load_case(ROOT / "cases" / "tower_sizing.yaml")
    return tuple(float(record["design"][name]) for name in case.design_names)


def _study_designs() -> dict[str, Any]:
    import dynsens
    from dynsens.study.sampling import sample_designs
    designs = sample_designs(dynsens.load_case(ROOT / WEIR), "lhs:24", 18)
    return {"designs": designs.tolist(), "first": _run(WEIR, True, tuple(designs[0]))}


GS240 = "results/ground_structure_240.yaml"


def _ground_structure_240() -> dict[str, Any]:
    """The 240-bar ground structure (the shipped generator at nx 9, ny 5, reach 2), start design."""
    import dynsens
    sys.path.insert(0, str(ROOT / "scripts"))
    from make_ground_structure import ground_structure
    sim = dynsens.simulate(dynsens.load_case_dict(ground_structure(9, 5, 2), "ground_structure_240.yaml"),
                           sensitivities=False, history=())
    return {"values": {k: float(v) for k, v in sorted(sim.values.items())}}


GS = "cases/ground_structure.yaml"


def _ground_structure() -> dict[str, Any]:
    """The shipped 2,252-bar ground structure at its start design."""
    import dynsens
    sim = dynsens.simulate(dynsens.load_case(ROOT / GS), sensitivities=False, history=())
    return {"values": {k: float(v) for k, v in sorted(sim.values.items())}}


GS2 = "cases/ground_structure_two_loads.yaml"


def _ground_structure_push() -> dict[str, Any]:
    """The two-load-case ground structure's second load case (push) at its start design (the
    first, impact, is the one-load-case ground structure's probe)."""
    import dynsens
    from dynsens.case.load_cases import load_case_set_file
    sim = dynsens.simulate(load_case_set_file(ROOT / GS2).case("push"), sensitivities=False, history=())
    return {"values": {k: float(v) for k, v in sorted(sim.values.items())}}


@dataclass(frozen=True)
class Figure:
    """A figure (or a set made by one command), the commands that make it and its probe."""
    name: str
    paths: tuple[str, ...]
    commands: tuple[tuple[str, ...], ...]
    probe: Callable[[], dict[str, Any]] = field(compare=False)
    # exit statuses that still made the figure: `optimize` exits 1 at its iteration limit, whose
    # design (feasible, verified) a figure may show
    statuses: tuple[int, ...] = (0,)


FIGURES = (
    Figure("fig5", ("docs/fig5.png",),
           ((sys.executable, "scripts/reproduce_table1.py", "--figure", "docs/fig5.png"),),
           lambda: {mode: _run(WEIR, True, None, (("integrator.event_location", mode),))
                    for mode in ("step", "interpolate")}),
    Figure("duffing_chain work-precision", ("docs/duffing_chain_tip_end_work_precision.png",),
           ((*DYNSENS, "convergence", "cases/duffing_chain.yaml", "--set", "integrator.t_end=1",
             "--dt", "0.004,0.002,0.001,0.0005", "-o", "results/convergence"),
            ("cp", "results/convergence/duffing_chain_tip_end_work_precision.png", "docs/")),
           lambda: _run("cases/duffing_chain.yaml", True, None, (("integrator.t_end", 1.0), ("integrator.dt", 0.004)))),
    Figure("weir work-precision", ("docs/tyrolean_weir_f_work_precision.png",),
           ((*DYNSENS, "convergence", WEIR, "--dt", "0.004,0.002,0.001", "--methods", "ddm-forward,fd-forward",
             "-o", "results/convergence"),
            ("cp", "results/convergence/tyrolean_weir_f_work_precision.png", "docs/")),
           lambda: _run(WEIR, True, None, (("integrator.dt", 0.004),))),
    Figure("weir optimization history", ("docs/weir_opt_history.png",),
           ((*DYNSENS, "optimize", WEIR, "-o", "results/weir_opt.h5", "--overwrite", "--plots", "results/weir_plots"),
            ("cp", "results/weir_plots/weir_opt_history.png", "docs/weir_opt_history.png")),
           lambda: _run(WEIR, True)),
    Figure("weir study", ("docs/weir_study/study_pairs.png", "docs/weir_study/study_sensitivity.png",
                          "docs/weir_study/study_responses.png"),
           ((*DYNSENS, "study", WEIR, "-o", "results/weir_study.h5", "--sample", "lhs:24", "--seed", "18",
             "--gradients", "--workers", "2", "--plots", "docs/weir_study", "--overwrite"),),
           _study_designs),
    # (the committed picture came from 80 + 150 MMA iterations with a restart, BENCHMARKS.md; this
    # command runs the 230 in one go, so `make figures` replaces it with a nearly equal design)
    Figure("ground structure 240 topology", ("docs/ground_structure_240_topology.png",),
           (("mkdir", "-p", "results"),
            (sys.executable, "scripts/make_ground_structure.py", "--nx", "9", "--ny", "5", "--reach", "2",
             "--output", GS240),
            (*DYNSENS, "optimize", GS240, "--maxiter", "230", "-o", "results/ground_structure_240_opt.h5",
             "--overwrite"),
            (sys.executable, "scripts/plot_topology.py", GS240, "results/ground_structure_240_opt.h5",
             "docs/ground_structure_240_topology.png")),
           _ground_structure_240, statuses=(0, 1)),
    # three verified optimizations, about 20 min on 2 cores (docs/weir_flexible.md); the probe is the start design
    Figure("virtuous circle", ("docs/virtuous_circle.png",),
           ((sys.executable, "scripts/virtuous_circle.py", "--figure", "docs/virtuous_circle.png"),),
           lambda: _run("cases/tyrolean_weir_flexible.yaml", False)),
    # three verified optimizations of the slider crank, about a minute
    Figure("crank circle", ("docs/crank_circle.png",),
           ((sys.executable, "scripts/crank_circle.py", "--figure", "docs/crank_circle.png"),),
           lambda: _run("cases/crank_circle.yaml", False)),
    Figure("views", ("docs/tyrolean_weir.gif", "docs/tower_stress_ratio.png"),
           ((sys.executable, "scripts/make_view_figures.py"),),
           lambda: {"weir": _run(WEIR, False), "tower": _run("cases/tower_sizing.yaml", False, _tower_optimum())}),
    # 80 MMA iterations of 2,252 variables with the verification, about 40 min on 2 shared cores
    # (BENCHMARKS.md, 2026-11-29); the probe is the start design
    Figure("ground structure topology", ("docs/ground_structure_topology.png",),
           (("mkdir", "-p", "results"),
            (*DYNSENS, "optimize", GS, "--maxiter", "80", "-o", "results/ground_structure_opt.h5", "--overwrite"),
            (sys.executable, "scripts/plot_topology.py", GS, "results/ground_structure_opt.h5",
             "docs/ground_structure_topology.png")),
           _ground_structure, statuses=(0, 1)),
    # the same under two load cases: twice the simulations per iteration, run side by side
    Figure("ground structure two loads topology", ("docs/ground_structure_two_loads_topology.png",),
           (("mkdir", "-p", "results"),
            (*DYNSENS, "optimize", GS2, "--maxiter", "80", "--workers", "2", "-o",
             "results/ground_structure_two_loads_opt.h5", "--overwrite"),
            (sys.executable, "scripts/plot_topology.py", GS2, "results/ground_structure_two_loads_opt.h5",
             "docs/ground_structure_two_loads_topology.png")),
           _ground_structure_push, statuses=(0, 1)),
)


def probes() -> dict[str, Any]:
    """Every figure's probe values, by figure name."""
    return {f.name: f.probe() for f in FIGURES}


def _numbers(x: Any) -> bool:
    return isinstance(x, list) and all(isinstance(v, (int, float)) for v in x)


def differences(recorded: Any, current: Any, where: str = "") -> list[str]:
    """Where two probe records differ: keys, lengths, or numbers beyond ``RTOL``.  A vector (a
    gradient, a design) is compared as a whole, relative to its largest entry: a component near
    zero may move by round-off of the others."""
    if isinstance(recorded, dict) and isinstance(current, dict):
        if recorded.keys() != current.keys():
            return [f"{where}: keys {sorted(recorded)} recorded, {sorted(current)} now"]
        return [d for k in recorded for d in differences(recorded[k], current[k], f"{where}.{k}" if where else k)]
    if isinstance(recorded, list) and isinstance(current, list):
        if len(recorded) != len(current):
            return [f"{where}: {len(recorded)} entries recorded, {len(current)} now"]
        if not (_numbers(recorded) and _numbers(current)):
            return [d for i, (a, b) in enumerate(zip(recorded, current)) for d in differences(a, b, f"{where}[{i}]")]
    a, b = np.atleast_1d(np.asarray(recorded, float)), np.atleast_1d(np.asarray(current, float))
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return [f"{where}: {recorded!r} recorded, {current!r} now"]
    a, b = np.nan_to_num(a), np.nan_to_num(b)
    scale = max(np.max(np.abs(a), initial=0.0), np.max(np.abs(b), initial=0.0))
    moved = np.abs(a - b) > RTOL * scale
    if not moved.any():
        return []
    i = int(np.argmax(np.abs(a - b)))
    at = f"[{i}]" if np.ndim(recorded) else ""
    share = abs(a[i] - b[i]) / scale
    return [f"{where}{at}: {float(a[i])!r} recorded, {float(b[i])!r} now ({share:.1e} of the largest entry)"]


def record() -> None:
    """Write the probes' values beside the figures (docs/figures.json), atomically; only
    :func:`make` calls it, after every figure was rebuilt (a record is never written alone)."""
    data = {"about": "written by `make figures` (scripts/figures.py); `make figures-check` compares "
                     "each figure's probe with these values",
            "rtol": RTOL,
            "figures": {f.name: {"paths": list(f.paths), "commands": [" ".join(c[1:] if c[0] == sys.executable
                                                                               else c) for c in f.commands],
                                 "probe": f.probe()} for f in FIGURES}}
    tmp = RECORD.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    tmp.replace(RECORD)
    print(f"written: {RECORD}")


def _build(f: Figure, log: Path | None) -> float:
    """Run a figure's commands (their output to ``log``, or here); the wall time (s)."""
    t0 = time.perf_counter()
    out = None if log is None else log.open("w", encoding="utf-8")
    try:
        for cmd in f.commands:
            print(f"$ {' '.join(cmd)}", file=out or sys.stdout, flush=True)
            status = subprocess.run(cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT if out else None).returncode
            if status not in f.statuses:
                raise SystemExit(f"{f.name}: `{' '.join(cmd)}` exited with status {status}"
                                 + (f" (its output: {log})" if log else ""))
    finally:
        if out is not None:
            out.close()
    return time.perf_counter() - t0


def make(start: str | None = None, jobs: int = 1) -> None:
    """Rebuild every figure by its commands (from the one named ``start`` on: a run that stopped
    there resumes), ``jobs`` figures at a time, then record the probes.  The figures write
    outputs of their own, so they may run side by side; with ``jobs`` > 1 each one's output goes
    to results/figure-logs/."""
    names = [f.name for f in FIGURES]
    if start is not None and start not in names:
        raise SystemExit(f"--from {start!r}: no such figure; the figures are {names}")
    todo = FIGURES[names.index(start) if start else 0:]
    logs = ROOT / "results" / "figure-logs"
    if jobs > 1:
        logs.mkdir(parents=True, exist_ok=True)

    failed = threading.Event()      # after a failure no further figure starts

    def build(f: Figure) -> None:
        if failed.is_set():
            return
        log = logs / (f.name.replace(" ", "_") + ".log") if jobs > 1 else None
        if log is not None:
            print(f"making {f.name} (output: {log.relative_to(ROOT)})", flush=True)
        try:
            print(f"made {f.name}: {_build(f, log):.0f} s", flush=True)
        except SystemExit:
            failed.set()
            raise

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        for done in [pool.submit(build, f) for f in todo]:
            done.result()           # the first failure stops `make` (figures running finish first)
    record()


def check() -> int:
    """0 when every figure's probe equals its record, 1 (naming the stale figures) otherwise."""
    if not RECORD.exists():
        print(f"{RECORD} missing: run `make figures`", file=sys.stderr)
        return 1
    recorded = json.loads(RECORD.read_text(encoding="utf-8"))["figures"]
    stale = []
    for f in FIGURES:
        t0 = time.perf_counter()
        missing = [p for p in f.paths if not (ROOT / p).exists()]
        diffs = ([f"missing {', '.join(missing)}"] if missing else []) + \
            (["no record"] if f.name not in recorded else differences(recorded[f.name]["probe"], f.probe()))
        print(f"{f.name}: {'current' if not diffs else 'STALE'} ({time.perf_counter() - t0:.1f} s)", flush=True)
        if diffs:
            stale.append((f, diffs))
    for f, diffs in stale:
        print(f"\n{f.name} ({', '.join(f.paths)}) is stale:", file=sys.stderr)
        for d in diffs[:8]:
            print(f"  {d}", file=sys.stderr)
        if len(diffs) > 8:
            print(f"  ... and {len(diffs) - 8} more", file=sys.stderr)
    if stale:
        print("\nrebuild with `make figures` (and commit docs/ with docs/figures.json)", file=sys.stderr)
        return 1
    print(f"all {len(FIGURES)} figure sets current")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("action", choices=("make", "check"))
    ap.add_argument("--from", dest="start", metavar="FIGURE",
                    help="make: rebuild from this figure on (the earlier ones were rebuilt by a run that stopped)")
    ap.add_argument("--jobs", type=int, default=1, help="make: figures built side by side (default 1)")
    args = ap.parse_args(argv)
    if args.action == "make":
        make(args.start, args.jobs)
        return 0
    return check()


if __name__ == "__main__":
    sys.exit(main())
