"""Any robot's ``sensor_msgs/msg/JointState`` (MCAP or a ROS bag) as a log, through a mapping in
the platform file from joint names and fields to the unit channels.

Platform file::

    joint_state:
      topic: /joint_states                       # (default)
      channels:                                  # every column of the platform's log
        phi_0: {joint: wheel_front, field: position}
        cur_0: {joint: wheel_front, field: effort, effort_is_torque: true}
        ...

An angle channel takes a joint's ``position`` [rad]; a current channel its ``effort``: the motor
current [A], or with ``effort_is_torque: true`` the joint torque [N m], divided by the unit's
``torque_constant`` (so that the pipeline's torque is the logged effort). The sample time is the
message's header stamp. Every problem is a one-line :class:`~ropod_sysid.errors.InputError`.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import message_numbers

JOINT_STATE_SCHEMA = "sensor_msgs/msg/JointState"
DEFAULT_TOPIC = "/joint_states"
FIELDS = ("position", "velocity", "effort")


@dataclass(frozen=True)
class JointSource:
    """Where one log column comes from."""

    joint: str
    field: str
    effort_is_torque: bool = False


@dataclass(frozen=True)
class JointStateMap:
    """The platform file's ``joint_state`` mapping."""

    topic: str
    channels: tuple[tuple[str, JointSource], ...]

    def to_dict(self) -> dict[str, Any]:
        return {"topic": self.topic, "channels": {
            col: {"joint": s.joint, "field": s.field,
                  **({"effort_is_torque": True} if s.effort_is_torque else {})}
            for col, s in self.channels}}


def parse_joint_state(data: Any, where: str, angles: tuple[str, ...],
                      currents: tuple[str, ...]) -> JointStateMap:
    """Validate the ``joint_state`` mapping for a log with these angle and current columns."""
    at = f"{where}: 'joint_state'"
    if not isinstance(data, Mapping):
        raise InputError(f"{at} must be a mapping with 'topic' and 'channels'")
    topic = data.get("topic", DEFAULT_TOPIC)
    if not isinstance(topic, str) or not topic.startswith("/"):
        raise InputError(f"{at}.topic must be a topic name like /joint_states, got {topic!r}")
    chans = data.get("channels")
    if not isinstance(chans, Mapping):
        raise InputError(f"{at}.channels must map every log column to {{joint, field}}")
    known = set(angles) | set(currents)
    out = []
    for col, entry in chans.items():
        if col not in known:
            raise InputError(f"{at}.channels: '{col}' is no column of this platform's log; "
                             f"its columns are {', '.join([*angles, *currents])}")
        if not isinstance(entry, Mapping) or not isinstance(entry.get("joint"), str):
            raise InputError(f"{at}.channels.{col} must be a mapping with a 'joint' name and a "
                             "'field'")
        field = entry.get("field")
        want = ("position",) if col in angles else ("effort",)
        if field not in want:
            raise InputError(f"{at}.channels.{col}.field is {field!r}; "
                             f"{'an angle' if col in angles else 'a current'} column takes "
                             f"'{want[0]}'")
        torque = entry.get("effort_is_torque", False)
        if not isinstance(torque, bool) or (torque and col in angles):
            raise InputError(f"{at}.channels.{col}.effort_is_torque must be true or false, and "
                             "only for a current column")
        out.append((str(col), JointSource(entry["joint"], field, torque)))
    missing = [c for c in (*angles, *currents) if c not in dict(out)]
    if missing:
        raise InputError(f"{at}.channels lacks {', '.join(missing[:6])}"
                         f"{' …' if len(missing) > 6 else ''}; map every column of the log")
    return JointStateMap(topic, tuple(out))


class JointStatePieces:
    """Decoded JointState messages → one log per chunk (sample k is message k)."""

    def __init__(self, stream: Any, platform: Any, where: str) -> None:
        from ropod_sysid.io.mcapdecode import BatchDecoder, ros2_decoder

        mapping = platform.joint_state
        if mapping is None:
            raise InputError(f"{where}: the log is {JOINT_STATE_SCHEMA} on "
                             f"{stream.channel.topic}; map its joints to the unit channels in "
                             "the platform file's 'joint_state' (see docs/file-formats.md)")
        if stream.encoding != "ros2":
            raise InputError(f"{where}: {JOINT_STATE_SCHEMA} must be CDR (ROS 2) or ROS 1 "
                             "encoded")
        self.decoder = BatchDecoder("ros2", ros2_decoder(stream.schema, stream.channel.topic,
                                                         where))
        self.platform, self.where, self.map = platform, where, dict(mapping.channels)
        self.locate = message_numbers()
        lay = platform.layout
        self.columns = lay.columns()
        k_t = dict(zip(lay.current_names, platform.torque_constants(), strict=True))
        self.scale = np.array([1.0 / k_t[c] if self.map[c].effort_is_torque else 1.0
                               for c in self.columns])
        self.index: dict[tuple[str, ...], np.ndarray] = {}

    def _where(self, names: tuple[str, ...], k: int) -> np.ndarray:
        """Indices into the message's arrays of each column's joint (cached per name list)."""
        if names not in self.index:
            pos = {n: i for i, n in enumerate(names)}
            missing = [self.map[c].joint for c in self.columns if self.map[c].joint not in pos]
            if missing:
                raise InputError(f"{self.where}: message {k} has no joint "
                                 f"{missing[0]!r} (it names {', '.join(names[:8])}); fix the "
                                 "platform file's joint_state mapping")
            self.index[names] = np.array([pos[self.map[c].joint] for c in self.columns])
        return self.index[names]

    def logs(self, rows: Any, done: int, final: bool) -> Iterator[Log]:
        assert rows is not None
        msgs = [self.decoder.decode(p) for p in rows.payloads]
        n = len(msgs)
        t = np.empty(n)
        vals = np.empty((n, len(self.columns)))
        fields = [self.map[c].field for c in self.columns]
        for k, m in enumerate(msgs):
            t[k] = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
            idx = self._where(tuple(m.name), done + k)
            arrays = {"position": m.position, "effort": m.effort}
            try:
                vals[k] = [arrays[f][i] for f, i in zip(fields, idx, strict=True)]
            except IndexError:
                raise InputError(f"{self.where}: message {done + k} has fewer values than "
                                 "joint names; the recording is malformed") from None
        vals *= self.scale
        bad = ~np.isfinite(vals).all(axis=1)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InputError(f"{self.where}: message {done + k} has a NaN or infinite joint "
                             "value; the log must be finite — repair or cut the recording")
        angles, currents = self.platform.layout.split(vals)
        yield Log(t, self.platform.layout, angles, currents, None, self.where)


__all__ = ["JOINT_STATE_SCHEMA", "JointStateMap", "JointStatePieces", "parse_joint_state"]
