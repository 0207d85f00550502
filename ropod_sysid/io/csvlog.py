"""The contract CSV log: read with checks, write with exact floats.

Reading uses the Arrow CSV reader (the engine behind ``pandas.read_csv(..., engine="pyarrow")``,
called directly because the pandas wrapper cannot combine explicit column names with a column
selection): multi-threaded for a whole file, on one thread when streaming. Arrow is strict: a wrong
field count or a non-number in a contract column stops it. Whenever Arrow stops, or the parsed
numbers contain NaN or infinity, the file is streamed again through Arrow as text, single-threaded
so that line numbers are known, and checked with vectorised regular expressions to find the first
offending line for the message (or, for harmless oddities the fast reader refuses such as
whitespace-only lines, to read the data). Only if Arrow cannot do even that (e.g. invalid UTF-8)
does Python's :mod:`csv` module go row by row.
That checked path is :mod:`ropod_sysid.io.csvdiagnose`.

Line numbers in messages are 1-based lines of the file, the header being line 1.
"""

from __future__ import annotations

import csv
import gzip
import io
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv

from ropod_sysid.errors import InputError
from ropod_sysid.io.atomic import atomic_path
from ropod_sysid.io.csvdiagnose import (
    _NUMBER,
    _diagnose,
    _diagnose_chunks,
    _line_numbers,
    _open,
)
from ropod_sysid.io.csvdiagnose import check_csv_lines as check_csv_lines
from ropod_sysid.io.csvdiagnose import check_csv_overflow as check_csv_overflow
from ropod_sysid.io.damage import check_gzip_start, is_gzip_name, reading
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import Gaps, TimeBase, check_order, check_times, checked_chunks
from ropod_sysid.platform import Platform

POSE_COLUMNS = ("x_b", "y_b", "theta_b")
MIN_SAMPLES = 3


def contract_columns(platform: Platform) -> list[str]:
    """The required columns of the platform's log, in contract order: ``t``, then per unit
    its angle and current channels (``docs/file-formats.md``)."""
    return ["t", *platform.layout.columns()]


# ---------------------------------------------------------------------------------------------
# reading


def read_csv_log(path: str | Path, platform: Platform, gaps: Gaps = "error") -> Log:
    """Read a contract CSV log for ``platform`` (``.csv``, or gzip-compressed ``.csv.gz``).

    Columns ``t`` and every unit's channels (for a smart wheel ``u``: ``delta_u``, ``phi_uL``,
    ``phi_uR``, ``cur_uL``, ``cur_uR``; :attr:`ropod_sysid.platform.Platform.layout`) are
    required; ``x_b``, ``y_b``, ``theta_b`` are optional (all three columns or none; a tracker
    slower than the log leaves all three cells of the rows between its frames empty, read as
    NaN); other columns are ignored. Every problem raises :class:`InputError` with one line that
    names the file, the line and/or column, and the fix; so does a bad time base
    (:mod:`ropod_sysid.io.timebase`; ``gaps="allow"``: gaps in time are let through).
    """
    where = str(path)
    path = Path(path)
    n_fields, wanted, col_idx, pose_present = _layout(path, where, platform)
    sparse = len(POSE_COLUMNS) if pose_present else 0

    data = _fast_read(path, n_fields, col_idx, sparse)
    if data is None:
        # Arrow stopped, or there is NaN/inf: find the first bad line (raises), or read the
        # oddities the fast reader refuses (whitespace-only lines).
        data = _diagnose(path, where, n_fields, wanted, col_idx, sparse)

    _check_rows(where, data.shape[1], MIN_SAMPLES)
    check_times(data[0], where, _line_numbers(path), gaps)
    return _to_log(data, platform, pose_present, where)


def iter_csv_log(path: str | Path, platform: Platform, chunk_rows: int = 50_000,
                 gaps: Gaps = "error") -> Iterator[Log]:
    """Read a contract CSV log (``.csv`` or ``.csv.gz``) as consecutive logs of ``chunk_rows``
    samples (the last one shorter), in memory bounded by the chunk size.

    The checks and messages are those of :func:`read_csv_log`, applied chunk by chunk with the
    file's line numbers: the header and columns before the first chunk; a row that Arrow
    refuses, a NaN or infinite value, or a bad time base (:mod:`ropod_sysid.io.timebase`,
    checked across chunks) raise :class:`InputError` when the pass reaches them — chunks
    before it may already have been yielded, so a consumer must not act on a partial pass.
    Too few rows raise at the end.
    """
    if chunk_rows < 1:
        raise ValueError(f"chunk_rows must be positive, got {chunk_rows}")
    where = str(path)
    path = Path(path)
    layout = _layout(path, where, platform)
    tb = TimeBase(where, _line_numbers(path), gaps)
    return checked_chunks(_csv_chunks(path, where, platform, chunk_rows, layout), tb)


