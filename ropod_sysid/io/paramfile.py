"""The parameter file: identified values with their standard deviations and fit statistics.

Formats (``write_parameter_file(..., fmt=...)``):

``json``
    The layout of ``docs/file-formats.md``, indent 2::

        {"platform": "ropod",
         "parameters": {"m_b": {"value": 35.1, "std": 0.4}, ...},
         "rms": {"translation": 7.03, "rotation": 1.62},
         "condition_number": 1234.5, "rank": 29, "samples": 48000}

    plus the free-form ``extras`` as further top-level keys. JSON has no NaN or infinity: such
    numbers are written as ``null`` (a ``null`` condition number reads back as infinity, a
    ``null`` std as ``None``, any other ``null`` number as NaN).
``yaml``
    The same mapping as YAML.
``ros2``
    A ROS 2 parameter file ``{node: {ros__parameters: {...}}}`` with the platform geometry under
    ``base_kin_model`` (``d_w``, ``s_w``, ``r_wL_SW<i>``, ``r_wR_SW<i>``, ``xpos_SW<i>``,
    ``ypos_SW<i>``, i = 1..n in unit order, and ``unit_names``), the values under ``dyn_model``,
    the standard deviations under ``dyn_model_std`` (unknown ones left out), the names flagged as
    combinations in ``dyn_model_combination``, and ``platform``, ``rms``, ``condition_number``,
    ``rank``, ``samples``. Extras go under ``metadata``; values ROS 2 parameters cannot hold
    (nested lists, mixed lists, empty lists) are stored as JSON strings, ``None`` is left out.
``kelo``
    The ROS 2 parameter file of the KELO driver (``kelo_tulip``'s ``platform_driver`` node,
    under ``ros__parameters``): ``num_wheels`` first, ``wheel_distance``, ``wheel_diameter``,
    ``wheel0``, ``wheel1``, … each ``{ethercat_number, x, y, a}`` (the platform file's
    per-unit ``ethercat_number``, pivot position and pivot encoder offset), and the identified
    values under ``dynamics``. Write-only.

:func:`read_parameter_file` reads json, yaml and ros2 files (YAML with the safe loader only).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.io.atomic import atomic_write_text
from ropod_sysid.model.units.swivel import check_all_swivel
from ropod_sysid.params import known_names, name_summary
from ropod_sysid.platform import Platform
from ropod_sysid.yamlload import safe_load

Format = Literal["json", "yaml", "ros2", "kelo"]
FORMATS: tuple[str, ...] = ("json", "yaml", "ros2", "kelo")
REQUIRED_KEYS = ("platform", "parameters", "rms", "condition_number", "rank", "samples")
RMS_KEYS = ("translation", "rotation")
DEFAULT_NODE = "ropod_dynamic_model"
_NUMERIC_TEXT = re.compile(r"^\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*$")


@dataclass
class ParameterFile:
    """Contents of a parameter file.

    Attributes
    ----------
    platform : str
        Platform name.
    parameters : dict
        name → ``{"value": float, "std": float | None}``, optionally ``"combination": bool``
        (the entry is an identifiable combination rather than a physical parameter).
    rms : dict
        ``{"translation": float, "rotation": float}``, residual RMS [N], [N m].
    condition_number : float
    rank : int
    samples : int
    extras : dict
        Free-form metadata written as further top-level keys (``friction``, ``span_s``,
        ``null_space``, ``input_delay_s``, ``fixed`` …).
    """

    platform: str
    parameters: dict[str, dict[str, Any]]
    rms: dict[str, float]
    condition_number: float
    rank: int
    samples: int
    extras: dict[str, Any] = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        """name → value."""
        return {k: float(v["value"]) for k, v in self.parameters.items()}

    def stds(self) -> dict[str, float | None]:
        """name → standard deviation (None when unknown)."""
        return {k: (None if v.get("std") is None else float(v["std"]))
                for k, v in self.parameters.items()}

    def to_dict(self) -> dict[str, Any]:
        """The contract layout (JSON-ready: plain Python types, non-finite numbers → None)."""
        clash = [k for k in self.extras if k in REQUIRED_KEYS]
        if clash:
            raise ValueError(f"extras may not use the contract keys {clash}")
        params: dict[str, dict[str, Any]] = {}
        for name, entry in self.parameters.items():
            e: dict[str, Any] = {"value": _finite_or_none(entry["value"]),
                                 "std": _finite_or_none(entry.get("std"))}
            if "combination" in entry:
                e["combination"] = bool(entry["combination"])
            for k, v in entry.items():
                if k not in e:
                    e[k] = _plain(v)
            params[str(name)] = e
        out: dict[str, Any] = {
            "platform": str(self.platform),
            "parameters": params,
            "rms": {k: _finite_or_none(v) for k, v in self.rms.items()},
            "condition_number": _finite_or_none(self.condition_number),
            "rank": int(self.rank),
            "samples": int(self.samples),
        }
        out.update({str(k): _plain(v) for k, v in self.extras.items()})
        return out

    @classmethod
    def from_dict(cls, data: Any, where: str = "<parameters>") -> ParameterFile:
        """Validate the contract mapping (as parsed from JSON/YAML) and build the object."""
        if not isinstance(data, dict):
            raise InputError(f"{where}: expected a mapping with keys {', '.join(REQUIRED_KEYS)}")
        for key in REQUIRED_KEYS:
            if key not in data:
                raise InputError(f"{where}: missing key '{key}'; a parameter file has "
                                 f"{', '.join(REQUIRED_KEYS)}")
        platform = data["platform"]
        if not isinstance(platform, str):
            raise InputError(f"{where}: key 'platform' must be the platform name (text), "
                             f"got {platform!r}")
        raw = data["parameters"]
        if not isinstance(raw, dict):
            raise InputError(f"{where}: key 'parameters' must be a mapping name → "
                             "{value, std}")
        parameters: dict[str, dict[str, Any]] = {}
        for name, entry in raw.items():
            key = f"parameters.{name}"
            if not isinstance(entry, dict) or "value" not in entry:
                raise InputError(f"{where}: key '{key}' must be a mapping with 'value' and "
                                 "'std', like {\"value\": 35.1, \"std\": 0.4}")
            e: dict[str, Any] = dict(entry)
            e["value"] = _number(entry["value"], f"{key}.value", where, null=math.nan)
            e["std"] = _number(entry.get("std"), f"{key}.std", where, null=None)
            if "combination" in entry and not isinstance(entry["combination"], bool):
                raise InputError(f"{where}: key '{key}.combination' must be true or false, "
                                 f"got {entry['combination']!r}")
            parameters[str(name)] = e
        rms = _rms(data["rms"], "rms", where)
        cond = _number(data["condition_number"], "condition_number", where, null=math.inf)
        rank = _integer(data["rank"], "rank", where)
        samples = _integer(data["samples"], "samples", where)
        extras = {k: v for k, v in data.items() if k not in REQUIRED_KEYS}
        return cls(platform, parameters, rms, cond, rank, samples, extras)


# ---------------------------------------------------------------------------------------------
# writing


def write_parameter_file(pf: ParameterFile, path: str | Path, fmt: Format = "json",
                         platform: Platform | None = None, *,
                         node_name: str = DEFAULT_NODE) -> None:
    """Write ``pf`` to ``path`` atomically in format ``fmt`` (json, yaml, ros2, kelo).

    ``ros2`` and ``kelo`` include the platform geometry and need ``platform``; ``node_name`` is
    the ROS 2 node the parameters are for.
    """
    if fmt == "json":
        text = json.dumps(pf.to_dict(), indent=2, allow_nan=False) + "\n"
    elif fmt == "yaml":
        text = yaml.safe_dump(pf.to_dict(), sort_keys=False, allow_unicode=True)
    elif fmt in ("ros2", "kelo"):
        if platform is None:
            raise InputError(f"{path}: the {fmt} format includes the platform geometry; "
                             "give the platform file")
        data = _ros2_dict(pf, platform, node_name) if fmt == "ros2" else _kelo_dict(pf, platform)
        text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
    else:
        raise InputError(f"{path}: unknown parameter file format {fmt!r}; use one of "
                         f"{', '.join(FORMATS)}")
    atomic_write_text(path, text)


def _geometry(platform: Platform) -> dict[str, Any]:
    """The base's kinematic model: the ropod controller's keys for a smart-wheel platform,
    else the platform file's unit entries."""
    if set(platform.types) != {"swivel"}:
        return {"units": [u.to_entry({}) for u in platform.units],
                "unit_names": list(platform.unit_names)}
    first = platform.units[0]
    kin: dict[str, Any] = {"d_w": float(first.wheel_distance),
                           "s_w": float(first.caster_offset)}
    for side in ("L", "R"):
        for i, u in enumerate(platform.units):
            kin[f"r_w{side}_SW{i + 1}"] = float(u.wheel_radius)
    for axis, c in (("x", 0), ("y", 1)):
        for i, u in enumerate(platform.units):
            kin[f"{axis}pos_SW{i + 1}"] = float(u.pivot[c])
    kin["unit_names"] = list(platform.unit_names)
    return kin


