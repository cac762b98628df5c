"""dynsens inside OpenMDAO: the lightweight truss under two load cases plus a cost model.

Two ``CaseComponent``s simulate cases/truss_lightweight.yaml, the second with a 20 % larger impact
(an override, as ``--set``); both share the bar areas.  An ``ExecComp`` prices the sections
(material cost per tonne plus a fabrication cost per mm² of area).  SLSQP minimises the cost
subject to both load cases' stress and buckling limits.

Run: ``python scripts/openmdao_example.py`` (needs ``pip install 'dynsens[openmdao]'``).
"""
from __future__ import annotations

from pathlib import Path

import openmdao.api as om

from dynsens.openmdao import CaseComponent

CASE = Path(__file__).resolve().parents[1] / "cases" / "truss_lightweight.yaml"
AREAS = ("A_chord_bottom", "A_chord_top", "A_web")


def build(maxiter: int = 50) -> om.Problem:
    """The problem: two load cases of the truss, a cost model, SLSQP."""
    prob = om.Problem()
    model = prob.model
    ivc = model.add_subsystem("areas", om.IndepVarComp())
    for a in AREAS:
        ivc.add_output(a, 400.0)      # mm² (the case gives its areas no unit)
    model.add_subsystem("nominal", CaseComponent(case=CASE))
    model.add_subsystem("severe", CaseComponent(case=CASE, overrides={"model.loads[0].value": -72000.0}))
    model.add_subsystem("cost", om.ExecComp("cost = 3000.0*mass + 0.01*(A_chord_bottom + A_chord_top + A_web)",
                                            mass={"units": "t"}))
    for a in AREAS:
        for sub in ("nominal", "severe", "cost"):
            model.connect(f"areas.{a}", f"{sub}.{a}")
    model.connect("nominal.mass", "cost.mass")
    for a in AREAS:     # bounds from the case; the areas live in the IndepVarComp
        model.add_design_var(f"areas.{a}", lower=50.0, upper=2000.0, ref0=50.0, ref=2000.0)
    model.add_objective("cost.cost", ref=200.0)
    for path in ("nominal", "severe"):
        for c in ("stress_ks", "buckling_ks"):
            model.add_constraint(f"{path}.{c}", upper=1.0)
    prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", tol=1e-6, maxiter=maxiter, disp=False)
    prob.setup()
    return prob


def main() -> om.Problem:
    prob = build()
    prob.run_driver()
    print("areas (mm²):", {a: round(float(prob.get_val(f"areas.{a}")[0]), 2) for a in AREAS})
    print("cost:", round(float(prob.get_val("cost.cost")[0]), 4), " mass (t):",
          round(float(prob.get_val("nominal.mass")[0]), 5))
    for path in ("nominal", "severe"):
        print(f"{path}: stress_ks {float(prob.get_val(f'{path}.stress_ks')[0]):.4f}, "
              f"buckling_ks {float(prob.get_val(f'{path}.buckling_ks')[0]):.4f}")
    return prob


if __name__ == "__main__":
    main()
