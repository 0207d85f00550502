"""Decoding the messages of an MCAP log a batch at a time: payloads → rows → logs.

A batch of payloads (the messages of the log's channel, in file order) is decoded at once:

* ROS 2 (CDR): the numbers of every message with the recording's fixed layout are read as
  columns (:mod:`ropod_sysid.io.cdr`); only messages that differ from it go through the
  per-message decoder (``mcap_ros2``), which also says which of them cannot be decoded;
* JSON: our layout's messages are parsed into columns by Arrow's JSON reader when every one
  is a line of UTF-8 with every field a number (:func:`_arrow_columns`); otherwise one by one
  by ``orjson`` (three times faster than the standard parser), and a message it refuses by
  ``json.loads``, which accepts ``NaN`` and gives the error message of a message that cannot
  be decoded. The smart-wheel layout's JSON goes one by one.

The rows of a chunk then become a contract log (:func:`contract_log`): columns straight from
the fixed layout or Arrow, or from the parsed JSON by one list per field, and the same
per-message code as before when anything is unusual, so that errors and damage notes name
the same message with the same words (a value that is no number, or too large for a float,
by :func:`_json_value_problem`; a NaN or infinity by the field it is in). The time base of
the logs is checked by the reader (:class:`ropod_sysid.io.timebase.TimeBase`).
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import orjson

from ropod_sysid.errors import InputError
from ropod_sysid.io.cdr import CONTRACT_ARRAYS, FixedLayout, contract_layout
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import message_numbers
from ropod_sysid.platform import Platform

MIN_SAMPLES = 3
POSE_FIELDS = ("x_b", "y_b", "theta_b")
_FLOAT_MAX = int(np.finfo(np.float64).max)   # a larger JSON integer overflows a float


@dataclass
class Rows:
    """Decoded messages: their payloads, the parsed JSON objects (JSON) or the columns of the
    messages that have the fixed layout (``fast``; ROS 2)."""

    payloads: list[bytes]
    objects: list[Any] | None = None
    fast: np.ndarray | None = None
    columns: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.payloads)

    def take(self, start: int, stop: int | None = None) -> Rows:
        objects = None if self.objects is None else self.objects[start:stop]
        fast = None if self.fast is None else self.fast[start:stop]
        return Rows(self.payloads[start:stop], objects, fast,
                    {k: v[start:stop] for k, v in self.columns.items()})

    @staticmethod
    def join(parts: list[Rows]) -> Rows:
        if len(parts) == 1:
            return parts[0]
        if len({p.objects is None for p in parts}) > 1:       # JSON columns and objects
            parts = [p if p.objects is not None else Rows(p.payloads, [_parse(x) for x in
                                                                       p.payloads])
                     for p in parts]
        # (every part has objects or none has: made so above)
        objects = None if parts[0].objects is None else [o for p in parts for o in p.objects]  # type: ignore[union-attr]
        fast = None if parts[0].fast is None else np.concatenate([p.fast for p in parts])
        return Rows([b for p in parts for b in p.payloads], objects, fast,
                    {k: np.concatenate([p.columns[k] for p in parts]) for k in parts[0].columns})


def ros2_decoder(schema: Any, topic: str, where: str) -> Any:
    """The per-message decoder of a ros2msg schema, or a one-line error."""
    if schema is None or schema.encoding != "ros2msg":
        raise InputError(f"{where}: channel {topic} is CDR-encoded but has no ros2msg schema; "
                         "it cannot be decoded")
    from mcap_ros2._dynamic import generate_dynamic

    try:
        with contextlib.redirect_stderr(io.StringIO()):     # the parser prints its complaints
            types = generate_dynamic(schema.name, schema.data.decode())
        return types[schema.name]
    except Exception as exc:   # noqa: BLE001 - the vendored rosidl parser has its own errors
        raise InputError(f"{where}: the ros2msg schema {schema.name!r} of {topic} cannot be "
                         f"parsed ({type(exc).__name__})") from None


class BatchDecoder:
    """Decodes batches of one channel's payloads (``encoding`` json or ros2); ``layout_of``
    gives the fixed layout of a ROS 2 message from its payload and decoding (None: none)."""

    def __init__(self, encoding: str, decode: Any, layout_of: Any = None,
                 columns_of: Any = None) -> None:
        from ropod_sysid.io.mcaplog import READ_ERRORS

        self.encoding, self.decode, self._layout_of = encoding, decode, layout_of
        self._columns_of = columns_of
        self._errors = READ_ERRORS
        self.layout: FixedLayout | None = None
        self.template: Any = None      # the decoded first message, whose layout it is
        self._first = True

    def __call__(self, payloads: list[bytes]) -> tuple[Rows, int | None, BaseException | None]:
        """(the rows up to the first message that cannot be decoded, its index in the batch
        or None, its exception)."""
        if self.encoding == "json":
            return self._json(payloads)
        return self._ros2(payloads)

    def _json(self, payloads: list[bytes]) -> tuple[Rows, int | None, BaseException | None]:
        columns = self._columns_of(payloads) if self._columns_of is not None else None
        if columns is not None:
            return Rows(payloads, columns=columns), None, None
        try:
            return Rows(payloads, list(map(orjson.loads, payloads))), None, None
        except orjson.JSONDecodeError:
            pass
        objects = []
        for j, p in enumerate(payloads):
            try:
                objects.append(orjson.loads(p))
            except orjson.JSONDecodeError:
                try:
                    objects.append(json.loads(p))
                except self._errors as exc:
                    return Rows(payloads[:j], objects), j, exc
        return Rows(payloads, objects), None, None

    def _ros2(self, payloads: list[bytes]) -> tuple[Rows, int | None, BaseException | None]:
        if self._first and payloads:
            self._first = False
            try:
                msg = self.decode(payloads[0])
            except self._errors as exc:
                return Rows([], fast=np.zeros(0, dtype=bool)), 0, exc
            if self._layout_of is not None:
                self.template = msg
                self.layout = self._layout_of(payloads[0], msg)
        n = len(payloads)
        columns: dict[str, np.ndarray]
        if self.layout is None:
            fast, columns = np.zeros(n, dtype=bool), {}
        else:
            fast, found = self.layout.read(payloads)
            columns = {}
            for k, v in found.items():
                full = np.zeros((n, *v.shape[1:]), dtype=v.dtype)
                full[fast] = v
                columns[k] = full
        for j in np.flatnonzero(~fast).tolist():     # the messages that differ: one by one
            try:
                self.decode(payloads[j])
            except self._errors as exc:
                return Rows(payloads, fast=fast, columns=columns).take(0, j), j, exc
        return Rows(payloads, fast=fast, columns=columns), None, None


# ---------------------------------------------------------------------------------------------
# rows → contract log


def contract_decoder(encoding: str, schema: Any, topic: str, where: str,
                     platform: Platform) -> BatchDecoder:
    if encoding == "json":
        fields = platform.layout.fields
        return BatchDecoder("json", json.loads, columns_of=lambda p: _arrow_columns(p, fields))
    if set(platform.types) != {"swivel"}:
        raise InputError(f"{where}: the ROS 2 layout of ropod-sysid carries smart-wheel "
                         "(swivel) units only, and the platform has "
                         f"{', '.join(t for t in platform.types if t != 'swivel')} units; "
                         "record JSON MCAP or CSV for this platform")
    return BatchDecoder("ros2", ros2_decoder(schema, topic, where), contract_layout)


def contract_log(rows: Rows, decoder: BatchDecoder, platform: Platform, where: str,
                 offset: int = 0, whole: bool = True) -> Log:
    """The log of the decoded contract messages ``rows``; ``offset``: the number of the first
    message in the file (for the messages' numbers in errors); ``whole``: the messages are the
    whole log (else a chunk of it: too few of them is no error)."""
    if decoder.encoding == "json":
        first = rows.objects[0] if rows.objects is not None else _parse(rows.payloads[0])
        if not isinstance(first, dict) or not isinstance(first.get("units"), dict):
            raise InputError(f"{where}: message {offset} is not a ropod-sysid log sample "
                             "(expected keys 't' and 'units'); the file may use another layout")
        _check_units(list(first["units"]), platform, where)
        has_pose = isinstance(first.get("pose"), dict)
        arrays = None
        cols = rows.columns
        if rows.objects is None and (not has_pose or cols["pose_ok"].all()):
            arrays = cols["t"], cols["values"], cols["pose"] if has_pose else None
            if not all(np.isfinite(a).all() for a in arrays if a is not None):
                arrays = None                             # let the loop name the message
        objects = rows.objects
        if arrays is None and objects is None:
            objects = [_parse(p) for p in rows.payloads]
        fields = platform.layout.fields
        if arrays is None:
            assert objects is not None  # parsed above when arrays is None
            arrays = _json_columns(objects, fields, has_pose)
        if arrays is None:
            assert objects is not None
            arrays = _json_loop(objects, fields, has_pose, where, offset)
    else:
        arrays = _ros2_columns(rows, decoder, platform, where)
        if arrays is None:
            arrays = _ros2_loop([decoder.decode(p) for p in rows.payloads], platform, where,
                                offset)
    return _checked(*arrays, platform, where, offset, whole)


class ContractPieces:
    """Rows of our layout → one log per chunk (its time base is checked by the reader,
    :class:`ropod_sysid.io.timebase.TimeBase`: sample k is message k, :attr:`locate`)."""

    def __init__(self, stream: Any, platform: Platform, where: str) -> None:
        self.decoder = contract_decoder(stream.encoding, stream.schema, stream.channel.topic,
                                        where, platform)
        self.platform, self.where = platform, where
        self.locate = message_numbers()

    def logs(self, rows: Rows | None, done: int, final: bool) -> Iterator[Log]:
        assert rows is not None     # (_check_recovered: a log has messages)
        yield contract_log(rows, self.decoder, self.platform, self.where, offset=done,
                           whole=final and done == 0)


def _parse(payload: bytes) -> Any:
    try:
        return orjson.loads(payload)
    except orjson.JSONDecodeError:
        return json.loads(payload)


def _arrow_columns(payloads: list[bytes], fields: list[tuple[str, str]]
                   ) -> dict[str, np.ndarray] | None:
    """t (n,), values (n, F) (the layout's (unit, field) pairs ``fields``), pose (n, 3) and
    pose_ok (n,) of JSON messages, parsed by
    Arrow's JSON reader (columns straight from the text, without the GIL); None unless every
    message is one line of UTF-8 holding every field as a number, and no value is a negative
    zero (``-0`` is 0.0 to Python's parser, -0.0 to Arrow's): then the messages are parsed
    one by one."""
    import pyarrow as pa
    import pyarrow.json as pajson

    n = len(payloads)
    joined = b"\n".join(payloads)
    if not n or joined.count(b"\n") != n - 1 or b"\r" in joined or b"\xef\xbb\xbf" in joined:
        return None
    try:
        joined.decode("utf-8")
    except UnicodeDecodeError:
        return None
    num = pa.float64()
    units = list(dict.fromkeys(u for u, _ in fields))
    per_unit = {u: [f for v, f in fields if v == u] for u in units}
    schema = pa.schema([("t", num),
                        ("units", pa.struct([(u, pa.struct([(f, num) for f in per_unit[u]]))
                                             for u in units])),
                        ("pose", pa.struct([(f, num) for f in POSE_FIELDS]))])
    try:
        table = pajson.read_json(
            io.BytesIO(joined), read_options=pajson.ReadOptions(block_size=1 << 20),
            parse_options=pajson.ParseOptions(explicit_schema=schema,
                                              unexpected_field_behavior="ignore"))
    except (pa.ArrowException, ValueError, OverflowError):
        return None
    if table.num_rows != n:
        return None

    def col(arr: Any) -> np.ndarray | None:
        return None if arr.null_count else arr.to_numpy(zero_copy_only=False)

    t = col(table.column("t").combine_chunks())
    us = table.column("units").combine_chunks()
    if t is None or us.null_count:
        return None
    values = np.empty((n, len(fields)))
    k = 0
    for i, u in enumerate(units):
        e = us.field(i)
        if e.null_count:
            return None
        for j in range(len(per_unit[u])):
            c = col(e.field(j))
            if c is None:
                return None
            values[:, k] = c
            k += 1
    pose = table.column("pose").combine_chunks()
    ok = ~pose.is_null().to_numpy(zero_copy_only=False)
    xyz = np.empty((n, 3))
    for j in range(3):
        f = pose.field(j)
        ok &= ~f.is_null().to_numpy(zero_copy_only=False)
        xyz[:, j] = f.to_numpy(zero_copy_only=False)
    if any(((a == 0) & np.signbit(a)).any() for a in (t, values, xyz[ok])):
        return None
    return {"t": t, "values": values, "pose": xyz, "pose_ok": ok}


def _json_columns(decoded: list[Any], fields: list[tuple[str, str]], has_pose: bool
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """t, values and pose of parsed JSON messages, one list per field; None when any message
    is unusual (a missing key, a value that is no plain number, a NaN: let the loop say)."""
    try:
        cols = [[m["t"] for m in decoded]]
        units = list(dict.fromkeys(u for u, _ in fields))
        entries = {u: [m["units"][u] for m in decoded] for u in units}
        cols += [[e[f] for e in entries[u]] for u, f in fields]
        if has_pose:
            poses = [m["pose"] for m in decoded]
            cols += [[p[f] for p in poses] for f in POSE_FIELDS]
        table = np.array(cols)
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    if table.dtype.kind not in "fiu" or not np.isfinite(table).all():
        return None
    table = table.astype(np.float64, copy=False)
    m = len(fields)
    pose = table[1 + m:].T if has_pose else None
    return table[0], table[1:1 + m].T, pose


def _needs(fields: list[tuple[str, str]]) -> str:
    """The unit fields a message needs, in words (``delta, phi_L, … of every unit``)."""
    per_unit: dict[str, list[str]] = {}
    for u, f in fields:
        per_unit.setdefault(u, []).append(f)
    kinds = list(dict.fromkeys(tuple(v) for v in per_unit.values()))
    if len(kinds) == 1:
        return f"t and {', '.join(kinds[0])} of every unit"
    return "t and " + "; ".join(
        f"{', '.join(k)} of unit{'s' if sum(v == list(k) for v in per_unit.values()) > 1 else ''}"
        f" {', '.join(u for u, v in per_unit.items() if v == list(k))}" for k in kinds)


def _json_loop(decoded: list[Any], fields: list[tuple[str, str]], has_pose: bool, where: str,
               offset: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    n = len(decoded)
    t = np.empty(n)
    vals = np.empty((n, len(fields)))
    pose = np.empty((n, 3)) if has_pose else None
    for k, m in enumerate(decoded):
        try:
            t[k] = m["t"]
            mu = m["units"]
            vals[k] = [mu[u][f] for u, f in fields]
            if pose is not None:
                p = m["pose"]
                pose[k] = (p["x_b"], p["y_b"], p["theta_b"])
        except KeyError as exc:
            raise InputError(f"{where}: message {offset + k} lacks a log field "
                             f"({_field(exc)}); every message needs {_needs(fields)}") from None
        except (TypeError, ValueError, OverflowError) as exc:
            raise InputError(f"{where}: message {offset + k} "
                             f"{_json_value_problem(m, fields, has_pose, exc)}") from None
    return t, vals, pose


def _json_value_problem(m: Any, fields: list[tuple[str, str]], pose: bool,
                        exc: BaseException) -> str:
    """What is wrong with the first field of JSON message ``m`` that is not a number."""
    paths = [("t",)] + [("units", u, f) for u, f in fields] \
        + ([("pose", f) for f in POSE_FIELDS] if pose else [])
    for path in paths:
        v = m
        try:
            for key in path:
                v = v[key]
        except (KeyError, TypeError, IndexError):
            return (f"lacks the log field {'.'.join(path)!r}; every message needs "
                    f"{_needs(fields)}")
        if isinstance(v, int) and not isinstance(v, bool) and abs(v) > _FLOAT_MAX:
            return (f"has a number too large for a float in {'.'.join(path)} ({len(str(v))} "
                    "digits; it overflows to infinity); the log must be finite — repair or cut "
                    "the recording")
        if not isinstance(v, int | float):
            return (f"has {str(v)[:40]!r} in {'.'.join(path)}, which is not a number; repair or "
                    "cut the recording")
    return f"has a malformed log field ({type(exc).__name__}); repair or cut the recording"


def _ros2_columns(rows: Rows, decoder: BatchDecoder, platform: Platform, where: str
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """t, values and pose of messages that all have the fixed layout, else None."""
    layout = decoder.layout
    if layout is None or rows.fast is None or not rows.fast.all():
        return None
    first_units = list(decoder.template.units)
    _check_units(first_units, platform, where)
    idx = [first_units.index(u) for u in platform.unit_names]
    values = rows.columns["values"]                       # (n, 5, len)
    if values.shape[2] < len(first_units):
        return None                                       # short arrays: the loop says so
    vals = np.ascontiguousarray(values[:, :, idx].transpose(0, 2, 1))
    pose = rows.columns["pose"] if rows.columns["pose"].shape[1] == 3 else None
    return rows.columns["t"], vals.reshape(len(vals), -1), pose


def _ros2_loop(decoded: list[Any], platform: Platform, where: str, offset: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    units = platform.unit_names
    n = len(decoded)
    t = np.empty(n)
    vals = np.empty((n, len(units), 5))
    first_units = list(decoded[0].units)
    _check_units(first_units, platform, where)
    idx = [first_units.index(u) for u in units]
    pose = np.empty((n, 3)) if len(decoded[0].pose) == 3 else None
    for k, m in enumerate(decoded):
        if list(m.units) != first_units:
            raise InputError(f"{where}: message {offset + k} lists units {list(m.units)} "
                             f"but message {offset} lists {first_units}; the unit order "
                             "must not change within a log")
        t[k] = m.t
        try:
            for j, arr in enumerate(getattr(m, a) for a in CONTRACT_ARRAYS):
                vals[k, :, j] = [arr[i] for i in idx]
            if pose is not None:
                pose[k] = m.pose
        except (IndexError, ValueError) as exc:
            raise InputError(f"{where}: message {offset + k} has arrays shorter than its "
                             f"unit list ({type(exc).__name__}); the message is malformed") \
                from None
    return t, vals.reshape(n, -1), pose


def _checked(t: np.ndarray, vals: np.ndarray, pose: np.ndarray | None, platform: Platform,
             where: str, offset: int, whole: bool) -> Log:
    n = t.shape[0]
    bad = ~np.isfinite(vals).all(axis=1) | ~np.isfinite(t)
    if pose is not None:
        bad |= ~np.isfinite(pose).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        named = [("t", t[k])] + [(f"units.{u}.{f}", vals[k, j])
                                 for j, (u, f) in enumerate(platform.layout.fields)]
        if pose is not None:
            named += [(f"pose.{f}", pose[k, j]) for j, f in enumerate(POSE_FIELDS)]
        name, value = next((n, v) for n, v in named if not np.isfinite(v))
        raise InputError(f"{where}: message {offset + k} has a NaN or infinite value ({name} = "
                         f"{float(value)!r}); the log must be finite — repair or cut the "
                         "recording")
    if whole and n < MIN_SAMPLES:
        raise InputError(f"{where}: only {n} message{'s' if n != 1 else ''}; at least "
                         f"{MIN_SAMPLES} samples are needed — use a longer log")
    angles, currents = platform.layout.split(np.asarray(vals, dtype=np.float64))
    return Log(np.ascontiguousarray(t, dtype=np.float64), platform.layout, angles, currents,
               None if pose is None else np.ascontiguousarray(pose, dtype=np.float64), where)


def _field(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"no {exc.args[0]!r}"
    return type(exc).__name__


def _check_units(log_units: list[str], platform: Platform, where: str) -> None:
    absent = [u for u in platform.unit_names if u not in log_units]
    if absent:
        raise InputError(
            f"{where}: the log has unit{'s' if len(log_units) != 1 else ''} "
            f"{', '.join(log_units) or '(none)'} but the platform '{platform.name}' expects units "
            f"{', '.join(platform.unit_names)}; use the platform file that matches the log")


__all__ = ["BatchDecoder", "ContractPieces", "Rows", "contract_decoder", "contract_log",
           "ros2_decoder"]
