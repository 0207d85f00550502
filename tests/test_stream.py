"""Chunked identification equals the in-memory path; the chunked CSV reader keeps its checks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ropod_sysid import grid, stream, validate
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_files, fit_logs
from ropod_sysid.io import timebase
from ropod_sysid.io.csvlog import iter_csv_log, read_csv_log, write_csv_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.regressor import Span, preprocess, triangles
from ropod_sysid.simulate import Sensors, record
from ropod_sysid.validate import validate_log
from tests.swivel_arrays import C, D, P, make_log, with_arrays

REL = 1e-10


def gram(tri):
    """RᵀR per DOF: the triangles' content independent of row signs."""
    return np.einsum("dij,dik->djk", tri.r, tri.r)


def assert_same_triangles(a, b, rel=1e-12):
    assert a.rows == b.rows
    ga, gb = gram(a), gram(b)
    assert np.abs(ga - gb).max() <= rel * np.abs(ga).max()


def assert_same_values(fa, fb, rel=REL):
    va, vb = fa.solution.values, fb.solution.values
    err = np.abs(va - vb) / np.abs(va)
    assert err.max() <= rel, dict(zip(fa.names, err, strict=True))


@pytest.fixture(scope="module")
def csv_logs(tmp_path_factory, runs_off_square):
    d = tmp_path_factory.mktemp("stream")
    paths = []
    for k, r in enumerate(runs_off_square):
        p = d / f"run{k}.csv"
        write_csv_log(r.log, p)
        paths.append(p)
    return paths


@pytest.fixture(scope="module")
def reference(off_square, csv_logs):
    """The in-memory fit of the written logs (read whole)."""
    return fit_logs([read_csv_log(p, off_square) for p in csv_logs], off_square)


@pytest.mark.parametrize("chunk", [97, 1000])
def test_fit_files_equals_in_memory_fit(off_square, csv_logs, reference, chunk):
    """Streaming the written CSVs in small chunks gives the in-memory fit to 1e-10."""
    fit = fit_files(csv_logs, off_square, chunk=chunk)
    assert_same_values(reference, fit)
    for a, b in zip(reference.logs, fit.logs, strict=True):
        assert a.source == b.source and a.samples == b.samples
        assert b.weight == pytest.approx(a.weight, rel=1e-12)
        assert_same_triangles(a.triangles, b.triangles)
    assert fit.rms["translation"] == pytest.approx(reference.rms["translation"], rel=1e-9)


@pytest.mark.parametrize("chunk", [97, 1000, 50_000])
def test_stream_of_conftest_runs_equals_triangles(off_square, runs_off_square, chunk):
    """In-memory logs streamed in chunks: the triangles of every run, and the fit of all."""
    model = PlatformModel(off_square)
    tris = []
    for r in runs_off_square:
        ref = triangles(model, preprocess(r.log, off_square))
        res = stream.stream_log(r.log, off_square, chunk=chunk)
        assert res.samples == r.log.n_samples and res.span_samples == 21
        assert_same_triangles(ref, res.triangles)
        tris.append((ref, res.triangles))
    from ropod_sysid.fit import fit_systems

    names = model.parameter_names("per-wheel")
    opts = FitOptions()
    a, _ = fit_systems([t for t, _ in tris], names, opts)
    b, _ = fit_systems([t for _, t in tris], names, opts)
    assert (np.abs(a.values - b.values) / np.abs(a.values)).max() <= REL


def jittered(off_square, run, jitter=0.0015, seed=3):
    return record(off_square, run, run.log.t, Sensors(jitter=jitter, seed=seed),
                  np.random.default_rng(seed), "jittered")


def test_jittered_log_same_grid(off_square, runs_off_square):
    """A jittered log is put on the same uniform grid in both paths (dt from the head)."""
    log = jittered(off_square, runs_off_square[1])
    model = PlatformModel(off_square)
    pre = preprocess(log, off_square)
    assert any("resampled" in n for n in pre.notes)
    res = stream.stream_log(log, off_square, chunk=97)
    assert res.samples == len(pre.t) and res.dt == pre.dt
    assert res.notes == pre.notes
    assert_same_triangles(triangles(model, pre), res.triangles)


