"""MCAP logs: bit-exact round trips, fits equal to the CSV's, damaged files read up to the damage.

The run is the conftest's session-scoped simulation (8 s on the off-square ropod, 200 Hz).
"""

from __future__ import annotations

import dataclasses
import json
import re
import warnings

import numpy as np
import pytest
from mcap.writer import CompressionType, IndexType
from mcap.writer import Writer as McapWriter

from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.io import read_log, write_log
from ropod_sysid.io.csvlog import read_csv_log, write_csv_log
from ropod_sysid.io.mcaplog import read_mcap_log, scan_mcap
from ropod_sysid.io.mcapwrite import (
    CHUNK_SIZE,
    CONTRACT_TOPIC,
    contract_json_schema,
    write_mcap_log,
)
from ropod_sysid.platform import platform_from_dict
from tests.swivel_arrays import C, D, P, with_arrays

ENCODINGS = ("json", "ros2")


@pytest.fixture(scope="module")
def files(tmp_path_factory, runs_off_square):
    d = tmp_path_factory.mktemp("mcap")
    write_csv_log(runs_off_square[0].log, d / "run.csv")
    return d


@pytest.fixture(scope="module")
def mcap_files(files, off_square):
    log = read_csv_log(files / "run.csv", off_square)
    out = {}
    for enc in ENCODINGS:
        out[enc] = files / f"run_{enc}.mcap"
        write_mcap_log(log, out[enc], enc)
    return out


def read_quiet(path, platform):
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # an intact file reads without any warning
        return read_mcap_log(path, platform)


def assert_same_log(a, b):
    for name in ("t", "angles", "currents"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and x.dtype == y.dtype == np.float64
        assert np.array_equal(x.view(np.int64), y.view(np.int64)), name   # bit for bit
    assert (a.pose is None) == (b.pose is None)
    if a.pose is not None:
        assert np.array_equal(a.pose.view(np.int64), b.pose.view(np.int64))
    assert a.units == b.units


# ---------------------------------------------------------------------------------------------
# round trips and fits


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_csv_mcap_csv_is_bit_exact(files, mcap_files, off_square, encoding):
    original = (files / "run.csv").read_bytes()
    log = read_quiet(mcap_files[encoding], off_square)
    assert_same_log(log, read_csv_log(files / "run.csv", off_square))
    back = files / f"back_{encoding}.csv"
    write_csv_log(log, back)
    assert back.read_bytes() == original


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_pose_and_awkward_floats_round_trip(tmp_path, off_square, runs_off_square, encoding):
    """Subnormals, signed zeros, huge and tiny values and an external pose survive exactly."""
    log = runs_off_square[1].log.slice(0, 50)
    rng = np.random.default_rng(3)
    delta = D(log).copy()
    delta[:5, 0] = [5e-324, -0.0, 1e300, -1.2345678901234567e-200, np.nextafter(1.0, 2.0)]
    pose = rng.normal(size=(50, 3)) * np.array([1e-3, 1e5, 3.0])
    log = with_arrays(log, delta=delta, pose=pose)
    path = tmp_path / "pose.mcap"
    write_mcap_log(log, path, encoding)
    back = read_quiet(path, off_square)
    assert_same_log(back, log)
    assert np.signbit(D(back)[1, 0])


def test_fit_on_mcap_equals_fit_on_csv(files, mcap_files, off_square):
    """The same numbers in, the same fit out: relative differences below 1e-12 (measured 0)."""
    ref = fit_logs([read_csv_log(files / "run.csv", off_square)], off_square, FitOptions())
    assert ref.solution.rank == len(ref.names)
    for enc in ENCODINGS:
        res = fit_logs([read_log(mcap_files[enc], off_square)], off_square, FitOptions())
        a, b = ref.solution.values, res.solution.values
        rel = np.max(np.abs(a - b) / np.abs(a))
        assert rel <= 1e-12, (enc, rel)
        assert res.rms == pytest.approx(ref.rms, rel=1e-12)


def test_write_log_and_read_log_dispatch_on_suffix(tmp_path, off_square, runs_off_square):
    log = runs_off_square[2].log.slice(0, 200)
    write_log(log, tmp_path / "a.mcap", off_square)
    assert_same_log(read_log(tmp_path / "a.mcap", off_square), log)


def test_files_carry_schemas_for_viewers(mcap_files, off_square):
    for enc, path in mcap_files.items():
        scan = scan_mcap(path)
        assert scan.damage is None and scan.complete
        (channel,) = scan.channels.values()
        schema = scan.schemas[channel.schema_id]
        assert channel.topic == CONTRACT_TOPIC
        if enc == "json":
            assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
            js = json.loads(schema.data)
            assert js == contract_json_schema(off_square.layout, pose=False)
            msg = json.loads(scan.messages[channel.id][0].data)
            assert set(msg) == {"t", "units"} and set(msg["units"]["1"]) == {
                "delta", "phi_L", "phi_R", "cur_L", "cur_R"}
        else:
            assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
            assert b"float64 t" in schema.data
        # small chunks: damage costs little
        assert scan.n_messages == 1601


def test_file_without_chunks_index_or_summary_reads(tmp_path, off_square, runs_off_square):
    """What a minimal writer (or a recording that never closed its summary) leaves."""
    log = runs_off_square[0].log.slice(0, 300)
    ref = tmp_path / "ref.mcap"
    write_mcap_log(log, ref, "json")
    scan = scan_mcap(ref)
    (channel,) = scan.channels.values()
    schema = scan.schemas[channel.schema_id]
    path = tmp_path / "bare.mcap"
    with open(path, "wb") as f:
        w = McapWriter(f, use_chunking=False, compression=CompressionType.NONE,
                       index_types=IndexType.NONE, repeat_channels=False, repeat_schemas=False,
                       use_statistics=False, use_summary_offsets=False, enable_crcs=False)
        w.start()
        sid = w.register_schema(schema.name, schema.encoding, schema.data)
        cid = w.register_channel(channel.topic, channel.message_encoding, sid)
        for m in scan.messages[channel.id]:
            w.add_message(cid, m.log_time, m.data, m.publish_time)
        w.finish()
    assert_same_log(read_quiet(path, off_square), log)
    # and cut right after the last message: no data end, no footer
    data = path.read_bytes()
    last = data.rfind(scan.messages[channel.id][-1].data) + len(scan.messages[channel.id][-1].data)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:last])
    with pytest.warns(UserWarning, match=r"truncated\); recovered the 300 messages"):
        back = read_mcap_log(cut, off_square)
    assert_same_log(back, log)
    # cut in the middle of a message: the messages before it
    cut.write_bytes(data[:last - 10])
    with pytest.warns(UserWarning, match=r"recovered the 299 messages before the damage"):
        assert read_mcap_log(cut, off_square).n_samples == 299


