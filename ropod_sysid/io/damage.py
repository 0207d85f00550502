"""Files that cannot be read to their end: one-line errors for damaged gzip data and I/O errors.

A ``.csv.gz`` that is truncated or corrupt makes the readers fail in different ways — Python's
:mod:`gzip` raises :class:`EOFError` (which click would turn into a bare ``Aborted!``),
:class:`gzip.BadGzipFile` or :class:`zlib.error`, Arrow an :class:`OSError` such as "Truncated
compressed stream". :func:`read_error` turns any of them into one :class:`InputError` line that
says what is wrong with the file, where (the line of the decompressed text), and what to do;
:func:`reading` applies it to a block of reading code.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ropod_sysid.errors import InputError

_GZIP_MAGIC = b"\x1f\x8b"
_BLOCK = 1 << 14   # compressed bytes per step: the damaged step loses its lines


def is_gzip_name(path: Path) -> bool:
    return path.name.lower().endswith(".gz")


def read_error(path: Path, where: str, exc: BaseException) -> InputError:
    """The one-line error for ``exc`` raised while reading ``path`` (named ``where``)."""
    if is_gzip_name(path):
        damage = gzip_damage(path)
        if damage is not None:
            return InputError(f"{where}: {damage}")
    if isinstance(exc, EOFError):
        return InputError(f"{where}: the file ends unexpectedly; copy it again")
    detail = getattr(exc, "strerror", None) or exc
    return InputError(f"{where}: cannot read the log file ({detail})")


@contextmanager
def reading(path: Path, where: str) -> Iterator[None]:
    """Turn the errors of reading ``path`` (I/O, damaged gzip data) into :func:`read_error`."""
    try:
        yield
    except (OSError, EOFError, zlib.error) as exc:
        raise read_error(path, where, exc) from None


def check_gzip_start(path: Path, where: str) -> None:
    """Raise :class:`InputError` if the start of a ``.gz`` file is damaged (its header above
    all: Python's :mod:`gzip` ignores reserved flag bits that zlib and Arrow refuse, so the
    readers would disagree on such a file)."""
    damage = gzip_damage(path, limit=_BLOCK)
    if damage is not None:
        raise InputError(f"{where}: {damage}")


def gzip_damage(path: Path, limit: int | None = None) -> str | None:
    """What is wrong with the gzip data of ``path`` (decompressed once, in blocks, counting
    lines), or None if it decompresses cleanly. Lines count from 1, the header being line 1.
    With ``limit``, only the first ``limit`` compressed bytes are looked at."""
    newlines = 0
    last = b"\n"    # the last decompressed byte
    member = 0       # gzip members (concatenated streams) started
    d = zlib.decompressobj(wbits=31)
    pending = b""
    try:
        with open(path, "rb") as f:
            while True:
                raw = pending or f.read(_BLOCK)
                pending = b""
                if not raw:
                    break
                if limit is not None and f.tell() > limit and member:
                    return None
                if member == 0 or d.eof:
                    if d.eof:
                        d = zlib.decompressobj(wbits=31)
                    if member == 0 and raw[:2] != _GZIP_MAGIC:
                        return ("is not gzip data although the name ends in .gz; rename it to "
                                ".csv if it is plain text, or compress it with gzip")
                    if member and raw[:2] != _GZIP_MAGIC:
                        return (f"has data that is not gzip after the end of the compressed "
                                f"text (after line {newlines}); copy the file again, or cut "
                                "the extra bytes off")
                    member += 1
                before = d.copy()
                try:
                    out = d.decompress(raw)
                except zlib.error as exc:
                    for k in range(len(raw)):   # the block again, byte by byte, up to the damage
                        try:
                            out = before.decompress(raw[k:k + 1])
                        except zlib.error:
                            break
                        newlines += out.count(b"\n")
                        last = out[-1:] or last
                    return _corrupt(str(exc), newlines, last != b"\n")
                newlines += out.count(b"\n")
                last = out[-1:] or last
                if d.eof:
                    pending = d.unused_data
    except OSError as exc:
        return f"cannot read the log file ({exc.strerror or exc})"
    if member == 0:
        return None  # an empty file: the readers say so themselves
    if not d.eof:
        at = f"in line {newlines + 1}" if last != b"\n" else f"after line {newlines}"
        return (f"the compressed data ends early, {at}: the .csv.gz file is truncated — copy it "
                "again, or decompress the readable part (zcat) into a .csv and remove its last, "
                "partial line")
    return None


def _corrupt(reason: str, newlines: int, partial: bool) -> str:
    """The message for a zlib error after ``newlines`` line ends (and a ``partial`` line)."""
    if "incorrect data check" in reason or "incorrect length check" in reason:
        return (f"the gzip checksum does not match: the compressed data is corrupt somewhere in "
                f"lines 1–{max(newlines + partial, 1)}; copy the file again from the recording")
    why = reason.split(":", 1)[-1].strip()
    if newlines == 0:
        return (f"the compressed data is corrupt from its start, in line 1 ({why}); copy the file "
                "again from the recording")
    return (f"the compressed data is corrupt in line {newlines + 1} ({why}); copy the file again "
            f"from the recording, or use the lines before it")
