"""The checked path of the contract CSV reader (:mod:`ropod_sysid.io.csvlog`): the first bad line.

When the fast Arrow reader stops, or the parsed numbers contain NaN or infinity, the file is
streamed again through Arrow as text, single-threaded so that line numbers are known, and
checked with vectorised regular expressions (:func:`_diagnose_chunks`): it raises a one-line
:class:`InputError` naming the first offending line and column, or, for harmless oddities the
fast reader refuses such as whitespace-only lines, reads the data. Only if Arrow cannot do even
that (e.g. invalid UTF-8) does Python's :mod:`csv` module go row by row (:func:`_slow_read`).
Also here: the file opener both paths share, the file lines of data rows for the time-base
messages (:func:`_line_numbers`), and the line checks offered to readers of other CSV layouts
(:func:`check_csv_lines`, :func:`check_csv_overflow`).

Line numbers in messages are 1-based lines of the file, the header being line 1.
"""

from __future__ import annotations

import codecs
import csv
import gzip
import math
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from ropod_sysid.errors import InputError
from ropod_sysid.io.damage import read_error, reading
from ropod_sysid.io.timebase import Locate

_DIAG_BLOCK = 1 << 22   # bytes per block when locating an error
_NUMBER = re.compile(
    r"^[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)$", re.IGNORECASE
)
# Arrow's default null spellings: they parse as missing, which we report as NaN.
_FINITE_RE = r"^[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$"
_NULLS = {"#n/a", "#n/a n/a", "#na", "-1.#ind", "-1.#qnan", "-nan", "1.#ind", "1.#qnan", "n/a",
          "na", "null", "nan", "+nan"}


def _open(path: Path, where: str, binary: bool = False):
    """Open the log (binary, or as text with undecodable bytes shown as U+FFFD)."""
    gz = path.name.lower().endswith(".gz")
    try:
        if binary:
            return gzip.open(path, "rb") if gz else open(path, "rb")  # noqa: SIM115
        if gz:
            return gzip.open(path, "rt", encoding="utf-8-sig", errors="replace", newline="")
        return open(path, encoding="utf-8-sig", errors="replace", newline="")  # noqa: SIM115
    except FileNotFoundError:
        raise InputError(f"{where}: no such log file; check the path") from None
    except IsADirectoryError:
        raise InputError(f"{where}: is a directory, not a CSV log file; give the file") from None
    except OSError as exc:
        raise InputError(f"{where}: cannot read the log file ({exc.strerror or exc})") from None


def check_csv_lines(path: str | Path, n_fields: int, columns: dict[str, int]) -> None:
    """Raise the :class:`InputError` of :func:`ropod_sysid.io.csvlog.read_csv_log` for the
    first damaged line of a CSV with a one-line header and ``n_fields`` fields per line, if
    any: a wrong field count, or a value in ``columns`` (name → field index) that is empty,
    text, NaN or infinite.

    For readers of other CSV layouts, to name the line when their own parse fails.
    """
    for _ in _diagnose_chunks(Path(path), str(path), n_fields, list(columns),
                              list(columns.values())):
        pass


def check_csv_overflow(path: str | Path, columns: dict[str, int], rows: np.ndarray) -> None:
    """Raise :class:`InputError` for the first of the data ``rows`` (0-based, in file order)
    whose value in ``columns`` (name → field index) is written as a finite number but is too
    large for a float (``1e400``) — for readers that keep spelled-out NaN and infinity (the
    smart-wheel layout drops those frames) but must not take damaged digits for them."""
    where = str(path)
    wanted = set(np.asarray(rows).tolist())
    if not wanted:
        return
    last = max(wanted)
    finite_text = re.compile(_FINITE_RE)
    for r, (line, rec) in enumerate(_records(Path(path), where)):
        if r in wanted:
            for name, k in columns.items():
                text = rec[k].strip() if k < len(rec) else ""
                if finite_text.match(text) and math.isinf(float(text)):
                    raise InputError(f"{where}: line {line}, column '{name}' "
                                     f"{_value_problem(text)}")
        if r >= last:
            return


