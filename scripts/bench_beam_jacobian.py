"""Per-call cost of the beam member's Jacobians: exact jets against the complex step (BENCHMARKS.md,
"Beam member Jacobian"). Run from the tree: `PYTHONPATH=$PWD DYNSENS_KERNEL=numpy python
scripts/bench_beam_jacobian.py [CALLS]`; prints ms per call, blocks interleaved."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from dynsens.case.load import load_case_dict
from dynsens.models.multibody import member_beams
from dynsens.models.multibody.residual import other_forces_jacobians


def main(calls: int) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_mechanism_members import _arm_with_beam
    model = load_case_dict(_arm_with_beam(raw_only=True)).model
    prm = model.parameters(np.array([0.01, 40.0]))
    n = model.traits.n_q
    q = np.zeros(n)
    q[3] = q[10] = 1.0
    q[0], q[7] = 0.5, 1.5 + 1e-3
    qd = np.full(n, 0.1)
    for mode in ("exact", "complex step") * 3:
        member_beams.BeamMember.exact_jacobians = mode == "exact"
        t0 = time.perf_counter()
        for _ in range(calls):
            other_forces_jacobians(model, 0.0, q, qd, prm)
        print(f"{mode}: {1e3 * (time.perf_counter() - t0) / calls:.1f} ms per Jacobian")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
