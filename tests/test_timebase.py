"""The time base (ropod_sysid.io.timebase): gaps, huge jumps, the unit of t, duplicated
timestamps and a log listed twice are one-line errors with exit status 2 and no output file;
--split-gaps fits the pieces between gaps as separate logs."""

from __future__ import annotations

import os
import time
import warnings

import numpy as np
import pytest

from ropod_sysid import stream
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_files, fit_logs
from ropod_sysid.io import check_distinct, read_log, write_log
from ropod_sysid.io.log import Log
from ropod_sysid.io.paramfile import read_parameter_file, write_parameter_file
from ropod_sysid.io.smartwheel import write_smartwheel
from ropod_sysid.io.timebase import TimeBase, split_chunks
from ropod_sysid.platform import save_platform
from tests.swivel_arrays import C, D, P, make_log
from tests.test_cli import one_line_error, run

GAP_FIX = ("a step longer than 5 median steps and 0.02 s is a gap, which resampling would "
           "fill with invented samples — give --split-gaps to fit the pieces as separate logs, "
           "or cut the log there")


def joined(a: Log, b: Log, gap: float) -> Log:
    """Log ``a``, then ``b`` starting ``gap`` s after a's last sample."""
    tb = b.t - b.t[0] + a.t[-1] + gap
    return make_log(np.concatenate([a.t, tb]), list(a.units), np.concatenate([D(a), D(b)]),
                    np.concatenate([P(a), P(b)]), np.concatenate([C(a), C(b)]),
                    source="joined")


@pytest.fixture(scope="module")
def d(tmp_path_factory, off_square, runs_off_square):
    d = tmp_path_factory.mktemp("timebase")
    save_platform(off_square, d / "platform.yaml")
    a, b = runs_off_square[0].log, runs_off_square[1].log
    gapped = joined(a, b, 10.0)
    write_log(gapped, d / "gapped.csv")
    write_log(gapped.slice(0, a.n_samples), d / "piece1.csv")
    write_log(gapped.slice(a.n_samples, gapped.n_samples), d / "piece2.csv")
    write_log(a, d / "run.csv")
    write_parameter_file(fit_files([d / "run.csv"], off_square).parameter_file(),
                         d / "params.json")
    return d


def cli(d, command: str, *logs: str, out: str = "out.json", extra: tuple[str, ...] = ()):
    args = [command, *[str(d / p) for p in logs], "--platform", str(d / "platform.yaml")]
    if command in ("fit", "report"):
        args += ["--out", str(d / out)]
    if command in ("validate", "report"):
        args += ["--params", str(d / "params.json")]
    return run(*args, *extra, "--quiet")


def gap_message(path, log: Log, k: int, line_of) -> str:
    step = log.t[k] - log.t[k - 1]
    return (f"{path}: {line_of(k)}: a gap of {step:.6g} s ({step / 0.005:.4g} median steps of "
            f"0.005 s) after t={float(log.t[k - 1])!r} on {line_of(k - 1)}; {GAP_FIX}")


# ---------------------------------------------------------------------------------------------
# gaps


def test_a_gap_is_an_error_naming_line_gap_and_fix(d, runs_off_square, off_square):
    n1 = runs_off_square[0].log.n_samples
    gapped = read_log(d / "gapped.csv", off_square, gaps="allow")
    assert gapped.t[n1] - gapped.t[n1 - 1] == pytest.approx(10.0)
    want = gap_message(d / "gapped.csv", gapped, n1, lambda k: f"line {k + 2}")
    assert "a gap of 10 s (2000 median steps of 0.005 s)" in want
    r = cli(d, "fit", "gapped.csv")
    one_line_error(r, want)
    assert r.output.strip() == f"error: {want}"
    assert not (d / "out.json").exists()
    one_line_error(cli(d, "validate", "gapped.csv"), want)
    one_line_error(cli(d, "report", "gapped.csv", out="r.html"), want)
    assert not (d / "r.html").exists()
    # the whole read, and chunks whose boundary is the gap (the check carries the last time)
    with pytest.raises(InputError) as whole:
        read_log(d / "gapped.csv", off_square)
    assert str(whole.value) == want
    for chunk in (n1, 997):
        with pytest.raises(InputError) as chunked:
            fit_files([d / "gapped.csv"], off_square, chunk=chunk)
        assert str(chunked.value) == want


