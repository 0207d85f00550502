"""The platform file (YAML) → geometry of the base and its wheel units.

The file format is described in ``docs/file-formats.md`` ("The platform file"); all values are
SI. Loading is strict: every problem is reported as one :class:`~ropod_sysid.errors.InputError`
line that names the file and the key.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.model.units import UNIT_TYPES, WHEEL_TYPES, Channel
from ropod_sysid.model.units.entry import UNIT_NAME as UNIT_NAME
from ropod_sysid.model.units.entry import number
from ropod_sysid.model.units.swivel import SwivelSpec
from ropod_sysid.yamlload import safe_load

UnitSpec = SwivelSpec  # the default unit type's entry (``type: swivel``)
TOP_LEVEL_TEXT = {"wheel_radius": "the wheel radius R_w in metres",
                  "wheel_distance": "the distance d_w between the two wheels of a unit in metres",
                  "torque_constant": "k_t in N m/A",
                  "friction_tanh_gain": "alpha in s/rad"}


@dataclass(frozen=True)
class Group:
    """Units of one type sharing their geometry: the type, its specs, their indices among the
    platform's units, and the indices of their angle and current channels in the log."""

    type: Any  # the unit-type class (:mod:`ropod_sysid.model.units`)
    specs: tuple[Any, ...]
    units: np.ndarray  # (k,) unit indices
    angles: np.ndarray  # (k·a,) angle channel indices
    currents: np.ndarray  # (k·m,) current channel indices

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.specs]


