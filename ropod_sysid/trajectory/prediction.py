"""Unit angles and rates predicted along planned motions, for any mix of unit types.

Every group of the platform predicts its own angles (:meth:`UnitType.predict_angles`: for the
swivel the pivot ODE of thesis eq. 8a and its wheel-flip flag; for the omni wheel the integral of
its wheel rates; for the steered wheel its planned steering) and the results are placed in the
platform's channel order, with the actuator rates at the predicted angles (each type's inverse
kinematics) for the joint-rate limits: the steering motors' (types with ``steering``) for the
steering-rate limit, the others' for the wheel-rate limit. The trajectory code asks every group
and names no joint.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.run_variants import variants
from ropod_sysid.trajectory.setpoints import Trajectory, _fine

if TYPE_CHECKING:
    from ropod_sysid.model import PlatformModel


@dataclass
class Prediction:
    """Angles and rates of the whole platform along V planned motions of N samples.

    angles, rates : (V, N, J) unit angles [rad] and rates [rad/s] in the platform's channel order
    actuator_rates : (V, N, A) rates of the actuated joints [rad/s], current-channel order
    turning : (V, N, n) rate of each unit's turning joint [rad/s] (zero for units without one)
    turning_units : (n,) True for the units whose type has a turning joint
    flags : finding (``"pulling (wheel flip)"``) → (V, N, n) bool (False for other types)
    lag : (V, N, n) quasi-steady lag (sin) of trailing units (zero for others), or None
    steering : (V, N, n) rate of each unit's actuated steering [rad/s] (zero for units without)
    steering_units : (n,) True for the units whose type has an actuated steering
    wheel_actuators : (A,) True for the actuators that drive wheels (every actuator but the
        steering motors)
    """

    angles: np.ndarray
    rates: np.ndarray
    actuator_rates: np.ndarray
    turning: np.ndarray
    turning_units: np.ndarray
    flags: dict[str, np.ndarray]
    lag: np.ndarray | None = None
    steering: np.ndarray = field(default_factory=lambda: np.zeros(0))
    steering_units: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    wheel_actuators: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    @property
    def turning_peak(self) -> float:
        """max |turning rate| over every series, sample and turning unit (nan: none)."""
        if not self.turning_units.any():
            return float("nan")
        return float(np.abs(self.turning[..., self.turning_units]).max())

    @property
    def steering_peak(self) -> float:
        """max |steering rate| over every series, sample and steered unit (nan: none)."""
        if not self.steering_units.any():
            return float("nan")
        return float(np.abs(self.steering[..., self.steering_units]).max())

    @property
    def wheel_rates(self) -> np.ndarray:
        """(V, N, A_w) rates of the actuators that drive wheels [rad/s] (the wheel-rate
        limit's; :attr:`wheel_actuators`)."""
        return self.actuator_rates[..., self.wheel_actuators]

    @property
    def flagged(self) -> bool:
        """Any unit flagged anywhere (a wheel flip)."""
        return any(bool(m.any()) for m in self.flags.values())


def trailing_points(platform: Platform) -> np.ndarray | None:
    """Attachment points (m, 2) [m] of the units that trail their velocity (types with a
    turning joint: the swivel's pivots), which planning keeps from reversing; None if none."""
    from ropod_sysid.model.units import UNIT_TYPES

    idx = [i for i, u in enumerate(platform.units) if UNIT_TYPES[u.type].turning is not None]
    return platform.positions[idx] if idx else None


def steering_points(platform: Platform) -> np.ndarray | None:
    """Attachment points (m, 2) [m] of the units with an actuated steering (the steered
    wheels: their steering axes), whose wheel-centre velocities planning keeps from turning
    faster than the steering-rate limit; None if none."""
    from ropod_sysid.model.units import UNIT_TYPES

    idx = [i for i, u in enumerate(platform.units)
           if getattr(UNIT_TYPES[u.type], "steering", None) is not None]
    return platform.positions[idx] if idx else None


def predict_angles(t: np.ndarray, twists: np.ndarray, model: PlatformModel | Platform,
                   initial: np.ndarray | None = None, twist_rates: np.ndarray | None = None,
                   planned: np.ndarray | None = None) -> Prediction:
    """Every group's angles along base-frame twists (…, N, 3) at times t (N,).

    ``model``: a :class:`~ropod_sysid.model.PlatformModel` (or a platform); ``initial`` (…, J)
    initial angles (default: each type's trailing start); with ``twist_rates`` the quasi-steady
    closed form (:meth:`UnitType.quasi_steady_angles`) instead of integration. ``planned``
    (…, N, L): the run's planned own coordinates (:attr:`PlatformModel.planned_columns`, a
    leg's extension; NaN or None: the type's default), given to the types that plan them.
    """
    from ropod_sysid.model import PlatformModel

    if isinstance(model, Platform):
        model = PlatformModel(model)
    assert isinstance(model, PlatformModel)
    tw = np.asarray(twists, float)
    lead = tw.shape[:-1]
    layout, n_units = model.layout, model.n_units
    angles = np.empty((*lead, layout.n_angles))
    rates = np.empty((*lead, layout.n_angles))
    act = np.empty((*lead, layout.n_currents))
    turning = np.zeros((*lead, n_units))
    turning_units = np.zeros(n_units, bool)
    steering = np.zeros((*lead, n_units))
    steering_units = np.zeros(n_units, bool)
    wheel_actuators = np.ones(layout.n_currents, bool)
    flags: dict[str, np.ndarray] = {}
    lag = None if twist_rates is None else np.zeros((*lead, n_units))
    first = 0
    for g, unit in model.groups:
        n_planned = len(getattr(g.type, "planned_channels", ())) * len(g.units)
        mine = None if planned is None else np.asarray(planned, float)[..., first:first
                                                                       + n_planned]
        first += n_planned
        if mine is not None and not np.isfinite(mine).all():
            mine = None
        extra = {} if not n_planned else {"legs": None if mine is None else mine[..., 0]}
        if twist_rates is not None:
            p = unit.quasi_steady_angles(t, tw, twist_rates, **extra)
        else:
            start = None if initial is None else np.asarray(initial, float)[..., g.angles]
            p = unit.predict_angles(t, tw, start, **extra)
        angles[..., g.angles] = p.angles
        rates[..., g.angles] = p.rates
        act[..., g.currents] = p.actuator
        if p.turning is not None:
            turning[..., g.units] = p.turning
            turning_units[g.units] = True
        if getattr(g.type, "steering", None) is not None:
            k = len(g.units)
            motor = np.asarray(g.currents).reshape(k, -1)[:, g.type.steering_current]
            steering[..., g.units] = act[..., motor]
            steering_units[g.units] = True
            wheel_actuators[motor] = False
        for what, mask in p.flags.items():
            flags.setdefault(what, np.zeros((*lead, n_units), bool))[..., g.units] = mask
        if lag is not None and p.lag is not None:
            lag[..., g.units] = p.lag
    return Prediction(angles, rates, act, turning, turning_units, flags, lag, steering,
                      steering_units, wheel_actuators)


def _variant_prediction(traj: Trajectory, model: PlatformModel | Platform,
                        ) -> tuple[Trajectory, np.ndarray, Prediction]:
    """The run on the fine grid (the pivot ODE is stiff: :func:`_fine`), the twists (4, N, 3)
    of its four variants there and their predicted angles."""
    from ropod_sysid.model import PlatformModel

    fine = _fine(traj)
    var = variants(fine).values()
    twists = np.stack([vt.twist() for vt in var])
    columns = (model if isinstance(model, PlatformModel) else PlatformModel(model)
               ).planned_columns
    planned = np.stack([vt.planned_series(columns) for vt in var]) if columns else None
    return fine, twists, predict_angles(fine.t, twists, model, planned=planned)