def test_a_gap_in_mcap_smartwheel_and_memory_names_message_frame_sample(d, off_square,
                                                                       runs_off_square):
    n1 = runs_off_square[0].log.n_samples
    gapped = read_log(d / "gapped.csv", off_square, gaps="allow")
    write_log(gapped, d / "gapped.mcap")
    with pytest.raises(InputError) as exc:
        read_log(d / "gapped.mcap", off_square)
    assert str(exc.value) == gap_message(d / "gapped.mcap", gapped, n1, lambda k: f"message {k}")
    with pytest.raises(InputError) as exc:   # chunked, the gap at a chunk boundary
        stream.stream_log(d / "gapped.mcap", off_square, chunk=n1)
    assert str(exc.value) == gap_message(d / "gapped.mcap", gapped, n1, lambda k: f"message {k}")
    write_smartwheel(gapped, d / "sw.csv", off_square)
    with pytest.raises(InputError, match=rf"sw.csv: frame #{n1}: a gap of 10 s \(2000 median "
                                         rf"steps of 0.005 s\) after t=.* on frame #{n1 - 1}; "):
        read_log(d / "sw.csv", off_square)
    gapped.source = "mem"
    with pytest.raises(InputError) as exc:
        stream.stream_log(gapped, off_square, chunk=500)
    assert str(exc.value) == gap_message("mem", gapped, n1, lambda k: f"sample {k}")
    with pytest.raises(InputError, match=r"mem: sample \d+: a gap of 10 s"):
        fit_logs([gapped], off_square)


def test_jitter_and_single_dropped_samples_are_no_gap(runs_off_square):
    t = runs_off_square[0].log.t
    rng = np.random.default_rng(3)
    jittered = t + rng.uniform(-0.4, 0.4, t.size) * 0.005
    TimeBase("j").check(np.delete(jittered, [10, 11, 12, 500]))   # 4 samples dropped: 5 steps
    tb = TimeBase("j", gaps="allow")
    tb.check(np.delete(t, np.arange(10, 16)))     # 6 dropped: a step of 7 median steps
    tb.finish()
    assert tb.gaps == [10]


def test_split_gaps_equals_the_pieces_as_separate_logs(d, off_square, runs_off_square):
    n1 = runs_off_square[0].log.n_samples
    split = fit_files([d / "gapped.csv"], off_square, FitOptions(split_gaps=True), chunk=997)
    pieces = fit_files([d / "piece1.csv", d / "piece2.csv"], off_square, chunk=997)
    va, vb = split.solution.values, pieces.solution.values
    assert np.max(np.abs(va - vb) / np.abs(vb)) < 1e-10
    assert np.max(np.abs(split.solution.std - pieces.solution.std)
                  / np.abs(pieces.solution.std)) < 1e-10
    assert [lf.source for lf in split.logs] == [f"{d / 'gapped.csv'}[1]", f"{d / 'gapped.csv'}[2]"]
    assert [lf.samples for lf in split.logs] == [lf.samples for lf in pieces.logs]
    assert split.logs[1].notes[0] == (f"{d / 'gapped.csv'}[2]: samples {n1}–{2 * n1 - 1} of "
                                      f"{d / 'gapped.csv'} (t 18–26 s), fitted as a separate "
                                      "log (--split-gaps)")
    # the in-memory path splits alike
    mem = fit_logs([read_log(d / "gapped.csv", off_square, gaps="allow")], off_square,
                   FitOptions(split_gaps=True))
    assert np.max(np.abs(mem.solution.values - vb) / np.abs(vb)) < 1e-6
    assert [lf.source for lf in mem.logs] == [lf.source for lf in split.logs]
    assert mem.logs[1].notes[0] == split.logs[1].notes[0]
    # the command: refused without the flag (test above), the pieces in the parameter file
    r = cli(d, "fit", "gapped.csv", out="split.json", extra=("--split-gaps",))
    assert r.exit_code == 0, r.output
    extras = read_parameter_file(d / "split.json").extras
    assert extras["split_gaps"] is True
    logs = extras["logs"]
    assert [(e["file"], e["samples"]) for e in logs] == [
        (f"{d / 'gapped.csv'}[{k + 1}]", lf.samples) for k, lf in enumerate(split.logs)]
    assert cli(d, "validate", "gapped.csv", extra=("--split-gaps",)).exit_code == 0
    r = cli(d, "report", "gapped.csv", out="split.html", extra=("--split-gaps",))
    assert r.exit_code == 0, r.output
    assert "gapped.csv[2]" in (d / "split.html").read_text()
    assert "--split-gaps" in run("fit", "--help").output
    assert "5 median steps and 0.02 s" in " ".join(run("fit", "--help").output.split())


