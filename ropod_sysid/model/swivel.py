"""The smart-wheel ("swivel") unit: a passive pivot with caster offset s_w and two driven wheels.

Thesis Sec. V-B (kinematics, eqs. 5–12), V-C (wheel and hub dynamics, eqs. 13–21),
V-D (parametrisations, eqs. 22–31) and App. B (matrix parametrisation, eqs. 43–48).
Everything is vectorised over samples N and the k units of the group: arrays are (N, k, …).

Notation: S = [[0, −1], [1, 0]] (a 90° turn); for a vector r fixed in a frame rotating with
angle θ, ω = θ̇, α = θ̈ and v = R(θ) r the world vector,
    Ṙ r = ω S v,   R̈ r = α S v − ω² v,
which is App. B's parametrisation (eqs. 44–48) written with the outer product
    R̈ r = (S v) ⊗ a^α q̈_b + (S v) b^α − ω² v   when α = a^α q̈_b + b^α.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ropod_sysid.params import DynamicParameters
from ropod_sysid.platform import Platform


def _turn(v: np.ndarray) -> np.ndarray:
    """S v for S = [[0, −1], [1, 0]] on the last axis."""
    out = np.empty_like(v)
    np.negative(v[..., 1], out=out[..., 0])
    out[..., 1] = v[..., 0]
    return out


def _rot(c: np.ndarray, s: np.ndarray, r: np.ndarray) -> np.ndarray:
    """R(θ) r for r of shape (…, 2) broadcast against c = cos θ, s = sin θ."""
    shape = np.broadcast_shapes(np.shape(c), r.shape[:-1])
    out = np.empty((*shape, 2))
    out[..., 0] = c * r[..., 0] - s * r[..., 1]
    out[..., 1] = s * r[..., 0] + c * r[..., 1]
    return out


def _b_times_inverse_rows(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """B [I2 0] A⁻¹ for stacks of 3×3 matrices A (…, 3, 3) and B (…, 3, 2).

    A⁻¹ from the adjugate: its columns are a1×a2, a2×a0, a0×a1 over det A = a0·(a1×a2), with
    a0, a1, a2 the rows of A (for A_iwh, det = −s_w: eq. 20 and the test of App. C); much
    faster than a batched LAPACK inverse of many tiny matrices.
    """
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = (
        [a[..., i, j] for j in range(3)] for i in range(3))
    inv01 = np.empty((*a.shape[:-2], 2, 3))  # rows 0 and 1 of A⁻¹: x, y of a1×a2, a2×a0, a0×a1
    inv01[..., 0, 0] = a11 * a22 - a12 * a21
    inv01[..., 1, 0] = a12 * a20 - a10 * a22
    inv01[..., 0, 1] = a21 * a02 - a22 * a01
    inv01[..., 1, 1] = a22 * a00 - a20 * a02
    inv01[..., 0, 2] = a01 * a12 - a02 * a11
    inv01[..., 1, 2] = a02 * a10 - a00 * a12
    det = a00 * inv01[..., 0, 0] + a01 * inv01[..., 1, 0] + a02 * (a10 * a21 - a11 * a20)
    inv01 /= det[..., None, None]
    return b[..., :, 0, None] * inv01[..., None, 0, :] + b[..., :, 1, None] * inv01[..., None, 1, :]


@dataclass
class SwivelData:
    """Per-sample parametrisations of k swivel units (shapes (N, k, …)).

    Accelerations are affine in q̈_b: ``X = A_X q̈_b + b_X``.
    """

    c_b: np.ndarray  # (N,) cos θ_b
    s_b: np.ndarray
    c_d: np.ndarray  # (N, k) cos δ_i
    s_d: np.ndarray
    c_i: np.ndarray  # (N, k) cos θ_i, θ_i = θ_b + δ_i
    s_i: np.ndarray
    theta_i_dot: np.ndarray  # (N, k) θ̇_i
    pivot_rate: np.ndarray  # (N, k) δ̇_i
    rd_ib: np.ndarray  # (N, k, 2) pivot point velocity (5b)
    a_theta: np.ndarray  # (N, k, 3) eq. 25
    b_theta: np.ndarray  # (N, k) eq. 26
    a_qcm: np.ndarray  # (N, k, 3, 3) eq. 23: q̈_icm = a_qcm q̈_b + b_qcm
    b_qcm: np.ndarray  # (N, k, 3)
    rd_cm: np.ndarray  # (N, k, 2) hub centre-of-mass velocity (9b)
    rd_w: np.ndarray  # (N, k, 2, 2) wheel centre velocities (10b), wheel axis L, R
    wheel_rate: np.ndarray  # (N, k, 2) φ̇_iw (11)
    a_phi: np.ndarray  # (N, k, 2, 3) eq. 30: φ̈ = a_phi q̈_b + b_phi
    b_phi: np.ndarray  # (N, k, 2)
    a_iwh: np.ndarray  # (N, k, 3, 3) eq. 20
    a_iwh2: np.ndarray  # (N, k, 3, 2) eq. 21
    b_fixy: np.ndarray  # (N, k, 3, 2) eq. 4
    g: np.ndarray  # (N, k, 3, 3) B_Fixy [I 0] A_iwh⁻¹, shared by eqs. 22, 32, 64
    b_tau: np.ndarray  # (N, 3, k, 2) B_τ,i (eq. 32)
    b_tau_fp: np.ndarray  # (N, 3, k) B_τfp,i (eq. 64)


class SwivelUnits:
    """k smart-wheel units of the thesis, attached at ``pivots`` (k, 2) in the base frame."""

    inertial_names = ("m_wh", "Jzz_wh", "Jrot_w")

    def __init__(self, pivots: np.ndarray, wheel_radius: float, wheel_distance: float,
                 caster_offset: float, hub_com_offset: float) -> None:
        self.pivots = np.asarray(pivots, dtype=float).reshape(-1, 2)
        self.n_units = self.pivots.shape[0]
        self.r_w = float(wheel_radius)
        self.d_w = float(wheel_distance)
        self.s_w = float(caster_offset)
        self.dx = float(hub_com_offset)
        self.s_cm = self.s_w - self.dx  # below eq. 9
        # body-fixed vectors in the unit frame: hub CoM (9), wheel centres L, R (10)
        self.r_cm = np.array([-self.s_cm, 0.0])
        self.r_wheels = np.array([[-self.s_w, self.d_w / 2], [-self.s_w, -self.d_w / 2]])

    @classmethod
    def from_platform(cls, platform: Platform, indices: list[int] | None = None) -> SwivelUnits:
        pivots = platform.pivots if indices is None else platform.pivots[indices]
        return cls(pivots, platform.wheel_radius, platform.wheel_distance,
                   platform.caster_offset, platform.hub_com_offset)

    # ---------------------------------------------------------------- kinematics
    def theta_i_dot(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """θ̇_i from the no-side-slip constraint (eq. 8a); shape (N, k)."""
        x, y = self.pivots[:, 0], self.pivots[:, 1]
        th_i = q[:, 2:3] + delta
        c_d, s_d = np.cos(delta), np.sin(delta)
        return (-np.sin(th_i) * qd[:, 0:1] + np.cos(th_i) * qd[:, 1:2]
                + qd[:, 2:3] * (x * c_d + y * s_d)) / self.s_w

    def joint_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """δ̇_i = θ̇_i − θ̇_b implied by the base motion (eq. 8a); shape (N, k)."""
        return self.theta_i_dot(q, qd, delta) - qd[:, 2:3]

    def wheel_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """φ̇_iw (N, k, 2) implied by the base motion: eqs. 8a, 10b and 11 in the unit frame,
        R_w φ̇_iw = c_δ v_x + s_δ v_y + θ̇_b (x s_δ − y c_δ) ∓ (d_w/2) θ̇_i (v in the base frame).
        """
        c_b, s_b = np.cos(q[:, 2:3]), np.sin(q[:, 2:3])
        vx = c_b * qd[:, 0:1] + s_b * qd[:, 1:2]  # base velocity in the base frame
        vy = -s_b * qd[:, 0:1] + c_b * qd[:, 1:2]
        w = qd[:, 2:3]
        x, y = self.pivots[:, 0], self.pivots[:, 1]
        c_d, s_d = np.cos(delta), np.sin(delta)
        th_i_dot = (-s_d * vx + c_d * vy + w * (x * c_d + y * s_d)) / self.s_w  # (8a)
        fwd = c_d * vx + s_d * vy + w * (x * s_d - y * c_d)
        half = 0.5 * self.d_w * th_i_dot
        return np.stack([fwd - half, fwd + half], axis=-1) / self.r_w

    def kinematics(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray,
                   delta_dot: np.ndarray | None = None) -> SwivelData:
        """All parametrisations of eqs. 5–31 for base pose q, rate qd (N, 3), pivots δ (N, k).

        ``delta_dot`` (measured δ̇) is used where the thesis uses δ̇_i (eq. 26) and to form
        θ̇_i = θ̇_b + δ̇_i; when omitted, θ̇_i follows from the constraint (8a).
        """
        q = np.asarray(q, float)
        qd = np.asarray(qd, float)
        delta = np.asarray(delta, float)
        n, k = delta.shape
        px, py = self.pivots[:, 0], self.pivots[:, 1]
        th_b, thd_b = q[:, 2], qd[:, 2]
        c_b, s_b = np.cos(th_b), np.sin(th_b)
        c_d, s_d = np.cos(delta), np.sin(delta)
        th_i = th_b[:, None] + delta
        c_i, s_i = np.cos(th_i), np.sin(th_i)
        if delta_dot is None:
            theta_i_dot = self.theta_i_dot(q, qd, delta)
            delta_dot = theta_i_dot - thd_b[:, None]
        else:
            delta_dot = np.asarray(delta_dot, float)
            theta_i_dot = thd_b[:, None] + delta_dot
        w_b = thd_b[:, None, None]  # (N, 1, 1)
        w_i = theta_i_dot[..., None]  # (N, k, 1)

        # pivot point P_ib (5a–c): r̈_ib = [I | S p] q̈_b − θ̇_b² p, p = R_b r_ib/b
        p = _rot(c_b[:, None], s_b[:, None], self.pivots[None])  # (N, k, 2)
        sp = _turn(p)
        rd_ib = qd[:, None, :2] + w_b * sp
        a_ib = np.zeros((n, k, 2, 3))
        a_ib[..., 0, 0] = 1.0
        a_ib[..., 1, 1] = 1.0
        a_ib[..., :, 2] = sp
        b_ib = -(w_b**2) * p

        # unit rotation θ̈_i (eqs. 24–26)
        a_theta = np.empty((n, k, 3))
        np.divide(-s_i, self.s_w, out=a_theta[..., 0])
        np.divide(c_i, self.s_w, out=a_theta[..., 1])
        a_theta[..., 2] = (px * c_d + py * s_d) / self.s_w
        b_theta = (-c_i * theta_i_dot * qd[:, 0:1] - s_i * theta_i_dot * qd[:, 1:2]
                   + thd_b[:, None] * (-px * s_d + py * c_d) * delta_dot) / self.s_w

        def body_point(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """Velocity and acceleration parametrisation of hub-fixed points r (m, 2) in the
            unit frame (eqs. 9, 10, 27); shapes (N, k, m, 2), (N, k, m, 2, 3), (N, k, m, 2)."""
            v = _rot(c_i[..., None], s_i[..., None], r)  # R_i r
            sv = _turn(v)
            wi = w_i[..., None]
            vel = rd_ib[..., None, :] + wi * sv  # (9b)/(10b)
            a = a_ib[:, :, None] + sv[..., :, None] * a_theta[:, :, None, None, :]  # App. B
            b = b_ib[:, :, None] + sv * b_theta[..., None, None] - wi**2 * v
            return vel, a, b

        vel, acc_a, acc_b = body_point(np.vstack([self.r_cm, self.r_wheels]))
        rd_cm, a_cm, b_cm = vel[:, :, 0], acc_a[:, :, 0], acc_b[:, :, 0]
        a_qcm = np.empty((n, k, 3, 3))  # (23)
        a_qcm[..., :2, :] = a_cm
        a_qcm[..., 2, :] = a_theta
        b_qcm = np.empty((n, k, 3))
        b_qcm[..., :2] = b_cm
        b_qcm[..., 2] = b_theta
        rd_w, a_w, b_w = vel[:, :, 1:], acc_a[:, :, 1:], acc_b[:, :, 1:]  # wheels L, R
        # unit forward direction e_x^i = (c_i, s_i), sideways e_y^i = (−s_i, c_i); dot products
        # written out (a reduction over an axis of length 2 is slow in numpy)
        cw, sw = c_i[..., None], s_i[..., None]  # (N, k, 1): against the two wheels
        # eq. 30: φ̈ = (e_x·r̈_w + θ̇_i e_y·ṙ_w) / R_w
        a_phi = (cw[..., None] * a_w[..., 0, :] + sw[..., None] * a_w[..., 1, :]) / self.r_w
        b_phi = (cw * b_w[..., 0] + sw * b_w[..., 1]
                 + w_i * (cw * rd_w[..., 1] - sw * rd_w[..., 0])) / self.r_w
        wheel_rate = (cw * rd_w[..., 0] + sw * rd_w[..., 1]) / self.r_w  # (11)

        # hub equations of motion (18–21)
        a_iwh = np.empty((n, k, 3, 3))
        a_iwh[..., 0, 0] = -c_b[:, None]
        a_iwh[..., 0, 1] = s_b[:, None]
        a_iwh[..., 0, 2] = -s_i
        a_iwh[..., 1, 0] = -s_b[:, None]
        a_iwh[..., 1, 1] = -c_b[:, None]
        a_iwh[..., 1, 2] = c_i
        a_iwh[..., 2, 0] = self.s_cm * s_d
        a_iwh[..., 2, 1] = -self.s_cm * c_d
        a_iwh[..., 2, 2] = -self.dx
        a_iwh2 = np.empty((n, k, 3, 2))
        a_iwh2[..., 0, :] = c_i[..., None]
        a_iwh2[..., 1, :] = s_i[..., None]
        a_iwh2[..., 2, 0] = -self.d_w / 2
        a_iwh2[..., 2, 1] = self.d_w / 2
        b_fixy = np.zeros((n, k, 3, 2))  # (4)
        b_fixy[..., 0, 0] = c_b[:, None]
        b_fixy[..., 0, 1] = -s_b[:, None]
        b_fixy[..., 1, 0] = s_b[:, None]
        b_fixy[..., 1, 1] = c_b[:, None]
        b_fixy[..., 2, 0] = -py
        b_fixy[..., 2, 1] = px
        # G = B_Fixy [I2 0] A_iwh⁻¹: F_ixy of (22)/(63) enters (32)/(64) through it
        g = _b_times_inverse_rows(b_fixy, a_iwh)
        b_tau = -np.moveaxis(g @ a_iwh2, 2, 1) / self.r_w  # (N, 3, k, 2): eqs. 22, 29, 31, 32
        b_tau_fp = np.moveaxis(g[..., 2], 1, 2).copy()  # (64): (I + G) e3
        b_tau_fp[:, 2, :] += 1.0
        return SwivelData(c_b, s_b, c_d, s_d, c_i, s_i, theta_i_dot, delta_dot, rd_ib, a_theta,
                          b_theta, a_qcm, b_qcm, rd_cm, rd_w, wheel_rate, a_phi, b_phi, a_iwh,
                          a_iwh2, b_fixy, g, b_tau, b_tau_fp)

    # ---------------------------------------------------------------- dynamics
    def _m_wh(self, params: DynamicParameters) -> np.ndarray:
        return np.diag([params.m_wh, params.m_wh, params.Jzz_wh])  # (19)

    def m_add(self, data: SwivelData, params: DynamicParameters) -> np.ndarray:
        """M_i,add = −B_Fixy A^{F_ixy}_{q̈_b} per unit (eqs. 22, 32, 49); shape (N, k, 3, 3).

        With F_iw = (τ_iw − J_rot,w φ̈_iw)/R_w (29) and q̈_icm (23):
        A^{F_ixyS}_{q̈_b} = A_iwh⁻¹ (M_wh A^{q̈_icm} + (J_rot,w/R_w) A_iwh2 A^{φ̈}).
        """
        inner = (self._m_wh(params) @ data.a_qcm
                 + (params.Jrot_w / self.r_w) * data.a_iwh2 @ data.a_phi)
        return -data.g @ inner

    def b_dir_units(self, data: SwivelData, params: DynamicParameters) -> np.ndarray:
        """b_dir,i = B_Fixy b^{F_ixy} per unit (eqs. 22, 32); shape (N, k, 3)."""
        inner = (np.einsum("cd,nkd->nkc", self._m_wh(params), data.b_qcm)
                 + (params.Jrot_w / self.r_w) * np.einsum("nkcw,nkw->nkc", data.a_iwh2,
                                                         data.b_phi))
        return np.einsum("nkcd,nkd->nkc", data.g, inner)

    def mass_terms(self, data: SwivelData,
                   params: DynamicParameters) -> tuple[np.ndarray, np.ndarray]:
        """(Σ_i M_i,add, Σ_i b_dir,i) of the group (eq. 32)."""
        return self.m_add(data, params).sum(axis=1), self.b_dir_units(data, params).sum(axis=1)

    def a_id(self, data: SwivelData, qdd: np.ndarray) -> np.ndarray:
        """Columns of A_ID for [m_wh, J_zz,wh, J_rot,w], summed over units; (N, 3, 3).

        The unit's share of M_dir q̈_b − b_dir is −G (M_wh q̈_icm + (J_rot,w/R_w) A_iwh2 φ̈),
        linear in the three parameters (eq. 35): the same pieces as :meth:`m_add`.
        """
        qdd_cm = np.einsum("nkcq,nq->nkc", data.a_qcm, qdd) + data.b_qcm
        phidd = np.einsum("nkwq,nq->nkw", data.a_phi, qdd) + data.b_phi
        lin = qdd_cm.copy()
        lin[..., 2] = 0.0
        rot = np.zeros_like(qdd_cm)
        rot[..., 2] = qdd_cm[..., 2]
        roll = np.einsum("nkcw,nkw->nkc", data.a_iwh2, phidd) / self.r_w
        cols = np.stack([lin, rot, roll], axis=-1)  # (N, k, 3, 3)
        # (optimize: numpy then contracts by batched matmul, 4× faster here)
        return -np.einsum("nkcd,nkdp->ncp", data.g, cols, optimize=True)

    def hub_accelerations(self, data: SwivelData,
                          qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q̈_icm (N, k, 3), φ̈ (N, k, 2)) for a given base acceleration (eqs. 23, 30)."""
        qdd_cm = np.einsum("nkcq,nq->nkc", data.a_qcm, qdd) + data.b_qcm
        phidd = np.einsum("nkwq,nq->nkw", data.a_phi, qdd) + data.b_phi
        return qdd_cm, phidd

    def kinetic_energy(self, data: SwivelData, params: DynamicParameters) -> np.ndarray:
        """Σ_i ½ m_wh |ṙ_icm|² + ½ J_zz,wh θ̇_i² + ½ J_rot,w Σ_w φ̇_iw² [J]; shape (N,)."""
        t = (0.5 * params.m_wh * (data.rd_cm**2).sum(-1)
             + 0.5 * params.Jzz_wh * data.theta_i_dot**2
             + 0.5 * params.Jrot_w * (data.wheel_rate**2).sum(-1))
        return t.sum(axis=1)