def jittered_after_the_head(platform, run, monkeypatch):
    """``run``'s log on its grid for 800 samples, jittered after them, with a head of 300
    samples (so that the pass finds the jitter only after its head)."""
    monkeypatch.setattr(timebase, "GRID_STEPS", 300)  # (the grid step, grid_step)
    monkeypatch.setattr(grid, "GRID_STEPS", 300)  # (the grid of the pass, ropod_sysid.grid)
    jit = jittered(platform, run)
    t = run.log.t.copy()
    t[800:] = jit.t[800:]
    return with_arrays(jit, t=t, delta=np.concatenate([D(run.log)[:800], D(jit)[800:]]),
                       phi=np.concatenate([P(run.log)[:800], P(jit)[800:]]))


def test_jitter_after_the_head_restarts_the_pass(off_square, runs_off_square, monkeypatch):
    """Steps off the grid only after the head: the pass restarts in resampling mode and still
    equals the in-memory path."""
    log = jittered_after_the_head(off_square, runs_off_square[2], monkeypatch)
    calls = []
    real = stream._pass

    def counting(*args, **kwargs):
        calls.append(args[8])  # resample flag
        return real(*args, **kwargs)

    monkeypatch.setattr(stream, "_pass", counting)
    pre = preprocess(log, off_square)
    res = stream.stream_log(log, off_square, chunk=200)
    assert calls == [False, True]
    assert res.samples == len(pre.t) and res.notes == pre.notes
    assert_same_triangles(triangles(PlatformModel(off_square), pre), res.triangles)


def test_reference_beside_a_restarted_pass(off_square, runs_off_square, monkeypatch):
    """The recipe check's reference formed beside the fit's blocks (ReferenceTee) survives
    the restart in resampling mode and equals a pass of its own recipe; past the automatic
    check's limit it is cut, the fit's own triangles unchanged."""
    from ropod_sysid import crosscheck

    log = jittered_after_the_head(off_square, runs_off_square[2], monkeypatch)
    refs: list = []
    res = stream.stream_pieces(log, off_square, chunk=200, check=FitOptions(recipe_check=True),
                               references=refs)
    (piece,) = refs
    span, delay = piece.span, piece.delay
    ((ref, main),) = piece.windows
    assert main is None and not piece.spread
    ref_options = crosscheck.reference_options(FitOptions(), res[0].dt)
    assert (span, delay) == (ref_options.span, ref_options.reduce_delay())
    alone = stream.stream_log(log, off_square, span=span, input_delay=delay, chunk=200)
    assert_same_triangles(alone.triangles, ref.triangles)
    assert_same_triangles(stream.stream_log(log, off_square, chunk=200).triangles,
                          res[0].triangles)
    # the automatic check's budget: the restarted pass gives back what its first try drew
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", len(log.t) + 10)
    refs.clear()
    stream.stream_pieces(log, off_square, chunk=200, check=FitOptions(), references=refs)
    ((whole, main),) = refs[0].windows
    assert main is None
    assert_same_triangles(alone.triangles, whole.triangles)
    # past it the reference is formed on windows spread over the log, each a log of its own,
    # and the fit's rows over each kept apart; the fit's own triangles are those of the pass
    # without the check
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", len(log.t) - 1)
    refs.clear()
    over = stream.stream_pieces(log, off_square, chunk=200, check=FitOptions(),
                                references=refs)
    (cut,) = refs
    plan = crosscheck.reference_windows([len(log.t)], len(log.t) - 1)[0]
    assert cut.spread and len(cut.windows) == len(plan) >= crosscheck.REFERENCE_WINDOWS - 1
    step = over[0].triangles.rows / over[0].triangles.samples
    for (window, main), (a, b) in zip(cut.windows, plan, strict=True):
        assert window.samples == b - a  # (the window, to the sample)
        assert main is not None
        assert abs(main.rows - step * window.triangles.samples) <= 0.1 * main.rows
        assert window.triangles.duration == pytest.approx((b - a - 1) * res[0].dt)
    assert sum(main.rows for _, main in cut.windows) < over[0].triangles.rows
    assert_same_triangles(res[0].triangles, over[0].triangles, rel=1e-9)


