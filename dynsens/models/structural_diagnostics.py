"""Mixin of :class:`~dynsens.models.structural.StructuralModel`: what run-time checks ask of it.

* :meth:`describe_equation`: a DOF with the elements and loads acting on it, by YAML path,
  type and name, for the messages of a NaN/Inf or a runaway;
* :meth:`displacement_scale`: the size of q the model's data imply (the runaway monitor,
  :mod:`dynsens.runaway`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .base import Linearization, Model


class StructuralDiagnostics:
    """Mixin: run-time diagnostics of a structural model (placed before :class:`Model`)."""

    n: int
    dof_names: list[str]
    loads: list[Any]
    elements_of: Any
    #: (YAML entry, DOFs it acts on) of every element and load, set by the builder
    equation_sources: list[tuple[str, list[int]]] = []

    def describe_equation(self, k: int) -> str:
        """DOF k and the elements and loads acting on it, by YAML path and name."""
        if not 0 <= k < self.n:
            return Model.describe_equation(self, k)  # type: ignore[arg-type]
        acting = [entry for entry, dofs in self.equation_sources if k in dofs]
        return f"DOF '{self.dof_names[k]}'" + (f" (acted on by {', '.join(acting)})" if acting else "")

    def displacement_scale(self, params: dict[str, Any], lin: Linearization | None) -> float:
        """The larger of the bar nodes' coordinates and the static deflections |f_amp|/K_dd of the
        loads' amplitudes on their DOFs (K: the tangent stiffness at t0)."""
        pv = np.real(params["pv"])
        bar_X = self.elements_of("bar").X           # the bars' coordinate indices
        scale = float(np.max(np.abs(pv[bar_X]))) if np.size(bar_X) else 0.0
        if lin is None or lin.R_q is None or not self.loads:
            return scale
        diag = np.real(lin.R_q.diagonal())
        for dof, amp, _ in self.loads:
            if dof < self.n and diag[dof] > 0:
                scale = max(scale, abs(float(pv[amp])) / float(diag[dof]))
        return scale
