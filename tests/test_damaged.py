"""Damaged files: one line naming the file, the line and the fix (exit 2, the input unchanged,
no output file) from every command that reads them; and a property-based fuzz test of the CSV
and MCAP readers and of ``fit``."""

from __future__ import annotations

import gzip
import os
import time
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.io import read_log, write_log
from ropod_sysid.io.csvlog import iter_csv_log, read_csv_log
from ropod_sysid.io.log import Log
from ropod_sysid.io.mcaplog import iter_mcap_log, read_mcap_log
from ropod_sysid.io.smartwheel import REQUIRED_FLOATS, write_smartwheel
from ropod_sysid.platform import load_platform, save_platform
from ropod_sysid.simulate import simulate
from tests.conftest import smooth_setpoints
from tests.swivel_arrays import C, D, P, make_log
from tests.test_cli import one_line_error

# Reproducible by default (the same examples on every run, no example database); set
# ROPOD_FUZZ=random (and ROPOD_FUZZ_EXAMPLES) to search afresh while developing.
_RANDOM = os.environ.get("ROPOD_FUZZ") == "random"
FUZZ = settings(
    max_examples=int(os.environ.get("ROPOD_FUZZ_EXAMPLES", "30")),
    derandomize=not _RANDOM, database=None, deadline=None,  # time is bounded by the property
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
TIME_LIMIT = 10.0  # seconds per read or per fit of a damaged 12 s log
# an exception a callback or a finaliser could only print ("Exception ignored in ...") fails
pytestmark = pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
FIELDS = 21        # t + 4 units × 5 columns


@pytest.fixture(scope="module")
def d(tmp_path_factory, off_square, truth) -> Path:
    """A short valid log (12 s at 100 Hz: long enough to fit) in every format, its platform and
    fitted parameters."""
    d = tmp_path_factory.mktemp("damaged")
    (run,) = simulate(off_square, truth, [smooth_setpoints(3.0, 1, 1)], rate=100.0)
    run.log = there_and_back(there_and_back(run.log))
    save_platform(off_square, d / "platform.yaml")
    write_log(run.log, d / "ok.csv")
    write_log(run.log, d / "ok.mcap")
    write_smartwheel(run.log, d / "sw.csv", off_square)
    write_smartwheel(run.log, d / "sw.mcap", off_square)
    r = cli("fit", str(d / "ok.csv"), "--platform", str(d / "platform.yaml"), "--out",
            str(d / "params.json"), "--quiet")
    assert r.exit_code == 0, r.output
    return d


def there_and_back(log: Log) -> Log:
    """The rest-to-rest run followed by itself backwards in time: every channel continuous, the
    wheels' no-slip constraints kept (they are homogeneous in the rates), twice the length."""
    t = np.concatenate([log.t, log.t[-1] + (log.t[1] - log.t[0]) + (log.t - log.t[0])])
    def back(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a, a[::-1]])
    return make_log(t, list(log.units), back(D(log)), back(P(log)), back(C(log)),
                    source=log.source)


def cli(*args: str):
    return CliRunner().invoke(main, list(args))


def command(name: str, log: Path, d: Path, platform: Path | None = None) -> list[str]:
    """The arguments of ``name`` reading ``log`` (outputs next to the log)."""
    pf = str(platform or d / "platform.yaml")
    out = log.parent
    return {
        "fit": ["fit", str(log), "--platform", pf, "--out", str(out / "out.json"), "--quiet"],
        "inspect": ["inspect", str(log), "--platform", pf],
        "convert": ["convert", str(log), str(out / "out.mcap"), "--platform", pf],
        "validate": ["validate", str(log), "--platform", pf, "--params", str(d / "params.json")],
    }[name]


COMMANDS = ("fit", "inspect", "convert", "validate")


def refused(args: list[str], inputs: list[Path], message: str) -> None:
    """``args`` exits 2 with exactly ``error: message``, leaves the inputs as they were and
    writes nothing."""
    folder = inputs[0].parent
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    r = cli(*args)
    one_line_error(r)
    assert r.output.strip() == f"error: {message}"
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


