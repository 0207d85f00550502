"""MCAP logs read: our contract layout (written by :mod:`ropod_sysid.io.mcapwrite`, JSON or
ROS 2 CDR, one message per control cycle on ``/ropod/sysid``) and the robot's smart-wheel layout
(:mod:`ropod_sysid.io.smartwheel`), back bit for bit.

Reading (:func:`read_mcap_log`, :func:`iter_mcap_log` in chunks) iterates the records in file
order without seeking, so files without index or summary (a recording that was cut off) read
too. A chunk of only messages is split into payloads without a record object per message
(:class:`MessageRun`), and the payloads are decoded a batch at a time
(:mod:`ropod_sysid.io.mcapdecode`). It recognises our layout (JSON or
ROS 2) and the smart-wheel layout (:mod:`ropod_sysid.io.smartwheel`) by schema and topic names.
Damage — truncation, a CRC mismatch, a broken compressed chunk, an unreadable record or message —
stops reading there: what came before is kept with a warning (``warnings.warn`` and
``Log.notes``) that says how many messages were recovered, or, when too little is left, the file is
refused with a one-line :class:`InputError`.
"""

from __future__ import annotations

import os
import struct
import sys
import warnings
import zlib
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from itertools import compress
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.exceptions import EndOfFile, InvalidMagic, McapError, RecordLengthLimitExceeded
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, MessageIndex, Schema
from mcap.stream_reader import (
    CRCValidationError,
    StreamReader,
    breakup_chunk,
    get_chunk_data_stream,
)

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log, join_logs
from ropod_sysid.io.mcapdecode import ContractPieces, Rows
from ropod_sysid.io.mcapwrite import (
    CONTRACT_JSON_SCHEMA,
    CONTRACT_ROS2_SCHEMA,
    CONTRACT_TOPIC,
)
from ropod_sysid.io.timebase import Gaps, TimeBase, checked_chunks
from ropod_sysid.platform import Platform

try:  # the compressors mcap uses; their errors mean a broken chunk
    from zstandard import ZstdError
except ImportError:  # pragma: no cover - zstandard comes with mcap
    class ZstdError(Exception):  # type: ignore[no-redef]
        pass

MIN_SAMPLES = 3
UNIT_FIELDS = ("delta", "phi_L", "phi_R", "cur_L", "cur_R")
_MAX_CHUNK = 1 << 30   # a larger uncompressed chunk size is taken for damage

# Everything the mcap reader and the decompressors raise on a damaged file, and what parsing
# garbage as records can raise. Caught only around the calls that read the file.
READ_ERRORS: tuple[type[BaseException], ...] = (
    McapError, ValueError, struct.error, EOFError, LookupError, TypeError, AttributeError,
    ArithmeticError, MemoryError, RuntimeError, OSError, ZstdError,
)


# ---------------------------------------------------------------------------------------------
# reading: records in file order, stopping at damage


