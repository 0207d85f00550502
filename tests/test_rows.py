"""The row grid: equation rows every few samples of a fast log, filtered alike on both sides."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid import signals, stream
from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.odometry import constraint_system, normal_equations, solve_symmetric3
from ropod_sysid.params import parameter_names
from ropod_sysid.regressor import (
    RowGrid,
    Span,
    filtered_system,
    preprocess,
    raw_system,
    row_average,
    row_inputs,
    triangles,
)
from tests.swivel_arrays import angles_of


@pytest.mark.parametrize(("k", "step", "span"), [(101, 10, 11), (21, 2, 11), (11, 1, 11),
                                                   (9, 1, 9), (201, 20, 11), (501, 50, 11)])
def test_default_grid_has_about_ten_rows_per_span(k, step, span):
    grid = RowGrid.for_span(k)
    assert (grid.step, grid.span) == (step, span)
    assert grid.span * grid.step == pytest.approx(k, rel=0.15)


def test_step_one_is_the_sample_by_sample_system():
    grid = RowGrid.for_span(101, 1)
    assert (grid.step, grid.span, grid.halo, grid.trim(101)) == (1, 101, 50, 101)
    assert RowGrid.for_span(101, 7) == RowGrid(7, 15)


@pytest.mark.parametrize("bad", [0, -3, 2.5])
def test_bad_row_step_is_one_line_error(bad):
    with pytest.raises(InputError) as e:
        RowGrid.for_span(21, bad)
    assert str(e.value) == (f"--row-step {bad!r}: give a positive whole number of samples "
                            "(1 = every sample) or leave it out for about ten rows per span")


def test_step_one_equals_loess_of_the_raw_system(off_square, runs_off_square):
    """Row step 1: LOESS (k) of the sample-by-sample A_ID,ext and b_ID, ends trimmed."""
    model = PlatformModel(off_square)
    pre = preprocess(runs_off_square[0].log, off_square, row_step=1)
    a, b = filtered_system(model, pre)
    a_raw, b_raw = raw_system(model, pre)
    k, n = pre.span_samples, len(pre.t)
    assert pre.trim == k and a.shape[0] == n - 2 * k
    kept = slice(k, n - k)
    np.testing.assert_allclose(a, signals.loess(a_raw, k)[kept], rtol=0,
                               atol=1e-12 * np.abs(a).max())
    np.testing.assert_allclose(b, signals.loess(b_raw, k)[kept], rtol=0,
                               atol=1e-12 * np.abs(b).max())


def test_rows_are_states_at_the_row_samples_with_averaged_torques(off_square, runs_off_square):
    pre = preprocess(runs_off_square[0].log, off_square, row_step=4)
    idx = pre.row_samples()
    assert idx[0] == pre.trim and np.all(np.diff(idx) == 4)
    assert idx[-1] < len(pre.t) - pre.trim <= idx[-1] + 4
    rows = row_inputs(pre, idx)
    np.testing.assert_array_equal(rows.qdd, pre.qdd[idx])
    np.testing.assert_array_equal(rows.angles, pre.angles[idx])
    j = 17
    np.testing.assert_allclose(rows.tau[j], pre.tau[idx[j] - 2: idx[j] + 3].mean(axis=0),
                               rtol=1e-14)


def test_row_average_is_the_weighted_window_of_each_row():
    """Evenly spaced rows (strided views) and any rows (gathers) give Σ_j w_j x[i − h + j],
    also on the delay bracket's (N, A, n) torques."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(400, 8, 5))
    w = rng.normal(size=9)  # h = 4
    even = 7 + 6 * np.arange(60)
    odd = np.array([4, 5, 30, 31, 200, 395])
    for index in (even, odd, even[:1]):
        windows = np.stack([x[i - 4: i + 5] for i in index])  # (rows, 9, 8, 5)
        want = np.einsum("j,rjab->rab", w, windows)
        np.testing.assert_allclose(row_average(x, index, w), want, rtol=1e-13, atol=1e-14)
    assert row_average(x, even, w).shape == (60, 8, 5)


@pytest.mark.parametrize(("span", "step", "moved"), [("0.1s", 2, 0.01), ("0.2s", 4, 0.025)])
def test_row_grid_keeps_the_identification(off_square, truth, runs_off_square, span, step,
                                           moved):
    """Eleven rows per span of the noise-free 200 Hz runs. Against the every-sample fit:
    measured 0.3 % (0.1 s, every 2nd sample) and 2.1 % (0.2 s, every 4th) at most, on the
    weakly determined hub parameters; m_b and J_zz,b within 0.6 %. Against the truth: 5 %."""
    logs = [r.log for r in runs_off_square]
    sp = Span.parse(span)
    every = fit_logs(logs, off_square, FitOptions(span=sp, row_step=1))
    fit = fit_logs(logs, off_square, FitOptions(span=sp, row_step=step))
    true = truth.vector(parameter_names(off_square, "per-wheel"))
    assert fit.solution.rank == every.solution.rank == 29
    change = np.abs(fit.solution.values / every.solution.values - 1)
    assert change.max() < moved and change[:2].max() < 0.006
    assert np.abs(fit.solution.values / true - 1).max() < 0.05
    n_rows = sum(lf.triangles.rows for lf in fit.logs)
    assert n_rows == pytest.approx(sum(lf.triangles.rows for lf in every.logs) / step, rel=0.02)
    # the covered samples do not depend on the step
    assert fit.samples == pytest.approx(every.samples, rel=0.01)


