"""Kinematics of k smart-wheel (swivel) units: the parametrisations of thesis eqs. 5–31.

Sec. V-B (kinematics, eqs. 5–12) and V-D (parametrisations, eqs. 22–31) with App. B (the matrix
parametrisation, eqs. 43–48), for :class:`ropod_sysid.model.units.swivel.SwivelUnits`, whose
dynamics are built from them; kept out of the type's module for its size. Everything is
vectorised over samples N and the k units of the group: arrays are (N, k, …).

Notation: S = [[0, −1], [1, 0]] (a 90° turn); for a vector r fixed in a frame rotating with
angle θ, ω = θ̇, α = θ̈ and v = R(θ) r the world vector,
    Ṙ r = ω S v,   R̈ r = α S v − ω² v,
which is App. B's parametrisation (eqs. 44–48) written with the outer product
    R̈ r = (S v) ⊗ a^α q̈_b + (S v) b^α − ω² v   when α = a^α q̈_b + b^α.

Products over the short trailing axes (2 × 3 blocks) are written one (N, k) plane at a time:
numpy's broadcasting over axes of length 2 or 3 runs that many tiny inner loops and cost about
three times as much.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.model.units import turn

if TYPE_CHECKING:
    from ropod_sysid.model.units.swivel import SwivelUnits


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
    out = np.empty((*a.shape[:-2], b.shape[-2], 3))
    for i in range(b.shape[-2]):  # written out: broadcasting over the 2 × 3 axes is slow
        for j in range(3):
            out[..., i, j] = b[..., i, 0] * inv01[..., 0, j] + b[..., i, 1] * inv01[..., 1, j]
    return out


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
    b_tau_w: np.ndarray  # (N, 3, k, 2) B_τ,i (eq. 32)
    b_tau_fp: np.ndarray  # (N, 3, k) B_τfp,i (eq. 64)

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ over the group's 2k wheels (L, R per unit); (N, 3, 2k)."""
        return self.b_tau_w.reshape(self.b_tau_w.shape[0], 3, -1)

    @property
    def angle_rate(self) -> np.ndarray:
        """(δ̇, φ̇_L, φ̇_R) per unit; (N, 3k)."""
        n, k = self.pivot_rate.shape
        out = np.empty((n, k, 3))
        out[..., 0] = self.pivot_rate
        out[..., 1:] = self.wheel_rate
        return out.reshape(n, 3 * k)

    @property
    def actuator_rate(self) -> np.ndarray:
        """Wheel rates φ̇ (N, 2k)."""
        return self.wheel_rate.reshape(self.wheel_rate.shape[0], -1)