def _ros2_dict(pf: ParameterFile, platform: Platform, node_name: str) -> dict[str, Any]:
    params: dict[str, Any] = {
        "platform": str(pf.platform),
        "base_kin_model": _geometry(platform),
        "dyn_model": {str(k): float(v["value"]) for k, v in pf.parameters.items()},
        "dyn_model_std": {str(k): float(v["std"]) for k, v in pf.parameters.items()
                          if v.get("std") is not None},
    }
    combos = [str(k) for k, v in pf.parameters.items() if v.get("combination")]
    if combos:
        params["dyn_model_combination"] = combos
    params["rms"] = {str(k): float(v) for k, v in pf.rms.items()}
    params["condition_number"] = float(pf.condition_number)
    params["rank"] = int(pf.rank)
    params["samples"] = int(pf.samples)
    if pf.extras:
        params["metadata"] = _ros_mapping(pf.extras)
    return {node_name: {"ros__parameters": params}}


KELO_NODE = "platform_driver"  # the KELO ROS 2 driver's node (kelo_tulip)


def _kelo_dict(pf: ParameterFile, platform: Platform) -> dict[str, Any]:
    """The ROS 2 parameter file the KELO driver (``kelo_tulip``'s ``platform_driver``) loads:
    ``num_wheels`` first (the driver reads it before anything else), the wheel geometry, per
    wheel its ``ethercat_number`` (the platform file's per-unit key), position and pivot
    offset ``a``, and the fitted model under ``dynamics``."""
    check_all_swivel(platform, "the KELO format")
    missing = [u.name for u in platform.units if u.ethercat_number is None]
    if missing:
        raise InputError(f"{platform.source}: the KELO format needs every unit's "
                         f"'ethercat_number' (the drive's EtherCAT slave number); add it to "
                         f"unit{'s' if len(missing) > 1 else ''} {', '.join(missing)}")
    first = platform.units[0]
    data: dict[str, Any] = {
        "num_wheels": platform.n_units,
        "wheel_distance": float(first.wheel_distance),
        "wheel_diameter": 2.0 * float(first.wheel_radius),
    }
    for i, u in enumerate(platform.units):
        data[f"wheel{i}"] = {"ethercat_number": int(u.ethercat_number), "x": float(u.pivot[0]),
                             "y": float(u.pivot[1]), "a": float(u.pivot_offset)}
    data["dynamics"] = {str(k): float(v["value"]) for k, v in pf.parameters.items()}
    return {KELO_NODE: {"ros__parameters": data}}