@pytest.mark.parametrize(("step", "chunk"), [(3, 97), (7, 1000), (1, 250)])
def test_stream_equals_in_memory_on_any_grid(off_square, runs_off_square, step, chunk):
    model = PlatformModel(off_square)
    log = runs_off_square[2].log
    ref = triangles(model, preprocess(log, off_square, row_step=step))
    res = stream.stream_log(log, off_square, chunk=chunk, row_step=step)
    assert res.triangles.rows == ref.rows and res.triangles.samples == ref.samples
    ga = np.einsum("dij,dik->djk", ref.r, ref.r)
    gb = np.einsum("dij,dik->djk", res.triangles.r, res.triangles.r)
    assert np.abs(ga - gb).max() <= 1e-12 * np.abs(ga).max()


def test_normal_equations_equal_those_of_the_constraint_rows(off_square):
    rng = np.random.default_rng(4)
    delta = rng.uniform(-np.pi, np.pi, (500, 4))
    delta_rate = rng.normal(size=(500, 4))
    phi_rate = rng.normal(size=(500, 4, 2))
    model = PlatformModel(off_square)
    angles = angles_of(delta)
    rates = np.concatenate([delta_rate[..., None], phi_rate], axis=-1).reshape(500, 12)
    a, b = constraint_system(model, angles, rates)
    ata, atb = normal_equations(model, angles, rates)
    np.testing.assert_allclose(ata, np.einsum("nki,nkj->nij", a, a), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(atb, np.einsum("nki,nk->ni", a, b), rtol=1e-13, atol=1e-13)
    x = solve_symmetric3(ata, atb)
    ref = np.linalg.lstsq(a[7], b[7], rcond=None)[0]
    np.testing.assert_allclose(x[7], ref, rtol=1e-12)


def test_cli_row_step(tmp_path, off_square, runs_off_square):
    from ropod_sysid.platform import save_platform

    save_platform(off_square, tmp_path / "platform.yaml")
    logs = []
    for k, r in enumerate(runs_off_square):
        logs.append(str(tmp_path / f"run{k}.csv"))
        write_csv_log(r.log, logs[-1])
    out = tmp_path / "p.json"
    common = [*logs, "--platform", str(tmp_path / "platform.yaml"), "--out", str(out), "--quiet"]
    r = CliRunner().invoke(main, ["fit", *common, "--row-step", "4"])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert data["row_step"] == 4
    rows = [lg["rows"] for lg in data["logs"]]
    # a row every 4th sample, less those at rest (the runs start and stop standing still)
    assert all(0.9 * lg["samples"] < 4 * lg["rows"] < lg["samples"] + 4 for lg in data["logs"])
    assert data["samples"] == sum(lg["samples"] for lg in data["logs"]) > 4 * sum(rows) - 16
    bad = CliRunner().invoke(main, ["fit", *common, "--row-step", "two"])
    assert bad.exit_code == 2
    assert bad.output.strip() == ("error: --row-step 'two': use auto or a positive whole number "
                                  "of samples (1 = every sample)")
    # validate takes the fit's row step from the file, and says so when it is bad
    v = CliRunner().invoke(main, ["validate", logs[0], "--platform",
                                  str(tmp_path / "platform.yaml"), "--params", str(out),
                                  "--json", "--quiet"])
    assert v.exit_code == 0, v.output
    assert json.loads(v.output)["logs"][0]["samples"] == data["logs"][0]["samples"]
    data["row_step"] = "x"
    out.write_text(json.dumps(data))
    v = CliRunner().invoke(main, ["validate", logs[0], "--platform",
                                  str(tmp_path / "platform.yaml"), "--params", str(out)])
    assert v.exit_code == 2
    assert v.output.strip() == (f"error: {out}: key 'row_step' must be 'auto' or a positive "
                                "whole number of samples, got 'x'")


def test_std_accounts_for_the_rows_loess():
    """Noise white before the rows' LOESS is correlated after it: over 300 noise draws the
    spread of the estimates matches the std reported with RowGrid.correlation (3.5 for a
    window of 11 rows, i.e. 1.9× the std that assumes independent rows)."""
    from ropod_sysid.solve import qr_triangle, solve

    rng = np.random.default_rng(5)
    n, kr = 3000, 11
    t = np.linspace(0.0, 30.0, n)
    a = np.column_stack([np.sin(t), np.cos(0.7 * t), np.ones(n)])
    m = np.array([1.0, 2.0, 3.0])
    c = RowGrid(1, kr).correlation
    assert c == pytest.approx(3.52, abs=0.01)
    a_f = signals.loess(a, kr)[kr:-kr]
    est, std = [], []
    for _ in range(300):
        b_f = signals.loess(a @ m + rng.normal(0.0, 0.1, n), kr)[kr:-kr]
        sol = solve(qr_triangle(a_f, b_f), len(b_f), ["a", "b", "c"], correlation=c)
        est.append(sol.values)
        std.append(sol.std)
    ratio = np.std(est, axis=0) / np.mean(std, axis=0)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