def _csv_chunks(path: Path, where: str, platform: Platform, chunk_rows: int,
                layout: tuple[int, list[str], list[int], bool]) -> Iterator[Log]:
    """The chunks of :func:`iter_csv_log` before the time checks."""
    n_fields, wanted, col_idx, pose_present = layout
    rows = 0  # rows yielded
    pending: list[np.ndarray] = []  # held back until there are enough rows for a log

    def emit(data: np.ndarray) -> Log:
        nonlocal rows
        rows += data.shape[1]
        return _to_log(data, platform, pose_present, where)

    blocks = _stream_data(path, where, n_fields, wanted, col_idx, chunk_rows,
                          len(POSE_COLUMNS) if pose_present else 0)
    for data in _rechunk(blocks, chunk_rows):
        pending.append(data)
        if rows + sum(p.shape[1] for p in pending) >= MIN_SAMPLES:
            for held in pending:
                yield emit(held)
            pending = []
    _check_rows(where, rows + sum(p.shape[1] for p in pending), MIN_SAMPLES)
    for held in pending:  # pragma: no cover - only with chunk_rows < MIN_SAMPLES
        yield emit(held)


def check_csv_header(path: str | Path, platform: Platform) -> None:
    """The header checks of :func:`read_csv_log` alone (before a long streaming pass)."""
    _layout(Path(path), str(path), platform)


def _layout(path: Path, where: str, platform: Platform
            ) -> tuple[int, list[str], list[int], bool]:
    """Header checks: (number of fields, wanted column names, their indices, pose present)."""
    header = _read_header(path, where)
    names = [h.strip() for h in header]
    required = contract_columns(platform)
    _check_columns(names, required, platform, where)
    pose_present = _all_or_none(names, POSE_COLUMNS, where)
    wanted = required + (list(POSE_COLUMNS) if pose_present else [])
    index = {name: k for k, name in enumerate(names)}
    return len(names), wanted, [index[c] for c in wanted], bool(pose_present)


def _to_log(data: np.ndarray, platform: Platform, pose_present: bool, where: str) -> Log:
    """The log of the wanted columns ``data`` (k, N) in contract order."""
    lay = platform.layout
    base = 1 + len(lay.angle_names) + len(lay.current_names)
    angles, currents = lay.split(data[1:base].T)
    pose = np.ascontiguousarray(data[base:base + 3].T) if pose_present else None
    return Log(np.ascontiguousarray(data[0]), lay, angles, currents, pose, where)


def _rechunk(blocks: Iterator[np.ndarray], rows: int) -> Iterator[np.ndarray]:
    """Blocks of columns (k, m) regrouped into blocks of exactly ``rows`` (the last shorter)."""
    held: list[np.ndarray] = []
    count = 0
    for block in blocks:
        while block.shape[1]:
            take = min(rows - count, block.shape[1])
            held.append(block[:, :take])
            count += take
            block = block[:, take:]
            if count == rows:
                yield held[0] if len(held) == 1 else np.concatenate(held, axis=1)
                held, count = [], 0
    if count:
        yield held[0] if len(held) == 1 else np.concatenate(held, axis=1)


def _check_rows_and_time(path: Path, where: str, t: np.ndarray, min_rows: int) -> None:
    """Enough data rows, and strictly increasing time (one-line errors with file lines)."""
    _check_rows(where, t.shape[0], min_rows)
    check_order(t, where, _line_numbers(path))


def _check_rows(where: str, n: int, min_rows: int) -> None:
    if n == 0:
        raise InputError(
            f"{where}: the file has a header but no data rows; it needs at least "
            f"{min_rows} samples (one row per sample)"
        )
    if n < min_rows:
        raise InputError(
            f"{where}: only {n} data row{'s' if n != 1 else ''}; at least {min_rows} samples "
            "are needed — use a longer log"
        )


def _all_or_none(names: Sequence[str], group: Sequence[str], where: str) -> list[str]:
    """The columns of ``group`` in the header, which must hold all of them or none."""
    present = [c for c in group if c in names]
    if present and len(present) < len(group):
        absent = [c for c in group if c not in names]
        raise InputError(
            f"{where}: column{'s' if len(absent) > 1 else ''} "
            f"{', '.join(repr(c) for c in absent)} missing while "
            f"{', '.join(repr(c) for c in present)} present; give all of "
            f"{', '.join(group)} or none")
    return present


