"""An independent reference for Bricard's mechanism (IFToMM benchmark A04): joint coordinates.

The open chain ground → rod1 → … → rod5 is described by the five angles θ of joints J1…J5
(product of exponentials about the published axes through the published corners); joint J6
closes the loop with five equations (3 coincidence, 2 axis alignment), one of them redundant.
Equations of motion (virtual work): M(θ) θ̈ + h(θ, θ̇) = Q(θ) + Cᵀλ,  C θ̈ = −Ċθ̇, solved by
least squares (θ̈ is unique; the redundant multiplier is not).  Directional derivatives of the
Jacobians along θ̇ are taken by complex step.  Integrated with scipy's DOP853 at tight
tolerances.  Nothing here uses dynsens.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

AXES = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)


def _rot(a, th):
    """Rotation by th about unit axis a (Rodrigues), complex-safe."""
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)


class Bricard:
    def __init__(self, L=1.0, masses=(1.0,) * 5, g=9.81, a=0.1):
        self.L, self.m, self.g = L, np.array(masses, float), g
        corners = L * np.array([[0, 0, 0], [1, 0, 0], [1, -1, 0], [1, -1, 1], [0, -1, 1], [0, 0, 1]], float)
        self.p = corners[:5]                       # joint points J1..J5
        self.p6 = corners[5]
        self.com = 0.5 * (corners[:5] + corners[1:6])
        along = [0, 1, 2, 0, 1]                    # rod k's long axis (global, reference pose)
        self.I0 = []
        for k in range(5):
            big = self.m[k] * (L * L + a * a) / 12
            d = np.full(3, big)
            d[along[k]] = self.m[k] * 2 * a * a / 12
            self.I0.append(np.diag(d))

    def frames(self, th):
        """Per body k: rotation R_k, and the current axes/points of joints 1..k."""
        R = np.eye(3, dtype=np.result_type(th, float))
        t = np.zeros(3, dtype=R.dtype)                 # x -> R x + t
        axes, pts, Rs, ts = [], [], [], []
        for i in range(5):
            axes.append(R @ AXES[i])
            pts.append(R @ self.p[i] + t)
            Ri = _rot(AXES[i], th[i])
            # compose with the rotation about the reference axis through the reference point
            t = t + R @ (self.p[i] - Ri @ self.p[i])
            R = R @ Ri
            Rs.append(R)
            ts.append(t)
        return Rs, ts, axes, pts

    def jacobians(self, th):
        Rs, ts, axes, pts = self.frames(th)
        Jv, Jw, c = [], [], []
        for k in range(5):
            ck = Rs[k] @ self.com[k] + ts[k]
            jv = np.zeros((3, 5), ck.dtype)
            jw = np.zeros((3, 5), ck.dtype)
            for i in range(k + 1):
                jv[:, i] = np.cross(axes[i], ck - pts[i])
                jw[:, i] = axes[i]
            Jv.append(jv)
            Jw.append(jw)
            c.append(ck)
        # closure at J6: the point of rod5 at p6 and rod5's x axis
        x6 = Rs[4] @ self.p6 + ts[4]
        ex = Rs[4] @ np.array([1.0, 0, 0])
        C = np.zeros((5, 5), x6.dtype)
        for i in range(5):
            C[:3, i] = np.cross(axes[i], x6 - pts[i])
            w = np.cross(axes[i], ex)
            C[3, i], C[4, i] = w[1], w[2]
        return Jv, Jw, c, Rs, C, x6, ex

    def rhs(self, t, y):
        th, thd = y[:5], y[5:]
        Jv, Jw, c, Rs, C, _, _ = self.jacobians(th)
        h = 1e-30
        Jv_d, Jw_d, _, _, C_d, _, _ = self.jacobians(th + 1j * h * thd)
        M = np.zeros((5, 5))
        f = np.zeros(5)
        for k in range(5):
            Ik = Rs[k] @ self.I0[k] @ Rs[k].T
            w = Jw[k] @ thd
            M += self.m[k] * Jv[k].T @ Jv[k] + Jw[k].T @ Ik @ Jw[k]
            acc_v = (np.imag(Jv_d[k]) / h) @ thd
            acc_w = (np.imag(Jw_d[k]) / h) @ thd
            f += Jv[k].T @ (self.m[k] * np.array([0, -self.g, 0]) - self.m[k] * acc_v)
            f -= Jw[k].T @ (Ik @ acc_w + np.cross(w, Ik @ w))
        gam = -(np.imag(C_d) / h) @ thd
        K = np.block([[M, C.T], [C, np.zeros((5, 5))]])
        sol = np.linalg.lstsq(K, np.concatenate([f, gam]), rcond=1e-12)[0]
        return np.concatenate([thd, sol[:5]])

    def solve(self, t_eval, rtol=1e-12, atol=1e-12):
        """Body COM positions (len(t_eval), 5, 3) and the closure residual along the way."""
        sol = solve_ivp(self.rhs, (0.0, t_eval[-1]), np.zeros(10), method="DOP853", t_eval=t_eval,
                        rtol=rtol, atol=atol)
        assert sol.success
        out, closure = [], 0.0
        for th in sol.y[:5].T:
            _, _, c, _, _, x6, ex = self.jacobians(th)
            out.append(np.array(c))
            closure = max(closure, np.linalg.norm(x6 - self.p6), abs(ex[1]), abs(ex[2]))
        return np.array(out), closure
