"""The number of Python function calls of one run of a case: a load-independent measure of the
interpreter's share of a step, for A/B checks of two trees on a busy machine (where CPU times
spread by more than the difference sought).

The case runs once untimed (numba compilation and first calls), then once under cProfile; the total
of its call counts is printed.  Compare two trees with ``PYTHONPATH=<tree>``:

    PYTHONPATH=/tmp/before python scripts/count_calls.py cases/duffing_chain.yaml
    PYTHONPATH=. python scripts/count_calls.py cases/duffing_chain.yaml
"""
from __future__ import annotations

import argparse
import cProfile
import pstats

import dynsens


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case")
    ap.add_argument("--primal", action="store_true", help="without sensitivities")
    ap.add_argument("--top", type=int, default=0, help="also list the N functions called most often")
    args = ap.parse_args()
    case = dynsens.load_case(args.case, ["output.history=none"])
    sens = not args.primal
    dynsens.run_case(case, sensitivities=sens)
    prof = cProfile.Profile()
    prof.enable()
    dynsens.run_case(case, sensitivities=sens)
    prof.disable()
    stats = pstats.Stats(prof)
    print(f"{args.case}: {stats.total_calls} Python calls ({dynsens.__file__})")
    if args.top:
        stats.sort_stats("ncalls").print_stats(args.top)


if __name__ == "__main__":
    main()
