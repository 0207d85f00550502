"""What the report draws, gathered while a log streams: bounded, chunk-invariant, exact."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.errors import InputError
from ropod_sysid.fit import fit_files
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.plotdata import Envelope, RowSample
from ropod_sysid.regressor import preprocess, system
from ropod_sysid.report import render_fit_report
from ropod_sysid.stream import stream_log


def signals(n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    x = np.arange(n) * 0.01
    y = np.column_stack([np.sin(x), rng.normal(size=n), np.cumsum(rng.normal(size=n))])
    y[n // 3, 1] = 50.0  # one spike in a long log
    y[n // 2, 2] = np.nan
    return x, y


@pytest.mark.parametrize("chunk", [3, 7, 1000, 50_000])  # (3: tiny chunks, in 1 s)
def test_envelope_is_the_bucket_extremes_whatever_the_chunks(chunk):
    n, buckets = 20_011, 64
    x, y = signals(n)
    env = Envelope(buckets)
    for s in range(0, n, chunk):
        env.push(x[s:s + chunk], y[s:s + chunk])
    assert env.size == 512  # the smallest power of two giving at most 64 buckets
    xs, ys = env.lines(3)
    assert xs.shape == ys.shape == (2 * 40, 3)  # ceil(20011 / 512) = 40 buckets, min and max
    for j in range(3):
        v = y[:, j]
        for g in range(40):
            part = v[g * 512:(g + 1) * 512]
            pair = ys[2 * g: 2 * g + 2, j]
            assert set(pair) == {np.nanmin(part), np.nanmax(part)}
        assert np.all(np.diff(xs[:, j]) >= 0)  # in the order of the samples
        # each point's x is its sample's
        np.testing.assert_array_equal(np.interp(xs[:, j], x, v), ys[:, j])
    assert 50.0 in ys[:, 1]


def test_envelope_keeps_every_sample_of_a_short_signal():
    x, y = signals(100)
    env = Envelope(128)
    env.push(x[:60], y[:60])
    env.push(x[60:], y[60:])
    xs, ys = env.lines(3)
    np.testing.assert_array_equal(xs[:, 0], x)
    np.testing.assert_array_equal(ys, y)


def test_row_sample_halves_to_stay_bounded():
    n, cap = 10_000, 1000
    rows = RowSample(cap)
    t = np.arange(n, dtype=float)
    a = np.arange(n * 6, dtype=float).reshape(n, 3, 2)
    for s in range(0, n, 333):
        rows.push(t[s:s + 333], a[s:s + 333], t[s:s + 333, None] * np.ones(3), a[s:s + 333, :, 0])
    assert rows.stride == 16  # 10000 / 8 rows would exceed 1000
    tk, ak, bk, qk = rows.arrays()
    np.testing.assert_array_equal(tk, t[::16])
    np.testing.assert_array_equal(ak, a[::16])
    np.testing.assert_array_equal(bk[:, 2], t[::16])
    assert len(tk) <= cap


def test_stream_gathers_the_rows_and_samples_of_the_in_memory_path(off_square,
                                                                    runs_off_square):
    log = runs_off_square[0].log
    res = stream_log(log, off_square, chunk=400, plot=True)
    plot = res.plot
    pre = preprocess(log, off_square)
    b = np.concatenate([blk for _, _, blk in system(PlatformModel(off_square), pre)])
    kept = pre.row_samples()
    assert plot.row_stride == 1 and len(plot.t_rows) == len(kept)
    # the triangles count the rows that carry an equation: not those at rest (zero rows)
    assert res.triangles.equations == np.count_nonzero(np.abs(b).sum(axis=1)) < len(kept)
    np.testing.assert_allclose(plot.t_rows, pre.t[kept], rtol=0, atol=1e-12)
    np.testing.assert_allclose(plot.b_rows, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    np.testing.assert_allclose(plot.qd_rows, pre.qd[kept], rtol=1e-9, atol=1e-9)
    assert plot.samples == log.n_samples and plot.duration == pytest.approx(log.duration)
    assert not plot.has_pose and plot.dt == pytest.approx(0.005)
    # every logged sample's torque passes the envelope: its extremes are the log's
    tau = off_square.torque_constants() * log.currents
    np.testing.assert_allclose(np.nanmax(plot.torque[1], axis=0), tau.max(axis=0))
    np.testing.assert_allclose(np.nanmin(plot.torque[1], axis=0), tau.min(axis=0))
    np.testing.assert_allclose(plot.start[:2], pre.q[0, :2], atol=1e-12)


def test_fit_files_keeps_bounded_plot_data_and_the_report_needs_no_logs(
        tmp_path, off_square, runs_off_square, monkeypatch):
    import ropod_sysid.stream as stream_module

    paths = []
    for k, r in enumerate(runs_off_square[:2]):
        paths.append(tmp_path / f"run{k}.csv")
        write_csv_log(r.log, paths[-1])
    result = fit_files(paths, off_square, plots=True)
    plain = fit_files(paths, off_square)
    assert all(lf.plot is not None for lf in result.logs)
    assert all(lf.plot is None for lf in plain.logs)
    np.testing.assert_array_equal(result.solution.values, plain.solution.values)

    def no_second_pass(*_args, **_kwargs):
        raise AssertionError("the report read a log again")

    monkeypatch.setattr(stream_module, "stream_log", no_second_pass)
    monkeypatch.setattr("ropod_sysid.report.html.stream_log", no_second_pass)
    html = render_fit_report(result)
    assert html.count("data:image/png;base64,") == 2 * 2 + 5  # + autocorrelation, prediction
    with pytest.raises(InputError, match="kept no plot data; give the fit's logs"):
        render_fit_report(plain)