def test_split_gaps_leaves_out_short_pieces_or_refuses(d, off_square, runs_off_square):
    a = runs_off_square[0].log
    short = joined(a, a.slice(0, 30), 3.0)
    write_log(short, d / "short_tail.csv")
    res = fit_files([d / "short_tail.csv"], off_square, FitOptions(split_gaps=True))
    assert [lf.source for lf in res.logs] == [f"{d / 'short_tail.csv'}[1]"]
    assert any("short_tail.csv[2]: 30 samples are too few for a smoother span of 21 samples" in n
               and "left out" in n for n in res.logs[0].notes)
    ref = fit_files([d / "run.csv"], off_square)
    assert np.allclose(res.solution.values, ref.solution.values, rtol=1e-10)
    mem = fit_logs([read_log(d / "short_tail.csv", off_square, gaps="allow")], off_square,
                   FitOptions(split_gaps=True))
    assert [lf.source for lf in mem.logs] == [lf.source for lf in res.logs]
    assert res.logs[0].notes[-1] in mem.logs[0].notes
    tiny = joined(a.slice(0, 40), a.slice(0, 30), 3.0)
    write_log(tiny, d / "tiny.csv")
    r = cli(d, "fit", "tiny.csv", out="tiny.json", extra=("--split-gaps",))
    one_line_error(r, "tiny.csv: every piece between the gaps in time is too short to fit",
                   "tiny.csv[1]: 40 samples are too few", "tiny.csv[2]: 30 samples")
    assert not (d / "tiny.json").exists()


def test_split_chunks_cuts_at_gaps_across_chunk_boundaries():
    t = np.r_[np.arange(50) * 0.01, 10 + np.arange(50) * 0.01, 30 + np.arange(3) * 0.01]
    log = make_log(t, ["1"], np.zeros((t.size, 1)), np.zeros((t.size, 1, 2)),
                   np.zeros((t.size, 1, 2)), source="m")
    for chunk in (7, 50, 1000):
        parts = list(split_chunks((log.slice(s, s + chunk) for s in range(0, t.size, chunk)),
                                  "m"))
        pieces = [np.concatenate([p.t for p in parts if p.piece == j]) for j in range(3)]
        assert [p.size for p in pieces] == [50, 50, 3]
        assert np.array_equal(np.concatenate(pieces), t)


# ---------------------------------------------------------------------------------------------
# a huge jump, the unit of t, duplicated timestamps


def test_a_jump_of_a_million_seconds_is_refused_at_once(d, off_square, runs_off_square):
    a = runs_off_square[0].log
    write_log(joined(a, a, 1e6), d / "jump.csv")
    start = time.perf_counter()
    r = cli(d, "fit", "jump.csv", out="jump.json")
    took = time.perf_counter() - start
    one_line_error(r, "jump.csv: line 1603: a gap of 1e+06 s (2e+08 median steps of 0.005 s)")
    assert took < 1.0 and not (d / "jump.json").exists()
    start = time.perf_counter()
    with pytest.raises(InputError, match="a gap of 1e"):
        stream.stream_log(joined(a, a, 1e6), off_square)   # in memory, before any grid
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize("scale, fragment", [
    (1000.0, "the median time step of the first 1600 steps is 5 s (a rate of 0.2 Hz); is `t` in "
             "milliseconds? t must be in seconds — divide it by 1000 (by 1e9 for nanoseconds)"),
    (1e-3, "the median time step of the first 1600 steps is 5e-06 s, under 0.1 ms (a rate above "
           "10 kHz); is `t` in another unit (minutes, hours)? t must be in seconds"),
])
def test_time_in_the_wrong_unit(d, runs_off_square, scale, fragment):
    a = runs_off_square[0].log
    log = a.slice(0, a.n_samples)
    log.t = a.t * scale
    name = f"unit{scale:g}.csv"
    write_log(log, d / name)
    r = cli(d, "fit", name, out="unit.json")
    one_line_error(r, f"{d / name}: {fragment}")
    assert not (d / "unit.json").exists()
    write_log(log, d / "unit.mcap")
    one_line_error(cli(d, "fit", "unit.mcap", out="unit.json"), fragment)


