"""ROS 1 bags (``.bag``) and rosbag2 recordings (a directory with ``metadata.yaml``, sqlite3 or
MCAP storage), read with the `rosbags <https://gitlab.com/ternaris/rosbags>`_ library.

The same two layouts as in MCAP (:mod:`ropod_sysid.io.mcaplog`) are recognised by topic and
message type: the tool's own ``ropod_sysid_msgs/msg/LogSample`` on ``/ropod/sysid`` and the
robot's smart-wheel data (``/sw_ethercat_parser/data``). A ROS 1 message is converted to CDR
(``rosbags``' ``ros1_to_cdr``, with the message definition the bag carries) and then decoded by
the MCAP readers' batch decoders, so the checks, the damage notes and the streaming (a batch of
messages at a time, memory bounded by the chunk) are theirs. ROS 1 MCAP files (``ros1``
message encoding) go the same way (:func:`ros1_to_cdr`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import Gaps, TimeBase, checked_chunks
from ropod_sysid.platform import Platform

BATCH = 8192  # messages converted and decoded at once


def is_bag(path: str | Path) -> bool:
    """A ROS 1 bag (``.bag``) or a rosbag2 recording (a directory with ``metadata.yaml``)."""
    p = Path(path)
    return p.name.lower().endswith(".bag") or (p.is_dir() and (p / "metadata.yaml").is_file())


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.EMPTY)


def ros1_to_cdr(msgtype: str, msgdef: str, where: str) -> Callable[[bytes], bytes]:
    """A converter of ROS 1 serialised messages of ``msgtype`` (definition ``msgdef``, the
    ROS 1 text format with its ``MSG:`` sections) to CDR, or a one-line error."""
    from rosbags.typesys import get_types_from_msg

    store = _typestore()
    try:
        types: dict[str, Any] = {}
        for name, text in _sections(msgtype, msgdef):
            types.update(get_types_from_msg(text, name))
        store.register(types)
    except Exception as exc:  # noqa: BLE001 - the parser's own errors
        raise InputError(f"{where}: the message definition of {msgtype} cannot be parsed "
                         f"({type(exc).__name__}); the recording is damaged") from None
    full = _full(msgtype)
    return lambda raw: bytes(store.ros1_to_cdr(raw, full))


def _sections(msgtype: str, msgdef: str) -> list[tuple[str, str]]:
    """The (type, definition) sections of a ROS 1 / ros2msg concatenated definition."""
    lines: list[str]
    out, name, lines = [], _full(msgtype), []
    for line in msgdef.splitlines():
        if line.startswith("=" * 10):
            out.append((name, "\n".join(lines)))
            name, lines = "", []
        elif line.startswith("MSG: ") and not lines:
            name = _full(line[5:].strip())
        else:
            lines.append(line)
    out.append((name, "\n".join(lines)))
    return [(n, t) for n, t in out if n]


def _full(name: str) -> str:
    """``pkg/Type`` → ``pkg/msg/Type``."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[-1]}" if len(parts) == 2 else name


def iter_bag_log(path: str | Path, platform: Platform, chunk: int = 50_000,
                 gaps: Gaps = "error") -> Iterator[Log]:
    """The log in a ROS 1 bag or rosbag2 recording as consecutive logs of at most ``chunk``
    samples (see the module docstring); one-line :class:`InputError` when it cannot be opened
    or holds no log."""
    from mcap.records import Channel, Schema

    from ropod_sysid.io.mcaplog import McapScan, _chunks, _warned, layout_pieces, pick_stream

    where = str(path)
    reader = _open(Path(path), where)
    try:
        scan = McapScan()
        by_id: dict[int, Any] = {}
        for k, conn in enumerate(reader.connections, 1):
            by_id[k] = conn
            scan.schemas[k] = Schema(id=k, name=conn.msgtype, encoding="ros2msg",
                                     data=(conn.msgdef.data if hasattr(conn.msgdef, "data")
                                           else str(conn.msgdef or "")).encode())
            scan.channels[k] = Channel(id=k, schema_id=k, topic=conn.topic,
                                       message_encoding="cdr", metadata={})
            scan.counts[k] = int(conn.msgcount)
        scan.complete = True
        stream = pick_stream(scan, where)
        conn = by_id[stream.channel.id]
        convert = None
        if _is_ros1(reader):
            assert stream.schema is not None  # every channel has one (above)
            convert = ros1_to_cdr(conn.msgtype, stream.schema.data.decode(), where)
        pieces = layout_pieces(stream, platform, where, chunk)
        tb = TimeBase(where, pieces.locate, gaps)
        yield from _warned(checked_chunks(
            _chunks(path, chunk, scan, stream, pieces,
                    batches=_batches(reader, conn, convert, where)), tb))
    finally:
        reader.close()


def _open(path: Path, where: str) -> Any:
    from rosbags.highlevel import AnyReader

    if not path.exists():
        raise InputError(f"{where}: no such file or recording; check the path")
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags' readers raise their own errors
        what = " ".join(str(exc).split())[:80]
        raise InputError(f"{where}: cannot read the recording ({type(exc).__name__}"
                         f"{': ' + what if what else ''}); is it a ROS 1 bag or a rosbag2 "
                         "directory?") from None
    return reader


def _is_ros1(reader: Any) -> bool:
    return not getattr(reader, "is2", False)


def _batches(reader: Any, conn: Any, convert: Callable[[bytes], bytes] | None,
             where: str) -> Iterator[list[bytes]]:
    """The channel's payloads (CDR) in batches of :data:`BATCH`; damage ends the batches with
    a one-line error naming the message."""
    batch: list[bytes] = []
    k = 0
    try:
        for _, _, raw in reader.messages(connections=[conn]):
            batch.append(convert(raw) if convert is not None else bytes(raw))
            k += 1
            if len(batch) >= BATCH:
                yield batch
                batch = []
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - a damaged recording, in rosbags' words
        what = " ".join(str(exc).split())[:80]
        raise InputError(f"{where}: message {k} on {conn.topic} cannot be read "
                         f"({type(exc).__name__}{': ' + what if what else ''}); the recording "
                         "is damaged — cut it before that message") from None
    if batch:
        yield batch


__all__ = ["is_bag", "iter_bag_log", "ros1_to_cdr"]