# ---------------------------------------------------------------------------------------------
# damage


def read_damaged(path, platform):
    """('ok', n, warning texts) or ('error', message); any other exception fails the test."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            log = read_mcap_log(path, platform)
        except InputError as exc:
            text = str(exc)
            assert "\n" not in text and text.startswith(str(path))
            return ("error", text)
    texts = [str(w.message) for w in caught]
    for text in texts:
        assert "\n" not in text
    assert texts == log.notes
    return ("ok", log.n_samples, texts)


def recovered(text: str) -> int:
    m = re.search(r"recovered the (\d+) messages before the damage|all (\d+) messages were "
                  r"recovered", text)
    assert m, text
    return int(m.group(1) or m.group(2))


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_truncated_files_read_up_to_the_cut(tmp_path, mcap_files, off_square, encoding):
    data = mcap_files[encoding].read_bytes()
    path = tmp_path / "cut.mcap"
    counts = []
    cuts = [0, 5, 8, 40, 200] + [int(f * len(data)) for f in np.linspace(0.05, 0.95, 19)] \
        + [len(data) - 100, len(data) - 9, len(data) - 1]
    for cut in cuts:
        path.write_bytes(data[:cut])
        out = read_damaged(path, off_square)
        if out[0] == "error":
            assert cut <= CHUNK_SIZE + 1024, (cut, out)        # inside the first chunk
            assert re.search(r"empty|not an MCAP file|not a readable MCAP file|no messages could "
                             r"be recovered|only \d+ messages? could be recovered", out[1]), out
            counts.append(0)
            continue
        _, n, texts = out
        assert len(texts) == 1 and "damaged MCAP file" in texts[0] and "truncated" in texts[0]
        assert recovered(texts[0]) == n
        counts.append(n)
    assert counts == sorted(counts)                    # a longer file never gives less
    assert counts[-1] == 1601                          # cut in the footer: everything is there
    assert max(counts[-4:-1]) >= 1601 - 200             # small chunks: little is lost
    assert sum(c > 0 for c in counts) >= 20


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_bit_flips_give_a_warning_or_a_one_line_error(tmp_path, mcap_files, off_square,
                                                      encoding):
    """Chunk and data-section CRCs catch every flipped bit: never a silent misread, never a
    traceback. A flip in the data reads the messages before its chunk; in an index or the
    summary, all of them."""
    data = mcap_files[encoding].read_bytes()
    path = tmp_path / "flip.mcap"
    rng = np.random.default_rng(11)
    kinds = {"error": 0, "partial": 0, "all": 0}
    for _ in range(40):
        pos = int(rng.integers(0, len(data)))
        b = bytearray(data)
        b[pos] ^= 1 << int(rng.integers(0, 8))
        path.write_bytes(bytes(b))
        out = read_damaged(path, off_square)
        if out[0] == "error":
            kinds["error"] += 1
            continue
        _, n, texts = out
        assert texts, f"flip at byte {pos} went unnoticed"
        assert recovered(texts[0]) == n
        kinds["all" if n == 1601 else "partial"] += 1
    assert kinds["partial"] > 12


def test_bad_crc_in_a_chunk_and_a_broken_compressed_chunk(tmp_path, mcap_files, off_square):
    data = mcap_files["json"].read_bytes()
    scan = scan_mcap(mcap_files["json"])
    assert scan.damage is None
    path = tmp_path / "bad.mcap"
    # the middle of the file is inside compressed chunk data
    mid = len(data) // 2
    for pos, flip in ((mid, 0x01), (mid + 1, 0xFF)):
        b = bytearray(data)
        b[pos] ^= flip
        path.write_bytes(bytes(b))
        out = read_damaged(path, off_square)
        assert out[0] == "ok"
        assert re.search(r"CRC mismatch of the compressed chunk|broken compressed chunk",
                         out[2][0]), out
        assert 200 < out[1] < 1601


def test_damaged_summary_keeps_every_message(tmp_path, mcap_files, off_square):
    data = mcap_files["json"].read_bytes()
    path = tmp_path / "summary.mcap"
    b = bytearray(data)
    b[-60] ^= 0x10          # inside the summary section / footer
    path.write_bytes(bytes(b))
    out = read_damaged(path, off_square)
    assert out[0] == "ok" and out[1] == 1601
    assert "all 1601 messages were recovered" in out[2][0]


def test_not_mcap_files_are_refused_in_one_line(tmp_path, files, off_square):
    cases = {
        "empty.mcap": b"",
        "csv.mcap": (files / "run.csv").read_bytes()[:2000],
        "short.mcap": b"\x89MCAP0\r",
    }
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
        with pytest.raises(InputError) as err:
            read_mcap_log(tmp_path / name, off_square)
        assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="no such log file"):
        read_mcap_log(tmp_path / "missing.mcap", off_square)
    with pytest.raises(InputError, match="is a directory"):
        read_mcap_log(tmp_path, off_square)


def test_wrong_platform_unknown_topic_and_nan_are_one_line_errors(tmp_path, mcap_files,
                                                                  off_square, runs_off_square):
    other = off_square.to_dict()
    other["units"][3]["name"] = "rear_right"
    with pytest.raises(InputError, match="expects units 1, 2, 3, rear_right"):
        read_mcap_log(mcap_files["ros2"], platform_from_dict(other))
    with pytest.raises(InputError, match="expects units"):
        read_mcap_log(mcap_files["json"], platform_from_dict(other))

    log = runs_off_square[0].log.slice(0, 20)
    path = tmp_path / "other_topic.mcap"
    write_mcap_log(log, path, topic="/something/else")
    assert read_quiet(path, off_square).n_samples == 20        # found by its schema name
    with open(path, "wb") as f:
        w = McapWriter(f)
        w.start()
        sid = w.register_schema("foo/Bar", "jsonschema", b"{}")
        cid = w.register_channel("/foo", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    with pytest.raises(InputError, match=r"no ropod-sysid log .* \(channels: /foo \(foo/Bar, "
                                         r"json\)\)"):
        read_mcap_log(path, off_square)

    bad = with_arrays(log, current=C(log).copy())
    C(bad)[7, 2, 1] = np.nan
    write_mcap_log(bad, path, "json")
    with pytest.raises(InputError, match="message 7 has a NaN"):
        read_mcap_log(path, off_square)
    unsorted = dataclasses.replace(log, t=log.t[[0, 2, 1] + list(range(3, 20))])
    write_mcap_log(unsorted, path, "ros2")
    with pytest.raises(InputError, match="message 2: time .* is not after"):
        read_mcap_log(path, off_square)


# ---------------------------------------------------------------------------------------------
# chunked reading


def read_chunked(path, platform, chunk):
    """iter_mcap_log's chunks joined: ('ok', log, warning texts, chunk lengths) or
    ('error', message)."""
    from ropod_sysid.io.log import Log
    from ropod_sysid.io.mcaplog import iter_mcap_log

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            parts = list(iter_mcap_log(path, platform, chunk))
        except InputError as exc:
            assert "\n" not in str(exc)
            return ("error", str(exc))
    cat = {name: np.concatenate([getattr(p, name) for p in parts])
           for name in ("t", "angles", "currents")}
    pose = None if parts[0].pose is None else np.concatenate([p.pose for p in parts])
    notes = [n for p in parts for n in p.notes]
    log = Log(cat["t"], parts[0].layout, cat["angles"], cat["currents"], pose, str(path), notes)
    return ("ok", log, [str(w.message) for w in caught], [p.n_samples for p in parts])


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("chunk", [97, 1600, 5000])
def test_chunked_read_is_the_whole_read(mcap_files, off_square, encoding, chunk):
    whole = read_quiet(mcap_files[encoding], off_square)
    ok, log, texts, sizes = read_chunked(mcap_files[encoding], off_square, chunk)
    assert ok == "ok" and texts == [] and log.notes == []
    assert_same_log(log, whole)
    assert max(sizes) <= chunk and sum(sizes) == whole.n_samples == 1601
    assert len(sizes) == -(-1601 // chunk)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_chunked_read_of_damaged_files_recovers_the_same(tmp_path, mcap_files, off_square,
                                                         encoding):
    """Cut anywhere: the chunks hold exactly the messages the whole read recovers, with the
    same note (on the last chunk) and warning, or fail with the same one-line error."""
    data = mcap_files[encoding].read_bytes()
    path = tmp_path / "cut.mcap"
    for cut in [5, 200] + [int(f * len(data)) for f in np.linspace(0.05, 0.95, 10)] \
            + [len(data) - 9]:
        path.write_bytes(data[:cut])
        whole = read_damaged(path, off_square)
        chunked = read_chunked(path, off_square, 300)
        if whole[0] == "error":
            assert chunked == whole, cut
            continue
        _, n, texts = whole
        ok, log, ctexts, sizes = chunked
        assert ok == "ok" and log.n_samples == n and ctexts == texts == log.notes, cut
        assert_same_log(log, read_log_quietly(path, off_square))


def read_log_quietly(path, platform):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_mcap_log(path, platform)


def test_time_going_back_across_a_chunk_names_the_message(tmp_path, off_square,
                                                          runs_off_square):
    from ropod_sysid.io.mcaplog import iter_mcap_log

    log = runs_off_square[0].log.slice(0, 400)
    log = dataclasses.replace(log, t=log.t.copy())  # (a slice shares the fixture's arrays)
    log.t[300] = log.t[299]  # message 300 of the file, the first of the fourth chunk of 100
    path = tmp_path / "back.mcap"
    write_mcap_log(log, path, "json")
    with pytest.raises(InputError) as e:
        list(iter_mcap_log(path, off_square, 100))
    with pytest.raises(InputError) as whole:
        read_mcap_log(path, off_square)
    assert str(e.value) == str(whole.value)
    assert "message 300: time" in str(e.value) and "of message 299" in str(e.value)


def test_chunked_read_of_a_too_short_log_has_the_whole_read_error(tmp_path, off_square,
                                                                  runs_off_square):
    from ropod_sysid.io.mcaplog import iter_mcap_log

    path = tmp_path / "two.mcap"
    write_mcap_log(runs_off_square[0].log.slice(0, 2), path, "json")
    with pytest.raises(InputError) as whole:
        read_mcap_log(path, off_square)
    with pytest.raises(InputError) as chunked:
        list(iter_mcap_log(path, off_square, 100))
    assert str(chunked.value) == str(whole.value)
    assert "only 2 messages; at least 3 samples are needed" in str(whole.value)


# ---------------------------------------------------------------------------------------------
# batch decoding: the fixed CDR layout, messages off it, JSON parsed by orjson


def write_ros2_messages(path, messages):
    """A contract ROS 2 file of the given message dicts (any units, arrays and poses)."""
    from mcap_ros2._dynamic import serialize_dynamic

    from ropod_sysid.io.mcapwrite import CONTRACT_MSGDEF, CONTRACT_ROS2_SCHEMA, new_writer

    encode = serialize_dynamic(CONTRACT_ROS2_SCHEMA, CONTRACT_MSGDEF)[CONTRACT_ROS2_SCHEMA]
    with open(path, "wb") as f:
        w = new_writer(f, profile="ros2")
        sid = w.register_schema(CONTRACT_ROS2_SCHEMA, "ros2msg", CONTRACT_MSGDEF.encode())
        cid = w.register_channel(CONTRACT_TOPIC, "cdr", sid)
        for k, m in enumerate(messages):
            w.add_message(cid, k, encode(m), k, k)
        w.finish()


def contract_messages(log, units=None):
    units = units or list(log.units)
    idx = [list(log.units).index(u) for u in units]
    out = []
    for k in range(log.n_samples):
        out.append({"t": float(log.t[k]), "units": units,
                    "delta": D(log)[k, idx].tolist(), "phi_l": P(log)[k, idx, 0].tolist(),
                    "phi_r": P(log)[k, idx, 1].tolist(), "cur_l": C(log)[k, idx, 0].tolist(),
                    "cur_r": C(log)[k, idx, 1].tolist(), "pose": []})
    return out


def test_fixed_cdr_layout_reads_the_numbers_of_every_message(mcap_files, off_square):
    """The layout of the first message finds the same numbers as the per-message decoder in
    every message; a message of another length or with other counts is left out."""
    from ropod_sysid.io.cdr import contract_layout
    from ropod_sysid.io.mcapdecode import ros2_decoder

    scan = scan_mcap(mcap_files["ros2"])
    (channel,) = scan.channels.values()
    decode = ros2_decoder(scan.schemas[channel.schema_id], channel.topic, "x")
    payloads = [m.data for m in scan.messages[channel.id]]
    layout = contract_layout(payloads[0], decode(payloads[0]))
    assert layout is not None and layout.size == len(payloads[0])
    odd = bytearray(payloads[5])
    odd[16] ^= 1                          # the length of the first unit name
    batch = payloads[:5] + [bytes(odd), payloads[6][:-8]] + payloads[7:]
    mask, cols = layout.read(batch)
    assert mask.tolist() == [True] * 5 + [False, False] + [True] * (len(batch) - 7)
    msgs = [decode(p) for p in payloads]
    keep = [m for m, ok in zip(msgs, mask, strict=True) if ok]
    assert np.array_equal(cols["t"], [m.t for m in keep])
    assert np.array_equal(cols["values"][:, 1], [m.phi_l for m in keep])
    assert cols["pose"].shape == (len(keep), 0)


@pytest.mark.parametrize("chunk", [None, 97])
def test_ros2_messages_off_the_fixed_layout_are_decoded_one_by_one(tmp_path, off_square,
                                                                   runs_off_square, chunk):
    from ropod_sysid.io.mcaplog import iter_mcap_log

    log = runs_off_square[1].log.slice(0, 400)
    msgs = contract_messages(log)
    msgs[150]["pose"] = [1.0, 2.0, 3.0]     # longer than the others; ignored, as message 0
    path = tmp_path / "odd.mcap"           # has no pose
    write_ros2_messages(path, msgs)

    def read(p):
        if chunk is None:
            return read_quiet(p, off_square)
        ok, back, texts, _ = read_chunked(p, off_square, chunk)
        assert ok == "ok" and texts == []
        return back

    assert_same_log(read(path), log)
    msgs[160] = contract_messages(log.slice(160, 161), ["2", "1", "3", "4"])[0]
    write_ros2_messages(path, msgs)
    with pytest.raises(InputError) as err:
        list(iter_mcap_log(path, off_square, chunk)) if chunk else read_mcap_log(path, off_square)
    assert (f"message 160 lists units ['2', '1', '3', '4'] but message {chunk or 0} lists "
            "['1', '2', '3', '4']") in str(err.value)
    msgs[160] = dict(contract_messages(log.slice(160, 161))[0], cur_r=[0.5, 0.5])
    write_ros2_messages(path, msgs)
    with pytest.raises(InputError, match="message 160 has arrays shorter than its unit list"):
        list(iter_mcap_log(path, off_square, chunk)) if chunk else read_mcap_log(path, off_square)


def test_json_messages_orjson_refuses_are_read_by_json(tmp_path, off_square, runs_off_square):
    """Integers for floats, extra keys and a message only Python's parser takes (a big
    integer) read as before; text that is no JSON is damage named as json.loads names it."""
    log = runs_off_square[2].log.slice(0, 60)
    path = tmp_path / "j.mcap"
    write_mcap_log(log, path, "json")
    scan = scan_mcap(path)
    (channel,) = scan.channels.values()
    payloads = [m.data for m in scan.messages[channel.id]]
    msgs = [json.loads(p) for p in payloads]
    msgs[3]["extra"] = {"note": "ignored"}
    msgs[4]["units"]["1"]["cur_L"] = 2
    msgs[5]["units"]["2"]["cur_R"] = 10**30           # beyond orjson's integers
    expected = with_arrays(log, current=C(log).copy())
    C(expected)[4, 0, 0], C(expected)[5, 1, 1] = 2.0, 1e30

    def write(texts):
        with open(path, "wb") as f:
            w = McapWriter(f)
            w.start()
            sid = w.register_schema(scan.schemas[channel.schema_id].name, "jsonschema", b"{}")
            cid = w.register_channel(CONTRACT_TOPIC, "json", sid)
            for k, text in enumerate(texts):
                w.add_message(cid, k, text, k)
            w.finish()

    write([json.dumps(m).encode() for m in msgs])
    assert_same_log(read_quiet(path, off_square), expected)
    texts = [json.dumps(m).encode() for m in msgs]
    texts[6] = texts[6].replace(b'"t": ', b'"t":\n ', 1)        # JSON over two lines
    texts[7] = re.sub(rb'"phi_L": [^,]+', b'"phi_L": -0', texts[7], count=1)  # Python: 0.0
    P(expected)[7, 0, 0] = 0.0
    write(texts)
    back = read_quiet(path, off_square)
    assert_same_log(back, expected)
    assert not np.signbit(P(back)[7, 0, 0])
    del msgs[9]["units"]["3"]["delta"]
    write([json.dumps(m).encode() for m in msgs])
    with pytest.raises(InputError, match=r"message 9 lacks a log field \(no 'delta'\)"):
        read_mcap_log(path, off_square)
    msgs[9]["units"]["3"]["delta"] = 0.5
    write([json.dumps(m).encode() for m in msgs[:40]] + [b'{"t": 1.0, "units": {'] +
          [json.dumps(m).encode() for m in msgs[41:]])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back = read_mcap_log(path, off_square)
    assert back.n_samples == 40
    assert ("message 40 on /ropod/sysid cannot be decoded (JSONDecodeError: Expecting "
            "property name enclosed in double quotes") in str(caught[0].message)


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_log_channel_interleaved_with_another_reads_the_same(tmp_path, mcap_files, off_square,
                                                              encoding):
    """Chunks that mix our channel with another topic's messages (as a robot's recording
    does) give the same log, whole and in chunks."""
    from ropod_sysid.io.mcapwrite import new_writer

    scan = scan_mcap(mcap_files[encoding])
    (channel,) = scan.channels.values()
    schema = scan.schemas[channel.schema_id]
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f:
        w = new_writer(f)
        sid = w.register_schema(schema.name, schema.encoding, schema.data)
        cid = w.register_channel(channel.topic, channel.message_encoding, sid)
        other = w.register_channel("/tf", "json", w.register_schema("x/Y", "jsonschema", b"{}"))
        for k, m in enumerate(scan.messages[channel.id]):
            w.add_message(cid, m.log_time, m.data, m.publish_time, k)
            if k % 3 == 0:
                w.add_message(other, m.log_time, b'{"x": %d}' % k, m.log_time, k)
        w.finish()
    whole = read_quiet(mcap_files[encoding], off_square)
    assert_same_log(read_quiet(path, off_square), whole)
    ok, log, texts, _ = read_chunked(path, off_square, 500)
    assert ok == "ok" and texts == []
    assert_same_log(log, whole)
