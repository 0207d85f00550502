"""Pivot angles and rates predicted along planned motions (thesis eq. 8a).

Kinematics (thesis eq. 8a, written in the base frame): pivot i at r_i = (x_i, y_i) [m] moves with
P_i = (vx − ω y_i, vy + ω x_i) [m/s]; its unit turns towards P_i,

    δ̇_i = |P_i| sin(ψ_i − δ_i) / s_w − ω,        ψ_i = atan2(P_iy, P_ix),

so with the small caster offset s_w [m] the unit trails its pivot (δ_i ≈ ψ_i, stable) and turns
as fast as the direction ψ_i does. A unit flips (δ_i − ψ_i passes ±π/2 on its way to the stable
side) when P_i reverses or passes near zero while turning: the transition from the unstable
"pulling" to the stable "pushing" configuration, which shakes the platform and fits badly (Sec.
VI-A).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ropod_sysid.model.units.swivel import check_all_swivel
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.run_variants import variants
from ropod_sysid.trajectory.setpoints import Trajectory, _fine


def _pivot_velocities(twist: np.ndarray, pivots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pivot point velocities P_i in the base frame for twists (..., 3): (..., n) x and y."""
    vx, vy, w = twist[..., 0:1], twist[..., 1:2], twist[..., 2:3]
    return vx - w * pivots[:, 1], vy + w * pivots[:, 0]


def trailing_pivots(twist: np.ndarray, pivots: np.ndarray) -> np.ndarray:
    """Pivot angles trailing the first motion of a twist series (N, 3): (n,) [rad].

    Same rule as :func:`ropod_sysid.simulate.initial_pivots`: every unit aligned with the
    velocity of its pivot at the first nonzero twist; zero if the series never moves.
    """
    moving = np.flatnonzero(np.abs(twist).sum(axis=1) > 1e-9)
    if moving.size == 0:
        return np.zeros(len(pivots))
    px, py = _pivot_velocities(twist[moving[0]], pivots)
    return np.arctan2(py, px)


@dataclass
class PivotPrediction:
    """Pivot angles and rates predicted along planned motions.

    delta, rate : (V, N, n) [rad], [rad/s] for V twist series of N samples and n units.
    pulling : (V, N, n) True where a moving unit leads its pivot (the unstable configuration:
        the wheel is ahead of the pivot, cos(δ − ψ) < 0 while |P_i| > 1 cm/s).
    """

    delta: np.ndarray
    rate: np.ndarray
    pulling: np.ndarray


def predict_pivots(t: np.ndarray, twists: np.ndarray, platform: Platform,
                   delta0: np.ndarray | None = None) -> PivotPrediction:
    """Integrate the pivot angles along base-frame twists with the kinematic model (eq. 8a).

    Parameters
    ----------
    t : (N,) time [s]
    twists : (N, 3) or (V, N, 3) base-frame twist series (vx, vy [m/s], ω [rad/s])
    platform : pivots r_i [m] and caster offset s_w [m]
    delta0 : (V, n) or (n,) initial pivot angles [rad]; default: trailing the first motion

    The stiff scalar ODE δ̇_i = |P_i| sin(ψ_i − δ_i)/s_w − ω (time constant s_w/|P_i|, 10 ms at
    1 m/s on the ropod) is integrated with the linearly implicit trapezoidal rule, which is
    stable at any step for trailing units, in one loop over time steps vectorised over series and
    units. The rates are those of the model's ``joint_rates`` at the integrated angles.
    """
    tw = np.asarray(twists, float)
    single = tw.ndim == 2
    if single:
        tw = tw[None]
    n_var, n, _ = tw.shape
    check_all_swivel(platform, "the pivot prediction")
    pivots = platform.positions
    k = len(pivots)
    s_w = platform.units[0].caster_offset
    if delta0 is None:
        d = np.stack([trailing_pivots(tw[v], pivots) for v in range(n_var)])
    else:
        d = np.broadcast_to(np.asarray(delta0, float), (n_var, k)).copy()
    px, py = _pivot_velocities(tw, pivots)  # (V, N, n)
    w = np.broadcast_to(tw[..., 2:3], px.shape)
    # time-major contiguous arrays of the flattened (V·n) state
    pxt = np.ascontiguousarray(px.transpose(1, 0, 2).reshape(n, -1)) / s_w
    pyt = np.ascontiguousarray(py.transpose(1, 0, 2).reshape(n, -1)) / s_w
    wt = np.ascontiguousarray(w.transpose(1, 0, 2).reshape(n, -1))
    dts = np.diff(np.asarray(t, float))
    delta = np.empty((n, n_var * k))
    rate = np.empty((n, n_var * k))
    x = d.reshape(-1).copy()
    cos, sin = np.cos, np.sin
    for j in range(n - 1):
        c, s = cos(x), sin(x)
        f0 = c * pyt[j] - s * pxt[j] - wt[j]
        f1 = c * pyt[j + 1] - s * pxt[j + 1] - wt[j + 1]
        jac = -(c * pxt[j + 1] + s * pyt[j + 1])
        h = dts[j]
        delta[j] = x
        rate[j] = f0
        x = x + h * (f0 + f1) / np.maximum(2.0 - h * jac, 1.0)
    c, s = cos(x), sin(x)
    delta[-1] = x
    rate[-1] = c * pyt[-1] - s * pxt[-1] - wt[-1]
    delta = delta.reshape(n, n_var, k).transpose(1, 0, 2)
    rate = rate.reshape(n, n_var, k).transpose(1, 0, 2)
    speed = np.hypot(px, py)
    lead = np.cos(delta) * px + np.sin(delta) * py  # P_i along the unit's e_x
    pulling = (lead < 0) & (speed > 0.01)
    if single:
        return PivotPrediction(delta[0], rate[0], pulling[0])
    return PivotPrediction(delta, rate, pulling)


def _variant_pivots(traj: Trajectory, platform: Platform,
                    ) -> tuple[Trajectory, np.ndarray, PivotPrediction]:
    """The run on the fine grid (the pivot ODE is stiff: :func:`_fine`), the twists (4, N, 3)
    of its four variants there and their predicted pivots."""
    fine = _fine(traj)
    twists = np.stack([vt.twist() for vt in variants(fine).values()])
    return fine, twists, predict_pivots(fine.t, twists, platform)
