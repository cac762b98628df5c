"""A planar chain of N links with a rotational spring-damper at every joint: seconds per step,
before and after rotational spring-dampers joined the compiled multibody kernel, side by side.

The case (built below as YAML): N rigid links of a 1 m, 1 kg/m cantilever, the first hinged to
the ground, each next one to the last by a revolute about z; a rotational spring-damper at every
joint (stiffness k = EI/ℓ, EI = 12 N·m², damping c = 0.01 N·m·s/rad), gravity −9.81 m/s² in y;
released straight (horizontal) at rest, so the chain sags and swings like a flexible beam (the
test set's "beam" problem).  Design variables: k and c (every spring shares them).

Per-step cost: each tree runs the same case over two horizons (``--steps``) in alternation;
the marginal cost per step is the difference of the run times over the difference of the step
counts (the assembly and initial conditions, paid once per run, drop out); the median over
``--repeats``.  Primal runs, and with ``--sensitivities`` also runs with the two design
sensitivities (direct mode, complex partials).  Every tree is warmed up first (numba compiles,
or loads its cache, before any timing).

Trees: "after" is the dynsens this script belongs to; "before" is the base commit (``--base``,
default 85aec78, where rotational spring-dampers were Python force elements with complex-step
Jacobians), extracted with ``git archive`` into ``--base-dir``.  Each tree is timed in its own
subprocess (PYTHONPATH set to it), one after the other.

Run: python scripts/bench_rotational_chain.py [--links 40] [--steps 5 25] [--repeats 3] [--sensitivities]
(dynsens is imported before numpy, so that its single-threaded BLAS setting takes effect.)
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
LENGTH, MASS_PER_LENGTH, EI, DAMPING, THICKNESS = 1.0, 1.0, 12.0, 0.01, 0.01


def chain_case(n: int, steps: int, dt: float = 1.0e-3) -> dict[str, Any]:
    """The N-link chain as a case dictionary (the YAML of a case file), over ``steps`` steps."""
    ell = LENGTH / n
    m = MASS_PER_LENGTH * ell
    i_axial = m * THICKNESS ** 2 / 8.0                   # a slender round bar: tiny about its axis
    i_bend = m * ell ** 2 / 12.0
    bodies = {f"link{i + 1}": {"mass": m, "inertia": [i_axial, i_bend, i_bend],
                               "position": [(i + 0.5) * ell, 0.0, 0.0]} for i in range(n)}
    joints, forces = [], []
    for i in range(n):
        b1 = "ground" if i == 0 else f"link{i}"
        b2 = f"link{i + 1}"
        joints.append({"name": f"hinge{i + 1}", "type": "revolute", "body_1": b1, "body_2": b2,
                       "point": [i * ell, 0.0, 0.0], "axis": [0, 0, 1]})
        forces.append({"type": "rotational_spring_damper", "name": f"spring{i + 1}", "body_1": b1,
                       "body_2": b2, "axis": [0, 0, 1], "stiffness": "k", "damping": "c"})
    return {
        "name": f"rotational_chain_{n}",
        "description": f"{n}-link planar chain with a rotational spring-damper at every joint",
        "design": {"variables": [{"name": "k", "value": EI / ell, "lower": 0.5 * EI / ell, "upper": 2 * EI / ell},
                                 {"name": "c", "value": DAMPING, "lower": 0.0, "upper": 1.0}]},
        "model": {"type": "multibody", "gravity": [0.0, -9.81, 0.0], "bodies": bodies,
                  "joints": joints, "forces": forces},
        "integrator": {"scheme": "newmark", "dt": dt, "t_end": steps * dt},
        "sensitivity": {"enabled": True, "partials": "complex"},
        "responses": [{"name": "tip_y", "type": "value", "quantity": {"body": f"link{n}", "kind": "position"},
                       "component": f"link{n}.y", "unit": "m"}],
    }


def measure(n: int, steps: tuple[int, int], repeats: int, sensitivities: list[bool]) -> dict[str, Any]:
    """Median marginal seconds per step of this process's dynsens, per sensitivity setting."""
    import dynsens  # first: it sets BLAS single-threaded before numpy loads  # noqa: I001
    import numpy as np

    cases = {s: dynsens.load_case_dict(chain_case(n, s), source=f"rotational_chain_{n}.yaml") for s in steps}
    for sens in sensitivities:                         # warm up: compile (or load) every path used
        res = dynsens.run_case(cases[steps[0]], sensitivities=sens)
        assert res.status == "completed", res.message
    out: dict[str, Any] = {"dynsens": str(Path(dynsens.__file__).parent)}
    per: dict[bool, list[float]] = {s: [] for s in sensitivities}
    for _ in range(repeats):
        for sens in sensitivities:
            wall = []
            for s in steps:
                t0 = time.perf_counter()
                res = dynsens.run_case(cases[s], sensitivities=sens)
                wall.append(time.perf_counter() - t0)
                assert res.status == "completed", res.message
            per[sens].append((wall[1] - wall[0]) / (steps[1] - steps[0]))
            if not sens:
                out["tip_y"] = float(res.responses["tip_y"].value)
            else:
                out["gradient"] = [float(g) for g in res.responses["tip_y"].gradient]
    out["per_step"] = {("sens" if s else "primal"): float(np.median(v)) for s, v in per.items()}
    out["all"] = {("sens" if s else "primal"): v for s, v in per.items()}
    return out


