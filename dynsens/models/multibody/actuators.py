r"""The interface of axial force elements with first-order states (actuators).

An axial element acts between two points P_1 (body_1) and P_2 (body_2) along their
separation ``d = P_2 − P_1`` with a push force P (positive pushes P_2 away from P_1) that
depends on the length ``L = ‖d‖``, its rate ``L̇`` and the element's own first-order states
``p`` (``n_pressures`` of them, at ``p_index`` in the model's p), whose rates are
``ṗ = h(L, L̇, p, t, x)`` (issue: generic first-order states ṗ = h(q, q̇, p, t, x)).

The model integrates every element's states with the same γ-rule as q (block row 3 of the
residual, ``ṗ − h``), and the kernel (:mod:`.residual`) differentiates through the
partials the element returns, so a new actuator only implements :class:`AxialElement`:

* ``n_pressures`` (number of first-order states) and ``p_index`` (set by the builder);
* ``constants(prm)``: its design-dependent constants (complex-safe), shape (n_c,);
* ``law(L, L̇, p, t, pv, c)`` returning ``(P, P_L, P_L̇, P_p, h, h_L, h_L̇, h_p)``: the push
  force, its partials by L, L̇ and each state (list of n_pressures), the rates h (list of
  n_pressures) and their partials (lists; ``h_p[i][j] = ∂h_i/∂p_j``), all broadcasting over
  any leading shape and complex-safe.

An element whose law the compiled kernel (:mod:`.compiled`) knows sets ``law_kind`` (0: the
spring-damper's :func:`.forces.spring_law`, 1: the cylinder's
:func:`.hydraulics.cylinder_law`; each law is written once, in plain arithmetic, and serves
both kernels) and gives its time-dependent input through ``external(t, pv)``; a model with
an element of ``law_kind = None`` is evaluated by the numpy kernel.

The forces on the bodies follow from P alone (``Q = J_dᵀ d P/L``, exact Jacobian in
:mod:`.residual`).  :class:`.hydraulics.HydraulicCylinder` is the first actuator with states,
:class:`.forces.SpringDamper` the stateless case.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .bodies import Diff

Array = np.ndarray


class AxialElement:
    """Base class of axial force elements and actuators (see the module docstring).

    Attributes
    ----------
    name : the element's name in the case.
    d : the point separation P_2 − P_1 (length).
    n_pressures : number of first-order states (0 for passive elements).
    p_index : position of the first state in the model's p.
    """

    name: str
    d: Diff
    n_pressures: int = 0
    p_index: int = 0

    law_kind: int | None = None

    def constants(self, prm: Any) -> Array:
        """Design-dependent constants of the law for one parameter set, (n_c,)."""
        raise NotImplementedError

    def external(self, t: float, pv: Array) -> Any:
        """Time-dependent input of the law at t (s) for parameters pv (n,) or (B, n); 0 if none."""
        return 0.0

    def settled_from(self, pv: Array) -> float:
        """A time T (s) after which :meth:`external` no longer changes (−inf: never changes)."""
        return -np.inf

    def law(self, L: Array, Ld: Array, p: Array, t: float, pv: Array, c: Array) -> tuple:
        """(P, P_L, P_L̇, P_p, h, h_L, h_L̇, h_p) at length L (length), rate L̇ (length/s),
        states p (..., n_pressures), time t (s), parameters pv and constants c (..., n_c)."""
        raise NotImplementedError