@dataclass(frozen=True)
class Layout:
    """The log channels of a platform: per unit in platform order, its type's angle channels,
    then (separately) its current channels (``docs/file-formats.md``)."""

    units: tuple[str, ...]
    angle_names: tuple[str, ...]
    current_names: tuple[str, ...]
    wrapped: np.ndarray  # (J,) bool: angle channels to unwrap
    angle_channels: tuple[Channel, ...]
    current_channels: tuple[Channel, ...]
    angle_unit: np.ndarray  # (J,) index of the unit of each angle channel
    current_unit: np.ndarray  # (A,) index of the unit of each current channel

    @property
    def n_angles(self) -> int:
        return len(self.angle_names)

    @property
    def encoders(self) -> np.ndarray:
        """(J,) bool: the angle channels of rotary encoders [rad], whose counts
        ``--encoder-counts`` gives (a leg's extension [m] is not one)."""
        return np.array([c.unit == "rad" for c in self.angle_channels], bool)

    @property
    def n_currents(self) -> int:
        return len(self.current_names)

    def columns(self) -> list[str]:
        """The CSV columns after ``t``: per unit its angles, then its currents."""
        return [name for name, _, _ in self._order]

    @property
    def fields(self) -> list[tuple[str, str]]:
        """(unit, field) of each column of :meth:`columns`: the keys of a JSON MCAP message."""
        return [(self.units[i], ch.field) for _, i, ch in self._order]

    @cached_property
    def _order(self) -> list[tuple[str, int, Channel]]:
        out = []
        for i in range(len(self.units)):
            out += [(n, i, c) for n, u, c in zip(self.angle_names, self.angle_unit,
                                                 self.angle_channels, strict=True) if u == i]
            out += [(n, i, c) for n, u, c in zip(self.current_names, self.current_unit,
                                                 self.current_channels, strict=True) if u == i]
        return out

    def split(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (N, F) in :meth:`columns` order → (angles (N, J), currents (N, A)),
        contiguous."""
        index = {name: k for k, name in enumerate(self.columns())}
        return (np.ascontiguousarray(values[:, [index[c] for c in self.angle_names]]),
                np.ascontiguousarray(values[:, [index[c] for c in self.current_names]]))


@dataclass(frozen=True)
class Platform:
    """A base with its wheel units (thesis Appendix A, in SI units).

    Attributes
    ----------
    name : str
    friction_tanh_gain : float  α in tanh(α·rate) of the Coulomb friction terms [s/rad]
    units : the unit entries, one spec per unit (:mod:`ropod_sysid.model.units`)
    settings : the platform-wide keys of the file (``wheel_radius``, ``torque_constant`` …)
        that unit entries inherit unless they override them
    """

    name: str
    friction_tanh_gain: float
    units: tuple[Any, ...]
    settings: dict[str, float] = field(default_factory=dict, compare=False)
    source: str = field(default="<memory>", compare=False)
    joint_state: Any = field(default=None, compare=False)  # JointState mapping, if any

    @property
    def n_units(self) -> int:
        return len(self.units)

    @property
    def unit_names(self) -> list[str]:
        return [u.name for u in self.units]

    @property
    def types(self) -> list[str]:
        """The unit types present, in order of first appearance."""
        return list(dict.fromkeys(u.type for u in self.units))

    @property
    def positions(self) -> np.ndarray:
        """Attachment points of the units in the base frame, shape (n, 2) [m]."""
        return np.array([u.position for u in self.units], dtype=float).reshape(-1, 2)

    def with_positions(self, positions: np.ndarray) -> Platform:
        """A copy with the attachment points replaced (same unit names and settings)."""
        units = tuple(u.moved(p) for u, p in zip(self.units, np.asarray(positions, float),
                                                 strict=True))
        return Platform(self.name, self.friction_tanh_gain, units, dict(self.settings),
                        self.source, self.joint_state)

    @cached_property
    def layout(self) -> Layout:
        """The platform's log channels."""
        a_names, c_names, a_ch, c_ch, a_u, c_u = [], [], [], [], [], []
        for i, u in enumerate(self.units):
            cls = UNIT_TYPES[u.type]
            for ch in cls.angles:
                a_names.append(ch.column(u.name))
                a_ch.append(ch)
                a_u.append(i)
            for ch in cls.currents:
                c_names.append(ch.column(u.name))
                c_ch.append(ch)
                c_u.append(i)
        return Layout(tuple(self.unit_names), tuple(a_names), tuple(c_names),
                      np.array([c.wrapped for c in a_ch], bool), tuple(a_ch), tuple(c_ch),
                      np.array(a_u, int), np.array(c_u, int))

    @cached_property
    def groups(self) -> tuple[Group, ...]:
        """The units grouped by type and shared geometry, types in order of appearance."""
        lay = self.layout
        keyed: dict[tuple[str, Any], list[int]] = {}
        for i, u in enumerate(self.units):
            keyed.setdefault((u.type, UNIT_TYPES[u.type].group_key(u)), []).append(i)
        order = {t: k for k, t in enumerate(self.types)}
        out = []
        for (utype, _), idx in sorted(keyed.items(), key=lambda kv: order[kv[0][0]]):
            cls = UNIT_TYPES[utype]
            units = np.array(idx, int)
            out.append(Group(cls, tuple(self.units[i] for i in idx), units,
                             np.flatnonzero(np.isin(lay.angle_unit, units)),
                             np.flatnonzero(np.isin(lay.current_unit, units))))
        return tuple(out)

    def columns_text(self) -> str:
        """The log columns the platform needs, in words: ``t, delta_u, phi_uL, … for units
        1, 2`` (per unit type for a mixed platform)."""
        parts = []
        for t in self.types:
            cls = UNIT_TYPES[t]
            cols = ", ".join(c.template.replace("{u}", "u") for c in (*cls.angles, *cls.currents))
            units = ", ".join(u.name for u in self.units if u.type == t)
            parts.append(f"{cols} for unit{'s' if ',' in units else ''} {units}")
        if len(parts) == 1:
            return "t, " + parts[0]
        return "t and " + "; ".join(parts)

    def unit_of_column(self, name: str) -> str | None:
        """The unit name a column of one of the platform's types would belong to
        (``phi_7L`` → ``7``), or None."""
        import re

        templates = sorted({c.template for t in self.types
                            for c in (*UNIT_TYPES[t].angles, *UNIT_TYPES[t].currents)},
                           key=lambda tpl: -len(tpl))
        for tpl in templates:
            head, tail = tpl.split("{u}")
            m = re.fullmatch(re.escape(head) + r"(\w+?)" + re.escape(tail), name)
            if m:
                return m.group(1)
        return None

    def torque_constants(self) -> np.ndarray:
        """Torque per current of every current channel (A,) [N m/A]."""
        out = np.empty(self.layout.n_currents)
        for g in self.groups:
            out[g.currents] = g.type.from_specs(g.specs, self.friction_tanh_gain
                                                ).torque_constants()
        return out

    def to_dict(self) -> dict[str, Any]:
        """The platform as the YAML mapping of the platform file (``docs/file-formats.md``)."""
        out: dict[str, Any] = {"name": self.name}
        out.update(self.settings)
        out["friction_tanh_gain"] = self.friction_tanh_gain
        units = []
        for u in self.units:
            d = u.to_entry(self.settings)
            if u.type != "swivel":
                d = {"name": d.pop("name"), "type": d.get("type", u.type)} | {
                    k: v for k, v in d.items() if k != "type"}
            units.append(d)
        out["units"] = units
        if self.joint_state is not None:
            out["joint_state"] = self.joint_state.to_dict()
        return out


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


def _settings(data: dict[str, Any], where: str) -> dict[str, float]:
    """The platform-wide keys of the unit types, checked (numbers; positive where needed)."""
    keys: list[str] = []
    for cls in UNIT_TYPES.values():
        keys += [k for k in cls.platform_keys if k not in keys]
    out = {}
    for key in keys:
        if key in data:
            out[key] = number(data, key, where)
            if key in TOP_LEVEL_TEXT and out[key] <= 0:
                raise InputError(f"{where}: '{key}' must be > 0, got {out[key]}; give "
                                 f"{TOP_LEVEL_TEXT[key]}")
    return out


def _unit_type(entry: Any, k: int, where: str) -> Any:
    utype = str(entry.get("type", "swivel")) if isinstance(entry, dict) else "swivel"
    if utype not in WHEEL_TYPES:
        raise InputError(
            f"{where}: 'units[{k}].type' is {utype!r}; known unit types: "
            f"{', '.join(WHEEL_TYPES)} — use one of them (or leave 'type' out for swivel)")
    if isinstance(entry, dict) and "leg" in entry:  # the wheel on a leg (``<type>+leg``)
        return UNIT_TYPES[f"{utype}+leg"]
    return UNIT_TYPES[utype]


def platform_from_dict(data: Any, where: str = "<platform>", min_units: int = 2) -> Platform:
    """Validate a platform mapping (the parsed YAML) and build a :class:`Platform`."""
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a YAML mapping with keys wheel_radius, units, ...")
    settings = _settings(data, where)
    alpha = number(data, "friction_tanh_gain", where, 10.0)
    if alpha <= 0:
        raise InputError(f"{where}: 'friction_tanh_gain' must be > 0, got {alpha}; give "
                         f"{TOP_LEVEL_TEXT['friction_tanh_gain']}")
    units_raw = data.get("units")
    if units_raw is None:
        raise InputError(f"{where}: missing key 'units' (a list of {{name, pivot}} entries)")
    if not isinstance(units_raw, list):
        raise InputError(f"{where}: 'units' must be a list of {{name, pivot}} entries, got "
                         f"{units_raw!r}")
    if len(units_raw) < min_units:
        raise InputError(f"{where}: 'units' lists {len(units_raw)} unit(s); at least "
                         f"{'two' if min_units == 2 else min_units} needed — list every wheel "
                         "unit with its name and pivot")
    units = tuple(_unit_type(e, k, where).parse_entry(e, k, where, settings)
                  for k, e in enumerate(units_raw))
    seen: set[str] = set()
    for k, u in enumerate(units):
        if u.name in seen:
            raise InputError(f"{where}: 'units[{k}].name' {u.name!r} is used twice; names "
                             "must be unique")
        seen.add(u.name)
    platform = Platform(str(data.get("name", "platform")), alpha, units, settings, where)
    if "joint_state" in data:  # a robot that publishes sensor_msgs/JointState
        from ropod_sysid.io.jointstate import parse_joint_state

        lay = platform.layout
        platform = Platform(platform.name, alpha, units, settings, where,
                            parse_joint_state(data["joint_state"], where, lay.angle_names,
                                              lay.current_names))
    return platform


def platform_of(specs: Sequence[Any], name: str = "platform", friction_tanh_gain: float = 10.0,
                settings: dict[str, float] | None = None) -> Platform:
    """A platform from unit specs built in code."""
    return Platform(name, friction_tanh_gain, tuple(specs), dict(settings or {}))


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
        at = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None)
        why = f" ({' '.join(str(problem).split())})" if problem else ""
        raise InputError(f"{path}:{at} is not valid YAML{why}; fix the syntax") from None
    return platform_from_dict(data, str(path))


def save_platform(platform: Platform, path: str | Path) -> None:
    """Write a platform file (atomically)."""
    from ropod_sysid.io.atomic import atomic_write_text

    atomic_write_text(path, yaml.safe_dump(platform.to_dict(), sort_keys=False))
