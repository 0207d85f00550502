"""Signal conditioning: LOESS smoothing, derivatives and resampling (low-pass filtering:
:mod:`ropod_sysid.lowpass`).

Small pure functions in the style of :mod:`scipy.signal`. Every function works along axis 0
(or ``axis``) and treats all other axes as independent channels, so an ``(N, 3, 2)`` array is
smoothed as six signals at once.

LOESS follows the documented behaviour of MATLAB's ``smooth(y, span, 'loess')`` (restated in
``docs/method.md``, "LOESS"; written from that description, not from MathWorks code):
local quadratic fit, tricube weights that vanish at the farthest sample of each window, windows
of ``k`` samples that shift rather than shrink at the ends, and for uniform sampling an even
``k`` made odd. For uniform sampling every interior output is the same fixed symmetric kernel,
so :func:`loess` is a convolution plus two small ``((k-1)/2, k)`` matrices for the ends.
:func:`loess_bruteforce` is the literal per-sample definition, kept as a test reference and for
non-uniform sample positions.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = [
    "central_difference",
    "five_point_difference",
    "is_uniform",
    "loess",
    "loess_bruteforce",
    "loess_end_weights",
    "loess_kernel",
    "loess_span_samples",
    "resample_uniform",
    "rloess",
]

# Above this window length the interior convolution uses overlap-save FFT (scipy.fft); at or
# below it, direct correlation (a sliding window times the kernel) is faster. Measured on
# N = 1e5..4e6: direct wins up to k ~ 50, FFT is 2-10x faster from k ~ 100 on.
_DIRECT_MAX_K = 51
# Overlap-save segments are about this many kernel lengths (fastest of 4, 8, 16 for k = 101).
_SEGMENT_KERNELS = 8

# Robust LOESS solves a window's 3x3 normal equations directly when det(A) / prod(diag(A)) exceeds
# this (1 for an orthogonal design, 0 when singular); otherwise by SVD on the weighted design.
_WELL_CONDITIONED = 1e-6

# Work arrays of at most about this many float64 elements (32 MiB) in chunked code paths.
_CHUNK_ELEMENTS = 1 << 22
_CACHED_END_ELEMENTS = 1 << 18  # end weights kept per window (16 windows: 32 MB at most)


# --------------------------------------------------------------------------------------------
# LOESS building blocks
# --------------------------------------------------------------------------------------------


def loess_span_samples(span: float, n: int, *, make_odd: bool = True) -> int:
    """Window length in samples for a LOESS span, by MATLAB's ``smooth`` rule.

    Parameters
    ----------
    span : float
        ``span < 1``: fraction of the signal length (``k = ceil(span * n)``);
        ``span >= 1``: number of samples (fractional part dropped). Must be positive.
    n : int
        Number of samples in the signal.
    make_odd : bool, optional
        Turn an even ``k`` into ``2 * floor(k / 2) + 1`` (MATLAB does this for uniform sample
        positions only). Default True.

    Returns
    -------
    k : int
        Window length in samples, ``1 <= k <= n`` (0 only when ``n == 0``). With ``make_odd``
        it is odd: if rounding up to odd would exceed ``n`` (``n`` even), ``n - 1`` is used.

    Examples
    --------
    >>> loess_span_samples(4, 100), loess_span_samples(0.1, 100), loess_span_samples(50, 20)
    (5, 11, 19)
    """
    n = int(n)
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    span = float(span)
    if not np.isfinite(span) or span <= 0:
        raise ValueError(f"span must be a positive finite number, got {span}")
    if n == 0:
        return 0
    k = np.ceil(span * n) if span < 1 else span
    k = min(int(np.floor(k)), n)
    if make_odd:
        k = 2 * (k // 2) + 1
        if k > n:
            k = n if n % 2 == 1 else n - 1
    return max(k, 1)


def _local_quadratic_rows(u: np.ndarray, w: np.ndarray, degree: int = 2) -> np.ndarray:
    """Rows ``r`` with ``r @ y`` = constant term of the ``w``-weighted polynomial fit of y on u
    (a quadratic, or the ``degree`` given: 4 for the quartic smoother).

    ``u`` and ``w`` have shape ``(rows, k)``; the fit is solved by a batched QR of
    ``sqrt(w) * [1, u, …, u^degree]`` (better conditioned than normal equations). Needs at
    least ``degree + 1`` distinct positions with positive weight per row.
    """
    sw = np.sqrt(w)
    powers = [np.ones_like(u), u]
    while len(powers) <= degree:
        powers.append(powers[-1] * u)
    design = sw[..., None] * np.stack(powers, axis=-1)  # (rows, k, degree + 1)
    q, r = np.linalg.qr(design)  # q (rows, k, d + 1), r (rows, d + 1, d + 1)
    e1 = np.zeros(r.shape[:-2] + (degree + 1, 1))
    e1[..., 0, 0] = 1.0
    v = np.linalg.solve(np.swapaxes(r, -1, -2), e1)  # R^T v = e1  ->  v = R^-T e1
    return (q @ v)[..., 0] * sw


def _tricube(u: np.ndarray) -> np.ndarray:
    """Tricube weight ``(1 - |u|^3)^3`` for ``|u| < 1``, zero elsewhere."""
    a = np.clip(np.abs(u), 0.0, 1.0)
    return (1.0 - a**3) ** 3


def _interior_geometry(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised positions ``u`` (length k) and tricube weights of the centred window."""
    c = (k - 1) // 2
    u = (np.arange(k) - c) / c
    return u, _tricube(u)


