"""Identification against simulations with known parameters (thesis Sec. VI, App. D-C)."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.errors import IdentifiabilityError, InputError
from ropod_sysid.fit import FitOptions, fit_logs, physical_bounds
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import is_inertial, parameter_names, thesis_fixed_masses
from ropod_sysid.platform import ropod_platform
from ropod_sysid.regressor import Span, preprocess, raw_system
from ropod_sysid.solve import Triangles, qr_triangle, solve, stack_triangles
from tests.swivel_arrays import C, D, P, with_arrays


def rel_err(fit, truth_vec):
    return np.abs(fit.solution.values - truth_vec) / np.abs(truth_vec)


def test_exact_logs_recover_every_parameter(off_square, truth, runs_off_square):
    """Noise-free 200 Hz logs, pivots off the square, span 0.1 s: every parameter within 3 %,
    the base mass and inertia within 1.5 %, friction within 2 %."""
    fit = fit_logs([r.log for r in runs_off_square], off_square)
    names = fit.names
    err = rel_err(fit, truth.vector(parameter_names(off_square)))
    assert fit.solution.rank == len(names) == 29
    assert np.all(err < 0.03), dict(zip(names, err.round(4), strict=True))
    assert err[names.index("m_b")] < 0.015 and err[names.index("Jzz_b")] < 0.015
    friction = [j for j, n in enumerate(names) if not is_inertial(n)]
    assert np.all(err[friction] < 0.02)
    assert fit.rms["translation"] < 0.5 and fit.rms["rotation"] < 0.1


def test_noisy_logs_errors_are_covered_by_std(off_square, truth, runs_off_square_noisy):
    """2¹⁴-count encoders, 30 mA current noise: the errors stay within the standard
    deviations the parameter file promises (measured: at most 1.7σ, median 0.4σ)."""
    fit = fit_logs(runs_off_square_noisy, off_square)
    true = truth.vector(parameter_names(off_square))
    sol = fit.solution
    z = np.abs(sol.values - true) / sol.std
    assert np.all(z < 3), dict(zip(sol.names, z.round(1), strict=True))
    # the effective translational inertia m_b + 4 m_wh + 8 J_rot/R_w² is well determined
    rw = off_square.units[0].wheel_radius
    eff = lambda v: v[0] + 4 * v[2] + 8 * v[4] / rw**2  # noqa: E731
    assert eff(sol.values) == pytest.approx(eff(true), rel=0.01)
    friction = [j for j, n in enumerate(sol.names) if n.startswith(("fwv", "fpv"))]
    assert np.all(np.abs(sol.values[friction] - true[friction]) / np.abs(true[friction]) < 0.05)


def test_symmetric_ropod_names_its_null_space(runs_square):
    """Thesis Sec. VI-C: with symmetric attachment points the stacked regressor loses rank.
    The fit names the combination and recovers the identifiable combinations."""
    pf = ropod_platform()
    true = thesis_fixed_masses(pf.unit_names).vector(parameter_names(pf))
    fit = fit_logs([r.log for r in runs_square], pf)
    sol = fit.solution
    assert sol.rank == 28
    assert sol.null_space.shape == (29, 1)
    null = sol.null_space[:, 0]
    assert np.all(null[5:] == 0.0)  # only the inertial parameters are involved
    # independent route: the null vector of A_ID,ext built from the exact simulated states
    model = PlatformModel(pf)
    r = runs_square[0]
    st = model.state(r.q, r.qd, r.angles)
    a = model.a_id_ext(st, r.qdd)[:, :, :5].reshape(-1, 5)
    scale = np.linalg.norm(a, axis=0)
    _, s, vt = np.linalg.svd(a / scale, full_matrices=False)
    assert s[-1] < 1e-10 * s[0]
    exact = vt[-1] / scale
    cos = abs(exact @ null[:5]) / np.linalg.norm(exact) / np.linalg.norm(null[:5])
    assert cos > 0.999
    # the values stand for identifiable combinations: x_B = true_B + K true_D
    dep = [j for j in range(29) if sol.combination[j] and np.isnan(sol.std[j])]
    assert len(dep) == 1 and sol.values[dep[0]] == 0.0
    d = dep[0]
    for j in range(5):
        if j == d:
            continue
        k = -null[j] / null[d]
        assert sol.values[j] == pytest.approx(true[j] + k * true[d], rel=0.03)
        assert sol.combination[j] and sol.names[d] in sol.combinations[sol.names[j]]
    text = sol.null_space_text()[0]
    assert "m_b" in text and "Jrot_w" in text
    pfile = fit.parameter_file().to_dict()
    assert pfile["rank"] == 28 and pfile["null_space"] == [text]
    assert pfile["parameters"][sol.names[d]]["combination"] is True
    # fixing the dependent parameter separates the rest
    fixed = fit_logs([r.log for r in runs_square], pf,
                     FitOptions(fix={sol.names[d]: float(true[d])}))
    assert fixed.solution.rank == 28 and not fixed.solution.combination.any()
    assert np.all(np.abs(fixed.solution.values[:5] - true[:5]) / true[:5] < 0.05)


def test_rotation_weight_matches_mean_squares(off_square, runs_off_square):
    """Sec. VI-A: w² mean(b_θ²) = mean(b_x², b_y²), per stacked system."""
    model = PlatformModel(off_square)
    pre = preprocess(runs_off_square[0].log, off_square, Span.parse("0.1s"))
    from ropod_sysid.regressor import filtered_system

    a, b = filtered_system(model, pre)
    tri = Triangles.from_rows(a, b)
    w = tri.rotation_weight()
    assert w**2 * np.mean(b[:, 2] ** 2) == pytest.approx(np.mean(b[:, :2] ** 2), rel=1e-10)
    fit_auto = fit_logs([runs_off_square[0].log], off_square)
    fit_none = fit_logs([runs_off_square[0].log], off_square,
                        FitOptions(weight_rotation="none"))
    fit_num = fit_logs([runs_off_square[0].log], off_square, FitOptions(weight_rotation=w))
    assert fit_auto.logs[0].weight == pytest.approx(w)
    assert fit_none.logs[0].weight == 1.0
    np.testing.assert_allclose(fit_num.solution.values, fit_auto.solution.values, rtol=1e-9)
    assert not np.allclose(fit_none.solution.values, fit_auto.solution.values, rtol=1e-6)


def test_triangles_equal_the_stacked_least_squares(off_square, runs_off_square):
    """QR triangles give the least-squares answer of the explicitly stacked system."""
    model = PlatformModel(off_square)
    from ropod_sysid.regressor import filtered_system

    blocks, tris = [], []
    for r in runs_off_square[:2]:
        pre = preprocess(r.log, off_square)
        a, b = filtered_system(model, pre)
        tri = Triangles.from_rows(a, b)
        w = tri.rotation_weight()
        a = a.copy()
        b = b.copy()
        a[:, 2] *= w
        b[:, 2] *= w
        blocks.append((a.reshape(-1, a.shape[2]), b.reshape(-1)))
        tris.append(tri.weighted(w))
    a_all = np.vstack([a for a, _ in blocks])
    b_all = np.concatenate([b for _, b in blocks])
    x_ref = np.linalg.lstsq(a_all, b_all, rcond=None)[0]
    names = parameter_names(off_square)
    sol = solve(stack_triangles(tris), len(b_all), names)
    np.testing.assert_allclose(sol.values, x_ref, rtol=1e-8)
    # and chunked triangles equal one-shot triangles
    r_one = qr_triangle(a_all, b_all)
    r_two = stack_triangles([qr_triangle(a, b) for a, b in blocks])
    np.testing.assert_allclose(np.abs(r_one), np.abs(r_two), atol=1e-8 * np.abs(r_one).max())


def test_fix_holds_a_parameter(off_square, truth, runs_off_square):
    fit = fit_logs([r.log for r in runs_off_square], off_square,
                   FitOptions(fix={"m_b": 35.1, "m_wh": 4.2}))
    sol = fit.solution
    assert sol.values[0] == 35.1 and sol.values[2] == 4.2
    assert np.isnan(sol.std[0]) and np.isnan(sol.std[2])
    assert sol.rank == 27
    err = np.abs(sol.values - truth.vector(parameter_names(off_square)))
    assert err[1] / truth["Jzz_b"] < 0.02
    with pytest.raises(InputError, match="--fix m_x: unknown parameter"):
        fit_logs([runs_off_square[0].log], off_square, FitOptions(fix={"m_x": 1.0}))


def test_physical_fit_respects_bounds(off_square, runs_off_square_noisy):
    fit = fit_logs(runs_off_square_noisy[:2], off_square, FitOptions(physical=True))
    lo, hi = physical_bounds(fit.names)
    v = fit.physical.values
    assert np.all(v >= lo - 1e-12) and np.all(v <= hi + 1e-12)
    assert fit.physical_rms["translation"] >= fit.rms["translation"] - 1e-9
    assert fit.parameter_file().extras["rms_free_fit"] == fit.rms


def test_shared_friction_has_nine_parameters(off_square, truth, runs_off_square):
    fit = fit_logs([r.log for r in runs_off_square], off_square,
                   FitOptions(friction="shared"))
    assert fit.names == ["m_b", "Jzz_b", "m_wh", "Jzz_wh", "Jrot_w", "fwv", "fwc", "fpv", "fpc"]
    # the shared coefficients land near the mean of the per-wheel truth
    def mean(family: str) -> float:
        return float(np.mean([v for k, v in truth.items() if k.startswith(family + "_")]))

    assert fit.solution.values[5] == pytest.approx(mean("fwv"), rel=0.15)
    assert fit.solution.values[7] == pytest.approx(mean("fpv"), rel=0.15)


def test_input_delay_is_estimated(off_square, runs_off_square):
    """Currents logged 10 ms early relative to the motion: auto finds the lag."""
    shift = 2  # samples at 200 Hz
    logs = []
    for r in runs_off_square:
        log = r.log
        cur = np.concatenate([C(log)[shift:], np.repeat(C(log)[-1:], shift, 0)])
        logs.append(with_arrays(log, current=cur))
    fit = fit_logs(logs, off_square, FitOptions(input_delay="auto"))
    assert fit.input_delay == pytest.approx(shift / 200.0, abs=1.5e-3)
    plain = fit_logs(logs, off_square)
    assert fit.rms["translation"] < 0.5 * plain.rms["translation"]


def test_rank_zero_is_an_error(off_square, runs_off_square):
    log = runs_off_square[0].log
    still = with_arrays(log, delta=np.zeros_like(D(log)), phi=np.zeros_like(P(log)),
                        current=np.zeros_like(C(log)))
    with pytest.raises(IdentifiabilityError, match="rank 0"):
        fit_logs([still], off_square)


def test_too_short_for_the_span(off_square, runs_off_square):
    log = runs_off_square[0].log.slice(0, 40)
    with pytest.raises(InputError, match="too few for a smoother span"):
        fit_logs([log], off_square, FitOptions(span=Span.parse("0.1s")))


def test_span_parsing():
    assert Span.parse("0.25s").samples(0.005, 1000) == 51
    assert Span.parse("21").samples(0.005, 1000) == 21
    with pytest.raises(InputError, match="odd whole number ≥ 5; did you mean 19 or 21"):
        Span.parse("20")  # a count of samples is odd (LOESS centres its window)
    assert Span.parse(None).samples(0.005, 1000) == 21
    with pytest.raises(InputError, match="--span 'abc'"):
        Span.parse("abc")
    with pytest.raises(InputError):
        Span.parse("-3")


def test_filtering_in_blocks_equals_one_shot(off_square, runs_off_square):
    """The regressor is filtered block by block with a half-window overlap: same result."""
    from ropod_sysid.regressor import system

    model = PlatformModel(off_square)
    pre = preprocess(runs_off_square[1].log, off_square)
    big = list(system(model, pre, chunk=10**9))
    small = list(system(model, pre, chunk=97))
    a1 = np.concatenate([a for _, a, _ in big])
    a2 = np.concatenate([a for _, a, _ in small])
    np.testing.assert_allclose(a2, a1, rtol=1e-12, atol=1e-12 * np.abs(a1).max())
    assert a1.shape[0] == pre.n_rows
    a_raw, _ = raw_system(model, pre)
    assert a_raw.shape[0] == len(pre.t)


def test_a_log_that_stops_and_restarts_fits_like_its_pieces(off_square, truth):
    """Two copies of a run joined end to end (at the seam the robot stands, its speed loops
    holding their currents, then a controller reset) give the parameters of the two runs
    fitted as separate logs, within σ: the rows at rest carry no equation."""
    import dataclasses

    from ropod_sysid.simulate import Setpoints, simulate

    t = np.arange(0.0, 12.0 + 0.005, 0.01)

    def smooth(u):
        u = np.clip(u, 0.0, 1.0)
        return u**3 * (10 - 15 * u + 6 * u**2)

    fwd = smooth(t / 2.0) * smooth((11.5 - t) / 2.0)  # forward only at both ends
    mix = smooth((t - 3.0) / 2.0) * smooth((9.0 - t) / 2.0)
    sp = Setpoints(t, 0.5 * fwd + 0.3 * mix * np.sin(2 * np.pi * t / 6),
                   0.3 * mix * np.sin(2 * np.pi * t / 8), 0.8 * mix * np.sin(2 * np.pi * t / 5))
    (run,) = simulate(off_square, truth, [sp], rate=200.0)
    log = run.log
    dt = float(np.median(np.diff(log.t)))
    shift = log.angles[-1] - log.angles[0]
    w = log.layout.wrapped
    shift[w] = 2 * np.pi * np.round(shift[w] / (2 * np.pi))  # pivots: whole turns
    joined = dataclasses.replace(
        log, t=np.concatenate([log.t, log.t + log.t[-1] + dt]),
        angles=np.concatenate([log.angles, log.angles + shift]),
        currents=np.concatenate([log.currents, log.currents]))
    one = fit_logs([joined], off_square)
    two = fit_logs([log, dataclasses.replace(log, source="again")], off_square)
    assert one.logs[0].triangles.idle > 0  # the stop's rows are set aside
    z = (one.solution.values - two.solution.values) / one.solution.std
    # (measured: median |Δ|/σ 0.6, the largest 2.0 of 29, a friction coefficient)
    assert np.median(np.abs(z)) < 1.0 and np.abs(z).max() < 2.5, np.round(z, 2)
