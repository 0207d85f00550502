"""The sensor model of ``trajectory check`` and ``optimize --objective sigma``
(ropod_sysid.noise), checked against fits of simulated logs: the σ it predicts is
the fit's white-noise σ, and the bias it predicts from the encoders is the fit's error."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.errors import InputError
from ropod_sysid.fit import fit_logs
from ropod_sysid.noise import SensorNoise, row_kernel
from ropod_sysid.simulate import Sensors, record, simulate
from ropod_sysid.trajectory import check, optimize, typical
from ropod_sysid.trajectory.run_variants import variants


@pytest.fixture(scope="module")
def planned_37(off_square, truth):
    """A 37 s typical run of the off-square ropod and its four variants simulated at 100 Hz."""
    traj = typical(37.0, platform=off_square)
    runs = simulate(off_square, truth, [v.to_setpoints() for v in variants(traj).values()],
                    rate=100.0)
    return traj, runs


def fitted(platform, runs, sensors: Sensors, seed: int = 0):
    """The fit of the runs recorded with ``sensors``; the encoders' zero at a random place
    within a count for each seed (else quantisation would be the same on every seed)."""
    import dataclasses

    rng = np.random.default_rng(seed)
    counts = sensors.encoder_counts
    logs = []
    for k, r in enumerate(runs):
        log = record(platform, r, r.log.t, dataclasses.replace(sensors, encoder_counts=None),
                     rng, f"run{k}")
        if counts:
            q = 2 * np.pi / counts
            offset = rng.uniform(0.0, q, log.angles.shape[1])
            log = dataclasses.replace(log, angles=np.round((log.angles + offset) / q) * q
                                      - offset)
        logs.append(log)
    return fit_logs(logs, platform).solution


def test_the_sensor_model_checks_its_values():
    with pytest.raises(InputError, match=r"^--current-noise -1: give σ in A, ≥ 0$"):
        SensorNoise(-1.0)
    with pytest.raises(InputError, match="--encoder-counts 8: give a whole number of counts"):
        SensorNoise(encoder_counts=8)
    with pytest.raises(InputError, match="no sensor noise"):
        SensorNoise(0.0, None)
    sn = SensorNoise(log_rate=1000.0)
    assert (sn.k, sn.grid.step, sn.rows_per_second) == (101, 10, 100.0)


def test_a_row_kernel_spreads_the_rows_loess_over_the_step():
    from ropod_sysid import signals
    from ropod_sysid.regressor import RowGrid

    grid = RowGrid(step=3, span=5)
    g = row_kernel(grid, np.array([1.0]))
    np.testing.assert_allclose(g[::3], signals.loess_kernel(5))
    assert np.count_nonzero(g) == np.count_nonzero(signals.loess_kernel(5))
    np.testing.assert_allclose(row_kernel(RowGrid(1, 3), np.array([0.5, 0.5])), [0.5, 0.5])


@pytest.mark.parametrize(("current", "counts", "tol"), [(0.03, None, 0.05), (0.0, 2**14, 0.25),
                                                       (0.03, 2**14, 0.25)])
def test_the_predicted_sigma_is_the_fits_white_noise_sigma(off_square, truth, planned_37,
                                                           current, counts, tol):
    """Current noise alone: within 5 % (measured: 0.5–1 %); with encoder quantisation within
    25 % (measured: the prediction 10–22 % high). Every parameter: the σ share one σ̂."""
    traj, runs = planned_37
    rep = check(traj, off_square, sensors=SensorNoise(current, counts, 100.0))
    sol = fitted(off_square, runs, Sensors(encoder_counts=counts, current_noise=current))
    assert rep.names == sol.names
    ratio = sol.std_white / rep.std
    assert np.all(np.abs(ratio - 1.0) < tol), dict(zip(sol.names, np.round(ratio, 3),
                                                               strict=True))
    assert np.sqrt(sol.sigma2) == pytest.approx(rep.sigma_hat, rel=tol)


def test_the_predicted_encoder_bias_is_the_fits_error(off_square, truth, planned_37):
    """Quantised wheel and pivot angles, no current noise, eight encoder zeros: on the 37 s
    typical run the fits' mean errors of the masses and inertias are the predicted
    errors-in-variables bias (same sign, within 40 %; measured 5–40 %) where it stands out of
    the seeds' scatter. (Not on every run: on the 30 s typical run the prediction for m_b is
    −1.8 kg and the fits' mean +0.7 ± 0.3 kg, a difference not understood; docs/method.md.)"""
    traj, runs = planned_37
    rep = check(traj, off_square, sensors=SensorNoise(0.0, 2**14, 100.0))
    errs = []
    for seed in range(8):
        sol = fitted(off_square, runs, Sensors(encoder_counts=2**14), seed)
        errs.append(sol.values - truth.vector(sol.names))
    errs = np.array(errs)
    mean, se = errs.mean(axis=0), errs.std(axis=0, ddof=1) / np.sqrt(len(errs))
    shown = 0
    for name in ("m_b", "Jzz_b", "m_wh", "Jzz_wh", "Jrot_w"):
        j = sol.names.index(name)
        if abs(rep.bias[j]) > 3 * se[j]:
            shown += 1
            assert mean[j] == pytest.approx(rep.bias[j], rel=0.4), name
    assert shown >= 3


