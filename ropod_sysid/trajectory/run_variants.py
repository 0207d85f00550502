"""The four variants of a run (thesis Sec. VI-A): original, mirrored, negated, mirrored-negated.

The thesis identifies on a run repeated in four variants — original, mirrored (left and right
corners swapped: vy → −vy, ω → −ω), negated (every translation and rotation with a minus sign)
and mirrored-negated — whose stacked regressors are solved together. Each variant's pose is
integrated from its own twist.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.trajectory.limits import Floor
from ropod_sysid.trajectory.setpoints import Trajectory, integrate_pose

VARIANTS = ("original", "mirrored", "negated", "mirrored_negated")
# variant → sign of (vx, vy, ω) (Sec. VI-A): mirrored swaps left and right corners
VARIANT_SIGNS: dict[str, tuple[float, float, float]] = {
    "original": (1.0, 1.0, 1.0),
    "mirrored": (1.0, -1.0, -1.0),
    "negated": (-1.0, -1.0, -1.0),
    "mirrored_negated": (-1.0, 1.0, 1.0),
}


def variant(traj: Trajectory, name: str) -> Trajectory:
    """One of the four variants of Sec. VI-A (see :data:`VARIANT_SIGNS`); pose re-integrated."""
    if name not in VARIANT_SIGNS:
        raise InputError(f"unknown variant {name!r}; known: {', '.join(VARIANTS)}")
    if name == "original":
        return traj
    sx, sy, sw = VARIANT_SIGNS[name]
    return Trajectory.from_twist(traj.t, sx * traj.vx, sy * traj.vy, sw * traj.omega,
                                 traj.planned)  # a planned leg extends the same way


def variants(traj: Trajectory) -> dict[str, Trajectory]:
    """The four variants of the thesis (Sec. VI-A): 'original', 'mirrored' (vy → −vy,
    ω → −ω: left and right corners swapped), 'negated' (vx, vy, ω all negated) and
    'mirrored_negated'. Poses are integrated from each variant's twist."""
    return {name: variant(traj, name) for name in VARIANTS}


def _variant_paths(t: np.ndarray, tw: np.ndarray) -> np.ndarray:
    """World positions (S, 4, N, 2) of the four variants of base-frame twists (S, N, 3)."""
    out = np.empty(tw.shape[:1] + (4,) + tw.shape[1:2] + (2,))
    for k, name in enumerate(VARIANTS):
        sx, sy, sw = VARIANT_SIGNS[name]
        x, y, _ = integrate_pose(t, sx * tw[..., 0], sy * tw[..., 1], sw * tw[..., 2])
        out[:, k, :, 0], out[:, k, :, 1] = x, y
    return out



def _off_floor(var: Mapping[str, Trajectory], floor: Floor) -> str | None:
    """The first variant whose planned path leaves the floor, None if all stay on it."""
    for name, vt in var.items():
        if (vt.x.min() < floor[0] or vt.x.max() > floor[1] or vt.y.min() < floor[2]
                or vt.y.max() > floor[3]):
            return name
    return None
