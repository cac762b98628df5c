r"""Stability of beam members: flexural buckling of a beam-column under axial force and bending,
checked with the interaction equations of AISC 360-16 (*Specification for Structural Steel
Buildings*, ANSI/AISC 360-16), §H1.1, Eq. (H1-1a) and (H1-1b), in a simplified elastic form.

For a member with required axial strength P_r and required flexural strengths M_rx, M_ry:

.. math::

    \frac{P_r}{P_c} ≥ 0.2:\quad
    \frac{P_r}{P_c} + \frac{8}{9}\Big(\frac{M_{rx}}{M_{cx}} + \frac{M_{ry}}{M_{cy}}\Big) ≤ 1 \quad\text{(H1-1a)},

    \frac{P_r}{P_c} < 0.2:\quad
    \frac{P_r}{2P_c} + \frac{M_{rx}}{M_{cx}} + \frac{M_{ry}}{M_{cy}} ≤ 1 \quad\text{(H1-1b)}.

The simplified elastic strengths taken here (nominal, times the resistance factor φ):

* compression: P_c = φ·min(P_e, F_y A), the elastic Euler load P_e = π²EI/(KL)² of the weaker
  axis (L the beam element's length, K the effective-length factor) capped by the squash load
  (an elastic–perfectly-plastic column; AISC's column curve, Eq. E3-2/E3-3, lies below it);
* tension (§H1.2 uses the same equations): P_c = φ·F_y A;
* bending: M_c = φ·F_y W, the first-yield moment (W = I/c, the elastic section modulus; the
  plastic modulus Z of compact sections would be larger, so W errs on the safe side).

So P_r/P_c = max(K²·(−N/P_e|_{K=1}), |N|/(F_y A))/φ and M_r/M_c = |σ_b|/(φF_y) with the bending
part σ_b = (σ⁺ − σ⁻)/2 of the extreme-fibre stresses σ^± = N/A ± M c/I at each end (3D beams:
|M_y|/W_y + |M_z|/W_z, exactly the sum of H1-1; a tube takes the resultant moment).

**One continuous ratio.**  H1-1 selects the equation by P_r/P_c, so its value jumps at 0.2
(at M_r = 0 from 0.1 to 0.2).  Reported here is instead

.. math:: u = \max\big(p + \tfrac{8}{9} m,\; \tfrac{p}{2} + m\big),\qquad p = P_r/P_c,\ m = ΣM_r/M_c,

the load factor at which proportional loading reaches the H1-1 curve.  Both lines meet the
curve at (m, p) = (0.9, 0.2) and the safe region is their intersection, so u ≤ 1 exactly where
H1-1 is satisfied (u = the H1-1 value whenever that is 1), while u stays continuous for
gradient-based sizing.  Since p and m are maxima of linear functions of the member's outputs
(the axial ratios and the two signs of σ_b) and u is increasing in both, u itself is the
maximum of a fixed set of linear forms of those outputs (:func:`interaction_forms`): a sampled
maximum or KS of them needs no new derivative code.

Why AISC rather than Eurocode 3 (EN 1993-1-1 §6.3.3): both check a beam-column by an
interaction of an axial and a bending ratio, but §6.3.3's factors k_yy, k_zy (Annex A or B)
depend on the moment distribution, the slenderness and the section class in ways a simplified
elastic form would have to invent; H1-1 states its interaction with two fixed lines.
"""
from __future__ import annotations

from typing import Any

import numpy as np

#: (coefficient of p = P_r/P_c, of m = M_r/M_c) of AISC 360-16 Eq. H1-1a and Eq. H1-1b
H1_LINES = ((1.0, 8.0 / 9.0), (0.5, 1.0))
#: components per member the forms read: −N/P_e (K = 1) about two axes, then σ⁺, σ⁻ at ends 1 and 2
MEMBER_COMPONENTS = 6


def interaction_forms(K: float, yield_stress: float, resistance_factor: float = 1.0) -> np.ndarray:
    """Linear forms C (F, 6) with u = max_f C_f·v over one member's components
    v = (b_y, b_z, σ₁⁺, σ₁⁻, σ₂⁺, σ₂⁻): b = −N/P_e at K = 1 about each axis (a plane beam gives its
    one b twice), σ the extreme-fibre stresses at both ends (the unit of ``yield_stress``).

    The forms cover every choice of the active axial ratio (K²b_y, K²b_z, ±N/(F_y A)), the sign
    of the bending part and the line of H1-1, at each end; all are divided by φ."""
    rows = []
    for end in (0, 1):
        plus, minus = np.zeros(MEMBER_COMPONENTS), np.zeros(MEMBER_COMPONENTS)
        plus[2 + 2 * end], minus[3 + 2 * end] = 1.0, 1.0
        axial = (plus + minus) / (2 * yield_stress)          # N/(F_y A)
        bending = (plus - minus) / (2 * yield_stress)        # M c/(I F_y), signed
        p_rows = [K * K * np.eye(MEMBER_COMPONENTS)[0], K * K * np.eye(MEMBER_COMPONENTS)[1], axial, -axial]
        for p in p_rows:
            for m in (bending, -bending):
                for a, b in H1_LINES:
                    rows.append((a * p + b * m) / resistance_factor)
    return np.array(rows)


def interaction_ratio(v: Any, forms: np.ndarray) -> Any:
    """u (...,) of member components v (..., 6) (:func:`interaction_forms`): the largest form."""
    return np.max(np.real(np.asarray(v)) @ forms.T, axis=-1)


def buckling_scale(K: float) -> float:
    """−N/P_e at effective-length factor K from its value at K = 1: P_e ∝ 1/K², so times K²."""
    return K * K