def test_optimize_for_sigma_beats_the_typical_run(off_square):
    typ = check(typical(8.0, platform=off_square), off_square, sensors=SensorNoise())
    opt = optimize(off_square, duration=8.0, harmonics=3, maxiter=2, seed=0, processes=2)
    assert opt.objective == "sigma" and set(opt.targets) == {"m_b", "Jzz_b", "m_wh", "Jzz_wh",
                                                            "Jrot_w"}
    rep = check(opt.trajectory, off_square, sensors=SensorNoise())
    assert rep.ok, [f.text() for f in rep.findings]
    idx = [rep.names.index(n) for n in opt.targets]
    assert np.all(rep.relative_std[idx] * 1.5 < typ.relative_std[idx])
    np.testing.assert_allclose([opt.targets[n] for n in opt.targets], rep.relative_std[idx])
    with pytest.raises(InputError, match="--target m_x: not a parameter"):
        optimize(off_square, duration=10.0, maxiter=1, target=["m_x"])


def test_check_and_optimize_take_the_sensor_model_on_the_command_line(tmp_path, off_square):
    from click.testing import CliRunner

    from ropod_sysid.cli.main import main
    from ropod_sysid.platform import save_platform

    path = tmp_path / "p.yaml"
    save_platform(off_square, path)
    runner = CliRunner()
    out = tmp_path / "opt"
    res = runner.invoke(main, ["trajectory", "optimize", "--platform", str(path), "--duration",
                               "6", "--harmonics", "2", "--maxiter", "2", "--out", str(out),
                               "--target", "m_b,Jzz_b", "--current-noise", "0.05"])
    assert res.exit_code == 0, res.output
    assert "predicted for 0.05 A current noise, 16384-count encoders" in res.output
    assert "m_b σ " in res.output and "Jzz_b σ " in res.output
    res = runner.invoke(main, ["trajectory", "check", str(out / "original.csv"), "--platform",
                               str(path), "--encoder-counts", "4096", "--log-rate", "200"])
    assert res.exit_code == 0, res.output
    assert ("predicted standard deviation of the fit (its white-noise σ) for 0.03 A current "
            "noise, 4096-count encoders, 200 Hz logs") in res.output
    assert "rel. bias" in res.output
    assert "the recipe check (fit's default on logs of up to 1,000,000 samples)" in res.output
    res = runner.invoke(main, ["trajectory", "check", str(out / "original.csv"), "--platform",
                               str(path), "--exact-encoders", "--encoder-counts", "4096"])
    assert res.exit_code == 2
    assert res.output.strip() == ("error: --exact-encoders and --encoder-counts: give one of "
                                  "them")
    res = runner.invoke(main, ["trajectory", "check", str(out / "original.csv"), "--platform",
                               str(path), "--encoder-counts", "4096", "--no-recipe-check"])
    assert res.exit_code == 0, res.output
    assert "rel. bias" in res.output and "recipe check" not in res.output
    res = runner.invoke(main, ["trajectory", "check", str(out / "original.csv"), "--platform",
                               str(path)])
    assert "white noise σ_b = 1 N" in res.output  # no sensor model: as before
    assert "recipe check" not in res.output  # (a σ of white noise on b_ID: no shift added)


