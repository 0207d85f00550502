"""Excitation trajectories: plan, check and optimise identification runs (thesis Sec. VI-A).

A run is a series of base-twist setpoints in the *base* frame — t [s], vx, vy [m/s], ω [rad/s] —
that the robot's velocity controller tracks; its planned pose x, y [m], θ [rad] in the world
frame follows by integration from zero. The thesis identifies on a "typical" run (straights,
corners, rotations, constant velocity and acceleration) repeated in four variants — original,
mirrored (left and right corners swapped), negated (every translation and rotation with a minus
sign) and mirrored-negated — whose stacked regressors are solved together (Sec. VI-A). It keeps
out the transition of a wheel unit from its unstable "pulling" to its stable "pushing"
configuration, which shakes the platform and fits badly; the disturbance observer ignores the
data when a pivot rate exceeds 1.5 rad/s for the same reason (Sec. VII-C).

Kinematics used throughout (thesis eq. 8a, written in the base frame): pivot i at r_i = (x_i, y_i)
moves with P_i = (vx − ω y_i, vy + ω x_i); its unit turns towards P_i,

    δ̇_i = |P_i| sin(ψ_i − δ_i) / s_w − ω,        ψ_i = atan2(P_iy, P_ix),

so with the small caster offset s_w the unit trails its pivot (δ_i ≈ ψ_i, stable) and turns as
fast as the direction ψ_i does. A unit flips (δ_i − ψ_i passes ±π/2 on its way to the stable
side) when P_i reverses or passes near zero while turning. Limits, as in the thesis's
experiments: |v| = |(vx, vy)| ≤ v_max, |a| ≤ a_max (the world acceleration of the base origin,
centripetal part included), |ω| ≤ ω_max, |ω̇| ≤ α_max, |δ̇_i| ≤ pivot_rate_max.

Contents: :class:`Trajectory` (CSV I/O, setpoints), :func:`typical`, :func:`variants`,
:func:`predict_pivots`, :func:`check` (limits, floor, pivot rates, the predicted stacked
regressor's condition number and rank and each parameter's predicted standard deviation),
:func:`plot` and :func:`optimize` (finite Fourier series, Swevers et al.).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.io.atomic import atomic_write_text
from ropod_sysid.io.csvlog import read_numeric_table
from ropod_sysid.platform import Platform, ropod_platform
from ropod_sysid.simulate import Setpoints

Floor = tuple[float, float, float, float]
DEFAULT_FLOOR: Floor = (-3.0, 3.0, -2.0, 2.0)
COLUMNS = ("t", "vx", "vy", "omega", "x", "y", "theta")
TWIST_COLUMNS = ("t", "vx", "vy", "omega")
POSE_COLUMNS = ("x", "y", "theta")
VARIANTS = ("original", "mirrored", "negated", "mirrored_negated")
# variant → sign of (vx, vy, ω) (Sec. VI-A): mirrored swaps left and right corners
VARIANT_SIGNS: dict[str, tuple[float, float, float]] = {
    "original": (1.0, 1.0, 1.0),
    "mirrored": (1.0, -1.0, -1.0),
    "negated": (-1.0, -1.0, -1.0),
    "mirrored_negated": (-1.0, 1.0, 1.0),
}
TYPICAL_MAX_DURATION = 3600.0  # typical(): the longest run [s] (an hour of driving)
OPTIMIZE_DURATION = (5.0, 600.0)  # optimize(): shortest and longest run [s]
MAX_HARMONICS = 20  # optimize(): most harmonics of each Fourier series
SPIN_START_MIN = 30.0  # typical(): runs this long [s] or longer start with a rotation in place
DESIGN_MARGIN = 0.9  # typical(): every limit is planned at 90 % of its value
PIVOT_DESIGN_MARGIN = 0.8  # … and the pivot rate (quasi-steady) at 80 %


# ---------------------------------------------------------------------------------------------
# limits


@dataclass(frozen=True)
class Limits:
    """Limits of an identification run (defaults: the thesis's experiments, Sec. VI-A, VII-C).

    Attributes
    ----------
    v_max : float
        Speed of the base origin |(vx, vy)| [m/s].
    a_max : float
        Acceleration of the base origin in the world frame, centripetal part included [m/s²].
    w_max : float
        Rotation rate |ω| [rad/s].
    alpha_max : float
        Rotational acceleration |ω̇| [rad/s²].
    pivot_rate_max : float or None
        Pivot rate |δ̇_i| of every unit [rad/s], predicted with the kinematic model; None: no
        limit (wheel flips allowed).
    """

    v_max: float = 1.0
    a_max: float = 1.0
    w_max: float = 1.0
    alpha_max: float = 1.0
    pivot_rate_max: float | None = 1.5

    def __post_init__(self) -> None:
        for name in ("v_max", "a_max", "w_max", "alpha_max", "pivot_rate_max"):
            value = getattr(self, name)
            if value is None and name == "pivot_rate_max":
                continue
            if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
                raise InputError(f"limit {name} must be a positive number, got {value!r}")

    def scaled(self, factor: float, pivot_factor: float | None = None) -> Limits:
        """All limits times ``factor`` (the pivot rate times ``pivot_factor`` if given)."""
        pf = factor if pivot_factor is None else pivot_factor
        return Limits(self.v_max * factor, self.a_max * factor, self.w_max * factor,
                      self.alpha_max * factor,
                      None if self.pivot_rate_max is None else self.pivot_rate_max * pf)


def _check_floor(floor: Sequence[float]) -> Floor:
    if len(floor) != 4:
        raise InputError("floor must be four numbers: x_min x_max y_min y_max [m]")
    x0, x1, y0, y1 = (float(v) for v in floor)
    if not all(math.isfinite(v) for v in (x0, x1, y0, y1)):
        raise InputError("floor bounds must be finite numbers [m]")
    if not (x0 < 0 < x1 and y0 < 0 < y1):
        raise InputError(
            f"floor ({x0:g}, {x1:g}, {y0:g}, {y1:g}) must contain the start pose (0, 0) strictly "
            "inside: give x_min < 0 < x_max and y_min < 0 < y_max")
    return (x0, x1, y0, y1)


# ---------------------------------------------------------------------------------------------
# the trajectory


def integrate_pose(t: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                   omega: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World pose (x, y [m], θ [rad]) from base-frame twist setpoints, starting at zero.

    θ is the trapezoidal integral of ω; the world velocity R(θ)(vx, vy) is integrated the same
    way (second order in the sample interval). Arrays (..., N) over the last axis.
    """
    t = np.asarray(t, float)
    dt = np.diff(t)

    def cumtrapz(f: np.ndarray) -> np.ndarray:
        out = np.zeros_like(f)
        out[..., 1:] = np.cumsum(0.5 * (f[..., 1:] + f[..., :-1]) * dt, axis=-1)
        return out

    theta = cumtrapz(np.asarray(omega, float))
    c, s = np.cos(theta), np.sin(theta)
    x = cumtrapz(c * vx - s * vy)
    y = cumtrapz(s * vx + c * vy)
    return x, y, theta


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Base-twist setpoints and the planned pose of one run.

    Attributes
    ----------
    t : (N,) time [s], strictly increasing
    vx, vy : (N,) base velocity in the base frame [m/s]
    omega : (N,) rotation rate [rad/s]
    x, y : (N,) planned position of the base origin in the world frame [m], zero at t[0]
    theta : (N,) planned heading [rad], zero at t[0]
    """

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    omega: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray

    @classmethod
    def from_twist(cls, t: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                   omega: np.ndarray) -> Trajectory:
        """A trajectory whose pose is integrated from the twist (:func:`integrate_pose`)."""
        t, vx, vy, omega = (np.asarray(a, float).copy() for a in (t, vx, vy, omega))
        x, y, theta = integrate_pose(t, vx, vy, omega)
        return cls(t, vx, vy, omega, x, y, theta)

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def twist(self) -> np.ndarray:
        """(N, 3) base-frame twist (vx, vy, ω)."""
        return np.stack([self.vx, self.vy, self.omega], axis=-1)

    def to_setpoints(self) -> Setpoints:
        """The setpoints the simulator and the robot's velocity controller take."""
        return Setpoints(self.t - self.t[0], self.vx.copy(), self.vy.copy(), self.omega.copy())

    def twist_rates(self) -> np.ndarray:
        """(N, 3) time derivative of the twist (v̇x, v̇y, ω̇) by second-order differences."""
        if self.n_samples < 3:
            return np.zeros((self.n_samples, 3))
        return np.stack([np.gradient(v, self.t, edge_order=2)
                         for v in (self.vx, self.vy, self.omega)], axis=-1)

    def kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World-frame q, q̇, q̈ (N, 3) of the planned motion (thesis notation q_b^0).

        q̇ = (R(θ)(vx, vy), ω), q̈ = (R(θ)(v̇ + ω S v), ω̇) with S the 90° turn.
        """
        rates = self.twist_rates()
        c, s = np.cos(self.theta), np.sin(self.theta)
        ax = rates[:, 0] - self.omega * self.vy
        ay = rates[:, 1] + self.omega * self.vx
        q = np.stack([self.x, self.y, self.theta], axis=-1)
        qd = np.stack([c * self.vx - s * self.vy, s * self.vx + c * self.vy, self.omega], -1)
        qdd = np.stack([c * ax - s * ay, s * ax + c * ay, rates[:, 2]], axis=-1)
        return q, qd, qdd

    def speed(self) -> np.ndarray:
        """|(vx, vy)| [m/s]."""
        return np.hypot(self.vx, self.vy)

    def acceleration(self) -> np.ndarray:
        """|world acceleration of the base origin| = |v̇ + ω S v| [m/s²]."""
        rates = self.twist_rates()
        return np.hypot(rates[:, 0] - self.omega * self.vy, rates[:, 1] + self.omega * self.vx)

    def write_csv(self, path: str | Path) -> None:
        """Write ``t, vx, vy, omega, x, y, theta`` (header first, %.17g) atomically."""
        atomic_write_text(path, trajectory_csv_text(self))


def trajectory_csv_text(traj: Trajectory) -> str:
    """The CSV text of a trajectory (exact floats, ``\\n`` line ends)."""
    data = np.column_stack([traj.t, traj.vx, traj.vy, traj.omega, traj.x, traj.y, traj.theta])
    lines = [",".join(COLUMNS)]
    lines += [",".join(f"{v:.17g}" for v in row) for row in data.tolist()]
    return "\n".join(lines) + "\n"


def write_trajectory_csv(traj: Trajectory, path: str | Path) -> None:
    """Write a trajectory CSV atomically (see :meth:`Trajectory.write_csv`)."""
    traj.write_csv(path)


def read_trajectory_csv(path: str | Path) -> Trajectory:
    """Read a setpoint CSV: ``t, vx, vy, omega`` required, ``x, y, theta`` optional.

    Without the pose columns the pose is integrated from the twist. Extra columns are ignored.
    Every problem raises :class:`InputError` with one line naming the file, line and column
    (the checks of the log reader, :func:`ropod_sysid.io.csvlog.read_numeric_table`).
    """
    cols = read_numeric_table(path, list(TWIST_COLUMNS), optional=POSE_COLUMNS)
    if "x" in cols:
        return Trajectory(*(cols[c] for c in COLUMNS))
    return Trajectory.from_twist(*(cols[c] for c in TWIST_COLUMNS))


# ---------------------------------------------------------------------------------------------
# variants


def variant(traj: Trajectory, name: str) -> Trajectory:
    """One of the four variants of Sec. VI-A (see :data:`VARIANT_SIGNS`); pose re-integrated."""
    if name not in VARIANT_SIGNS:
        raise InputError(f"unknown variant {name!r}; known: {', '.join(VARIANTS)}")
    if name == "original":
        return traj
    sx, sy, sw = VARIANT_SIGNS[name]
    return Trajectory.from_twist(traj.t, sx * traj.vx, sy * traj.vy, sw * traj.omega)


def variants(traj: Trajectory) -> dict[str, Trajectory]:
    """The four variants of the thesis (Sec. VI-A): 'original', 'mirrored' (vy → −vy,
    ω → −ω: left and right corners swapped), 'negated' (vx, vy, ω all negated) and
    'mirrored_negated'. Poses are integrated from each variant's twist."""
    return {name: variant(traj, name) for name in VARIANTS}


# ---------------------------------------------------------------------------------------------
# pivot prediction (eq. 8a)


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
    pivots = platform.pivots
    k = len(pivots)
    s_w = platform.caster_offset
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


# ---------------------------------------------------------------------------------------------
# the typical run (Sec. VI-A)


def _quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk blend s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and its first two derivatives in τ."""
    tau = np.clip(tau, 0.0, 1.0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds


_TAU = np.linspace(0.0, 1.0, 257)
_S, _DS, _DDS = _quintic(_TAU)


class PlanningError(InputError):
    """A typical run cannot be planned within the limits (one line, CLI exit 2)."""


def _blend_time(a: np.ndarray, b: np.ndarray, caps: Limits, pivots: np.ndarray | None,
                t_min: float = 0.4) -> float:
    """Shortest duration [s] of a minimum-jerk blend of the twist from level a to level b.

    During the blend the twist is a + (b − a) s(τ): continuous acceleration, zero at both ends.
    The duration meets the rotational acceleration cap, the world acceleration cap (with the
    centripetal part ω S v, which does not shrink with a longer blend) and, with pivots, the
    quasi-steady pivot rate ψ̇_i = cross(P_i, Ṗ_i)/|P_i|² of every unit.
    """
    d = b - a
    t_req = t_min
    if d[2] != 0.0:
        t_req = max(t_req, abs(d[2]) * _DS.max() / caps.alpha_max)
    lev = a + np.outer(_S, d)
    u, w = lev[:, :2], lev[:, 2]
    c = w[:, None] * np.stack([-u[:, 1], u[:, 0]], axis=1)
    g = d[:2][None, :] * _DS[:, None]
    gg = (g * g).sum(1)
    gc = (g * c).sum(1)
    cc = (c * c).sum(1)
    a2 = caps.a_max**2
    if np.any(cc > a2 * (1 + 1e-9)):
        raise PlanningError("planned corner exceeds the acceleration limit")
    m = gg > 1e-24
    if np.any(m):
        x_hi = (-gc[m] + np.sqrt(np.maximum(gc[m] ** 2 - gg[m] * (cc[m] - a2), 0.0))) / gg[m]
        t_req = max(t_req, 1.0 / max(float(x_hi.min()), 1e-12))
    if pivots is not None and caps.pivot_rate_max is not None:
        sp = np.stack([-pivots[:, 1], pivots[:, 0]], axis=1)  # S r_i
        pa = a[:2][None, :] + a[2] * sp  # (n, 2) P_i at the start
        dp = d[:2][None, :] + d[2] * sp
        cross = pa[:, 0] * dp[:, 1] - pa[:, 1] * dp[:, 0]  # constant along a linear blend
        p = pa[None] + _S[:, None, None] * dp[None]
        p2 = (p * p).sum(-1)
        scale = np.linalg.norm(pa, axis=1) * np.linalg.norm(dp, axis=1) + 1e-300
        turning = np.abs(cross) > 1e-9 * scale
        # a pivot velocity that passes through zero inside the blend reverses: the unit flips
        dp2 = (dp * dp).sum(1)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_zero = np.where(dp2 > 0, -(pa * dp).sum(1) / dp2, -1.0)
        through = (~turning) & (s_zero > 1e-9) & (s_zero < 1 - 1e-9)
        if np.any(through):
            raise PlanningError("a planned blend reverses a pivot velocity (wheel flip)")
        if np.any(turning):
            with np.errstate(divide="ignore"):
                rate = np.abs(cross[turning])[None] / p2[:, turning] * _DS[:, None]
            t_req = max(t_req, float(rate.max()) / caps.pivot_rate_max)
    if not math.isfinite(t_req):
        raise PlanningError("a planned blend needs an infinite time (pivot velocity near zero)")
    return float(t_req)


class _Plan:
    """A twist program: minimum-jerk blends between constant levels and holds of a level.

    Segments are [a, b, T]: the twist goes from level a to level b over T seconds (a hold when
    a == b). The heading change of a segment is exact: T (ω_a + ω_b)/2.
    """

    def __init__(self, caps: Limits, pivots: np.ndarray | None, theta0: float = 0.0) -> None:
        self.caps = caps
        self.pivots = pivots
        self.segs: list[list] = []
        self.level = np.zeros(3)
        self.theta = theta0
        self._cache: dict[tuple[float, ...], float] = {}

    def blend_time(self, a: np.ndarray, b: np.ndarray) -> float:
        key = tuple(np.round(np.concatenate([a, b]), 12))
        if key not in self._cache:
            self._cache[key] = _blend_time(a, b, self.caps, self.pivots)
        return self._cache[key]

    def to(self, b: Sequence[float], t: float | None = None) -> float:
        b = np.asarray(b, float)
        t = self.blend_time(self.level, b) if t is None else t
        self.segs.append([self.level, b, t])
        self.theta += t * (self.level[2] + b[2]) / 2
        self.level = b
        return t

    def hold(self, h: float) -> int:
        self.segs.append([self.level, self.level, max(float(h), 0.0)])
        self.theta += max(h, 0.0) * self.level[2]
        return len(self.segs) - 1

    @property
    def duration(self) -> float:
        return float(sum(s[2] for s in self.segs))

    # -- maneuvers (from a translation level, back to it)
    def corner(self, dtheta: float, w: float) -> None:
        """Turn the heading by ``dtheta`` [rad] exactly in a corner at rate ≤ w [rad/s]."""
        u = self.level
        sgn = 1.0 if dtheta >= 0 else -1.0
        for _ in range(60):
            lev = u + np.array([0.0, 0.0, sgn * w])
            t1, t2 = self.blend_time(u, lev), self.blend_time(lev, u)
            h = (abs(dtheta) - w * (t1 + t2) / 2) / w
            if h >= 0:
                break
            w *= 0.9
        else:  # pragma: no cover - only for tiny angles
            raise PlanningError("cannot plan a corner this small")
        self.to(lev, t1)
        self.hold(h)
        self.to(u, t2)

    def spin_corner(self, dtheta: float, v_slow: float, w: float) -> None:
        """A corner of ``dtheta`` plus at least one whole rotation in place: slow down, turn
        into a tight arc, stop translating while rotating, hold, and back (same direction)."""
        u = self.level
        sgn = 1.0 if dtheta >= 0 else -1.0
        slow = u * (v_slow / np.linalg.norm(u[:2]))
        arc = slow + np.array([0.0, 0.0, sgn * w])
        rot = np.array([0.0, 0.0, sgn * w])
        t_arc = self.blend_time(slow, arc)
        t_rot = self.blend_time(arc, rot)
        turned = w * (t_arc + 2 * t_rot)  # heading of the four rotating blends
        target = abs(dtheta) + 2 * math.pi
        while target < turned:
            target += 2 * math.pi
        self.to(slow)
        self.to(arc, t_arc)
        self.to(rot, t_rot)
        self.hold((target - turned) / w)
        self.to(arc, t_rot)
        self.to(slow, t_arc)
        self.to(u)

    def stop_and_go(self, pause: float) -> None:
        """Decelerate to rest, wait, accelerate again in the same direction."""
        u = self.level
        self.to(np.zeros(3))
        self.hold(pause)
        self.to(u)


def _sample(segs: Sequence[Sequence], t: np.ndarray) -> np.ndarray:
    """The twist (N, 3) of a program at times t (zero after its end)."""
    durs = np.array([s[2] for s in segs])
    ends = np.cumsum(durs)
    starts = ends - durs
    idx = np.searchsorted(ends, t, side="right")
    out = np.zeros((len(t), 3))
    for j in np.unique(idx):
        if j >= len(segs) or durs[j] <= 0:
            continue
        a, b, dur = segs[j]
        m = idx == j
        s, _, _ = _quintic((t[m] - starts[j]) / dur)
        out[m] = a + np.outer(s, b - a)
    return out


def _path(segs: Sequence[Sequence], theta0: float, p0: np.ndarray, dt: float,
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sampled twist, world position (N, 2) and heading (N,) of a program from (p0, θ0)."""
    total = float(sum(s[2] for s in segs))
    n = max(int(math.ceil(total / dt)), 1) + 1
    t = np.linspace(0.0, total, n)
    tw = _sample(segs, t)
    x, y, th = integrate_pose(t, tw[:, 0], tw[:, 1], tw[:, 2])
    c, s = math.cos(theta0), math.sin(theta0)
    pos = np.stack([c * x - s * y, s * x + c * y], axis=-1) + p0
    return tw, pos, th + theta0


@dataclass
class _Design:
    """Speeds and rates of a typical run."""

    v: float  # cruise speed on the long straights [m/s]
    v_corner: float  # speed in corners and on the short sides [m/s]
    v_spin: float  # speed at which a rotation in place is entered [m/s]
    w_corner: float  # corner rate [rad/s]
    w_spin: float  # rotation rate in place [rad/s]
    pause: float  # rest in a stop-and-go [s]


# lobe kinds of the typical run, in order: corners with a rotation in place, crab (lateral)
LOBES: tuple[tuple[str, bool], ...] = (("drive", False), ("crab", True), ("drive", True),
                                       ("crab", False))


def _lobe(plan: _Plan, kind: str, size: tuple[float, float], design: _Design, mirror: bool,
          first: bool) -> list[list[int]]:
    """One lobe of the run: a loop from the start back to it, at cruise speed along +x there.

    ``drive``: a rounded rectangle with four corners (left ones, right ones when mirrored), the
    first with a whole rotation in place. ``crab``: the same loop at constant heading — the
    short sides driven sideways (vy), the long side backwards with a stop-and-go — turning the
    direction of travel in the base frame instead of the heading. ``size`` = (e, c): length of
    the half straights through the start and of the second short side [m]. Returns groups of
    hold indices to solve for closure (x, then y).
    """
    sgn = -1.0 if mirror else 1.0
    cruise = np.array([design.v, 0.0, 0.0])
    slow = np.array([design.v_corner, 0.0, 0.0])
    e, c = size
    if first:
        plan.to(cruise)
    plan.hold(e / design.v)
    plan.to(slow)
    if kind == "drive":
        plan.corner(sgn * math.pi / 2, design.w_corner)
        k_y = plan.hold(0.0)
        plan.corner(sgn * math.pi / 2, design.w_corner)
        plan.to(cruise)
        k_x = plan.hold(0.0)
        plan.to(slow)
        plan.corner(sgn * math.pi / 2, design.w_corner)
        plan.hold(c / design.v_corner)
        plan.corner(sgn * math.pi / 2, design.w_corner)
        groups = [[k_x], [k_y]]
    else:
        side = np.array([0.0, sgn * design.v_corner, 0.0])
        plan.to(side)
        k_y = plan.hold(0.0)
        plan.to(-slow)
        plan.to(-cruise)
        k_x1 = plan.hold(0.0)
        plan.stop_and_go(design.pause)
        k_x2 = plan.hold(0.0)
        plan.to(-slow)
        plan.to(-side)
        plan.hold(c / design.v_corner)
        plan.to(slow)
        groups = [[k_x1, k_x2], [k_y]]
    plan.to(cruise)
    plan.hold(e / design.v)
    return groups


def _close(plan: _Plan, first: int, groups: Sequence[Sequence[int]], theta0: float,
           p0: np.ndarray, target: np.ndarray) -> bool:
    """Lengthen the holds of ``groups`` so that the segments from ``first`` end at ``target``.

    A hold of a pure translation (ω = 0) at heading θ moves the base by h R(θ) u: the end point
    is affine in the hold times, so two groups of holds in independent directions close the
    loop exactly. Returns False if a hold would have to be negative.
    """
    _, pos, _ = _path(plan.segs[first:], theta0, p0, 0.005)
    heading = theta0
    dirs = {}
    for j, (a, b, dur) in enumerate(plan.segs[first:], start=first):
        c, s = math.cos(heading), math.sin(heading)
        dirs[j] = np.array([c * a[0] - s * a[1], s * a[0] + c * a[1]])
        heading += dur * (a[2] + b[2]) / 2
    mat = np.stack([sum(dirs[j] for j in g) for g in groups], axis=1)
    try:
        h = np.linalg.solve(mat, target - pos[-1])
    except np.linalg.LinAlgError:
        return False
    if np.any(h < -1e-9):
        return False
    for g, hj in zip(groups, h, strict=True):
        for j in g:
            plan.segs[j][2] += float(max(hj, 0.0))
    return True


def _lobe_plan(kind: str, size: tuple[float, float], design: _Design, caps: Limits,
               pivots: np.ndarray | None, mirror: bool = False) -> _Plan | None:
    plan = _Plan(caps, pivots)
    plan.level = np.array([design.v, 0.0, 0.0])
    groups = _lobe(plan, kind, size, design, mirror, first=False)
    if not _close(plan, 0, groups, 0.0, np.zeros(2), np.zeros(2)):
        return None
    return plan


def _fits(plan: _Plan | None, half: tuple[float, float]) -> bool:
    """Does a lobe stay within |x| ≤ W, |y| ≤ H? Its variants are reflections of it (a drive
    lobe has vy = 0, a crab lobe ω = 0), so they stay inside too."""
    if plan is None:
        return False
    _, pos, _ = _path(plan.segs, 0.0, np.zeros(2), 0.02)
    return bool(np.abs(pos[:, 0]).max() <= half[0] and np.abs(pos[:, 1]).max() <= half[1])


def _bisect(ok: Callable[[float], bool], lo: float, hi: float, steps: int = 10) -> float | None:
    """Largest value in [lo, hi] for which ``ok`` holds (assumed monotone), None if not at lo."""
    if not ok(lo):
        return None
    if ok(hi):
        return hi
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def _fit_lobe(kind: str, design: _Design, caps: Limits, pivots: np.ndarray | None,
              half: tuple[float, float]) -> tuple[float, float] | None:
    """Sizes (e, c) [m] of the largest lobe of ``kind`` inside |x| ≤ W, |y| ≤ H."""
    lo = None
    for e0 in np.arange(0.0, 2 * half[0], 0.25):
        if _fits(_lobe_plan(kind, (float(e0), 0.0), design, caps, pivots), half):
            lo = float(e0)
            break
    if lo is None:
        return None
    e = _bisect(lambda e: _fits(_lobe_plan(kind, (e, 0.0), design, caps, pivots), half),
                lo, 2 * half[0], steps=8)
    assert e is not None
    c = _bisect(lambda c: _fits(_lobe_plan(kind, (e, c), design, caps, pivots), half),
                0.0, 2 * half[1], steps=8)
    return (e, c if c is not None else 0.0)


def _start_spin(plan: _Plan, design: _Design) -> None:
    """Start: a whole clockwise rotation in place from rest (units set tangentially, as they
    trail a rotation), then away along +x through a tight right arc, at cruise speed; heading
    back to 0 (mod 2π). Clockwise, so that the original run turns both ways early on."""
    rot = np.array([0.0, 0.0, -design.w_spin])
    arc = np.array([design.v_spin, 0.0, -design.w_spin])
    slow = np.array([design.v_spin, 0.0, 0.0])
    t_rot = plan.blend_time(np.zeros(3), rot)
    t_arc = plan.blend_time(rot, arc)
    t_slow = plan.blend_time(arc, slow)
    turned = design.w_spin * (t_rot / 2 + t_arc + t_slow / 2)
    target = 2 * math.pi
    while target < turned:
        target += 2 * math.pi
    plan.to(rot, t_rot)
    plan.hold((target - turned) / design.w_spin)
    plan.to(arc, t_arc)
    plan.to(slow, t_slow)
    plan.to(np.array([design.v, 0.0, 0.0]))
    plan.theta = 0.0  # a whole number of turns: the world heading is back to +x


def _typical_program(duration: float, caps: Limits, floor: Floor, pivots: np.ndarray | None,
                     design: _Design, order: Sequence[tuple[str, bool]],
                     shrink: float) -> list[list]:
    """The program of a typical run (see :func:`typical`), exactly ``duration`` long."""
    half = (shrink * min(floor[1], -floor[0]), shrink * min(floor[3], -floor[2]))
    sizes = {kind: _fit_lobe(kind, design, caps, pivots, half) for kind in {k for k, _ in order}}
    if any(v is None for v in sizes.values()):
        raise PlanningError("the floor is too small for a typical run at these limits")

    plan = _Plan(caps, pivots)
    spin_start = duration >= SPIN_START_MIN
    if spin_start:
        _start_spin(plan, design)
    lobe = 0
    while plan.duration < duration + 10.0:
        kind, mirror = order[lobe % len(order)]
        first = len(plan.segs)
        size = sizes[kind]
        if lobe == 0:  # the start moved the base along +x already: shorten the first straight
            if spin_start:
                p0 = _path(plan.segs, 0.0, np.zeros(2), 0.005)[1][-1]
                advance = float(p0[0])
            else:
                p0 = np.zeros(2)
                advance = 0.5 * design.v * plan.blend_time(np.zeros(3), np.array([design.v, 0, 0]))
            size = (max(size[0] - advance, 0.0), size[1])
        else:
            p0 = np.zeros(2)
        groups = _lobe(plan, kind, size, design, mirror, first=lobe == 0 and not spin_start)
        if not _close(plan, first, groups, 0.0, p0, np.zeros(2)):
            raise PlanningError("the floor is too small for a typical run at these limits")
        lobe += 1

    # stop on the last straight (a translation hold) that leaves time to decelerate
    starts = np.cumsum([0.0] + [s[2] for s in plan.segs])
    for j in range(len(plan.segs) - 1, -1, -1):
        a, b, dur = plan.segs[j]
        if not (np.array_equal(a, b) and a[2] == 0.0 and np.linalg.norm(a[:2]) > 0):
            continue
        t_stop = plan.blend_time(a, np.zeros(3))
        if starts[j] + t_stop <= duration and (dur > 0 or starts[j] + t_stop > duration - 1.0):
            break
    else:
        need = min(starts[j] + plan.blend_time(a, np.zeros(3))
                   for j, (a, b, _) in enumerate(plan.segs)
                   if np.array_equal(a, b) and a[2] == 0.0 and np.linalg.norm(a[:2]) > 0)
        raise PlanningError(f"duration {duration:g} s is too short for a typical run at these "
                            f"limits; give at least {math.ceil(need * 10) / 10:g} s")
    segs = [list(s) for s in plan.segs[:j + 1]]
    segs[j][2] = min(dur, duration - t_stop - starts[j])
    segs.append([a, np.zeros(3), t_stop])
    total = sum(s[2] for s in segs)
    k = duration / total  # ≥ 1: stretch time (speeds / k, accelerations / k²; same path)
    return [[sa / k, sb / k, sd * k] for sa, sb, sd in segs]


def _heading(segs: Sequence[Sequence]) -> float:
    """Exact heading change of a list of segments [rad]."""
    return float(sum(d * (a[2] + b[2]) / 2 for a, b, d in segs))


def typical(duration: float = 60.0, v_max: float = 1.0, a_max: float = 1.0,
            w_max: float = 1.0, alpha_max: float = 1.0, floor: Sequence[float] = DEFAULT_FLOOR,
            dt: float = 0.005, seed: int = 0, pivot_rate_max: float | None = 1.5,
            platform: Platform | None = None) -> Trajectory:
    """A "typical" identification run (thesis Sec. VI-A), from rest to rest.

    The run is a chain of loops ("lobes") through the start, each leaving and reaching it along
    +x at cruise speed: the lobes of the upper half of the floor turn left, the mirrored ones of
    the lower half turn right. Lobe kinds, in turn:

    * drive — straights at cruise speed (constant-velocity phases), slowing down into the four
      corners (acceleration phases); the first corner includes a whole rotation in place;
    * crab — the same loop at constant heading (the ropod is holonomic): the short sides driven
      sideways (vy), the long side backwards with a stop-and-go.

    Runs of 30 s or more start with a whole clockwise rotation in place and a right arc. A 60 s
    run holds the start, a left drive lobe and most of a crab lobe; the right corners of the
    drive lobes follow in longer runs — and in the mirrored variant, which swaps them.

    The order is drive-left, drive-right, crab, crab-mirrored, and again. Every change of the
    twist is a minimum-jerk blend (10τ³ − 15τ⁴ + 6τ⁵) between constant levels, so the
    acceleration is continuous (jumps in it bias the identification); each blend is as short as
    the limits allow at 90 % of their value (pivot rates: 80 %, quasi-steady). The lobes are
    sized to the floor and closed exactly by solving for the length of two straights.

    Wheel flips (Sec. VI-A) are planned out: no blend reverses the velocity of a pivot, a stop is
    followed by motion in the same direction, and the direction of every pivot velocity turns no
    faster than the pivot-rate limit. The pivot rates predicted by integration
    (:func:`predict_pivots`) are then checked for all four variants, and so is the floor.

    Parameters
    ----------
    duration : length of the run [s] (≥ about 10 s); the program is cut on a straight, ends with
        a stop and is stretched in time (slower, same path) to last exactly this long.
    v_max, a_max, w_max, alpha_max : limits [m/s, m/s², rad/s, rad/s²] (see :class:`Limits`)
    floor : (x_min, x_max, y_min, y_max) [m], the rectangle the base origin must stay in, in
        the world frame of the planned pose (start at the origin, heading +x). Default: 6 m × 4 m
        centred on the start. The run uses the largest rectangle centred on the start inside it;
        shrink the floor by the robot's half size yourself.
    dt : sample interval of the setpoints [s]
    seed : 0 for the reference run; other seeds vary the speeds (±10 %) and the lobe order,
        repeatably.
    pivot_rate_max : pivot-rate limit [rad/s] (Sec. VII-C: 1.5); None to not plan for it
    platform : geometry for the pivot rates; default the ropod (:func:`ropod_platform`)

    Returns
    -------
    Trajectory
        Setpoints at ``dt`` and the planned pose.
    """
    limits = Limits(v_max, a_max, w_max, alpha_max, pivot_rate_max)
    floor = _check_floor(floor)
    if not (isinstance(duration, int | float) and 0 < duration <= TYPICAL_MAX_DURATION):
        raise InputError(f"duration must be a number of seconds in (0, "
                         f"{TYPICAL_MAX_DURATION:g}], got {duration!r}")
    if not (isinstance(dt, int | float) and 0 < dt <= 0.1):
        raise InputError(f"dt must be in (0, 0.1] s, got {dt!r}")
    if platform is None:
        platform = ropod_platform()
    pivots = platform.pivots if pivot_rate_max is not None else None
    rng = np.random.default_rng(seed)
    jitter = 1.0 if seed == 0 else float(rng.uniform(0.9, 1.1))
    order = list(LOBES)
    if seed != 0:
        order = [order[i] for i in rng.permutation(len(order))]
        k = next(i for i, (kind, _) in enumerate(order) if kind == "drive")
        order = order[k:] + order[:k]  # a drive lobe first: it absorbs the start's offset
    pivot_margin = PIVOT_DESIGN_MARGIN
    shrink = 0.97
    speed = 1.0
    last_error = ""
    for _attempt in range(10):
        caps = limits.scaled(DESIGN_MARGIN, pivot_margin)
        v = min(0.8 * jitter, 0.85) * v_max * speed
        v_corner = min(0.4 * v_max * jitter, 0.9 * caps.a_max / (0.9 * caps.w_max)) * speed
        design = _Design(
            v=v, v_corner=v_corner, v_spin=0.2 * v_max * speed,
            w_corner=min(0.9 * caps.w_max, 0.9 * caps.a_max / v_corner),
            w_spin=0.9 * caps.w_max, pause=1.0)
        try:
            segs = _typical_program(duration, caps, floor, pivots, design, order, shrink)
        except PlanningError as exc:
            if "duration" in str(exc):
                raise
            speed *= 0.85  # smaller corners
            last_error = str(exc)
            continue
        n = int(round(duration / dt))
        t = np.arange(n + 1) * dt
        if t[-1] < duration - 1e-9:
            t = np.append(t, duration)
        tw = _sample(segs, t)
        traj = Trajectory.from_twist(t, tw[:, 0], tw[:, 1], tw[:, 2])
        var = variants(traj)
        if any(vt.x.min() < floor[0] or vt.x.max() > floor[1] or vt.y.min() < floor[2]
               or vt.y.max() > floor[3] for vt in var.values()):
            shrink *= 0.93
            last_error = "the planned run leaves the floor"
            continue
        if pivot_rate_max is not None:
            pred = predict_pivots(traj.t, np.stack([vt.twist() for vt in var.values()]),
                                  platform)
            peak = float(np.abs(pred.rate).max())
            if peak > pivot_rate_max * 0.95 or pred.pulling.any():
                pivot_margin *= 0.8
                last_error = f"predicted pivot rate {peak:.2f} rad/s exceeds the limit"
                continue
        return traj
    raise PlanningError(f"cannot plan a typical run within the limits: {last_error}; relax "
                        "the limits, enlarge the floor or use no pivot-rate limit")


# ---------------------------------------------------------------------------------------------
# the predicted regressor (eqs. 35, 36, 66) along planned motions


def _world_motion(t: np.ndarray, twist: np.ndarray, rates: np.ndarray | None = None,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-frame q, q̇, q̈ (..., N, 3) of base-frame twists (..., N, 3) starting at zero.

    ``rates`` are the twist derivatives (second-order differences if not given).
    """
    if rates is None:
        rates = np.gradient(twist, t, axis=-2, edge_order=2)
    x, y, th = integrate_pose(t, twist[..., 0], twist[..., 1], twist[..., 2])
    c, s = np.cos(th), np.sin(th)
    vx, vy, w = twist[..., 0], twist[..., 1], twist[..., 2]
    ax = rates[..., 0] - w * vy
    ay = rates[..., 1] + w * vx
    q = np.stack([x, y, th], axis=-1)
    qd = np.stack([c * vx - s * vy, s * vx + c * vy, w], axis=-1)
    qdd = np.stack([c * ax - s * ay, s * ax + c * ay, rates[..., 2]], axis=-1)
    return q, qd, qdd


def _regressor_rows(model: object, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                    delta: np.ndarray, friction: str, chunk: int = 20000) -> np.ndarray:
    """A_ID,ext (M, 3, p) at M samples (chunked to bound the memory)."""
    out = []
    for k in range(0, q.shape[0], chunk):
        sl = slice(k, k + chunk)
        st = model.state(q[sl], qd[sl], delta[sl])  # type: ignore[attr-defined]
        out.append(model.a_id_ext(st, qdd[sl], friction))  # type: ignore[attr-defined]
    return np.concatenate(out, axis=0)


@dataclass
class Conditioning:
    """Column-scaled singular values of a stacked regressor and what they say.

    singular_values : descending, of A with every column scaled to unit norm (as
        :func:`ropod_sysid.solve.solve` does)
    rank : number of singular values above ``1e-9 σ_max`` (the identifiable subspace)
    condition_number : σ_max / σ_rank — on the identifiable subspace
    condition_number_full : σ_max / σ_min over all columns (inf when rank deficient)
    """

    singular_values: np.ndarray
    rank: int
    condition_number: float
    condition_number_full: float


RANK_TOL = 1e-9


def conditioning(a: np.ndarray) -> Conditioning:
    """:class:`Conditioning` of a stacked regressor (M, p) (or (…, 3, p) rows)."""
    a = a.reshape(-1, a.shape[-1])
    norms = np.linalg.norm(a, axis=0)
    sv = np.linalg.svd(a / np.where(norms > 0, norms, 1.0), compute_uv=False)
    if sv.size == 0 or sv[0] == 0:
        return Conditioning(sv, 0, math.inf, math.inf)
    rank = int(np.sum(sv > RANK_TOL * sv[0]))
    full = float(sv[0] / sv[-1]) if rank == sv.size else math.inf
    return Conditioning(sv, rank, float(sv[0] / sv[rank - 1]), full)


def predicted_std(a: np.ndarray, noise: float | tuple[float, float] = 1.0,
                  rows_per_second: float = 1.0, tol: float = RANK_TOL) -> np.ndarray:
    """Predicted standard deviation of each parameter (p,) of a least-squares fit.

    Parameters
    ----------
    a : (M, 3, p) regressor rows sampled at ``rows_per_second`` samples per second of run
    noise : σ of b_ID, white: one value for every row, or (translation [N], rotation [N m])
    rows_per_second : the log samples each evaluated sample stands for: the information of a
        log at rate r_log evaluated at rate r_eval is r_log / r_eval times that of the rows

    Returns σ·sqrt(diag((AᵀWA)⁺)) with W = diag(1/σ²); parameters the data determine only in
    combination with others (outside the identifiable subspace) get inf.
    """
    sig = (noise, noise) if isinstance(noise, int | float) else noise
    w = np.array([1.0 / sig[0], 1.0 / sig[0], 1.0 / sig[1]])
    aw = (a * w[None, :, None]).reshape(-1, a.shape[-1]) * math.sqrt(rows_per_second)
    norms = np.linalg.norm(aw, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    _, sv, vt = np.linalg.svd(aw / scale, full_matrices=False)
    if sv.size == 0 or sv[0] == 0:
        return np.full(a.shape[-1], math.inf)
    r = int(np.sum(sv > tol * sv[0]))
    vr = vt[:r].T  # (p, r)
    cov_diag = ((vr / sv[:r]) ** 2).sum(axis=1) / scale**2
    # a unit vector e_j is identifiable when it lies in the row space span(vr)
    inside = np.linalg.norm(vr, axis=1) > 1 - 1e-6
    return np.where(inside & (norms > 0), np.sqrt(cov_diag), math.inf)


# ---------------------------------------------------------------------------------------------
# check


@dataclass
class Finding:
    """A limit, floor or pivot finding: what, where (time range [s], variant) and how much."""

    what: str
    limit: float
    peak: float
    t_start: float
    t_end: float
    variant: str = "all"

    def text(self) -> str:
        return (f"{self.what}: {self.peak:.3g} > {self.limit:.3g} from t={self.t_start:.2f} s "
                f"to {self.t_end:.2f} s ({self.variant})")


def _runs(mask: np.ndarray, t: np.ndarray, values: np.ndarray, what: str, limit: float,
          variant: str) -> list[Finding]:
    """Contiguous runs of ``mask`` as findings (peak of ``values`` in each)."""
    out = []
    if not np.any(mask):
        return out
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        out.append(Finding(what, limit, float(np.max(values[a:b])), float(t[a]),
                           float(t[b - 1]), variant))
    return out


@dataclass
class CheckReport:
    """Everything :func:`check` found out about a planned run.

    Attributes
    ----------
    duration, samples : of the run
    limits, floor : what it was checked against
    peaks : name → maximum over the four variants of |v|, |a|, |ω|, |ω̇| and the pivot rate
    findings : limits broken (with time range and variant), floor left, wheel flips
    pivot_peak : (4, n) maximum |δ̇| per variant and unit [rad/s]; pivot_peak_time (4, n) [s]
    extent : (4, 4) x_min, x_max, y_min, y_max of the planned path of each variant [m]
    names : parameter names (per-wheel or shared friction)
    conditioning : of the stacked regressor of the four variants
    true_values, std, relative_std : (p,) parameters, predicted standard deviations and
        std / |true value| for noise σ_b = ``noise`` at ``log_rate``
    """

    duration: float
    samples: int
    platform: str
    units: list[str]
    limits: Limits
    floor: Floor
    peaks: dict[str, float]
    findings: list[Finding]
    pivot_peak: np.ndarray
    pivot_peak_time: np.ndarray
    extent: np.ndarray
    names: list[str]
    conditioning: Conditioning
    noise: float
    log_rate: float
    true_values: np.ndarray
    std: np.ndarray
    relative_std: np.ndarray
    friction: str = "per-wheel"

    @property
    def condition_number(self) -> float:
        return self.conditioning.condition_number

    @property
    def rank(self) -> int:
        return self.conditioning.rank

    @property
    def ok(self) -> bool:
        """True when the run breaks no limit, stays on the floor and flips no wheel."""
        return not self.findings

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready summary."""
        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "duration": self.duration, "samples": self.samples, "platform": self.platform,
            "limits": {"v_max": self.limits.v_max, "a_max": self.limits.a_max,
                       "w_max": self.limits.w_max, "alpha_max": self.limits.alpha_max,
                       "pivot_rate_max": self.limits.pivot_rate_max},
            "floor": list(self.floor),
            "peaks": {k: num(v) for k, v in self.peaks.items()},
            "ok": self.ok,
            "findings": [f.__dict__ for f in self.findings],
            "pivot_rate_max": {v: {u: num(self.pivot_peak[i, j])
                                   for j, u in enumerate(self.units)}
                               for i, v in enumerate(VARIANTS)},
            "extent": {v: [float(e) for e in self.extent[i]] for i, v in enumerate(VARIANTS)},
            "friction": self.friction,
            "rank": self.rank, "parameters": len(self.names),
            "condition_number": num(self.condition_number),
            "condition_number_full": num(self.conditioning.condition_number_full),
            "noise": self.noise, "log_rate": self.log_rate,
            "predicted": {n: {"value": float(v), "std": num(s), "relative_std": num(r)}
                          for n, v, s, r in zip(self.names, self.true_values, self.std,
                                                self.relative_std, strict=True)},
        }

    def text(self) -> str:
        """A readable account (table) for the terminal."""
        lim = self.limits
        out = [f"run: {self.duration:.2f} s, {self.samples} setpoints; platform {self.platform} "
               f"({len(self.units)} units); variants: {', '.join(VARIANTS)}"]
        rows = [("speed |v|", "m/s", self.peaks["speed"], lim.v_max),
                ("acceleration |a|", "m/s²", self.peaks["acceleration"], lim.a_max),
                ("rotation rate |ω|", "rad/s", self.peaks["omega"], lim.w_max),
                ("rot. acceleration |ω̇|", "rad/s²", self.peaks["alpha"], lim.alpha_max),
                ("pivot rate |δ̇| (predicted)", "rad/s", self.peaks["pivot_rate"],
                 lim.pivot_rate_max)]
        out.append("")
        out.append(f"{'limit':<36}{'max':>10}{'limit':>10}  status")
        for name, unit, peak, limit in rows:
            status = "-" if limit is None else ("ok" if peak <= limit * (1 + 1e-9) else
                                                 "EXCEEDED")
            lim_s = "none" if limit is None else f"{limit:.3g}"
            out.append(f"{name + ' [' + unit + ']':<36}{peak:>10.3f}{lim_s:>10}  {status}")
        x0, x1, y0, y1 = self.floor
        ext = self.extent
        inside = not any(f.what.startswith("floor") for f in self.findings)
        out.append(f"{'floor x [' + f'{x0:g}, {x1:g}' + '] m':<36}{ext[:, 0].min():>10.2f}"
                   f"{ext[:, 1].max():>10.2f}  {'ok' if inside else 'LEFT'}")
        out.append(f"{'floor y [' + f'{y0:g}, {y1:g}' + '] m':<36}{ext[:, 2].min():>10.2f}"
                   f"{ext[:, 3].max():>10.2f}  {'ok' if inside else 'LEFT'}")
        out.append("")
        out.append("max predicted pivot rate per unit [rad/s] (trailing start, eq. 8a):")
        out.append(f"{'variant':<18}" + "".join(f"{'unit ' + u:>12}" for u in self.units))
        for i, v in enumerate(VARIANTS):
            cells = [f"{self.pivot_peak[i, j]:>6.2f} @{self.pivot_peak_time[i, j]:>3.0f}s"
                     for j in range(len(self.units))]
            out.append(f"{v:<18}" + "".join(f"{c:>12}" for c in cells))
        out.append("")
        if self.findings:
            out.append(f"findings ({len(self.findings)}):")
            for f in self.findings[:40]:
                out.append(f"  - {f.text()}")
            if len(self.findings) > 40:
                out.append(f"  … and {len(self.findings) - 40} more (see --json)")
        else:
            out.append("findings: none (every limit respected, inside the floor, no wheel flip)")
        out.append("")
        c = self.conditioning
        out.append(f"stacked regressor A_ID,ext of the four variants ({self.friction} friction): "
                   f"{len(self.names)} parameters, rank {c.rank}")
        out.append(f"  condition number (column-scaled, identifiable subspace): "
                   f"{c.condition_number:.4g}")
        if c.rank < len(self.names):
            out.append(f"  condition number (all columns): inf — {len(self.names) - c.rank} "
                       "combination(s) not identifiable (symmetric pivots: thesis Sec. VI-C)")
        else:
            out.append(f"  condition number (all columns): {c.condition_number_full:.4g}")
        out.append("")
        out.append(f"predicted standard deviation for white noise σ_b = {self.noise:g} N / N m "
                   f"on b_ID at {self.log_rate:g} Hz:")
        out.append(f"{'parameter':<12}{'value':>12}{'std':>12}{'rel. std':>12}")
        for n, v, sd, r in zip(self.names, self.true_values, self.std, self.relative_std,
                               strict=True):
            sd_s = f"{sd:.3g}" if math.isfinite(sd) else "n/a"
            r_s = f"{100 * r:.3g} %" if math.isfinite(r) else "combined"
            out.append(f"{n:<12}{v:>12.4g}{sd_s:>12}{r_s:>12}")
        return "\n".join(out)


def _fine(traj: Trajectory, dt: float = 0.005) -> Trajectory:
    """The trajectory on a grid of at most ``dt``, twist interpolated linearly (as the
    simulator's and the robot's setpoint interpolation)."""
    steps = np.diff(traj.t)
    if steps.max() <= dt * (1 + 1e-9):
        return traj
    n = int(math.ceil(traj.duration / dt))
    t = traj.t[0] + np.linspace(0.0, traj.duration, n + 1)
    tw = np.stack([np.interp(t, traj.t, v) for v in (traj.vx, traj.vy, traj.omega)], axis=-1)
    return Trajectory.from_twist(t, tw[:, 0], tw[:, 1], tw[:, 2])


def check(traj: Trajectory, platform: Platform, limits: Limits | None = None,
          floor: Sequence[float] = DEFAULT_FLOOR, noise: float = 1.0,
          params: Mapping[str, float] | None = None, friction: str = "per-wheel",
          log_rate: float = 100.0, eval_rate: float = 20.0) -> CheckReport:
    """Check a planned run before putting the robot on the floor (thesis Sec. VI-A).

    Parameters
    ----------
    traj : the run (original variant); the other three variants are derived from it
    platform : geometry for the pivot rates and the regressor
    limits : :class:`Limits` (default the thesis's); floor : (x_min, x_max, y_min, y_max) [m]
    noise : σ_b [N, N m] of white noise on b_ID for the predicted standard deviations
    params : true parameter values (name → value) for the relative standard deviations; default
        :func:`ropod_sysid.params.thesis_fixed_masses`
    friction : ``"per-wheel"`` or ``"shared"`` friction coefficients
    log_rate : sample rate [Hz] of the logs the fit will use
    eval_rate : rate [Hz] at which the regressor is evaluated (the information is scaled to
        ``log_rate``)

    Returns
    -------
    CheckReport
        Limits and where they are broken, floor, predicted pivot rates per unit and wheel flips
        (all four variants), and the stacked regressor A_ID,ext over the four variants along the
        planned motion (q, q̇, q̈ in the world frame, pivots integrated with eq. 8a): its
        condition number and rank (column-scaled), and the predicted standard deviation of
        every parameter. Violations are findings, not errors.
    """
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.params import DynamicParameters, parameter_names, thesis_fixed_masses

    limits = limits or Limits()
    floor = _check_floor(floor)
    if friction not in ("per-wheel", "shared"):
        raise InputError(f"unknown friction model {friction!r}; use per-wheel or shared")
    if not (noise > 0 and math.isfinite(noise)):
        raise InputError(f"noise must be a positive number (N, N m), got {noise!r}")
    model = PlatformModel(platform)
    var = variants(traj)
    findings: list[Finding] = []
    # limits: the same for all variants (sign changes only)
    rates = traj.twist_rates()
    speed, accel = traj.speed(), traj.acceleration()
    omega, alpha = np.abs(traj.omega), np.abs(rates[:, 2])
    checks = [("speed |v| [m/s]", speed, limits.v_max),
              ("acceleration |a| [m/s²]", accel, limits.a_max),
              ("rotation rate |ω| [rad/s]", omega, limits.w_max),
              ("rotational acceleration |ω̇| [rad/s²]", alpha, limits.alpha_max)]
    for what, values, limit in checks:
        findings += _runs(values > limit * (1 + 1e-9), traj.t, values, what, limit, "all")
    # floor, per variant (the planned path)
    extent = np.zeros((4, 4))
    fine = _fine(traj)
    fine_var = variants(fine)
    for i, (name, vt) in enumerate(var.items()):
        extent[i] = [vt.x.min(), vt.x.max(), vt.y.min(), vt.y.max()]
        out_x = np.maximum(floor[0] - vt.x, vt.x - floor[1])
        out_y = np.maximum(floor[2] - vt.y, vt.y - floor[3])
        findings += _runs(out_x > 0, vt.t, out_x, "floor left in x [m beyond]", 0.0, name)
        findings += _runs(out_y > 0, vt.t, out_y, "floor left in y [m beyond]", 0.0, name)
    # pivots (on a fine grid: the pivot ODE is stiff)
    twists = np.stack([vt.twist() for vt in fine_var.values()])
    pred = predict_pivots(fine.t, twists, platform)
    prate = np.abs(pred.rate)
    pivot_peak = prate.max(axis=1)
    pivot_peak_time = fine.t[prate.argmax(axis=1)]
    for i, name in enumerate(VARIANTS):
        for j, u in enumerate(platform.unit_names):
            if limits.pivot_rate_max is not None:
                findings += _runs(prate[i, :, j] > limits.pivot_rate_max, fine.t, prate[i, :, j],
                                  f"pivot rate of unit {u} [rad/s]", limits.pivot_rate_max, name)
            findings += _runs(pred.pulling[i, :, j], fine.t,
                              np.ones(fine.n_samples), f"unit {u} pulling (wheel flip)", 0.0,
                              name)
    peaks = {"speed": float(speed.max()), "acceleration": float(accel.max()),
             "omega": float(omega.max()), "alpha": float(alpha.max()),
             "pivot_rate": float(prate.max())}
    # the stacked regressor along the planned motion (pivots as predicted)
    step = max(int(round(1.0 / (eval_rate * float(np.median(np.diff(fine.t)))))), 1)
    idx = np.arange(0, fine.n_samples, step)
    q, qd, qdd = _world_motion(fine.t, twists)
    n_var = len(VARIANTS)
    a = _regressor_rows(model, q[:, idx].reshape(-1, 3), qd[:, idx].reshape(-1, 3),
                        qdd[:, idx].reshape(-1, 3),
                        pred.delta[:, idx].reshape(n_var * idx.size, -1), friction)
    cond = conditioning(a)
    names = parameter_names(platform.unit_names, friction)  # type: ignore[arg-type]
    if params is None:
        truth = thesis_fixed_masses(platform.unit_names)
    else:
        truth = DynamicParameters.from_mapping(params, platform.unit_names, "parameters")
    true_values = truth.vector(platform.unit_names, friction)  # type: ignore[arg-type]
    dt_eval = step * float(np.median(np.diff(fine.t)))
    std = predicted_std(a, noise, rows_per_second=log_rate * dt_eval)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.abs(true_values) > 0, std / np.abs(true_values), math.inf)
    findings.sort(key=lambda f: (f.t_start, f.what))
    return CheckReport(traj.duration, traj.n_samples, platform.name, platform.unit_names,
                       limits, floor, peaks, findings, pivot_peak, pivot_peak_time, extent,
                       names, cond, float(noise), float(log_rate), true_values, std, rel,
                       friction)