@dataclass
class McapScan:
    """What a pass over an MCAP file found, up to the first damage."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: dict[int, list[Message]] = field(default_factory=dict)   # channel id → messages
    counts: dict[int, int] = field(default_factory=dict)   # channel id → number of messages
    damage: str | None = None          # what stopped reading, None for an intact file
    complete: bool = False             # the whole data section was read (damage, if any, is
                                       # in the summary, the footer or outside the chunks)
    size: int = 0

    @property
    def n_messages(self) -> int:
        return sum(self.counts.values())


class _Bounded:
    """A file that never reads past its end, whatever length a damaged record asks for."""

    def __init__(self, f: IO[bytes], size: int) -> None:
        self._f, self.size, self.pos = f, size, 0

    def read(self, n: int = -1) -> bytes:
        n = self.size - self.pos if n is None or n < 0 else min(n, self.size - self.pos)
        data = self._f.read(n) if n > 0 else b""
        self.pos += len(data)
        return data


class _Reader(StreamReader):
    """The ``mcap`` stream reader, but a message index (16 bytes per message, which we never
    use) is passed over in one read instead of parsed entry by entry: the same bytes are
    consumed (and CRC-checked), and a file that ends inside it ends there as well."""

    def _read_record(self, opcode: int, length: int) -> Any:
        if opcode != Opcode.MESSAGE_INDEX:
            return super()._read_record(opcode, length)
        stream = self._stream
        channel_id = stream.read2()
        size = stream.read4()
        size += -size % 16                    # whole (timestamp, offset) entries, as read
        if size and len(stream.read(size)) < size:
            raise EndOfFile()
        return MessageIndex(channel_id, [])


def _open_binary(path: Path, where: str) -> IO[bytes]:
    try:
        return open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:
        raise InputError(f"{where}: no such log file; check the path") from None
    except IsADirectoryError:
        raise InputError(f"{where}: is a directory, not an MCAP log file; give the file") \
            from None
    except OSError as exc:
        raise InputError(f"{where}: cannot read the log file ({exc.strerror or exc})") from None


def scan_mcap(path: str | Path, keep_messages: bool = True) -> McapScan:
    """All schemas, channels and messages of an MCAP file in file order, up to any damage
    (without ``keep_messages`` the messages are only counted, :attr:`McapScan.counts`).

    Raises :class:`InputError` only when the file is not MCAP at all (missing, empty, wrong
    magic, unreadable first record); damage further on is reported in :attr:`McapScan.damage`.
    """
    scan = McapScan()
    for record in _records(path, scan, light=not keep_messages):
        _take(scan, record, keep_messages)
    return scan


class MessageRun:
    """The messages of a chunk, parsed only as far as their channels and payloads (the
    payloads of a chunk of equal records are cut when asked for)."""

    __slots__ = ("_cut", "_data", "channels")

    def __init__(self, channels: list[int], data: list[bytes] | None = None,
                 cut: Any = None) -> None:
        self.channels, self._data, self._cut = channels, data, cut

    @property
    def data(self) -> list[bytes]:
        if self._data is None:
            self._data = self._cut()
        return self._data

    def of(self, channel_id: int) -> list[bytes]:
        """The payloads on one channel."""
        if self.channels.count(channel_id) == len(self.channels):
            return self.data
        return list(compress(self.data, [c == channel_id for c in self.channels]))


def _records(path: str | Path, scan: McapScan, light: bool = False
             ) -> Generator[Any, None, None]:
    """The records of an MCAP file in file order (chunks broken up), up to the first damage,
    which is noted in ``scan`` (with :attr:`McapScan.complete` and the size) as
    :func:`scan_mcap` describes. ``light``: a chunk of only messages comes as one
    :class:`MessageRun` instead of :class:`Message` records."""
    where = str(path)
    path = Path(path)
    with _open_binary(path, where) as f:
        try:
            scan.size = os.fstat(f.fileno()).st_size
        except OSError:
            scan.size = 0
        if scan.size == 0:
            raise InputError(f"{where}: the file is empty; an MCAP log was expected")
        src = _Bounded(f, scan.size)
        reader = _Reader(src, emit_chunks=True, validate_crcs=True,  # type: ignore[arg-type]
                         record_size_limit=scan.size)
        records = reader.records
        good_end = 0        # end of the last record read intact
        first = True
        footer: Footer | None = None
        while True:
            try:
                record = next(records)   # after the footer: checks the closing magic bytes
                inner = ((_light_records if light else _chunk_records)(record)
                         if isinstance(record, Chunk) else [record])
            except StopIteration:
                if footer is None and scan.damage is None:
                    scan.damage = (f"the file ends after byte {good_end} without a footer — "
                                   "truncated")
                break
            except InvalidMagic:
                if first:
                    raise InputError(
                        f"{where}: not an MCAP file (it does not start with the MCAP magic "
                        "bytes); give a .mcap log, or a .csv file for a CSV log") from None
                scan.damage = "bad magic bytes at the end of the file"
                break
            except READ_ERRORS as exc:
                what = _what(exc, good_end, src.pos >= scan.size, src.pos == good_end)
                if first:
                    raise InputError(f"{where}: not a readable MCAP file ({what})") from None
                scan.damage = what
                if isinstance(exc, CRCValidationError) and isinstance(exc.record, DataEnd):
                    scan.complete = True    # every message was read; the damage is elsewhere
                break
            first = False
            for r in inner:
                yield r
                if isinstance(r, DataEnd):
                    scan.complete = True
                elif isinstance(r, Footer):
                    footer = r
                    if not _summary_crc_ok(f, r, good_end):
                        scan.damage = "CRC mismatch of the summary section"
            good_end = src.pos


def _summary_crc_ok(f: IO[bytes], footer: Footer, footer_start: int) -> bool:
    """Check the footer's summary CRC (the stream reader does not): it covers the summary
    section and the footer up to the CRC field. True when there is nothing to check."""
    if footer.summary_crc == 0 or footer.summary_start == 0:
        return True
    end = footer_start + 1 + 8 + 8 + 8       # opcode, length, summary_start, offset_start
    if not 0 < footer.summary_start <= footer_start:
        return False
    try:
        here = f.tell()
        f.seek(footer.summary_start)
        data = f.read(end - footer.summary_start)
        f.seek(here)
    except (OSError, ValueError):
        return True     # not seekable: nothing to check
    return zlib.crc32(data) == footer.summary_crc


def _chunk_records(chunk: Chunk) -> list[Any]:
    if chunk.uncompressed_size > _MAX_CHUNK:
        raise ValueError(f"implausible chunk size {chunk.uncompressed_size}")
    return breakup_chunk(chunk, validate_crc=True)


_MESSAGE_HEAD = struct.Struct("<BQH")      # opcode, record length, channel id


def _light_records(chunk: Chunk) -> list[Any]:
    """:func:`_chunk_records` for a chunk of only well-formed messages, as a
    :class:`MessageRun`; any other chunk is broken up by the ``mcap`` library."""
    if chunk.uncompressed_size > _MAX_CHUNK:
        raise ValueError(f"implausible chunk size {chunk.uncompressed_size}")
    stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    data = stream.read(size)
    run = _uniform_run(data, size)
    if run is not None:
        return [run]
    channels: list[int] = []
    ends: list[int] = []
    head = _MESSAGE_HEAD.unpack_from
    pos = 0
    try:
        while pos < size:
            op, length, cid = head(data, pos)
            end = pos + 9 + length
            if op != Opcode.MESSAGE or length < 22 or end > size:
                return breakup_chunk(chunk, validate_crc=True)
            channels.append(cid)
            ends.append(end)
            pos = end
    except struct.error:
        return breakup_chunk(chunk, validate_crc=True)
    if not ends:
        return []
    return [MessageRun(channels, cut=lambda: [data[s + 31:e] for s, e in
                                              zip([0, *ends[:-1]], ends, strict=True)])]


def _uniform_run(data: bytes, size: int) -> MessageRun | None:
    """The messages of a chunk whose records are all messages of one length (a fixed-layout
    channel), found with numpy; None for any other chunk."""
    if size < 31:
        return None
    op, length, _ = _MESSAGE_HEAD.unpack_from(data, 0)
    step = 9 + length
    if op != Opcode.MESSAGE or length < 22 or size % step:
        return None
    rows = np.frombuffer(data, dtype=np.uint8).reshape(-1, step)
    if not ((rows[:, 0] == op).all() and (rows[:, 1:9] == rows[0, 1:9]).all()):
        return None
    channels = rows[:, 9:11].copy().view("<u2").ravel().tolist()
    return MessageRun(channels, cut=lambda: [data[p:p + length - 22]
                                             for p in range(31, size, step)])


def _take(scan: McapScan, record: Any, keep_messages: bool = True) -> None:
    # the first copy counts: the summary repeats schemas and channels, and is read last
    if isinstance(record, Schema):
        scan.schemas.setdefault(record.id, record)
    elif isinstance(record, Channel):
        scan.channels.setdefault(record.id, record)
    elif isinstance(record, Message):
        cid = record.channel_id
        scan.counts[cid] = scan.counts.get(cid, 0) + 1
        if keep_messages:
            scan.messages.setdefault(cid, []).append(record)
    elif isinstance(record, MessageRun):
        for cid in set(record.channels):
            scan.counts[cid] = scan.counts.get(cid, 0) + record.channels.count(cid)


def _what(exc: BaseException, good_end: int, at_eof: bool, boundary: bool) -> str:
    """What went wrong after byte ``good_end``, in words."""
    if (at_eof or isinstance(exc, EndOfFile)) and boundary:
        return f"the file ends after byte {good_end}, before its end records — truncated"
    if at_eof or isinstance(exc, EndOfFile):
        return f"the file ends in the middle of a record after byte {good_end} — truncated"
    if isinstance(exc, RecordLengthLimitExceeded):
        return (f"the record after byte {good_end} runs past the end of the file — truncated, "
                "or a corrupt record length")
    if isinstance(exc, CRCValidationError):
        kind = type(exc.record).__name__
        return (f"CRC mismatch of the compressed chunk after byte {good_end}" if kind == "Chunk"
                else "CRC mismatch of the data section, outside the CRC-checked chunks")
    if isinstance(exc, ZstdError | RuntimeError):
        return f"broken compressed chunk after byte {good_end} ({type(exc).__name__})"
    text = " ".join(str(exc).split())[:80]
    return f"unreadable record after byte {good_end} ({type(exc).__name__}" \
           f"{': ' + text if text else ''})"


# ---------------------------------------------------------------------------------------------
# reading: layouts


@dataclass
class Stream:
    """The messages of the channel holding the log, and how to decode them."""

    layout: str          # "contract" or "smartwheel"
    encoding: str        # "json" or "ros2"
    channel: Channel
    schema: Schema | None
    messages: list[Message]


def layout_of(channel: Channel, schema: Schema | None) -> tuple[str, str] | None:
    """(layout, encoding) of a channel when it is one we read, else None."""
    from ropod_sysid.io.smartwheel import SW_TOPIC, is_smartwheel_schema

    name = schema.name if schema is not None else ""
    enc = channel.message_encoding
    # (ROS 1 messages are converted to CDR as they are read: iter_mcap_log)
    encoding = "json" if enc == "json" else "ros2" if enc in ("cdr", "ros1") else None
    if encoding is None:
        return None
    if name in (CONTRACT_JSON_SCHEMA, CONTRACT_ROS2_SCHEMA, "ropod_sysid_msgs/LogSample"):
        return "contract", encoding
    if is_smartwheel_schema(name) or channel.topic == SW_TOPIC:
        return "smartwheel", encoding
    if channel.topic == CONTRACT_TOPIC:
        return "contract", encoding
    if name in ("sensor_msgs/msg/JointState", "sensor_msgs/JointState"):
        return "jointstate", encoding
    return None


def pick_stream(scan: McapScan, where: str) -> Stream:
    """The channel that holds the log (ours, else the smart-wheel data), or a one-line error."""
    found = []
    for cid, channel in scan.channels.items():
        schema = scan.schemas.get(channel.schema_id)
        lay = layout_of(channel, schema)
        if lay is not None:
            found.append(Stream(lay[0], lay[1], channel, schema, scan.messages.get(cid, [])))
    if not found:
        if not scan.channels:
            raise _no_data(scan, where, "no channels")
        listed = ", ".join(
            f"{c.topic} ({scan.schemas[c.schema_id].name if c.schema_id in scan.schemas else 'no schema'}, {c.message_encoding})"  # noqa: E501
            for c in list(scan.channels.values())[:5])
        raise InputError(
            f"{where}: no ropod-sysid log or smart-wheel data in this MCAP file (channels: "
            f"{listed}); expected topic {CONTRACT_TOPIC} or /sw_ethercat_parser/data")
    order = {"contract": 0, "smartwheel": 1, "jointstate": 2}
    found.sort(key=lambda s: (order[s.layout], -scan.counts.get(s.channel.id, 0)))
    return found[0]


def _no_data(scan: McapScan, where: str, what: str) -> InputError:
    if scan.damage:
        return InputError(f"{where}: damaged MCAP file ({scan.damage}); no messages could be "
                          "recovered")
    return InputError(f"{where}: the MCAP file has {what}; no log messages to read")


def read_mcap_log(path: str | Path, platform: Platform, gaps: Gaps = "error") -> Log:
    """Read an MCAP log (our layout, JSON or ROS 2, or the smart-wheel layout) for ``platform``.

    Damage stops reading: the messages before it are kept with a warning (``warnings.warn`` and
    ``Log.notes``) saying how many were recovered; with fewer than 3 recovered, or when the file
    is no MCAP at all, :class:`InputError` (one line) is raised; so is a bad time base
    (:mod:`ropod_sysid.io.timebase`; ``gaps="allow"``: gaps in time are let through).
    """
    return join_logs(list(iter_mcap_log(path, platform, chunk=sys.maxsize, gaps=gaps)))


BATCH = 8192     # payloads decoded at once


def iter_mcap_log(path: str | Path, platform: Platform, chunk: int = 50_000,
                  gaps: Gaps = "error") -> Iterator[Log]:
    """:func:`read_mcap_log` as consecutive logs of at most ``chunk`` samples, in memory
    bounded by the chunk: a first pass over the records finds the channels, counts the
    messages and notes any damage (nothing is kept), a second decodes the chosen channel's
    messages a batch at a time (:mod:`ropod_sysid.io.mcapdecode`). The same checks and
    messages as one piece, numbered in the whole file; the time base is checked as the chunks
    come (:func:`ropod_sysid.io.timebase.checked_chunks`); the notes (damage, dropped
    smart-wheel frames) and their warnings come with the last chunk, after its checks.
    """
    if chunk < 1:
        raise ValueError(f"chunk must be positive, got {chunk}")
    where = str(path)
    scan = scan_mcap(path, keep_messages=False)
    stream = pick_stream(scan, where)
    batches = None
    if stream.channel.message_encoding == "ros1":
        stream, batches = _ros1_stream(path, stream, where)
    pieces = layout_pieces(stream, platform, where, chunk)
    tb = TimeBase(where, pieces.locate, gaps)
    return _warned(checked_chunks(_chunks(path, chunk, scan, stream, pieces, batches), tb))


def layout_pieces(stream: Stream, platform: Platform, where: str, chunk: int) -> Any:
    """The decoder of the stream's layout: the tool's own, the smart-wheel data, or a
    JointState mapped in the platform file (:mod:`ropod_sysid.io.jointstate`)."""
    if stream.layout == "contract":
        return ContractPieces(stream, platform, where)
    if stream.layout == "jointstate":
        from ropod_sysid.io.jointstate import JointStatePieces

        return JointStatePieces(stream, platform, where)
    from ropod_sysid.io.swframes import SmartWheelPieces

    return SmartWheelPieces(stream, platform, where, chunk)


def _ros1_stream(path: str | Path, stream: Stream, where: str
                 ) -> tuple[Stream, Iterator[list[bytes]]]:
    """A ROS 1 channel of an MCAP file (``ros1`` profile) as a CDR one: its ``ros1msg``
    schema read as ``ros2msg`` (the text formats agree for the messages read here) and its
    payloads converted as they are read (:func:`ropod_sysid.io.rosbag.ros1_to_cdr`)."""
    from ropod_sysid.io.rosbag import ros1_to_cdr

    schema = stream.schema
    if schema is None:
        raise InputError(f"{where}: channel {stream.channel.topic} is ROS 1 encoded but has no "
                         "schema; it cannot be decoded")
    convert = ros1_to_cdr(schema.name, schema.data.decode(), where)
    as_cdr = Stream(stream.layout, "ros2", stream.channel,
                    Schema(id=schema.id, name=schema.name, encoding="ros2msg",
                           data=schema.data), stream.messages)
    return as_cdr, ([convert(r) for r in raw]
                    for raw in _payload_batches(path, stream.channel.id))


def _payload_batches(path: str | Path, cid: int) -> Iterator[list[bytes]]:
    """The payloads of channel ``cid`` in file order, in batches of about :data:`BATCH`,
    read as they are needed (the reader stops where the file is damaged)."""
    records = _records(path, McapScan(), light=True)
    raw: list[bytes] = []
    try:
        for record in records:
            if isinstance(record, MessageRun):
                raw.extend(record.of(cid))
            elif isinstance(record, Message) and record.channel_id == cid:
                raw.append(record.data)
            if len(raw) >= BATCH:
                yield raw
                raw = []
    finally:
        records.close()
    if raw:
        yield raw


def _warned(logs: Iterator[Log]) -> Iterator[Log]:
    """The chunks, each one's notes warned as it is handed on (time checked by then)."""
    for log in logs:
        for note in log.notes:
            warnings.warn(note, stacklevel=2)
        yield log