def read_numeric_table(path: str | Path, required: list[str], optional: Sequence[str] = (),
                       min_rows: int = 2) -> dict[str, np.ndarray]:
    """Read a numeric CSV table (setpoints, force schedules) with the log reader's checks.

    ``required`` names the columns to return; the first must be the time column ``t``, which
    must strictly increase. ``optional`` is a group of columns given all together or not at
    all (returned when present). Other columns are ignored. Errors are one line naming the
    file, the line and the column.
    """
    where = str(path)
    path = Path(path)
    if not path.exists():  # the log reader's messages speak of a log
        raise InputError(f"{where}: no such file; check the path")
    names = [h.strip() for h in _read_header(path, where)]
    seen: dict[str, int] = {}
    for k, name in enumerate(names):
        if name in seen and name in required:
            raise InputError(
                f"{where}: column '{name}' appears twice in the header (columns {seen[name] + 1} "
                f"and {k + 1}); remove or rename one of them"
            )
        seen.setdefault(name, k)
    missing = [c for c in required if c not in seen]
    if missing:
        raise InputError(
            f"{where}: column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(repr(c) for c in missing)} missing; the file needs the columns "
            f"{', '.join(required)} (header row first)"
        )
    present = _all_or_none(names, optional, where)
    wanted = list(required) + present
    col_idx = [seen[c] for c in wanted]
    data = _fast_read(path, len(names), col_idx)
    if data is None:
        data = _diagnose(path, where, len(names), wanted, col_idx)
    _check_rows_and_time(path, where, data[0], min_rows)
    return {c: np.ascontiguousarray(data[j]) for j, c in enumerate(wanted)}


def _read_header(path: Path, where: str) -> list[str]:
    with reading(path, where), _open(path, where, binary=True) as f:
        raw = f.readline()
        blank_file = not raw.strip() and not any(
            chunk.strip() for chunk in iter(lambda: f.read(1 << 20), b"")
        )
    if is_gzip_name(path):
        check_gzip_start(path, where)
    if not raw.strip():
        if blank_file:
            raise InputError(
                f"{where}: the file is empty; a log needs a header row (t and the unit "
                "channels, e.g. delta_u, phi_uL, phi_uR, cur_uL, cur_uR) and data rows"
            )
        raise InputError(
            f"{where}: line 1 is empty; the first line must be the header row naming the columns "
            "(t, delta_u, phi_uL, …)"
        )
    try:
        first = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(
            f"{where}: not a UTF-8 text file (line 1 cannot be decoded); save the log as "
            "comma-separated UTF-8 text"
        ) from None
    try:
        header = next(csv.reader([first], skipinitialspace=True))
    except csv.Error as exc:
        raise InputError(f"{where}: line 1 (header) is not valid CSV ({exc})") from None
    return header


def _check_columns(names: list[str], required: list[str], platform: Platform,
                   where: str) -> None:
    seen: dict[str, int] = {}
    for k, name in enumerate(names):
        if name in seen and (name in required or name in POSE_COLUMNS):
            raise InputError(
                f"{where}: column '{name}' appears twice in the header (columns {seen[name] + 1} "
                f"and {k + 1}); remove or rename one of them"
            )
        seen.setdefault(name, k)
    missing = [c for c in required if c not in seen]
    if not missing:
        return
    units_txt = ", ".join(platform.unit_names)
    if "t" in missing and names and _NUMBER.match(names[0]):
        raise InputError(
            f"{where}: line 1 looks like data, not a header; the first line must name the "
            f"columns {platform.columns_text()}"
        )
    if len(names) == 1:
        for sep, label in ((";", "semicolons"), ("\t", "tabs"), ("|", "'|'")):
            if sep in names[0]:
                raise InputError(
                    f"{where}: the header is one column separated by {label}; the log must be "
                    "comma-separated — re-export it with ',' as separator"
                )
    log_units: list[str] = []
    for name in names:
        u = platform.unit_of_column(name)
        if u is not None and u not in log_units:
            log_units.append(u)
    absent = [u for u in platform.unit_names if u not in log_units]
    if log_units and absent:
        raise InputError(
            f"{where}: the log has columns for unit{'s' if len(log_units) > 1 else ''} "
            f"{', '.join(log_units)} but the platform '{platform.name}' expects units "
            f"{units_txt}; use the platform file that matches the log or rename the columns "
            f"({platform.columns_text()})"
        )
    shown = ", ".join(repr(c) for c in missing[:6])
    more = f" and {len(missing) - 6} more" if len(missing) > 6 else ""
    verb = "is" if len(missing) == 1 else "are"
    raise InputError(
        f"{where}: column{'s' if len(missing) > 1 else ''} {shown}{more} {verb} missing; the log "
        f"needs {platform.columns_text()}"
    )


