"""Optimize cases/tower_sizing.yaml, post-check the optimum and record it.

    python scripts/optimize_tower.py [--from OPT.h5]

Runs ``dynsens optimize`` on the tower (or reads a finished run's OPT.h5), reruns the best
design, checks every member's tension, compression and buckling ratio at every stored step,
and writes cases/records/tower_sizing_optimum.yaml (design, mass, iterations, simulations, wall time,
largest ratio) which tests/test_sizing_tower.py checks again.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
import yaml

import dynsens
from dynsens.optimize.verify import format_verification, verify_design
from dynsens.postcheck import check_members

ROOT = Path(__file__).resolve().parent.parent
TOWER = ROOT / "cases" / "tower_sizing.yaml"
RECORD = ROOT / "cases" / "records" / "tower_sizing_optimum.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="source", help="a finished optimization's HDF5 file")
    args = ap.parse_args()
    source = args.source
    if source is None:
        source = str(Path(tempfile.mkdtemp()) / "tower_opt.h5")
        subprocess.run([sys.executable, "-m", "dynsens", "optimize", str(TOWER), "-o", source],
                       check=False)
    case = dynsens.load_case(TOWER)
    with h5py.File(source, "r") as f:
        st = f["optimization/start_0"].attrs
        x = np.asarray(st["x_opt"], float)
        stats = {"iterations": int(st["nit"]), "simulations": int(st["nfev"])}
        status = str(f.attrs.get("status", ""))
        wall = float(st["wall_time"])
        names = json.loads(f["optimization"].attrs["response_names"])
        responses = dict(zip(names, np.asarray(st["responses_opt"], float).tolist()))
        labels = [c["response"] for c in json.loads(f["optimization"].attrs["constraints"])]
        rounds = len(f["verification/rounds/f"]) - 1 if "verification/rounds" in f else 0
        if rounds:   # every round's iterations, simulations and wall time
            stats = {"iterations": int(np.sum(f["verification/rounds/nit"])),
                     "simulations": int(np.sum(f["verification/rounds/n_sim"]))}
            wall = float(np.sum(f["verification/rounds/wall_time"]))
        tightened = {}
        if rounds:
            base = [float(b) for b in f["verification/rounds/bounds"][0]]
            last = [float(b) for b in f["verification/rounds/bounds"][-1]]
            tightened = {str(i): b for i, (b0, b) in enumerate(zip(base, last)) if b != b0}
    mass0 = float(dynsens.run_case(case, sensitivities=False).responses["mass"].value)
    chk = check_members(case, x)
    member, kind, ratio = chk.worst()
    v = verify_design(case, x, refine=2, horizon="auto", tail=0.1)
    print(format_verification(v))
    record = {
        "case": "tower_sizing.yaml", "status": status, **stats, "wall_time_s": round(wall, 1),
        "mass_start": mass0, "mass": float(responses["mass"]),
        "post_check": {"largest_ratio": chk.largest, "member": member, "kind": kind, "steps": chk.steps,
                       "passes": bool(chk.passes(1e-3))},
        "verification": {"passed": bool(v.passed), "rounds": rounds,
                         "tightened_bounds": {(labels[int(i)] if int(i) < len(labels) else i): b
                                              for i, b in tightened.items()},
                         "largest_ratio": {run: float(m.largest) for run, m in v.members.items()},
                         "runs": {r.name: {"dt": r.dt, "t_end": r.t_end} for r in v.runs}},
        "design": {n: float(v) for n, v in zip(case.design_names, x)},
    }
    RECORD.write_text("# written by scripts/optimize_tower.py from a `dynsens optimize` run\n"
                      + yaml.safe_dump(record, sort_keys=False, width=110), encoding="utf-8")
    print(f"mass {mass0:.4f} t -> {record['mass']:.4f} t ({100 * (1 - record['mass'] / mass0):.1f} % lighter); "
          f"post-check largest ratio {chk.largest:.5f} ({member}, {kind}); {stats}; wall {wall:.0f} s")


if __name__ == "__main__":
    main()