def test_wrapped_angles_tracker_pose_and_input_delay(off_square, runs_off_square):
    """Pivot angles wrapped to (−π, π], a tracker pose with wrapped heading, an input delay:
    unwrapping, the pose path and the delayed torques continue across chunks."""
    r = runs_off_square[3]
    wrap = lambda a: np.angle(np.exp(1j * a))  # noqa: E731
    pose = np.column_stack([r.q[:, :2], wrap(r.q[:, 2] * 4)])
    log = with_arrays(r.log, delta=wrap(D(r.log) + 3.0), pose=pose)
    model = PlatformModel(off_square)
    for delay in (0.0, 0.012):
        ref = triangles(model, preprocess(log, off_square, None, delay))
        res = stream.stream_log(log, off_square, input_delay=delay, chunk=97)
        assert_same_triangles(ref, res.triangles)


def test_gzip_csv_and_other_span(tmp_path, off_square, runs_off_square):
    """A .csv.gz log, a span in samples, shared friction."""
    log = runs_off_square[0].log
    p = tmp_path / "run.csv.gz"
    write_csv_log(log, p)
    with open(p, "rb") as f:
        assert f.read(2) == b"\x1f\x8b"
    opts = FitOptions(span=Span.parse("31"), friction="shared")
    ref = fit_logs([log], off_square, opts)
    fit = fit_files([p], off_square, opts, chunk=1000)
    assert_same_values(ref, fit)


def test_validate_source_equals_validate_log(off_square, truth, runs_off_square):
    log = jittered(off_square, runs_off_square[0], seed=5)
    ref = validate_log(log, off_square, truth)
    got = validate.validate_source(log, off_square, truth, chunk=97, keep_series=True)
    assert got.samples == ref.samples
    for key in ("x", "y", "theta", "translation", "rotation"):
        assert got.rms[key] == pytest.approx(ref.rms[key], rel=1e-9)
    for key in ("F_bx", "F_by", "T_bz"):
        assert got.observer_rms[key] == pytest.approx(ref.observer_rms[key], rel=1e-9)
        assert got.observer_max[key] == pytest.approx(ref.observer_max[key], rel=1e-9)
    assert got.share_above == ref.share_above
    np.testing.assert_array_equal(got.t, ref.t)
    np.testing.assert_allclose(got.f_hat, ref.f_hat, rtol=0,
                               atol=1e-9 * np.abs(ref.f_hat).max())
    lean = validate.validate_source(log, off_square, truth, chunk=1000)
    assert lean.f_hat.shape == (0, 3) and lean.observer_rms == pytest.approx(got.observer_rms)


def test_too_short_log_has_the_in_memory_message(off_square, runs_off_square):
    log = runs_off_square[0].log.slice(0, 50)
    with pytest.raises(InputError) as one:
        preprocess(log, off_square)
    with pytest.raises(InputError) as two:
        stream.stream_log(log, off_square, chunk=7)
    assert str(one.value) == str(two.value)


# ---------------------------------------------------------------------------------------------
# the chunked CSV reader


@pytest.fixture(scope="module")
def small_csv(tmp_path_factory, off_square, runs_off_square):
    """The first 300 rows of a run as CSV lines (header first)."""
    d = tmp_path_factory.mktemp("csvchunks")
    p = d / "small.csv"
    write_csv_log(runs_off_square[0].log.slice(0, 300), p)
    return p.read_text().splitlines()


def same_error(path, platform, chunk):
    with pytest.raises(InputError) as whole:
        read_csv_log(path, platform)
    with pytest.raises(InputError) as chunked:
        list(iter_csv_log(path, platform, chunk))
    assert str(chunked.value) == str(whole.value)
    return str(whole.value)