def _fast_read(path: Path, n_cols: int, col_idx: list[int], sparse: int = 0
               ) -> np.ndarray | None:
    """All wanted columns as a (k, N) float64 array, or None if Arrow cannot read the file
    cleanly or a value is NaN or infinite. The last ``sparse`` columns form a group whose cells
    may be empty together (:func:`_sparse_values`: NaN there)."""
    arrow_names = [f"c{k}" for k in range(n_cols)]
    include = [arrow_names[k] for k in col_idx]
    try:
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(column_names=arrow_names, skip_rows=1),
            parse_options=pacsv.ParseOptions(delimiter=","),
            convert_options=pacsv.ConvertOptions(
                column_types={c: pa.float64() for c in include}, include_columns=include,
                null_values=[""],  # only an empty cell is missing ("nan" is a value)
            ),
        )
    except (pa.ArrowException, ValueError, OSError):
        return None
    try:
        return _table_values(table, include, sparse)
    except _FastFailed:
        return None


def _table_values(table: pa.Table, include: list[str], sparse: int) -> np.ndarray:
    """The float64 values (k, N) of an Arrow table's columns ``include``; raises
    :class:`_FastFailed` for a null (an empty cell) or a NaN or infinite value, except that the
    last ``sparse`` columns may be empty together in a row (then NaN: a tracker pose between its
    frames)."""
    n = table.num_rows
    out = np.empty((len(include), n), dtype=np.float64)
    masks = []
    for j, c in enumerate(include):
        col = table.column(c)
        if j >= len(include) - sparse:
            masks.append(col.is_null().to_numpy(zero_copy_only=False) if col.null_count
                         else np.zeros(n, dtype=bool))
            col = pc.fill_null(col, np.nan) if col.null_count else col
        elif col.null_count:
            raise _FastFailed
        float_values(col, out[j])
    finite = np.isfinite(out)
    if masks:
        if any(not np.array_equal(m, masks[0]) for m in masks[1:]):
            raise _FastFailed  # a pose cell given where another one of its row is empty
        finite[-sparse:, masks[0]] = True
    if n and not finite.all():
        raise _FastFailed
    return out


def float_values(col: pa.ChunkedArray, out: np.ndarray) -> None:
    """Copy a null-free float64 Arrow column into ``out`` straight from its data buffers.

    (``to_numpy`` of an Arrow array imports pandas, half a second of a streaming pass.)
    """
    pos = 0
    for chunk in col.chunks:
        n = len(chunk)
        if chunk.type != pa.float64() or chunk.null_count:
            raise ValueError(f"expected a float64 column without nulls, got {chunk.type}")
        out[pos: pos + n] = np.frombuffer(chunk.buffers()[1], dtype=np.float64, count=n,
                                          offset=8 * chunk.offset)
        pos += n


class _FastFailed(Exception):
    pass


def _fast_chunks(path: Path, where: str, n_cols: int, col_idx: list[int], block_bytes: int,
                 sparse: int = 0) -> Iterator[np.ndarray]:
    """Streaming counterpart of :func:`_fast_read`: the wanted columns, ``block_bytes`` of the
    file at a time; raises :class:`_FastFailed` where Arrow stops or a value is NaN, missing or
    infinite.

    The file is cut at line ends here and each piece parsed by Arrow from memory, on one
    thread: the reading runs beside the fit's own threads, and Arrow's multi-threaded reader
    took twice the CPU time for the same wall time on 2 cores (a 60-minute 1 kHz log: 3.9 CPU-s
    against 3.0; its fit 4.9-5.1 s against 4.35-4.5 s). (Arrow's own streaming reader reads
    ahead of a slow consumer without bound — most of a large file.) A field with a quoted line
    break, which a contract log never has, makes a piece unparsable and so takes the checked
    path.
    """
    arrow_names = [f"c{k}" for k in range(n_cols)]
    include = [arrow_names[k] for k in col_idx]
    read_options = pacsv.ReadOptions(column_names=arrow_names, use_threads=False)
    parse_options = pacsv.ParseOptions(delimiter=",")
    convert_options = pacsv.ConvertOptions(column_types={c: pa.float64() for c in include},
                                           include_columns=include, null_values=[""])
    with _open(path, where, binary=True) as f:  # noqa: SIM117 - errors of reading, not opening
        with reading(path, where):  # damaged gzip data, I/O errors
            f.readline()  # the header (one line, as _read_header reads it)
            # one buffer, read into and parsed in place: the piece up to its last line end,
            # the unfinished line moved to the front for the next read (copying each block
            # twice, as joining and slicing bytes does, cost 8 % of a 60-minute log's fit)
            buf = bytearray(block_bytes)
            held = 0  # bytes of an unfinished line at the front of buf
            while True:
                end = held + _read_into(f, buf, held)
                if end == len(buf):  # full: parse up to its last line end
                    cut = buf.rfind(b"\n", 0, end) + 1
                    if cut == 0:  # a line longer than the buffer: read more, into a
                        held = end  # new one (the old may still be exported to Arrow)
                        buf = buf + bytes(len(buf))
                        continue
                else:  # the end of the file
                    cut = end
                if cut and not _blank(buf, cut):
                    with memoryview(buf) as view:
                        yield _parse_piece(view[:cut], include, read_options, parse_options,
                                           convert_options, sparse)
                if end < len(buf):
                    return
                held = end - cut
                buf[:held] = buf[cut:end]


