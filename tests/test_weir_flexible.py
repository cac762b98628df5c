"""The Tyrolean weir with a flexible cleaning rack (cases/tyrolean_weir_flexible.yaml, issue 33):
the coupled gradient of the mechanism's geometry, pump flow and the rack's bar sections, direct
and adjoint, against the complex step of the whole run over a short window."""
from __future__ import annotations

import dynsens
import yaml

from conftest import CASES
from dynsens.case.load import load_case_dict
from helpers import assert_gradients_match_complex_step_and_adjoint


def _weir(t_end):
    """The flexible weir over [0, t_end] (complex partials, so that the complex step of the whole
    run is exact to round-off)."""
    raw = yaml.safe_load((CASES / "tyrolean_weir_flexible.yaml").read_text(encoding="utf-8"))
    raw["integrator"]["t_end"] = t_end
    raw["sensitivity"]["partials"] = "complex"
    raw["responses"] = [r for r in raw["responses"] if r["name"] in (
        "stroke", "ks_force", "theta_0", "rack_mass", "sigma_ZB", "sigma_ZL", "sigma_BL",
        "sigma_c_BL", "buckling_BL", "f", "g1", "g2")]
    raw.pop("optimization")
    return load_case_dict(raw)


def test_flexible_weir_gradients_match_complex_step_and_adjoint():
    """Geometry (θ_AZ, l_AZ, l_BZ), pump flow V_S and the three bar sections through the coupled
    rack–cylinder–mechanism run of 20 steps: direct = complex step of the whole run (rtol 1e-7)
    = adjoint (rtol 1e-8). The window covers the start transient, in which every bar is loaded."""
    case = _weir(0.02)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-7, rtol_adjoint=1e-8)
