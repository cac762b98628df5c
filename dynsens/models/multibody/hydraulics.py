r"""Double-acting hydraulic cylinder between two markers, with two pressure states.

(weir_model.md §3.5.)  Stroke and rate from the pin points A (body_1) and B (body_2):

    s = ‖r_B − r_A‖ − L0,   ṡ = ê·(ṙ_B − ṙ_A),   ê = (r_B − r_A)/‖r_B − r_A‖

Chamber volumes and pressure build-up (first-order states p1 piston side, p2 rod side;
pressure unit = force/length², e.g. MPa with N and mm):

    V1 = V_h1 + A1 s                 V2 = V_h2 + A2 (s_max − s)
    ṗ1 = K/V1 (Q_P(t) − A1 ṡ)         ṗ2 = K/V2 (A2 ṡ − G_T (p2 − p_T))
    Q_P(t) = V̇_S φ(t)  (pump flow, φ a time function, e.g. smoothstep over the valve time)

Actuator force (positive pushes B away from A), applied as an internal pair along ê:

    F_h = p1 A1 − p2 A2 − d_HA ṡ

The residual rows of the cylinder are ``ṗ − h`` (method.md §1, block row 3).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ModelError
from ..timefunctions import TimeFunction
from .actuators import AxialElement
from .bodies import Ctx, Diff
from .rotations import dot

Array = np.ndarray

# parameter names of a cylinder (keys of ``idx``)
CYLINDER_PARAMS = ("area_1", "area_2", "length_0", "stroke_max", "bulk_modulus", "dead_volume_1",
                   "dead_volume_2", "tank_conductance", "tank_pressure", "damping", "pump_flow")


def cylinder_law(L: Any, Ld: Any, p1: Any, p2: Any, QP: Any, A1: Any, A2: Any, L0: Any, s_max: Any,
                 K: Any, Vh1: Any, Vh2: Any, G: Any, pT: Any, dmp: Any) -> tuple:
    """The cylinder's law in plain arithmetic (numpy arrays of any shape, real or complex, and
    the compiled kernel's scalars alike): push force P = F_h, pressure rates h1, h2 and their
    nonzero partials, from |AB| = L, its rate L̇, pressures p1, p2, pump flow QP (volume/s) and
    the constants of :meth:`HydraulicCylinder.constants`.

    Returns (P, ∂P/∂L̇, ∂P/∂p1, ∂P/∂p2, h1, h2, ∂h1/∂L, ∂h2/∂L, ∂h1/∂L̇, ∂h2/∂L̇, ∂h2/∂p2);
    ∂P/∂L = ∂h1/∂p = ∂h2/∂p1 = 0.
    """
    s = L - L0
    V1 = Vh1 + A1 * s
    V2 = Vh2 + A2 * (s_max - s)
    KV1 = K / V1
    KV2 = K / V2
    h1 = KV1 * (QP - A1 * Ld)
    h2 = KV2 * (A2 * Ld - G * (p2 - pT))
    return (p1 * A1 - p2 * A2 - dmp * Ld, -dmp, A1, -A2, h1, h2, -A1 * h1 / V1, A2 * h2 / V2,
            -A1 * KV1, A2 * KV2, -G * KV2)


@dataclass(eq=False)
class HydraulicCylinder(AxialElement):
    """One cylinder, an :class:`.actuators.AxialElement` with two states; ``p_index`` is the position
    of p1 in the first-order state (p2 follows).

    ``idx`` maps the names of :data:`CYLINDER_PARAMS` to parameter-vector indices
    (areas are stored derived in params.scal under ``name + '.A1'`` / ``'.A2'``).
    """

    name: str
    d: Diff
    idx: dict[str, int]
    pump: TimeFunction
    p_index: int
    initial: Any = "static"     # "static" or (i_p1, i_p2) parameter indices
    initial_p2: int = -1

    n_pressures = 2

    def areas(self, prm: Any) -> tuple[Any, Any]:
        return prm.scal[self.name + ".A1"], prm.scal[self.name + ".A2"]

    def constants(self, prm: Any) -> Array:
        """[A1, A2, L0, s_max, K, V_h1, V_h2, G_T, p_T, d_HA] for one parameter set."""
        pv, ix = prm.pv, self.idx
        return np.array([*self.areas(prm)] + [pv[ix[k]] for k in (
            "length_0", "stroke_max", "bulk_modulus", "dead_volume_1", "dead_volume_2",
            "tank_conductance", "tank_pressure", "damping")])

    @staticmethod
    def _volumes(s: Array, c: Array) -> tuple[Array, Array]:
        return c[..., 5] + c[..., 0] * s, c[..., 6] + c[..., 1] * (c[..., 3] - s)

    def law(self, L: Array, Ld: Array, p: Array, t: float, pv: Array, c: Array) -> tuple:
        """Actuator force F_h, pressure rates h1, h2 and their exact partials.

        Parameters
        ----------
        L, Ld : distance |AB| (length) and its rate (length/s), any shape.
        p : pressures [p1, p2] (pressure), shape (..., 2).
        t : time (s); pv : parameter vector(s); c : :meth:`constants`, shape (..., 10).

        Returns
        -------
        (P, P_L, P_L̇, P_p, h, h_L, h_L̇, h_p): the push force P = F_h (force), its partials
        by L, L̇ and [p1, p2] (a list), the rates h = [h1, h2] (pressure/s) and their partials
        (lists; h_p[i][j] = ∂h_i/∂p_j).
        """
        P, P_Ld, P_p1, P_p2, h1, h2, h1_L, h2_L, h1_Ld, h2_Ld, h2_p2 = cylinder_law(
            L, Ld, p[..., 0], p[..., 1], self.external(t, pv), *np.moveaxis(c, -1, 0))
        zero = np.zeros_like(h1)
        return (P, zero, P_Ld + zero, [P_p1 + zero, P_p2 + zero], [h1, h2], [h1_L, h2_L],
                [h1_Ld, h2_Ld], [[zero, zero], [zero, h2_p2]])

    law_kind = 1

    def external(self, t: float, pv: Array) -> Any:
        """Pump flow Q_P(t) = V̇_S φ(t) (volume/s); pv (n,) or (B, n)."""
        return pv[..., self.idx["pump_flow"]] * self.pump.value(t, pv)

    def settled_from(self, pv: Array) -> float:
        """A time T (s) after which the pump flow no longer changes (that of its time function)."""
        return self.pump.settled_from(pv)

    def kinematics(self, ctx: Ctx) -> tuple[Array, Array, Array]:
        """(s, ṡ, ê): stroke (1, k), stroke rate (1, k), unit axis A→B (3, k)."""
        dv, dd, _ = self.d.kin(ctx)
        L = np.sqrt(dot(dv, dv))
        e = dv / L
        return L - ctx.params.pv[self.idx["length_0"]], dot(e, dd), e

    def volumes(self, s: Array, prm: Any) -> tuple[Array, Array]:
        """Chamber volumes V1, V2 (length³) for stroke s."""
        return self._volumes(s, self.constants(prm))

    def _law_at(self, ctx: Ctx, p: Array) -> tuple:
        s, sd, _ = self.kinematics(ctx)
        j = self.p_index
        L = s + ctx.params.pv[self.idx["length_0"]]
        return self.law(L, sd, p[j:j + 2].T, ctx.t, ctx.params.pv, self.constants(ctx.params))

    def force(self, ctx: Ctx, p: Array) -> Array:
        """F_h (1, k), force unit, for pressures p (n_p, k)."""
        return self._law_at(ctx, p)[0]

    def add(self, ctx: Ctx, p: Array, out: Array) -> None:
        """Generalized force of the actuator pair into out (n_q, k)."""
        _, _, e = self.kinematics(ctx)
        self.d.apply(ctx, self.force(ctx, p) * e, out)

    def rates(self, ctx: Ctx, p: Array) -> tuple[Array, Array]:
        """h1, h2 (1, k): pressure rates (pressure/s)."""
        h = self._law_at(ctx, p)[4]
        return h[0], h[1]

    def check(self, s: Any, prm: Any, t: float, constants: Array | None = None) -> None:
        """Raise ModelError when a chamber volume is not positive at stroke s (length);
        ``constants`` = :meth:`constants` (prm) when already at hand."""
        c = self.constants(prm) if constants is None else constants
        V1, V2 = self._volumes(s, c)
        if np.real(V1) > 0.0 and np.real(V2) > 0.0:
            return
        A1, A2 = self.areas(prm)
        sr = float(np.real(s))
        if np.real(V1) <= 0.0:
            lim = -np.real(prm.pv[self.idx["dead_volume_1"]] / A1)
            raise ModelError(
                f"hydraulic cylinder '{self.name}': piston-side volume V1 <= 0 at t = {t:.6g} s "
                f"(stroke s = {sr:.6g}, limit s > {lim:.6g}: the cylinder is pushed beyond its "
                "retracted end)")
        if np.real(V2) <= 0.0:
            lim = np.real(prm.pv[self.idx["stroke_max"]] + prm.pv[self.idx["dead_volume_2"]] / A2)
            raise ModelError(
                f"hydraulic cylinder '{self.name}': rod-side volume V2 <= 0 at t = {t:.6g} s "
                f"(stroke s = {sr:.6g}, limit s < {lim:.6g} = s_max + V_h2/A2): stop the run "
                "earlier with an event on the stroke")
