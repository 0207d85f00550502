"""Contract CSV logs: reading with one-line errors, bit-exact round trips."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from ropod_sysid.errors import InputError
from ropod_sysid.io import csvdiagnose, csvlog
from ropod_sysid.io.csvlog import contract_columns, read_csv_log, write_csv_log
from ropod_sysid.io.log import Log
from ropod_sysid.platform import ropod_platform
from tests.swivel_arrays import C, D, P
from tests.swivel_arrays import make_log as swivel_log

PLATFORM = ropod_platform()
UNITS = PLATFORM.unit_names
COLS = contract_columns(PLATFORM)  # 21 columns


@pytest.fixture(autouse=True, params=["arrow", "small-blocks", "csv-module"])
def locate_mode(request, monkeypatch):
    """Every test runs with each way of locating errors: Arrow streaming in one block, in many
    small blocks (read-ahead across blocks), and the row-by-row csv-module fallback."""
    if request.param == "small-blocks":
        monkeypatch.setattr(csvdiagnose, "_DIAG_BLOCK", 300)  # (the checked path's block)
    elif request.param == "csv-module":
        def refuse(*args, **kwargs):
            raise pa.ArrowInvalid("forced fallback")
        monkeypatch.setattr(csvlog.pacsv, "open_csv", refuse)
    return request.param


def make_log(n: int = 8, pose: bool = False, seed: int = 0) -> Log:
    rng = np.random.default_rng(seed)
    k = len(UNITS)
    return swivel_log(
        t=0.01 * np.arange(n) + 0.5,
        units=list(UNITS),
        delta=rng.uniform(-np.pi, np.pi, (n, k)),
        phi=np.cumsum(rng.normal(size=(n, k, 2)), axis=0),
        current=rng.normal(size=(n, k, 2)),
        pose=rng.normal(size=(n, 3)) if pose else None,
    )


def simple_lines(n: int = 5, header: list[str] | None = None) -> list[str]:
    """Header + n rows of small exact numbers; row r has t = r/10 and value r + c/100."""
    header = header or COLS
    lines = [",".join(header)]
    for r in range(n):
        vals = [f"{r / 10}"] + [f"{r + c / 100}" for c in range(1, len(header))]
        lines.append(",".join(vals))
    return lines


def write(tmp_path, lines, name="run.csv", end="\n"):
    p = tmp_path / name
    p.write_text(end.join(lines) + end, encoding="utf-8")
    return p


def error_of(path) -> str:
    with pytest.raises(InputError) as exc:
        read_csv_log(path, PLATFORM)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(str(path))
    return msg


# ------------------------------------------------------------------ happy paths


def test_round_trip_bit_identical(tmp_path):
    log = make_log(200, pose=True)
    rng = np.random.default_rng(1)
    # awkward floats: random bit patterns, subnormals, signed zero, extremes
    bits = rng.integers(0, 2**64, size=C(log).size, dtype=np.uint64)
    cur = bits.view(np.float64).copy()
    cur[~np.isfinite(cur)] = 1.0 / 3.0
    cur[:6] = [0.0, -0.0, 5e-324, -1.7976931348623157e308, 0.1, 2.0**-1060]
    C(log)[...] = cur.reshape(C(log).shape)
    p = tmp_path / "out" / "log.csv"
    write_csv_log(log, p)
    back = read_csv_log(p, PLATFORM)
    for name in ("t", "angles", "currents", "pose"):
        a, b = getattr(log, name) + 0.0, getattr(back, name)  # a "-0" is written as "0"
        assert a.shape == b.shape and b.dtype == np.float64
        assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), name
    zeros = C(back)[C(back) == 0]
    assert zeros.size and not np.signbit(zeros).any() and ",-0," not in p.read_text()
    assert back.units == UNITS
    assert back.source == str(p)
    assert [f.name for f in p.parent.iterdir()] == ["log.csv"]  # no temporary left behind
    assert p.read_text().splitlines()[0] == ",".join(log.columns())


def test_round_trip_without_pose(tmp_path):
    log = make_log(5)
    p = tmp_path / "log.csv"
    write_csv_log(log, p)
    back = read_csv_log(p, PLATFORM)
    assert back.pose is None
    assert np.array_equal(P(back), P(log))
    assert P(back).shape == (5, 4, 2) and D(back).shape == (5, 4)


def test_layout_of_arrays(tmp_path):
    back = read_csv_log(write(tmp_path, simple_lines(4)), PLATFORM)
    row = 2
    assert back.t[row] == 0.2
    # columns: t, delta_1, phi_1L, phi_1R, cur_1L, cur_1R, delta_2, ...
    assert D(back)[row, 0] == row + 0.01
    assert P(back)[row, 0, 0] == row + 0.02
    assert P(back)[row, 0, 1] == row + 0.03
    assert C(back)[row, 0, 0] == row + 0.04
    assert C(back)[row, 0, 1] == row + 0.05
    assert D(back)[row, 1] == row + 0.06
    assert C(back)[row, 3, 1] == row + 0.20


def test_extra_columns_ignored_and_any_order(tmp_path):
    header = ["note"] + COLS[::-1] + ["comment"]
    lines = [",".join(header)]
    for r in range(4):
        vals = {c: f"{r + k / 100}" for k, c in enumerate(COLS)}
        vals["t"] = f"{r / 10}"
        lines.append(",".join(["hello"] + [vals[c] for c in COLS[::-1]] + ["x y"]))
    back = read_csv_log(write(tmp_path, lines), PLATFORM)
    assert back.t.tolist() == [0.0, 0.1, 0.2, 0.3]
    assert D(back)[1, 0] == 1.01
    assert back.pose is None


def test_quotes_whitespace_crlf_blank_lines(tmp_path):
    header = ", ".join(f'"{c}"' for c in COLS)
    rows = []
    for r in range(4):
        vals = [f" {r / 10} "] + [f'" {r + c / 100}"' for c in range(1, len(COLS))]
        rows.append(" ,".join(vals))
    p = write(tmp_path, [header, rows[0], "", rows[1], rows[2], "", rows[3]], end="\r\n")
    back = read_csv_log(p, PLATFORM)
    assert back.t.tolist() == [0.0, 0.1, 0.2, 0.3]
    assert C(back)[3, 3, 1] == 3.20


def test_whitespace_only_line_is_blank(tmp_path):
    lines = simple_lines(4)
    lines.insert(3, "   ")
    back = read_csv_log(write(tmp_path, lines), PLATFORM)
    assert back.n_samples == 4
    assert P(back)[3, 0, 0] == 3.02


def test_pose_columns_read(tmp_path):
    back = read_csv_log(write(tmp_path, simple_lines(3, COLS + ["x_b", "y_b", "theta_b"])),
                        PLATFORM)
    assert back.pose is not None and back.pose.shape == (3, 3)
    assert back.pose[1].tolist() == [1.21, 1.22, 1.23]


# ------------------------------------------------------------------ bad input


def test_missing_file(tmp_path):
    msg = error_of(tmp_path / "nope.csv")
    assert msg == f"{tmp_path / 'nope.csv'}: no such log file; check the path"


def test_empty_file(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text("")
    assert error_of(p) == (f"{p}: the file is empty; a log needs a header row (t and the unit "
                           "channels, e.g. delta_u, phi_uL, phi_uR, cur_uL, cur_uR) and data "
                           "rows")
    p.write_text("\n  \n\n")
    assert "the file is empty" in error_of(p)


def test_header_only(tmp_path):
    p = write(tmp_path, simple_lines(0))
    assert error_of(p) == (f"{p}: the file has a header but no data rows; it needs at least 3 "
                           "samples (one row per sample)")


def test_missing_column(tmp_path):
    header = [c for c in COLS if c != "phi_2L"]
    p = write(tmp_path, simple_lines(4, header))
    assert error_of(p) == (f"{p}: column 'phi_2L' is missing; the log needs t, delta_u, "
                           "phi_uL, phi_uR, cur_uL, cur_uR for units 1, 2, 3, 4")


def test_several_missing_columns(tmp_path):
    header = [c for c in COLS if c not in ("t", "cur_4R")]
    msg = error_of(write(tmp_path, simple_lines(4, header)))
    assert "columns 't', 'cur_4R' are missing" in msg


def test_duplicate_column(tmp_path):
    header = COLS + ["cur_3L"]
    p = write(tmp_path, simple_lines(4, header))
    assert error_of(p) == (f"{p}: column 'cur_3L' appears twice in the header (columns 15 and "
                           "22); remove or rename one of them")


def test_text_in_number_field(tmp_path):
    lines = simple_lines(6)
    fields = lines[4].split(",")
    fields[COLS.index("phi_1R")] = "abc"
    lines[4] = ",".join(fields)
    p = write(tmp_path, lines)
    assert error_of(p) == (f"{p}: line 5, column 'phi_1R' has 'abc', which is not a number; "
                           "fix the value or remove the line")


def test_text_line_number_counts_blank_lines(tmp_path):
    lines = simple_lines(6)
    lines.insert(2, "")
    fields = lines[5].split(",")
    fields[0] = "1x"
    lines[5] = ",".join(fields)
    msg = error_of(write(tmp_path, lines))
    assert "line 6, column 't' has '1x'" in msg


@pytest.mark.parametrize("token", ["nan", "NaN", "NA", "null"])
def test_nan(tmp_path, token):
    lines = simple_lines(6)
    fields = lines[3].split(",")
    fields[COLS.index("delta_3")] = token
    lines[3] = ",".join(fields)
    p = write(tmp_path, lines)
    assert error_of(p) == (f"{p}: line 4, column 'delta_3' is NaN ({token!r}); the log must be "
                           "finite — repair or remove the line")


@pytest.mark.parametrize("token", ["inf", "-inf", "Infinity"])
def test_infinity(tmp_path, token):
    lines = simple_lines(6)
    fields = lines[6].split(",")
    fields[COLS.index("cur_4L")] = token
    lines[6] = ",".join(fields)
    p = write(tmp_path, lines)
    assert error_of(p) == (f"{p}: line 7, column 'cur_4L' is infinite ({token!r}); the log must "
                           "be finite — repair or remove the line")


def test_empty_field(tmp_path):
    lines = simple_lines(6)
    fields = lines[2].split(",")
    fields[COLS.index("cur_2R")] = ""
    lines[2] = ",".join(fields)
    p = write(tmp_path, lines)
    assert error_of(p) == (f"{p}: line 3, column 'cur_2R' is empty; every contract column needs "
                           "a number on every line — fill it in or remove the line")


def test_nan_in_pose_column(tmp_path):
    lines = simple_lines(5, COLS + ["x_b", "y_b", "theta_b"])
    lines[5] = lines[5].rsplit(",", 1)[0] + ",nan"
    msg = error_of(write(tmp_path, lines))
    assert "line 6, column 'theta_b' is NaN" in msg


@pytest.mark.parametrize("t_bad", ["0.2", "0.15"])
def test_non_increasing_time(tmp_path, t_bad):
    lines = simple_lines(6)
    fields = lines[4].split(",")   # t = 0.3 on line 5; line 4 has t = 0.2
    fields[0] = t_bad
    lines[4] = ",".join(fields)
    p = write(tmp_path, lines)
    if t_bad == "0.2":  # a duplicated timestamp is named as such
        assert error_of(p) == (f"{p}: line 5: time t=0.2 repeats t=0.2 of line 4 (a duplicated "
                               "timestamp); time must strictly increase — remove the repeated "
                               "sample")
        return
    assert error_of(p) == (f"{p}: line 5: time t={float(t_bad)!r} is not after t=0.2 on line 4; "
                           "time must strictly increase — sort the rows or remove repeated "
                           "samples")


def test_non_increasing_time_line_numbers_with_blank_lines(tmp_path):
    lines = simple_lines(6)
    lines[5] = lines[5].replace("0.4,", "0.1,", 1)
    lines.insert(1, "")
    lines.insert(4, "")
    msg = error_of(write(tmp_path, lines))
    assert "line 8: time t=0.1 is not after t=0.3 on line 7" in msg


def test_truncated_last_line(tmp_path):
    lines = simple_lines(6)
    lines[-1] = ",".join(lines[-1].split(",")[:7])
    p = tmp_path / "run.csv"
    p.write_text("\n".join(lines))  # no final newline, as after an interrupted write
    assert error_of(p) == (f"{p}: the last line (7) has 7 of 21 fields — the file looks "
                           "truncated; remove line 7")


def test_short_line_in_the_middle(tmp_path):
    lines = simple_lines(6)
    lines[3] = ",".join(lines[3].split(",")[:20])
    p = write(tmp_path, lines)
    assert error_of(p) == (f"{p}: line 4 has 20 fields but the header has 21; fix or remove "
                           "that line")


def test_long_line(tmp_path):
    lines = simple_lines(6)
    lines[2] += ",7"
    msg = error_of(write(tmp_path, lines))
    assert "line 3 has 22 fields but the header has 21" in msg


def test_unit_names_do_not_match_platform(tmp_path):
    header = ["t"] + [f"{k}_{u}{s}" for u in "ABCD"
                      for k, s in (("delta", ""), ("phi", "L"), ("phi", "R"), ("cur", "L"),
                                   ("cur", "R"))]
    p = write(tmp_path, simple_lines(4, header))
    assert error_of(p) == (f"{p}: the log has columns for units A, B, C, D but the platform "
                           "'ropod' expects units 1, 2, 3, 4; use the platform file that "
                           "matches the log or rename the columns (t, delta_u, phi_uL, phi_uR, "
                           "cur_uL, cur_uR for units 1, 2, 3, 4)")


def test_too_few_samples(tmp_path):
    p = write(tmp_path, simple_lines(2))
    assert error_of(p) == (f"{p}: only 2 data rows; at least 3 samples are needed — use a "
                           "longer log")
    p = write(tmp_path, simple_lines(1))
    assert "only 1 data row;" in error_of(p)


def test_partial_pose(tmp_path):
    p = write(tmp_path, simple_lines(4, COLS + ["x_b", "y_b"]))
    assert error_of(p) == (f"{p}: column 'theta_b' missing while 'x_b', 'y_b' present; give "
                           "all of x_b, y_b, theta_b or none")


def test_no_header_row(tmp_path):
    lines = simple_lines(5)[1:]
    msg = error_of(write(tmp_path, lines))
    assert "line 1 looks like data, not a header" in msg


def test_semicolon_separated(tmp_path):
    lines = [line.replace(",", ";") for line in simple_lines(4)]
    msg = error_of(write(tmp_path, lines))
    assert "separated by semicolons" in msg and "comma-separated" in msg


def test_not_utf8(tmp_path):
    p = tmp_path / "run.csv"
    p.write_bytes("t,delta_1\n0,1\n".encode("utf-16"))
    assert error_of(p) == (f"{p}: not a UTF-8 text file (line 1 cannot be decoded); save the "
                           "log as comma-separated UTF-8 text")


def test_not_utf8_in_the_middle(tmp_path):
    p = tmp_path / "run.csv"
    lines = simple_lines(5)
    p.write_bytes(("\n".join(lines[:3]) + "\n").encode() + b"0.3\xff\xfe" + b",1" * 20 + b"\n")
    assert error_of(p) == (f"{p}: line 4, column 't' has bytes that are not UTF-8 text "
                           "('0.3\ufffd\ufffd'); the file is damaged there — repair or remove "
                           "the line")


def test_errors_after_many_rows(tmp_path):
    """Bad rows deep in the file, across several blocks: the first one is named."""
    lines = simple_lines(400)
    fields = lines[300].split(",")
    fields[COLS.index("phi_4L")] = "oops"
    lines[300] = ",".join(fields)
    lines[350] = ",".join(lines[350].split(",")[:5])
    lines.insert(100, "")
    p = write(tmp_path, lines)
    assert "line 302, column 'phi_4L' has 'oops'" in error_of(p)
    lines[301] = lines[301].replace("oops", "1.5")
    p = write(tmp_path, lines)
    assert "line 352 has 5 fields but the header has 21" in error_of(p)
    del lines[351]
    lines.append(",".join(lines[-1].split(",")[:9]))
    p = write(tmp_path, lines)
    assert error_of(p).endswith("the last line (402) has 9 of 21 fields — the file looks "
                                "truncated; remove line 402")


def test_gzip_round_trip_is_bit_exact(tmp_path):
    """Logs ending in .csv.gz are written compressed and read back bit for bit."""
    import gzip

    from ropod_sysid.io import read_log, write_log
    from ropod_sysid.platform import ropod_platform

    pf = ropod_platform()
    rng = np.random.default_rng(3)
    n = 200
    log = swivel_log(np.arange(n) * 0.01, pf.unit_names, rng.normal(size=(n, 4)),
                     rng.normal(size=(n, 4, 2)), rng.normal(size=(n, 4, 2)))
    path = tmp_path / "run.csv.gz"
    write_log(log, path)
    with gzip.open(path, "rt") as f:
        assert f.readline().startswith("t,delta_1,phi_1L")
    back = read_log(path, pf)
    for name in ("t", "angles", "currents"):
        assert np.array_equal(getattr(back, name), getattr(log, name))


@pytest.mark.parametrize("compressed", [False, True])
def test_fast_chunks_of_any_block_size_are_the_file(tmp_path, compressed):
    """The streaming reader's pieces (one buffer, parsed in place, the unfinished line carried
    to the next read) give the file's values whatever the block size: smaller than a line (the
    buffer grows), a line and a bit, many lines; plain and gzip (which reads short)."""
    import gzip

    rng = np.random.default_rng(3)
    values = rng.normal(size=(200, 4)) * 10.0 ** rng.integers(-3, 12, size=(200, 4))
    long_row = 150  # one line far longer than the others
    lines = ["a,b,c,d"] + [",".join(repr(float(v)) for v in row) for row in values]
    lines[1 + long_row] = ",".join(f"{float(v):.300e}" for v in values[long_row])
    text = ("\n".join(lines) + "\n").encode()
    path = tmp_path / ("t.csv.gz" if compressed else "t.csv")
    path.write_bytes(gzip.compress(text) if compressed else text)
    expected = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]]).T
    for block in (7, 40, 1000, 1 << 20):
        parts = list(csvlog._fast_chunks(path, str(path), 4, [0, 1, 2, 3], block))
        got = np.concatenate(parts, axis=1)
        np.testing.assert_array_equal(got, expected, err_msg=f"block {block}")
        if block < len(lines[1 + long_row]):
            assert len(parts) > 2
