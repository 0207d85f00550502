"""The platform file (YAML) → geometry of the base and its wheel units.

The file format is described in ``docs/file-formats.md`` ("The platform file"); all values are
SI. Loading is strict: every problem is reported as one :class:`~ropod_sysid.errors.InputError`
line that names the file and the key.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.yamlload import safe_load

UNIT_NAME = re.compile(r"^[A-Za-z0-9_]+$")
UNIT_TYPES = ("swivel",)


@dataclass(frozen=True)
class UnitSpec:
    """One wheel unit as the platform file describes it.

    Attributes
    ----------
    name : str
        Unit name used in log columns (``delta_<name>``, ``phi_<name>L`` …).
    pivot : tuple[float, float]
        Attachment point r_ib/b^b in the base frame [m] (Table I, in metres).
    type : str
        Unit model; ``"swivel"`` is the smart wheel of the thesis.
    left_motor : int
        For the smart-wheel data layout: which motor (1 or 2) drives the left wheel.
    sign_left, sign_right : int
        Sign of each motor's encoder and current relative to the log's conventions (+1 or -1).
    pivot_offset : float
        Pivot encoder calibration [rad], subtracted from the raw pivot angle.
    """

    name: str
    pivot: tuple[float, float]
    type: str = "swivel"
    left_motor: int = 1
    sign_left: int = 1
    sign_right: int = 1
    pivot_offset: float = 0.0


@dataclass(frozen=True)
class Platform:
    """Geometry of a swivel-wheeled platform (thesis Appendix A, in SI units).

    Attributes
    ----------
    wheel_radius : float      R_w [m]
    wheel_distance : float    d_w [m], between the two wheels of a unit
    caster_offset : float     s_w [m], pivot axis to wheel axle
    hub_com_offset : float    Δx [m], kinematic centre to unit centre of mass
    torque_constant : float   k_t [N m/A]
    friction_tanh_gain : float  α in tanh(α·rate) of the Coulomb friction terms [s/rad]
    """

    name: str
    wheel_radius: float
    wheel_distance: float
    caster_offset: float
    hub_com_offset: float
    torque_constant: float
    friction_tanh_gain: float
    units: tuple[UnitSpec, ...]
    source: str = field(default="<memory>", compare=False)

    @property
    def n_units(self) -> int:
        return len(self.units)

    @property
    def unit_names(self) -> list[str]:
        return [u.name for u in self.units]

    @property
    def pivots(self) -> np.ndarray:
        """Attachment points r_ib/b^b, shape (n, 2) [m]."""
        return np.array([u.pivot for u in self.units], dtype=float).reshape(-1, 2)

    @property
    def s_cm(self) -> float:
        """Pivot axis to hub centre of mass, s_cm = s_w − Δx [m] (below eq. 9)."""
        return self.caster_offset - self.hub_com_offset

    def with_pivots(self, pivots: np.ndarray) -> Platform:
        """A copy with the attachment points replaced (same unit names and settings)."""
        pivots = np.asarray(pivots, dtype=float)
        units = tuple(
            UnitSpec(u.name, (float(p[0]), float(p[1])), u.type, u.left_motor, u.sign_left,
                     u.sign_right, u.pivot_offset)
            for u, p in zip(self.units, pivots, strict=True)
        )
        return Platform(self.name, self.wheel_radius, self.wheel_distance, self.caster_offset,
                        self.hub_com_offset, self.torque_constant, self.friction_tanh_gain,
                        units, self.source)

    def to_dict(self) -> dict[str, Any]:
        """The platform as the YAML mapping of the platform file (``docs/file-formats.md``)."""
        units = []
        for u in self.units:
            d: dict[str, Any] = {"name": u.name, "pivot": [u.pivot[0], u.pivot[1]]}
            if u.type != "swivel":
                d["type"] = u.type
            if u.left_motor != 1:
                d["left_motor"] = u.left_motor
            if u.sign_left != 1:
                d["sign_left"] = u.sign_left
            if u.sign_right != 1:
                d["sign_right"] = u.sign_right
            if u.pivot_offset != 0.0:
                d["pivot_offset"] = u.pivot_offset
            units.append(d)
        return {
            "name": self.name,
            "wheel_radius": self.wheel_radius,
            "wheel_distance": self.wheel_distance,
            "caster_offset": self.caster_offset,
            "hub_com_offset": self.hub_com_offset,
            "torque_constant": self.torque_constant,
            "friction_tanh_gain": self.friction_tanh_gain,
            "units": units,
        }


def ropod_platform() -> Platform:
    """The ropod of the thesis (Table I converted to metres; k_t = 0.28 N m/A)."""
    return platform_from_dict(
        {
            "name": "ropod",
            "wheel_radius": 0.0525,
            "wheel_distance": 0.08,
            "caster_offset": 0.01,
            "hub_com_offset": -0.005,
            "torque_constant": 0.28,
            "friction_tanh_gain": 10.0,
            "units": [
                {"name": "1", "pivot": [0.21, 0.21]},
                {"name": "2", "pivot": [-0.21, 0.21]},
                {"name": "3", "pivot": [-0.21, -0.21]},
                {"name": "4", "pivot": [0.21, -0.21]},
            ],
        },
        "<ropod>",
    )


def _number(data: dict[str, Any], key: str, where: str, default: float | None = None) -> float:
    if key not in data:
        if default is not None:
            return default
        raise InputError(f"{where}: missing key '{key}'; add it (SI units, see "
                         "docs/file-formats.md)")
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: key '{key}' must be a number, got {value!r}; write a plain "
                         "number in SI units (e.g. 0.05 or 5e-2)")
    if not math.isfinite(float(value)):
        raise InputError(f"{where}: key '{key}' must be finite, got {value!r}; give its value "
                         "in SI units")
    return float(value)


def _unit(entry: Any, k: int, where: str) -> UnitSpec:
    key = f"units[{k}]"
    if not isinstance(entry, dict):
        raise InputError(f"{where}: '{key}' must be a mapping like {{name: \"1\", pivot: [x, y]}}")
    if "name" not in entry:
        raise InputError(f"{where}: '{key}' has no 'name'; give every unit a name")
    name = str(entry["name"])
    if not UNIT_NAME.match(name):
        raise InputError(
            f"{where}: '{key}.name' is {name!r}; use letters, digits and underscores only"
        )
    pivot = entry.get("pivot")
    if (
        not isinstance(pivot, list | tuple)
        or len(pivot) != 2
        or not all(isinstance(p, int | float) and not isinstance(p, bool) for p in pivot)
        or not all(math.isfinite(float(p)) for p in pivot)
    ):
        raise InputError(f"{where}: '{key}.pivot' must be two finite numbers [x, y] in metres")
    utype = str(entry.get("type", "swivel"))
    if utype not in UNIT_TYPES:
        raise InputError(
            f"{where}: '{key}.type' is {utype!r}; known unit types: {', '.join(UNIT_TYPES)} — "
            "use one of them (or leave 'type' out for swivel)"
        )
    left_motor = entry.get("left_motor", 1)
    if left_motor not in (1, 2):
        raise InputError(f"{where}: '{key}.left_motor' must be 1 or 2, got {left_motor!r}")
    signs = []
    for s in ("sign_left", "sign_right"):
        v = entry.get(s, 1)
        if v not in (1, -1):
            raise InputError(f"{where}: '{key}.{s}' must be 1 or -1, got {v!r}")
        signs.append(int(v))
    offset = _number(entry, "pivot_offset", f"{where}: '{key}'", 0.0) if "pivot_offset" in entry \
        else 0.0
    return UnitSpec(name, (float(pivot[0]), float(pivot[1])), utype, int(left_motor),
                    signs[0], signs[1], offset)


def platform_from_dict(data: Any, where: str = "<platform>") -> Platform:
    """Validate a platform mapping (the parsed YAML) and build a :class:`Platform`."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a YAML mapping with keys wheel_radius, units, ...")
    r_w = _number(data, "wheel_radius", where)
    d_w = _number(data, "wheel_distance", where)
    s_w = _number(data, "caster_offset", where)
    dx = _number(data, "hub_com_offset", where, 0.0)
    k_t = _number(data, "torque_constant", where)
    alpha = _number(data, "friction_tanh_gain", where, 10.0)
    for key, value, what in (("wheel_radius", r_w, "the wheel radius R_w in metres"),
                             ("wheel_distance", d_w, "the distance d_w between the two wheels "
                              "of a unit in metres"),
                             ("torque_constant", k_t, "k_t in N m/A"),
                             ("friction_tanh_gain", alpha, "alpha in s/rad")):
        if value <= 0:
            raise InputError(f"{where}: '{key}' must be > 0, got {value}; give {what}")
    if s_w == 0:
        raise InputError(
            f"{where}: 'caster_offset' must be nonzero (the swivel model needs s_w ≠ 0); give "
            "the distance from the pivot axis to the wheel axle in metres"
        )
    units_raw = data.get("units")
    if units_raw is None:
        raise InputError(f"{where}: missing key 'units' (a list of {{name, pivot}} entries)")
    if not isinstance(units_raw, list):
        raise InputError(f"{where}: 'units' must be a list of {{name, pivot}} entries, got "
                         f"{units_raw!r}")
    if len(units_raw) < 2:
        raise InputError(f"{where}: 'units' lists {len(units_raw)} unit(s); at least two needed "
                         "— list every wheel unit with its name and pivot")
    units = tuple(_unit(e, k, where) for k, e in enumerate(units_raw))
    seen: set[str] = set()
    for k, u in enumerate(units):
        if u.name in seen:
            raise InputError(f"{where}: 'units[{k}].name' {u.name!r} is used twice; names "
                             "must be unique")
        seen.add(u.name)
    return Platform(str(data.get("name", "platform")), r_w, d_w, s_w, dx, k_t, alpha, units,
                    where)


def load_platform(path: str | Path) -> Platform:
    """Read and validate a platform YAML file (safe loader only)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: no such platform file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read platform file ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise InputError(f"{path}: line {line} is not UTF-8 text; save the platform file as "
                         "UTF-8") from None
    try:
        data = safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None)
        why = f" ({' '.join(str(problem).split())})" if problem else ""
        raise InputError(f"{path}:{line} is not valid YAML{why}; fix the syntax") from None
    return platform_from_dict(data, str(path))


def save_platform(platform: Platform, path: str | Path) -> None:
    """Write a platform file (atomically)."""
    from ropod_sysid.io.atomic import atomic_write_text

    atomic_write_text(path, yaml.safe_dump(platform.to_dict(), sort_keys=False))
