"""A leg's platform-file entry (``leg: {hip, axis, range}``) and the spec of a wheel unit on a
leg (:mod:`ropod_sysid.model.units.legs`): one-line errors naming the unit, the key and the fix."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ropod_sysid.errors import InputError

LEG_KEYS = ("hip", "axis", "range")
AXIS_TOLERANCE = 1e-3  # |axis| may differ from 1 by this much (then it is normalised)


@dataclass(frozen=True)
class LegSpec:
    """A leg: hip h and unit axis a in the base frame [m], its extension range [m]."""

    hip: tuple[float, float]
    axis: tuple[float, float]
    range: tuple[float, float]

    def point(self, extension: np.ndarray | float) -> np.ndarray:
        """Attachment points h + λ a (…, 2) [m] at extensions λ (…)."""
        lam = np.asarray(extension, float)[..., None]
        return np.asarray(self.hip) + lam * np.asarray(self.axis)

    @property
    def middle(self) -> float:
        """The middle of the extension range [m]."""
        return 0.5 * (self.range[0] + self.range[1])

    def to_entry(self) -> dict[str, list[float]]:
        return {"hip": list(self.hip), "axis": list(self.axis), "range": list(self.range)}


@dataclass(frozen=True)
class LeggedSpec:
    """A wheel unit (``wheel``: its type's spec, attached at the hip) on a leg."""

    wheel: Any
    leg: LegSpec

    @property
    def name(self) -> str:
        return str(self.wheel.name)

    @property
    def type(self) -> str:
        return f"{self.wheel.type}+leg"

    @property
    def position(self) -> tuple[float, float]:
        """The attachment point at the middle of the leg's range [m] (nominal)."""
        p = self.leg.point(self.leg.middle)
        return float(p[0]), float(p[1])

    def moved(self, position: Sequence[float]) -> LeggedSpec:
        """The same unit with its leg shifted so that the nominal point is ``position``."""
        shift = np.asarray(position, float) - np.asarray(self.position)
        hip = (self.leg.hip[0] + float(shift[0]), self.leg.hip[1] + float(shift[1]))
        return LeggedSpec(self.wheel.moved(hip), LegSpec(hip, self.leg.axis, self.leg.range))

    def to_entry(self, defaults: Mapping[str, Any]) -> dict[str, Any]:
        d = dict(self.wheel.to_entry(defaults))
        for key in ("pivot", "position"):
            d.pop(key, None)
        d["type"] = self.wheel.type
        d["leg"] = self.leg.to_entry()
        return d


def _pair(value: Any, at: str, key: str, what: str) -> tuple[float, float]:
    if (not isinstance(value, list | tuple) or len(value) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool)
                       and np.isfinite(float(v)) for v in value)):
        raise InputError(f"{at}: key 'leg.{key}' must be two finite numbers ({what})")
    return float(value[0]), float(value[1])


def parse_leg(entry: Mapping[str, Any], at: str) -> LegSpec:
    """The ``leg:`` mapping of a unit entry, validated; one-line errors."""
    leg = entry.get("leg")
    example = "{hip: [x, y], axis: [ex, ey], range: [lmin, lmax]}"
    if not isinstance(leg, Mapping):
        raise InputError(f"{at}: key 'leg' must be a mapping like {example}")
    unknown = sorted(set(map(str, leg)) - set(LEG_KEYS))
    if unknown:
        raise InputError(f"{at}: unknown key 'leg.{unknown[0]}'; known keys: "
                         f"{', '.join(LEG_KEYS)}")
    for key in LEG_KEYS:
        if key not in leg:
            raise InputError(f"{at}: 'leg' has no '{key}'; give it as {example}")
    hip = _pair(leg["hip"], at, "hip", "the leg's hip in the base frame in metres")
    axis = _pair(leg["axis"], at, "axis", "a unit vector along the leg in the base frame")
    norm = float(np.hypot(*axis))
    if norm == 0.0:
        raise InputError(f"{at}: 'leg.axis' is zero; give a unit vector along the leg, e.g. "
                         "[1, 0]")
    if abs(norm - 1.0) > AXIS_TOLERANCE:
        raise InputError(f"{at}: 'leg.axis' has length {norm:.4g}; give a unit vector "
                         f"(e.g. [{axis[0] / norm:.4f}, {axis[1] / norm:.4f}])")
    lo, hi = _pair(leg["range"], at, "range", "the least and greatest extension in metres")
    if not lo < hi:
        raise InputError(f"{at}: 'leg.range' is [{lo:g}, {hi:g}]; give [lmin, lmax] with "
                         "lmin < lmax in metres")
    return LegSpec(hip, (axis[0] / norm, axis[1] / norm), (lo, hi))