def test_chunks_are_the_whole_log(tmp_path, off_square, small_csv):
    p = tmp_path / "ok.csv"
    lines = small_csv[:100] + ["", "   ", ""] + small_csv[100:]  # blank-looking lines
    p.write_text("\n".join(lines) + "\n")
    whole = read_csv_log(p, off_square)
    for chunk in (1, 7, 97, 1000):
        parts = list(iter_csv_log(p, off_square, chunk))
        assert all(x.n_samples == chunk for x in parts[:-1])
        for name in ("t", "angles", "currents"):
            np.testing.assert_array_equal(
                np.concatenate([getattr(x, name) for x in parts]), getattr(whole, name))


@pytest.mark.parametrize("case", ["nan", "text", "time", "time-at-seam", "short", "truncated",
                                  "long", "few"])
def test_chunked_errors_name_the_same_line(tmp_path, off_square, small_csv, case):
    lines = list(small_csv)
    if case == "nan":
        f = lines[250].split(",")
        f[3] = "nan"
        lines[250] = ",".join(f)
    elif case == "text":
        f = lines[180].split(",")
        f[7] = "1.2.3"
        lines[180] = ",".join(f)
    elif case in ("time", "time-at-seam"):
        row = 150 if case == "time" else 98  # data row 97 = first row of the second chunk
        f = lines[row].split(",")
        f[0] = lines[row - 1].split(",")[0]
        lines[row] = ",".join(f)
    elif case == "short":
        lines[120] = ",".join(lines[120].split(",")[:-2])
    elif case == "truncated":
        lines[-1] = ",".join(lines[-1].split(",")[:5])
    elif case == "long":
        lines[200] += ",1"
    elif case == "few":
        lines = lines[:3]
    p = tmp_path / f"{case}.csv"
    p.write_text("\n".join(lines) + "\n")
    msg = same_error(p, off_square, 97)
    assert "\n" not in msg
    if case not in ("few", "truncated"):
        assert "line" in msg


def test_unknown_format_and_missing_file(tmp_path, off_square):
    with pytest.raises(InputError, match="unknown log format '.txt'"):
        fit_files([tmp_path / "a.txt"], off_square)
    with pytest.raises(InputError, match="no such log file"):
        fit_files([tmp_path / "missing.csv"], off_square)


def test_chunk_of_in_memory_log_keeps_notes(off_square, runs_off_square):
    log = runs_off_square[0].log
    noted = make_log(log.t, log.units, D(log), P(log), C(log), None, "noted", ["a note"])
    res = stream.stream_log(noted, off_square, chunk=500)
    assert res.notes == ["a note"]


@pytest.mark.parametrize("kind", ["mcap", "smartwheel-csv"])
def test_other_formats_are_read_whole_and_reduced_in_chunks(tmp_path, off_square,
                                                            runs_off_square, kind):
    """MCAP (no chunked reader yet) and the robot's smart-wheel CSV are read whole by their
    readers, then reduced in chunks: the same fit as the in-memory path."""
    from ropod_sysid.io import read_log

    log = runs_off_square[1].log
    if kind == "mcap":
        from ropod_sysid.io.mcapwrite import write_mcap_log

        p = tmp_path / "run.mcap"
        write_mcap_log(log, p)
    else:
        smartwheel = pytest.importorskip("ropod_sysid.io.smartwheel")
        p = tmp_path / "run.csv"
        smartwheel.write_smartwheel(log, p, off_square)
    ref = fit_logs([read_log(p, off_square)], off_square)
    fit = fit_files([p], off_square, chunk=300)
    assert_same_values(ref, fit)


def test_grid_step_averages_out_jitter_and_keeps_gaps():
    """The sample time is the slope of the head's times, not its median step: ±1 ms of
    jitter at 100 Hz leaves 2e-6 of the step, dropped samples keep their place."""
    rng = np.random.default_rng(11)
    t = np.arange(6001) * 0.01 + rng.uniform(-1e-3, 1e-3, 6001)
    t = np.delete(t, [50, 51, 52, 3000])
    assert abs(timebase.grid_step(t) - 0.01) < 2e-8
    assert abs(float(np.median(np.diff(t))) - 0.01) > 1e-7  # what the median step gives
    assert timebase.grid_step(np.arange(500) * 0.005) == pytest.approx(0.005, rel=1e-14)


