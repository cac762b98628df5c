"""Write the generated structural cases (duffing_chain.yaml, truss_impact.yaml) into cases/.

They are generated because listing 20 masses or 20 bars by hand invites typos; the
output is committed and is the case users read.  Run: python scripts/make_cases.py
"""
from __future__ import annotations

from pathlib import Path

import yaml

CASES = Path(__file__).resolve().parent.parent / "cases"


def duffing_chain(n: int = 20, t_end: float = 2.0) -> dict:
    """A chain of n masses with cubic springs and dampers, force pulse at the free end (m, s, kg, N)."""
    dofs = [f"u{i + 1}" for i in range(n)]
    elements = []
    for i, d in enumerate(dofs):
        left = "ground" if i == 0 else dofs[i - 1]
        elements.append({"type": "mass", "name": f"m{i + 1}", "dof": d, "mass": "m"})
        elements.append({"type": "spring", "name": f"s{i + 1}", "dofs": [d, left], "k": "k", "k3": "k3"})
        elements.append({"type": "damper", "name": f"d{i + 1}", "dofs": [d, left], "c": "c"})
    return {
        "name": "duffing_chain",
        "description": f"Chain of {n} equal masses joined by cubic (hardening) springs and dampers, "
                       "fixed at one end, hit by a smooth force pulse at the other. Units: m, s, kg, N.",
        "design": {"variables": [
            {"name": "m", "value": 1.0, "lower": 0.2, "upper": 5.0},
            {"name": "c", "value": 2.0, "lower": 0.0, "upper": 20.0, "scale": 1.0},
            {"name": "k", "value": 1.0e3, "lower": 1.0e2, "upper": 1.0e4},
            {"name": "k3", "value": 1.0e6, "lower": 0.0, "upper": 1.0e7, "scale": 1.0e6},
        ]},
        "model": {"type": "structural", "dofs": dofs, "elements": elements,
                  "loads": [{"dof": dofs[-1], "value": 100.0,
                             "function": {"type": "pulse", "t0": 0.0, "duration": 0.1}}]},
        "integrator": {"scheme": "newmark", "dt": 1.0e-3, "t_end": t_end},
        "sensitivity": {"enabled": True, "partials": "forward"},
        "output": {"history": ["q"], "quantities": [
            {"name": "tip_displacement", "quantity": {"dof": dofs[-1], "kind": "displacement"}, "unit": "m",
             "label": f"displacement of {dofs[-1]}"},
            {"name": "force_s1", "quantity": {"element": "s1", "kind": "force"}, "unit": "N",
             "label": "force of spring s1 (at the wall)"}]},
        "responses": [
            {"name": "tip_end", "type": "value", "quantity": {"dof": dofs[-1], "kind": "displacement"}},
            {"name": "tip_ks", "type": "ks", "quantity": {"dof": dofs[-1], "kind": "displacement"},
             "rho": 200.0, "unit": "m"},
            {"name": "force_ks", "type": "ks", "quantity": {"element": "s1", "kind": "force"},
             "rho": 0.1, "unit": "N"},
            {"name": "tip_integral", "type": "integral", "quantity": {"dof": dofs[-1], "kind": "displacement"}},
        ],
    }


def truss_impact(panels: int = 4, a: float = 500.0) -> dict:
    """A 2D cantilever truss (geometrically nonlinear bars) hit by a tip impact (mm, s, t, N, MPa)."""
    nodes = {}
    for i in range(panels + 1):
        fixed = ["x", "y"] if i == 0 else []
        nodes[f"b{i}"] = {"coords": [i * a, 0.0], "fixed": fixed}
        nodes[f"t{i}"] = {"coords": [i * a, a], "fixed": fixed}
    elements = []

    def bar(name: str, n1: str, n2: str, area: str) -> None:
        elements.append({"type": "bar", "name": name, "nodes": [n1, n2], "area": area,
                         "E": 210000.0, "density": 7.85e-9})
    for i in range(panels):
        bar(f"bottom{i + 1}", f"b{i}", f"b{i + 1}", "A_chord_bottom")
        bar(f"top{i + 1}", f"t{i}", f"t{i + 1}", "A_chord_top")
        bar(f"diag{i + 1}", f"b{i}", f"t{i + 1}", "A_web")
        bar(f"vert{i + 1}", f"b{i + 1}", f"t{i + 1}", "A_web")
    elements.append({"type": "mass", "name": "tip_mass", "node": f"t{panels}", "mass": 0.05})
    return {
        "name": "truss_impact",
        "description": "Cantilever Warren-type 2D truss, geometrically nonlinear bars, a 50 kg tip mass hit "
                       "by a 5 ms impact pulse; bar areas are the design (lightweight design: minimise "
                       "mass subject to a KS stress bound). Units: mm, s, t, N, MPa.",
        "design": {"variables": [
            {"name": "A_chord_bottom", "value": 400.0, "lower": 50.0, "upper": 2000.0},
            {"name": "A_chord_top", "value": 400.0, "lower": 50.0, "upper": 2000.0},
            {"name": "A_web", "value": 250.0, "lower": 50.0, "upper": 2000.0},
        ]},
        "model": {"type": "structural", "dim": 2, "nodes": nodes, "elements": elements,
                  "damping": {"rayleigh": {"alpha": 5.0, "beta": 1.0e-5}},
                  "loads": [{"node": f"t{panels}", "direction": "y", "value": -6.0e4,
                             "function": {"type": "pulse", "t0": 0.0, "duration": 0.005}}]},
        "integrator": {"scheme": "newmark", "dt": 1.0e-4, "t_end": 0.05},
        "sensitivity": {"enabled": True, "partials": "forward"},
        "output": {"history": ["q"], "quantities": [
            {"name": "tip_displacement", "quantity": {"dof": f"t{panels}.y", "kind": "displacement"},
             "unit": "mm", "label": f"vertical displacement of t{panels}"},
            {"name": "stress", "quantity": {"element": "all", "kind": "stress"}, "unit": "MPa",
             "label": "bar stress"}]},
        "responses": [
            {"name": "mass", "type": "mass", "unit": "t"},
            {"name": "stress_ks", "type": "ks", "quantity": {"element": "all", "kind": "stress"},
             "rho": 0.5, "unit": "MPa"},
            {"name": "tip_ks", "type": "ks", "quantity": {"dof": f"t{panels}.y", "kind": "displacement"},
             "rho": 10.0, "unit": "mm"},
        ],
    }


def main() -> None:
    """Write the generated cases."""
    for name, case in (("duffing_chain", duffing_chain()), ("truss_impact", truss_impact())):
        text = "# generated by scripts/make_cases.py — edit that script, not this file\n" + \
            yaml.safe_dump(case, sort_keys=False, default_flow_style=None, width=110)
        (CASES / f"{name}.yaml").write_text(text, encoding="utf-8")
        print(f"wrote cases/{name}.yaml")


if __name__ == "__main__":
    main()