def _ros_value(value: Any) -> Any:
    """A value ROS 2 parameters can hold, or its JSON text; None for 'leave out'."""
    value = _plain(value, keep_nonfinite=True)
    if value is None:
        return None
    if isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, dict):
        return _ros_mapping(value)
    if isinstance(value, list) and value:
        kinds = {type(v) if isinstance(v, bool | int | float | str) else object for v in value}
        if kinds == {int, float}:
            return [float(v) for v in value]
        if len(kinds) == 1 and object not in kinds:
            return value
    return json.dumps(_plain(value))


def _ros_mapping(mapping: Mapping[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in mapping.items():
        rv = _ros_value(v)
        if rv is not None:
            out[str(k)] = rv
    return out


# ---------------------------------------------------------------------------------------------
# reading


def read_parameter_file(path: str | Path) -> ParameterFile:
    """Read a json, yaml or ros2 parameter file (format recognised from its content)."""
    where = str(path)
    data = _load_mapping(Path(path), where, "parameter file")
    node = _ros2_node(data)
    kelo = node[1] if node is not None else data
    if isinstance(kelo, dict) and "wheel0" in kelo and "dynamics" in kelo \
            and "parameters" not in kelo:
        raise InputError(f"{where}: this is a KELO driver file (write-only, no statistics); "
                         "read the json, yaml or ros2 parameter file instead")
    if node is not None:
        return _from_ros2(*node, where)
    return ParameterFile.from_dict(data, where)


def read_parameters(path: str | Path, platform: Platform) -> ParameterFile:
    """A fit's parameter file, or a flat mapping name → value (a simulation's truth) as a
    parameter file of ``platform`` without standard deviations. When it is neither: the flat
    mapping's error for a file without a ``parameters`` key or a ROS 2 node (a flat mapping of
    another platform: "unknown parameter …"), else the parameter file's error."""
    try:
        return read_parameter_file(path)
    except InputError as exc:
        try:
            values = read_truth_parameters(path, platform)
        except InputError as flat:
            data = _load_mapping(Path(path), str(path), "parameter file")
            raise (flat if "parameters" not in data and _ros2_node(data) is None
                   else exc) from None
    return ParameterFile(platform.name, {k: {"value": v, "std": None} for k, v in values.items()},
                         {"translation": float("nan"), "rotation": float("nan")},
                         float("nan"), 0, 0)


def read_truth_parameters(path: str | Path, platform: Platform) -> dict[str, float]:
    """name → value from a parameter file (json/yaml/ros2) or a flat mapping name → number.

    Names must be parameter names of the platform (per-wheel, shared or body-axis friction
    names; see :func:`ropod_sysid.params.parameter_names`). A flat mapping may also carry a
    ``platform`` name, which is ignored. Parameters not given are left out (the caller decides
    defaults).
    """
    where = str(path)
    data = _load_mapping(Path(path), where, "parameter file")
    node = _ros2_node(data)
    if node is not None:
        params = node[1]
        raw = params.get("dyn_model")
        prefix = "ros__parameters.dyn_model."
        if not isinstance(raw, dict):
            raise InputError(f"{where}: key 'ros__parameters.dyn_model' is missing or not a "
                             "mapping name → value")
    elif isinstance(data, dict) and isinstance(data.get("parameters"), dict):
        raw, prefix = data["parameters"], "parameters."
    elif isinstance(data, dict):
        raw = {k: v for k, v in data.items() if not (k == "platform" and isinstance(v, str))}
        prefix = ""
    else:
        raise InputError(f"{where}: expected a mapping name → number (like m_b: 35.1) or a "
                         "parameter file")
    known = set(known_names(platform))
    out: dict[str, float] = {}
    for name, entry in raw.items():
        key = f"{prefix}{name}"
        if str(name) not in known:
            raise InputError(
                f"{where}: unknown parameter '{name}'; known names are {name_summary(platform)}"
            )
        if isinstance(entry, dict):
            if "value" not in entry:
                raise InputError(f"{where}: key '{key}' must be a number or a mapping with "
                                 "'value'")
            entry, key = entry["value"], f"{key}.value"
        value = _number(entry, key, where, null=None, allow_null=False)
        if not math.isfinite(value):
            raise InputError(f"{where}: key '{key}' must be a finite number, got {entry!r}")
        out[str(name)] = value
    return out


def _load_mapping(path: Path, where: str, what: str) -> Any:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{where}: no such {what}; check the path") from None
    except IsADirectoryError:
        raise InputError(f"{where}: is a directory, not a {what}") from None
    except UnicodeDecodeError:
        raise InputError(f"{where}: not a UTF-8 text file; a {what} is JSON or YAML text") \
            from None
    except OSError as exc:
        raise InputError(f"{where}: cannot read the {what} ({exc.strerror or exc})") from None
    if not text.strip():
        raise InputError(f"{where}: the file is empty; expected a JSON or YAML mapping")
    data: Any
    if path.suffix.lower() == ".json" or text.lstrip().startswith("{"):
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            if path.suffix.lower() == ".json":
                raise InputError(f"{where}: line {exc.lineno}: not valid JSON ({exc.msg}); fix "
                                 "the syntax") from None
            data = _yaml(text, where)
    else:
        data = _yaml(text, where)
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a mapping at the top level, got "
                         f"{type(data).__name__}")
    return data


def _yaml(text: str, where: str) -> Any:
    try:
        return safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f" line {mark.line + 1}:" if mark is not None else ""
        raise InputError(f"{where}:{line} not valid YAML; fix the syntax") from None


def _ros2_node(data: Any) -> tuple[str, dict[str, Any]] | None:
    """(node name, its ros__parameters unflattened) when ``data`` is a ROS 2 parameter file."""
    if not isinstance(data, dict):
        return None
    nodes = [(str(k), v["ros__parameters"]) for k, v in data.items()
             if isinstance(v, dict) and "ros__parameters" in v]
    if not nodes:
        return None
    for name, params in nodes:
        if isinstance(params, dict) and ("dyn_model" in params
                                         or any(str(k).startswith("dyn_model.") for k in params)):
            return name, _unflatten(params)
    name, params = nodes[0]
    return name, _unflatten(params) if isinstance(params, dict) else {}


def _unflatten(params: dict[str, Any]) -> dict[str, Any]:
    """ROS 2 allows ``a.b: 1`` as well as ``a: {b: 1}``; nest the dotted form."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        parts = str(key).split(".")
        node = out
        for p in parts[:-1]:
            if not isinstance(node.get(p), dict):
                node[p] = {}
            node = node[p]
        leaf = parts[-1]
        if isinstance(value, dict):
            nested = _unflatten(value)
            if isinstance(node.get(leaf), dict):
                node[leaf].update(nested)
            else:
                node[leaf] = nested
        else:
            node[leaf] = value
    return out


def _from_ros2(node: str, params: dict[str, Any], where: str) -> ParameterFile:
    base = f"{node}.ros__parameters"
    for key in ("platform", "dyn_model", "rms", "condition_number", "rank", "samples"):
        if key not in params:
            raise InputError(f"{where}: missing key '{base}.{key}'; not a parameter file written "
                             "by ropod-sysid (ros2 format)")
    values = params["dyn_model"]
    stds = params.get("dyn_model_std", {})
    combos = params.get("dyn_model_combination", [])
    for key, v, kind in (("dyn_model", values, dict), ("dyn_model_std", stds, dict),
                         ("dyn_model_combination", combos, list)):
        if not isinstance(v, kind):
            raise InputError(f"{where}: key '{base}.{key}' must be a "
                             f"{'mapping name → number' if kind is dict else 'list of names'}")
    parameters: dict[str, dict[str, Any]] = {}
    for name, value in values.items():
        e: dict[str, Any] = {
            "value": _number(value, f"{base}.dyn_model.{name}", where, null=math.nan),
            "std": _number(stds.get(name), f"{base}.dyn_model_std.{name}", where, null=None),
        }
        if name in combos:
            e["combination"] = True
        parameters[str(name)] = e
    for name in stds:
        if name not in values:
            raise InputError(f"{where}: key '{base}.dyn_model_std.{name}' has no value in "
                             f"'{base}.dyn_model'")
    platform = params["platform"]
    if not isinstance(platform, str):
        raise InputError(f"{where}: key '{base}.platform' must be the platform name (text)")
    metadata = params.get("metadata", {})
    if not isinstance(metadata, dict):
        raise InputError(f"{where}: key '{base}.metadata' must be a mapping")
    return ParameterFile(
        platform, parameters, _rms(params["rms"], f"{base}.rms", where),
        _number(params["condition_number"], f"{base}.condition_number", where, null=math.inf),
        _integer(params["rank"], f"{base}.rank", where),
        _integer(params["samples"], f"{base}.samples", where),
        dict(metadata),
    )


# ---------------------------------------------------------------------------------------------
# value helpers


_MISSING = object()


def _number(value: Any, key: str, where: str, null: Any = _MISSING,
            allow_null: bool = True) -> Any:
    """A float from a JSON/YAML scalar; ``null`` is what a null/absent value becomes."""
    if value is None and allow_null and null is not _MISSING:
        return null
    if isinstance(value, str) and _NUMERIC_TEXT.match(value):
        return float(value)   # YAML 1.1 reads 1e-3 (no dot) as text
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: key '{key}' must be a number, got {value!r}")
    return float(value)


def _integer(value: Any, key: str, where: str) -> int:
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where}: key '{key}' must be a whole number, got {value!r}")
    return int(value)


def _rms(value: Any, key: str, where: str) -> dict[str, float]:
    if not isinstance(value, dict):
        raise InputError(f"{where}: key '{key}' must be a mapping "
                         "{translation: number, rotation: number}")
    for k in RMS_KEYS:
        if k not in value:
            raise InputError(f"{where}: missing key '{key}.{k}'")
    return {str(k): _number(v, f"{key}.{k}", where, null=math.nan) for k, v in value.items()}


def _finite_or_none(value: Any) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def plain_data(value: Any) -> Any:
    """Plain, strict-JSON-ready data: numpy scalars/arrays, tuples → float/int/list, paths →
    text, NaN and infinities → None."""
    return _plain(value)


def _plain(value: Any, keep_nonfinite: bool = False) -> Any:
    """Plain Python data (numpy scalars/arrays, tuples → float/int/list); non-finite → None."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, dict):
        return {str(k): _plain(v, keep_nonfinite) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v, keep_nonfinite) for v in value]
    if isinstance(value, float) and not math.isfinite(value) and not keep_nonfinite:
        return None
    if isinstance(value, Path):
        return str(value)
    return value
