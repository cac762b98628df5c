"""Each element's residual derivatives (the Newton matrix blocks) against complex step."""
import numpy as np
import pytest

import dynsens
from dynsens.models.base import StepState, as_dense
from conftest import CASES

TRUSS_3D = {
    "design": {"variables": [{"name": "A", "value": 100.0, "lower": 1, "upper": 1e3}]},
    "model": {"type": "structural", "dim": 3,
              "nodes": {"a": {"coords": [0, 0, 0], "fixed": "all"}, "b": {"coords": [1000, 0, 0], "fixed": "all"},
                        "c": {"coords": [500, 800, 300]}, "d": {"coords": [0, 900, 0], "fixed": "all"}},
              "elements": [{"type": "bar", "name": f"b{i}", "nodes": [n, "c"], "area": "A", "E": 2.1e5,
                            "density": 7.85e-9} for i, n in enumerate("abd")]
              + [{"type": "spring", "name": "s", "dofs": ["c.x", "ground"], "k": 10.0, "k2": 1.0, "k3": "0.5*A"},
                 {"type": "damper", "name": "dmp", "dofs": ["c.y", "c.z"], "c": 0.3}],
              "damping": {"rayleigh": {"alpha": 0.1, "beta": 1e-4}}},
    "integrator": {"dt": 1e-4, "t_end": 1e-3},
}


def _cases():
    yield "duffing_chain", dynsens.load_case(CASES / "duffing_chain.yaml")
    yield "truss_impact", dynsens.load_case(CASES / "truss_impact.yaml")
    yield "truss_3d", dynsens.load_case_dict(TRUSS_3D)


@pytest.mark.parametrize("name,case", list(_cases()))
def test_linearization_matches_complex_step(name, case):
    rng = np.random.default_rng(0)
    model = case.model
    n = model.traits.n_q
    params = model.parameters(case.x0)
    s = StepState(rng.normal(size=n) * 5, rng.normal(size=n), rng.normal(size=n), np.zeros(0), np.zeros(0), np.zeros(0))
    lin = model.linearize(0.01, s, params)
    h = 1e-30
    for block, field in ((lin.R_q, "q"), (lin.R_qd, "qd"), (lin.R_z, "qdd")):
        J = np.zeros((n, n))
        for j in range(n):
            pert = s._replace(**{field: getattr(s, field) + 1j * h * np.eye(n)[j]})
            J[:, j] = np.imag(model.residual(0.01, pert, params)) / h
        B = np.zeros((n, n)) if block is None else as_dense(block)
        assert np.allclose(B, J, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(J).max())), field
