"""Our MCAP layout (the contract channels in an MCAP file) and its writer; read back bit for bit
by :mod:`ropod_sysid.io.mcaplog`.

Our layout is one message per control cycle holding every unit, on topic ``/ropod/sysid``:

``json`` (schema ``ropod_sysid/LogSample``, encoding ``jsonschema``, so any MCAP viewer shows it)::

    {"t": 0.005,
     "units": {"1": {"delta": 0.1, "phi_L": 2.5, "phi_R": 2.4, "cur_L": 0.3, "cur_R": -0.1}, ...},
     "pose": {"x_b": 0.0, "y_b": 0.0, "theta_b": 0.0}}          # only when the log has a pose

``ros2`` (schema ``ropod_sysid_msgs/msg/LogSample``, encoding ``ros2msg``, messages CDR): see
:data:`CONTRACT_MSGDEF` — ``float64 t`` and one ``float64[]`` per channel, in ``units`` order.

Floats are written exactly (JSON numbers in Python's shortest round-trip form, CDR float64), so
CSV → MCAP → CSV gives the identical file. Chunks are small (64 KiB before compression) so that
a damaged or truncated file loses little.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from ropod_sysid.errors import InputError
from ropod_sysid.io.atomic import atomic_path
from ropod_sysid.io.log import Log
from ropod_sysid.platform import Layout

CONTRACT_TOPIC = "/ropod/sysid"
CONTRACT_JSON_SCHEMA = "ropod_sysid/LogSample"
CONTRACT_ROS2_SCHEMA = "ropod_sysid_msgs/msg/LogSample"
ENCODINGS = ("json", "ros2")
CHUNK_SIZE = 64 * 1024
POSE_FIELDS = ("x_b", "y_b", "theta_b")
_LIBRARY = "ropod-sysid"

# rosbag2's description of a reliable, volatile publisher keeping the last 10 messages (what
# `ros2 bag play` needs to republish the channel)
OFFERED_QOS = ("- history: 1\n  depth: 10\n  reliability: 1\n  durability: 2\n"
               "  deadline:\n    sec: 9223372036\n    nsec: 854775807\n"
               "  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n"
               "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n"
               "    nsec: 854775807\n  avoid_ros_namespace_conventions: false\n")

CONTRACT_MSGDEF = """\
# One control cycle of a ropod-sysid log: the log channels of every unit (SI units).
float64 t          # time [s]
string[] units     # unit names, platform-file order; the arrays below follow it
float64[] delta    # pivot angle per unit [rad]
float64[] phi_l    # left wheel angle per unit [rad], unwrapped, rolling forward positive
float64[] phi_r    # right wheel angle per unit [rad]
float64[] cur_l    # left motor current per unit [A]
float64[] cur_r    # right motor current per unit [A]
float64[] pose     # x_b [m], y_b [m], theta_b [rad] from an external tracker, or empty
"""


def write_mcap_log(log: Log, path: str | Path, encoding: str = "json",
                   topic: str = CONTRACT_TOPIC) -> None:
    """Write ``log`` as an MCAP file in our layout (``encoding`` json or ros2), atomically."""
    if encoding not in ENCODINGS:
        raise InputError(f"{path}: unknown MCAP encoding {encoding!r}; use json or ros2")
    log_times = _log_times(log.t)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        if encoding == "json":
            _write_contract_json(log, f, topic, log_times)
        else:
            _write_contract_ros2(log, f, topic, log_times)


def _log_times(t: np.ndarray) -> list[int]:
    """Message log times [ns] from the sample times: the times themselves when they are ≥ 0
    (a wall-clock ``t`` keeps its date, so the file lines up with the other recordings of the
    run), else relative to the first sample."""
    t = np.asarray(t, dtype=np.float64)
    if t.size == 0:
        return []
    ns = np.round((t if t[0] >= 0 else t - t[0]) * 1e9)
    return np.clip(ns, 0, 2.0**63 - 1).astype(np.int64).tolist()


def new_writer(f: IO[bytes], profile: str = "") -> McapWriter:
    """An MCAP writer with our chunking (small chunks, zstd, chunk and data-section CRCs),
    started."""
    writer = McapWriter(f, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD,
                        enable_crcs=True, enable_data_crcs=True)
    writer.start(profile=profile, library=_LIBRARY)
    return writer


def contract_json_schema(layout: Layout, pose: bool) -> dict[str, Any]:
    """The JSON schema of one message of our layout (for viewers)."""
    num = {"type": "number"}
    units = list(layout.units)
    channels: dict[str, list[Any]] = {u: [] for u in units}
    for ch, i in zip(layout.angle_channels, layout.angle_unit, strict=True):
        channels[units[i]].append(ch)
    for ch, i in zip(layout.current_channels, layout.current_unit, strict=True):
        channels[units[i]].append(ch)

    def unit(u: str) -> dict[str, Any]:
        return {"type": "object",
                "properties": {c.field: {**num, "description": f"{c.description} [{c.unit}]"}
                               for c in channels[u]},
                "required": [c.field for c in channels[u]]}

    schema: dict[str, Any] = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": CONTRACT_JSON_SCHEMA,
        "description": ("One control cycle of a ropod-sysid log (SI units; see ropod-sysid's "
                        "docs/file-formats.md)."),
        "type": "object",
        "properties": {
            "t": {**num, "description": "time [s]"},
            "units": {"type": "object", "properties": {u: unit(u) for u in units},
                      "required": list(units)},
        },
        "required": ["t", "units"],
    }
    if pose:
        schema["properties"]["pose"] = {
            "type": "object",
            "description": "base pose from an external tracker [m, m, rad]",
            "properties": {k: num for k in POSE_FIELDS},
            "required": list(POSE_FIELDS),
        }
        schema["required"].append("pose")
    return schema


def _write_contract_json(log: Log, f: IO[bytes], topic: str, log_times: list[int]) -> None:
    writer = new_writer(f)
    layout = log.layout
    schema_id = writer.register_schema(
        CONTRACT_JSON_SCHEMA, "jsonschema",
        json.dumps(contract_json_schema(layout, log.pose is not None)).encode())
    channel_id = writer.register_channel(topic, "json", schema_id,
                                         {"layout": "ropod_sysid/contract"})
    t = np.asarray(log.t, dtype=np.float64).tolist()
    cols = log.columns()
    fields = layout.fields
    rows = np.column_stack([cols[c] for c in layout.columns()]).astype(np.float64).tolist()
    pose = None if log.pose is None else np.asarray(log.pose, dtype=np.float64).tolist()
    dumps = json.JSONEncoder(separators=(",", ":"), allow_nan=True).encode
    for k, tk in enumerate(t):
        units: dict[str, dict[str, float]] = {u: {} for u in layout.units}
        for (u, name), v in zip(fields, rows[k], strict=True):
            units[u][name] = v
        msg: dict[str, Any] = {"t": tk, "units": units}
        if pose is not None:
            msg["pose"] = dict(zip(POSE_FIELDS, pose[k], strict=True))
        writer.add_message(channel_id, log_times[k], dumps(msg).encode(), log_times[k], k)
    writer.finish()


def _write_contract_ros2(log: Log, f: IO[bytes], topic: str, log_times: list[int]) -> None:
    from mcap_ros2._dynamic import serialize_dynamic

    writer = new_writer(f, profile="ros2")
    encode = serialize_dynamic(CONTRACT_ROS2_SCHEMA, CONTRACT_MSGDEF)[CONTRACT_ROS2_SCHEMA]
    schema_id = writer.register_schema(CONTRACT_ROS2_SCHEMA, "ros2msg", CONTRACT_MSGDEF.encode())
    channel_id = writer.register_channel(topic, "cdr", schema_id,
                                         {"layout": "ropod_sysid/contract",
                                          "offered_qos_profiles": OFFERED_QOS})
    units = list(log.units)
    if any(ch.field not in ("delta", "phi_L", "phi_R", "cur_L", "cur_R")
           for ch in (*log.layout.angle_channels, *log.layout.current_channels)):
        raise InputError(f"{log.source}: the ROS 2 layout of ropod-sysid carries smart-wheel "
                         "(swivel) units only; write JSON MCAP or CSV for this platform")
    t = np.asarray(log.t, dtype=np.float64).tolist()
    by_name = log.columns()
    cols = [np.column_stack([by_name[f"{prefix}_{u}{side}"] for u in units]).tolist()
            for prefix, side in (("delta", ""), ("phi", "L"), ("phi", "R"), ("cur", "L"),
                                 ("cur", "R"))]
    pose = None if log.pose is None else np.asarray(log.pose, dtype=np.float64).tolist()
    for k, tk in enumerate(t):
        msg = {"t": tk, "units": units, "delta": cols[0][k], "phi_l": cols[1][k],
               "phi_r": cols[2][k], "cur_l": cols[3][k], "cur_r": cols[4][k],
               "pose": [] if pose is None else pose[k]}
        writer.add_message(channel_id, log_times[k], encode(msg), log_times[k], k)
    writer.finish()


__all__ = ["CONTRACT_MSGDEF", "CONTRACT_TOPIC", "ENCODINGS", "contract_json_schema", "new_writer",
           "write_mcap_log"]