def pivot_kinematics(units: SwivelUnits, q: np.ndarray, qd: np.ndarray, delta: np.ndarray,
                     delta_dot: np.ndarray | None = None) -> SwivelData:
    """All parametrisations of eqs. 5–31 for base pose q, rate qd (N, 3), pivots δ (N, k).

    ``delta_dot`` (measured δ̇) is used where the thesis uses δ̇_i (eq. 26) and to form
    θ̇_i = θ̇_b + δ̇_i; when omitted, θ̇_i follows from the constraint (8a).
    """
    q = np.asarray(q, float)
    qd = np.asarray(qd, float)
    delta = np.asarray(delta, float)
    n, k = delta.shape
    px, py = units.pivots[:, 0], units.pivots[:, 1]
    th_b, thd_b = q[:, 2], qd[:, 2]
    c_b, s_b = np.cos(th_b), np.sin(th_b)
    c_d, s_d = np.cos(delta), np.sin(delta)
    th_i = th_b[:, None] + delta
    c_i, s_i = np.cos(th_i), np.sin(th_i)
    if delta_dot is None:
        theta_i_dot = units.theta_i_dot(q, qd, delta)
        delta_dot = theta_i_dot - thd_b[:, None]
    else:
        delta_dot = np.asarray(delta_dot, float)
        theta_i_dot = thd_b[:, None] + delta_dot
    w_b = thd_b[:, None, None]  # (N, 1, 1)
    w_i = theta_i_dot[..., None]  # (N, k, 1)

    # pivot point P_ib (5a–c): r̈_ib = [I | S p] q̈_b − θ̇_b² p, p = R_b r_ib/b
    p = _rot(c_b[:, None], s_b[:, None], units.pivots[None])  # (N, k, 2)
    sp = turn(p)
    rd_ib = qd[:, None, :2] + w_b * sp
    b_ib = -(w_b**2) * p  # (a_ib = [I | S p], written out in body_point)

    # unit rotation θ̈_i (eqs. 24–26)
    a_theta = np.empty((n, k, 3))
    np.divide(-s_i, units.s_w, out=a_theta[..., 0])
    np.divide(c_i, units.s_w, out=a_theta[..., 1])
    a_theta[..., 2] = (px * c_d + py * s_d) / units.s_w
    b_theta = (-c_i * theta_i_dot * qd[:, 0:1] - s_i * theta_i_dot * qd[:, 1:2]
               + thd_b[:, None] * (-px * s_d + py * c_d) * delta_dot) / units.s_w

    def body_point(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Velocity and acceleration parametrisation of hub-fixed points r (m, 2) in the
        unit frame (eqs. 9, 10, 27); shapes (N, k, m, 2), (N, k, m, 2, 3), (N, k, m, 2).
        One point and one component at a time, on (N, k) planes (numpy's broadcasting
        over the short trailing axes cost three times as much)."""
        m = r.shape[0]
        vel, a, b = np.empty((n, k, m, 2)), np.empty((n, k, m, 2, 3)), np.empty((n, k, m, 2))
        at0, at1, at2 = a_theta[..., 0], a_theta[..., 1], a_theta[..., 2]
        w2 = theta_i_dot**2
        for j, (r0, r1) in enumerate(r):
            v0, v1 = c_i * r0 - s_i * r1, s_i * r0 + c_i * r1  # v = R_i r
            sv0, sv1 = -v1, v0  # S v
            vel[:, :, j, 0] = rd_ib[..., 0] + theta_i_dot * sv0  # (9b)/(10b)
            vel[:, :, j, 1] = rd_ib[..., 1] + theta_i_dot * sv1
            # App. B: a = [I | S p] + (S v) ⊗ a^θ,  b = b_ib + (S v) b^θ − θ̇_i² v
            a[:, :, j, 0, 0] = 1.0 + sv0 * at0
            a[:, :, j, 0, 1] = sv0 * at1
            a[:, :, j, 0, 2] = sp[..., 0] + sv0 * at2
            a[:, :, j, 1, 0] = sv1 * at0
            a[:, :, j, 1, 1] = 1.0 + sv1 * at1
            a[:, :, j, 1, 2] = sp[..., 1] + sv1 * at2
            b[:, :, j, 0] = b_ib[..., 0] + sv0 * b_theta - w2 * v0
            b[:, :, j, 1] = b_ib[..., 1] + sv1 * b_theta - w2 * v1
        return vel, a, b

    vel, acc_a, acc_b = body_point(np.vstack([units.r_cm, units.r_wheels]))
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
    a_phi = np.empty((n, k, 2, 3))
    for w in range(2):  # (N, k) planes: see body_point
        for j in range(3):
            a_phi[:, :, w, j] = (c_i * a_w[:, :, w, 0, j] + s_i * a_w[:, :, w, 1, j]) / units.r_w
    b_phi = (cw * b_w[..., 0] + sw * b_w[..., 1]
             + w_i * (cw * rd_w[..., 1] - sw * rd_w[..., 0])) / units.r_w
    wheel_rate = (cw * rd_w[..., 0] + sw * rd_w[..., 1]) / units.r_w  # (11)

    # hub equations of motion (18–21)
    a_iwh = np.empty((n, k, 3, 3))
    a_iwh[..., 0, 0] = -c_b[:, None]
    a_iwh[..., 0, 1] = s_b[:, None]
    a_iwh[..., 0, 2] = -s_i
    a_iwh[..., 1, 0] = -s_b[:, None]
    a_iwh[..., 1, 1] = -c_b[:, None]
    a_iwh[..., 1, 2] = c_i
    a_iwh[..., 2, 0] = units.s_cm * s_d
    a_iwh[..., 2, 1] = -units.s_cm * c_d
    a_iwh[..., 2, 2] = -units.dx
    a_iwh2 = np.empty((n, k, 3, 2))
    a_iwh2[..., 0, :] = c_i[..., None]
    a_iwh2[..., 1, :] = s_i[..., None]
    a_iwh2[..., 2, 0] = -units.d_w / 2
    a_iwh2[..., 2, 1] = units.d_w / 2
    b_fixy = np.zeros((n, k, 3, 2))  # (4)
    b_fixy[..., 0, 0] = c_b[:, None]
    b_fixy[..., 0, 1] = -s_b[:, None]
    b_fixy[..., 1, 0] = s_b[:, None]
    b_fixy[..., 1, 1] = c_b[:, None]
    b_fixy[..., 2, 0] = -py
    b_fixy[..., 2, 1] = px
    # G = B_Fixy [I2 0] A_iwh⁻¹: F_ixy of (22)/(63) enters (32)/(64) through it
    g = _b_times_inverse_rows(b_fixy, a_iwh)
    b_tau = -np.moveaxis(g @ a_iwh2, 2, 1) / units.r_w  # (N, 3, k, 2): eqs. 22, 29, 31, 32
    b_tau_fp = np.moveaxis(g[..., 2], 1, 2).copy()  # (64): (I + G) e3
    b_tau_fp[:, 2, :] += 1.0
    return SwivelData(c_b, s_b, c_d, s_d, c_i, s_i, theta_i_dot, delta_dot, rd_ib, a_theta,
                      b_theta, a_qcm, b_qcm, rd_cm, rd_w, wheel_rate, a_phi, b_phi, a_iwh,
                      a_iwh2, b_fixy, g, b_tau, b_tau_fp)
