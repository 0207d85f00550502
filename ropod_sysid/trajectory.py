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

Contents: :class:`Trajectory` (CSV I/O, setpoints), :func:`typical`, :func:`variants` and
:func:`predict_pivots`.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ropod_sysid.errors import InputError
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
        from ropod_sysid.io.atomic import atomic_write_text

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
    Every problem raises :class:`InputError` with one line naming the file, line and column.
    Line numbers count the header as line 1.
    """
    where = str(path)
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise InputError(f"{where}: no such trajectory file; check the path") from None
    except IsADirectoryError:
        raise InputError(f"{where}: is a directory, not a trajectory CSV file") from None
    except UnicodeDecodeError:
        raise InputError(f"{where}: not a text CSV file (invalid UTF-8)") from None
    except OSError as exc:
        raise InputError(f"{where}: cannot read the trajectory ({exc.strerror or exc})") from None
    except csv.Error as exc:
        raise InputError(f"{where}: not a valid CSV file ({exc})") from None
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise InputError(f"{where}: empty file; expected a header line "
                         f"'{','.join(COLUMNS)}' and one row per setpoint")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in TWIST_COLUMNS if c not in header]
    if missing:
        raise InputError(
            f"{where}: line 1: missing column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(c) for c in missing)}; the header needs t, vx, vy, omega "
            "(optionally x, y, theta)")
    pose_present = [c for c in POSE_COLUMNS if c in header]
    if pose_present and len(pose_present) < 3:
        absent = [c for c in POSE_COLUMNS if c not in header]
        raise InputError(
            f"{where}: line 1: column{'s' if len(absent) > 1 else ''} "
            f"{', '.join(repr(c) for c in absent)} missing while "
            f"{', '.join(repr(c) for c in pose_present)} present; give all of x, y, theta or none")
    dupes = sorted({h for h in header if header.count(h) > 1 and h in COLUMNS})
    if dupes:
        raise InputError(f"{where}: line 1: column {dupes[0]!r} appears twice; keep one")
    wanted = list(TWIST_COLUMNS) + (list(POSE_COLUMNS) if pose_present else [])
    idx = [header.index(c) for c in wanted]
    values: list[list[float]] = []
    lines: list[int] = []
    for lineno, row in enumerate(rows[1:], start=2):
        if not row or not any(cell.strip() for cell in row):
            continue  # blank line
        if len(row) != len(header):
            raise InputError(f"{where}: line {lineno}: {len(row)} fields, the header has "
                             f"{len(header)}; every row needs one value per column")
        out = []
        for col, k in zip(wanted, idx, strict=True):
            cell = row[k].strip()
            try:
                v = float(cell)
            except ValueError:
                raise InputError(f"{where}: line {lineno}, column '{col}': {cell!r} is not a "
                                 "number") from None
            if not math.isfinite(v):
                raise InputError(f"{where}: line {lineno}, column '{col}': {cell!r} is not a "
                                 "finite number; replace NaN/inf by a value")
            out.append(v)
        values.append(out)
        lines.append(lineno)
    if len(values) < 2:
        raise InputError(f"{where}: {len(values)} data row{'s' if len(values) != 1 else ''}; a "
                         "trajectory needs at least 2 setpoints")
    data = np.array(values)
    t = data[:, 0]
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        k = int(bad[0])
        raise InputError(f"{where}: line {lines[k + 1]}, column 't': t={t[k + 1]!r} is not after "
                         f"t={t[k]!r} on line {lines[k]}; time must strictly increase")
    if pose_present:
        return Trajectory(*(np.ascontiguousarray(data[:, j]) for j in range(7)))
    return Trajectory.from_twist(t, data[:, 1], data[:, 2], data[:, 3])


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
    """Start: a whole rotation in place from rest (units set tangentially, as they trail a
    rotation), then away along +x through a tight arc, at cruise speed; heading back to 0."""
    rot = np.array([0.0, 0.0, design.w_spin])
    arc = np.array([design.v_spin, 0.0, design.w_spin])
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
    if not (isinstance(duration, int | float) and math.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be a positive number of seconds, got {duration!r}")
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
