"""The compiled (numba) kernel of k omni units at one sample: the simulator's fast path.

The same pieces as :meth:`OmniUnits.kinematics`, :meth:`OmniUnits.mass_terms`, the per-wheel
friction and :meth:`OmniUnits.kinetic_energy` (004 eqs. 1–13; eqs. O1–O3 of
:mod:`ropod_sysid.model.units.omni`), written out per unit with scalars. The numpy methods stay
the reference (``tests/test_simulate_jit.py`` compares the two). The functions are compiled into
the simulator's loop (:func:`ropod_sysid.simulate_jit.run`, cached with it) and have no Python
wrapper of their own (``no_cpython_wrapper=True``): they are not called from Python.

Arrays (:func:`arrays`):

- ``geo`` = [α, a_1, r_1, c_1, …, a_k, r_k, c_k]: the friction tanh gain, then per unit its
  heading a_i, wheel radius r_i and moment arm c_i = p_i × h_i;
- ``par`` = [J_rot,o, f_ov (k), f_oc (k)] (zero friction with body-axis friction);
- ``ia`` (k,) the platform's angle channels of φ_i, ``ic`` (k,) its actuator channels.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from ropod_sysid.model.units import FrictionVariant
    from ropod_sysid.model.units.omni import OmniUnits


def arrays(units: OmniUnits, params: Mapping[str, float], variant: FrictionVariant
           ) -> tuple[np.ndarray, np.ndarray]:
    """(``geo``, ``par``) of the group for the parameters and the friction variant."""
    geo = np.concatenate([[units.alpha], np.column_stack(
        [units.headings, units.r, units.moment_arm]).reshape(-1)])
    fov, foc = units._coefficients(params, variant)
    return geo, np.concatenate([[float(params["Jrot_o"])], fov, foc])


@njit(no_cpython_wrapper=True, error_model="numpy")
def dynamics(geo: np.ndarray, par: np.ndarray, ia: np.ndarray, ic: np.ndarray, q: np.ndarray,
             qd: np.ndarray, ang: np.ndarray, m: np.ndarray, b: np.ndarray, btau: np.ndarray,
             tauf: np.ndarray, ff: np.ndarray, arate: np.ndarray, crate: np.ndarray) -> None:
    """Add M_add = J_rot,o Σ J_iᵀ J_i to ``m`` and b_dir = −J_rot,o Σ J_iᵀ (J̇_i q̇_b) to ``b``
    (O3); write B_τ,i = J_iᵀ into ``btau`` (3, A), the friction torque
    τ_f,i = f_ov,i φ̇_i + f_oc,i tanh(α φ̇_i) into ``tauf`` and φ̇_i = J_i q̇_b (O1) into
    ``arate`` and ``crate``. No unactuated joint: ``ff`` is left alone."""
    alpha = geo[0]
    k = ia.shape[0]
    j_rot = par[0]
    jac = np.empty(3)
    for i in range(k):
        a_i, r_i, c_i = geo[1 + 3 * i], geo[2 + 3 * i], geo[3 + 3 * i]
        ch, sh = math.cos(q[2] + a_i), math.sin(q[2] + a_i)
        jac[0], jac[1], jac[2] = ch / r_i, sh / r_i, c_i / r_i  # (O1)
        jdq = qd[2] * (-sh * qd[0] + ch * qd[1]) / r_i  # (O2)
        phid = jac[0] * qd[0] + jac[1] * qd[1] + jac[2] * qd[2]
        for c in range(3):
            for d in range(3):
                m[c, d] += j_rot * jac[c] * jac[d]
            b[c] -= j_rot * jac[c] * jdq
            btau[c, ic[i]] = jac[c]
        tauf[ic[i]] = par[1 + i] * phid + par[1 + k + i] * math.tanh(alpha * phid)
        arate[ia[i]] = phid
        crate[ic[i]] = phid


@njit(no_cpython_wrapper=True, error_model="numpy")
def actuator_rates(geo: np.ndarray, ia: np.ndarray, ic: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, ang: np.ndarray, crate: np.ndarray) -> None:
    """φ̇_i = J_i q̇_b (O1) the base motion asks of the wheels, into ``crate`` (A,)."""
    for i in range(ia.shape[0]):
        a_i, r_i, c_i = geo[1 + 3 * i], geo[2 + 3 * i], geo[3 + 3 * i]
        ch, sh = math.cos(q[2] + a_i), math.sin(q[2] + a_i)
        crate[ic[i]] = (ch * qd[0] + sh * qd[1] + c_i * qd[2]) / r_i


@njit(no_cpython_wrapper=True, error_model="numpy")
def kinetic_energy(geo: np.ndarray, par: np.ndarray, ia: np.ndarray, q: np.ndarray,
                   qd: np.ndarray, ang: np.ndarray) -> float:
    """Σ_i ½ J_rot,o φ̇_i² [J] with φ̇_i from O1."""
    t = 0.0
    for i in range(ia.shape[0]):
        a_i, r_i, c_i = geo[1 + 3 * i], geo[2 + 3 * i], geo[3 + 3 * i]
        ch, sh = math.cos(q[2] + a_i), math.sin(q[2] + a_i)
        phid = (ch * qd[0] + sh * qd[1] + c_i * qd[2]) / r_i
        t += 0.5 * par[0] * phid * phid
    return t