# ---------------------------------------------------------------------------------------------
# damaged logs, one class at a time


def lines_of(d: Path) -> list[bytes]:
    return (d / "ok.csv").read_bytes().split(b"\n")


def with_field(lines: list[bytes], line: int, field: int, value: bytes) -> bytes:
    """The file with field ``field`` of (1-based) line ``line`` replaced."""
    out = list(lines)
    fields = out[line - 1].split(b",")
    fields[field] = value
    out[line - 1] = b",".join(fields)
    return b"\n".join(out)


def gz_truncated(d: Path) -> tuple[bytes, str]:
    packed = gzip.compress((d / "ok.csv").read_bytes())
    cut = packed[: len(packed) // 2]
    line = zlib.decompressobj(wbits=31).decompress(cut).count(b"\n") + 1
    return cut, (f"the compressed data ends early, in line {line}: the .csv.gz "
                 "file is truncated — copy it again, or decompress the readable part (zcat) "
                 "into a .csv and remove its last, partial line")


def gz_checksum(d: Path) -> tuple[bytes, str]:
    packed = bytearray(gzip.compress((d / "ok.csv").read_bytes()))
    packed[-6] ^= 0x10                                   # in the CRC-32 of the trailer
    n = (d / "ok.csv").read_bytes().count(b"\n")
    return bytes(packed), (f"the gzip checksum does not match: the compressed data is corrupt "
                           f"somewhere in lines 1–{n}; copy the file again from the recording")


def gz_plain(d: Path) -> tuple[bytes, str]:
    return (d / "ok.csv").read_bytes(), ("is not gzip data although the name ends in .gz; rename "
                                         "it to .csv if it is plain text, or compress it with "
                                         "gzip")


def not_utf8(d: Path) -> tuple[bytes, str]:
    lines = lines_of(d)
    value = lines[50].split(b",")[1]
    data = with_field(lines, 51, 1, b"\xff\xfe" + value)
    shown = "\ufffd\ufffd" + value.decode()
    return data, (f"line 51, column 'delta_1' has bytes that are not UTF-8 text ({shown!r}); the "
                  "file is damaged there — repair or remove the line")


def overflow(d: Path) -> tuple[bytes, str]:
    return with_field(lines_of(d), 41, 3, b"1e400"), (
        "line 41, column 'phi_1R' has '1e400', which is too large for a float (it overflows to "
        "infinity); the log must be finite — repair or remove the line")


def many_digits(d: Path) -> tuple[bytes, str]:
    return with_field(lines_of(d), 41, 3, b"-" + b"9" * 400), (
        "line 41, column 'phi_1R' has a number of 401 characters ('-999999999'…), which is too "
        "large for a float (it overflows to infinity); the log must be finite — repair or remove "
        "the line")


def short_line_not_utf8(d: Path) -> tuple[bytes, str]:
    """A cut line with a bad byte: Arrow's handler of bad rows cannot even decode its text."""
    lines = lines_of(d)
    lines[40] = lines[40][:60] + b"\xac"
    got = lines[40].count(b",") + 1
    return b"\n".join(lines), (f"line 41 has {got} fields but the header has {FIELDS}; fix or "
                               "remove that line")


CONTRACT_CASES = {"not_utf8": not_utf8, "short_line_not_utf8": short_line_not_utf8,
                  "overflow": overflow, "many_digits": many_digits}
def gz_header(d: Path) -> tuple[bytes, str]:
    """A reserved flag bit set: zlib and Arrow refuse it, Python's gzip would read on."""
    packed = bytearray(gzip.compress((d / "ok.csv").read_bytes()))
    packed[3] |= 0x40
    return bytes(packed), ("the compressed data is corrupt from its start, in line 1 (unknown "
                           "header flags set); copy the file again from the recording")


GZIP_CASES = {"gz_truncated": gz_truncated, "gz_checksum": gz_checksum, "gz_plain": gz_plain,
              "gz_header": gz_header}


@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize("case, compressed", [(c, z) for c in CONTRACT_CASES for z in (0, 1)]
                         + [(c, 1) for c in GZIP_CASES])
def test_damaged_contract_csv_is_one_line(tmp_path, d, case, compressed, name):
    if case in GZIP_CASES:
        data, message = GZIP_CASES[case](d)
    else:
        data, message = CONTRACT_CASES[case](d)
        data = gzip.compress(data) if compressed else data
    log = tmp_path / ("run.csv.gz" if compressed else "run.csv")
    log.write_bytes(data)
    refused(command(name, log, d), [log], f"{log}: {message}")


def sw_lines(d: Path) -> list[bytes]:
    return (d / "sw.csv").read_bytes().split(b"\n")


def sw_field(d: Path, name: str) -> int:
    return sw_lines(d)[0].decode().split(",").index(name)


def sw_not_utf8(d: Path) -> tuple[bytes, str]:
    k = sw_field(d, "sensors.0.encoder_1")
    return with_field(sw_lines(d), 41, k, b"\xff\xfe"), (
        "line 41, column 'sensors.0.encoder_1' has bytes that are not UTF-8 text "
        "('\ufffd\ufffd'); the file is damaged there — repair or remove the line")


def sw_overflow(d: Path) -> tuple[bytes, str]:
    k = sw_field(d, "sensors.2.current_1_q")
    return with_field(sw_lines(d), 30, k, b"1e400"), (
        "line 30, column 'sensors.2.current_1_q' has '1e400', which is too large for a float (it "
        "overflows to infinity); the log must be finite — repair or remove the line")


def sw_truncated(d: Path) -> tuple[bytes, str]:
    data = (d / "sw.csv").read_bytes()
    lines = data.split(b"\n")
    cut = len(b"\n".join(lines[:200])) + 1 + len(lines[200]) // 2
    got = data[:cut].split(b"\n")[-1].count(b",") + 1
    n = lines[0].count(b",") + 1
    return data[:cut], (f"the last line (201) has {got} of {n} fields — the file looks "
                        "truncated; remove line 201")


def sw_clock_digits(d: Path) -> tuple[bytes, str]:
    k = sw_field(d, "sensors.1.sensor_ts")
    return with_field(sw_lines(d), 12, k, b"9" * 30), (
        "line 12, column 'sensors.1.sensor_ts' has '999999999999… (30 digits)', which is not a "
        "whole number of nanoseconds from 0 to 2^64 − 1; fix the value or remove the line")


SW_CASES = {"not_utf8": sw_not_utf8, "overflow": sw_overflow, "truncated": sw_truncated,
            "clock_digits": sw_clock_digits}


@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize("case", list(SW_CASES))
def test_damaged_smartwheel_csv_is_one_line(tmp_path, d, case, name):
    data, message = SW_CASES[case](d)
    log = tmp_path / "sw.csv"
    log.write_bytes(data)
    refused(command(name, log, d), [log], f"{log}: {message}")


def test_spelled_out_nan_in_the_smartwheel_layout_is_still_a_dropped_frame(tmp_path, d):
    k = sw_field(d, "sensors.2.current_1_q")
    log = tmp_path / "sw.csv"
    log.write_bytes(with_field(sw_lines(d), 30, k, b"inf"))
    with pytest.warns(UserWarning, match=r"1 with NaN or infinite values: frames #28 "):
        out = read_log(log, load_platform(d / "platform.yaml"))
    assert out.n_samples == 4 * 301 - 1  # one frame of four 3 s runs dropped


def mcap_with_message(d: Path, path: Path, k: int, replace: tuple[bytes, bytes]) -> None:
    """The short log as a contract JSON MCAP (intact CRCs) whose message ``k`` has its first
    ``replace[0]`` replaced by ``replace[1]`` (a producer that wrote a bad value)."""
    import json
    import re

    from ropod_sysid.io.mcaplog import UNIT_FIELDS
    from ropod_sysid.io.mcapwrite import (
        CONTRACT_JSON_SCHEMA,
        CONTRACT_TOPIC,
        contract_json_schema,
        new_writer,
    )

    log = read_log(d / "ok.csv", load_platform(d / "platform.yaml"))
    with open(path, "wb") as f:
        w = new_writer(f)
        sid = w.register_schema(CONTRACT_JSON_SCHEMA, "jsonschema",
                                json.dumps(contract_json_schema(log.layout, False)).encode())
        cid = w.register_channel(CONTRACT_TOPIC, "json", sid, {"layout": "ropod_sysid/contract"})
        for j in range(log.n_samples):
            vals = np.stack([D(log)[j], P(log)[j, :, 0], P(log)[j, :, 1],
                             C(log)[j, :, 0], C(log)[j, :, 1]], axis=-1).tolist()
            msg = {"t": float(log.t[j]), "units": {
                u: dict(zip(UNIT_FIELDS, v, strict=True)) for u, v in zip(log.units, vals,
                                                                          strict=True)}}
            payload = json.dumps(msg).encode()
            if j == k:
                payload = re.sub(replace[0], replace[1], payload, count=1)
            ns = int(round(float(log.t[j]) * 1e9))
            w.add_message(cid, ns, payload, ns, j)
        w.finish()


MCAP_CASES = {
    "many_digits": ((rb'"phi_R": [^,}]+', b'"phi_R": ' + b"9" * 400),
                    "message 40 has a number too large for a float in units.1.phi_R (400 digits; "
                    "it overflows to infinity); the log must be finite — repair or cut the "
                    "recording"),
    "overflow": ((rb'"cur_L": [^,}]+', b'"cur_L": -1e400'),
                 "message 40 has a NaN or infinite value (units.1.cur_L = -inf); the log must be "
                 "finite — repair or cut the recording"),
    "text": ((rb'"t": [^,}]+', b'"t": "0.4 s"'),
             "message 40 has '0.4 s' in t, which is not a number; repair or cut the recording"),
}


@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize("case", list(MCAP_CASES))
def test_bad_value_in_an_intact_mcap_is_one_line(tmp_path, d, case, name):
    replace, message = MCAP_CASES[case]
    log = tmp_path / "run.mcap"
    mcap_with_message(d, log, 40, replace)
    refused(command(name, log, d), [log], f"{log}: {message}")


def test_a_smartwheel_value_too_large_for_a_float_drops_its_frame(off_square):
    from ropod_sysid.io.smartwheel import frames_from_messages

    decoded = [{"sensors": [{"sensor_ts": 1_000_000 * (k + 1), **dict.fromkeys(REQUIRED_FLOATS,
                                                                               24.0)}
                            for _ in range(4)]} for k in range(5)]
    decoded[3]["sensors"][2]["encoder_2"] = 10**400
    frames = frames_from_messages(decoded, off_square, "sw.mcap")
    assert frames.malformed.tolist() == [False, False, False, True, False]


# ---------------------------------------------------------------------------------------------
# platform files


def platform_text(d: Path, **changes: object) -> str:
    data = yaml.safe_load((d / "platform.yaml").read_text())
    for key, value in changes.items():
        if key == "unit0_type":
            data["units"][0]["type"] = value
        else:
            data[key] = value
    return yaml.safe_dump(data, sort_keys=False)


def test_yaml_12_floats_are_numbers(tmp_path, d):
    """``8e-2`` (YAML 1.1 would read a string) is a number like 0.08."""
    text = (d / "platform.yaml").read_text()
    plain = load_platform(d / "platform.yaml")
    for old, new in (("wheel_distance: 0.08", "wheel_distance: 8e-2"),
                     ("wheel_radius: 0.0525", "wheel_radius: 525E-4"),
                     ("caster_offset: 0.01", "caster_offset: 1.0e-2"),
                     ("torque_constant: 0.28", "torque_constant: .28"),
                     ("friction_tanh_gain: 10.0", "friction_tanh_gain: 1e1"),
                     ("- 0.23\n", "- 23e-2\n"), ("- -0.19\n", "- -.19\n")):
        assert old in text, old
        text = text.replace(old, new, 1)
    p = tmp_path / "exp.yaml"
    p.write_text(text)
    assert load_platform(p) == plain
    r = cli(*command("inspect", d / "ok.csv", d, p))
    assert r.exit_code == 0, r.output


PLATFORM_CASES = {
    "zero_radius": ({"wheel_radius": 0},
                    "'wheel_radius' must be > 0, got 0.0; give the wheel radius R_w in metres"),
    "negative_distance": ({"wheel_distance": -0.08},
                          "'wheel_distance' must be > 0, got -0.08; give the distance d_w between "
                          "the two wheels of a unit in metres"),
    "zero_caster": ({"caster_offset": 0.0},
                    "'caster_offset' must be nonzero (the swivel model needs s_w ≠ 0); give the "
                    "distance from the pivot axis to the wheel axle in metres"),
    "no_units": ({"units": []},
                 "'units' lists 0 unit(s); at least two needed — list every wheel unit with its "
                 "name and pivot"),
    "units_not_a_list": ({"units": 0}, "'units' must be a list of {name, pivot} entries, got 0"),
    "unknown_type": ({"unit0_type": "mecanum"},
                     "'units[0].type' is 'mecanum'; known unit types: swivel, omni, steered — use "
                     "one of them (or leave 'type' out for swivel)"),
    "nan": ({"wheel_radius": float("nan")},
            "key 'wheel_radius' must be finite, got nan; give its value in SI units"),
    "infinite": ({"torque_constant": float("inf")},
                 "key 'torque_constant' must be finite, got inf; give its value in SI units"),
}


@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize("case", list(PLATFORM_CASES))
def test_bad_platform_file_is_one_line(tmp_path, d, case, name):
    changes, message = PLATFORM_CASES[case]
    p = tmp_path / "platform.yaml"
    p.write_text(platform_text(d, **changes))
    log = tmp_path / "run.csv"
    log.write_bytes((d / "ok.csv").read_bytes())
    refused(command(name, log, d, p), [p, log], f"{p}: {message}")


@pytest.mark.parametrize("text, message", [
    ("wheel_radius: 0.05\nwheel_radius: 0.06\n",
     "line 2 is not valid YAML (the key 'wheel_radius' appears twice in one mapping; keep one of "
     "them); fix the syntax"),
    ("name: r\xe9\n", "line 1 is not UTF-8 text; save the platform file as UTF-8"),
])
def test_duplicate_keys_and_bad_bytes_in_a_platform_file(tmp_path, d, text, message):
    p = tmp_path / "platform.yaml"
    p.write_bytes(text.encode("latin-1"))
    log = tmp_path / "run.csv"
    log.write_bytes((d / "ok.csv").read_bytes())
    refused(command("fit", log, d, p), [p, log], f"{p}: {message}")


# ---------------------------------------------------------------------------------------------
# fuzzing

REPLACEMENTS = (b"abc", b"", b"nan", b"1e400", b"-" + b"9" * 400, b"\xff", b"1,2", b'"x',
                b"0.5", b"-1e-400", b"7")
VALID_NUMBERS = (b"0.5", b"-1e-400", b"7")

TEXT_DAMAGE = ("flip", "delete", "duplicate", "replace", "truncate", "not_utf8")


def damage_of(kinds: tuple[str, ...]) -> st.SearchStrategy:
    """(kind, position, position, replacement, compressed) for :func:`damage_csv`."""
    return st.tuples(st.sampled_from(kinds), st.floats(0, 1, exclude_max=True),
                     st.floats(0, 1, exclude_max=True), st.sampled_from(REPLACEMENTS),
                     st.booleans())


damage = damage_of(TEXT_DAMAGE + ("gz_truncate", "gz_flip"))


def damage_csv(data: bytes, how: tuple, used: list[int] | None = None,
               ) -> tuple[bytes, bool, bool]:
    """(damaged file, compressed, must be refused) for a contract CSV ``data``; ``used``: the
    fields a reader reads (all of them by default; a replaced field is one of them).

    Structural damage must be noticed: a duplicated line (time stops increasing, or the header
    becomes a row of text), a deleted header, a field replaced by something that is not a
    finite number, an extra field or an unclosed quote, a byte that is not UTF-8, a cut that
    leaves a last line with missing fields, and any cut of the compressed data. A flipped bit
    in a digit, a deleted data line (a gap: the time-base checks' business) or a cut at a line
    end give another valid log and may read.
    """
    kind, u, v, value, compressed = how
    if kind.startswith("gz_"):
        compressed = True
    lines = data.split(b"\n")[:-1]               # the file ends with a line end
    n_fields = lines[0].count(b",") + 1
    every = used is None
    used = list(range(n_fields)) if used is None else used
    i = int(u * len(lines))
    must = False
    if kind == "flip":
        pos = int(u * len(data))
        bit = int(v * 8)
        out = bytearray(data)
        out[pos] ^= 1 << bit
        data = bytes(out)
        must = bit == 7 and every                 # a byte ≥ 0x80 alone is never UTF-8
    elif kind == "delete":
        del lines[i]
        data = b"".join(ln + b"\n" for ln in lines)
        must = i == 0
    elif kind == "duplicate":
        lines.insert(i, lines[i])
        data = b"".join(ln + b"\n" for ln in lines)
        must = True
    elif kind == "replace":
        i = max(i, 1)
        fields = lines[i].split(b",")
        fields[used[int(v * len(used))]] = value
        lines[i] = b",".join(fields)
        data = b"".join(ln + b"\n" for ln in lines)
        must = value not in VALID_NUMBERS
    elif kind == "truncate":
        cut = int(u * len(data))
        data = data[:cut]
        tail = data.rsplit(b"\n", 1)[-1]
        must = len(tail) > 0 and tail.count(b",") + 1 < n_fields
    elif kind == "not_utf8":
        pos = int(u * len(data))
        data = data[:pos] + b"\xff" + data[pos:]
        must = every
    packed = gzip.compress(data, mtime=0) if compressed else data
    if kind == "gz_truncate":
        packed = packed[: int(u * len(packed))]
        must = True
    elif kind == "gz_flip":
        out = bytearray(packed)
        out[int(u * len(packed))] ^= 1 << int(v * 8)
        packed = bytes(out)
    return packed, compressed, must


def outcome(read) -> tuple[str, object]:
    """("ok", value) or ("error", message) of ``read()``, which must take < TIME_LIMIT and
    raise nothing but a one-line InputError."""
    start = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            value = read()
        result: tuple[str, object] = ("ok", (value, [str(w.message) for w in caught]))
    except InputError as exc:
        assert "\n" not in str(exc)
        result = ("error", str(exc))
    assert time.perf_counter() - start < TIME_LIMIT
    return result


def check_log(log, path: Path) -> None:
    """What a reader promises about a log it returns."""
    assert log.source == str(path)
    assert np.all(np.diff(log.t) > 0)
    for a in (log.t, D(log), P(log), C(log)):
        assert np.isfinite(a).all()


@FUZZ
@given(how=damage)
def test_fuzz_csv_reader(tmp_path, d, off_square, how):
    """Property: reading a damaged contract CSV (whole, and in chunks) returns a log that keeps
    the reader's promises (finite values, increasing time) or raises a one-line InputError
    naming the file — nothing else, within 10 s; structural damage (see :func:`damage_csv`)
    is always refused; the whole and the chunked read agree."""
    data, compressed, must = damage_csv((d / "ok.csv").read_bytes(), how)
    path = tmp_path / ("fuzz.csv.gz" if compressed else "fuzz.csv")
    path.write_bytes(data)
    whole = outcome(lambda: read_csv_log(path, off_square))
    chunked = outcome(lambda: list(iter_csv_log(path, off_square, chunk_rows=64)))
    assert whole[0] == chunked[0], (whole, chunked)
    event(f"{how[0]}: {whole[0]}")
    if must:
        assert whole[0] == "error", how
    if whole[0] == "error":
        assert str(whole[1]).startswith(f"{path}: ")
        return
    log, _ = whole[1]
    check_log(log, path)
    parts, _ = chunked[1]
    np.testing.assert_array_equal(np.concatenate([p.t for p in parts]), log.t)
    np.testing.assert_array_equal(np.concatenate([C(p) for p in parts]), C(log))


@FUZZ
@given(how=damage_of(TEXT_DAMAGE))
def test_fuzz_smartwheel_csv_reader(tmp_path, d, off_square, how):
    """Property: a damaged smart-wheel CSV reads (frames dropped with a warning naming them, or
    nothing noticed for damage that leaves valid frames) or raises a one-line InputError
    naming the file — nothing else, within 10 s. Structural damage in the fields the layout
    uses (a duplicated line: its clock stops increasing; a deleted header, a used field that
    is not a finite number, a cut last line) is refused or noted."""
    data = (d / "sw.csv").read_bytes()
    names = data.split(b"\n", 1)[0].decode().split(",")
    used = [k for k, name in enumerate(names)
            if name.split(".")[-1] in ("sensor_ts", *REQUIRED_FLOATS)
            and int(name.split(".")[1]) < off_square.n_units]
    damaged, _, must = damage_csv(data, (*how[:4], False), used)
    path = tmp_path / "sw.csv"
    path.write_bytes(damaged)
    result = outcome(lambda: read_log(path, off_square))
    event(f"{how[0]}: {result[0]}")
    if result[0] == "error":
        assert str(result[1]).startswith(f"{path}: ")
        return
    log, caught = result[1]
    check_log(log, path)
    if must:
        assert caught and log.notes, how


@FUZZ
@given(how=st.tuples(st.sampled_from(("flip", "truncate", "flip_sw", "truncate_sw")),
                     st.floats(0, 1, exclude_max=True), st.integers(0, 7)))
def test_fuzz_mcap_reader(tmp_path, d, off_square, how):
    """Property: a damaged MCAP file (a flipped bit anywhere, a cut anywhere; contract and
    smart-wheel layouts) reads with a warning that names the damage, or raises a one-line
    InputError — never silently, never a traceback, within 10 s; the whole and the chunked
    read agree (the CRCs and the structure of MCAP catch every such damage)."""
    kind, u, bit = how
    data = (d / ("sw.mcap" if kind.endswith("_sw") else "ok.mcap")).read_bytes()
    if kind.startswith("flip"):
        out = bytearray(data)
        out[int(u * len(data))] ^= 1 << bit
        data = bytes(out)
    else:
        data = data[: int(u * len(data))]
    path = tmp_path / "fuzz.mcap"
    path.write_bytes(data)
    whole = outcome(lambda: read_mcap_log(path, off_square))
    chunked = outcome(lambda: list(iter_mcap_log(path, off_square, chunk=64)))
    assert whole[0] == chunked[0], (whole, chunked)
    event(f"{kind}: {whole[0]}")
    if whole[0] == "error":
        assert str(whole[1]).startswith(f"{path}: ")
        return
    log, caught = whole[1]
    check_log(log, path)
    assert caught or log.notes, f"damage {how} went unnoticed"


@FUZZ
@given(how=damage)
def test_fuzz_fit(tmp_path, d, how):
    """Property: ``fit`` on a damaged short log exits 0 (writing the parameter file) or 2 with
    exactly one ``error:`` line (any other line a ``warning:``) and no output file; never a
    traceback, never longer than 10 s; structural damage (see :func:`damage_csv`) exits 2.
    The input is left as it was."""
    data, compressed, must = damage_csv((d / "ok.csv").read_bytes(), how)
    log = tmp_path / ("fuzz.csv.gz" if compressed else "fuzz.csv")
    log.write_bytes(data)
    out = tmp_path / "out.json"
    out.unlink(missing_ok=True)
    start = time.perf_counter()
    r = cli(*command("fit", log, d))
    assert time.perf_counter() - start < TIME_LIMIT
    assert "Traceback" not in r.output and "Exception ignored" not in r.output, r.output
    assert r.exit_code in (0, 2), (r.exit_code, r.output, how)
    event(f"{how[0]}: exit {r.exit_code}")
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    if r.exit_code == 2:
        errors = [ln for ln in lines if ln.startswith("error: ")]
        assert len(errors) == 1, r.output
        assert all(ln.startswith(("error: ", "warning: ")) for ln in lines), r.output
        assert not out.exists()
    else:
        assert not must, (how, r.output)
        assert out.exists()
    assert log.read_bytes() == data
