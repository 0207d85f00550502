"""Limits and floor of an identification run (thesis Sec. VI-A, VII-C).

Limits, as in the thesis's experiments: |v| = |(vx, vy)| ≤ v_max [m/s], |a| ≤ a_max [m/s²] (the
world acceleration of the base origin, centripetal part included), |ω| ≤ ω_max [rad/s],
|ω̇| ≤ α_max [rad/s²], |δ̇_i| ≤ pivot_rate_max [rad/s] for units with a turning joint (the
swivel's pivot; the disturbance observer ignores the data above 1.5 rad/s, Sec. VII-C),
|β̇_i| ≤ steer_rate_max [rad/s] for units with an actuated steering (the steered wheel's steering
motor; 001's vehicle: 195.95 °/s) and, optionally, |φ̇| ≤ wheel_rate_max [rad/s] for every
other actuated joint (the units' ``actuator_rates``, e.g. a motor's top speed), and optionally the
base's curvature radius R = |(vx, vy)| / |ω| ≥ curvature_radius_min [m] wherever it rotates (002
eq. 26: the instantaneous centre of rotation stays outside the footprint, so no wheel on a leg
comes to rest in a type-A singularity while its leg is held; a rotation in place, R = 0, breaks
it; :func:`default_curvature_radius` gives a platform's default). The floor is the
rectangle (x_min, x_max, y_min, y_max) [m] the base origin must stay in, in the world frame of
the planned pose (start at the origin). A run that cannot be planned within them raises
:class:`PlanningError`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ropod_sysid.errors import InputError

Floor = tuple[float, float, float, float]
DEFAULT_FLOOR: Floor = (-3.0, 3.0, -2.0, 2.0)
# typical(), optimize(): the pivot rate (quasi-steady) is planned at 80 % of its limit
PIVOT_DESIGN_MARGIN = 0.8
STEER_RATE_MAX = 3.42  # default steering-rate limit [rad/s]: 001's 195.95 °/s
# default_curvature_radius(): R_min as a multiple of the legs' largest reach; 002's R_min =
# 0.82 m is 1.28 times the half-diagonal (0.639 m) of its largest footprint, 985 × 815 mm (eq. 26)
CURVATURE_REACH_FACTOR = 1.3


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
        Pivot rate |δ̇_i| of every unit with a turning joint (the swivel) [rad/s], predicted
        with the kinematic model; None: no limit (wheel flips allowed).
    wheel_rate_max : float or None
        Rate |φ̇| of every actuated joint that drives a wheel [rad/s], predicted with the
        units' inverse kinematics; None (default): no limit.
    steer_rate_max : float or None
        Steering rate |β̇_i| of every unit with an actuated steering (the steered wheel's
        steering motor) [rad/s], predicted from its planned steering; None: no limit.
        Default :data:`STEER_RATE_MAX`.
    curvature_radius_min : float or None
        Least curvature radius R = |(vx, vy)| / |ω| of the base's motion wherever it rotates
        [m] (002 eq. 26; a rotation in place has R = 0); None (default): no limit.
    """

    v_max: float = 1.0
    a_max: float = 1.0
    w_max: float = 1.0
    alpha_max: float = 1.0
    pivot_rate_max: float | None = 1.5
    wheel_rate_max: float | None = None
    steer_rate_max: float | None = STEER_RATE_MAX
    curvature_radius_min: float | None = None

    def __post_init__(self) -> None:
        optional = ("pivot_rate_max", "wheel_rate_max", "steer_rate_max",
                    "curvature_radius_min")
        for name in ("v_max", "a_max", "w_max", "alpha_max", *optional):
            value = getattr(self, name)
            if value is None and name in optional:
                continue
            if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
                raise InputError(f"limit {name} must be a positive number, got {value!r}")

    def scaled(self, factor: float, pivot_factor: float | None = None,
               steer_factor: float | None = None) -> Limits:
        """All limits times ``factor`` (the pivot rate times ``pivot_factor``, the steering
        rate times ``steer_factor`` if given); the least curvature radius, a lower bound,
        divided by ``factor``."""
        pf = factor if pivot_factor is None else pivot_factor
        sf = factor if steer_factor is None else steer_factor
        return Limits(self.v_max * factor, self.a_max * factor, self.w_max * factor,
                      self.alpha_max * factor,
                      None if self.pivot_rate_max is None else self.pivot_rate_max * pf,
                      None if self.wheel_rate_max is None else self.wheel_rate_max * factor,
                      None if self.steer_rate_max is None else self.steer_rate_max * sf,
                      None if self.curvature_radius_min is None
                      else self.curvature_radius_min / factor)


def default_curvature_radius(platform: object) -> float | None:
    """The default least curvature radius [m] of a platform's runs: for a platform with units
    on legs :data:`CURVATURE_REACH_FACTOR` times the farthest any leg's attachment point
    reaches from the base origin (the units' ``reach``), rounded up to the centimetre, so the
    instantaneous centre of rotation stays outside the largest footprint with a margin as in
    002 (eq. 26: 0.82 m against 0.639 m); None (no limit) for a platform without legs."""
    from ropod_sysid.model import PlatformModel

    model = platform if isinstance(platform, PlatformModel) else PlatformModel(platform)  # type: ignore[arg-type]
    reach = [float(unit.reach) for _, unit in model.groups if hasattr(unit, "reach")]
    if not reach:
        return None
    return math.ceil(CURVATURE_REACH_FACTOR * max(reach) * 100 - 1e-9) / 100


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


class PlanningError(InputError):
    """A typical run cannot be planned within the limits (one line, CLI exit 2)."""
