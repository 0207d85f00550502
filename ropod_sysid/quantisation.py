"""An encoder's quantisation error: its variance, what a filter passes of it, and recognising a
quantised log.

An angle quantised to counts of 2π/N has an error uniform over a count: variance
(2π/N)²/12 (:func:`encoder_variance`). That error is white per sample only while the angle
moves a count per sample or more, or while the sample instants' jitter spreads it over
several counts. A slower angle steps rarely and its error is a sampled sawtooth of c cycles
per sample (c counts per sample), whose harmonics a filter passes by its gain there
(:func:`sawtooth_share`); an angle moving steadily is a tone at c mod 1, and through a row's
window each channel's error is the sawtooth of its motion there, averaged over where the
count grid lies (:func:`tone_share`, the motion from :func:`window_motion`). These shares,
relative to the white variance σ² ‖g‖² of the whole kernel g, are what
:mod:`ropod_sysid.noise` multiplies its white-noise terms by. A log whose angles move by whole
counts is recognised by :func:`detect_encoder_counts`, and the fit says so
(:func:`counts_note`).
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ropod_sysid.io.log import Log

__all__ = ["counts_note", "detect_encoder_counts", "encoder_variance", "log_encoder_counts",
           "sawtooth_share", "tone_share", "window_motion"]


def encoder_variance(counts: int) -> float:
    """Variance of a quantised angle [rad²]: one count 2π/counts, uniform."""
    return (2.0 * math.pi / counts) ** 2 / 12.0


@functools.lru_cache(maxsize=16)
def _sawtooth_table(kernel: bytes, points: int = 512, harmonics: int = 400
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(c, share) on [0, 1] counts per sample for the kernel (bytes of float64)."""
    g = np.frombuffer(kernel)
    n_fft = 1 << 15
    f = np.fft.rfftfreq(n_fft)
    h2 = np.abs(np.fft.rfft(g, n_fft)) ** 2
    c = np.linspace(0.0, 1.0, points + 1)
    k = np.arange(1, harmonics + 1)
    fr = np.outer(c, k) % 1.0
    fr = np.minimum(fr, 1.0 - fr)  # |H|² is even and of period 1 (aliasing)
    # a sawtooth of c cycles per sample: harmonics k c of power step²/(2π²k²); white: step²/12
    # (the harmonics past the last hold 1/(1.64 harmonics) of the power: 0.15 %)
    share = (6.0 / np.pi**2) * (np.interp(fr, f, h2) / k**2).sum(axis=-1) / np.sum(g**2)
    return c, share


def sawtooth_share(kernel: np.ndarray, counts_per_sample: np.ndarray) -> np.ndarray:
    """The variance of a kernel's output for an angle quantised while it moves ``c`` counts per
    sample, over the white noise's (step²/12 ‖g‖²): below a count per sample the error is a
    sampled sawtooth of c cycles per sample, whose harmonics k c (power step²/(2π²k²)) the
    kernel passes by |H(k c)|² (aliased); white from one count on. (Measured on the
    steered-four's steering angles: 0.6, 1.5, 2.5 for c in 0.02–0.05, 0.05–0.1, 0.1–0.2
    against 0.71, 1.51, 2.57 by this formula; the share is not c, which is 10–25× smaller.)"""
    c, share = _sawtooth_table(np.ascontiguousarray(kernel, float).tobytes())
    a = np.abs(counts_per_sample)
    return np.where(a >= 1.0, 1.0, np.interp(a, c, share))


# tone_share: a channel whose jitter spreads it over this many counts (2 |c| J) is white: the
# tone's part of each lag's covariance is then under 1/(15 w²) of the white one's (0.1 %)
DITHERED = 8.0
# tone_share: about this many (lag, node) terms per channel and row: 7 nodes per lag for the
# kernels of 100–200 Hz logs (L ≈ 25–45 taps), 3 at 1 kHz (L ≈ 205), 1 for longer kernels
TONE_TERMS = 640
# tone_share takes its nodes for a channel whose acceleration a bends its motion over the
# kernel's L taps by |a| L² ≥ CHIRP_BENT counts, else one node per lag (they would coincide)
CHIRP_BENT = 1.0


