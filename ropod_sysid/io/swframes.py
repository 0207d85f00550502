"""Smart-wheel frames → contract samples, a piece of the recording at a time.

:class:`FrameChecks` applies the checks and the conversion that
:func:`ropod_sysid.io.smartwheel.frames_to_log` describes to consecutive pieces of the frames,
carrying across pieces what they need: the last kept clock value of every unit and the last
two good frames (a frame is judged non-monotonic from the two good frames after it), the
first kept clock value (t counts from it), the unwrapping state of every encoder
(:func:`ropod_sysid.odometry.unwrap_from`, bit-identical to one ``np.unwrap``), the pivot
branch chosen at the first kept sample, and for the note the counts and the first frames of
every reason with the kept frames around them. The samples equal those of the whole log bit
for bit, and the note is the same. The runs of consecutive kept frames are recorded, so that
the time checks of the samples (:mod:`ropod_sysid.io.timebase`) name their frames
(:meth:`FrameChecks.locate`).
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.io.cdr import struct_array_layout
from ropod_sysid.io.log import Log, join_logs
from ropod_sysid.io.mcapdecode import BatchDecoder, Rows, ros2_decoder
from ropod_sysid.model.units import swivel
from ropod_sysid.odometry import unwrap_from
from ropod_sysid.platform import Platform

_TWO_PI = 2.0 * math.pi
SHOWN = 5      # frames named per reason in the note


@dataclass
class _Held:
    """Good frames whose monotonicity waits for the frames after them."""

    index: np.ndarray      # (g,) frame numbers
    ts: np.ndarray         # (g, n) uint64
    floats: np.ndarray     # (F, g, n)


def _monotonic(v: list[int], last: int | None, decide: int, drops: list[int]
               ) -> tuple[list[bool], int | None]:
    """Which of the first ``decide`` values of one unit's clock to keep — each after the last
    kept one, and no forward spikes (a value that the next one falls back from, the next
    still after the last kept one) — looking ahead at ``v[decide:]`` (two values, or none at
    the end of the log); and the last kept value after them. ``drops``: the positions ``p``
    where ``v[p + 1] <= v[p]``; the rising runs between them are kept without a look."""
    n = len(v)
    keep = [True] * decide
    k = 0
    while k < decide:
        cur = v[k]
        if last is not None and cur <= last:
            keep[k] = False
            k += 1
            continue
        nxt = v[k + 1] if k + 1 < n else None
        if nxt is not None and nxt <= cur and (last is None or nxt > last) and \
                (last is not None or k + 2 >= n or v[k + 2] > nxt):
            keep[k] = False
            k += 1
            continue
        last = cur
        if nxt is not None and nxt > cur:       # a rising run up to the next fall-back
            j = bisect_left(drops, k + 1)
            stop = min(drops[j] if j < len(drops) else n, decide)
            if stop > k + 1:
                last = v[stop - 1]
                k = stop
                continue
        k += 1
    return keep, last


class FrameChecks:
    """The checks and conversion of smart-wheel frames, piece by piece (:meth:`push`, then
    :meth:`finish`)."""

    def __init__(self, platform: Platform, where: str, fields: tuple[str, ...],
                 voltage_range: tuple[float, float], notes: list[str] | None = None) -> None:
        self.platform, self.where, self.fields = platform, where, fields
        self.lo, self.hi = voltage_range
        self.notes = list(notes or [])
        n = platform.n_units
        self.labels = ("malformed (missing fields or sensors)", "zeroed",
                       "with NaN or infinite values",
                       f"with voltage_bus outside [{self.lo:g}, {self.hi:g}] V",
                       "with non-monotonic sensor_ts")
        self.counts = [0] * len(self.labels)
        self.shown: list[list[int]] = [[] for _ in self.labels]
        self.times: dict[int, float] = {}           # shown frame → its time, once known
        self.waiting: list[int] = []                # shown frames before the next kept one
        self.last_kept: tuple[int, float] | None = None
        self.first_kept: float | None = None
        self.n_frames = 0
        self.n_kept = 0
        self.held = _Held(np.zeros(0, dtype=np.int64), np.zeros((0, n), dtype=np.uint64),
                          np.zeros((len(fields), 0, n)))
        self.last_ts: list[int | None] = [None] * n
        self.ts0: np.uint64 | None = None
        self.unwrap: dict[str, np.ndarray] = {}     # encoder → (last raw, correction) (2, n)
        self.branch: np.ndarray | None = None
        self.run_samples: list[int] = []            # the runs of consecutive kept frames:
        self.run_frames: list[int] = []             # first sample and first frame of each

    def locate(self, samples: Sequence[int]) -> list[str]:
        """The kept frames of samples (a ``locate`` of :mod:`ropod_sysid.io.timebase`)."""
        out = []
        for s in samples:
            j = bisect_right(self.run_samples, s) - 1
            out.append(f"frame #{self.run_frames[j] + s - self.run_samples[j]}")
        return out

    def _runs(self, index: np.ndarray) -> None:
        """Record where the kept frames ``index`` (the next samples) skip frames."""
        starts = np.flatnonzero(np.diff(index) != 1) + 1
        if self.last_kept is None or int(index[0]) != self.last_kept[0] + 1:
            starts = np.concatenate([[0], starts])
        self.run_samples += (starts + self.n_kept).tolist()
        self.run_frames += index[starts].tolist()

    def _count(self, reason: int, frames: np.ndarray) -> None:
        """Count the ``frames`` (numbers, ascending) dropped for ``reason``."""
        self.counts[reason] += frames.size
        room = SHOWN - len(self.shown[reason])
        if room > 0 and frames.size:
            new = frames[:room].tolist()
            self.shown[reason] += new
            self.waiting = sorted(self.waiting + new)

    def push(self, ts: np.ndarray, values: dict[str, np.ndarray], malformed: np.ndarray,
             final: bool = False) -> Log | None:
        """Check the next frames (``ts`` (N, n) uint64, ``values`` field → (N, n), the
        frames that were malformed); the samples of the frames decided so far, or None."""
        start = self.n_frames
        self.n_frames += ts.shape[0]
        floats = np.stack([values[f] for f in self.fields])          # (F, N, n)
        bad = malformed.copy()
        self._count(0, np.flatnonzero(malformed) + start)
        zeroed = ((ts == 0) | np.all(floats == 0.0, axis=0)).any(axis=1) & ~bad
        self._count(1, np.flatnonzero(zeroed) + start)
        bad |= zeroed
        nonfinite = ~np.isfinite(floats).all(axis=(0, 2)) & ~bad
        self._count(2, np.flatnonzero(nonfinite) + start)
        bad |= nonfinite
        vb = values["voltage_bus"]
        volt = ~((vb >= self.lo) & (vb <= self.hi)).all(axis=1) & ~bad
        self._count(3, np.flatnonzero(volt) + start)
        bad |= volt
        good = np.flatnonzero(~bad)
        h = self.held
        index = np.concatenate([h.index, good + start])
        gts = np.concatenate([h.ts, ts[good]])
        gfl = np.concatenate([h.floats, floats[:, good]], axis=1)
        decide = index.size if final else max(index.size - 2, 0)
        mono = np.ones(decide, dtype=bool)
        for i in range(gts.shape[1]):
            col = gts[:, i]
            last = self.last_ts[i]
            if bool(np.all(col[1:] > col[:-1])) and (last is None or col.size == 0
                                                      or int(col[0]) > last):
                if decide:
                    self.last_ts[i] = int(col[decide - 1])
                continue
            drops = np.flatnonzero(col[1:] <= col[:-1]).tolist()
            keep, self.last_ts[i] = _monotonic(col.tolist(), last, decide, drops)
            mono &= np.array(keep, dtype=bool)
        self._count(4, index[:decide][~mono])
        self.held = _Held(index[decide:], gts[decide:], gfl[:, decide:])
        kept = np.flatnonzero(mono)
        return self._samples(index[kept], gts[kept], gfl[:, kept])

    def _samples(self, index: np.ndarray, ts: np.ndarray, floats: np.ndarray) -> Log | None:
        if index.size == 0:
            return None
        if self.ts0 is None:
            self.ts0 = ts[0, 0]
        rel_ns = (ts[:, 0] - self.ts0).astype(np.int64)  # integer subtraction, then seconds
        t = rel_ns.astype(np.float64) / 1e9
        self._runs(index)
        self._resolve_times(index, t)
        self.n_kept += index.size
        v = dict(zip(self.fields, floats, strict=True))
        n = self.platform.n_units
        m = index.size
        delta = np.empty((m, n))
        phi = np.empty((m, n, 2))
        cur = np.empty((m, n, 2))
        enc = {name: self._unwrap(name, v[name]) for name in
               ("encoder_1", "encoder_2", "encoder_pivot")}
        if self.branch is None:
            d0 = enc["encoder_pivot"][0] - np.array([u.pivot_offset for u in self.platform.units])
            self.branch = np.array([_TWO_PI * math.floor((d + math.pi) / _TWO_PI) for d in d0])
        for i, u in enumerate(self.platform.units):
            lm, rm = u.left_motor, 3 - u.left_motor
            phi[:, i, 0] = u.sign_left * enc[f"encoder_{lm}"][:, i]
            phi[:, i, 1] = u.sign_right * enc[f"encoder_{rm}"][:, i]
            cur[:, i, 0] = u.sign_left * v[f"current_{lm}_q"][:, i]
            cur[:, i, 1] = u.sign_right * v[f"current_{rm}_q"][:, i]
            d = enc["encoder_pivot"][:, i] - u.pivot_offset
            d -= self.branch[i]
            delta[:, i] = d
        return swivel.from_arrays(self.platform, t, delta, phi, cur, None, self.where)

    def _unwrap(self, name: str, x: np.ndarray) -> np.ndarray:
        """np.unwrap along the frames, continued from the previous piece."""
        state = self.unwrap.get(name)
        if state is None:
            up, corr = unwrap_from(x)
        else:
            up, corr = unwrap_from(np.concatenate([state[:1], x]), state[1])
            up, corr = up[1:], corr[1:]
        self.unwrap[name] = np.stack([x[-1], corr[-1]])
        return up

    def _resolve_times(self, index: np.ndarray, t: np.ndarray) -> None:
        """The times of shown frames, as np.interp over the kept frames by frame number
        gives them, from the kept frames on either side."""
        if self.first_kept is None:
            self.first_kept = float(t[0])
        rest = []
        for s in self.waiting:
            j = int(np.searchsorted(index, s))
            if j == index.size:
                rest.append(s)
                continue
            before = self.last_kept if j == 0 else (int(index[j - 1]), float(t[j - 1]))
            if before is None:
                self.times[s] = self.first_kept
            else:
                self.times[s] = float(np.interp(s, [before[0], int(index[j])],
                                                [before[1], float(t[j])]))
        self.waiting = rest
        self.last_kept = (int(index[-1]), float(t[-1]))

    def finish(self) -> tuple[Log | None, list[str]]:
        """The samples of the held frames and the notes; raises :class:`InputError` when
        fewer than 3 frames were usable."""
        last = self.push(np.zeros((0, self.platform.n_units), dtype=np.uint64),
                         {f: np.zeros((0, self.platform.n_units)) for f in self.fields},
                         np.zeros(0, dtype=bool), final=True)
        if self.n_kept < 3:
            raise InputError(
                f"{self.where}: only {self.n_kept} of {self.n_frames} smart-wheel frames are "
                "usable (the others are zeroed, out of range or out of order); at least 3 "
                "samples are needed")
        for s in self.waiting:
            self.times[s] = self.last_kept[1] if self.last_kept else 0.0
        notes = list(self.notes)
        n_bad = sum(self.counts)
        if n_bad:
            parts = []
            for label, count, shown in zip(self.labels, self.counts, self.shown, strict=True):
                if count:
                    named = ", ".join(f"#{k} (t≈{self.times[k]:.3f} s)" for k in shown)
                    more = f" and {count - SHOWN} more" if count > SHOWN else ""
                    parts.append(f"{count} {label}: frames {named}{more}")
            notes.append(f"{self.where}: dropped {n_bad} of {self.n_frames} smart-wheel frames "
                         f"— {'; '.join(parts)} (frame numbers count from 0 in file order)")
        return last, notes


# ---------------------------------------------------------------------------------------------
# MCAP messages → frames

_CDR_TYPES = {"uint8": (1, "u1"), "int8": (1, "i1"), "uint16": (2, "u2"), "int16": (2, "i2"),
              "uint32": (4, "u4"), "int32": (4, "i4"), "uint64": (8, "u8"), "int64": (8, "i8"),
              "float32": (4, "f4"), "float64": (8, "f8"), "bool": (1, "u1")}


def sensor_fields(msgdef: str) -> list[tuple[str, int, str]] | None:
    """The primitive fields (name, bytes, numpy type) of the sensor struct of a smart-wheel
    ros2msg schema whose message is only ``X[] sensors``; None for any other shape."""
    sections = [sec.strip().splitlines() for sec in msgdef.split("=" * 80)]

    def fields(lines: list[str]) -> list[tuple[str, str]]:
        out = []
        for line in lines:
            words = line.split("#", 1)[0].split()
            if words and not line.startswith("MSG:"):
                out.append((words[0], words[1] if len(words) > 1 else ""))
        return out

    top = fields(sections[0])
    if len(sections) != 2 or len(top) != 1 or top[0][1] != "sensors" \
            or not top[0][0].endswith("[]"):
        return None
    out = []
    for kind, name in fields(sections[1]):
        if kind not in _CDR_TYPES or "=" in name:
            return None
        out.append((name, *_CDR_TYPES[kind]))
    return out


def smartwheel_decoder(encoding: str, schema: object, topic: str, where: str) -> BatchDecoder:
    """The batch decoder of a smart-wheel channel: JSON, or ROS 2 with the fixed layout of
    its schema's sensor struct when it has one."""
    from ropod_sysid.io.smartwheel import REQUIRED

    if encoding == "json":
        import json

        return BatchDecoder("json", json.loads)
    decode = ros2_decoder(schema, topic, where)
    found = sensor_fields(schema.data.decode(errors="replace"))   # type: ignore[attr-defined]
    names = {f for f, _, _ in found or []}

    def layout_of(payload: bytes, msg: object) -> object:
        if found is None or not set(REQUIRED) <= names or ("sensor_ts", 8, "u8") not in found:
            return None
        try:
            items = list(msg.sensors)   # type: ignore[attr-defined]
        except (AttributeError, TypeError):
            return None
        return struct_array_layout(payload, items, found, REQUIRED)

    return BatchDecoder("ros2", decode, layout_of)