def _diagnose(path: Path, where: str, n_fields: int, wanted: list[str],
              col_idx: list[int], sparse: int = 0) -> np.ndarray:
    """Error path: stream the file through Arrow as text, single-threaded so that Arrow knows
    the line numbers; raise for the first bad line, or return the data when nothing is wrong
    but blank-looking lines. Falls back to the csv module if Arrow cannot even do that."""
    chunks = list(_diagnose_chunks(path, where, n_fields, wanted, col_idx, sparse))
    if not chunks:
        return np.empty((len(col_idx), 0), dtype=np.float64)
    return np.concatenate(chunks, axis=1)


def _diagnose_chunks(path: Path, where: str, n_fields: int, wanted: list[str],
                     col_idx: list[int], sparse: int = 0) -> Iterator[np.ndarray]:
    """:func:`_diagnose` block by block: yields the data of clean blocks as (k, m) arrays and
    raises :class:`InputError` at the first bad line (a wrong field count only once the rows
    after it show it is not the truncated last line). The last ``sparse`` wanted columns may
    be empty together in a row (NaN there: a tracker pose between its frames)."""
    import pyarrow.compute as pc  # only the slow, checked path needs it

    arrow_names = [f"c{k}" for k in range(n_fields)]
    skipped: list[int] = []                 # lines Arrow did not turn into rows, ascending
    invalid: list[tuple[int, int]] = []     # (line, fields) of non-blank wrong-length rows

    def on_invalid(row: Any) -> str:
        if row.number is None:
            raise _NoLineNumbers
        skipped.append(row.number)
        if row.text.strip():
            invalid.append((row.number, row.actual_columns))
        return "skip"

    def line_of(r: int) -> int:
        line = 2 + r
        for s in skipped:
            if s > line:
                break
            line += 1
        return line

    def count_error(last: bool) -> InputError:
        line, got = invalid[0]
        if last and got < n_fields:
            return InputError(
                f"{where}: the last line ({line}) has {got} of {n_fields} fields — the file "
                f"looks truncated; remove line {line}"
            )
        hint = " (or add the missing column names to the header)" if got > n_fields else ""
        return InputError(
            f"{where}: line {line} has {got} field{'s' if got != 1 else ''} but the header has "
            f"{n_fields}; fix or remove that line{hint}"
        )

    order = sorted(range(len(col_idx)), key=col_idx.__getitem__)   # file column order
    yielded = 0
    row0 = 0
    last_data_line = 0
    reader: pacsv.CSVStreamingReader | None = None
    try:
        if not _valid_utf8(path, where):
            # Arrow's handler of bad rows would fail to decode their text ("Exception
            # ignored"): the csv module reads the bytes as U+FFFD instead
            raise _NoLineNumbers
        reader = pacsv.open_csv(
            path,
            read_options=pacsv.ReadOptions(use_threads=False, column_names=arrow_names,
                                           skip_rows=1, block_size=_DIAG_BLOCK),
            parse_options=pacsv.ParseOptions(delimiter=",", ignore_empty_lines=False,
                                             invalid_row_handler=on_invalid),
            convert_options=pacsv.ConvertOptions(
                column_types={c: pa.string() for c in arrow_names},
                strings_can_be_null=False, quoted_strings_can_be_null=False,
            ),
        )
        for batch in reader:
            n = batch.num_rows
            cols = [pc.utf8_trim_whitespace(batch.column(k)) for k in range(n_fields)]
            blank = np.ones(n, dtype=bool)
            for c in cols:
                blank &= pc.equal(c, "").to_numpy(zero_copy_only=False)
            first: tuple[int, int] | None = None
            group = range(len(col_idx) - sparse, len(col_idx))
            skip = np.zeros(n, dtype=bool)  # rows whose sparse group is empty
            if sparse:
                skip[:] = True
                for j in group:
                    skip &= pc.equal(cols[col_idx[j]], "").to_numpy(zero_copy_only=False)
            for j in order:
                ok = pc.match_substring_regex(cols[col_idx[j]], _FINITE_RE)
                ok = ok.to_numpy(zero_copy_only=False) | (skip if j in group else False)
                bad = np.flatnonzero(~ok & ~blank)
                if bad.size and (first is None or bad[0] < first[0]):
                    first = (int(bad[0]), j)
            if first is not None:
                line = line_of(row0 + first[0])
                if not invalid or line < invalid[0][0]:
                    raw = batch.column(col_idx[first[1]])[first[0]].as_py()
                    problem = _value_problem(raw) or "is not a finite number"
                    raise InputError(f"{where}: line {line}, column '{wanted[first[1]]}' "
                                     f"{problem}")
            data_rows = np.flatnonzero(~blank)
            if data_rows.size:
                last_data_line = line_of(row0 + int(data_rows[-1]))
            if invalid and (len(invalid) > 1 and invalid[1][0] <= last_data_line
                            or last_data_line > invalid[0][0]):
                raise count_error(last=False)
            row0 += n
            if not invalid:
                keep = pa.array(~blank)
                texts = [cols[k] if j not in group else
                         pc.replace_substring_regex(cols[k], "^$", "nan")
                         for j, k in enumerate(col_idx)]
                data = np.array(
                    [pc.cast(pc.filter(c, keep), pa.float64()).to_numpy() for c in texts],
                    dtype=np.float64).reshape(len(col_idx), -1)
                nonfinite = ~np.isfinite(data)   # numbers too large for a float (1e400)
                if sparse:
                    nonfinite[-sparse:, skip[~blank]] = False
                if nonfinite.any():
                    r = int(np.flatnonzero(nonfinite.any(axis=0))[0])
                    j = next(j for j in order if nonfinite[j, r])
                    raw = batch.column(col_idx[j])[int(data_rows[r])].as_py()
                    raise InputError(f"{where}: line {line_of(row0 - n + int(data_rows[r]))}, "
                                     f"column '{wanted[j]}' {_value_problem(raw)}")
                yielded += data.shape[1]
                yield data
    except OSError as exc:      # damaged gzip data (Arrow decompresses .gz itself)
        raise read_error(path, where, exc) from None
    except (_NoLineNumbers, pa.ArrowException):
        # Arrow cannot even read it as text: the csv module, row by row (the rows already
        # yielded are skipped)
        rest = _slow_read(path, where, n_fields, wanted, col_idx, sparse)
        if rest.shape[1] > yielded:
            yield rest[:, yielded:]
        return
    finally:
        # stop Arrow's reader now, not when an error's traceback lets go of this frame (at
        # interpreter exit its threads may be gone: "Exception ignored" or an abort)
        if reader is not None:
            reader.close()
    if invalid:
        raise count_error(last=len(invalid) == 1 and last_data_line < invalid[0][0])


