"""The compiled (numba) kernel of k swivel units at one sample: the simulator's fast path.

The same pieces as :meth:`SwivelUnits.pivot_kinematics`, :meth:`SwivelUnits.m_add`,
:meth:`SwivelUnits.b_dir_units`, the friction of App. D and :meth:`SwivelUnits.kinetic_energy`,
written out per unit with scalars (thesis Sec. V-B–D, App. B): numpy's per-call overhead on
arrays of four units is what keeps the vectorised simulator near real time. The numpy methods stay
the reference (``tests/test_simulate_jit.py`` compares the two). The functions are compiled into
the simulator's loop (:func:`ropod_sysid.simulate_jit.run`, cached with it) and have no Python
wrapper of their own (``no_cpython_wrapper=True``): they are not called from Python.

Arrays (:func:`arrays`):

- ``geo`` = [R_w, d_w, s_w, Δx, α, x_1, y_1, …, x_k, y_k] (α: the friction tanh gain);
- ``par`` = [m_wh, J_zz,wh, J_rot,w, f_wv (2k), f_wc (2k), f_pv (k), f_pc (k)] (wheels L, R per
  unit; zero friction with body-axis friction);
- ``ia`` (3k,) the platform's angle channels of δ, φ_L, φ_R per unit, ``ic`` (2k,) its actuator
  channels of the wheels L, R.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from ropod_sysid.model.units import FrictionVariant
    from ropod_sysid.model.units.swivel import SwivelUnits

N_GEO = 5  # geometry entries before the pivots


def arrays(units: SwivelUnits, params: Mapping[str, float], variant: FrictionVariant
           ) -> tuple[np.ndarray, np.ndarray]:
    """(``geo``, ``par``) of the group for the parameters and the friction variant."""
    geo = np.concatenate([[units.r_w, units.d_w, units.s_w, units.dx, units.alpha],
                          units.pivots.reshape(-1)])
    inertial = [float(params[n]) for n in units.inertial_names]
    if variant == "body":
        friction = np.zeros(6 * units.n_units)
    else:
        fwv, fwc, fpv, fpc = units._coefficients(params, variant)
        friction = np.concatenate([fwv.reshape(-1), fwc.reshape(-1), fpv, fpc])
    return geo, np.concatenate([inertial, friction])


@njit(no_cpython_wrapper=True, error_model="numpy")
def _point(r0: float, r1: float, c_i: float, s_i: float, w_i: float, rd_ib0: float,
           rd_ib1: float, sp0: float, sp1: float, b_ib0: float, b_ib1: float, at0: float,
           at1: float, at2: float, bt: float) -> tuple:
    """Velocity and acceleration parametrisation of a hub-fixed point r in the unit frame (eqs.
    9, 10, 27; App. B: R̈ r = (S v) ⊗ a^α q̈_b + (S v) b^α − ω² v): (ṙ (2), A (2 × 3), b (2))."""
    v0 = c_i * r0 - s_i * r1  # v = R_i r
    v1 = s_i * r0 + c_i * r1
    sv0, sv1 = -v1, v0
    vel0 = rd_ib0 + w_i * sv0  # (9b)/(10b)
    vel1 = rd_ib1 + w_i * sv1
    a00, a01, a02 = 1.0 + sv0 * at0, sv0 * at1, sp0 + sv0 * at2
    a10, a11, a12 = sv1 * at0, 1.0 + sv1 * at1, sp1 + sv1 * at2
    b0 = b_ib0 + sv0 * bt - w_i * w_i * v0
    b1 = b_ib1 + sv1 * bt - w_i * w_i * v1
    return vel0, vel1, a00, a01, a02, a10, a11, a12, b0, b1


@njit(no_cpython_wrapper=True, error_model="numpy")
def _wheel(pt: tuple, c_i: float, s_i: float, w_i: float, r_w: float) -> tuple:
    """A wheel's φ̈ = a_φ q̈_b + b_φ (eq. 30: φ̈ = (e_x·r̈_w + θ̇_i e_y·ṙ_w) / R_w) and its rate
    φ̇ (11) from its centre's parametrisation ``pt`` (:func:`_point`): (a_φ (3), b_φ, φ̇)."""
    return ((c_i * pt[2] + s_i * pt[5]) / r_w, (c_i * pt[3] + s_i * pt[6]) / r_w,
            (c_i * pt[4] + s_i * pt[7]) / r_w,
            (c_i * pt[8] + s_i * pt[9] + w_i * (c_i * pt[1] - s_i * pt[0])) / r_w,
            (c_i * pt[0] + s_i * pt[1]) / r_w)


