"""The base's curvature radius over a run's moving time (Robuffo Giordano et al. (002) eq. 26:
R = |(vx, vy)| / |ω| ≥ R_min keeps the instantaneous centre of rotation outside the footprint,
so no wheel on a held leg comes to rest in a type-A singularity), and when a run counts as
moving (some unit's attachment point at least :data:`MOVING_SPEED` fast). Vectorised over
samples; ``trajectory check``, ``typical`` and ``optimize`` read it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MOVING_SPEED = 0.01  # [m/s] the platform moves while a unit's attachment point is this fast


def moving_mask(twists: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(…, N) True where some unit's attachment point (n, 2) moves at least
    :data:`MOVING_SPEED` with the base twists (…, N, 3)."""
    u_x = twists[..., :1] - twists[..., 2:] * positions[:, 1]
    u_y = twists[..., 1:2] + twists[..., 2:] * positions[:, 0]
    return (np.hypot(u_x, u_y) >= MOVING_SPEED).any(axis=-1)


def curvature_radius(twists: np.ndarray) -> np.ndarray:
    """R = |(vx, vy)| / |ω| (…, N) [m] of base-frame twists (…, N, 3): the distance of the
    instantaneous centre of rotation from the base origin (002 eq. 26); inf where ω = 0, 0 in
    a rotation in place."""
    tw = np.asarray(twists, float)
    w = np.abs(tw[..., 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(w > 0, np.hypot(tw[..., 0], tw[..., 1]) / np.where(w > 0, w, 1.0),
                        np.inf)


@dataclass
class CurvatureReport:
    """The base's curvature radius R = |(vx, vy)| / |ω| over a run's moving time (some unit's
    attachment point at least ``moving_speed`` fast; the four variants share R): its least
    value ``min_radius`` [m] (inf: the base never rotates while moving) at ``t_min`` [s], and
    with a limit ``limit`` (002 eq. 26's R_min) the ``moving_fraction`` of the moving time and
    the ``longest`` stretch [s] below it (0 without a limit)."""

    limit: float | None
    moving_speed: float
    min_radius: float
    t_min: float
    moving_fraction: float
    longest: float

    @property
    def ok(self) -> bool:
        return self.limit is None or self.moving_fraction == 0.0

    def to_dict(self) -> dict[str, object]:
        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {"limit": self.limit, "moving_speed": self.moving_speed,
                "min_radius": num(self.min_radius), "t_min": num(self.t_min),
                "moving_fraction": self.moving_fraction, "longest": self.longest,
                "ok": self.ok}

    def text(self) -> list[str]:
        lim = "none" if self.limit is None else f"{self.limit:.3g} m"
        least = (f"{self.min_radius:.3f} m at t={self.t_min:.2f} s"
                 if math.isfinite(self.min_radius) else "inf (no rotation while moving)")
        out = [f"curvature radius R = |v|/|ω| while moving (002 eq. 26, limit R_min {lim}): "
               f"least {least}"]
        if self.limit is not None:
            out.append(f"  below R_min: {100 * self.moving_fraction:.1f} % of the moving time, "
                       f"longest {self.longest:.2f} s"
                       + ("" if self.ok else " (the centre of rotation comes inside the "
                          "footprint: a rotation in place or a tight turn)"))
        return out


def curvature_report(t: np.ndarray, twist: np.ndarray, positions: np.ndarray,
                     limit: float | None) -> CurvatureReport:
    """The :class:`CurvatureReport` of a run: base-frame twists (N, 3) at times t (N,), the
    units' attachment points (n, 2) [m] (what moves) and the least radius ``limit`` [m] or
    None. Vectorised over samples."""
    radius = curvature_radius(twist)
    moving = moving_mask(twist, positions)
    w = np.gradient(t) if t.size > 1 else np.ones(1)
    if moving.any():
        r_mov = np.where(moving, radius, np.inf)
        k = int(np.argmin(r_mov))
        least = float(r_mov[k])
        t_min = float(t[k]) if math.isfinite(least) else math.nan
    else:
        least, t_min = math.inf, math.nan
    frac = longest = 0.0
    if limit is not None and moving.any():
        below = moving & (radius < limit * (1 - 1e-9))
        frac = float(below @ w / (moving @ w))
        cum = np.concatenate([[0.0], np.cumsum(w)])
        edge = np.diff(np.concatenate([[0], below.astype(np.int8), [0]]))
        on, off = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
        longest = float((cum[off] - cum[on]).max(initial=0.0))
    return CurvatureReport(limit, MOVING_SPEED, least, t_min, frac, longest)