def test_fit_corrects_the_encoders_bias_on_the_shipped_sample():
    """The shipped sample (2¹⁴-count encoders): a plain fit has J_zz,wh + 1.125 J_rot,w 14 %
    low at 12σ (the predicted errors-in-variables bias); ``--encoder-counts 16384`` subtracts
    E[δAᵀδA] from the normal equations and every identifiable combination of the inertial
    parameters comes within 0.5 %, every value within 2σ of the truth."""
    import glob
    import json
    from pathlib import Path

    from ropod_sysid.fit import FitOptions, fit_files
    from ropod_sysid.platform import load_platform
    from ropod_sysid.summary import compared_values

    sample = Path(__file__).resolve().parents[1] / "datasets" / "ropod"
    platform = load_platform(sample / "platform.yaml")
    truth = json.loads((sample / "truth.json").read_text())
    res = fit_files(sorted(glob.glob(str(sample / "*.csv.gz"))), platform,
                    FitOptions(encoder_counts=2**14))
    sol = res.solution
    other = compared_values(sol, truth)
    z = []
    for j, name in enumerate(sol.names):
        if name in other and np.isfinite(sol.std[j]):
            z.append((sol.values[j] - other[name]) / sol.std[j])
            if name in ("m_b", "Jzz_b", "m_wh", "Jzz_wh"):
                assert abs(sol.values[j] / other[name] - 1) < 0.005, name
    assert np.all(np.abs(z) < 2), np.round(z, 2)
    assert res.parameter_file().extras["encoder_counts"] == 2**14
    with pytest.raises(InputError, match="--encoder-counts 8: give the encoders' counts"):
        FitOptions(encoder_counts=8)


def test_the_encoder_correction_streams_like_in_memory(off_square, runs_off_square_noisy,
                                                      tmp_path):
    """``fit_files`` (streamed in chunks) and ``fit_logs`` (whole logs) form the same error
    gram (to 1e-8), and the corrected values agree to 1e-5 (measured 3e-6: AᵀA − E is worse
    conditioned than AᵀA, which amplifies rounding; uncorrected they agree to 1e-12)."""
    from ropod_sysid.fit import FitOptions, fit_files
    from ropod_sysid.io import write_log

    logs = list(runs_off_square_noisy[:2])
    paths = []
    for k, log in enumerate(logs):
        paths.append(tmp_path / f"run{k}.csv")
        write_log(log, paths[-1])
    opts = FitOptions(encoder_counts=2**14)
    streamed = fit_files(paths, off_square, opts, chunk=1500)
    whole = fit_logs(logs, off_square, opts)
    np.testing.assert_allclose(streamed.solution.values, whole.solution.values, rtol=1e-5)
    e_s = sum(lf.triangles.error_gram for lf in streamed.logs)
    e_w = sum(lf.triangles.error_gram for lf in whole.logs)
    np.testing.assert_allclose(e_s, e_w, rtol=1e-8, atol=1e-12 * np.abs(e_w).max())
    plain = fit_logs(logs, off_square)
    assert not np.allclose(plain.solution.values, whole.solution.values, rtol=1e-3)


def test_the_fits_gram_thins_a_long_logs_later_rows(monkeypatch, tmp_path):
    """``fit --encoder-counts`` takes a log's gram rows past
    :data:`ropod_sysid.noise.FIT_GRAM_DENSE` (a minute of log) 4× sparser. Made to thin the
    shipped sample's first log (1,993 gram rows, dense as shipped) from its 300th gram row on:
    streamed in chunks its gram equals the whole log's (to 1e-8), and the corrected values move
    by under 0.2σ from the dense gram's (measured: 0.010σ here; 0.11σ on a 10-minute 1 kHz log)."""
    from ropod_sysid import noise
    from ropod_sysid.fit import FitOptions, fit_files
    from ropod_sysid.io import write_log
    from tests.conftest import shipped

    pf, _, logs = shipped("ropod")
    opts = FitOptions(encoder_counts=2**14)
    dense = fit_logs(logs[:1], pf, opts)
    monkeypatch.setattr(noise, "FIT_GRAM_DENSE", 300)
    thin = fit_logs(logs[:1], pf, opts)
    path = tmp_path / "run.csv"
    write_log(logs[0], path)
    streamed = fit_files([path], pf, opts, chunk=1000)
    e_s, e_w = streamed.logs[0].triangles.error_gram, thin.logs[0].triangles.error_gram
    np.testing.assert_allclose(e_s, e_w, rtol=1e-8, atol=1e-12 * np.abs(e_w).max())
    e_d = dense.logs[0].triangles.error_gram
    assert not np.allclose(e_w, e_d, rtol=1e-6)  # thinned
    sol, ref = thin.solution, dense.solution
    ok = np.isfinite(ref.std)
    shift = np.abs(sol.values - ref.values)[ok] / ref.std[ok]
    assert 0 < shift.max() < 0.2, shift.max()


