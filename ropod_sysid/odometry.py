"""Wheel odometry: encoder angles (wheels, pivots) → base pose (thesis Sec. VI-B).

Per sample interval, the base displacement that best explains the increments of every unit's
angles is found by least squares on the units' no-slip constraint rows, linear in the
base-frame twist (v_x, v_y, ω): each unit type gives its rows (for the swivel eqs. 8a and 11,
for the omni wheel the rim-speed row of 004 eq. 2), and the rows of all units, of any mix of
types, form one least-squares problem per interval, solved by its 3 × 3 normal equations. The
increments are integrated with the mid-interval heading; the pose is zero at the first sample.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ropod_sysid.model import PlatformModel


def normal_equations(model: PlatformModel, angles: np.ndarray, increments: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """AᵀA (N, 3, 3) and Aᵀb (N, 3) of the constraint rows of every unit, summed over the
    unit groups (:meth:`ropod_sysid.model.units.UnitType.normal_equations`) at the angles
    (N, J) for their increments or rates (N, J)."""
    whole = len(model.groups) == 1  # one group: all the channels, in order

    def cols(values: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return values if whole else np.take(values, idx, axis=1)

    ata = atb = None
    for g, unit in model.groups:
        a, b = unit.normal_equations(cols(angles, g.angles), cols(increments, g.angles))
        ata, atb = (a, b) if ata is None else (ata + a, atb + b)
    assert ata is not None and atb is not None
    return ata, atb


def constraint_system(model: PlatformModel, angles: np.ndarray, rates: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The constraint rows of every unit stacked: A (N, r, 3), b (N, r), A ν = b in the
    base-frame twist ν."""
    parts = [unit.constraint_rows(np.take(angles, g.angles, axis=1),
                                  np.take(rates, g.angles, axis=1)) for g, unit in model.groups]
    return (np.concatenate([a for a, _ in parts], axis=1),
            np.concatenate([b for _, b in parts], axis=1))


def base_twist(model: PlatformModel, angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """Least-squares base twist (v_x, v_y, ω) in the base frame [m/s, rad/s]; (N, 3)."""
    a, b = constraint_system(model, angles, rates)
    return np.einsum("nij,nj->ni", np.linalg.pinv(a), b)


def wrap_jumps(p: np.ndarray) -> np.ndarray:
    """Where consecutive samples (along axis 0) of wrapped angles ``p`` step by half a turn or
    more: numpy's rule for where :func:`numpy.unwrap` corrects; (N − 1, …) booleans."""
    return np.abs(np.diff(p, axis=0)) >= np.pi


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
    jump = np.abs(dd) >= high  # numpy's rule (wrap_jumps): smaller steps get no correction
    start = np.zeros_like(p[:1]) if corr0 is None else np.asarray(corr0, float)[None]
    if not jump.any():  # the sum below of zero steps: the start's correction everywhere
        corr = np.repeat(start, p.shape[0], axis=0)
        return p + start, corr
    ph = np.zeros_like(dd)
    d = dd[jump]
    ddmod = np.mod(d - low, period) + low
    np.copyto(ddmod, high, where=(ddmod == low) & (d > 0))
    ph[jump] = ddmod - d
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
    unwrapping has added to each angle there (to continue it over the next samples)."""

    pose: np.ndarray  # (3,)
    unwrap: np.ndarray  # (J,)


def unwrap_angles(wrapped: np.ndarray, angles: np.ndarray, corr0: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`unwrap_from` of the channels flagged ``wrapped`` (J,) of ``angles`` (N, J); the
    others unchanged. Returns the angles and the corrections (N, J) (zero where not wrapped).

    Where no wrapped channel steps by half a turn (smoothed angles of unwrapped ones, as the
    fit's), the corrections are the start's on every sample: then they come back as a
    read-only broadcast of it, and the angles themselves when it is zero.
    """
    angles = np.asarray(angles, float)
    start = np.zeros(angles.shape[1])
    if not wrapped.any():
        return angles, np.broadcast_to(start, angles.shape)
    if corr0 is not None:
        start[wrapped] = np.asarray(corr0, float)[wrapped]
    idx = np.flatnonzero(wrapped)
    sub = np.take(angles, idx, axis=1)
    if not wrap_jumps(sub).any():  # unwrap_from's sum of zero steps
        corr = np.broadcast_to(start, angles.shape)
        if not start.any():
            return angles, corr
        out = angles.copy()
        out[:, idx] = sub + start[idx]
        return out, corr
    out = angles.copy()
    corr = np.zeros_like(angles)
    out[:, idx], corr[:, idx] = unwrap_from(sub, start[idx])
    return out, corr


def odometry_from(model: PlatformModel, angles: np.ndarray,
                  start: OdometryState | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Base pose (N, 3) from smoothed encoder angles (N, J), as :func:`odometry`, continued
    from ``start`` at sample 0 (None: the pose is zero there).

    The per-interval least squares on the constraint rows is solved by its 3 × 3 normal
    equations (:func:`solve_symmetric3`); the pose is the sequential cumulative sum of the
    displacements from the start pose, so that a log cut into overlapping pieces gives the pose
    of one pass. Returns the pose and the unwrapping corrections per sample (for
    :class:`OdometryState`).
    """
    angles, corr = unwrap_angles(model.layout.wrapped, angles,
                                 None if start is None else start.unwrap)
    d_ang = np.diff(angles, axis=0)
    mid = angles[:-1] + 0.5 * d_ang
    step = solve_symmetric3(*normal_equations(model, mid, d_ang))  # base frame
    pose0 = np.zeros(3) if start is None else np.asarray(start.pose, float)
    theta = np.cumsum(np.concatenate([pose0[2:], step[:, 2]]))
    heading = theta[:-1] + 0.5 * step[:, 2]
    c, s = np.cos(heading), np.sin(heading)
    dx = c * step[:, 0] - s * step[:, 1]
    dy = s * step[:, 0] + c * step[:, 1]
    pose = np.empty((angles.shape[0], 3))
    pose[:, 0] = np.cumsum(np.concatenate([pose0[:1], dx]))
    pose[:, 1] = np.cumsum(np.concatenate([pose0[1:2], dy]))
    pose[:, 2] = theta
    return pose, corr


def odometry(model: PlatformModel, angles: np.ndarray) -> np.ndarray:
    """Base pose (x_b, y_b, θ_b) [m, m, rad] from encoder angles (N, J) in the platform's
    channel order (wrapped pivot angles are unwrapped); (N, 3), zero at sample 0. See
    :func:`odometry_from` to continue from a pose reached earlier."""
    return odometry_from(model, angles)[0]