def _chunks(path: str | Path, chunk: int, scan: McapScan, stream: Stream, pieces: Any,
            batches: Iterator[list[bytes]] | None = None) -> Iterator[Log]:
    """The chunks of :func:`iter_mcap_log`, before the time checks; ``batches``: the
    channel's payloads from another recording format (:mod:`ropod_sysid.io.rosbag`) instead
    of the MCAP file's records."""
    where = str(path)
    cid = stream.channel.id
    damage = scan.damage
    pending: list[Rows] = []
    n_pending = 0
    decoded = 0      # messages decoded
    done = 0         # messages handed on
    raw: list[bytes] = []

    def decode() -> bool:
        """Decode ``raw`` into ``pending``; False at a message that cannot be decoded."""
        nonlocal damage, decoded, n_pending
        rows, bad, exc = pieces.decoder(raw[:])
        if len(rows):
            pending.append(rows)
            n_pending += len(rows)
        decoded += len(rows)
        raw.clear()
        if bad is not None:
            damage = _undecodable(decoded, stream, exc)
            return False
        return True

    def ready() -> Iterator[Log]:
        nonlocal done, n_pending, pending
        while n_pending > chunk:          # one held back: the last chunk is never empty
            rows = Rows.join(pending)
            pending, n_pending = [rows.take(chunk)], n_pending - chunk
            yield from pieces.logs(rows.take(0, chunk), done, False)
            done += chunk

    source = _payload_batches(path, cid) if batches is None else batches
    try:
        for batch in source:
            raw.extend(batch)
            if not decode():
                break
            yield from ready()
        else:
            decode()
    finally:
        close = getattr(source, "close", None)
        if close is not None:
            close()
    yield from ready()
    _check_recovered(decoded, damage, stream, where)
    rows = Rows.join(pending) if pending else None
    out = list(pieces.logs(rows, done, True))
    last = out[-1]
    if damage:
        last.notes.insert(0, _damage_note(decoded, scan.counts.get(cid, 0), damage, scan,
                                          where))
    yield from out