def test_counts_note_names_the_quartic_where_the_span_allows(off_square, runs_off_square,
                                                              tmp_path):
    """A quantised 200 Hz log (21 samples in the 0.1 s span) fitted plain: the note asks for
    --encoder-counts and, at that rate, the quartic with the lag searched (in memory and
    streamed); with a 0.05 s span (11 samples), with the quartic, or with the counts given,
    not."""
    from ropod_sysid.fit import FitOptions, fit_files
    from ropod_sysid.io import write_log
    from ropod_sysid.regressor import Span
    from ropod_sysid.simulate import sensed

    log = sensed(runs_off_square[0].log, off_square, Sensors(encoder_counts=2**14),
                 np.random.default_rng(1))
    path = tmp_path / "q.csv"
    write_log(log, path)
    ask = ("give --encoder-counts 16384 to correct the fit for the encoders' quantisation (its "
           "errors in the accelerations shrink the values); at this rate with --smoother "
           "quartic --input-delay auto, which keep the LOESS's bias out of a long log's values")

    def notes(fit) -> str:
        return " | ".join(n for lf in fit.logs for n in lf.notes)

    assert ask in notes(fit_logs([log], off_square))
    assert ask in notes(fit_files([path], off_square, FitOptions(), chunk=500))
    for opts in (FitOptions(span=Span.parse("0.05s")),
                 FitOptions(span=Span.parse(None).with_smoother("quartic"))):
        text = notes(fit_logs([log], off_square, opts))
        assert "give --encoder-counts 16384" in text and "--smoother quartic" not in text
    assert "whole counts" not in notes(fit_logs([log], off_square,
                                                FitOptions(encoder_counts=2**14)))


def test_encoder_counts_are_detected_from_the_angles_steps_not_from_a_writers_rounding():
    """Angles that move by whole counts of 2π/16384 are recognised as 16384-count encoders
    (wrapped channels taken modulo 2π); exact angles, and exact angles a log writer rounded to
    7 decimals (2π/1e-7 ≈ 6.3e7 steps per turn, above MAX_DETECTED_COUNTS), are not."""
    from ropod_sysid.quantisation import MAX_DETECTED_COUNTS, detect_encoder_counts

    t = np.linspace(0.0, 10.0, 2001)[:, None]
    # a wheel, a wrapped angle, and one turning so slowly that rounding moves it by single steps
    exact = np.hstack([3.0 * np.sin(t) + 0.4 * t, np.angle(np.exp(2j * t)), 2e-6 * t])
    step = 2 * np.pi / 2**14
    wrapped = np.array([False, True, False])
    assert detect_encoder_counts(np.round(exact / step) * step, wrapped) == 2**14
    assert detect_encoder_counts(exact, wrapped) is None
    assert 2 * np.pi / 1e-7 > MAX_DETECTED_COUNTS
    assert detect_encoder_counts(np.round(exact, 7), wrapped) is None


@pytest.fixture(scope="module")
def steered_swivel_rows():
    """The first log of steered-swivel, exact and as 2¹⁴-count encoders read it (no current
    noise): platform, truth, model, the two logs, the quantised log preprocessed, and the
    filtered rows of both (A_exact, A_quantised)."""
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.regressor import filtered_system, preprocess
    from ropod_sysid.simulate import sensed
    from tests.conftest import shipped

    pf, truth, logs = shipped("steered-swivel")
    log = logs[0]
    quantised = sensed(log, pf, Sensors(encoder_counts=2**14, current_noise=0.0),
                       np.random.default_rng(0))
    model = PlatformModel(pf)
    a_e, _ = filtered_system(model, preprocess(log, pf))
    pre = preprocess(quantised, pf)
    a_q, _ = filtered_system(model, pre)
    return pf, truth, model, log, quantised, pre, a_e, a_q