def tone_nodes(size: int) -> int:
    """Nodes per lag (odd, 1–7) of :func:`tone_share` for a kernel of ``size`` taps."""
    q = max(1, min(7, TONE_TERMS // max(size, 1)))
    return q if q % 2 else q - 1


@functools.lru_cache(maxsize=16)
def _lag_table(kernel: bytes, nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                     np.ndarray, float]:
    """A kernel's (bytes of float64) pairs of taps grouped for :func:`tone_share`: for each lag
    m ≥ 1 its pairs (s, s + m) in ``nodes`` groups of about equal Σ |g_s g_(s+m)| in the order of
    their centres μ (offsets from the kernel's middle), each group a row of (m, its Σ g_s
    g_(s+m), its centre and 6 m² times its variance of the centres, both weighted
    |g_s g_(s+m)|); and ‖g‖². Lags whose pairs are all zero are left out."""
    g = np.frombuffer(kernel)
    g2 = float(g @ g)
    first, second = np.triu_indices(g.size, 1)
    order = np.lexsort((first, second - first))  # by lag, then by centre
    first, second = first[order], second[order]
    lag = second - first
    w = g[first] * g[second]
    aw = np.abs(w)
    mid = 0.5 * (first + second) - 0.5 * (g.size - 1)
    start = np.flatnonzero(np.r_[True, lag[1:] != lag[:-1]])  # each lag's first pair
    which = np.repeat(np.arange(start.size), np.diff(np.r_[start, lag.size]))
    total = np.add.reduceat(aw, start)
    cum = np.cumsum(aw)
    within = cum - np.r_[0.0, cum][start][which] - 0.5 * aw  # |w| before the pair, in its lag
    group = np.minimum((within * (nodes / np.maximum(total, 1e-300))[which]).astype(int),
                       nodes - 1)
    key = which * nodes + group
    size = start.size * nodes
    t = np.bincount(key, aw, size)
    keep = (t > 0) & np.repeat(total > 1e-15 * g2, nodes)
    t = np.where(keep, t, 1.0)
    mu = np.bincount(key, aw * mid, size) / t
    var = np.maximum(np.bincount(key, aw * mid**2, size) / t - mu**2, 0.0)
    m = np.repeat(lag[start], nodes).astype(float)
    return (m[keep], np.bincount(key, w, size)[keep], mu[keep], 6.0 * m[keep] ** 2 * var[keep],
            g2)


def _bernoulli4(x: np.ndarray) -> np.ndarray:
    """({x} (1 − {x}))² = B₄({x}) + 1/30, in place of x: the sawtooth's autocovariance B₂/2
    integrated twice (times 24), periodic (for :func:`tone_share`)."""
    x -= np.floor(x)
    x *= x - 1.0
    x *= x
    return x


def tone_share(kernel: np.ndarray, rate: np.ndarray, accel: np.ndarray, jitter: float = 0.0,
               nodes: int | None = None, chunk: int = 1 << 15) -> np.ndarray:
    """The variance of a kernel's output for an angle quantised while it moves through the
    kernel's window as x(μ) = c μ + ½ a μ² counts (``rate`` c [counts/sample] and ``accel``
    a [counts/sample²], (N, J), μ the offset from the window's centre), over the white noise's
    (step²/12 ‖g‖²), expected over where the encoder's count grid lies (its zero).

    The error e = round(x) − x [counts] of two samples whose positions differ by u counts has
    the covariance ρ(u) = B₂({u})/2 = Σ_{k≥1} cos(2πku) / (2π²k²) over the grid's zero (B₂ the
    second Bernoulli polynomial, {u} the fractional part; ρ(0) = 1/12, the white variance), so
    with every harmonic of the sawtooth

        share = 1 + (24 / ‖g‖²) Σ_{m≥1} Σ_{s} g_s g_(s+m) ρ(x(μ_s + m) − x(μ_s)),

    and a pair at lag m centred at μ differs by m (c + a μ) counts. At a steady rate (a = 0)
    this is Σ_m R(m) ρ(m c), R the kernel's autocorrelation: the error is a tone at (c mod 1)
    cycles per sample (and its harmonics), which the kernel passes where k c is near a whole
    number, not white noise (a slow angle, c < 1, gives :func:`sawtooth_share`). Each lag's
    pairs are taken in ``nodes`` groups by their centres (:func:`_lag_table`; default
    :func:`tone_nodes` of the kernel's length, which bounds the work), each at its mean centre
    μ_q with the spread of its centres as a triangle of the same variance, together with the
    jitter: sample instants jittered uniformly by ±J samples (``jitter``; the log's times are
    the true instants, which the fit resamples) move a sample's position by r j (r = c + a μ_q),
    the difference of two such moves is triangular over ±2 |r| J (for a steady rate exact: the
    harmonic k of a pair's covariance scaled by sinc²(2 k r J)). ρ through a triangle of
    half-width w is

        [Q(u + w) − 2 Q(u) + Q(u − w)] / (24 w²),   Q = ({u} (1 − {u}))²

    (Q'' = 12 B₂ = 24 ρ), w² = (2 r J)² + 6 m² a² σ_q² (at least 10⁻⁸). A jitter that spreads a
    channel over ``DITHERED`` counts or more makes its error white (share 1); a channel at rest
    has none (0); one whose acceleration bends its motion over the kernel's L taps by less than
    ``CHIRP_BENT`` counts (|a| L²) takes one node per lag. Exact (every harmonic) at a steady
    rate without jitter. Against the sum over the sawtooth's first 64 harmonics with each tap's
    own rate and jitter (the exact quadratic motion; 10–30× the time), the predicted inertial
    gram diagonals of ``benchmarks/counts.py``'s steered-four, the ropod's 60 s typical run at
    100 Hz and its 20 s one at 1 kHz (zeros at random) agree within 1.1, 1.2 and 1.2 % (one
    node per lag: 5.3, 4.5, 5.5 %). Measured (quantised − exact rows, ``benchmarks/counts.py``),
    predicted / empirical of the inertial columns' diagonals and (E m)_j per row kind, the
    white share (:func:`sawtooth_share` of the row's rate) → this one: steered-four's x and y
    rows 0.89–2.47 → 0.85–0.99 (its θ rows 0.16–0.98 → 0.26–0.96: the θ kind there is not
    this), the ropod's 60 s run at 100 Hz 0.67–1.53 → 0.73–1.01 (with the shipped sample's
    ±0.5 ms jitter 0.89–1.06 → 0.91–1.07), its 20 s one at 1 kHz 0.63–1.58 → 0.70–1.30
    (zeros at random 0.86–1.51 → 0.90–1.13; at 0 its symmetric wheels' errors are alike), the
    off-square ropod's 30 s one at 1 kHz 1.34–1.77 → 0.91–1.03, steered-swivel within 0.07.
    O(N J L nodes), in chunks of about ``chunk`` terms."""
    g = np.ascontiguousarray(kernel, float)
    q = tone_nodes(g.size) if nodes is None else int(nodes)
    c = np.asarray(rate, float).reshape(-1)
    a = np.asarray(accel, float).reshape(-1)
    dj = (2.0 * jitter) ** 2
    out = np.ones(c.size)
    moving = (c != 0) | (a != 0)
    out[~moving] = 0.0
    work = moving & (dj * c * c < DITHERED**2)
    fine = work & (np.abs(a) * g.size**2 >= CHIRP_BENT) if q > 1 else np.zeros_like(work)
    for nq, sel in ((1, work & ~fine), (q, fine)):
        if sel.any():
            out[sel] = _tone_terms(_lag_table(g.tobytes(), nq), c[sel], a[sel], dj, chunk)
    return np.maximum(out, 0.0).reshape(np.shape(rate))


def _tone_terms(table: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float],
                c: np.ndarray, a: np.ndarray, dj: float, chunk: int) -> np.ndarray:
    """:func:`tone_share`'s sum over the (lag, node) rows of ``table`` (:func:`_lag_table`) for
    channels at rates c and accelerations a (n,), ``dj`` = (2 J)²."""
    lag, weight, mu, spread, g2 = table
    out = np.empty(c.size)
    rows = max(1, chunk // lag.size)
    for i in range(0, c.size, rows):
        sel = slice(i, i + rows)
        r = c[sel, None] + a[sel, None] * mu  # each node's rate
        u = r * lag
        u -= np.floor(u)  # (ρ has period 1; a small w then keeps its digits)
        w2 = a[sel, None] ** 2 * spread
        if dj > 0:
            w2 += dj * r * r
        np.maximum(w2, 1e-8, out=w2)
        w = np.sqrt(w2)
        rho = _bernoulli4(u + w)
        rho += _bernoulli4(u - w)
        u *= u - 1.0
        u *= u
        rho -= 2.0 * u
        rho /= w2  # 24 ρ
        out[sel] = 1.0 + (rho @ weight) / g2
    return out


def window_motion(pre: object, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The angle channels' rates [rad/s] and accelerations [rad/s²] (each (N, J)) through the
    window of each row at samples ``index`` of ``pre``: a straight line through the smoothed
    rates of the samples within the rows' halo (:attr:`RowGrid.halo`: those a streamed block
    holds around its rows, so streamed and whole logs agree), for :func:`tone_share`."""
    rates = pre.angle_rates  # type: ignore[attr-defined]
    h = int(pre.grid.halo)  # type: ignore[attr-defined]
    off = np.arange(-h, h + 1)
    at = np.clip(np.asarray(index)[:, None] + off, 0, rates.shape[0] - 1)  # (N, L)
    inside = (np.asarray(index)[:, None] + off >= 0) & (np.asarray(index)[:, None] + off
                                                         < rates.shape[0])
    w = inside.astype(float)
    s = off.astype(float) * pre.dt  # type: ignore[attr-defined]
    sw, sws, swss = w.sum(1), (w * s).sum(1), (w * s * s).sum(1)
    r = rates[at]  # (N, L, J)
    ry = np.einsum("nl,nlj->nj", w, r)
    rsy = np.einsum("nl,nlj->nj", w * s, r)
    det = sw * swss - sws**2
    det = np.where(det > 0, det, np.inf)
    accel = (sw[:, None] * rsy - sws[:, None] * ry) / det[:, None]
    rate = (ry - sws[:, None] * accel) / sw[:, None]
    return rate, accel


# detect_encoder_counts(): finer steps (under 0.4 µrad) are a writer's rounding of exact angles
# (7 decimals: 2π/1e-7 ≈ 6.3e7 "counts"), not an encoder's, and too small to bias a fit
MAX_DETECTED_COUNTS = 2**24


def detect_encoder_counts(angles: np.ndarray, wrapped: np.ndarray | None = None) -> int | None:
    """The counts per revolution of encoders whose angles (N, J) [rad] move by whole counts,
    or None when they do not (exact or resampled angles). The count is the smallest step of
    any channel (or its half or third, when that step is two or three counts), refined on the
    steps of up to 50 counts, accepted when 99 % of the steps are whole numbers of it (to 0.1
    count: a log written with 8 digits rounds its angles) and 2π is a whole number of it (to
    0.1 %), and at most :data:`MAX_DETECTED_COUNTS`. ``wrapped`` (J,): channels wrapped to ±π,
    whose steps across the wrap are taken modulo 2π."""
    a = np.asarray(angles, float)
    if a.ndim != 2 or a.shape[0] < 3:
        return None
    d = np.diff(a, axis=0)
    if wrapped is not None and np.any(wrapped):
        w = np.asarray(wrapped, bool)
        d[:, w] = np.angle(np.exp(1j * d[:, w]))
    steps = np.abs(d[np.abs(d) > 1e-12])
    if steps.size < 10:
        return None
    smallest = float(steps.min())
    for div in (1, 2, 3):
        q = smallest / div
        # refined on the small steps (a log written with 8 digits rounds each angle)
        k = np.round(steps / q)
        small = (k >= 1) & (k <= 50)
        if not small.any():
            continue
        q = float(steps[small].sum() / k[small].sum())
        ratio = steps / q
        if np.mean(np.abs(ratio - np.round(ratio)) < 0.1) < 0.99:
            continue
        counts = 2.0 * math.pi / q
        if (abs(counts - round(counts)) < 1e-3 * counts
                and 16 <= round(counts) <= MAX_DETECTED_COUNTS):
            return int(round(counts))
    return None


def log_encoder_counts(log: Log) -> int | None:
    """:func:`detect_encoder_counts` of a log's encoder channels (its layout's ``encoders``;
    a leg's extension is no rotary encoder), the wrapped ones taken modulo 2π."""
    enc = log.layout.encoders
    return detect_encoder_counts(log.angles[:, enc], np.asarray(log.layout.wrapped)[enc])


def counts_note(source: str, detected: int | None, given: int | None,
                constrained: bool = False, quartic: bool = False) -> str | None:
    """The note on a log whose angles move by whole counts of its encoders
    (:func:`detect_encoder_counts`) when the fit was not told them, or was told others.
    ``constrained``: a platform whose constraint forces the fit projects out (steered wheels,
    legs), where the correction was measured to over-correct on three of four simulated
    platforms (docs/accuracy.md). ``quartic``: a LOESS fit whose span holds the quartic
    smoother's samples (:data:`ropod_sysid.recipe.QUARTIC_MIN_SAMPLES`), which with the
    correction keeps the LOESS's bias out of long logs (as ``inspect`` advises:
    :func:`ropod_sysid.inspect.fit_suggestion`). (What ``--input-delay auto`` did with the
    counts is the search's own note: :func:`ropod_sysid.delay.search_counts_note`.)"""
    if detected is None or detected == given:
        return None
    if given is None:
        check = ("; on a platform with steered wheels or legs it can over-correct: compare "
                 "the two fits") if constrained else ""
        also = ("; at this rate with --smoother quartic --input-delay auto, which keep the "
                "LOESS's bias out of a long log's values") if quartic else ""
        return (f"{source}: the angles move by whole counts of 2π/{detected}; give "
                f"--encoder-counts {detected} to correct the fit for the encoders' "
                f"quantisation (its errors in the accelerations shrink the values){also}{check}")
    return (f"{source}: the angles move by whole counts of 2π/{detected}, not of the "
            f"--encoder-counts {given} given; check the encoders' resolution")
