"""Pivot angles of smart-wheel (swivel) units along planned base motions (thesis eq. 8a).

The bodies of :meth:`ropod_sysid.model.units.swivel.SwivelUnits.predict_angles` and
:meth:`~ropod_sysid.model.units.swivel.SwivelUnits.quasi_steady_angles` (the trajectory planner,
check and excitation search), kept out of the type's module for its size. Kinematics (eq. 8a,
written in the base frame): pivot i at r_i = (x_i, y_i) [m] moves with
P_i = (vx − ω y_i, vy + ω x_i) [m/s]; its unit turns towards P_i,

    δ̇_i = |P_i| sin(ψ_i − δ_i) / s_w − ω,        ψ_i = atan2(P_iy, P_ix),

so with the small caster offset s_w [m] the unit trails its pivot (δ_i ≈ ψ_i, stable) and turns
as fast as the direction ψ_i does. A unit flips (δ_i − ψ_i passes ±π/2 on its way to the stable
side) when P_i reverses or passes near zero while turning: the transition from the unstable
"pulling" to the stable "pushing" configuration, which shakes the platform and fits badly (Sec.
VI-A).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ropod_sysid.model.units import AnglePrediction, integrated, series, trailing_start, unit_major

PULLING = "pulling (wheel flip)"  # the flag of a unit that leads its pivot


def pivot_velocities(twist: np.ndarray, pivots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pivot point velocities P_i in the base frame for twists (..., 3): (..., k) x and y."""
    vx, vy, w = twist[..., 0:1], twist[..., 1:2], twist[..., 2:3]
    return vx - w * pivots[:, 1], vy + w * pivots[:, 0]


def integrate_pivots(t: np.ndarray, tw: np.ndarray, pivots: np.ndarray, s_w: float,
                     delta0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pivot angles, rates (V, N, k) and ``pulling`` (V, N, k) along twists (V, N, 3) from
    δ(t_0) = ``delta0`` (V, k).

    The stiff scalar ODE δ̇_i = |P_i| sin(ψ_i − δ_i)/s_w − ω (time constant s_w/|P_i|, 10 ms at
    1 m/s on the ropod) is integrated with the linearly implicit trapezoidal rule, which is
    stable at any step for trailing units, in one loop over time steps vectorised over series and
    units. The rates are eq. 8a's at the integrated angles. ``pulling``: a moving unit leads its
    pivot (the wheel ahead of the pivot, cos(δ − ψ) < 0 while |P_i| > 1 cm/s).
    """
    n_var, n, _ = tw.shape
    k = len(pivots)
    px, py = pivot_velocities(tw, pivots)  # (V, N, k)
    w = np.broadcast_to(tw[..., 2:3], px.shape)
    # time-major contiguous arrays of the flattened (V·k) state
    pxt = np.ascontiguousarray(px.transpose(1, 0, 2).reshape(n, -1)) / s_w
    pyt = np.ascontiguousarray(py.transpose(1, 0, 2).reshape(n, -1)) / s_w
    wt = np.ascontiguousarray(w.transpose(1, 0, 2).reshape(n, -1))
    dts = np.diff(np.asarray(t, float))
    delta = np.empty((n, n_var * k))
    rate = np.empty((n, n_var * k))
    x = np.asarray(delta0, float).reshape(-1).copy()
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
    return delta, rate, (lead < 0) & (speed > 0.01)


def quasi_steady(tw: np.ndarray, twd: np.ndarray, pivots: np.ndarray, s_w: float,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quasi-steady pivot angle, rate and sin(lag) (…, N, k) for twists and their rates
    (…, N, 3): every unit trails its pivot velocity P_i with the lag that makes eq. 8a hold,
    sin(ψ_i − δ_i) = s_w (ω + ψ̇_i) / |P_i| — meaningful only while it is well below 1; the rate
    is ψ̇_i = (P_i × Ṗ_i) / |P_i|²."""
    px, py = pivot_velocities(tw, pivots)
    pdx, pdy = pivot_velocities(twd, pivots)
    p2 = px**2 + py**2
    speed = np.sqrt(p2)
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = np.where(p2 > 1e-18, (px * pdy - py * pdx) / p2, 0.0)
        sin_lag = np.where(p2 > 1e-18, s_w * (tw[..., 2:3] + rate)
                           / np.maximum(speed, 1e-12), 0.0)
    lag = np.arcsin(np.clip(sin_lag, -1.0, 1.0))
    return np.arctan2(py, px) - lag, rate, sin_lag


def predict(unit: Any, t: np.ndarray, twists: np.ndarray,
            initial: np.ndarray | None) -> AnglePrediction:
    """:meth:`SwivelUnits.predict_angles` of the group ``unit``: :func:`integrate_pivots` from
    ``initial`` (…, 3k) or the trailing start, wheel angles by :func:`_with_wheels`."""
    tw, lead = series(twists)
    k = unit.n_units
    if initial is None:
        start = trailing_start(unit, tw)
    else:
        start = np.broadcast_to(np.asarray(initial, float).reshape(-1, 3 * k),
                                (tw.shape[0], 3 * k))
    delta, rate, pulling = integrate_pivots(t, tw, unit.pivots, unit.s_w, start[:, 0::3])
    return _with_wheels(unit, t, tw, lead, delta, rate, start, {PULLING: pulling})


def predict_quasi_steady(unit: Any, t: np.ndarray, twists: np.ndarray,
                         twist_rates: np.ndarray) -> AnglePrediction:
    """:meth:`SwivelUnits.quasi_steady_angles` of the group ``unit``: :func:`quasi_steady`,
    wheel angles by :func:`_with_wheels` (from zero), ``lag`` set."""
    tw, lead = series(twists)
    delta, rate, sin_lag = quasi_steady(tw, series(twist_rates)[0], unit.pivots, unit.s_w)
    pred = _with_wheels(unit, t, tw, lead, delta, rate, None, {})
    pred.lag = sin_lag.reshape(*lead, *sin_lag.shape[1:])
    return pred


def _with_wheels(unit: Any, t: np.ndarray, tw: np.ndarray, lead: tuple[int, ...],
                 delta: np.ndarray, rate: np.ndarray, start: np.ndarray | None,
                 flags: dict[str, np.ndarray]) -> AnglePrediction:
    """Angles and rates (…, N, 3k) of pivot angles and rates (V, N, k) along twists
    (V, N, 3): the wheel rates of eq. 11 (base frame: θ = 0; the actuator rates), integrated
    from ``start`` (V, 3k) (None: zero)."""
    n_var, n, k = delta.shape
    wheel = unit.wheel_rates(np.zeros((n_var * n, 3)), tw.reshape(-1, 3),
                             delta.reshape(-1, k)).reshape(n_var, n, 2 * k)
    phi0 = np.zeros((n_var, 2 * k)) if start is None else \
        unit_major(start, 3)[..., 1:].reshape(n_var, 2 * k)
    angles = np.empty((n_var, n, k, 3))
    rates = np.empty((n_var, n, k, 3))
    angles[..., 0], rates[..., 0] = delta, rate
    angles[..., 1:] = integrated(t, wheel, phi0).reshape(n_var, n, k, 2)
    rates[..., 1:] = wheel.reshape(n_var, n, k, 2)
    shape = (*lead, n)
    return AnglePrediction(angles.reshape(*shape, 3 * k), rates.reshape(*shape, 3 * k),
                           wheel.reshape(*shape, 2 * k), rate.reshape(*shape, k),
                           {f: m.reshape(*shape, k) for f, m in flags.items()})