def test_the_planned_runs_encoder_errors_are_the_fits_on_the_same_rows(steered_swivel_rows):
    """Issue 14 item 6: ``trajectory check`` carries the encoders' errors through the fit's
    own recipe. Given the row samples of the quantised steered-swivel log as its planned
    motion (with each channel's motion through the rows' windows, :func:`window_motion`, from
    which the fit takes each channel's share, :func:`tone_share`), the planned-run path (what
    :func:`stacked_regressor` calls) returns the error gram ``fit --encoder-counts`` subtracts
    (:func:`fit_error_gram`) to round-off (``trajectory check`` itself has no such windows and
    takes the :func:`sawtooth_share` of its rows' rates); and the rows' encoder variance it
    adds to σ̂², the variance of δA m, is the measured one of the filtered rows' (quantised −
    exact) A m on the base rows to 0.7–1.3 (measured 0.82, 0.75, 0.80 for x, y, θ; with the
    rates' sawtooth share 0.84, 0.77, 0.81; the old chain, q̈'s errors through the odometry
    gain alone: 1.14, 1.30, 0.27). The steering rows' variance it puts 4–8× low (measured
    0.12, 0.26; with the sawtooth share 0.12, 0.24; the old chain the same), not asserted: a
    cause not found, and a small share of σ̂² (those rows' variance is 30–60× smaller than
    the base rows')."""
    from ropod_sysid.noise import fit_error_gram
    from ropod_sysid.quantisation import window_motion
    from ropod_sysid.trajectory.identifiability import _regressor_rows

    pf, truth, model, _, _, pre, a_e, a_q = steered_swivel_rows
    rows = pre.row_samples()
    sensors = SensorNoise(0.0, 2**14, 1.0 / pre.dt, span=pre.span_samples * pre.dt,
                          row_step=pre.grid.step, degree=pre.degree)
    own = model.coordinate_channels
    qd = np.concatenate([pre.qd, pre.angle_rates[:, own]], axis=1)
    _, var, gram = _regressor_rows(model, pre.q[rows], qd[rows], pre.qdd[rows],
                                   pre.angles[rows], "per-wheel", noise=(truth, sensors),
                                   angle_rates=pre.angle_rates[rows],
                                   motion=window_motion(pre, rows))
    fit = fit_error_gram(model, pre, rows, 2**14, stride=1)  # (the fit: every third row)
    np.testing.assert_allclose(gram, fit, rtol=1e-10, atol=1e-12 * np.abs(fit).max())
    m = truth.vector(model.parameter_names())
    err = (a_q - a_e) @ m  # (N, D): the rows' error from the encoders (no current noise)
    ratio = var.mean(axis=0)[:3] / np.mean(err**2, axis=0)[:3]
    assert np.all((ratio > 0.7) & (ratio < 1.3)), ratio.round(3)


def test_the_encoders_error_gram_matches_the_measured_one_on_a_constrained_platform(
        steered_swivel_rows):
    """Issue 14: the error gram ``fit --encoder-counts`` subtracts, against the Gram matrix of
    the filtered rows' differences (2¹⁴-count quantised − exact) on the first log of
    steered-swivel (two steered wheels, two casters: its rows are projected onto the allowed
    motions, its steering rates reach q̈ through odometry, its steering angles move less
    than a count per sample). Measured on this log: predicted / empirical of the inertial
    columns' diagonals 0.81–1.05 per row kind (the gram of the raw measured state before
    issue 14: 0.59–10.9, J_zz,wh's 9.9–10.9). And the corrected fit of the quantised log (no
    current noise) brings J_zz,b nearer the exact log's fit than the plain one (measured on
    this one log, where J_zz,b is poorly determined: plain −129 %, corrected +0.0 %; before
    issue 14 the correction gave −131 %). About 3 s."""
    from ropod_sysid.fit import FitOptions
    from ropod_sysid.noise import fit_error_gram
    from ropod_sysid.solve import kind_rows

    pf, _, model, log, quantised, pre, a_e, a_q = steered_swivel_rows
    names = model.parameter_names()
    pred = fit_error_gram(model, pre, pre.row_samples(), 2**14)
    inertial = [j for j, n in enumerate(names) if n.startswith(("m_", "J"))]
    for d in range(3):
        x = kind_rows(a_q - a_e, d)
        emp = np.einsum("ij,ij->j", x, x)
        ratio = np.diag(pred[d])[inertial] / emp[inertial]
        assert np.all((ratio > 0.7) & (ratio < 1.3)), (d, dict(zip(
            [names[j] for j in inertial], ratio.round(2), strict=True)))
    ref = fit_logs([log], pf).solution
    plain = fit_logs([quantised], pf).solution
    corrected = fit_logs([quantised], pf, FitOptions(encoder_counts=2**14)).solution
    j = ref.names.index("Jzz_b")
    assert abs(corrected.values[j] - ref.values[j]) < 0.5 * abs(plain.values[j] - ref.values[j])


