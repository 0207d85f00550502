"""Fixed-layout ROS 2 (CDR) messages decoded a whole batch at a time with numpy.

The messages of our contract layout (``ropod_sysid_msgs/msg/LogSample``) and of the smart-wheel
layout (``SmartWheelSensors[] sensors``) have, within one recording, the same byte length and
the same bytes everywhere but in their numbers: the encapsulation header, the sequence and
string lengths, the unit names and the alignment padding repeat in every message. So a batch
of payloads is joined into one buffer and viewed as ``(messages, bytes)``; a message whose
length and non-number bytes equal those of the first message (the template) has its numbers
where the template has them, and they are read as columns. Messages that differ (another
length, other counts: damage, or a recording that changed) are left to the per-message decoder.

The layout of the template is computed from the CDR rules (XCDR1: primitives aligned to their
size relative to the end of the 4-byte header, sequences and strings prefixed by a uint32
count, an empty sequence has no element padding) and then checked against the per-message
decoder's reading of the template: if any number differs, there is no fixed layout and every
message goes through the per-message decoder.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import compress
from typing import Any, Literal

import numpy as np

HEADER = 4          # CDR encapsulation header: representation id (2 bytes) and options
_LITTLE, _BIG = b"\x00\x01", b"\x00\x00"


class _Walk:
    """Positions of the fields of one CDR message, walked in declaration order."""

    def __init__(self, size: int) -> None:
        self.pos = 0                         # relative to the end of the header
        self.values = np.zeros(size, dtype=bool)   # bytes that hold numbers

    def _at(self, n: int) -> int:
        self.pos += -self.pos % min(n, 8)
        at = self.pos
        self.pos += n
        return HEADER + at

    def number(self, n: int) -> int:
        """A primitive of ``n`` bytes: its offset in the message (marked as a value)."""
        at = self._at(n)
        self.values[at:at + n] = True
        return at

    def count(self) -> None:
        """A sequence's or string's uint32 length (structure, not a value)."""
        self._at(4)

    def string(self, text: str) -> None:
        self.count()
        self.pos += len(text.encode()) + 1

    def numbers(self, count: int, n: int) -> np.ndarray:
        """A sequence of ``count`` primitives of ``n`` bytes: their offsets."""
        self.count()
        return np.array([self.number(n) for _ in range(count)], dtype=np.int64)


@dataclass
class FixedLayout:
    """Where the numbers of every message shaped like ``template`` are."""

    size: int
    order: Literal["<", ">"]                    # little- or big-endian
    structure_at: np.ndarray                    # offsets of the non-number bytes
    structure: np.ndarray                       # their values in the template
    fields: dict[str, tuple[np.ndarray, str]]   # name → (offsets of any shape, numpy type)

    def read(self, payloads: Sequence[bytes]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(mask of the payloads that have this layout, field → values of those payloads,
        shaped ``(matching, *offsets.shape)``)."""
        n = len(payloads)
        lengths = np.fromiter(map(len, payloads), dtype=np.int64, count=n)
        same = lengths == self.size
        joined = b"".join(payloads if same.all() else compress(payloads, same.tolist()))
        rows = np.frombuffer(joined, dtype=np.uint8).reshape(-1, self.size)
        fits = (rows[:, self.structure_at] == self.structure).all(axis=1)
        mask = same.copy()
        mask[same] = fits
        rows = rows[fits] if not fits.all() else rows
        out = {}
        for name, (offsets, kind) in self.fields.items():
            dt = np.dtype(kind).newbyteorder(self.order)
            cols = offsets[..., None] + np.arange(dt.itemsize)
            raw = np.ascontiguousarray(rows[:, cols.reshape(-1)])
            out[name] = raw.view(dt).reshape(rows.shape[0], *offsets.shape)
        return mask, out


def _layout(template: bytes, walk: Callable[[_Walk], dict[str, tuple[np.ndarray, str]]],
            expected: dict[str, np.ndarray]) -> FixedLayout | None:
    """The fixed layout of ``template`` walked by ``walk``, if the numbers read at its
    offsets are ``expected`` (the per-message decoder's values) bit for bit; else None."""
    head = bytes(template[:2])
    if len(template) < HEADER or head not in (_LITTLE, _BIG):
        return None
    w = _Walk(len(template))
    try:
        fields = walk(w)
    except (TypeError, ValueError, AttributeError):
        return None
    if HEADER + w.pos != len(template):
        return None
    buf = np.frombuffer(template, dtype=np.uint8)
    at = np.flatnonzero(~w.values)
    layout = FixedLayout(len(template), "<" if head == _LITTLE else ">", at, buf[at].copy(),
                         fields)
    _, got = layout.read([template])
    for name, want in expected.items():
        have = got[name][0]
        want = np.asarray(want, dtype=have.dtype)
        if have.shape != want.shape or have.tobytes() != want.tobytes():
            return None
    return layout


CONTRACT_ARRAYS = ("delta", "phi_l", "phi_r", "cur_l", "cur_r")


def contract_layout(template: bytes, msg: Any) -> FixedLayout | None:
    """The fixed layout of our contract message (:data:`ropod_sysid.io.mcapwrite.CONTRACT_MSGDEF`)
    like ``msg``, the per-message decoding of ``template``: fields ``t`` and the five arrays
    ``values`` (5, len) and ``pose`` (len)."""
    try:
        units, pose = [str(u) for u in msg.units], list(msg.pose)
        arrays = [list(getattr(msg, a)) for a in CONTRACT_ARRAYS]
    except (AttributeError, TypeError):
        return None

    def walk(w: _Walk) -> dict[str, tuple[np.ndarray, str]]:
        t = w.number(8)
        w.count()
        for u in units:
            w.string(u)
        values = [w.numbers(len(a), 8) for a in arrays]
        if len({len(v) for v in values}) != 1:
            raise ValueError("arrays of different lengths")
        return {"t": (np.array(t), "f8"), "values": (np.stack(values), "f8"),
                "pose": (w.numbers(len(pose), 8), "f8")}

    try:
        expected = {"t": np.array(float(msg.t)), "values": np.array(arrays, dtype=np.float64),
                    "pose": np.array(pose, dtype=np.float64)}
    except (TypeError, ValueError):
        return None
    return _layout(template, walk, expected)


def struct_array_layout(template: bytes, items: Sequence[Any],
                        fields: Sequence[tuple[str, int, str]], keep: Sequence[str],
                        ) -> FixedLayout | None:
    """The fixed layout of a message holding one sequence of structs with the primitive
    ``fields`` (name, bytes, numpy type) in order, like ``items`` (its decoded elements):
    the fields ``keep``, each with offsets (len(items),)."""
    def walk(w: _Walk) -> dict[str, tuple[np.ndarray, str]]:
        w.count()
        at: dict[str, list[int]] = {name: [] for name, _, _ in fields}
        for _ in items:
            for name, size, _ in fields:
                at[name].append(w.number(size))
        return {name: (np.array(at[name], dtype=np.int64), kind) for name, _, kind in fields
                if name in keep}

    try:
        expected = {name: np.array([getattr(s, name) for s in items], dtype=kind)
                    for name, _, kind in fields if name in keep}
    except (TypeError, ValueError, AttributeError, OverflowError):
        return None
    return _layout(template, walk, expected)


__all__ = ["FixedLayout", "contract_layout", "struct_array_layout"]
