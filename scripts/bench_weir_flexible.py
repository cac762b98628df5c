"""Wall time (s) of the flexible weir (cases/tyrolean_weir_flexible.yaml) over its first 0.5 s:
primal, direct and adjoint sensitivities, three repeats each, medians; for BENCHMARKS.md."""
import copy
import statistics
import time
from dataclasses import replace
from pathlib import Path

import yaml

import dynsens
from dynsens.case.load import load_case_dict

CASE = Path(__file__).resolve().parents[1] / "cases" / "tyrolean_weir_flexible.yaml"


def main(t_end: float = 0.5, repeats: int = 3) -> None:
    """Print the wall times and their median per mode."""
    raw = yaml.safe_load(CASE.read_text(encoding="utf-8"))
    raw["integrator"]["t_end"] = t_end
    raw.pop("optimization")
    for mode in ("primal", "direct", "adjoint"):
        r = copy.deepcopy(raw)
        r["sensitivity"]["enabled"] = mode != "primal"
        case = load_case_dict(r)
        if mode == "adjoint":
            case.plan = replace(case.plan, method="adjoint")
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            dynsens.run_case(case)
            times.append(time.perf_counter() - t0)
        print(mode, [round(t, 2) for t in times], "median", round(statistics.median(times), 2), flush=True)


if __name__ == "__main__":
    main()