@njit(no_cpython_wrapper=True, error_model="numpy")
def dynamics(geo: np.ndarray, par: np.ndarray, ia: np.ndarray, ic: np.ndarray, q: np.ndarray,
             qd: np.ndarray, ang: np.ndarray, m: np.ndarray, b: np.ndarray, btau: np.ndarray,
             tauf: np.ndarray, ff: np.ndarray, arate: np.ndarray, crate: np.ndarray) -> None:
    """Add the group's M_add to ``m`` (3, 3) and b_dir to ``b`` (eqs. 22, 32, 49), pivot friction
    B_τfp τ_fp to ``ff`` (eq. 64); write its columns of B_τ into ``btau`` (3, A), roll friction
    τ_fw into ``tauf`` (A,) (eqs. 53, 56–57), the rates δ̇, φ̇ into ``arate`` (J,) and φ̇ into
    ``crate`` (A,). θ̇_i follows from the no-side-slip constraint (8a). Scalars only (no
    allocation per call)."""
    r_w, d_w, s_w, dx, alpha = geo[0], geo[1], geo[2], geo[3], geo[4]
    s_cm = s_w - dx  # below eq. 9
    h = d_w / 2
    k = ia.shape[0] // 3
    m_wh, jzz, jr = par[0], par[1], par[2] / r_w
    th_b, thd = q[2], qd[2]
    c_b, s_b = math.cos(th_b), math.sin(th_b)
    for i in range(k):
        px, py = geo[N_GEO + 2 * i], geo[N_GEO + 2 * i + 1]
        delta = ang[ia[3 * i]]
        c_d, s_d = math.cos(delta), math.sin(delta)
        c_i, s_i = c_b * c_d - s_b * s_d, s_b * c_d + c_b * s_d  # θ_i = θ_b + δ_i
        w_i = (-s_i * qd[0] + c_i * qd[1] + thd * (px * c_d + py * s_d)) / s_w  # (8a)
        delta_dot = w_i - thd
        # pivot point P_ib (5a–c): r̈_ib = [I | S p] q̈_b − θ̇_b² p, p = R_b r_ib/b
        p0 = c_b * px - s_b * py
        p1 = s_b * px + c_b * py
        sp0, sp1 = -p1, p0
        rd_ib0, rd_ib1 = qd[0] + thd * sp0, qd[1] + thd * sp1
        b_ib0, b_ib1 = -(thd * thd) * p0, -(thd * thd) * p1
        # unit rotation θ̈_i = a_θ q̈_b + b_θ (eqs. 24–26)
        at = (-s_i / s_w, c_i / s_w, (px * c_d + py * s_d) / s_w)
        bt = (-c_i * w_i * qd[0] - s_i * w_i * qd[1]
              + thd * (-px * s_d + py * c_d) * delta_dot) / s_w
        # hub centre of mass (9, 23, 27): q̈_icm = A^{q̈_icm} q̈_b + b^{q̈_icm}, rows x, y, θ_i
        cm = _point(-s_cm, 0.0, c_i, s_i, w_i, rd_ib0, rd_ib1, sp0, sp1, b_ib0, b_ib1, at[0],
                    at[1], at[2], bt)
        # wheels L, R (10, 11, 30)
        wl = _wheel(_point(-s_w, h, c_i, s_i, w_i, rd_ib0, rd_ib1, sp0, sp1, b_ib0, b_ib1,
                           at[0], at[1], at[2], bt), c_i, s_i, w_i, r_w)
        wr = _wheel(_point(-s_w, -h, c_i, s_i, w_i, rd_ib0, rd_ib1, sp0, sp1, b_ib0, b_ib1,
                           at[0], at[1], at[2], bt), c_i, s_i, w_i, r_w)
        # hub equations of motion (18–21): G = B_Fixy [I2 0] A_iwh⁻¹ (B_Fixy of eq. 4),
        # A_iwh⁻¹ from the adjugate of its rows x0, x1, x2 (eq. 20)
        x00, x01, x02 = -c_b, s_b, -s_i
        x10, x11, x12 = -s_b, -c_b, c_i
        x20, x21, x22 = s_cm * s_d, -s_cm * c_d, -dx
        i00 = x11 * x22 - x12 * x21
        i10 = x12 * x20 - x10 * x22
        i01 = x21 * x02 - x22 * x01
        i11 = x22 * x00 - x20 * x02
        i02 = x01 * x12 - x02 * x11
        i12 = x02 * x10 - x00 * x12
        det = x00 * i00 + x01 * i10 + x02 * (x10 * x21 - x11 * x20)
        i00, i01, i02 = i00 / det, i01 / det, i02 / det
        i10, i11, i12 = i10 / det, i11 / det, i12 / det
        tau_fp = par[3 + 4 * k + i] * delta_dot + par[3 + 5 * k + i] * math.tanh(
            alpha * delta_dot)  # (58–60)
        # inner = M_wh A^{q̈_icm} + (J_rot,w/R_w) A_iwh2 A^{φ̈} (A_iwh2 of eq. 21), column j;
        # its b-part likewise (j = 3)
        for c in range(3):
            if c == 0:
                f0, f1 = c_b, -s_b
            elif c == 1:
                f0, f1 = s_b, c_b
            else:
                f0, f1 = -py, px
            g0 = f0 * i00 + f1 * i10
            g1 = f0 * i01 + f1 * i11
            g2 = f0 * i02 + f1 * i12
            for j in range(4):
                e0 = m_wh * cm[2 + j] + jr * (c_i * wl[j] + c_i * wr[j]) if j < 3 else \
                    m_wh * cm[8] + jr * (c_i * wl[3] + c_i * wr[3])
                e1 = m_wh * cm[5 + j] + jr * (s_i * wl[j] + s_i * wr[j]) if j < 3 else \
                    m_wh * cm[9] + jr * (s_i * wl[3] + s_i * wr[3])
                e2 = jzz * (at[j] if j < 3 else bt) + jr * (-h * wl[j] + h * wr[j])
                if j < 3:  # M_i,add = −G inner (eqs. 22, 32, 49)
                    m[c, j] -= g0 * e0 + g1 * e1 + g2 * e2
                else:  # b_dir,i = G inner_b (eqs. 22, 32)
                    b[c] += g0 * e0 + g1 * e1 + g2 * e2
            # B_τ,i = −G A_iwh2 / R_w (eqs. 22, 29, 31, 32), B_τfp,i = (I + G) e3 (64)
            btau[c, ic[2 * i]] = -(g0 * c_i + g1 * s_i - g2 * h) / r_w
            btau[c, ic[2 * i + 1]] = -(g0 * c_i + g1 * s_i + g2 * h) / r_w
            ff[c] += (g2 + (1.0 if c == 2 else 0.0)) * tau_fp
        for w in range(2):
            j = 2 * i + w
            phid = wl[4] if w == 0 else wr[4]
            tauf[ic[j]] = par[3 + j] * phid + par[3 + 2 * k + j] * math.tanh(alpha * phid)
            crate[ic[j]] = phid
        arate[ia[3 * i]] = delta_dot
        arate[ia[3 * i + 1]] = wl[4]
        arate[ia[3 * i + 2]] = wr[4]


