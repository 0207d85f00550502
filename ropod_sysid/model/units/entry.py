"""Validation of platform-file values shared by the unit types and the platform loader: each
problem is one :class:`~ropod_sysid.errors.InputError` line naming the file, the key and the fix."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from ropod_sysid.errors import InputError

UNIT_NAME = re.compile(r"^[A-Za-z0-9_]+$")


def number(data: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    """``data[key]`` as a finite float (``default`` when absent; no default: an error)."""
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


def point(entry: Mapping[str, Any], key: str, at: str, what: str) -> tuple[float, float]:
    """``entry[key]`` as two finite numbers [x, y] in metres."""
    value = entry.get(key)
    if (not isinstance(value, list | tuple) or len(value) != 2
            or not all(isinstance(p, int | float) and not isinstance(p, bool)
                       and math.isfinite(float(p)) for p in value)):
        raise InputError(f"{at}: key '{key}' must be two finite numbers [x, y] in metres "
                         f"({what})")
    return float(value[0]), float(value[1])


def unit_name(entry: Any, k: int, where: str, example: str) -> str:
    """The validated ``name`` of the entry ``units[k]`` (a mapping like ``example``)."""
    key = f"units[{k}]"
    if not isinstance(entry, Mapping):
        raise InputError(f"{where}: '{key}' must be a mapping like {example}")
    if "name" not in entry:
        raise InputError(f"{where}: '{key}' has no 'name'; give every unit a name")
    name = str(entry["name"])
    if not UNIT_NAME.match(name):
        raise InputError(f"{where}: '{key}.name' is {name!r}; use letters, digits and "
                         "underscores only")
    return name


def check_keys(entry: Mapping[str, Any], known: tuple[str, ...], at: str, type_name: str) -> None:
    """No key outside ``known`` in a unit entry."""
    unknown = sorted(set(map(str, entry)) - set(known))
    if unknown:
        raise InputError(f"{at}: unknown key '{unknown[0]}' for type {type_name}; known keys: "
                         f"{', '.join(known)}")


def resolved(entry: Mapping[str, Any], key: str, at: str, where: str,
             defaults: Mapping[str, float], positive: bool, what: str) -> float:
    """A key the entry may override: its own value, else the platform-wide one; missing from
    both is an error naming the platform file."""
    if key in entry:
        value = number(entry, key, at)
    elif key in defaults:
        value = float(defaults[key])
    else:
        raise InputError(f"{where}: missing key '{key}'; add it (SI units, see "
                         "docs/file-formats.md)")
    if positive and value <= 0:
        raise InputError(f"{at if key in entry else where}: '{key}' must be > 0, got {value:g}; "
                         f"give {what}")
    return value
