"""Time two source trees of dynsens side by side: the same cases, interleaved, in fresh processes.

Each measurement runs ``run_case`` once (after a warm-up run in the same process) without and
with sensitivities and reports the median wall (or, with ``--clock cpu``, CPU) times of each
tree and their ratio.  Usage:

    git worktree add /tmp/before <commit>
    python scripts/bench_versions.py /tmp/before . cases/tyrolean_weir.yaml --repeats 3

The same tree under two environments, e.g. the numpy kernel against the compiled one:

    python scripts/bench_versions.py . . cases/slider_crank.yaml --before-env DYNSENS_KERNEL=numpy
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, sys, time
import dynsens
case = dynsens.load_case(sys.argv[1], ["output.history=none"] + sys.argv[4:])
sens = sys.argv[2] == "1"
dynsens.run_case(case, sensitivities=sens)
clock = time.process_time if sys.argv[3] == "cpu" else time.perf_counter
t0 = clock()
dynsens.run_case(case, sensitivities=sens)
print(json.dumps({"seconds": clock() - t0, "package": dynsens.__file__}))
"""


def time_once(tree: Path, case: Path, sens: bool, overrides: list[str], extra_env: dict[str, str],
              clock: str = "wall") -> float:
    """Wall or CPU time (s, ``clock``) of one run of ``case`` with the dynsens package of ``tree``."""
    root = tree.resolve()
    env = dict(os.environ, PYTHONPATH=str(root), **extra_env)
    # run inside the tree: `python -c` puts the working directory first on sys.path
    out = subprocess.run([sys.executable, "-c", CHILD, str(case.resolve()), "1" if sens else "0", clock, *overrides],
                         env=env, cwd=root, capture_output=True, text=True, check=True)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    if not Path(res["package"]).resolve().is_relative_to(root):
        raise RuntimeError(f"{root}: imported dynsens from {res['package']}, not from the tree")
    return float(res["seconds"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("before", type=Path, help="source tree of the earlier version")
    ap.add_argument("after", type=Path, help="source tree of the later version")
    ap.add_argument("cases", nargs="+", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="wall time, or the process's CPU time (steadier on a loaded machine)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="case override")
    for side in ("before", "after"):
        ap.add_argument(f"--{side}-env", action="append", default=[], metavar="KEY=VALUE",
                        help=f"environment variable of the {side} runs")
    args = ap.parse_args()
    envs = {side: dict(kv.split("=", 1) for kv in getattr(args, f"{side}_env")) for side in ("before", "after")}
    print("| case | run | before [s] | after [s] | after / before |")
    print("|---|---|---|---|---|")
    for case in args.cases:
        for sens in (False, True):
            t: dict[str, list[float]] = {"before": [], "after": []}
            for _ in range(args.repeats):
                for name in ("before", "after"):
                    t[name].append(time_once(getattr(args, name), case, sens, args.overrides, envs[name],
                                                 args.clock))
            b, a = statistics.median(t["before"]), statistics.median(t["after"])
            label = "primal + sensitivities" if sens else "primal"
            print(f"| {case.stem} | {label} | {b:.3f} | {a:.3f} | {a / b:.2f} |", flush=True)


if __name__ == "__main__":
    main()