class _NoLineNumbers(Exception):
    pass


def _valid_utf8(path: Path, where: str) -> bool:
    """Whether the whole file is UTF-8 text (one decoding pass, error path only)."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    with reading(path, where), _open(path, where, binary=True) as f:
        try:
            for block in iter(lambda: f.read(_DIAG_BLOCK), b""):
                decoder.decode(block)
            decoder.decode(b"", final=True)
        except UnicodeDecodeError:
            return False
    return True


def _records(path: Path, where: str) -> Iterator[tuple[int, list[str]]]:
    """Non-blank data records after the header, with the file line each starts on."""
    with reading(path, where), _open(path, where) as f:
        reader = csv.reader(f, skipinitialspace=True)
        try:
            next(reader)
            prev = reader.line_num
            for rec in reader:
                start, prev = prev + 1, reader.line_num
                if not rec or all(not field.strip() for field in rec):
                    continue
                yield start, rec
        except csv.Error as exc:
            raise InputError(
                f"{where}: line {reader.line_num + 1} is not valid CSV ({exc}); fix or remove it"
            ) from None


def _value_problem(text: str) -> str | None:
    s = text.strip()
    low = s.lower()
    if not s:
        return "is empty; every contract column needs a number on every line — fill it in or " \
               "remove the line"
    if low in _NULLS:
        return f"is NaN ({s!r}); the log must be finite — repair or remove the line"
    if "\ufffd" in s:   # undecodable bytes, read as U+FFFD
        return (f"has bytes that are not UTF-8 text ({s!r}); the file is damaged there — "
                "repair or remove the line")
    if not _NUMBER.match(s):
        return f"has {s!r}, which is not a number; fix the value or remove the line"
    if low.lstrip("+-") in ("inf", "infinity"):
        return f"is infinite ({s!r}); the log must be finite — repair or remove the line"
    if math.isinf(float(s)):
        shown = repr(s) if len(s) <= 24 else f"a number of {len(s)} characters ({s[:10]!r}…)"
        return (f"has {shown}, which is too large for a float (it overflows to infinity); the "
                "log must be finite — repair or remove the line")
    return None


def _slow_read(path: Path, where: str, n_fields: int, wanted: list[str],
               col_idx: list[int], sparse: int = 0) -> np.ndarray:
    """Last resort, per-row Python: raise for the first bad line, else return the data (the
    last ``sparse`` wanted columns may be empty together: NaN)."""
    rows: list[list[float]] = []
    short: tuple[int, int] | None = None   # (line, fields) of a short record, maybe the last
    isfinite = math.isfinite
    for line, rec in _records(path, where):
        if short is not None:
            raise InputError(
                f"{where}: line {short[0]} has {short[1]} field{'s' if short[1] != 1 else ''} but "
                f"the header has {n_fields}; fix or remove that line"
            )
        if len(rec) < n_fields:
            short = (line, len(rec))
            continue
        if len(rec) > n_fields:
            raise InputError(
                f"{where}: line {line} has {len(rec)} fields but the header has {n_fields}; "
                "fix or remove that line (or add the missing column names to the header)"
            )
        fields = [rec[k] for k in col_idx]
        if sparse and all(not f.strip() for f in fields[-sparse:]):
            fields[-sparse:] = ["nan"] * sparse
            try:
                values = list(map(float, fields))
                ok = all(map(isfinite, values[:-sparse])) and "_" not in "".join(fields)
            except ValueError:
                ok = False
            if ok:
                rows.append(values)
                continue
        try:
            values = list(map(float, fields))
            ok = all(map(isfinite, values)) and "_" not in "".join(fields)
        except ValueError:
            ok = False
        if not ok:
            for j, text in enumerate(fields):
                problem = _value_problem(text)
                if problem is not None:
                    raise InputError(f"{where}: line {line}, column '{wanted[j]}' {problem}")
            raise InputError(f"{where}: line {line} has a value that is not a number; fix or "
                             "remove that line")
        rows.append(values)
    if short is not None:
        raise InputError(
            f"{where}: the last line ({short[0]}) has {short[1]} of {n_fields} fields — the file "
            f"looks truncated; remove line {short[0]}"
        )
    return np.array(rows, dtype=np.float64).reshape(-1, len(col_idx)).T


def _line_numbers(path: Path) -> Locate:
    """``locate`` of :mod:`ropod_sysid.io.timebase` for a CSV log: the data rows' file lines."""
    def locate(rows: Sequence[int]) -> list[str]:
        lines = _data_row_lines(path, max(rows) + 1)
        return [f"line {lines[r]}" for r in rows]
    return locate


def _data_row_lines(path: Path, count: int) -> list[int]:
    """File line numbers of the first ``count`` data rows (error path only)."""
    lines: list[int] = []
    for line, _ in _records(path, str(path)):
        lines.append(line)
        if len(lines) >= count:
            break
    return lines