def rows_to_frames(rows: Rows, decoder: BatchDecoder, platform: Platform, where: str,
                   offset: int) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, list[str]]:
    """(sensor_ts, values, malformed, notes) of decoded smart-wheel messages, as
    :func:`ropod_sysid.io.smartwheel.frames_from_messages` gives them."""
    from ropod_sysid.io.smartwheel import (
        REQUIRED_FLOATS,
        extra_sensors_note,
        frames_from_messages,
    )

    n = platform.n_units
    cols = rows.columns
    if decoder.layout is not None and rows.fast is not None and rows.fast.all() \
            and cols["sensor_ts"].shape[1] >= n:
        count = cols["sensor_ts"].shape[1]
        notes = [extra_sensors_note(where, count, platform)] if offset == 0 and count > n \
            else []
        values = {f: cols[f][:, :n].astype(np.float64) for f in REQUIRED_FLOATS}
        return (np.ascontiguousarray(cols["sensor_ts"][:, :n], dtype=np.uint64), values,
                np.zeros(len(rows), dtype=bool), notes)
    decoded = rows.objects if decoder.encoding == "json" else \
        [decoder.decode(p) for p in rows.payloads]
    assert decoded is not None  # the JSON decoder of smart-wheel data parses every message
    fr = frames_from_messages(decoded, platform, where, decoder.encoding, offset)
    return fr.sensor_ts, fr.values, fr.malformed, fr.notes


