"""Dynamic parameters: names, the vector m_ext (eq. 66) and values by name.

m_ext = [m_b, Jzz_b, inertial parameters of each unit type, friction of each unit type] with the
types in the order of their first unit in the platform file. For the ropod (all ``swivel``):
[m_b, Jzz_b, m_wh, Jzz_wh, Jrot_w, f_w, f_p] with, per wheel (Table II order),
f_w = [fwv_1L, fwc_1L, fwv_1R, fwc_1R, …] (eq. 57) and, per pivot, f_p = [fpv_1, fpc_1, …]
(eq. 60); with shared coefficients f_w = [fwv, fwc] (eq. 56) and f_p = [fpv, fpc] (eq. 59).
With body-axis friction (``body``) the units' friction is replaced by the base's
``fbv_x, fbv_y, fbv_w, fbc_x, fbc_y, fbc_w`` (:mod:`ropod_sysid.model.base`). Each unit type
names its own parameters (:mod:`ropod_sysid.model.units`).

Sign convention of the thesis (eqs. 53, 58, 65): friction torques are *added* to the motor
torques, so dissipative wheel friction has negative coefficients; pivot friction acts on the
base with +τ_fp and on the hub with −τ_fp, so dissipative pivot friction has fpv, fpc ≥ 0.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.model.base import (
    BASE_PARAMETERS,
    BODY_FRICTION,
    FRICTION_SIGNS,
    PARAMETER_INFO,
)
from ropod_sysid.model.units import UNIT_TYPES, FrictionVariant, check_variant

if TYPE_CHECKING:
    from ropod_sysid.platform import Platform

Friction = FrictionVariant


def _info() -> dict[str, tuple[str, str]]:
    out = dict(PARAMETER_INFO)
    for cls in UNIT_TYPES.values():
        out.update(cls.parameter_info)
    return out


def _signs() -> dict[str, int]:
    out = dict(FRICTION_SIGNS)
    for cls in UNIT_TYPES.values():
        out.update(cls.friction_signs)
    return out


INFO = _info()
DISSIPATIVE_SIGN = _signs()  # friction family → sign of a dissipative coefficient
UNITS_OF = {k: v[0] for k, v in INFO.items()}
DESCRIPTION = {k: v[1] for k, v in INFO.items()}
INERTIAL_NAMES = frozenset(BASE_PARAMETERS).union(
    *(cls.inertial_names for cls in UNIT_TYPES.values()))


def inertial_names(platform: Platform) -> list[str]:
    """m_b, J_zz,b and the inertial parameters of the platform's unit types, in m_ext order."""
    names = list(BASE_PARAMETERS)
    for t in platform.types:  # a type also on legs shares its inertial parameters
        names += [n for n in UNIT_TYPES[t].inertial_names if n not in names]
    return names


def friction_names(platform: Platform, friction: Friction = "per-wheel") -> list[str]:
    """The friction parameters of m_ext, in order."""
    check_variant(friction)
    if friction == "body":
        return list(BODY_FRICTION)
    names: list[str] = []
    for t in platform.types:
        units = [u.name for u in platform.units if u.type == t]
        names += [n for n in UNIT_TYPES[t].friction_names(units, friction) if n not in names]
    return names


def parameter_names(platform: Platform, friction: Friction = "per-wheel") -> list[str]:
    """Names of m_ext in order: inertial parameters, then friction coefficients."""
    return inertial_names(platform) + friction_names(platform, friction)


def known_names(platform: Platform) -> list[str]:
    """Every parameter name of the platform under any friction variant."""
    out: list[str] = []
    for v in ("per-wheel", "shared", "body"):
        out += [n for n in parameter_names(platform, v) if n not in out]
    return out


def name_summary(platform: Platform) -> str:
    """The platform's parameter names in a few words, for messages."""
    per_wheel = friction_names(platform, "per-wheel")
    families = list(dict.fromkeys(kind_of(n) for n in per_wheel))
    patterns = []
    for fam in families:
        suffixes = {n[len(fam) + 1:] for n in per_wheel if kind_of(n) == fam}
        sides = {s[-1] for s in suffixes if s[:-1] in platform.unit_names and s[-1] in "LR"}
        patterns.append(f"{fam}_<u>{'L/R' if sides == {'L', 'R'} else ''}")
    shared = friction_names(platform, "shared")
    return (f"{', '.join(inertial_names(platform) + patterns)} for units "
            f"{', '.join(platform.unit_names)}, or shared {', '.join(shared)}, or body-axis "
            f"{', '.join(BODY_FRICTION)}")


