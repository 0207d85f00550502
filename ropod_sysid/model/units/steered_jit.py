"""The compiled (numba) kernel of k centred steered wheels at one sample: the simulator's fast
path for 001's vehicle.

The same pieces as :meth:`SteeredUnits.kinematics`, :meth:`SteeredUnits.mass_terms`,
:meth:`SteeredUnits.constraint_jacobian`, :meth:`SteeredUnits.friction_torques`,
:meth:`SteeredUnits.kinetic_energy` and the planned branch of
:meth:`SteeredUnits.controller_setpoints` (001; eqs. S1–S8 of
:mod:`ropod_sysid.model.units.steered`), written out per unit with scalars. Unlike the swivel's
and the omni wheel's, this kernel writes beyond the base block: unit i's steering angle β_i is
the generalized coordinate ``row + i`` (its rate ``qd[row + i]``, a state of the simulator), and
its lateral no-slip row S2 is the constraint row ``con + i``, which the simulator's loop
projects out (Udwadia–Kalaba, :meth:`PlatformModel.forward_dynamics`). The numpy methods stay
the reference (``tests/test_simulate_jit.py`` compares the two). The functions are compiled into
the simulator's loop (:func:`ropod_sysid.simulate_jit.run`, cached with it) and have no Python
wrapper of their own (``no_cpython_wrapper=True``): they are not called from Python.

Arrays (:func:`arrays`):

- ``geo`` = [α, x_1, y_1, r_1, …, x_k, y_k, r_k] (α: the friction tanh gain; per unit its
  steering axis p_i and wheel radius r_i);
- ``par`` = [J_st, J_rot,s, f_dv,1, f_dc,1, f_sv,1, f_sc,1, …] (the drives' zero with body-axis
  friction);
- ``ia`` (2k,) the platform's angle channels of β_i, φ_i per unit, ``ic`` (2k,) its actuator
  channels of the drive and the steering motor per unit;
- ``plan`` (2k,) the planned steering at the step, β_d,i then β̇_d,i
  (:meth:`SteeredUnits.controller_plan`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from ropod_sysid.model.units import FrictionVariant
    from ropod_sysid.model.units.steered import SteeredUnits

CONSTRAINTS = 1  # constraint rows per unit (S2), for the loop's row offsets
PLANNED = 2  # planned entries per unit (β_d, β̇_d)


def arrays(units: SteeredUnits, params: Mapping[str, float], variant: FrictionVariant
           ) -> tuple[np.ndarray, np.ndarray]:
    """(``geo``, ``par``) of the group for the parameters and the friction variant."""
    geo = np.concatenate([[units.alpha], np.column_stack(
        [units.positions, units.r]).reshape(-1)])
    friction = units._coefficients(params, variant).reshape(-1)  # (f_dv, f_dc, f_sv, f_sc)
    return geo, np.concatenate([[float(params["Jst"]), float(params["Jrot_s"])], friction])


@njit(no_cpython_wrapper=True, error_model="numpy")
def dynamics(geo: np.ndarray, par: np.ndarray, ia: np.ndarray, ic: np.ndarray, row: int,
             con: int, q: np.ndarray, qd: np.ndarray, ang: np.ndarray, m: np.ndarray,
             b: np.ndarray, btau: np.ndarray, tauf: np.ndarray, arate: np.ndarray,
             crate: np.ndarray, g: np.ndarray, gdot: np.ndarray) -> None:
    """Add the group's M_add to ``m`` (D, D) and b_dir to ``b`` (D,) (S5, S6); write its
    columns of B_τ into ``btau`` (D, A) (S7), the friction torques τ_fd, τ_fs into ``tauf``
    (A,), its lateral rows G_i and Ġ_i q̇ into ``g`` (C, D) and ``gdot`` (C,) (S2, S4), the
    rates β̇, φ̇ into ``arate`` (J,) and φ̇, β̇ into ``crate`` (A,). ``qd`` (D,) is the
    generalized velocity: β̇_i = qd[row + i]. Every joint is actuated: no f_f."""
    alpha = geo[0]
    j_st, j_rot = par[0], par[1]
    thd = qd[2]
    for i in range(ia.shape[0] // 2):
        px, py, r = geo[1 + 3 * i], geo[2 + 3 * i], geo[3 + 3 * i]
        beta, bd = ang[ia[2 * i]], qd[row + i]
        cb, sb = math.cos(beta), math.sin(beta)
        c_i = px * sb - py * cb  # p × h (S1)
        e_i = px * cb + py * sb  # p · h (S2)
        psi = q[2] + beta  # the wheel's world heading ψ = θ + β
        cp, sp = math.cos(psi), math.sin(psi)
        j0, j1, j2 = cp / r, sp / r, c_i / r  # J_i (S1)
        n_dot_v = -sp * qd[0] + cp * qd[1]
        jdq = ((thd + bd) * n_dot_v + bd * e_i * thd) / r  # J̇_i q̇_b (S3)
        phid = j0 * qd[0] + j1 * qd[1] + j2 * thd  # φ̇_i = J_i q̇_b (S1)
        for c in range(3):
            jc = j0 if c == 0 else (j1 if c == 1 else j2)
            m[c, 0] += j_rot * jc * j0  # J_rot,s J_iᵀ J_i (S5)
            m[c, 1] += j_rot * jc * j1
            m[c, 2] += j_rot * jc * j2
            b[c] -= j_rot * jc * jdq  # −J_rot,s J_iᵀ J̇_i q̇_b (S6)
            btau[c, ic[2 * i]] = jc  # drive i → [J_iᵀ; 0] (S7)
        # J_st (e_θ + e_βi)(e_θ + e_βi)ᵀ (S5); steering i → e_βi (S7)
        m[2, 2] += j_st
        m[2, row + i] += j_st
        m[row + i, 2] += j_st
        m[row + i, row + i] += j_st
        btau[row + i, ic[2 * i + 1]] = 1.0
        # friction added to the motor torques, f_v rate + f_c tanh(α rate) (001 Sec. 3.1)
        f = 4 * i
        tauf[ic[2 * i]] = par[2 + f] * phid + par[3 + f] * math.tanh(alpha * phid)
        tauf[ic[2 * i + 1]] = par[4 + f] * bd + par[5 + f] * math.tanh(alpha * bd)
        # lateral no-slip G_i = [n_iᵀ, e_i] (S2) and Ġ_i q̇ (S4), ψ̇ = θ̇ + β̇
        g[con + i, 0] = -sp
        g[con + i, 1] = cp
        g[con + i, 2] = e_i
        gdot[con + i] = -(thd + bd) * (cp * qd[0] + sp * qd[1]) - bd * c_i * thd
        arate[ia[2 * i]] = bd
        arate[ia[2 * i + 1]] = phid
        crate[ic[2 * i]] = phid
        crate[ic[2 * i + 1]] = bd


@njit(no_cpython_wrapper=True, error_model="numpy")
def setpoints(geo: np.ndarray, ia: np.ndarray, ic: np.ndarray, plan: np.ndarray,
              twist: np.ndarray, ang: np.ndarray, want: np.ndarray, err: np.ndarray) -> None:
    """The decentralised controllers' setpoints along the planned steering (001 eqs. 24–25):
    the drive rate φ̇_d = h(β_d)·u / r of the wheel-centre velocity u = v + ω × p_i for the
    base-frame ``twist`` and the planned rate β̇_d into ``want`` (A,), the steering angle error
    β_d − β into ``err`` (A,) (:meth:`SteeredUnits.controller_setpoints` with a plan)."""
    k = ia.shape[0] // 2
    for i in range(k):
        px, py, r = geo[1 + 3 * i], geo[2 + 3 * i], geo[3 + 3 * i]
        u_x = twist[0] - twist[2] * py  # :meth:`SteeredUnits.centre_velocity`
        u_y = twist[1] + twist[2] * px
        beta_d = plan[i]
        want[ic[2 * i]] = (math.cos(beta_d) * u_x + math.sin(beta_d) * u_y) / r
        want[ic[2 * i + 1]] = plan[k + i]
        err[ic[2 * i + 1]] = beta_d - ang[ia[2 * i]]


@njit(no_cpython_wrapper=True, error_model="numpy")
def kinetic_energy(geo: np.ndarray, par: np.ndarray, ia: np.ndarray, row: int, q: np.ndarray,
                   qd: np.ndarray, ang: np.ndarray) -> float:
    """Σ_i ½ J_st (θ̇ + β̇_i)² + ½ J_rot,s φ̇_i² [J] with φ̇_i from S1."""
    t = 0.0
    for i in range(ia.shape[0] // 2):
        px, py, r = geo[1 + 3 * i], geo[2 + 3 * i], geo[3 + 3 * i]
        beta = ang[ia[2 * i]]
        c_i = px * math.sin(beta) - py * math.cos(beta)
        psi = q[2] + beta
        phid = (math.cos(psi) * qd[0] + math.sin(psi) * qd[1] + c_i * qd[2]) / r
        turn = qd[2] + qd[row + i]
        t += 0.5 * par[0] * turn * turn + 0.5 * par[1] * phid * phid
    return t