def test_the_error_gram_on_every_third_row_gives_the_fit_of_every_row(monkeypatch):
    """``fit --encoder-counts`` evaluates the error gram on about three rows per smoother span
    (:func:`ropod_sysid.noise.gram_stride`: every third row of the 11-row span here), the sum
    scaled to every row. On the first log of the shipped steered sample, the gram's inertial
    diagonal stays within 3 % of every row's, and the corrected fit's values within 0.05σ
    (measured 0.007σ on all four logs; stride 6 moved one value by 1.07σ)."""
    from ropod_sysid import noise
    from ropod_sysid.fit import FitOptions
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.regressor import preprocess
    from tests.conftest import shipped

    pf, _, logs = shipped("steered")
    model = PlatformModel(pf)
    pre = preprocess(logs[0], pf)
    assert noise.gram_stride(pre.grid.span) == 3 and noise.gram_stride(5) == 1
    every = noise.fit_error_gram(model, pre, pre.row_samples(), 2**14, stride=1)
    third = noise.fit_error_gram(model, pre, pre.row_samples(), 2**14)
    inertial = [j for j, n in enumerate(model.parameter_names()) if n.startswith(("m_", "J"))]
    for d in range(3):
        a, b = np.diag(third[d])[inertial], np.diag(every[d])[inertial]
        np.testing.assert_allclose(a, b, rtol=0.03, atol=1e-12 * b.max())
    opts = FitOptions(encoder_counts=2**14)
    strided = fit_logs(logs[:1], pf, opts).solution
    monkeypatch.setattr(noise, "GRAM_ROWS_PER_SPAN", 100)  # stride 1
    full = fit_logs(logs[:1], pf, opts).solution
    shift = np.abs(np.array(strided.values) - np.array(full.values)) / np.array(full.std)
    assert np.nanmax(shift) < 0.05, dict(zip(full.names, shift.round(3), strict=True))


def test_the_search_gram_thins_later_rows_and_blocks_agree():
    """The delay search's gram (:func:`ropod_sysid.noise.search_gram_stride`) takes a log's
    rows from ``sparse_after`` on :data:`SEARCH_GRAM_LATER` times sparser, each weighted so,
    chosen by the log's row number: the log in two blocks cut anywhere gives the gram of one
    block, and the thinned gram (from the middle of the log on) keeps the inertial diagonals
    of the dense one within 2 % on the first log of the shipped sample (measured 0.05-0.62 %),
    and so does one node per lag in the tone share (:data:`SEARCH_TONE_NODES`; 0.01-0.59 %)."""
    from ropod_sysid import noise
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.regressor import preprocess
    from tests.conftest import shipped

    pf, _, logs = shipped("ropod")
    model = PlatformModel(pf)
    pre = preprocess(logs[0], pf)
    rows = pre.row_samples()
    stride = noise.search_gram_stride(pre.grid.span)
    half = rows.size // 2

    def gram(index, first=0, after=None, nodes=None):
        return noise.fit_error_gram(model, pre, index, 2**14, first_row=first, stride=stride,
                                    tone_nodes=nodes, sparse_after=after)

    dense = gram(rows)
    thinned = gram(rows, after=half)
    for cut in (half - 7, half + 13):
        split = gram(rows[:cut], after=half) + gram(rows[cut:], cut, after=half)
        np.testing.assert_allclose(split, thinned, rtol=1e-12, atol=1e-12 * np.abs(thinned).max())
    assert np.array_equal(gram(rows, after=rows.size), dense)  # nothing later: the dense gram
    one_node = gram(rows, nodes=1)
    inertial = [j for j, n in enumerate(model.parameter_names()) if n.startswith(("m_", "J"))]
    for d in range(3):
        ref = np.diag(dense[d])[inertial]
        for other in (thinned, one_node):
            np.testing.assert_allclose(np.diag(other[d])[inertial], ref, rtol=0.02,
                                       atol=1e-9 * ref.max())


