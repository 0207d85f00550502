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

from dataclasses import dataclass

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


def normal_equations(platform: Platform, delta: np.ndarray, delta_rate: np.ndarray,
                     phi_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """AᵀA (N, 3, 3) and Aᵀb (N, 3) of :func:`constraint_system`, summed over the units
    without forming the (3n × 3) rows.

    Unit i contributes its rows L = (c, s, f − d_w/2), R = (c, s, f + d_w/2) and
    S = (−s, c, g), with f = x s_δ − y c_δ and g = x c_δ + y s_δ − s_w (eqs. 11, 8a).
    """
    p = platform.pivots
    x, y = p[:, :1], p[:, 1:]  # (n, 1): arrays below are unit-major (n, N), sums over units
    r_w, d_w, s_w = platform.wheel_radius, platform.wheel_distance, platform.caster_offset
    delta_t = np.ascontiguousarray(np.asarray(delta, float).T)
    rate_t = np.ascontiguousarray(np.asarray(delta_rate, float).T)
    phi_t = np.ascontiguousarray(np.moveaxis(np.asarray(phi_rate, float), 0, -1))  # (n, 2, N)
    phi_l, phi_r = phi_t[:, 0], phi_t[:, 1]
    c, s = np.cos(delta_t), np.sin(delta_t)
    f = x * s - y * c
    g = x * c + y * s - s_w
    b_sum = r_w * (phi_l + phi_r)  # b_L + b_R
    b_diff = r_w * (phi_r - phi_l) - d_w * rate_t  # b_R − b_L
    b_s = s_w * rate_t
    n_units, n = delta_t.shape
    cc = (c * c).sum(axis=0)
    ata = np.empty((n, 3, 3))
    ata[:, 0, 0] = n_units + cc
    ata[:, 0, 1] = ata[:, 1, 0] = (c * s).sum(axis=0)
    ata[:, 0, 2] = ata[:, 2, 0] = (2.0 * c * f - s * g).sum(axis=0)
    ata[:, 1, 1] = 2 * n_units - cc  # Σ 1 + s² = Σ 2 − c²
    ata[:, 1, 2] = ata[:, 2, 1] = (2.0 * s * f + c * g).sum(axis=0)
    ata[:, 2, 2] = (2.0 * f * f + g * g).sum(axis=0) + n_units * d_w * d_w / 2
    atb = np.empty((n, 3))
    atb[:, 0] = (c * b_sum - s * b_s).sum(axis=0)
    atb[:, 1] = (s * b_sum + c * b_s).sum(axis=0)
    atb[:, 2] = (f * b_sum + d_w / 2 * b_diff + g * b_s).sum(axis=0)
    return ata, atb


def base_twist(platform: Platform, delta: np.ndarray, delta_rate: np.ndarray,
               phi_rate: np.ndarray) -> np.ndarray:
    """Least-squares base twist (v_x, v_y, ω) in the base frame [m/s, rad/s]; (N, 3)."""
    a, b = constraint_system(platform, delta, delta_rate, phi_rate)
    return np.einsum("nij,nj->ni", np.linalg.pinv(a), b)


def unwrap_from(p: np.ndarray, corr0: np.ndarray | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`numpy.unwrap` along axis 0, continued from the correction ``corr0`` that an
    unwrap of the earlier samples added at ``p[0]`` (None: p[0] is the first sample).

    Returns the unwrapped samples and the correction at each sample; with the same formula
    and a sequential cumulative sum it equals one ``np.unwrap`` over the whole signal bit for
    bit, however the signal is cut into pieces.
    """
    p = np.asarray(p, dtype=float)
    period = 2 * np.pi
    low, high = -period / 2, period / 2
    dd = np.diff(p, axis=0)
    ph = np.zeros_like(dd)
    jump = np.abs(dd) >= high  # numpy's rule: smaller steps get no correction
    if jump.any():
        d = dd[jump]
        ddmod = np.mod(d - low, period) + low
        np.copyto(ddmod, high, where=(ddmod == low) & (d > 0))
        ph[jump] = ddmod - d
    start = np.zeros_like(p[:1]) if corr0 is None else np.asarray(corr0, float)[None]
    corr = np.cumsum(np.concatenate([start, ph]), axis=0)
    return p + corr, corr


def solve_symmetric3(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """x with m x = v for symmetric 3 × 3 matrices ``m`` (N, 3, 3) and ``v`` (N, 3), by the
    adjugate (the normal equations of the constraints are well conditioned: the 3n rows span
    the plane's twists with O(1) coefficients)."""
    a, b, c = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    d, e, f = m[:, 1, 1], m[:, 1, 2], m[:, 2, 2]
    adj_a, adj_b, adj_c = d * f - e * e, c * e - b * f, b * e - c * d
    adj_d, adj_e, adj_f = a * f - c * c, b * c - a * e, a * d - b * b
    inv_det = 1.0 / (a * adj_a + b * adj_b + c * adj_c)
    x = np.empty_like(v)
    x[:, 0] = (adj_a * v[:, 0] + adj_b * v[:, 1] + adj_c * v[:, 2]) * inv_det
    x[:, 1] = (adj_b * v[:, 0] + adj_d * v[:, 1] + adj_e * v[:, 2]) * inv_det
    x[:, 2] = (adj_c * v[:, 0] + adj_e * v[:, 1] + adj_f * v[:, 2]) * inv_det
    return x


@dataclass
class OdometryState:
    """Where wheel odometry stands at one sample: the pose (x_b, y_b, θ_b) and the correction
    unwrapping has added to each pivot angle there (to continue it over the next samples)."""

    pose: np.ndarray  # (3,)
    unwrap: np.ndarray  # (n,)


def odometry_from(platform: Platform, delta: np.ndarray, phi: np.ndarray,
                  start: OdometryState | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Base pose (N, 3) from smoothed encoder angles, as :func:`ropod_sysid.odometry.odometry`,
    continued from ``start`` at sample 0 (None: the pose is zero there).

    The per-interval least squares on the no-slip constraints is solved by its 3 × 3 normal
    equations (:func:`solve_symmetric3`); the pose is the sequential cumulative sum of the
    displacements from the start pose, so that a log cut into overlapping pieces gives the pose
    of one pass. Returns the pose and the unwrapping corrections of δ per sample (for
    :class:`OdometryState`).
    """
    delta, corr = unwrap_from(delta, None if start is None else start.unwrap)
    phi = np.asarray(phi, float)
    d_delta = np.diff(delta, axis=0)
    d_phi = np.diff(phi, axis=0)
    mid = delta[:-1] + 0.5 * d_delta
    step = solve_symmetric3(*normal_equations(platform, mid, d_delta, d_phi))  # base frame
    pose0 = np.zeros(3) if start is None else np.asarray(start.pose, float)
    theta = np.cumsum(np.concatenate([pose0[2:], step[:, 2]]))
    heading = theta[:-1] + 0.5 * step[:, 2]
    c, s = np.cos(heading), np.sin(heading)
    dx = c * step[:, 0] - s * step[:, 1]
    dy = s * step[:, 0] + c * step[:, 1]
    pose = np.empty((delta.shape[0], 3))
    pose[:, 0] = np.cumsum(np.concatenate([pose0[:1], dx]))
    pose[:, 1] = np.cumsum(np.concatenate([pose0[1:2], dy]))
    pose[:, 2] = theta
    return pose, corr


def odometry(platform: Platform, delta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Base pose (x_b, y_b, θ_b) [m, m, rad] from encoder angles; (N, 3), zero at sample 0.

    ``delta`` (N, n) pivot angles (wrapped or not) and ``phi`` (N, n, 2) wheel angles,
    unwrapped. See :func:`odometry_from` to continue from a pose reached earlier.
    """
    return odometry_from(platform, delta, phi)[0]
