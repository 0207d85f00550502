"""Twist programs of minimum-jerk blends between constant levels (the typical run, Sec. VI-A).

Every change of the twist (vx, vy [m/s], ω [rad/s]) is a blend a + (b − a) s(τ) with the
minimum-jerk profile s(τ) = 10τ³ − 15τ⁴ + 6τ⁵, so the acceleration is continuous (jumps in it
bias the identification); each blend is as short as the limits allow (:func:`_blend_time`: the
rotational and world acceleration, the quasi-steady pivot rate of eq. 8a and the steering rate of
steered wheels). :class:`_Plan` chains blends and holds into manoeuvres (corners, rotations in
place, stop-and-go).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ropod_sysid.model.units.steered import PLAN_SPEED
from ropod_sysid.trajectory.limits import Limits, PlanningError
from ropod_sysid.trajectory.setpoints import integrate_pose


def _quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk blend s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and its first two derivatives in τ."""
    tau = np.clip(tau, 0.0, 1.0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds


_TAU = np.linspace(0.0, 1.0, 257)
_S, _DS, _DDS = _quintic(_TAU)


def _direction_rate(a: np.ndarray, d: np.ndarray, points: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Along the blend a + s(τ) d of the twist: the velocities P_i = v + ω S r_i of ``points``
    r_i (m, 2) in the base frame — at the start (m, 2), their change (m, 2), cross(P_i, d P_i)
    (m,), constant along the blend — and |P_i|² on the blend's grid (257, m). The direction of
    P_i turns at cross / |P_i|² · ds/dτ / T for a blend of T seconds."""
    sp = np.stack([-points[:, 1], points[:, 0]], axis=1)  # S r_i
    pa = a[:2][None, :] + a[2] * sp  # (m, 2) P_i at the start
    dp = d[:2][None, :] + d[2] * sp
    cross = pa[:, 0] * dp[:, 1] - pa[:, 1] * dp[:, 0]
    p = pa[None] + _S[:, None, None] * dp[None]
    return pa, dp, cross, (p * p).sum(-1)


def _blend_time(a: np.ndarray, b: np.ndarray, caps: Limits, pivots: np.ndarray | None,
                t_min: float = 0.4, steering: np.ndarray | None = None) -> float:
    """Shortest duration [s] of a minimum-jerk blend of the twist from level a to level b.

    During the blend the twist is a + (b − a) s(τ): continuous acceleration, zero at both ends.
    The duration meets the rotational acceleration cap, the world acceleration cap (with the
    centripetal part ω S v, which does not shrink with a longer blend), with pivots the
    quasi-steady pivot rate ψ̇_i = cross(P_i, Ṗ_i)/|P_i|² of every unit, and with ``steering``
    (the steering axes of steered wheels) their steering rate, which is that same rate of
    their wheel-centre velocity (the planned steering follows it exactly while the wheel moves
    at least :data:`~ropod_sysid.model.units.steered.PLAN_SPEED`, below which |P_i| is taken
    as that speed: the steering turns smoothly there, and ``check`` verifies it). A steered
    wheel may reverse (its drive does): no error for a velocity through zero.
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
        pa, dp, cross, p2 = _direction_rate(a, d, pivots)
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
    if steering is not None and caps.steer_rate_max is not None:
        _, _, cross, p2 = _direction_rate(a, d, steering)
        rate = np.abs(cross)[None] / np.maximum(p2, PLAN_SPEED**2) * _DS[:, None]
        t_req = max(t_req, float(rate.max()) / caps.steer_rate_max)
    if not math.isfinite(t_req):
        raise PlanningError("a planned blend needs an infinite time (pivot velocity near zero)")
    return float(t_req)


# blend times by (limits, pivots, steering axes), then by the levels a, b (rounded to 1e-12):
# a typical run's search builds some 60 plans asking 670 blends, 38 of them distinct
_BLEND_TIMES: dict[tuple[object, bytes | None, bytes | None], dict[tuple[float, ...], float]] = {}
BLEND_CACHE = 4096  # blends kept per set of limits and axes (then the set starts again)


class _Plan:
    """A twist program: minimum-jerk blends between constant levels and holds of a level.

    Segments are [a, b, T]: the twist goes from level a to level b over T seconds (a hold when
    a == b). The heading change of a segment is exact: T (ω_a + ω_b)/2.
    """

    def __init__(self, caps: Limits, pivots: np.ndarray | None, theta0: float = 0.0,
                 steering: np.ndarray | None = None) -> None:
        self.caps = caps
        self.pivots = pivots
        self.steering = steering  # steering axes of steered wheels (steering-rate cap)
        self.segs: list[list] = []
        self.level = np.zeros(3)
        self.theta = theta0
        # the blend times of every plan with the same limits and axes (a search builds many)
        self._cache = _BLEND_TIMES.setdefault(
            (caps, None if pivots is None else np.asarray(pivots, float).tobytes(),
             None if steering is None else np.asarray(steering, float).tobytes()), {})

    def blend_time(self, a: np.ndarray, b: np.ndarray) -> float:
        key = tuple(np.round(np.concatenate([a, b]), 12))
        if key not in self._cache:
            if len(self._cache) >= BLEND_CACHE:
                self._cache.clear()
            self._cache[key] = _blend_time(a, b, self.caps, self.pivots,
                                           steering=self.steering)
        return self._cache[key]

    def to(self, b: Sequence[float] | np.ndarray, t: float | None = None) -> float:
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
    durs = np.array([s[2] for s in segs], float)
    ends = np.cumsum(durs)
    starts = ends - durs
    idx = np.searchsorted(ends, t, side="right")
    inside = idx < len(segs)
    j = np.minimum(idx, len(segs) - 1)
    a = np.array([s[0] for s in segs], float).reshape(len(segs), 3)
    d = np.array([s[1] for s in segs], float).reshape(len(segs), 3) - a
    inside &= durs[j] > 0
    tau = np.where(inside, (t - starts[j]) / np.where(durs[j] > 0, durs[j], 1.0), 0.0)
    s, _, _ = _quintic(tau)
    return np.where(inside[:, None], a[j] + s[:, None] * d[j], 0.0)


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