def friction_of(params: Mapping[str, float]) -> Friction:
    """The friction variant a parameter set uses: ``body`` when it has body-axis friction,
    else ``per-wheel`` (shared coefficients stand in for the per-wheel ones)."""
    return "body" if any(n in params for n in BODY_FRICTION) else "per-wheel"


def kind_of(name: str) -> str:
    """The parameter family of a name: ``fwv_1L`` → ``fwv``, ``m_b`` → ``m_b``."""
    return name if name in INFO else name.split("_", 1)[0]


def is_inertial(name: str) -> bool:
    """Whether a parameter is a mass or an inertia (else a friction coefficient)."""
    return name in INERTIAL_NAMES


class Parameters(Mapping[str, float]):
    """Dynamic parameters by name (SI), as the model uses them.

    A per-wheel friction coefficient that is not given reads as the shared one of its family
    when that is given (``fwv_1L`` ← ``fwv``), else as zero: the unit types look their
    coefficients up by name (:mod:`ropod_sysid.model.units`).
    """

    def __init__(self, values: Mapping[str, float]) -> None:
        self._values = {str(k): float(v) for k, v in values.items()}

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"Parameters({self._values!r})"

    @classmethod
    def from_mapping(cls, values: Mapping[str, float], platform: Platform,
                     where: str = "<parameters>") -> Parameters:
        """Check that every inertial parameter of the platform is given; friction
        coefficients not given are zero."""
        for k in inertial_names(platform):
            if k not in values:
                raise InputError(f"{where}: parameter '{k}' is missing")
        return cls(values)

    @classmethod
    def from_vector(cls, m_ext: np.ndarray, names: Sequence[str]) -> Parameters:
        """From the vector m_ext ordered as ``names``."""
        return cls(dict(zip(names, np.asarray(m_ext, float), strict=True)))

    def value(self, name: str) -> float:
        """A parameter's value: given, or a shared friction coefficient as the mean of its
        per-wheel ones, or a per-wheel one as its shared one, else 0 for friction; a missing
        inertial parameter is an error."""
        if name in self._values:
            return self._values[name]
        fam = kind_of(name)
        if name == fam and not is_inertial(name):
            per = [v for k, v in self._values.items() if k != fam and kind_of(k) == fam]
            return float(np.mean(per)) if per else 0.0
        if fam in self._values and not is_inertial(name):
            return self._values[fam]
        if is_inertial(name):
            raise InputError(f"parameter '{name}' is missing")
        return 0.0

    def vector(self, names: Sequence[str]) -> np.ndarray:
        """m_ext ordered as ``names`` (:meth:`value` of each)."""
        return np.array([self.value(k) for k in names])

    def check_physical(self, where: str = "<parameters>") -> None:
        """Masses and inertias of a platform that can move: all ≥ 0, the base mass > 0 (a
        simulation of anything else is no simulation); one-line :class:`InputError`."""
        for k, v in self._values.items():
            if not is_inertial(k):
                continue
            if not (v > 0 if k == "m_b" else v >= 0):
                raise InputError(f"{where}: parameter '{k}' is {v:g} {UNITS_OF[k]}; the "
                                 f"{DESCRIPTION[k]} must be {'> 0' if k == 'm_b' else '≥ 0'}")

    def without_friction(self) -> Parameters:
        """The masses and inertias alone (every friction coefficient zero)."""
        return Parameters({k: v for k, v in self._values.items() if is_inertial(k)})

    def to_mapping(self) -> dict[str, float]:
        return dict(self._values)


# The name of the parameter class before unit types had their own parameters.
DynamicParameters = Parameters


def typical_parameters(platform: Platform, m_b: float, Jzz_b: float) -> Parameters:
    """Base mass and inertia as given, and each unit type's plausible inertial and per-wheel
    friction values (:meth:`UnitType.typical_parameters`): values to simulate with."""
    values = {"m_b": m_b, "Jzz_b": Jzz_b}
    for t in platform.types:
        values |= UNIT_TYPES[t].typical_parameters(
            [u.name for u in platform.units if u.type == t])
    return Parameters(values)


def thesis_fixed_masses(units: Sequence[str]) -> Parameters:
    """Plausible ropod values: the masses weighed in App. E, inertias and friction of the
    thesis's "fixed masses" column of Table II, made physically consistent (J ≥ 0, friction
    dissipative) so that they can drive a simulation."""
    return Parameters({"m_b": 35.1, "Jzz_b": 3.8145}
                      | UNIT_TYPES["swivel"].typical_parameters(list(units)))
