"""The smart-wheel layout: per-unit motor mapping, signs, pivot offsets, wrapped encoders,
integer clocks and corrupt frames; the same fit as the clean contract log.

The run is the conftest's session-scoped simulation (8 s on the off-square ropod, 200 Hz).
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings

import numpy as np
import pytest

from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.io import read_log
from ropod_sysid.io.mcaplog import scan_mcap
from ropod_sysid.io.smartwheel import (
    REQUIRED_FLOATS,
    SW_TOPIC,
    SmartWheelFrames,
    frames_to_log,
    raw_frames,
    read_smartwheel_csv,
    write_smartwheel,
)
from ropod_sysid.platform import Platform, platform_from_dict
from tests.swivel_arrays import C, D, P, make_log

# fit of the smart-wheel files vs the clean log: relative difference per parameter. The inputs
# differ only by rounding (unwrapping adds 2πk, t passes through integer nanoseconds); measured
# 3e-12 (unwrapped encoders) to 3e-11 (wrapped) relative; the bound leaves room for other BLAS.
FIT_RTOL = 1e-9


def sw_platform(base: Platform) -> Platform:
    """The off-square ropod with the settings the public drivers disagree on."""
    d = base.to_dict()
    d["units"][0]["pivot_offset"] = -2.0
    d["units"][1]["left_motor"] = 2                    # motors swapped
    d["units"][2]["sign_left"] = -1                    # a flipped sign
    d["units"][3].update(sign_right=-1, left_motor=2, pivot_offset=1.3)
    return platform_from_dict(d, "sw")


@pytest.fixture(scope="module")
def clean(runs_off_square, off_square):
    log = runs_off_square[0].log
    return log, fit_logs([log], off_square, FitOptions())


def assert_same_fit(a, b, rtol=FIT_RTOL):
    assert a.names == b.names
    rel = np.abs(a.solution.values - b.solution.values) / np.abs(a.solution.values)
    assert rel.max() <= rtol, dict(zip(a.names, rel, strict=True))


def equal_up_to_turns(x, y, atol=1e-9):
    """Equal up to a whole number of turns, the same one along the series."""
    k = np.round((x[0] - y[0]) / (2 * np.pi))
    return np.allclose(x - 2 * np.pi * k, y, rtol=0, atol=atol)


@pytest.mark.parametrize("container,encoding,wrap", [
    ("mcap", "json", "2pi"), ("mcap", "ros2", "pi"), ("csv", "json", "2pi"),
    ("mcap", "json", None),
])
def test_swapped_flipped_wrapped_and_corrupt_gives_the_clean_fit(tmp_path, clean, off_square,
                                                                 container, encoding, wrap):
    log, ref = clean
    pf = sw_platform(off_square)
    path = tmp_path / f"sw.{container}"
    n_frames = write_smartwheel(log, path, pf, encoding=encoding, wrap=wrap, corrupt=3, seed=4)
    assert n_frames == log.n_samples + 9
    with pytest.warns(UserWarning, match=r"dropped 9 of 1610 smart-wheel frames — 3 zeroed: "
                                         r"frames #\d+ \(t≈\d+\.\d+ s\)"):
        back = read_log(path, pf)
    assert back.n_samples == log.n_samples
    note = back.notes[-1]
    for label in ("3 zeroed", "3 with voltage_bus outside [10, 60] V",
                  "3 with non-monotonic sensor_ts"):
        assert label in note
    # the channels themselves: the clean log up to whole turns and rounding
    assert np.allclose(back.t, log.t - log.t[0], rtol=0, atol=1e-12)
    assert np.array_equal(C(back), C(log))
    for i in range(4):
        assert equal_up_to_turns(D(back)[:, i], D(log)[:, i])
        assert -np.pi <= D(back)[0, i] < np.pi
        for w in range(2):
            assert equal_up_to_turns(P(back)[:, i, w], P(log)[:, i, w])
    assert_same_fit(ref, fit_logs([back], pf, FitOptions()))


def test_the_settings_matter(tmp_path, clean, off_square):
    """Read with the default settings, the same file gives a different fit."""
    log, ref = clean
    path = tmp_path / "sw.mcap"
    write_smartwheel(log, path, sw_platform(off_square))
    with warnings.catch_warnings():
        warnings.simplefilter("error")        # a clean file: nothing dropped, no warning
        wrong = read_log(path, off_square)
    assert not np.array_equal(C(wrong), C(log))
    res = fit_logs([wrong], off_square, FitOptions())
    rel = np.abs(res.solution.values - ref.solution.values) / np.abs(ref.solution.values)
    assert rel.max() > 0.1


def test_message_layouts(tmp_path, clean, off_square):
    log, _ = clean
    pf = sw_platform(off_square)
    for enc, schema_enc, msg_enc in (("json", "jsonschema", "json"), ("ros2", "ros2msg", "cdr")):
        path = tmp_path / f"{enc}.mcap"
        write_smartwheel(log.slice(0, 50), path, pf, encoding=enc)
        scan = scan_mcap(path)
        (ch,) = scan.channels.values()
        assert ch.topic == SW_TOPIC and ch.message_encoding == msg_enc
        assert scan.schemas[ch.schema_id].encoding == schema_enc
        assert "SmartWheel" in scan.schemas[ch.schema_id].name
        assert len(scan.messages[ch.id]) == 50
    path = tmp_path / "sw.csv"
    write_smartwheel(log.slice(0, 50), path, pf)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:5] == ["sensors.0.status1", "sensors.0.status2", "sensors.0.sensor_ts",
                          "sensors.0.setpoint_ts", "sensors.0.encoder_1"]
    assert "sensors.3.voltage_bus" in header


def frames(ts, **values) -> SmartWheelFrames:
    """Hand-made frames of two units; values default to plausible constants."""
    ts = np.asarray(ts, dtype=np.uint64)
    n = ts.shape[0]
    if ts.ndim == 1:
        ts = np.stack([ts, ts], axis=1)
    vals = {f: np.full((n, 2), 0.5) for f in REQUIRED_FLOATS}
    vals["voltage_bus"][:] = 24.0
    for k, v in values.items():
        vals[k] = np.asarray(v, dtype=float).reshape(n, -1) * np.ones((1, 2))
    return SmartWheelFrames(ts, vals, np.zeros(n, dtype=bool), "hand")


def two_units(**unit2) -> Platform:
    units = [{"name": "a", "pivot": [0.2, 0.0]}, {"name": "b", "pivot": [-0.2, 0.0], **unit2}]
    return platform_from_dict({"wheel_radius": 0.05, "wheel_distance": 0.08,
                               "caster_offset": 0.01, "torque_constant": 0.3, "units": units})


def test_mapping_of_motors_signs_and_pivot_offset():
    n = 5
    t = np.arange(n, dtype=np.uint64) * np.uint64(1_000_000) + np.uint64(123)
    e1, e2 = np.arange(n) * 0.1, -np.arange(n) * 0.2
    c1, c2 = np.full(n, 1.5), np.full(n, -2.5)
    fr = frames(t, encoder_1=e1, encoder_2=e2, current_1_q=c1, current_2_q=c2,
                encoder_pivot=np.full(n, 0.3))
    log = frames_to_log(fr, two_units(left_motor=2, sign_left=-1, pivot_offset=0.5))
    assert np.array_equal(log.t, np.arange(n) * 1e-3)
    # unit a: default settings
    assert np.array_equal(P(log)[:, 0, 0], e1) and np.array_equal(P(log)[:, 0, 1], e2)
    assert np.array_equal(C(log)[:, 0], np.stack([c1, c2], axis=1))
    assert np.allclose(D(log)[:, 0], 0.3)
    # unit b: left is motor 2 with a flipped sign, right is motor 1
    assert np.array_equal(P(log)[:, 1, 0], -e2) and np.array_equal(P(log)[:, 1, 1], e1)
    assert np.array_equal(C(log)[:, 1, 0], -c2) and np.array_equal(C(log)[:, 1, 1], c1)
    assert np.allclose(D(log)[:, 1], 0.3 - 0.5)
    assert log.notes == []


@pytest.mark.parametrize("wrap", ["2pi", "pi"])
def test_wrapped_encoders_are_unwrapped(wrap):
    n = 400
    angle = np.linspace(-7.0, 30.0, n)               # five turns, 0.09 rad per sample
    raw = np.mod(angle, 2 * np.pi) if wrap == "2pi" else np.mod(angle + np.pi, 2 * np.pi) - np.pi
    fr = frames(np.arange(1, n + 1) * 1000, encoder_1=raw, encoder_pivot=raw)
    log = frames_to_log(fr, two_units())
    assert equal_up_to_turns(P(log)[:, 0, 0], angle, atol=1e-12)
    assert equal_up_to_turns(D(log)[:, 0], angle, atol=1e-12)
    assert D(log)[0, 0] == pytest.approx(-7.0 + 2 * np.pi)   # first pivot sample in [−π, π)


def test_sensor_ts_stays_integer_until_seconds():
    """A clock near the top of uint64: float64 of the raw value is 2 µs coarse there, yet the
    times come out exact to the nanosecond."""
    t0 = 18_000_000_000_000_000_123                  # > int64 max, < uint64 max
    steps = np.array([0, 1, 1_000_001, 2_000_003, 3_000_000])
    ts = np.array([t0 + int(s) for s in steps], dtype=np.uint64)
    log = frames_to_log(frames(ts), two_units())
    assert np.array_equal(log.t, steps / 1e9)
    naive = np.array([float(int(x)) for x in ts]) - float(t0)
    assert np.abs(naive / 1e9 - steps / 1e9).max() > 1e-7     # what floats would have done


@pytest.mark.parametrize("encoding", ["json", "ros2", "csv"])
def test_huge_clock_through_the_files(tmp_path, clean, off_square, encoding):
    log, _ = clean
    short = log.slice(0, 100)
    path = tmp_path / ("sw.csv" if encoding == "csv" else "sw.mcap")
    write_smartwheel(short, path, off_square, encoding="json" if encoding == "csv" else encoding,
                     t0_ns=18_446_744_000_000_000_000)
    back = read_log(path, off_square)
    expected = np.round((short.t - short.t[0]) * 1e9) / 1e9
    assert np.array_equal(back.t, expected)


def test_corrupt_frames_are_dropped_and_reported():
    ms = 1_000_000
    ts = np.array([1, 2, 3, 0, 4, 5, 3, 6, 7 + (1 << 40), 8, 9, 10, 11, 12], dtype=np.uint64) * ms
    ts[3] = 0
    volt = np.full(14, 24.0)
    volt[10] = 75.0
    pivot = np.full(14, 0.25)
    pivot[11] = np.nan
    fr = frames(ts, voltage_bus=volt, encoder_pivot=pivot)
    for f in REQUIRED_FLOATS:
        fr.values[f][3] = 0.0
    with pytest.warns(UserWarning) as caught:
        log = frames_to_log(fr, two_units())
    kept_ms = [1, 2, 3, 4, 5, 6, 8, 11, 12]
    assert np.array_equal(log.t, (np.array(kept_ms) - 1) * 1e-3)
    (note,) = log.notes
    assert str(caught[0].message) == note
    assert note.startswith("hand: dropped 5 of 14 smart-wheel frames — ")
    assert "1 zeroed: frames #3 (t≈" in note
    assert "1 with NaN or infinite values: frames #11" in note
    assert "1 with voltage_bus outside [10, 60] V: frames #10" in note
    assert "2 with non-monotonic sensor_ts: frames #6 (t≈0.005 s), #8 (t≈0.006 s)" in note


def test_a_spike_in_one_units_clock_drops_the_frame():
    ts = np.stack([np.arange(1, 9), np.arange(1, 9)], axis=1).astype(np.uint64) * np.uint64(1000)
    ts[4, 1] += np.uint64(1 << 50)
    log = frames_to_log(frames(ts), two_units(), warn=False)
    assert log.n_samples == 7 and "frames #4" in log.notes[0]


def test_too_few_good_frames_is_a_one_line_error():
    fr = frames([1000, 2000, 3000, 4000], voltage_bus=[24.0, 5.0, 5.0, 24.0])
    with pytest.raises(InputError, match=r"only 2 of 4 smart-wheel frames are usable"):
        frames_to_log(fr, two_units())


def test_csv_errors_are_one_line(tmp_path, clean, off_square):
    log, _ = clean
    path = tmp_path / "sw.csv"
    write_smartwheel(log.slice(0, 30), path, off_square)
    lines = path.read_text().splitlines()
    header = lines[0].split(",")

    def rewrite(name, rows):
        p = tmp_path / name
        p.write_text("\n".join(rows) + "\n")
        return p

    j = header.index("sensors.2.encoder_pivot")
    drop = [",".join(c for k, c in enumerate(r.split(",")) if k != j) for r in lines]
    with pytest.raises(InputError, match=r"column 'sensors.2.encoder_pivot' is missing"):
        read_log(rewrite("missing.csv", drop), off_square)
    bad = list(lines)
    cells = bad[7].split(",")
    cells[header.index("sensors.1.current_2_q")] = "abc"
    bad[7] = ",".join(cells)
    with pytest.raises(InputError) as err:
        read_smartwheel_csv(rewrite("bad.csv", bad), off_square)
    assert "\n" not in str(err.value) and "sensors.1.current_2_q" in str(err.value)
    empty = list(lines)
    cells = empty[5].split(",")
    cells[header.index("sensors.3.sensor_ts")] = ""
    empty[5] = ",".join(cells)
    with pytest.raises(InputError, match=r"line 6, column 'sensors.3.sensor_ts' is empty"):
        read_log(rewrite("empty.csv", empty), off_square)
    big = off_square.to_dict()
    big["units"].append({"name": "5", "pivot": [0.0, 0.3]})
    with pytest.raises(InputError, match=r"cover 4 sensors .* has 5 units"):
        read_log(path, platform_from_dict(big))


def test_mcap_errors_and_damage(tmp_path, clean, off_square):
    log, _ = clean
    path = tmp_path / "sw.mcap"
    write_smartwheel(log, path, off_square, encoding="ros2", corrupt={"zeroed": 2})
    big = off_square.to_dict()
    big["units"].append({"name": "5", "pivot": [0.0, 0.3]})
    with pytest.raises(InputError, match=r"has 4 sensors but the platform 'ropod' has 5 units"):
        read_log(path, platform_from_dict(big))
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(UserWarning) as caught:
        back = read_log(cut, off_square)
    texts = [str(w.message) for w in caught]
    m = re.search(r"truncated\); recovered the (\d+) messages before the damage", texts[0])
    assert m, texts
    dropped = sum(int(x) for x in re.findall(r"dropped (\d+) of", " ".join(texts)))
    assert back.n_samples == int(m.group(1)) - dropped
    assert 300 < back.n_samples < log.n_samples


def test_fewer_smartwheel_frames_than_messages_when_fields_are_missing(tmp_path, clean,
                                                                      off_square):
    """A message that lacks a field is dropped as malformed (the first one must be whole)."""
    import json

    from ropod_sysid.io.mcapwrite import new_writer
    from ropod_sysid.io.smartwheel import SW_FIELDS

    log, _ = clean
    f, recv = raw_frames(log.slice(0, 40), off_square)
    path = tmp_path / "m.mcap"
    with open(path, "wb") as out:
        w = new_writer(out)
        sid = w.register_schema("robot/SmartWheelData", "jsonschema", b"{}")
        cid = w.register_channel("/other/topic", "json", sid)
        for k in range(40):
            sensors = [{n: f[n][k, i].item() for n in SW_FIELDS} for i in range(4)]
            if k == 17:
                del sensors[2]["encoder_2"]
            w.add_message(cid, int(recv[k]), json.dumps({"sensors": sensors}).encode(),
                          int(recv[k]))
        w.finish()
    with pytest.warns(UserWarning, match=r"dropped 1 of 40 .* 1 malformed"):
        back = read_log(path, off_square)
    assert back.n_samples == 39
    assert math.isclose(back.t[17], log.t[18] - log.t[0], abs_tol=1e-12)


def test_extra_sensors_are_ignored_with_a_note(tmp_path, clean, off_square):
    log, _ = clean
    three = off_square.to_dict()
    three["units"] = three["units"][:3]
    pf3 = platform_from_dict(three)
    path = tmp_path / "sw.csv"
    write_smartwheel(log.slice(0, 30), path, off_square)
    with pytest.warns(UserWarning, match="has 4 sensors; the first 3 are read as units 1, 2, 3"):
        back = read_log(path, pf3)
    short = dataclasses.replace(log.slice(0, 30))
    assert np.array_equal(C(back), C(short)[:, :3])


@pytest.mark.parametrize("encoding", ["json", "ros2"])
def test_smartwheel_mcap_streams_in_chunks(tmp_path, clean, off_square, encoding):
    """Chunk by chunk (the checks carried across chunks) the samples are the whole read's bit
    for bit, the note comes once with the last chunk, and the streamed fit is the whole one."""
    from ropod_sysid.fit import fit_files
    from ropod_sysid.io.mcaplog import iter_mcap_log, read_mcap_log

    log, _ = clean
    pf = sw_platform(off_square)
    path = tmp_path / "sw.mcap"
    write_smartwheel(log, path, pf, encoding=encoding, wrap="pi", corrupt=4, seed=9)
    with pytest.warns(UserWarning):
        whole = read_mcap_log(path, pf)
    for chunk in (1, 2, 97, 1000):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            parts = list(iter_mcap_log(path, pf, chunk))
        assert [str(w.message) for w in caught] == whole.notes
        assert [p.n_samples for p in parts[:-1]] == [chunk] * (len(parts) - 1)
        assert 1 <= parts[-1].n_samples <= chunk
        assert all(p.notes == [] for p in parts[:-1]) and parts[-1].notes == whole.notes
        for name in ("t", "angles", "currents"):
            joined = np.concatenate([getattr(p, name) for p in parts])
            assert np.array_equal(joined, getattr(whole, name)), (chunk, name)
    with pytest.warns(UserWarning, match="dropped 12 of 1613"):
        streamed = fit_files([path], pf, FitOptions(), chunk=500)
    assert_same_fit(fit_logs([whole], pf, FitOptions()), streamed, rtol=1e-12)


@pytest.mark.parametrize("encoding", ["json", "ros2"])
def test_a_gap_after_dropped_frames_names_the_same_frame_whole_and_in_chunks(
        tmp_path, runs_off_square, off_square, encoding):
    """The time checks (ropod_sysid.io.timebase) of a smart-wheel MCAP name the frame of the
    file, past the dropped ones, whether the log is read whole or chunk by chunk; with
    gaps="allow" the log reads, and its chunks are the whole read's."""
    from ropod_sysid.io.mcaplog import iter_mcap_log, read_mcap_log

    a, b = runs_off_square[0].log, runs_off_square[1].log
    gapped = make_log(np.concatenate([a.t, b.t - b.t[0] + a.t[-1] + 10.0]), list(a.units),
                      np.concatenate([D(a), D(b)]), np.concatenate([P(a), P(b)]),
                      np.concatenate([C(a), C(b)]))
    path = tmp_path / "gapped.mcap"
    write_smartwheel(gapped, path, off_square, encoding=encoding, corrupt=4, seed=5)
    f, _ = raw_frames(gapped, off_square, corrupt=4, seed=5)
    ts0 = f["sensor_ts"][:, 0].astype(np.int64)
    after = int(np.flatnonzero(ts0 - ts0[0] > int(round((a.t[-1] - a.t[0] + 5.0) * 1e9)))[0])
    assert after > a.n_samples                  # dropped frames lie before the gap
    pattern = rf"{re.escape(str(path))}: frame #{after}: a gap of 10 s .* on frame #\d+; "
    with pytest.raises(InputError, match=pattern) as whole:
        read_mcap_log(path, off_square)
    for chunk in (1, 97, a.n_samples, 1000):
        with pytest.raises(InputError) as chunked:
            list(iter_mcap_log(path, off_square, chunk))
        assert str(chunked.value) == str(whole.value)
    with pytest.warns(UserWarning, match="dropped 12 of"):
        allowed = read_mcap_log(path, off_square, gaps="allow")
    assert allowed.n_samples == gapped.n_samples
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parts = list(iter_mcap_log(path, off_square, 97, gaps="allow"))
    assert np.array_equal(np.concatenate([p.t for p in parts]), allowed.t)