def _read_into(f: io.BufferedIOBase, buf: bytearray, start: int) -> int:
    """Bytes read from ``f`` into ``buf`` from ``start`` on, until it is full or the file ends
    (a gzip stream returns less than asked)."""
    got = start
    with memoryview(buf) as view:
        while got < len(buf):
            n = f.readinto(view[got:])
            if not n:
                break
            got += n
    return got - start


def _blank(buf: bytearray, n: int) -> bool:
    """Whether the first ``n`` bytes of ``buf`` are all white space (copying only a short
    head unless it is blank)."""
    return bytes(buf[:min(n, 64)]).isspace() and bytes(buf[:n]).isspace()


def _parse_piece(piece: bytes | memoryview, include: list[str],
                 read_options: pacsv.ReadOptions,
                 parse_options: pacsv.ParseOptions, convert_options: pacsv.ConvertOptions,
                 sparse: int = 0) -> np.ndarray:
    try:
        table = pacsv.read_csv(pa.BufferReader(pa.py_buffer(piece)), read_options=read_options,
                               parse_options=parse_options, convert_options=convert_options)
    except (pa.ArrowException, ValueError):
        raise _FastFailed from None
    return _table_values(table, include, sparse)


def _stream_data(path: Path, where: str, n_fields: int, wanted: list[str], col_idx: list[int],
                 chunk_rows: int, sparse: int = 0) -> Iterator[np.ndarray]:
    """The wanted columns of the data rows, block by block, with the checks of
    :func:`read_csv_log`: fast Arrow blocks while the file is clean; from the first block Arrow
    refuses (or holding NaN/inf) on, :func:`_diagnose_chunks` from the start of the file, which
    raises for the first bad line or reads on past harmless oddities (blank-looking lines)."""
    block_bytes = max(1 << 16, min(chunk_rows * _row_bytes(path, where), 1 << 28))
    done = 0
    try:
        for data in _fast_chunks(path, where, n_fields, col_idx, block_bytes, sparse):
            done += data.shape[1]
            yield data
        return
    except _FastFailed:
        pass
    for data in _diagnose_chunks(path, where, n_fields, wanted, col_idx, sparse):
        if done >= data.shape[1]:
            done -= data.shape[1]
            continue
        yield data[:, done:]
        done = 0


def _row_bytes(path: Path, where: str) -> int:
    """Bytes per data row, estimated from the first few rows (for Arrow's block size)."""
    with reading(path, where), _open(path, where, binary=True) as f:
        head = f.read(1 << 16)
    lines = head.split(b"\n")[1:-1] or [head]
    return max(16, int(1.25 * max(len(ln) + 1 for ln in lines)))


# ---------------------------------------------------------------------------------------------
# writing


def write_csv_log(log: Log, path: str | Path) -> None:
    """Write ``log`` as a contract CSV (columns of :meth:`Log.columns`), atomically;
    gzip-compressed when the name ends in ``.gz``.

    Floats are written in the shortest form that reads back to the identical float64, so
    :func:`read_csv_log` of the written file returns bit-identical arrays — except that a
    negative zero is written as ``0``. Pose rows without a tracker frame (NaN) are written as
    empty cells.
    """
    cols = log.columns()
    table = pa.table({k: pa.array(np.asarray(v, dtype=np.float64) + 0.0,  # (no "-0")
                                  mask=np.isnan(v) if k in POSE_COLUMNS else None)
                      for k, v in cols.items()})
    opener = gzip.open if str(path).lower().endswith(".gz") else open
    with atomic_path(path) as tmp, opener(tmp, "wb") as f:
        f.write((",".join(cols) + "\n").encode("utf-8"))
        pacsv.write_csv(table, f, pacsv.WriteOptions(include_header=False,
                                                     quoting_style="needed"))