def plot(traj: Trajectory, path: str | Path, floor: Sequence[float] = DEFAULT_FLOOR,
         limits: Limits | None = None, platform: Platform | None = None) -> None:
    """Plot the planned path of the four variants on the floor, and the speeds, rotation rate
    and predicted pivot rates over time; PNG or SVG by the file suffix (written atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ropod_sysid.io.atomic import atomic_path

    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "svg"):
        raise InputError(f"{path}: plot format {path.suffix or '(none)'!r} unknown; use a .png "
                         "or .svg file name")
    limits = limits or Limits()
    floor = _check_floor(floor)
    var = variants(traj)
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1.2, 1]})
    x0, x1, y0, y1 = floor
    ax0.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", color="0.4"))
    for name, vt in var.items():
        ax0.plot(vt.x, vt.y, lw=1.2 if name == "original" else 0.7, label=name,
                 alpha=1.0 if name == "original" else 0.6)
    ax0.plot([0], [0], "ko", ms=4)
    ax0.set_aspect("equal")
    ax0.set_xlabel("x [m]")
    ax0.set_ylabel("y [m]")
    ax0.set_title("planned path of the base origin")
    ax0.legend(fontsize=8, loc="upper right")
    ax1.plot(traj.t, traj.speed(), label="|v| [m/s]")
    ax1.plot(traj.t, traj.acceleration(), label="|a| [m/s²]", lw=0.8)
    ax1.plot(traj.t, traj.omega, label="ω [rad/s]", lw=0.8)
    if platform is not None:
        fine = _fine(traj)
        twists = np.stack([vt.twist() for vt in variants(fine).values()])
        pred = predict_pivots(fine.t, twists, platform)
        ax1.plot(fine.t, np.abs(pred.rate).max(axis=(0, 2)), label="max |δ̇| [rad/s]", lw=0.8)
        if limits.pivot_rate_max is not None:
            ax1.axhline(limits.pivot_rate_max, color="0.5", ls=":", lw=0.8)
    ax1.axhline(limits.v_max, color="0.5", ls="--", lw=0.8)
    ax1.set_xlabel("t [s]")
    ax1.set_title("setpoints and limits")
    ax1.legend(fontsize=8)
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt, dpi=110)
    except OSError as exc:
        raise InputError(f"{path}: cannot write the plot ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)


# ---------------------------------------------------------------------------------------------
# optimal excitation: finite Fourier series (Swevers et al.)


KAPPA_FRACTION = 0.9  # FourierFamily: κ_max · max pivot radius (ICR outside the units)
RHO_BETA, RHO_KAPPA = 0.5, 0.1  # FourierFamily: rate scales of direction and curvature
SPEED_WEIGHT = 0.5  # optimize(): weight of −log(mean speed / v_max) in the objective
NU_MIN = 0.25  # FourierFamily: least speed between the ramps, as a fraction of s_v
MAX_LAG = 0.35  # optimize(): sin of the largest quasi-steady lag of a unit behind its pivot


class FourierFamily:
    """Rest-to-rest finite Fourier series for the base motion, in polar form (base frame).

    Each of the three base DOFs of the twist gets a finite Fourier series with base period T
    and H harmonics (Swevers et al.; ω_f = 2π / T, coefficients c, a_l, b_l):

        speed      ν(t) = s_v w(t) (ν_0 + (1 − ν_0)(1 + tanh g(t)) / 2),   ν_0 = 0.25
                   g(t) = c_v + Σ a_l sin(lω_f t) + b_l cos(lω_f t)
        direction  β(t) = π c_β + ρ_β w(t)² h_β(t)                 [rad, of travel, base frame]
        curvature  κ(t) = κ_max tanh(c_κ + ρ_κ w(t)² h_κ(t))         [rad/m]
        h(t) = Σ (a_l sin(lω_f t) − b_l cos(lω_f t)) / (l ω_f)        (so ḣ = Σ a_l cos + b_l sin)
        (vx, vy) = ν (cos β, sin β),   ω = ν κ,

    with w(t) a window rising from 0 to 1 over the first ``ramp`` seconds and falling back over
    the last (minimum-jerk profile): rest to rest, acceleration continuous. Why polar rather than
    a series per Cartesian component: pivot i moves with P_i = ν (e(β) + κ S r_i) (eq. 8a);
    with |κ| < κ_max = 0.6 / max|r_i| the bracket never vanishes — the instantaneous centre of
    rotation stays outside the units — so no pivot velocity ever reverses (no wheel flip, Sec.
    VI-A) whatever the coefficients, where Cartesian series reverse them all the time; between
    the ramps the speed stays above ν_0 s_v, for a unit cannot turn while its pivot stands. The
    direction of P_i, hence the pivot rate, depends on β and κ only, not on the speed scale s_v;
    ρ_β and ρ_κ size the rates of β and of κ's argument to the pivot-rate budget, and β, κ vary
    only where w is near 1 (w² factor), so the units need not turn while the base barely moves.
    """

    def __init__(self, duration: float, harmonics: int, t: np.ndarray, r_max: float,
                 rate_budget: float = 1.5, ramp: float | None = None) -> None:
        self.duration = float(duration)
        self.harmonics = int(harmonics)
        self.t = np.asarray(t, float)
        self.ramp = float(ramp if ramp is not None else min(0.15 * duration, 4.0))
        self.kappa_max = KAPPA_FRACTION / max(float(r_max), 1e-6)
        self.rho_beta = RHO_BETA * rate_budget / math.sqrt(2 * self.harmonics)
        self.rho_kappa = RHO_KAPPA * rate_budget / math.sqrt(2 * self.harmonics)
        wf = 2 * math.pi / self.duration
        lw = wf * np.arange(1, self.harmonics + 1)
        arg = np.outer(self.t, lw)
        sn, cs = np.sin(arg), np.cos(arg)
        one, zero = np.ones((len(self.t), 1)), np.zeros((len(self.t), 1))
        # bases (N, 2H+1); coefficient order [c, a_1..a_H, b_1..b_H]
        self.g0 = np.hstack([one, sn, cs])  # g and ġ (speed)
        self.g1 = np.hstack([zero, cs * lw, -sn * lw])
        self.h0 = np.hstack([zero, sn / lw, -cs / lw])  # h and ḣ (direction, curvature)
        self.h1 = np.hstack([zero, cs, sn])
        up, dup, _ = _quintic(self.t / self.ramp)
        dn, ddn, _ = _quintic((self.duration - self.t) / self.ramp)
        self.w = up * dn
        self.dw = dup / self.ramp * dn - up * ddn / self.ramp

    @property
    def n_coefficients(self) -> int:
        return 3 * (2 * self.harmonics + 1)

    def shape(self, coef: np.ndarray) -> tuple[np.ndarray, ...]:
        """(ν, ν̇, β, β̇, κ, κ̇) (S, N) at unit speed scale for coefficients (S, 3(2H+1))."""
        c = np.asarray(coef, float).reshape(-1, 3, 2 * self.harmonics + 1)
        g = c[:, 0] @ self.g0.T
        gd = c[:, 0] @ self.g1.T
        w, dw = self.w, self.dw
        th = np.tanh(g)
        base = NU_MIN + (1 - NU_MIN) * (1 + th) / 2
        nu = w * base
        nud = dw * base + w * (1 - NU_MIN) * (1 - th**2) * gd / 2
        w2, dw2 = w**2, 2 * w * dw
        hb, hbd = c[:, 1] @ self.h0.T, c[:, 1] @ self.h1.T
        beta = math.pi * c[:, 1, :1] + self.rho_beta * w2 * hb
        betad = self.rho_beta * (dw2 * hb + w2 * hbd)
        hk, hkd = c[:, 2] @ self.h0.T, c[:, 2] @ self.h1.T
        tk = np.tanh(c[:, 2, :1] + self.rho_kappa * w2 * hk)
        kappa = self.kappa_max * tk
        kappad = self.kappa_max * (1 - tk**2) * self.rho_kappa * (dw2 * hk + w2 * hkd)
        return nu, nud, beta, betad, kappa, kappad


def _variant_paths(t: np.ndarray, tw: np.ndarray) -> np.ndarray:
    """World positions (S, 4, N, 2) of the four variants of base-frame twists (S, N, 3)."""
    out = np.empty(tw.shape[:1] + (4,) + tw.shape[1:2] + (2,))
    for k, name in enumerate(VARIANTS):
        sx, sy, sw = VARIANT_SIGNS[name]
        x, y, _ = integrate_pose(t, sx * tw[..., 0], sy * tw[..., 1], sw * tw[..., 2])
        out[:, k, :, 0], out[:, k, :, 1] = x, y
    return out


@dataclass
class OptimizeResult:
    """An optimised excitation run and how it was found.

    Attributes
    ----------
    trajectory : the run (original variant), rest to rest, within the limits and the floor
    objective : ``"cond"`` or ``"logdet"``; value : its value (objective grid, penalties in)
    condition_number, rank : of the stacked regressor of the four variants (identifiable
        subspace, as :func:`check` evaluates it on the run's own grid)
    structural_rank : rank of the regressor the search found (identifiable subspace dimension)
    coefficients : (3, 2H+1) Fourier coefficients of speed, direction, curvature
    speed_scale : s_v [m/s]; evaluations, generations, seconds : the search's cost
    """

    trajectory: Trajectory
    objective: str
    value: float
    condition_number: float
    rank: int
    structural_rank: int
    coefficients: np.ndarray
    speed_scale: float
    evaluations: int
    generations: int
    seconds: float
    notes: list[str] = field(default_factory=list)


class _Objective:
    """Vectorised objective of :func:`optimize` over a population of coefficient vectors."""

    def __init__(self, platform: Platform, duration: float, harmonics: int, limits: Limits,
                 floor: Floor, objective: str, friction: str, grid_rate: float,
                 eval_rate: float) -> None:
        from ropod_sysid.model import PlatformModel

        self.platform = platform
        self.model = PlatformModel(platform)
        self.pivots = platform.pivots
        self.s_w = platform.caster_offset
        self.limits = limits
        self.floor = floor
        self.objective = objective
        self.friction = friction
        n = int(math.ceil(duration * grid_rate))
        self.t = np.linspace(0.0, duration, n + 1)
        r_max = float(np.linalg.norm(self.pivots, axis=1).max())
        self.family = FourierFamily(duration, harmonics, self.t, r_max,
                                    limits.pivot_rate_max or 1.5)
        step = max(int(round(grid_rate / eval_rate)), 1)
        self.eval_idx = np.arange(step // 2 + 1, n, step)  # interior samples (not at rest)
        self.rank: int | None = None
        self.evaluations = 0

    def twist(self, coef: np.ndarray, margin: float = 0.95,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Twist and its rate (S, N, 3) at the largest speed scale s_v within the limits and the
        floor (all four variants) times ``margin``, and s_v (S,)."""
        return _scaled_twist(self.family, coef, self.limits, self.floor, self.t, margin)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Objective values (S,) for coefficients x (D, S) (scipy's vectorised layout)."""
        coef = np.atleast_2d(np.asarray(x, float).T)
        out = np.empty(coef.shape[0])
        for k in range(0, coef.shape[0], 64):
            out[k:k + 64] = self._batch(coef[k:k + 64])
        self.evaluations += coef.shape[0]
        return out

    def pivots_quasi_steady(self, tw: np.ndarray, twd: np.ndarray,
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Quasi-steady pivot angle, rate and sin(lag) (…, N, n) for twists (…, N, 3): every
        unit trails its pivot velocity P_i with the lag that makes eq. 8a hold,
        sin(ψ_i − δ_i) = s_w (ω + ψ̇_i) / |P_i| — meaningful only while it is well below 1."""
        px, py = _pivot_velocities(tw, self.pivots)
        pdx, pdy = _pivot_velocities(twd, self.pivots)
        p2 = px**2 + py**2
        speed = np.sqrt(p2)
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = np.where(p2 > 1e-18, (px * pdy - py * pdx) / p2, 0.0)
            sin_lag = np.where(p2 > 1e-18, self.s_w * (tw[..., 2:3] + rate)
                               / np.maximum(speed, 1e-12), 0.0)
        lag = np.arcsin(np.clip(sin_lag, -1.0, 1.0))
        return np.arctan2(py, px) - lag, rate, sin_lag

    def _batch(self, coef: np.ndarray) -> np.ndarray:
        tw, twd, _ = self.twist(coef)
        signs = np.array([VARIANT_SIGNS[v] for v in VARIANTS])  # (4, 3)
        tw_v = tw[:, None] * signs[None, :, None, :]
        twd_v = twd[:, None] * signs[None, :, None, :]
        delta, rate, sin_lag = self.pivots_quasi_steady(tw_v, twd_v)
        lag = np.abs(sin_lag[:, :2]).max(axis=(1, 2, 3))  # negated variants: the same
        penalty = np.maximum(lag / MAX_LAG - 1.0, 0.0)
        if self.limits.pivot_rate_max is not None:
            peak = np.abs(rate[:, :2]).max(axis=(1, 2, 3))
            penalty += np.maximum(peak / (PIVOT_DESIGN_MARGIN * self.limits.pivot_rate_max)
                                  - 1.0, 0.0)
        idx = self.eval_idx
        q, qd, qdd = _world_motion(self.t, tw_v, twd_v)
        n_s, n_u = coef.shape[0], self.pivots.shape[0]
        # pivot rates from the constraint (eq. 8a) at the quasi-steady angles: consistent
        # kinematics, so the structural rank deficiency shows exactly
        st = self.model.state(q[:, :, idx].reshape(-1, 3), qd[:, :, idx].reshape(-1, 3),
                              delta[:, :, idx].reshape(-1, n_u))
        a = self.model.a_id_ext(st, qdd[:, :, idx].reshape(-1, 3),
                                self.friction)  # type: ignore[arg-type]
        a = a.reshape(n_s, -1, a.shape[-1])
        norms = np.linalg.norm(a, axis=1)
        a = a / np.where(norms > 0, norms, 1.0)[:, None, :]
        # einsum, not BLAS: many small products, and threaded BLAS stalls on a busy machine
        gram = np.einsum("smi,smj->sij", a, a)
        lam = np.clip(np.linalg.eigvalsh(gram)[:, ::-1], 1e-300, None)
        if self.rank is None:
            self.rank = max(conditioning(a[k]).rank for k in range(min(6, n_s)))
        r = self.rank
        if self.objective == "cond":
            value = 0.5 * np.log(lam[:, 0] / lam[:, r - 1])
        else:
            value = -np.log(lam[:, :r]).sum(axis=1) / r
        # tie-breaker towards brisk runs: the scaled regressor does not see the signal level
        speed = np.linalg.norm(tw[..., :2], axis=-1).mean(axis=1) / self.limits.v_max
        value = value - SPEED_WEIGHT * np.log(np.maximum(speed, 1e-6))
        return value + 10.0 * penalty + 100.0 * penalty**2


def _scaled_twist(family: FourierFamily, coef: np.ndarray, limits: Limits, floor: Floor,
                  t: np.ndarray, margin: float, s_v: np.ndarray | None = None,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Twist, twist rate (S, N, 3) and speed scale s_v (S,) of a family's candidates.

    s_v is the largest scale (times ``margin``) with |v| ≤ v_max, |ω| ≤ ω_max, |ω̇| ≤ α_max,
    |a| ≤ a_max (a = s_v sqrt(ν̇² + ν² (β̇ + s_v ν κ)²) grows monotonically with s_v) and the
    four variants inside the floor (bisection: the path grows with s_v); given s_v is used as is.
    """
    nu, nud, beta, betad, kappa, kappad = family.shape(coef)
    tiny = 1e-12
    if s_v is None:
        hi = np.minimum.reduce([
            limits.v_max / (nu.max(1) + tiny),
            limits.w_max / (np.abs(nu * kappa).max(1) + tiny),
            limits.alpha_max / (np.abs(nud * kappa + nu * kappad).max(1) + tiny)])
        hi = np.minimum(hi * margin, 20.0)

        sub = slice(None, None, max(len(t) // 150, 1))  # floor on a coarse grid
        t_sub = t[sub]

        def feasible(s: np.ndarray) -> np.ndarray:
            sc = s[:, None]
            acc = sc * np.sqrt(nud**2 + nu**2 * (betad + sc * nu * kappa) ** 2)
            ok = acc.max(1) <= limits.a_max * margin
            tw = _twist_of(sc, nu[:, sub], beta[:, sub], kappa[:, sub])
            paths = _variant_paths(t_sub, tw)
            x0, x1, y0, y1 = (margin * f for f in floor)
            inside = ((paths[..., 0] >= x0) & (paths[..., 0] <= x1) & (paths[..., 1] >= y0)
                      & (paths[..., 1] <= y1)).all(axis=(1, 2))
            return ok & inside

        lo = np.zeros_like(hi)
        top = feasible(hi)
        for _ in range(8):
            mid = 0.5 * (lo + hi)
            good = feasible(mid)
            lo = np.where(good, mid, lo)
            hi = np.where(good, hi, mid)
        s_v = np.where(top, hi, lo)
    sc = np.asarray(s_v, float)[:, None]
    tw = _twist_of(sc, nu, beta, kappa)
    cb, sb = np.cos(beta), np.sin(beta)
    twd = np.stack([sc * (nud * cb - nu * betad * sb), sc * (nud * sb + nu * betad * cb),
                    sc * (nud * kappa + nu * kappad)], axis=-1)
    return tw, twd, np.asarray(s_v, float)


def _twist_of(sc: np.ndarray, nu: np.ndarray, beta: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    return np.stack([sc * nu * np.cos(beta), sc * nu * np.sin(beta), sc * nu * kappa], axis=-1)


def optimize(platform: Platform, duration: float = 30.0, harmonics: int = 5,
             objective: str = "cond", seed: int = 0, maxiter: int = 25,
             limits: Limits | None = None, floor: Sequence[float] = DEFAULT_FLOOR,
             progress: bool = False, dt: float = 0.005, popsize: int = 4,
             friction: str = "per-wheel") -> OptimizeResult:
    """An optimal excitation run: finite Fourier series per base DOF (Swevers et al.).

    The run is a member of :class:`FourierFamily` (speed, direction of travel and curvature of
    the base, each a finite Fourier series, rest to rest, no pivot velocity ever reversing);
    every candidate runs at the largest speed within the limits and the floor (all four
    variants) at 95 %. The objective is evaluated on the stacked regressor A_ID,ext of the four
    variants (Sec. VI-A) along the planned motion on a coarse grid, units trailing their pivot
    velocities (quasi-steady eq. 8a):

    * ``"cond"`` — the condition number of the column-scaled regressor on its identifiable
      subspace (σ_max / σ_r, r the structural rank: on the ropod's symmetric square the regressor
      is rank deficient for every run, thesis Sec. VI-C), minimised;
    * ``"logdet"`` — the log-determinant of the column-scaled information matrix on that
      subspace, maximised.

    Pivot rates above 80 % of their limit, and quasi-steady lags of a unit behind its pivot with
    sin > 0.35 (a unit cannot follow a pivot that barely moves), are penalised; −0.5 log(mean
    speed / v_max) is added as a tie-breaker towards brisk runs, which the column-scaled
    regressor cannot see. scipy's differential evolution searches
    the coefficients (seeded, vectorised over the population); the best candidate whose limits,
    floor and pivot rates integrated on the fine grid all hold is returned.

    Parameters
    ----------
    platform : geometry (pivots, caster offset) for the regressor and the pivot rates
    duration : length of the run [s]; harmonics : H, harmonics per DOF (base period = duration)
    objective : ``"cond"`` or ``"logdet"``; seed : random seed (repeatable)
    maxiter : generations of the search; popsize : population = popsize × 3(2H+1) candidates
    limits, floor : as for :func:`typical`; progress : progress bar on stderr (terminal only)
    dt : sample interval of the returned setpoints [s]; friction : friction model of A_ID,ext

    Returns
    -------
    OptimizeResult
    """
    import time

    import scipy.optimize

    from ropod_sysid.progress import Progress

    limits = limits or Limits()
    floor = _check_floor(floor)
    if objective not in ("cond", "logdet"):
        raise InputError(f"unknown objective {objective!r}; use cond or logdet")
    if isinstance(harmonics, bool) or not isinstance(harmonics, int) \
            or not 1 <= harmonics <= MAX_HARMONICS:
        raise InputError(f"harmonics must be an integer from 1 to {MAX_HARMONICS}, got "
                         f"{harmonics!r}")
    lo, hi = OPTIMIZE_DURATION
    if not (isinstance(duration, int | float) and lo <= duration <= hi):
        raise InputError(f"duration must be between {lo:g} and {hi:g} s, got {duration!r}")
    if isinstance(maxiter, bool) or not isinstance(maxiter, int) or maxiter < 1:
        raise InputError(f"maxiter must be a positive integer, got {maxiter!r}")
    if friction not in ("per-wheel", "shared"):
        raise InputError(f"unknown friction model {friction!r}; use per-wheel or shared")
    t_start = time.monotonic()
    obj = _Objective(platform, float(duration), harmonics, limits, floor, objective, friction,
                     grid_rate=10.0, eval_rate=2.0)
    dim = obj.family.n_coefficients
    generations = 0
    with Progress(maxiter, "optimize", quiet=not progress) as bar:
        def callback(*_args: object, **_kw: object) -> None:
            nonlocal generations
            generations += 1
            bar.update(1)

        res = scipy.optimize.differential_evolution(
            obj, [(-1.0, 1.0)] * dim, seed=seed, maxiter=maxiter, popsize=popsize, tol=0.0,
            polish=False, vectorized=True, updating="deferred", init="latinhypercube",
            callback=callback)
    fine_t = np.linspace(0.0, duration, int(round(duration / dt)) + 1)
    fam = FourierFamily(duration, harmonics, fine_t,
                        float(np.linalg.norm(platform.pivots, axis=1).max()),
                        limits.pivot_rate_max or 1.5)
    notes: list[str] = []
    why_first = ""
    chosen = None
    for rank_k, k in enumerate(np.argsort(res.population_energies)[:12]):
        coef = res.population[k]
        _, _, s_v = obj.twist(coef[None])
        tw, _, _ = _scaled_twist(fam, coef[None], limits, floor, fine_t, 0.95, s_v)
        traj = Trajectory.from_twist(fine_t, tw[0, :, 0], tw[0, :, 1], tw[0, :, 2])
        ok, why = _verify(traj, platform, limits, floor)
        if ok:
            chosen = (coef, traj, float(s_v[0]), float(res.population_energies[k]))
            if rank_k:
                notes.append(f"{rank_k} better candidate(s) broke a limit on the fine grid "
                             f"({why_first}); took the next")
            break
        why_first = why_first or why
    if chosen is None:
        raise PlanningError(f"no optimised run within the limits ({why_first}); try another "
                            "seed, more maxiter or a longer duration")
    coef, traj, s_v, value = chosen
    rep = check(traj, platform, limits, floor, friction=friction)
    return OptimizeResult(traj, objective, value, rep.condition_number, rep.rank,
                          obj.rank or 0, coef.reshape(3, -1), s_v, obj.evaluations,
                          generations, time.monotonic() - t_start, notes)


def _verify(traj: Trajectory, platform: Platform, limits: Limits,
            floor: Floor) -> tuple[bool, str]:
    """Limits, floor (four variants) and integrated pivot rates of a run on its own grid."""
    rates = traj.twist_rates()
    if traj.speed().max() > limits.v_max:
        return False, "speed"
    if traj.acceleration().max() > limits.a_max:
        return False, "acceleration"
    if np.abs(traj.omega).max() > limits.w_max or np.abs(rates[:, 2]).max() > limits.alpha_max:
        return False, "rotation"
    var = variants(traj)
    for name, vt in var.items():
        if (vt.x.min() < floor[0] or vt.x.max() > floor[1] or vt.y.min() < floor[2]
                or vt.y.max() > floor[3]):
            return False, f"floor ({name})"
    if limits.pivot_rate_max is not None:
        pred = predict_pivots(traj.t, np.stack([vt.twist() for vt in var.values()]), platform)
        peak = float(np.abs(pred.rate).max())
        if peak > limits.pivot_rate_max or pred.pulling.any():
            return False, f"pivot rate {peak:.2f} rad/s"
    return True, ""
