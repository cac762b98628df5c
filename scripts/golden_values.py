"""Golden values of every shipped case: responses, gradients (direct and adjoint), the final
state and the counters, stored bit for bit (values as float hex, gradients and states as SHA-256
of their bits), so that a restructuring of the code can show that no number moved
(tests/test_golden_values.py).

Each case runs over its first ``STEPS`` steps (t_end shortened; a case that ends sooner runs
whole), once per derivative mode that applies to it; a file with load cases, once per load case
(`stem@name`).

    python scripts/golden_values.py --write      # after a change that is meant to move numbers
    python scripts/golden_values.py              # compare, print the differences
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

import dynsens
from dynsens.case.load_cases import has_load_cases, load_case_set_file

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"
GOLDEN = ROOT / "tests" / "golden_values.json"
STEPS = 10
# counters that measure the machine, not the numbers
VOLATILE = ("wall", "time", "compile", "cache")


def _hex(a: Any) -> Any:
    """Lists of float hex strings (complex: [re, im])."""
    a = np.asarray(a)
    if np.iscomplexobj(a):
        return [_hex(a.real), _hex(a.imag)]
    return [float(v).hex() for v in np.ravel(a).astype(float)]


def _digest(a: Any) -> str:
    """SHA-256 of an array's bits and shape (a gradient or a state: too long to store whole)."""
    a = np.ascontiguousarray(np.asarray(a))
    return hashlib.sha256(repr((a.dtype.str, a.shape)).encode() + a.tobytes()).hexdigest()


def loaders(path: Path) -> dict[str, Callable[[list[str]], Any]]:
    """The runs a case file holds, by label: the case (its stem), or each of its load cases
    (``stem@name``), each a loader taking ``--set`` overrides (applied to the base case)."""
    if not has_load_cases(path):
        return {path.stem: lambda ov: dynsens.load_case(path, ov)}
    names = list(load_case_set_file(path).cases)
    return {f"{path.stem}@{n}": (lambda ov, n=n: load_case_set_file(path, ov).cases[n]) for n in names}


def case_values(load: Callable[[list[str]], Any], method: str) -> dict[str, Any]:
    """The golden record of one case (``load``: its loader) and derivative mode."""
    case = load([])
    t_end = min(case.plan.t_end, case.plan.t0 + STEPS * case.plan.dt)
    case = load([f"integrator.t_end={t_end!r}", f"sensitivity.method={method}"])
    res = dynsens.run_case(case, history=("q",))
    return {
        "status": res.status,
        "method": res.method,
        "steps": len(res.time) - 1,
        "responses": {k: {"value": _hex(v.value), "gradient": None if v.gradient is None else _digest(v.gradient)}
                      for k, v in res.responses.items()},
        "final_q": _digest(res.history["q"][-1]),
        "counters": {k: int(v) for k, v in res.counters.items()
                     if not any(w in k for w in VOLATILE) and isinstance(v, (int, np.integer))},
    }


def methods(load: Callable[[list[str]], Any]) -> list[str]:
    """direct, and adjoint where the case allows it (its responses have adjoint seeds)."""
    case = load([])
    if not case.plan.sensitivities:
        return ["direct"]
    try:
        load(["sensitivity.method=adjoint"])
    except dynsens.CaseError:
        return ["direct"]
    return ["direct", "adjoint"]


# cases whose records are not (yet) reproducible bit for bit from one environment to another, with
# the reason; each is still checked by its own tests
NOT_RECORDED = {
    # its buckling KS differed between the tree that wrote the record and a fresh clone (2026-11-28,
    # 2,252 bars); not yet understood: tests/test_ground_structure.py checks it
    "ground_structure": "differs between a warm tree and a fresh clone (under investigation)",
    # the same 2,252 bars under two load cases: the same open question
    "ground_structure_two_loads": "the ground structure's model under two load cases (as above)",
}


def all_values() -> dict[str, Any]:
    out: dict[str, Any] = {}
    for path in sorted(CASES.glob("*.yaml")):
        if path.stem in NOT_RECORDED:
            continue
        for label, load in loaders(path).items():
            for method in methods(load):
                out[f"{label}/{method}"] = case_values(load, method)
    return out


def differences(stored: dict[str, Any], now: dict[str, Any]) -> list[str]:
    """Human-readable list of every record that differs."""
    out = []
    for key in sorted(set(stored) | set(now)):
        if key not in stored or key not in now:
            out.append(f"{key}: only {'now' if key in now else 'stored'}")
            continue
        a, b = stored[key], now[key]
        for field in ("status", "method", "steps", "final_q", "counters"):
            if a[field] != b[field]:
                out.append(f"{key}: {field} differs")
        for name in sorted(set(a["responses"]) | set(b["responses"])):
            if a["responses"].get(name) != b["responses"].get(name):
                out.append(f"{key}: response {name} differs")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help=f"store the values in {GOLDEN.relative_to(ROOT)}")
    args = ap.parse_args()
    now = all_values()
    if args.write:
        GOLDEN.write_text(json.dumps(now, indent=1, sort_keys=True) + "\n", encoding="utf-8")
        print(f"written: {GOLDEN} ({len(now)} runs)")
        return
    diff = differences(json.loads(GOLDEN.read_text(encoding="utf-8")), now)
    print("\n".join(diff) if diff else f"all {len(now)} runs bit-identical")
    sys.exit(1 if diff else 0)


if __name__ == "__main__":
    main()