class _Collect:
    """A grid sink that keeps what it is given."""

    def __init__(self) -> None:
        self.parts: list[grid._Samples] = []

    def start(self, dt: float, jitter: float = 0.0) -> None:
        self.dt = dt

    def push(self, samples: grid._Samples) -> None:
        self.parts.append(samples)


@pytest.mark.parametrize("sizes", [[1], [2, 1, 1, 3], [1, 1, 1, 1, 5]])
def test_grid_pieces_of_one_sample(runs_off_square, sizes, monkeypatch):
    """Pieces of one or two samples after the head (a log's last line, a short chunk): every
    sample passes on once, the pivot angles unwrapped as one np.unwrap of the whole log (jumps
    inside, between and next to the short pieces), and a step off the grid in a one-sample
    piece is found."""
    log = runs_off_square[0].log
    wrapped = log.layout.wrapped
    angles = log.angles.copy()
    angles[:, wrapped] = np.angle(np.exp(1j * (angles[:, wrapped] * 40.0 + 3.0)))  # many jumps
    log = dataclasses.replace(log, angles=angles)
    monkeypatch.setattr(grid, "GRID_STEPS", 200)  # the grid starts after 200 steps
    head = 250
    cuts = np.cumsum([head, *sizes])
    pieces = [log.slice(a, b) for a, b in zip([0, *cuts[:-1]], cuts, strict=True)]
    pieces.append(log.slice(int(cuts[-1]), log.n_samples))
    sink = _Collect()
    g = grid._Grid("run.csv", False, sink)
    for p in pieces:
        g.push(p)
    g.finish()
    out = grid._Samples.join(sink.parts)
    np.testing.assert_array_equal(out.t, log.t)
    want = np.unwrap(angles[:, wrapped], axis=0)
    np.testing.assert_array_equal(out.angles[:, wrapped], want)
    assert g.max_step == np.diff(log.t).max() and g.min_step == np.diff(log.t).min()

    t = log.t.copy()
    t[cuts[-2]:] += 0.3 * np.diff(log.t[:2])  # the step into the last short piece is off
    late = dataclasses.replace(log, t=t)
    g = grid._Grid("run.csv", False, _Collect())
    for a, b in zip([0, *cuts[:-2]], cuts[:-1], strict=True):
        g.push(late.slice(a, b))
    with pytest.raises(grid._OffGrid):
        g.push(late.slice(int(cuts[-2]), int(cuts[-1])))


def test_unwrap_angles_continued_over_pieces():
    """unwrap_angles over pieces, each continued from the correction the one before ended with,
    is one np.unwrap of the whole signal, whether a piece has jumps (the cumulative sum), none
    with a correction carried in (the correction added), or none from zero (the angles
    themselves); the corrections are the unwrap's minus the signal."""
    from ropod_sysid.odometry import unwrap_angles

    rng = np.random.default_rng(3)
    n = 400
    wrapped = np.array([True, False, False, True])
    x = np.cumsum(rng.normal(0.0, 0.02, (n, 4)), axis=0)
    x[:, 3] += 0.1 * np.maximum(np.arange(n) - 250, 0)  # crosses ±π at samples 281 and 344
    angles = x.copy()
    angles[:, wrapped] = np.angle(np.exp(1j * x[:, wrapped]))
    want = angles.copy()
    want[:, wrapped] = np.unwrap(angles[:, wrapped], axis=0)
    cuts = [0, 40, 80, 240, 285, 330, n]
    outs, corrs, corr0, kinds = [], [], None, set()
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        lo = max(a - 1, 0)  # each piece repeats the sample before it, as odometry's pieces do
        out, corr = unwrap_angles(wrapped, angles[lo:b], None if a == 0 else corr0)
        kinds.add((np.shares_memory(out, angles), bool(corr.any())))
        outs.append(out[a - lo:])
        corrs.append(corr[a - lo:])
        corr0 = corr[-1]
    np.testing.assert_array_equal(np.concatenate(outs), want)
    np.testing.assert_array_equal(np.concatenate(corrs), want - angles)
    # the angles themselves (no correction), and new ones with a correction (carried or new)
    assert kinds == {(True, False), (False, True)}