def test_the_corrected_triangle_solves_the_corrected_equations_when_they_are_indefinite():
    """When mᵀE m exceeds the residual (a log without current noise), [AᵀA − E, Aᵀb; bᵀA, bᵀb]
    is indefinite; its triangle (:func:`ropod_sysid.fit.corrected_factor`) still solves
    (AᵀA − E) m = Aᵀb, columns of very different scales included, with ρ clipped at 0 (an
    eigen-factor of the whole matrix moved the solution: the off-square ropod's m_b ≈ 0)."""
    from ropod_sysid.fit import corrected_factor
    from ropod_sysid.solve import solve

    rng = np.random.default_rng(3)
    scale = np.array([1.0, 1e3, 1e-2, 30.0])
    a = rng.normal(size=(400, 4)) * scale
    m = np.array([2.0, -1e-3, 50.0, 0.1])
    b = a @ m + rng.normal(scale=1e-3, size=400)
    e = 0.05 * np.diag(np.diag(a.T @ a))  # the encoders' share: far above the residual
    gram = np.column_stack([a, b]).T @ np.column_stack([a, b])
    gram[:4, :4] -= e
    assert np.linalg.eigvalsh(gram).min() < 0
    r = corrected_factor(gram, np.sqrt(np.diag(a.T @ a)))
    want = np.linalg.solve(gram[:4, :4], gram[:4, 4])
    sol = solve(r, 400, ["p0", "p1", "p2", "p3"])
    np.testing.assert_allclose(sol.values, want, rtol=1e-9)
    np.testing.assert_allclose(r[:4, :4].T @ r[:4, :4], gram[:4, :4], rtol=1e-9, atol=1e-9)
    assert r[4, 4] == 0.0


def test_check_predicts_the_recipe_shift_of_the_sample_fit():
    """trajectory check's recipe prediction (the four variants simulated without noise and
    fitted with the recipe check) gives the shift the README's fit of the shipped sample (2¹⁴
    counts, 30 mA, --encoder-counts) folds into σ: m_b, J_zz,b and m_wh within 25 %; the σ a
    checked fit reports is √(σ² + Δ²), and the JSON carries it."""
    import glob
    import json
    from pathlib import Path

    from ropod_sysid.fit import FitOptions, fit_files
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.noise import SensorNoise
    from ropod_sysid.platform import load_platform
    from ropod_sysid.trajectory import check, read_trajectory_csv

    sample = Path(__file__).resolve().parents[1] / "datasets" / "ropod"
    platform = load_platform(sample / "platform.yaml")
    truth = json.loads((sample / "truth.json").read_text())
    traj = read_trajectory_csv(sample / "trajectory" / "original.csv.gz",
                               PlatformModel(platform).planned_columns)
    rep = check(traj, platform, params=truth, sensors=SensorNoise(0.03, 2**14, 100.0),
                recipe=True)
    assert rep.recipe is not None and rep.recipe.names == rep.names
    assert rep.recipe.reference == "--smoother quartic --span 0.17s --input-delay auto"
    fit = fit_files(sorted(glob.glob(str(sample / "*.csv.gz"))), platform,
                    FitOptions(encoder_counts=2**14))
    assert fit.recipe_shift is not None
    predicted = dict(zip(rep.names, rep.recipe.shift, strict=True))
    for name in ("m_b", "Jzz_b", "m_wh"):
        assert predicted[name] == pytest.approx(fit.recipe_shift[name], rel=0.25), name
    np.testing.assert_allclose(rep.checked_std, np.hypot(rep.std, rep.recipe.shift))
    entry = rep.to_dict()["recipe_check"]["parameters"]["m_b"]  # type: ignore[index]
    assert entry["shift"] == pytest.approx(predicted["m_b"])
    assert entry["std"] == pytest.approx(float(rep.checked_std[0]))
    assert abs(entry["error"]) < 0.005 * truth["m_b"]  # the recipe's own bias: 0.2 %
    assert "σ checked" in rep.text()
