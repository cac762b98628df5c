"""scripts/virtuous_circle.py: the sequential design's case (the rack sized for a fixed mechanism)
is the flexible weir with the mechanism's variables made constants: the same run, the sections'
gradients the same columns."""
from __future__ import annotations

import numpy as np

import dynsens
import scripts_path  # noqa: F401  (puts scripts/ on the path)
from dynsens.case.load import load_case_dict
from virtuous_circle import GEOMETRY, SECTIONS, flexible_raw, with_fixed


def test_fixing_the_mechanism_keeps_the_run_and_the_section_gradients():
    raw = flexible_raw()
    raw.pop("optimization")
    raw["integrator"]["t_end"] = 0.02
    x = {"theta_AZ": -1.1, "l_AZ": 1800.0, "l_BZ": 1700.0, "V_S": 5.2e5, "A_ZL": 1200.0, "A_BL": 700.0}
    full = load_case_dict(raw)
    fixed = load_case_dict(with_fixed(raw, {k: x[k] for k in GEOMETRY}))
    assert tuple(fixed.design_names) == SECTIONS
    text = repr(with_fixed(raw, {k: x[k] for k in GEOMETRY}))
    assert not any(name in text for name in GEOMETRY)
    a = dynsens.run_case(full, np.array([x[n] for n in full.design_names]))
    b = dynsens.run_case(fixed, np.array([x[n] for n in SECTIONS]))
    cols = [list(full.design_names).index(n) for n in SECTIONS]
    for name, r in a.responses.items():
        np.testing.assert_allclose(b.responses[name].value, r.value, rtol=1e-12, err_msg=name)
        np.testing.assert_allclose(b.responses[name].gradient, r.gradient[cols], rtol=1e-10,
                                   atol=1e-12 * np.max(np.abs(r.gradient)), err_msg=name)
