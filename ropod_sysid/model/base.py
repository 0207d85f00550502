"""The platform base: the central body every wheel unit is attached to (thesis Sec. V-A).

All functions are vectorised over samples: ``q`` and friends have shape (N, 3) with columns
x_b, y_b, θ_b (world frame).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


def m_b(mass: float, inertia: float, n: int = 1) -> np.ndarray:
    """Mass matrix of the base alone, M_b = diag(m_b, m_b, J_zz,b) (eq. 2); shape (n, 3, 3)."""
    out = np.zeros((n, 3, 3))
    out[:, 0, 0] = mass
    out[:, 1, 1] = mass
    out[:, 2, 2] = inertia
    return out


def b_fb(theta_b: np.ndarray) -> np.ndarray:
    """B_Fb: base-frame force/torque F_b → world components (eq. 3); shape (N, 3, 3)."""
    c, s = np.cos(theta_b), np.sin(theta_b)
    out = np.zeros((*np.shape(theta_b), 3, 3))
    out[..., 0, 0], out[..., 0, 1] = c, -s
    out[..., 1, 0], out[..., 1, 1] = s, c
    out[..., 2, 2] = 1.0
    return out


def a_id_base(qdd: np.ndarray) -> np.ndarray:
    """Regressor columns of the base, d(M_b q̈)/d[m_b, J_zz,b]; shape (N, 3, 2) (eq. 35)."""
    out = np.zeros((qdd.shape[0], 3, 2))
    out[:, 0, 0] = qdd[:, 0]
    out[:, 1, 0] = qdd[:, 1]
    out[:, 2, 1] = qdd[:, 2]
    return out


def kinetic_energy_base(mass: float, inertia: float, qd: np.ndarray) -> np.ndarray:
    """½ m_b |ṙ_b|² + ½ J_zz,b θ̇_b² [J]; shape (N,)."""
    return 0.5 * mass * (qd[:, 0] ** 2 + qd[:, 1] ** 2) + 0.5 * inertia * qd[:, 2] ** 2


# ------------------------------------------------------------ body-axis friction (004)
# Friction of the base along its own axes, as 004 eqs. 6–8 model the 5DPO robot: viscous
# f_bv and Coulomb f_bc along x, y of the base frame and about z. It replaces the units'
# friction terms (``--friction body``); added like them, so dissipative values are negative.
BASE_PARAMETERS = ("m_b", "Jzz_b")
BODY_FRICTION = ("fbv_x", "fbv_y", "fbv_w", "fbc_x", "fbc_y", "fbc_w")
FRICTION_SIGNS = dict.fromkeys(BODY_FRICTION, -1)  # of dissipative friction
PARAMETER_INFO = {
    "m_b": ("kg", "platform base mass"),
    "Jzz_b": ("kg m²", "platform base inertia about z"),
    "fbv_x": ("N s/m", "viscous friction along the base x axis"),
    "fbv_y": ("N s/m", "viscous friction along the base y axis"),
    "fbv_w": ("N m s/rad", "viscous friction about the base z axis"),
    "fbc_x": ("N", "Coulomb friction along the base x axis"),
    "fbc_y": ("N", "Coulomb friction along the base y axis"),
    "fbc_w": ("N m", "Coulomb friction about the base z axis"),
}


def body_velocity(theta: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """ν = (v, v_n, ω): the world twist in the base frame (004 eq. 1); shape (N, 3)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * qd[:, 0] + s * qd[:, 1], -s * qd[:, 0] + c * qd[:, 1], qd[:, 2]],
                    axis=-1)


def body_friction_force(theta: np.ndarray, qd: np.ndarray, params: Mapping[str, float],
                        alpha: float) -> np.ndarray:
    """Generalized body-axis friction force in world coordinates, B_Fb F_f; (N, 3).

    F_f = f_bv ⊙ ν + f_bc ⊙ tanh(α ν) in the base frame (004 eqs. 6–8 with the signs of the
    contract: added, so dissipative coefficients are negative).
    """
    nu = body_velocity(theta, qd)
    fbv = np.array([float(params.get(n, 0.0)) for n in BODY_FRICTION[:3]])
    fbc = np.array([float(params.get(n, 0.0)) for n in BODY_FRICTION[3:]])
    f = fbv * nu + fbc * np.tanh(alpha * nu)
    return np.einsum("ncd,nd->nc", b_fb(theta), f)


def body_friction_columns(theta: np.ndarray, qd: np.ndarray, alpha: float) -> np.ndarray:
    """Columns of A_ID,ext for ``fbv_x … fbc_w``: −B_Fb e_j ν_j and −B_Fb e_j tanh(α ν_j);
    shape (N, 3, 6)."""
    nu = body_velocity(theta, qd)
    b = b_fb(theta)  # (N, 3, 3)
    return -np.concatenate([b * nu[:, None, :], b * np.tanh(alpha * nu)[:, None, :]], axis=2)
