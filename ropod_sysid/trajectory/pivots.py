"""Pivot angles and rates of an all-swivel platform along planned motions (thesis eq. 8a).

The swivel unit type's view of :func:`ropod_sysid.trajectory.prediction.predict_angles`: the
pivot ODE itself is the type's (:mod:`ropod_sysid.model.units.swivel_motion`); these wrappers
keep the pivot angles δ, their rates and the wheel-flip flag as (…, N, n) arrays for code and
tests that work with smart-wheel platforms only. The trajectory planner, check and search work
through the unit types (any mix).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ropod_sysid.model.units import UNIT_TYPES, unit_major
from ropod_sysid.model.units.swivel import check_all_swivel
from ropod_sysid.model.units.swivel_motion import PULLING
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.prediction import predict_angles


def trailing_pivots(twist: np.ndarray, platform: Platform) -> np.ndarray:
    """Pivot angles (n,) [rad] trailing the first motion of a twist series (N, 3): every unit
    aligned with the velocity of its pivot at the first nonzero twist (the type's
    ``initial_angles``, as :func:`ropod_sysid.simulate.initial_angles`); zero if it never
    moves."""
    from ropod_sysid.model.units import trailing_start

    check_all_swivel(platform, "the pivot prediction")
    unit = UNIT_TYPES["swivel"].from_specs(platform.units, platform.friction_tanh_gain)
    return unit_major(trailing_start(unit, np.asarray(twist, float)[None]), 3)[0, :, 0]


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
    """Integrate the pivot angles of an all-swivel platform along base-frame twists (N, 3) or
    (V, N, 3) with eq. 8a, from ``delta0`` (V, n) or (n,) [rad] (default: trailing the first
    motion); the rates are those of the model's ``angle_rates`` at the integrated angles."""
    check_all_swivel(platform, "the pivot prediction")
    initial = None
    if delta0 is not None:
        d = np.asarray(delta0, float)
        initial = np.zeros((*d.shape, 3))
        initial[..., 0] = d
        initial = initial.reshape(*d.shape[:-1], -1)
    pred = predict_angles(t, twists, platform, initial)
    # an all-swivel platform's angle channels are δ, φ_L, φ_R per unit (platform order)
    return PivotPrediction(pred.angles[..., 0::3], pred.turning, pred.flags[PULLING])
