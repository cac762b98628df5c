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
        "stroke", "ks_force", "theta_0", "rack_mass", "sigma_ZL", "sigma_BL",
        "sigma_c_BL", "buckling_BL", "f", "g1", "g2")]
    raw.pop("optimization")
    return load_case_dict(raw)


def test_flexible_weir_gradients_match_complex_step_and_adjoint():
    """Geometry (θ_AZ, l_AZ, l_BZ), pump flow V_S and the two bar sections through the coupled
    rack–cylinder–mechanism run of 20 steps: direct = complex step of the whole run (rtol 1e-7)
    = adjoint (rtol 1e-8). The window covers the start transient, in which every bar is loaded."""
    case = _weir(0.02)
    res = dynsens.run_case(case)
    assert res.status == "completed"
    assert_gradients_match_complex_step_and_adjoint(case, res, rtol_cs=1e-7, rtol_adjoint=1e-8)


def _rigid_equivalent(t_end):
    """cases/tyrolean_weir.yaml with its rack replaced by the rigid body of the flexible rack's
    node masses (hub at Z, point masses at B and L; bars massless), started from the same explicit
    pressures as the flexible case."""
    import numpy as np
    flex = yaml.safe_load((CASES / "tyrolean_weir_flexible.yaml").read_text(encoding="utf-8"))
    raw = yaml.safe_load((CASES / "tyrolean_weir.yaml").read_text(encoding="utf-8"))
    fb = flex["model"]["bodies"]
    x = {v["name"]: v["value"] for v in raw["design"]["variables"]}
    gam = np.arccos((x["l_AZ"] ** 2 + x["l_BZ"] ** 2 - 810000.0) / (2 * x["l_AZ"] * x["l_BZ"]))
    phi = x["theta_AZ"] + gam + 0.18151424220741028
    # node points in the rack frame (x along Z -> L), origin at Z
    pts = {"Z": np.array([0.0, 0.0]), "L": np.array([1500.0, 0.0]),
           "B": x["l_BZ"] * np.array([np.cos(-0.18151424220741028), np.sin(-0.18151424220741028)])}
    m = {"Z": 0.02, "B": 0.005, "L": fb["rack_L"]["mass"]}     # the lever's hub and pin (its 0.025 t), the grate
    M = sum(m.values())
    c = sum(m[k] * pts[k] for k in m) / M
    r = {k: pts[k] - c for k in m}
    ixx = sum(m[k] * r[k][1] ** 2 for k in m) + 50.0
    iyy = sum(m[k] * r[k][0] ** 2 for k in m) + 50.0
    izz = sum(m[k] * (r[k] @ r[k]) for k in m) + 50.0
    ixy = -sum(m[k] * r[k][0] * r[k][1] for k in m)
    # principal axes in the plane: the rigid body takes principal moments and a rotated frame
    w, v = np.linalg.eigh(np.array([[ixx, ixy], [ixy, iyy]]))
    alpha = float(np.arctan2(v[1, 0], v[0, 0]))
    rot = np.array([[np.cos(alpha), np.sin(alpha)], [-np.sin(alpha), np.cos(alpha)]])   # rack -> principal
    cg = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]]) @ c
    raw["model"]["bodies"]["rack"] = {
        "mass": M, "inertia": [float(w[0]), float(w[1]), float(izz)],
        "position": [float(cg[0]), float(cg[1]), 0.0],
        "orientation": {"axis": [0, 0, 1], "angle": float(phi + alpha)},
        "markers": {k: [float((rot @ r[k])[0]), float((rot @ r[k])[1]), 0.0] for k in ("Z", "B")}
        | {"load": [float((rot @ r["L"])[0]), float((rot @ r["L"])[1]), 0.0]}}
    for f in raw["model"]["forces"]:
        if f["type"] == "hydraulic_cylinder":
            f["initial_pressures"] = [2.8, 0.0]
    raw["integrator"]["t_end"] = t_end
    raw["sensitivity"]["enabled"] = False
    raw.pop("optimization")
    return raw, alpha




def _stiff_and_rigid(t_end, scheme):
    """Responses (p1, stroke, the joints' reactions x, y) of the flexible weir with massless bars
    of E = 2.1e10 MPa (1e5 x steel) and of its rigid equivalent, over [0, t_end]."""
    rigid_raw, _ = _rigid_equivalent(t_end)
    flex = yaml.safe_load((CASES / "tyrolean_weir_flexible.yaml").read_text(encoding="utf-8"))
    for mem in flex["model"]["members"]:
        mem["E"], mem["density"] = 2.1e10, 0.0
    flex["integrator"]["t_end"] = t_end
    flex["sensitivity"]["enabled"] = False
    flex.pop("optimization")
    out = [{"name": "p1", "type": "value", "quantity": {"element": "cylinder", "kind": "pressure_1"}},
           {"name": "stroke", "type": "value", "quantity": {"element": "cylinder", "kind": "stroke"}}]
    out += [{"name": f"F{j}{c}", "type": "value", "quantity": {"joint": j, "kind": "reaction_force"},
             "component": f"{j}.F{c}"} for j in "ZABP" for c in "xy"]
    for raw in (flex, rigid_raw):
        raw["integrator"].update(scheme)
        raw["responses"] = out
    return (dynsens.run_case(load_case_dict(flex)).responses,
            dynsens.run_case(load_case_dict(rigid_raw)).responses)


def test_very_stiff_rack_reproduces_the_rigid_rack():
    """Rigid limit: massless bars of E = 2.1e10 MPa against the rigid weir whose rack is the rigid
    body of the same masses (the lever's hub and pin, the grate at L).  The bars' axial modes
    (~1e6 rad/s, unresolved at dt = 1 ms and undamped by Newmark) ring in the undamped run: with the
    case's Newmark scheme, piston pressure and stroke at 0.1 s agree within 1e-3 relative (measured
    6e-4 and 5e-5) and the joint reactions not at all.  With generalized-alpha (rho_inf = 0) damping
    those modes, the pressure (measured 2e-5) and every joint reaction (at most 1.2e-4) at 0.3 s,
    when the explicit start pressures' transient has decayed, agree within 1e-4 and 5e-4."""
    rf, rr = _stiff_and_rigid(0.1, {})
    for name in ("p1", "stroke"):
        assert abs(rf[name].value / rr[name].value - 1) < 1e-3, name
    rf, rr = _stiff_and_rigid(0.3, {"scheme": "generalized_alpha", "rho_inf": 0.0})
    assert abs(rf["p1"].value / rr["p1"].value - 1) < 1e-4
    for name in ("FZx", "FZy", "FAx", "FAy", "FBx", "FBy"):
        assert abs(rf[name].value / rr[name].value - 1) < 5e-4, name
    # the prismatic joint's transverse reaction is small (~20 N): absolute, against the pin's force
    for name in ("FPx", "FPy"):
        assert abs(rf[name].value - rr[name].value) < 5e-4 * abs(rr["FBx"].value), name
