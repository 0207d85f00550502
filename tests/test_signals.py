"""Tests for ropod_sysid.signals: LOESS (MATLAB smooth), derivatives, resampling, filters."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.lowpass import butter2_lowpass, lowpass
from ropod_sysid.signals import (
    central_difference,
    five_point_difference,
    is_uniform,
    loess,
    loess_bruteforce,
    loess_end_weights,
    loess_kernel,
    loess_span_samples,
    resample_uniform,
    rloess,
)


def _rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


# ------------------------------------------------------------------ span rule


@pytest.mark.parametrize(
    ("span", "n", "expected"),
    [
        (4, 100, 5),  # even -> odd
        (5, 100, 5),
        (5.9, 100, 5),  # fractional part dropped
        (1, 100, 1),
        (0.1, 100, 11),  # ceil(10) = 10 -> 11
        (0.05, 99, 5),  # ceil(4.95) = 5
        (50, 20, 19),  # capped at n (even) -> n - 1
        (50, 21, 21),  # capped at n (odd)
        (0.999, 20, 19),
        (2, 2, 1),
    ],
)
def test_span_samples(span: float, n: int, expected: int) -> None:
    assert loess_span_samples(span, n) == expected


def test_span_samples_no_odd_and_errors() -> None:
    assert loess_span_samples(4, 100, make_odd=False) == 4
    assert loess_span_samples(0.1, 100, make_odd=False) == 10
    with pytest.raises(ValueError):
        loess_span_samples(0, 10)
    with pytest.raises(ValueError):
        loess_span_samples(-1, 10)


# ------------------------------------------------------------------ kernels


def test_kernel_k7_values() -> None:
    expected = [0, -0.077344, 0.309376, 0.535936, 0.309376, -0.077344, 0]
    np.testing.assert_allclose(loess_kernel(7), expected, rtol=0, atol=5e-7)


@pytest.mark.parametrize("k", [5, 7, 21, 101])
def test_kernel_and_end_weights_are_quadratic_exact(k: int) -> None:
    kernel = loess_kernel(k)
    ends = loess_end_weights(k)
    c = (k - 1) // 2
    assert kernel.shape == (k,)
    assert ends.shape == (c, k)
    assert kernel[0] == 0 and kernel[-1] == 0
    np.testing.assert_allclose(kernel, kernel[::-1], atol=0)
    j = np.arange(k)
    # interior: centre c; end row i: position i
    for p in range(3):
        np.testing.assert_allclose(kernel @ (j - c) ** p, 1.0 if p == 0 else 0.0, atol=1e-12)
        np.testing.assert_allclose(ends @ j**p, np.arange(c) ** p, atol=1e-9 * k**p)
    np.testing.assert_allclose(ends[:, -1], 0.0, atol=1e-15)


def test_kernel_small_k() -> None:
    np.testing.assert_array_equal(loess_kernel(3), [0, 1, 0])
    np.testing.assert_allclose(loess_kernel(5), [0, 0, 1, 0, 0], atol=1e-14)
    with pytest.raises(ValueError):
        loess_kernel(4)


@pytest.mark.parametrize("k", [9, 21, 101])
def test_quartic_kernel_reproduces_quintics_and_its_ends_quartics(k: int) -> None:
    """The quartic smoother (``--smoother quartic``): symmetric, so the interior reproduces
    quintics (the quadratic LOESS only cubics); the shifted end windows reproduce quartics."""
    kernel, ends = loess_kernel(k, 4), loess_end_weights(k, 4)
    c = (k - 1) // 2
    j = np.arange(k)
    for p in range(6):
        np.testing.assert_allclose(kernel @ ((j - c) / c) ** p, 1.0 if p == 0 else 0.0,
                                   atol=1e-10)
    for p in range(5):
        np.testing.assert_allclose(ends @ (j / k) ** p, (np.arange(c) / k) ** p, atol=1e-9)
    # the quadratic LOESS is off for a quartic (its fourth moment)
    assert abs(loess_kernel(k) @ ((j - c) / c) ** 4) > 1e-3
    x = np.arange(300.0) / 300
    y = np.column_stack([x**5, np.sin(9 * x)])
    out = loess(y, k, degree=4)
    np.testing.assert_allclose(out[c:-c, 0], y[c:-c, 0], atol=1e-12)
    assert np.abs(out - y)[c:-c, 1].max() < 0.2 * np.abs(loess(y, k) - y)[c:-c, 1].max()


def test_quartic_small_windows_return_the_samples() -> None:
    y = np.random.default_rng(2).standard_normal((30, 2))
    np.testing.assert_array_equal(loess(y, 5, degree=4), y)
    out = loess(y, 7, degree=4)  # five samples with weight: the interior is the sample
    np.testing.assert_allclose(out[3:-3], y[3:-3], atol=1e-12)
    np.testing.assert_allclose(loess_kernel(7, 4), [0, 0, 0, 1, 0, 0, 0], atol=1e-14)


def test_five_point_difference_is_exact_for_quartics() -> None:
    dt = 0.01
    t = np.arange(40) * dt
    y = np.column_stack([1 + t - 3 * t**2 + 2 * t**3 - 5 * t**4, np.sin(7 * t)])
    d = five_point_difference(y, dt)
    np.testing.assert_allclose(d[2:-2, 0], (1 - 6 * t + 6 * t**2 - 20 * t**3)[2:-2],
                               rtol=0, atol=1e-10)
    np.testing.assert_allclose(d[:2], central_difference(y, dt)[:2], atol=0)
    err5 = np.abs(d[2:-2, 1] - 7 * np.cos(7 * t[2:-2])).max()
    err3 = np.abs(central_difference(y, dt)[2:-2, 1] - 7 * np.cos(7 * t[2:-2])).max()
    assert err5 < 0.01 * err3


# ------------------------------------------------------------------ loess semantics


def test_k3_returns_input_unchanged() -> None:
    y = np.random.default_rng(0).standard_normal((50, 2))
    out = loess(y, 3)
    np.testing.assert_array_equal(out, y)
    assert out is not y
    np.testing.assert_array_equal(loess(y, 2), y)  # 2 -> 3
    np.testing.assert_array_equal(rloess(y, 3), y)
    np.testing.assert_array_equal(loess(y, 1), y)


def test_k5_interior_unchanged_ends_smoothed() -> None:
    y = np.random.default_rng(1).standard_normal(40)
    out = loess(y, 5)
    np.testing.assert_allclose(out[2:-2], y[2:-2], atol=1e-14)
    assert np.max(np.abs(out[:2] - y[:2])) > 1e-3  # ends are a genuine fit, not a copy
    assert np.max(np.abs(out[-2:] - y[-2:])) > 1e-3
    np.testing.assert_allclose(loess(y, 4), out, atol=0)  # 4 is made 5


@pytest.mark.parametrize("k", [5, 7, 9, 21, 51, 101, 151])
def test_quadratic_reproduced_including_ends(k: int) -> None:
    x = np.arange(400.0)
    q = 3.0 - 0.2 * x + 0.004 * x**2
    np.testing.assert_allclose(loess(q, k), q, rtol=0, atol=1e-11 * np.max(np.abs(q)))


def test_quadratic_reproduced_multichannel_and_axis() -> None:
    x = np.arange(120.0)
    q = np.stack([1 + x, 2 - 0.1 * x**2, 0.5 * x**2 - x], axis=1)  # (120, 3)
    np.testing.assert_allclose(loess(q, 11), q, atol=1e-10)
    np.testing.assert_allclose(loess(q.T, 11, axis=1), q.T, atol=1e-10)
    np.testing.assert_allclose(loess(q.T, 11, axis=-1), q.T, atol=1e-10)


def _random_signal(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    n = shape[0]
    trend = np.sin(np.arange(n) / 7.0).reshape((n,) + (1,) * (len(shape) - 1))
    return 3.0 * trend + rng.standard_normal(shape)


@pytest.mark.parametrize(
    ("n", "k"),
    [(7, 7), (30, 5), (31, 7), (60, 21), (101, 99), (200, 51), (260, 101), (400, 151)],
)
def test_fast_equals_bruteforce(n: int, k: int) -> None:
    rng = np.random.default_rng(n * 1000 + k)
    y = _random_signal(rng, (n,))
    fast = loess(y, k)
    ref = loess_bruteforce(y, k)
    c = (k - 1) // 2
    assert _rel_err(fast[c : n - c], ref[c : n - c]) <= 1e-12  # interior
    assert _rel_err(fast[:c], ref[:c]) <= 1e-12  # start
    assert _rel_err(fast[n - c :], ref[n - c :]) <= 1e-12  # end
    assert np.max(np.abs(fast - y)) > 0.1  # it really smoothed


@pytest.mark.parametrize("k", [9, 61])  # direct and FFT interior paths
def test_fast_equals_bruteforce_multichannel(k: int) -> None:
    rng = np.random.default_rng(k)
    y = _random_signal(rng, (150, 3, 2))
    fast = loess(y, k)
    assert fast.shape == y.shape
    assert _rel_err(fast, loess_bruteforce(y, k)) <= 1e-12
    # each channel on its own gives the same
    np.testing.assert_allclose(fast[:, 2, 1], loess(y[:, 2, 1], k), rtol=0, atol=1e-13)


def test_fast_equals_bruteforce_span_fraction_and_offset() -> None:
    rng = np.random.default_rng(5)
    y = 1e5 + _random_signal(rng, (300,))  # large offset: FFT path must stay accurate
    for span in (0.05, 0.25, 0.6):
        k = loess_span_samples(span, 300)
        fast = loess(y, span)
        np.testing.assert_allclose(fast, loess(y, k), atol=0)
        assert np.max(np.abs(fast - loess_bruteforce(y, span))) <= 1e-12 * 1e5


def test_k_larger_than_n_uses_n() -> None:
    y = _random_signal(np.random.default_rng(6), (20,))
    np.testing.assert_allclose(loess(y, 500), loess(y, 19), atol=0)
    np.testing.assert_allclose(loess(y[:19], 500), loess_bruteforce(y[:19], 19), atol=1e-12)


def test_nan_stays_local() -> None:
    y = _random_signal(np.random.default_rng(7), (300,))
    y[150] = np.nan
    for k in (11, 101):
        out = loess(y, k)
        assert np.isnan(out).sum() == k  # only windows containing sample 150
        assert np.isfinite(out[: 150 - k // 2]).all()


# ------------------------------------------------------------------ brute force, non-uniform x


def test_bruteforce_nonuniform_quadratic_and_order() -> None:
    rng = np.random.default_rng(8)
    x = np.cumsum(rng.uniform(0.5, 1.5, 80))
    q = 2.0 + 0.3 * x - 0.01 * x**2
    out = loess_bruteforce(q, 9, x=x)
    np.testing.assert_allclose(out, q, atol=1e-10)
    perm = rng.permutation(80)  # positions in any order
    y = q + rng.standard_normal(80)
    np.testing.assert_allclose(
        loess_bruteforce(y[perm], 9, x=x[perm]), loess_bruteforce(y, 9, x=x)[perm], atol=1e-13
    )


def test_bruteforce_even_k_only_made_odd_for_uniform_x() -> None:
    rng = np.random.default_rng(9)
    y = rng.standard_normal(60)
    x_uniform = 0.01 * np.arange(60)
    np.testing.assert_allclose(loess_bruteforce(y, 8, x=x_uniform), loess(y, 9), atol=1e-12)
    x = np.cumsum(rng.uniform(0.5, 1.5, 60))
    even = loess_bruteforce(y, 8, x=x)
    odd = loess_bruteforce(y, 9, x=x)
    assert np.max(np.abs(even - odd)) > 1e-3


# ------------------------------------------------------------------ rloess


def test_rloess_suppresses_outlier() -> None:
    rng = np.random.default_rng(10)
    x = np.arange(300.0)
    clean = np.sin(x / 20.0)
    y = clean + 0.01 * rng.standard_normal(300)
    y[[5, 150, 151]] += [4.0, 6.0, -5.0]
    err_plain = np.max(np.abs(loess(y, 25) - clean))
    err_robust = np.max(np.abs(rloess(y, 25) - clean))
    assert err_plain > 0.3
    assert err_robust < 0.05
    assert err_robust < err_plain / 10


def test_rloess_clean_quadratic_and_multichannel() -> None:
    x = np.arange(200.0)
    q = np.stack([1 + 0.5 * x - 0.003 * x**2, -2 + 0.001 * x**2], axis=1)
    np.testing.assert_allclose(rloess(q, 21), q, atol=1e-9)
    rng = np.random.default_rng(11)
    y = _random_signal(rng, (120, 2, 2))
    np.testing.assert_allclose(rloess(y, 15, iterations=0), loess(y, 15), atol=1e-12)
    robust = rloess(y, 15)
    assert robust.shape == y.shape
    assert np.max(np.abs(robust - loess(y, 15))) > 1e-3  # the robust passes did something
    np.testing.assert_allclose(robust[:, 1, 0], rloess(y[:, 1, 0], 15), atol=1e-12)
    np.testing.assert_allclose(robust[:, 0, 1], _rloess_reference(y[:, 0, 1], 15), atol=1e-12)


def _rloess_reference(y: np.ndarray, k: int, iterations: int = 5) -> np.ndarray:
    """Per-sample robust LOESS by the definition (SVD least squares for every window)."""
    n, c = y.size, (k - 1) // 2
    fit = loess_bruteforce(y, k)
    for _ in range(iterations):
        r = y - fit
        z = r / (6.0 * np.median(np.abs(r)))
        rob = np.where(np.abs(z) < 1, (1 - z**2) ** 2, 0.0)
        new = fit.copy()
        for i in range(n):
            lo = min(max(i - c, 0), n - k)
            t = np.arange(lo, lo + k) - i
            u = t / np.max(np.abs(t))
            w = (1 - np.abs(u) ** 3) ** 3 * rob[lo : lo + k]
            if w.sum() > 0:
                sw = np.sqrt(w)
                design = sw[:, None] * np.stack([np.ones(k), u, u * u], axis=1)
                new[i] = np.linalg.lstsq(design, sw * y[lo : lo + k], rcond=None)[0][0]
        fit = new
    return fit


@pytest.mark.parametrize("k", [7, 9, 25])
def test_rloess_equals_reference_on_heavy_tailed_data(k: int) -> None:
    # Cauchy noise knocks out whole window samples, so some local fits are (nearly) singular.
    y = np.random.default_rng(3).standard_cauchy(160)
    assert _rel_err(rloess(y, k), _rloess_reference(y, k)) <= 1e-12


# ------------------------------------------------------------------ derivatives, resampling


def test_central_difference_exact_for_quadratic_nonuniform() -> None:
    rng = np.random.default_rng(12)
    t = np.cumsum(rng.uniform(0.001, 0.02, 50))
    y = np.stack([1 + 2 * t - 3 * t**2, 4 * t**2], axis=1)
    dy = np.stack([2 - 6 * t, 8 * t], axis=1)
    np.testing.assert_allclose(central_difference(y, t), dy, rtol=0, atol=1e-9)
    y3 = np.broadcast_to(y[:, :, None], (50, 2, 3))
    assert central_difference(y3, t).shape == (50, 2, 3)


def test_central_difference_scalar_dt() -> None:
    dt = 0.01
    t = dt * np.arange(30)
    y = 5 * t**2 - t
    np.testing.assert_allclose(central_difference(y, dt), 10 * t - 1, atol=1e-10)
    np.testing.assert_allclose(central_difference(y[:2], dt), [(y[1] - y[0]) / dt] * 2)
    with pytest.raises(ValueError):
        central_difference(y, t[::-1])


def test_resample_uniform_linear_exact() -> None:
    rng = np.random.default_rng(13)
    t = 0.5 + np.arange(200) * 0.01 + rng.uniform(-0.003, 0.003, 200)
    y = np.stack([2 * t + 1, -t], axis=1)
    t_new, y_new = resample_uniform(t, y)
    dt = np.median(np.diff(t))
    assert t_new[0] == t[0]
    assert t_new[-1] <= t[-1] < t_new[-1] + dt
    np.testing.assert_allclose(np.diff(t_new), dt, rtol=1e-9)
    np.testing.assert_allclose(y_new, np.stack([2 * t_new + 1, -t_new], axis=1), atol=1e-12)
    assert is_uniform(t_new) and not is_uniform(t)


def test_resample_uniform_given_dt_and_grid_end() -> None:
    t = np.array([0.0, 0.1, 0.25, 0.3, 0.5])
    t_new, y_new = resample_uniform(t, 3 * t, dt=0.1)
    np.testing.assert_allclose(t_new, [0.0, 0.1, 0.2, 0.3, 0.4, 0.5], atol=1e-15)
    assert t_new[-1] <= t[-1]
    np.testing.assert_allclose(y_new, 3 * t_new, atol=1e-14)
    t_new, _ = resample_uniform(t, t, dt=0.15)
    np.testing.assert_allclose(t_new, [0.0, 0.15, 0.3, 0.45])


def test_is_uniform() -> None:
    assert is_uniform(0.01 * np.arange(1000))
    t = 0.01 * np.arange(1000)
    t[500] += 1e-5
    assert not is_uniform(t)
    assert is_uniform(t, rtol=1e-2)
    assert not is_uniform(np.zeros(5))


# ------------------------------------------------------------------ lowpass


@pytest.mark.parametrize("zero_phase", [False, True])
def test_lowpass_passes_1hz_attenuates_50hz(zero_phase: bool) -> None:
    dt = 0.001
    t = dt * np.arange(5000)
    slow = np.sin(2 * np.pi * 1.0 * t)
    fast = np.sin(2 * np.pi * 50.0 * t)
    y = np.stack([slow, fast], axis=1)
    out = lowpass(y, dt, 10.0, zero_phase=zero_phase)
    steady = slice(1000, 4000)
    amp_slow = np.max(np.abs(out[steady, 0]))
    amp_fast = np.max(np.abs(out[steady, 1]))
    assert amp_slow > 0.97
    assert amp_fast < (0.002 if zero_phase else 0.05)  # 2nd order: 1/25 at 5x the cut-off
    if zero_phase:
        np.testing.assert_allclose(out[steady, 0], slow[steady], atol=0.01)
    with pytest.raises(ValueError):
        lowpass(y, dt, 600.0)


@pytest.mark.parametrize("dt, cutoff", [(0.01, 10.0), (0.001, 10.0), (0.002, 240.0)])
def test_butter2_is_scipys_butterworth_and_filters_in_chunks_as_sosfilt(dt: float,
                                                                          cutoff: float) -> None:
    """The observer's low-pass without scipy.signal's import: the closed-form coefficients
    are scipy.signal.butter's, and a signal filtered in chunks (of 0, 1, 2 and more samples,
    the state carried between them) is sosfilt's of the whole, to 1e-13 relative."""
    from scipy import signal

    f = butter2_lowpass(dt, cutoff)
    b, a = signal.butter(2, cutoff, fs=1.0 / dt)
    np.testing.assert_allclose(f.b, b, rtol=1e-12)
    np.testing.assert_allclose(f.a, a, rtol=1e-12, atol=1e-15)
    x = np.random.default_rng(2).normal(size=(700, 3, 2)).cumsum(axis=0)
    edges = [0, 1, 1, 3, 4, 250, 700]
    y = np.concatenate([f(x[i:j]) for i, j in zip(edges[:-1], edges[1:], strict=True)])
    want = signal.sosfilt(signal.butter(2, cutoff, fs=1.0 / dt, output="sos"), x, axis=0)
    np.testing.assert_allclose(y, want, rtol=0, atol=1e-13 * np.abs(want).max())
    np.testing.assert_allclose(lowpass(np.moveaxis(x, 0, 1), dt, cutoff, axis=1),
                               np.moveaxis(want, 0, 1), rtol=0, atol=1e-13 * np.abs(want).max())
    with pytest.raises(ValueError, match=r"cutoff_hz must be in \(0, 50\) Hz for dt = 0.01 s"):
        butter2_lowpass(0.01, 50.0)


@pytest.mark.parametrize("k", [61, 101])
def test_fft_interior_over_many_segments_and_a_drifting_angle(k: int) -> None:
    """The overlap-save FFT over many segments equals the definition, also for an encoder
    angle that has turned 10⁴ rad (round-off within a few ulps of the angle)."""
    rng = np.random.default_rng(k)
    n = 40 * k
    t = np.arange(n) * 1e-3
    y = 1e4 + 60.0 * t + 0.2 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0, 1e-3, n)
    fast = loess(y, k)
    ref = loess_bruteforce(y, k)
    assert np.max(np.abs(fast - ref)) <= 1e-14 * 1e4  # a few ulps of the angle
    fd = np.diff(fast) / 1e-3
    assert np.max(np.abs(fd - np.diff(ref) / 1e-3)) <= 1e-14 * 1e4 / 1e-3
