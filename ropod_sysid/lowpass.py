"""Low-pass filtering: the disturbance observer's causal second-order Butterworth filter.

Small pure functions in the style of :mod:`scipy.signal`, along axis 0 (or ``axis``) with
every other axis an independent channel. The second-order filter needs no :mod:`scipy.signal`
(1.5–2.2 s to import with scipy 1.17, longer than a fit of the shipped sample): its recursion
is a banded lower-triangular solve (LAPACK's ``dtbtrs`` through :mod:`scipy.linalg`), and its
state carries from chunk to chunk (:class:`Biquad`), so a log streamed in chunks is filtered as
the whole. Other orders and the zero-phase filter use :mod:`scipy.signal`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["Biquad", "butter2_lowpass", "lowpass"]


class Biquad:
    """A causal second-order IIR filter y_n = b₀x_n + b₁x_{n−1} + b₂x_{n−2} − a₁y_{n−1} −
    a₂y_{n−2} (a₀ = 1) that keeps its state from chunk to chunk, as ``scipy.signal.lfilter``
    with ``zi``: the chunks filtered one after the other give the whole signal filtered.

    A chunk is one banded solve, not a loop over samples: the recursion is the lower-triangular
    banded Toeplitz system L y = B x (L's diagonals 1, a₁, a₂), solved by LAPACK's ``dtbtrs``
    (forward substitution, the recursion itself; equal to ``scipy.signal.sosfilt`` to 1e-15
    relative, and no 1.5-2 s import of :mod:`scipy.signal`). ``b``, ``a``: (3,) each."""

    def __init__(self, b: np.ndarray, a: np.ndarray) -> None:
        a = np.asarray(a, float)
        self.b, self.a = np.asarray(b, float) / a[0], a / a[0]
        self.x_past: np.ndarray | None = None  # the last two inputs (2, …), oldest first
        self.y_past: np.ndarray | None = None  # the last two outputs

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The next chunk x (N, …) filtered along axis 0 (zero state before the first)."""
        from scipy.linalg import lapack

        x = np.asarray(x, float)
        n, shape = x.shape[0], x.shape[1:]
        if self.x_past is None or self.y_past is None:
            self.x_past, self.y_past = np.zeros((2, *shape)), np.zeros((2, *shape))
        if n == 0:
            return x.copy()
        b, a = self.b, self.a
        xe = np.concatenate([self.x_past, x]).reshape(n + 2, -1)
        r = b[0] * xe[2:] + b[1] * xe[1:-1] + b[2] * xe[:-2]
        yp = self.y_past.reshape(2, -1)
        r[0] -= a[1] * yp[1] + a[2] * yp[0]
        if n > 1:
            r[1] -= a[2] * yp[1]
        ab = np.zeros((3, n))  # L in LAPACK's lower band storage: ab[i − j, j] = L[i, j]
        ab[0], ab[1, :-1], ab[2, :-2] = 1.0, a[1], a[2]
        y, info = lapack.dtbtrs(ab, r, uplo="L")
        if info != 0:  # pragma: no cover - the diagonal is 1
            raise np.linalg.LinAlgError(f"dtbtrs failed (info {info})")
        y = y.reshape(n, *shape)
        self.x_past = np.concatenate([self.x_past, x])[-2:]
        self.y_past = np.concatenate([self.y_past, y])[-2:]
        return y


def butter2_lowpass(dt: float, cutoff_hz: float) -> Biquad:
    """The second-order Butterworth low-pass of -3 dB frequency ``cutoff_hz`` [Hz] for samples
    ``dt`` [s] apart, as a :class:`Biquad`: the analogue prototype 1 / (s² + √2 s + 1) by the
    bilinear transform with the cut-off prewarped, K = tan(π f_c dt):
    b = K² (1, 2, 1) / c, a = (1, 2 (K² − 1) / c, (1 − √2 K + K²) / c), c = 1 + √2 K + K²
    (the coefficients of ``scipy.signal.butter(2, cutoff_hz, fs=1 / dt)`` to round-off)."""
    dt = float(dt)
    if not dt > 0:
        raise ValueError(f"dt must be positive, got {dt}")
    if not 0 < cutoff_hz < 0.5 / dt:
        raise ValueError(f"cutoff_hz must be in (0, {0.5 / dt:g}) Hz for dt = {dt:g} s")
    k = math.tan(math.pi * float(cutoff_hz) * dt)
    c = 1.0 + math.sqrt(2.0) * k + k * k
    return Biquad(np.array([k * k, 2 * k * k, k * k]) / c,
                  np.array([c, 2.0 * (k * k - 1.0), 1.0 - math.sqrt(2.0) * k + k * k]) / c)


def lowpass(
    y: np.ndarray,
    dt: float,
    cutoff_hz: float,
    order: int = 2,
    zero_phase: bool = False,
    axis: int = 0,
) -> np.ndarray:
    """Butterworth low-pass filter (e.g. the disturbance observer's 10 Hz filter).

    Parameters
    ----------
    y : array_like
        Uniformly sampled signal, any unit.
    dt : float
        Sample interval in s.
    cutoff_hz : float
        -3 dB cut-off frequency in Hz, below the Nyquist frequency ``1 / (2 dt)``.
    order : int, optional
        Filter order. Default 2.
    zero_phase : bool, optional
        False (default): causal, from zero initial state (phase lag, start-up transient;
        second order: :func:`butter2_lowpass`, else ``scipy.signal.sosfilt``). True:
        forward-backward ``sosfiltfilt`` (no lag, squared magnitude response, non-causal).
    axis : int, optional
        Time axis. Default 0.

    Returns
    -------
    ndarray
        Filtered signal, same shape and unit as ``y``.
    """
    dt = float(dt)
    if not dt > 0:
        raise ValueError(f"dt must be positive, got {dt}")
    fs = 1.0 / dt
    if not 0 < cutoff_hz < fs / 2:
        raise ValueError(f"cutoff_hz must be in (0, {fs / 2:g}) Hz for dt = {dt:g} s")
    y = np.asarray(y, dtype=float)
    if int(order) == 2 and not zero_phase:
        return np.moveaxis(butter2_lowpass(dt, cutoff_hz)(np.moveaxis(y, axis, 0)), 0, axis)
    from scipy import signal as _signal  # imported here: it takes longer to load than a fit

    sos = _signal.butter(int(order), float(cutoff_hz), btype="low", fs=fs, output="sos")
    if zero_phase:
        return _signal.sosfiltfilt(sos, y, axis=axis)
    return _signal.sosfilt(sos, y, axis=axis)
