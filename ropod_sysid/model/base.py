"""The platform base: the central body every wheel unit is attached to (thesis Sec. V-A).

All functions are vectorised over samples: ``q`` and friends have shape (N, 3) with columns
x_b, y_b, θ_b (world frame).
"""

from __future__ import annotations

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