def _end_geometry(k: int, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised positions and tricube weights for end rows ``rows`` (window = samples 0..k-1)."""
    rows = np.asarray(rows)[:, None]
    d = (k - 1) - rows  # farthest sample is the last one of the window
    u = (np.arange(k)[None, :] - rows) / d
    return u, _tricube(u)


def loess_kernel(k: int, degree: int = 2) -> np.ndarray:
    """Interior LOESS weights for uniform sampling: output ``= sum(kernel * window)``.

    Constant term of the tricube-weighted local quadratic (``degree`` 4: quartic) fit over a
    centred window of ``k`` samples; the two outermost samples have weight zero.

    Parameters
    ----------
    k : int
        Window length in samples, odd and positive.
    degree : int, optional
        2 (MATLAB's LOESS, the default) or 4 (local quartic: reproduces quintics, so its
        bias is O(h⁶) against O(h⁴), at more noise for the same window).

    Returns
    -------
    kernel : ndarray, shape (k,)
        Symmetric weights (dimensionless) summing to 1. For ``k <= degree + 3`` the identity
        (e.g. ``[0, 0, 1, 0, 0]`` for ``k = 5``, degree 2): only ``degree + 1`` samples carry
        weight.

    Examples
    --------
    >>> np.round(loess_kernel(7), 6).tolist()
    [0.0, -0.077344, 0.309376, 0.535936, 0.309376, -0.077344, 0.0]
    """
    k = _check_odd_k(k)
    if k <= degree + 1:
        kernel = np.zeros(k)
        kernel[k // 2] = 1.0
        return kernel
    u, w = _interior_geometry(k)
    kernel = _local_quadratic_rows(u[None, :], w[None, :], degree)[0]
    return 0.5 * (kernel + kernel[::-1])


def loess_end_weights(k: int, degree: int = 2) -> np.ndarray:
    """LOESS weights for the first ``(k-1)/2`` outputs of a uniformly sampled signal.

    Row ``i`` gives output ``i`` as ``weights[i] @ y[:k]`` (the window does not shrink at the
    start, it stays at samples ``0..k-1``). The last ``(k-1)/2`` outputs follow by symmetry:
    ``out[N-1-i] = weights[i] @ y[::-1][:k]``.

    Parameters
    ----------
    k : int
        Window length in samples, odd and positive.

    Returns
    -------
    weights : ndarray, shape ((k-1)/2, k)
        Dimensionless; each row sums to 1 and reproduces polynomials of ``degree`` (2, or 4)
        exactly. For ``k <= degree + 1`` the rows select their own sample. The cost is
        O(k^2), so very long windows are expensive.
    """
    k = _check_odd_k(k)
    c = (k - 1) // 2
    if k <= degree + 1:
        weights = np.zeros((c, k))
        weights[np.arange(c), np.arange(c)] = 1.0
        return weights
    u, w = _end_geometry(k, np.arange(c))
    return _local_quadratic_rows(u, w, degree)


def _check_odd_k(k: int) -> int:
    if int(k) != k or k < 1 or k % 2 == 0:
        raise ValueError(f"k must be a positive odd integer, got {k}")
    return int(k)


# --------------------------------------------------------------------------------------------
# LOESS
# --------------------------------------------------------------------------------------------


def _as_2d(y: np.ndarray, axis: int) -> tuple[np.ndarray, tuple[int, ...]]:
    """Move ``axis`` to the front and flatten the rest: ``(N, m)`` float64 and the moved shape."""
    moved = np.moveaxis(np.asarray(y, dtype=float), axis, 0)
    return moved.reshape(moved.shape[0], -1), moved.shape


def _from_2d(y2: np.ndarray, moved_shape: tuple[int, ...], axis: int) -> np.ndarray:
    return np.moveaxis(y2.reshape(moved_shape), 0, axis)


def _interior(y2: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``valid`` correlation of each column of ``y2`` with a symmetric kernel: ``(N-k+1, m)``."""
    k = kernel.size
    # (a NaN or inf sample makes its column's sum non-finite: one cheap pass over the data)
    if k <= _DIRECT_MAX_K or not np.isfinite(y2.sum(axis=0)).all():
        # Direct: NaN/inf only reach outputs whose window holds them. (1-2.5x faster than
        # scipy.ndimage.correlate1d at k = 11-51, N = 6e3-2e5, and no 0.4-0.8 s import.)
        return np.lib.stride_tricks.sliding_window_view(y2, k, axis=0) @ kernel
    # Overlap-save FFT. The kernel reproduces constants, so removing each channel's first
    # sample keeps the FFT round-off relative to the signal's variation, not to its offset.
    offset = y2[0].copy()
    out = _overlap_save(y2 - offset, kernel)
    out += offset
    return out


def _overlap_save(y2: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``valid`` convolution of each column of ``y2`` (N, m) with ``kernel`` (k,) by FFT over
    segments of about :data:`_SEGMENT_KERNELS` kernel lengths: ``(N-k+1, m)``, O(N log k)."""
    import scipy.fft as sp_fft  # here: loading it costs a short fit 0.2 s

    n, m = y2.shape
    k = kernel.size
    size = sp_fft.next_fast_len(max(_SEGMENT_KERNELS * k, 256), real=True)
    step = size - k + 1  # valid outputs per segment
    out_len = n - k + 1
    n_seg = -(-out_len // step)
    pad = n_seg * step + k - 1 - n
    if pad:
        y2 = np.concatenate([y2, np.zeros((pad, m))])
    segments = sliding_window_view(y2, size, axis=0)[::step]  # (n_seg, m, size)
    spectrum = sp_fft.rfft(segments, axis=-1)
    spectrum *= sp_fft.rfft(kernel[::-1], size)
    valid = sp_fft.irfft(spectrum, size, axis=-1)[..., k - 1:]  # (n_seg, m, step)
    return valid.transpose(0, 2, 1).reshape(-1, m)[:out_len]


@functools.lru_cache(maxsize=16)
def _window_weights(k: int, degree: int) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`loess_kernel` and, for windows whose (c, k) matrix is small (up to 2 MB: k up to
    about 720), the end rows' weights, computed once per window (a streamed log smooths every
    block with the same ones); read-only."""
    kernel = loess_kernel(k, degree)
    kernel.setflags(write=False)
    c = (k - 1) // 2
    if c * k > _CACHED_END_ELEMENTS:
        return kernel, None
    u, w = _end_geometry(k, np.arange(c))
    ends = _local_quadratic_rows(u, w, degree)
    ends.setflags(write=False)
    return kernel, ends


def _apply_ends(y2: np.ndarray, out: np.ndarray, k: int, degree: int = 2,
                ends: np.ndarray | None = None) -> None:
    """Write the first and last ``(k-1)/2`` outputs of a uniform LOESS into ``out`` (``ends``:
    their weights, if known)."""
    c = (k - 1) // 2
    head = y2[:k]
    tail = y2[::-1][:k]
    if ends is not None:
        out[:c] = ends @ head
        out[out.shape[0] - c:] = (ends @ tail)[::-1]
        return
    # Rows in blocks so that very long windows do not build a (c, k) matrix at once.
    block = max(1, _CHUNK_ELEMENTS // k)
    for start in range(0, c, block):
        rows = np.arange(start, min(c, start + block))
        u, w = _end_geometry(k, rows)
        weights = _local_quadratic_rows(u, w, degree)
        out[rows] = weights @ head
        out[out.shape[0] - 1 - rows] = weights @ tail


def loess(y: np.ndarray, span: float, axis: int = 0, degree: int = 2) -> np.ndarray:
    """LOESS smoothing of uniformly sampled data (MATLAB ``smooth(y, span, 'loess')``).

    Local quadratic fit with tricube weights over windows of ``k`` samples; near the ends the
    window shifts so it always holds ``k`` samples. Interior outputs are a convolution with
    :func:`loess_kernel` (direct for short windows, overlap-save FFT for long ones); the
    ``(k-1)/2`` outputs at each end use :func:`loess_end_weights`. Cost O(N k) at worst,
    O(N log k) for long windows, plus O(k^2) for the ends.

    Parameters
    ----------
    y : array_like, shape (N, ...)
        Samples at uniform spacing, any unit; other axes are independent channels.
    span : float
        Window: fraction of N if ``< 1``, else a number of samples. Made odd and capped at N by
        :func:`loess_span_samples`.
    axis : int, optional
        Axis along which to smooth. Default 0.
    degree : int, optional
        Of the local polynomial: 2 (MATLAB's LOESS, the default) or 4 (the quartic smoother,
        :func:`loess_kernel`).

    Returns
    -------
    ndarray
        Smoothed samples, same shape and unit as ``y`` (float64). ``k <= degree + 1`` returns
        a copy of ``y`` (a window of ``degree + 3`` samples only weights its centre in the
        interior). A non-finite sample spoils the
        outputs whose window contains it.

    See Also
    --------
    rloess : Robust variant that down-weights outliers.
    loess_bruteforce : Per-sample reference, also for non-uniform positions.
    """
    y2, moved_shape = _as_2d(y, axis)
    n = y2.shape[0]
    k = loess_span_samples(span, n) if n else 0
    if k <= degree + 1:
        return _from_2d(y2.copy(), moved_shape, axis)
    c = (k - 1) // 2
    out = np.empty_like(y2)
    kernel, ends = _window_weights(k, degree)
    out[c : n - c] = _interior(y2, kernel)
    _apply_ends(y2, out, k, degree, ends)
    return _from_2d(out, moved_shape, axis)


def loess_bruteforce(y: np.ndarray, span: float, x: np.ndarray | None = None) -> np.ndarray:
    """LOESS by its literal definition: one weighted quadratic least-squares fit per sample.

    Slow (a Python loop over samples, O(N k)); it is the reference that :func:`loess` is tested
    against and the way to smooth non-uniformly spaced samples.

    For sample ``i`` the window is the ``k`` samples nearest to ``x[i]`` (a contiguous block
    of the sorted positions; near the ends it shifts rather than shrinks; distance ties go to
    the block further left). ``d`` is the distance to the farthest sample in the window, the
    weights are ``(1 - (|x_j - x[i]| / d)^3)^3`` and the output is the constant term of the
    weighted fit of ``y_j`` on ``[1, t, t^2]``, ``t = x_j - x[i]`` (solved by SVD least squares,
    minimum-norm if the window is degenerate).

    Parameters
    ----------
    y : array_like, shape (N, ...)
        Samples, any unit; other axes are independent channels.
    span : float
        Window: fraction of N if ``< 1``, else a number of samples (see
        :func:`loess_span_samples`).
    x : array_like, shape (N,), optional
        Sample positions (e.g. time in s), any order. Default: uniform ``0..N-1``.
        Following MATLAB, an even ``k`` is made odd only when the positions are uniform
        (``x`` omitted or :func:`is_uniform`); for non-uniform ``x`` ``k`` is used as is.

    Returns
    -------
    ndarray
        Smoothed samples, same shape and unit as ``y`` (float64). ``k == 1`` returns a copy.
    """
    y2, moved_shape = _as_2d(y, 0)
    y_in = y2
    n = y2.shape[0]
    if x is None:
        xs = np.arange(n, dtype=float)
        order = None
        uniform = True
    else:
        x = np.asarray(x, dtype=float)
        if x.shape != (n,):
            raise ValueError(f"x must have shape ({n},), got {x.shape}")
        order = np.argsort(x, kind="stable")
        xs = x[order]
        y2 = y2[order]
        uniform = is_uniform(xs)
    k = loess_span_samples(span, n, make_odd=uniform) if n else 0
    if k <= 1:
        return _from_2d(y_in.copy(), moved_shape, 0)

    out = np.empty_like(y2)
    offsets = np.arange(k)
    for i in range(n):
        # k nearest samples = the contiguous block with the smallest farthest distance.
        starts = np.arange(max(0, i - k + 1), min(i, n - k) + 1)
        reach = np.maximum(xs[i] - xs[starts], xs[starts + k - 1] - xs[i])
        lo = starts[np.argmin(reach)]
        idx = lo + offsets
        t = xs[idx] - xs[i]
        d = np.max(np.abs(t))
        u = t / d if d > 0 else np.zeros_like(t)
        sw = np.sqrt(_tricube(u))
        design = sw[:, None] * np.stack([np.ones_like(u), u, u * u], axis=1)
        coef = np.linalg.lstsq(design, sw[:, None] * y2[idx], rcond=None)[0]
        out[i] = coef[0]
    if order is not None:
        unsorted = np.empty_like(out)
        unsorted[order] = out
        out = unsorted
    return _from_2d(out, moved_shape, 0)


def _robust_fit(y2: np.ndarray, rob: np.ndarray, k: int, previous: np.ndarray) -> np.ndarray:
    """One LOESS pass with per-sample robustness weights ``rob`` (shape of ``y2``, (N, m)).

    Batched 3x3 weighted normal equations in normalised positions ``u``. Windows whose system is
    poorly conditioned (robustness weights removed or nearly removed samples) are solved as
    least squares on the weighted design by SVD (minimum norm if singular), as
    :func:`numpy.linalg.lstsq` would; windows with no weight at all keep ``previous``.
    """
    n, m = y2.shape
    c = (k - 1) // 2
    out = np.empty_like(y2)
    rows_3 = np.arange(3)
    hankel = rows_3[:, None] + rows_3[None, :]

    def solve(tri: np.ndarray, u: np.ndarray, yw: np.ndarray, rw: np.ndarray) -> np.ndarray:
        # tri, u: (k,) or (b, k);  yw, rw: (b, m, k)  ->  fitted constant term (b, m), NaN if
        # the window has no weight.
        powers = u[..., None] ** np.arange(5)  # (k, 5) or (b, k, 5)
        g = tri[..., None, :] * rw  # (b, m, k) combined weights
        s = g @ powers  # (b, m, 5) weighted moments
        a = s[..., hankel]  # (b, m, 3, 3)
        rhs = (g * yw) @ powers[..., :3]  # (b, m, 3)
        diag = np.diagonal(a, axis1=-2, axis2=-1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            quality = np.linalg.det(a) / np.prod(diag, axis=-1)  # 1 if diagonal, 0 if singular
        fit = np.full(a.shape[:-2], np.nan)
        good = np.isfinite(quality) & (quality > _WELL_CONDITIONED)
        if good.any():
            fit[good] = np.linalg.solve(a[good], rhs[good][..., None])[:, 0, 0]
        poor = ~good & (s[..., 0] > 0)
        if poor.any():
            b_idx, m_idx = np.nonzero(poor)
            uu = np.broadcast_to(u, (a.shape[0], k))[b_idx]  # (p, k)
            sw = np.sqrt(g[b_idx, m_idx])  # (p, k)
            design = sw[..., None] * uu[..., None] ** rows_3  # (p, k, 3)
            pinv = np.linalg.pinv(design, rcond=k * np.finfo(float).eps)  # (p, 3, k)
            fit[poor] = np.einsum("pk,pk->p", pinv[:, 0, :], sw * yw[b_idx, m_idx])
        return fit

    # Interior: one window per output, all with the centred geometry.
    u_int, tri_int = _interior_geometry(k)
    yw_all = sliding_window_view(y2, k, axis=0)  # (N-k+1, m, k)
    rw_all = sliding_window_view(rob, k, axis=0)
    n_win = n - k + 1
    block = max(1, _CHUNK_ELEMENTS // (4 * m * k))
    for start in range(0, n_win, block):
        stop = min(n_win, start + block)
        out[c + start : c + stop] = solve(tri_int, u_int, yw_all[start:stop], rw_all[start:stop])

    # Ends: the first c rows share window 0..k-1; the last c rows are the same on reversed data.
    if c:
        u_end, tri_end = _end_geometry(k, np.arange(c))
        for src_y, src_r, rows in (
            (y2[:k], rob[:k], np.arange(c)),
            (y2[::-1][:k], rob[::-1][:k], n - 1 - np.arange(c)),
        ):
            yw = np.broadcast_to(src_y.T[None], (c, m, k))
            rw = np.broadcast_to(src_r.T[None], (c, m, k))
            out[rows] = solve(tri_end, u_end, yw, rw)

    empty = np.isnan(out) & ~np.isnan(previous)
    out[empty] = previous[empty]
    return out


def rloess(y: np.ndarray, span: float, iterations: int = 5, axis: int = 0) -> np.ndarray:
    """Robust LOESS (MATLAB ``smooth(y, span, 'rloess')``) for uniformly sampled data.

    Starts from :func:`loess`, then repeats ``iterations`` times: residuals ``r = y - fit``,
    ``s = median(|r|)`` per channel, bisquare weights ``(1 - (r / (6 s))^2)^2`` (zero for
    ``|r| >= 6 s``) multiplied into the tricube weights, and a new local quadratic fit for every
    sample. Each pass is vectorised: windows via ``sliding_window_view`` and batched 3x3
    weighted normal equations, in chunks.

    Parameters
    ----------
    y : array_like, shape (N, ...)
        Samples at uniform spacing, any unit; other axes are independent channels, each with
        its own robustness weights.
    span : float
        Window: fraction of N if ``< 1``, else a number of samples (see
        :func:`loess_span_samples`).
    iterations : int, optional
        Number of robust passes. Default 5 (MATLAB's).
    axis : int, optional
        Axis along which to smooth. Default 0.

    Returns
    -------
    ndarray
        Smoothed samples, same shape and unit as ``y`` (float64). ``k <= 3`` returns a copy.

    Notes
    -----
    ``s`` is floored at ``100 * eps * max|y|`` per channel so that an exact fit (residuals at
    round-off level) keeps full weights instead of amplifying round-off. A window whose weighted
    system is singular uses the minimum-norm solution; one whose weights are all zero keeps the
    previous pass's value. With ``k = 5`` the interior plain fit is exact, so ``s`` is set by
    the few end residuals (or the floor) and the result is sensitive to round-off; use
    ``k >= 7`` for meaningful robustness. Cost per pass O(N k); about 1 s per 1e6 samples for
    ``k = 21``. Outputs whose window contains a NaN are NaN.
    """
    if int(iterations) != iterations or iterations < 0:
        raise ValueError(f"iterations must be a non-negative integer, got {iterations}")
    y2, moved_shape = _as_2d(y, axis)
    n = y2.shape[0]
    k = loess_span_samples(span, n) if n else 0
    if k <= 3:
        return _from_2d(y2.copy(), moved_shape, axis)
    fit = loess(y2, k)
    floor = 100 * np.finfo(float).eps * np.nanmax(np.abs(y2), axis=0)
    for _ in range(int(iterations)):
        resid = y2 - fit
        s = np.maximum(np.nanmedian(np.abs(resid), axis=0), floor)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(s > 0, resid / (6.0 * s), 0.0)
        rob = np.where(np.abs(z) < 1.0, (1.0 - z**2) ** 2, 0.0)
        fit = _robust_fit(y2, rob, k, fit)
    return _from_2d(fit, moved_shape, axis)


# --------------------------------------------------------------------------------------------
# Derivatives, resampling, filtering
# --------------------------------------------------------------------------------------------


def central_difference(y: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """First derivative along axis 0 by finite differences, exact for quadratics.

    Interior: three-point central difference for non-uniform spacing,
    ``y'_i = -h2/(h1(h1+h2)) y_{i-1} + (h2-h1)/(h1 h2) y_i + h1/(h2(h1+h2)) y_{i+1}`` with
    ``h1 = t_i - t_{i-1}``, ``h2 = t_{i+1} - t_i``. Ends: second-order one-sided three-point
    differences. (This is ``numpy.gradient(..., edge_order=2)``.) With two samples the result
    is the single slope.

    Parameters
    ----------
    y : array_like, shape (N, ...)
        Samples, unit ``[y]``; other axes are independent channels.
    t : array_like, shape (N,), or float
        Strictly increasing sample times in s, or a scalar sample interval ``dt`` in s.

    Returns
    -------
    ndarray, shape (N, ...)
        Derivative, unit ``[y]/s``.
    """
    y = np.asarray(y, dtype=float)
    n = y.shape[0] if y.ndim else 0
    if n < 2:
        raise ValueError(f"central_difference needs at least 2 samples, got {n}")
    if np.ndim(t) == 0:
        dt = float(t)
        if not dt > 0:
            raise ValueError(f"dt must be positive, got {dt}")
        spacing: float | np.ndarray = dt
    else:
        spacing = np.asarray(t, dtype=float)
        if spacing.shape != (n,):
            raise ValueError(f"t must have shape ({n},), got {spacing.shape}")
        if not np.all(np.diff(spacing) > 0):
            raise ValueError("t must be strictly increasing")
    return np.gradient(y, spacing, axis=0, edge_order=2 if n >= 3 else 1)


def five_point_difference(y: np.ndarray, dt: float) -> np.ndarray:
    """First derivative along axis 0 of uniformly sampled ``y`` (N, …), exact for quartics.

    Interior: ``(y[i-2] - 8 y[i-1] + 8 y[i+1] - y[i+2]) / (12 dt)`` (its error is
    −dt⁴ y⁽⁵⁾/30, against dt² y⁽³⁾/6 for the three-point difference); the two samples at each
    end: :func:`central_difference`. Used after the quartic smoother, whose own error is of
    higher order than three-point differences'.
    """
    y = np.asarray(y, dtype=float)
    out = central_difference(y, dt)
    if y.shape[0] >= 5:
        out[2:-2] = (y[:-4] - 8.0 * y[1:-3] + 8.0 * y[3:-1] - y[4:]) / (12.0 * dt)
    return out


def is_uniform(t: np.ndarray, rtol: float = 1e-6) -> bool:
    """Whether samples are evenly spaced.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times (any unit, e.g. s).
    rtol : float, optional
        Largest allowed deviation of any step from the mean step, relative to the mean step.

    Returns
    -------
    bool
        True if every step is within ``rtol`` of the mean step and the mean step is non-zero
        (fewer than three samples: True unless the two are equal).
    """
    t = np.asarray(t, dtype=float).ravel()
    if t.size < 2:
        return True
    step = (t[-1] - t[0]) / (t.size - 1)
    if step == 0 or not np.isfinite(step):
        return False
    return bool(np.max(np.abs(np.diff(t) - step)) <= rtol * abs(step))


def resample_uniform(
    t: np.ndarray, y: np.ndarray, dt: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Put jittered samples on a uniform time grid by linear interpolation.

    Parameters
    ----------
    t : array_like, shape (N,)
        Strictly increasing sample times in s.
    y : array_like, shape (N, ...)
        Samples, any unit; other axes are independent channels.
    dt : float, optional
        Grid step in s. Default: median of ``diff(t)``.

    Returns
    -------
    t_new : ndarray, shape (M,)
        ``t[0] + dt * arange(M)``, the longest such grid not beyond ``t[-1]`` (a last point
        within round-off of ``t[-1]`` is kept and clipped to it).
    y_new : ndarray, shape (M, ...)
        ``y`` linearly interpolated at ``t_new``, per channel, same unit.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = t.size
    if t.ndim != 1 or n < 1 or y.shape[:1] != (n,):
        raise ValueError(f"t must be 1-D with len(t) == len(y); got t {t.shape}, y {y.shape}")
    if n == 1:
        return t.copy(), y.copy()
    steps = np.diff(t)
    if not np.all(steps > 0):
        raise ValueError("t must be strictly increasing")
    dt = float(np.median(steps)) if dt is None else float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive, got {dt}")
    m = int(np.floor((t[-1] - t[0]) / dt * (1 + 1e-12) + 1e-9)) + 1
    t_new = np.minimum(t[0] + dt * np.arange(m), t[-1])
    idx = np.clip(np.searchsorted(t, t_new, side="right") - 1, 0, n - 2)
    frac = (t_new - t[idx]) / steps[idx]
    frac = frac.reshape((m,) + (1,) * (y.ndim - 1))
    y_new = y[idx] + frac * (y[idx + 1] - y[idx])
    return t_new, y_new
