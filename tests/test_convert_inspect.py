"""``convert`` and ``inspect``: round trips through the command line, inspection fields, the
smart-wheel sample in datasets/, one-line errors with exit status 2.

The run is the conftest's session-scoped simulation (8 s on the off-square ropod, 200 Hz).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.inspect import Criteria, format_inspection, inspect_file, inspect_log
from ropod_sysid.io import read_log
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.io.mcaplog import scan_mcap
from ropod_sysid.platform import load_platform, platform_from_dict, save_platform
from tests.swivel_arrays import C, D, P, with_arrays

SAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "smartwheel"


@pytest.fixture(scope="module")
def files(tmp_path_factory, off_square, runs_off_square):
    d = tmp_path_factory.mktemp("convert")
    save_platform(off_square, d / "platform.yaml")
    sw = off_square.to_dict()
    sw["units"][1]["left_motor"] = 2
    sw["units"][2]["sign_right"] = -1
    sw["units"][3]["pivot_offset"] = 0.7
    save_platform(platform_from_dict(sw), d / "sw_platform.yaml")
    write_csv_log(runs_off_square[0].log, d / "run.csv")
    return d


def run(*args) -> object:
    return CliRunner().invoke(main, [str(a) for a in args])


def ok(result) -> None:
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output


def one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    for frag in fragments:
        assert frag in lines[0], lines[0]


def test_csv_to_mcap_and_back_through_both_encodings(files):
    d = files
    pf = d / "platform.yaml"
    ok(run("convert", d / "run.csv", d / "a.mcap", "--platform", pf))
    ok(run("convert", d / "a.mcap", d / "b.mcap", "--platform", pf, "--encoding", "ros2"))
    ok(run("convert", d / "b.mcap", d / "c.mcap", "--platform", pf, "--encoding", "json"))
    ok(run("convert", d / "c.mcap", d / "back.csv", "--platform", pf, "-q"))
    assert (d / "back.csv").read_bytes() == (d / "run.csv").read_bytes()
    encodings = {}
    for name in ("a", "b", "c"):
        scan = scan_mcap(d / f"{name}.mcap")
        (ch,) = scan.channels.values()
        encodings[name] = ch.message_encoding
    assert encodings == {"a": "json", "b": "cdr", "c": "json"}
    res = run("convert", d / "run.csv", d / "x.mcap", "--platform", pf)
    assert "wrote" in res.output and "1601 samples" in res.output


@pytest.mark.parametrize("out,encoding", [("sw.mcap", "json"), ("sw_ros2.mcap", "ros2"),
                                          ("sw.csv", None)])
def test_smartwheel_layout_out_and_back(files, off_square, runs_off_square, out, encoding):
    d = files
    swp = d / "sw_platform.yaml"
    args = ["convert", d / "run.csv", d / out, "--platform", swp, "--layout", "smartwheel"]
    if encoding:
        args += ["--encoding", encoding]
    ok(run(*args))
    back = d / f"{out}.back.csv"
    ok(run("convert", d / out, back, "--platform", swp))
    log = runs_off_square[0].log
    got = read_log(back, off_square)
    assert np.allclose(got.t, log.t - log.t[0], rtol=0, atol=1e-12)
    assert np.array_equal(C(got), C(log))
    assert np.allclose(np.diff(P(got), axis=0), np.diff(P(log), axis=0), rtol=0, atol=1e-12)
    assert np.allclose(np.cos(D(got)), np.cos(D(log)), rtol=0, atol=1e-12)
    if out.endswith(".csv"):
        assert (d / out).read_text().startswith("sensors.0.status1,")


def test_inspect_fields(files, runs_off_square):
    d = files
    res = run("inspect", d / "run.csv", "--platform", d / "platform.yaml", "--json")
    ok(res)
    info = json.loads(res.output)
    assert info["units"] == ["1", "2", "3", "4"]
    assert info["samples"] == 1601
    assert info["duration"] == pytest.approx(8.0)
    assert info["rate"] == pytest.approx(200.0)
    assert info["dt_median"] == pytest.approx(0.005)
    assert info["jitter"] < 1e-12
    assert info["gap_count"] == 0 and info["dropped_frames"] == 0
    log = runs_off_square[0].log
    assert set(info["ranges"]) == set(log.columns())
    assert info["ranges"]["cur_2R"] == [C(log)[:, 1, 1].min(), C(log)[:, 1, 1].max()]
    lo, hi = info["velocity_ranges"]["vx"]
    assert 0.8 < hi < 1.05 and lo > -0.05     # 0.6 + 0.4 sin, from rest
    assert set(info["pivot_coverage"]) == {"1", "2", "3", "4"}
    assert info["encoder_counts"] is None and info["fit_options"] == []  # exact angles
    # 8 s from rest to rest: not enough motion, and it says so
    assert info["enough_to_fit"] is False
    assert any("of motion; record at least 10 s" in r for r in info["reasons"])
    text = run("inspect", d / "run.csv", "--platform", d / "platform.yaml")
    ok(text)
    for field in ("units", "samples", "rate", "jitter", "gaps", "dropped", "ranges", "cur_4L",
                  "verdict"):
        assert field in text.output


def test_inspect_says_how_to_fit_quantised_angles(off_square, runs_off_square):
    """Angles on a 2¹⁴-count grid: --encoder-counts, and at 200 Hz (21 samples in the 0.1 s
    span) the quartic smoother with the lag searched; at 100 Hz (11 samples) the correction
    alone; on a constrained platform the over-correction caveat."""
    from ropod_sysid.inspect import fit_suggestion
    from ropod_sysid.regressor import Span
    from ropod_sysid.simulate import Sensors, sensed

    log = sensed(runs_off_square[0].log, off_square, Sensors(encoder_counts=2**14),
                 np.random.default_rng(1))
    ins = inspect_log(log, off_square)
    assert ins.encoder_counts == 2**14
    assert ins.fit_options == ["--encoder-counts 16384", "--smoother quartic",
                               "--input-delay auto"]
    text = format_inspection(ins)
    assert "encoders   the angles move by whole counts of 2π/16384\n" in text
    assert ("fit with   --encoder-counts 16384 --smoother quartic --input-delay auto (to correct "
            "for the encoders' quantisation, which shrinks a plain fit's values; the 0.1s span "
            "holds 21 samples, enough for the quartic smoother's five-point differences, which "
            "keep the LOESS's bias out of a long log's values (with the drives' lag searched))"
            in text)
    span = Span.parse(None)
    assert fit_suggestion(2**14, span, 0.01)[0] == ["--encoder-counts 16384"]  # 11 samples
    assert fit_suggestion(2**14, span, 0.1 / 17)[0][1:] == ["--smoother quartic",
                                                            "--input-delay auto"]
    assert fit_suggestion(2**14, span, 0.1 / 15)[0] == ["--encoder-counts 16384"]
    assert fit_suggestion(2**14, span.with_smoother("quartic"), 0.001)[0] == [
        "--encoder-counts 16384"]  # the quartic already
    assert fit_suggestion(2**14, span, 0.01, constrained=True)[1].endswith(
        "; with steered wheels or legs the correction can over-correct: compare a plain fit")
    assert fit_suggestion(None, span, 0.001) == ([], "")


def test_inspect_finds_gaps_and_the_criteria_decide(off_square, runs_off_square):
    log = runs_off_square[1].log
    keep = np.r_[0:600, 640:1000, 1003:log.n_samples]
    cut = with_arrays(log, delta=D(log)[keep], phi=P(log)[keep], current=C(log)[keep],
                      t=log.t[keep])
    ins = inspect_log(cut, off_square)
    assert ins.gap_count == 2
    assert [(g.index, round(g.t, 3), round(g.dt, 3)) for g in ins.gaps] == [
        (599, 2.995, 0.205), (959, 4.995, 0.02)]
    assert "2 gaps" in ins.warnings[0] and "0.205 s at t=2.995 s" in ins.warnings[0]
    relaxed = inspect_log(log, off_square, Criteria(min_moving=5.0, min_pivot_coverage=30.0))
    assert relaxed.enough_to_fit, relaxed.reasons
    strict = inspect_log(log, off_square, Criteria(min_vy=5.0))
    assert not strict.enough_to_fit and any(r.startswith("vy spans only") for r in strict.reasons)
    assert "verdict    not enough to fit" in format_inspection(strict)


def test_sample_dataset_reads_and_is_enough_to_fit():
    """datasets/smartwheel: smart-wheel MCAP made by make_sample.py, with its platform file."""
    path = SAMPLE / "sample.mcap"
    assert path.stat().st_size <= 1_000_000
    platform = load_platform(SAMPLE / "platform.yaml")
    assert [(u.left_motor, u.sign_left, u.sign_right) for u in platform.units] == [
        (1, 1, 1), (2, 1, 1), (1, 1, -1), (1, 1, 1)]
    ins = inspect_file(path, platform)
    assert ins.dropped_frames == 6 and ins.gap_count == 0
    assert 10.0 <= ins.duration <= 20.0
    assert ins.enough_to_fit, ins.reasons
    res = run("inspect", path, "--platform", SAMPLE / "platform.yaml")
    ok(res)
    assert "dropped    6 frames" in res.output and "verdict    enough to fit" in res.output


def test_bad_input_is_one_line_with_status_2(files, tmp_path):
    d = files
    pf = d / "platform.yaml"
    one_line_error(run("convert", d / "nope.csv", tmp_path / "x.mcap", "--platform", pf),
                   "nope.csv", "no such log file")
    one_line_error(run("convert", d / "run.csv", tmp_path / "x.txt", "--platform", pf),
                   "unknown log format '.txt'")
    one_line_error(run("convert", d / "run.csv", tmp_path / "x.csv", "--platform", pf,
                       "--encoding", "ros2"), "applies to .mcap output only")
    (tmp_path / "bad.mcap").write_bytes((d / "run.csv").read_bytes()[:300])
    one_line_error(run("inspect", tmp_path / "bad.mcap", "--platform", pf), "not an MCAP file")
    (tmp_path / "cut.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\x01" * 20)
    one_line_error(run("inspect", tmp_path / "cut.mcap", "--platform", pf))
    one_line_error(run("inspect", d / "run.csv", "--platform", tmp_path / "missing.yaml"),
                   "no such platform file")
    assert not (tmp_path / "x.mcap").exists() and not (tmp_path / "x.csv").exists()
    assert not list(tmp_path.glob(".*.tmp"))


def test_damaged_input_converts_with_a_warning(files, tmp_path):
    d = files
    pf = d / "platform.yaml"
    ok(run("convert", d / "run.csv", tmp_path / "full.mcap", "--platform", pf))
    data = (tmp_path / "full.mcap").read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: int(0.6 * len(data))])
    res = run("convert", tmp_path / "cut.mcap", tmp_path / "cut.csv", "--platform", pf)
    ok(res)
    warn = [ln for ln in res.output.splitlines() if ln.startswith("warning: ")]
    assert len(warn) == 1 and "truncated" in warn[0] and "recovered the" in warn[0]
    n = int(warn[0].split("recovered the ")[1].split()[0])
    assert len((tmp_path / "cut.csv").read_text().splitlines()) == n + 1


def test_convert_writes_gzip_compressed_csv(files):
    d = files
    pf = d / "platform.yaml"
    ok(run("convert", d / "run.csv", d / "a.mcap", "--platform", pf))
    ok(run("convert", d / "a.mcap", d / "back.csv.gz", "--platform", pf))
    import gzip

    assert gzip.decompress((d / "back.csv.gz").read_bytes()) == (d / "run.csv").read_bytes()
    one_line_error(run("convert", d / "run.csv", d / "sw.csv.gz", "--platform", pf,
                       "--layout", "smartwheel"),
                   "the smart-wheel layout is written as .csv or .mcap")
    one_line_error(run("convert", d / "run.csv", d / "x.txt", "--platform", pf),
                   "unknown log format '.txt'")
    assert not (d / "sw.csv.gz").exists() and not (d / "x.txt").exists()


STEERED = Path(__file__).resolve().parents[1] / "datasets" / "steered"


def test_steered_sample_converts_and_inspects(tmp_path):
    """The shipped steered sample: CSV → JSON MCAP → CSV gives the same table; the ROS 2 layout
    (swivel units only) is refused in one line; inspect counts the base rows the fit keeps and
    does not ask the two-wheel base for sideways motion, a singular configuration of it."""
    platform = str(STEERED / "platform.yaml")
    src = STEERED / "original.csv.gz"
    ok(run("convert", "--platform", platform, str(src), str(tmp_path / "o.mcap")))
    ok(run("convert", "--platform", platform, str(tmp_path / "o.mcap"), str(tmp_path / "o.csv")))
    a, b = (read_log(p, load_platform(platform)) for p in (src, tmp_path / "o.csv"))
    assert np.array_equal(a.angles, b.angles) and np.array_equal(a.currents, b.currents)
    one_line_error(run("convert", "--platform", platform, "--encoding", "ros2", str(src),
                       str(tmp_path / "r.mcap")),
                   f"error: {src}: the ROS 2 layout of ropod-sysid carries smart-wheel (swivel) "
                   "units only; write JSON MCAP or CSV for this platform")
    assert not (tmp_path / "r.mcap").exists()
    ins = inspect_file(src, load_platform(platform))
    assert ins.sideways_singular and ins.enough_to_fit, ins.reasons
    assert 0.9 < ins.base_rows_used <= 1.0
    text = format_inspection(ins)
    assert "sideways   a singular configuration of this platform" in text
    # the ropod's swivels do not constrain the base: nothing of the kind
    ropod = inspect_file(SAMPLE.parent / "ropod" / "original.csv.gz",
                         load_platform(SAMPLE.parent / "ropod" / "platform.yaml"))
    assert ropod.base_rows_used is None and not ropod.sideways_singular