def _base_tree(commit: str, where: Path) -> Path:
    """The base commit's files under ``where`` (extracted once with git archive)."""
    tree = where / commit
    if not (tree / "dynsens" / "__init__.py").exists():
        tree.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], check=True, capture_output=True)
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive.stdout, check=True)
    return tree


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--links", type=int, default=40)
    ap.add_argument("--steps", type=int, nargs=2, default=[5, 25], help="the two horizons, in steps of 1 ms")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--sensitivities", action="store_true", help="also runs with the two design sensitivities")
    ap.add_argument("--base", default="85aec78", help="the commit timed as 'before'")
    ap.add_argument("--base-dir", type=Path, default=Path("/tmp/dynsens-bench-base"))
    ap.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)   # (the subprocess)
    return ap.parse_args()


def main() -> None:
    a = _args()
    sens = [False, True] if a.sensitivities else [False]
    if a.measure:
        print(json.dumps(measure(a.links, tuple(a.steps), a.repeats, sens)))  # type: ignore[arg-type]
        return
    trees = {f"before ({a.base})": _base_tree(a.base, a.base_dir), "after": ROOT}
    results = {}
    for label, tree in trees.items():
        env = dict(os.environ, PYTHONPATH=str(tree))
        cmd = [sys.executable, str(Path(__file__).resolve()), "--measure", "--links", str(a.links),
               "--steps", *map(str, a.steps), "--repeats", str(a.repeats)]
        cmd += ["--sensitivities"] if a.sensitivities else []
        done = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True, cwd=tree)
        results[label] = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{label}: {results[label]}", file=sys.stderr, flush=True)
    print(f"{a.links}-link chain, {a.links} rotational spring-dampers, dt = 1 ms, marginal cost per step over "
          f"{a.steps[0]}→{a.steps[1]} steps, median of {a.repeats}")
    sens_col = " + 2 sensitivities (ms/step) |" if a.sensitivities else ""
    print(f"| tree | primal (ms/step) |{sens_col} tip y at end (m) |")
    print("|---|---|" + ("---|" if a.sensitivities else "") + "---|")
    for label, r in results.items():
        ps = r["per_step"]
        row = f"| {label} | {1e3 * ps['primal']:.2f} |" + (f" {1e3 * ps['sens']:.2f} |" if a.sensitivities else "")
        print(row + f" {r['tip_y']:.12g} |")
    b, f = results[f"before ({a.base})"]["per_step"], results["after"]["per_step"]
    print("speed-up: " + ", ".join(f"{k} {b[k] / f[k]:.1f}×" for k in b))


if __name__ == "__main__":
    main()
