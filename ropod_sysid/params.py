"""Dynamic parameters: names, the vector m_ext (eq. 66) and conversion to model arrays.

m_ext = [m_b, Jzz_b, m_wh, Jzz_wh, Jrot_w, f_w, f_p] with, per wheel (Table II order),
f_w = [fwv_1L, fwc_1L, fwv_1R, fwc_1R, …] (eq. 57) and, per pivot, f_p = [fpv_1, fpc_1, …]
(eq. 60); with shared coefficients f_w = [fwv, fwc] (eq. 56) and f_p = [fpv, fpc] (eq. 59).

Sign convention of the thesis (eqs. 53, 58, 65): roll friction is *added* to the wheel torque,
so dissipative roll friction has fwv, fwc ≤ 0; pivot friction acts on the base with +τ_fp and on
the hub with −τ_fp, so dissipative pivot friction has fpv, fpc ≥ 0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ropod_sysid.errors import InputError

Friction = Literal["per-wheel", "shared"]
INERTIAL = ("m_b", "Jzz_b", "m_wh", "Jzz_wh", "Jrot_w")
UNITS_OF = {
    "m_b": "kg", "Jzz_b": "kg m²", "m_wh": "kg", "Jzz_wh": "kg m²", "Jrot_w": "kg m²",
    "fwv": "N m s/rad", "fwc": "N m", "fpv": "N m s/rad", "fpc": "N m",
}
DESCRIPTION = {
    "m_b": "platform base mass",
    "Jzz_b": "platform base inertia about z",
    "m_wh": "smart-wheel unit mass",
    "Jzz_wh": "smart-wheel unit inertia about z",
    "Jrot_w": "wheel inertia about its axle",
    "fwv": "viscous roll friction",
    "fwc": "Coulomb roll friction",
    "fpv": "viscous pivot friction",
    "fpc": "Coulomb pivot friction",
}


def parameter_names(units: Sequence[str], friction: Friction = "per-wheel") -> list[str]:
    """Names of m_ext in order: 5 inertial, then roll, then pivot friction coefficients."""
    names = list(INERTIAL)
    if friction == "shared":
        return names + ["fwv", "fwc", "fpv", "fpc"]
    if friction != "per-wheel":
        raise InputError(f"unknown friction model {friction!r}; use per-wheel or shared")
    for u in units:
        for w in "LR":
            names += [f"fwv_{u}{w}", f"fwc_{u}{w}"]
    for u in units:
        names += [f"fpv_{u}", f"fpc_{u}"]
    return names


def kind_of(name: str) -> str:
    """The parameter family of a name: ``fwv_1L`` → ``fwv``, ``m_b`` → ``m_b``."""
    return name if name in INERTIAL else name.split("_", 1)[0]


@dataclass(frozen=True)
class DynamicParameters:
    """Dynamic parameters as the model uses them (SI).

    Attributes
    ----------
    m_b, Jzz_b, m_wh, Jzz_wh, Jrot_w : float
        Inertial parameters [kg, kg m²].
    fwv, fwc : (n, 2) arrays
        Roll friction per unit and wheel (L, R) [N m s/rad, N m] (eq. 57).
    fpv, fpc : (n,) arrays
        Pivot friction per unit [N m s/rad, N m] (eq. 60).
    """

    m_b: float
    Jzz_b: float
    m_wh: float
    Jzz_wh: float
    Jrot_w: float
    fwv: np.ndarray
    fwc: np.ndarray
    fpv: np.ndarray
    fpc: np.ndarray

    @classmethod
    def from_mapping(cls, values: Mapping[str, float], units: Sequence[str],
                     where: str = "<parameters>") -> DynamicParameters:
        """Build from a name → value mapping with per-wheel or shared friction names.

        Missing friction coefficients default to zero; missing inertial parameters are an error.
        """
        for k in INERTIAL:
            if k not in values:
                raise InputError(f"{where}: parameter '{k}' is missing")
        n = len(units)
        fwv = np.full((n, 2), float(values.get("fwv", 0.0)))
        fwc = np.full((n, 2), float(values.get("fwc", 0.0)))
        fpv = np.full(n, float(values.get("fpv", 0.0)))
        fpc = np.full(n, float(values.get("fpc", 0.0)))
        for i, u in enumerate(units):
            for j, w in enumerate("LR"):
                fwv[i, j] = values.get(f"fwv_{u}{w}", fwv[i, j])
                fwc[i, j] = values.get(f"fwc_{u}{w}", fwc[i, j])
            fpv[i] = values.get(f"fpv_{u}", fpv[i])
            fpc[i] = values.get(f"fpc_{u}", fpc[i])
        return cls(*(float(values[k]) for k in INERTIAL), fwv, fwc, fpv, fpc)

    @classmethod
    def from_vector(cls, m_ext: np.ndarray, units: Sequence[str],
                    friction: Friction = "per-wheel") -> DynamicParameters:
        """Build from the vector m_ext ordered as :func:`parameter_names`."""
        names = parameter_names(units, friction)
        return cls.from_mapping(dict(zip(names, np.asarray(m_ext, float), strict=True)), units)

    def to_mapping(self, units: Sequence[str]) -> dict[str, float]:
        """Per-wheel name → value mapping."""
        out = {k: float(getattr(self, k)) for k in INERTIAL}
        for i, u in enumerate(units):
            for j, w in enumerate("LR"):
                out[f"fwv_{u}{w}"] = float(self.fwv[i, j])
                out[f"fwc_{u}{w}"] = float(self.fwc[i, j])
        for i, u in enumerate(units):
            out[f"fpv_{u}"] = float(self.fpv[i])
            out[f"fpc_{u}"] = float(self.fpc[i])
        return out

    def vector(self, units: Sequence[str], friction: Friction = "per-wheel") -> np.ndarray:
        """m_ext ordered as :func:`parameter_names`."""
        names = parameter_names(units, friction)
        per_wheel = self.to_mapping(units)
        if friction == "shared":
            per_wheel |= {"fwv": float(self.fwv.mean()), "fwc": float(self.fwc.mean()),
                          "fpv": float(self.fpv.mean()), "fpc": float(self.fpc.mean())}
        return np.array([per_wheel[k] for k in names])

    def check_physical(self, where: str = "<parameters>") -> None:
        """Masses and inertias of a platform that can move: all ≥ 0, the base mass > 0 (a
        simulation of anything else is no simulation); one-line :class:`InputError`."""
        for k in INERTIAL:
            v = float(getattr(self, k))
            if not (v > 0 if k == "m_b" else v >= 0):
                raise InputError(f"{where}: parameter '{k}' is {v:g} {UNITS_OF[k]}; the "
                                 f"{DESCRIPTION[k]} must be {'> 0' if k == 'm_b' else '≥ 0'}")

    def without_friction(self) -> DynamicParameters:
        z2, z1 = np.zeros_like(self.fwv), np.zeros_like(self.fpv)
        return DynamicParameters(self.m_b, self.Jzz_b, self.m_wh, self.Jzz_wh, self.Jrot_w,
                                 z2, z2, z1, z1)


def thesis_fixed_masses(units: Sequence[str]) -> DynamicParameters:
    """Plausible ropod values: the masses weighed in App. E, inertias and friction of the
    thesis's "fixed masses" column of Table II, made physically consistent (J ≥ 0, friction
    dissipative) so that they can drive a simulation."""
    n = len(units)
    rng = np.random.default_rng(2021)
    return DynamicParameters(
        m_b=35.1, Jzz_b=3.8145, m_wh=4.2, Jzz_wh=0.012, Jrot_w=0.0105,
        fwv=-np.abs(0.03 + 0.02 * rng.random((n, 2))),
        fwc=-np.abs(0.15 + 0.15 * rng.random((n, 2))),
        fpv=0.15 + 0.07 * rng.random(n),
        fpc=0.01 + 0.03 * rng.random(n),
    )