def test_duplicated_timestamps_name_the_lines(d, runs_off_square):
    a = runs_off_square[0].log
    log = a.slice(0, a.n_samples)
    log.t = a.t.copy()
    log.t[700] = log.t[699]
    write_log(log, d / "dup.csv")
    r = cli(d, "fit", "dup.csv", out="dup.json")
    one_line_error(r, f"{d / 'dup.csv'}: line 702: time t={float(a.t[699])!r} repeats "
                      f"t={float(a.t[699])!r} of line 701 (a duplicated timestamp); time must "
                      "strictly increase — remove the repeated sample")
    assert not (d / "dup.json").exists()
    write_log(log, d / "dup.mcap")
    one_line_error(cli(d, "fit", "dup.mcap", out="dup.json"),
                   "dup.mcap: message 700: time", "repeats", "of message 699 (a duplicated")


# ---------------------------------------------------------------------------------------------
# a log listed twice


def test_the_same_log_twice_is_refused(d):
    twice = "twice counts its samples twice and shrinks every σ by √2 — list each once"
    run_csv = d / "run.csv"
    one_line_error(cli(d, "fit", "run.csv", "run.csv", out="twice.json"),
                   f"{run_csv}: the same log as {run_csv} (listed twice); a log given {twice}")
    link = d / "link.csv"
    if not link.exists():
        os.symlink(run_csv, link)
    one_line_error(cli(d, "fit", "run.csv", "link.csv", out="twice.json"),
                   f"{link}: the same log as {run_csv} (the same file by another path)")
    (d / "copy.csv").write_bytes(run_csv.read_bytes())
    one_line_error(cli(d, "fit", "run.csv", "copy.csv", out="twice.json"),
                   f"{d / 'copy.csv'}: the same content as {run_csv} (an identical copy)")
    assert not (d / "twice.json").exists()
    one_line_error(cli(d, "validate", "run.csv", "copy.csv"), "an identical copy")
    one_line_error(cli(d, "report", "copy.csv", "run.csv", out="twice.html"),
                   "an identical copy")
    assert not (d / "twice.html").exists()
    # the same size but other bytes is another log
    data = bytearray(run_csv.read_bytes())
    k = data.rindex(b"1")
    data[k:k + 1] = b"2"
    (d / "other.csv").write_bytes(bytes(data))
    check_distinct([run_csv, d / "other.csv", d / "missing.csv"])


def test_inspect_reports_gaps_instead_of_failing(d):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = run("inspect", str(d / "gapped.csv"), "--platform", str(d / "platform.yaml"))
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    assert "1 of them the fit refuses (a step longer than 5 median steps and 0.02 s is a gap): " \
           "give fit, validate and report --split-gaps to fit the 2 pieces" in text


def test_convert_keeps_a_log_with_gaps(d, off_square):
    r = run("convert", str(d / "gapped.csv"), str(d / "converted.mcap"), "--platform",
            str(d / "platform.yaml"), "--quiet")
    assert r.exit_code == 0, r.output
    a = read_log(d / "gapped.csv", off_square, gaps="allow")
    b = read_log(d / "converted.mcap", off_square, gaps="allow")
    assert np.array_equal(a.t, b.t)
    with pytest.raises(InputError, match="converted.mcap: message 1601: a gap of 10 s"):
        read_log(d / "converted.mcap", off_square)
