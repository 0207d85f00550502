"""Wheel odometry: encoder angles (wheels, pivots) → base pose (thesis Sec. VI-B).

Per sample interval, the base displacement that best explains the 2n wheel-angle increments and
the n pivot-angle increments is found by least squares on the no-slip constraints (8a) and (11),
written in the base frame for unit i at pivot (x, y) with angle δ:

    R_w φ̇_iL = c_δ v_x + s_δ v_y + ω (x s_δ − y c_δ) − (d_w/2)(ω + δ̇)     (11), wheel L
    R_w φ̇_iR = c_δ v_x + s_δ v_y + ω (x s_δ − y c_δ) + (d_w/2)(ω + δ̇)     (11), wheel R
    s_w (ω + δ̇) = −s_δ v_x + c_δ v_y + ω (x c_δ + y s_δ)                 (8a)

(v_x, v_y, ω: base twist in the base frame). The increments are integrated with the mid-interval
heading; the pose is zero at the first sample.
"""

from __future__ import annotations

import numpy as np

from ropod_sysid.platform import Platform


def constraint_system(platform: Platform, delta: np.ndarray, delta_rate: np.ndarray,
                      phi_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of eqs. 8a and 11 in the base twist: A (N, 3n, 3) and b (N, 3n).

    ``delta`` (N, n) [rad]; ``delta_rate`` (N, n) and ``phi_rate`` (N, n, 2) are rates [rad/s]
    (or increments [rad], which gives displacements instead of a twist).
    """
    p = platform.pivots
    x, y = p[:, 0], p[:, 1]
    r_w, d_w, s_w = platform.wheel_radius, platform.wheel_distance, platform.caster_offset
    c, s = np.cos(delta), np.sin(delta)
    n_s, n_u = delta.shape
    fwd = x * s - y * c
    a = np.empty((n_s, n_u, 3, 3))
    b = np.empty((n_s, n_u, 3))
    a[..., 0, 0], a[..., 0, 1], a[..., 0, 2] = c, s, fwd - d_w / 2  # wheel L
    a[..., 1, 0], a[..., 1, 1], a[..., 1, 2] = c, s, fwd + d_w / 2  # wheel R
    a[..., 2, 0], a[..., 2, 1], a[..., 2, 2] = -s, c, x * c + y * s - s_w  # no side slip
    b[..., 0] = r_w * phi_rate[..., 0] + d_w / 2 * delta_rate
    b[..., 1] = r_w * phi_rate[..., 1] - d_w / 2 * delta_rate
    b[..., 2] = s_w * delta_rate
    return a.reshape(n_s, 3 * n_u, 3), b.reshape(n_s, 3 * n_u)


def base_twist(platform: Platform, delta: np.ndarray, delta_rate: np.ndarray,
               phi_rate: np.ndarray) -> np.ndarray:
    """Least-squares base twist (v_x, v_y, ω) in the base frame [m/s, rad/s]; (N, 3)."""
    a, b = constraint_system(platform, delta, delta_rate, phi_rate)
    return np.einsum("nij,nj->ni", np.linalg.pinv(a), b)


def odometry(platform: Platform, delta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Base pose (x_b, y_b, θ_b) [m, m, rad] from encoder angles; (N, 3), zero at sample 0.

    ``delta`` (N, n) pivot angles and ``phi`` (N, n, 2) wheel angles, unwrapped.
    """
    delta = np.unwrap(np.asarray(delta, float), axis=0)
    phi = np.asarray(phi, float)
    d_delta = np.diff(delta, axis=0)
    d_phi = np.diff(phi, axis=0)
    mid = delta[:-1] + 0.5 * d_delta
    step = base_twist(platform, mid, d_delta, d_phi)  # displacements in the base frame
    theta = np.concatenate([[0.0], np.cumsum(step[:, 2])])
    heading = theta[:-1] + 0.5 * step[:, 2]
    c, s = np.cos(heading), np.sin(heading)
    dx = c * step[:, 0] - s * step[:, 1]
    dy = s * step[:, 0] + c * step[:, 1]
    pose = np.zeros((delta.shape[0], 3))
    pose[1:, 0] = np.cumsum(dx)
    pose[1:, 1] = np.cumsum(dy)
    pose[:, 2] = theta
    return pose