class SmartWheelPieces:
    """Rows of the smart-wheel layout → frames → checked samples, in chunks of ``chunk``
    samples (the checks drop frames and hold back the last two good ones)."""

    def __init__(self, stream: Any, platform: Platform, where: str, chunk: int) -> None:
        from ropod_sysid.io.smartwheel import REQUIRED_FLOATS, VOLTAGE_RANGE

        self.decoder = smartwheel_decoder(stream.encoding, stream.schema, stream.channel.topic,
                                          where)
        self.checks = FrameChecks(platform, where, REQUIRED_FLOATS, VOLTAGE_RANGE)
        self.platform, self.where, self.chunk = platform, where, chunk
        self.locate = self.checks.locate
        self.out: list[Log] = []
        self.n_out = 0

    def _add(self, piece: Log | None) -> None:
        if piece is not None:
            self.out.append(piece)
            self.n_out += piece.n_samples

    def logs(self, rows: Rows | None, done: int, final: bool) -> Iterator[Log]:
        if rows is not None:
            ts, values, malformed, notes = rows_to_frames(rows, self.decoder, self.platform,
                                                          self.where, done)
            self.checks.notes += notes
            self._add(self.checks.push(ts, values, malformed))
        notes = []
        if final:
            piece, notes = self.checks.finish()
            self._add(piece)
        while self.n_out > self.chunk or (final and self.n_out):
            log = join_logs(self.out, [])
            take = min(self.chunk, log.n_samples)
            self.out = [log.slice(take, log.n_samples)] if take < log.n_samples else []
            self.n_out -= take
            piece = log.slice(0, take)
            piece.notes = notes if not self.n_out else []
            yield piece


__all__ = ["FrameChecks", "SmartWheelPieces", "rows_to_frames", "sensor_fields",
           "smartwheel_decoder"]