@njit(no_cpython_wrapper=True, error_model="numpy")
def actuator_rates(geo: np.ndarray, ia: np.ndarray, ic: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, ang: np.ndarray, crate: np.ndarray) -> None:
    """Wheel rates the base motion asks for at the current pivot angles, into ``crate`` (A,):
    eqs. 8a, 10b and 11 in the unit frame (:meth:`SwivelUnits.wheel_rates`)."""
    r_w, d_w, s_w = geo[0], geo[1], geo[2]
    c_b, s_b = math.cos(q[2]), math.sin(q[2])
    vx = c_b * qd[0] + s_b * qd[1]  # base velocity in the base frame
    vy = -s_b * qd[0] + c_b * qd[1]
    w = qd[2]
    for i in range(ia.shape[0] // 3):
        px, py = geo[N_GEO + 2 * i], geo[N_GEO + 2 * i + 1]
        delta = ang[ia[3 * i]]
        c_d, s_d = math.cos(delta), math.sin(delta)
        th_i_dot = (-s_d * vx + c_d * vy + w * (px * c_d + py * s_d)) / s_w  # (8a)
        fwd = c_d * vx + s_d * vy + w * (px * s_d - py * c_d)
        half = 0.5 * d_w * th_i_dot
        crate[ic[2 * i]] = (fwd - half) / r_w
        crate[ic[2 * i + 1]] = (fwd + half) / r_w


@njit(no_cpython_wrapper=True, error_model="numpy")
def kinetic_energy(geo: np.ndarray, par: np.ndarray, ia: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, ang: np.ndarray) -> float:
    """Σ_i ½ m_wh |ṙ_icm|² + ½ J_zz,wh θ̇_i² + ½ J_rot,w Σ_w φ̇_iw² [J] (App. C; 9b, 8a, 11)."""
    r_w, d_w, s_w, dx = geo[0], geo[1], geo[2], geo[3]
    s_cm = s_w - dx
    th_b, thd = q[2], qd[2]
    c_b, s_b = math.cos(th_b), math.sin(th_b)
    t = 0.0
    for i in range(ia.shape[0] // 3):
        px, py = geo[N_GEO + 2 * i], geo[N_GEO + 2 * i + 1]
        delta = ang[ia[3 * i]]
        c_d, s_d = math.cos(delta), math.sin(delta)
        c_i, s_i = math.cos(th_b + delta), math.sin(th_b + delta)
        w_i = (-s_i * qd[0] + c_i * qd[1] + thd * (px * c_d + py * s_d)) / s_w  # (8a)
        rd_ib0 = qd[0] - thd * (s_b * px + c_b * py)  # (5b)
        rd_ib1 = qd[1] + thd * (c_b * px - s_b * py)
        # ṙ = ṙ_ib + θ̇_i S R_i r for the hub CoM r = (−s_cm, 0) and the wheels (−s_w, ±d_w/2)
        t_cm = (rd_ib0 - w_i * (s_i * -s_cm)) ** 2 + (rd_ib1 + w_i * (c_i * -s_cm)) ** 2
        t_w = 0.0
        for half in (d_w / 2, -d_w / 2):
            v0 = c_i * -s_w - s_i * half
            v1 = s_i * -s_w + c_i * half
            phid = (c_i * (rd_ib0 - w_i * v1) + s_i * (rd_ib1 + w_i * v0)) / r_w  # (11)
            t_w += phid * phid
        t += 0.5 * par[0] * t_cm + 0.5 * par[1] * w_i * w_i + 0.5 * par[2] * t_w
    return t