def _undecodable(k: int, stream: Stream, exc: BaseException) -> str:
    what = " ".join(str(exc).split())[:60]
    return (f"message {k} on {stream.channel.topic} cannot be decoded "
            f"({type(exc).__name__}{': ' + what if what else ''})")


def _check_recovered(n: int, damage: str | None, stream: Stream, where: str) -> None:
    """The one-line errors of a log with no messages, or too few before damage."""
    if n == 0:
        if damage:
            raise InputError(f"{where}: damaged MCAP file ({damage}); no messages could be "
                             "recovered")
        raise InputError(f"{where}: no messages on {stream.channel.topic}; the log is empty")
    if damage and n < MIN_SAMPLES:
        raise InputError(f"{where}: damaged MCAP file ({damage}); only {n} message"
                         f"{'s' if n != 1 else ''} could be recovered, at least {MIN_SAMPLES} "
                         "samples are needed")


def _damage_note(n: int, total: int, damage: str, scan: McapScan, where: str) -> str:
    if scan.complete and damage is scan.damage:
        return (f"{where}: damaged MCAP file ({damage}); all {n} messages were recovered "
                "(the damage is not in them)")
    of = f" of {total}" if total > n else ""
    return (f"{where}: damaged MCAP file ({damage}); recovered the {n}{of} message"
            f"{'s' if n != 1 else ''} before the damage — the log may end early")


__all__ = ["McapScan", "iter_mcap_log", "read_mcap_log", "scan_mcap"]
