"""What the report plots of a log, gathered while the log streams, in memory bounded by a fixed
number of points whatever the log's length.

The fit pass (:mod:`ropod_sysid.stream`) hands every block of samples and of equation rows to a
:class:`PlotGather`; the report draws from the :class:`LogPlot` it returns, so a report does
not read or preprocess the logs again:

- :class:`Envelope`: a min/max envelope of signals over time (inputs, states): per bucket of
  consecutive samples each column's minimum and maximum with their time, the bucket size
  doubling whenever there would be more than ``max_buckets`` buckets, so that a single spike
  in a long log still shows (the envelope of the envelope is the envelope);
- :class:`RowSample`: every s-th equation row A_ID,ext, b_ID (eq. 36), s doubling whenever more
  than ``max_rows`` would be kept, so that after the solve the fit A_ID,ext m* and the error
  b_ID − A_ID,ext m* can be drawn (the thesis's Fig. 13) and their histograms taken. Every
  figure computed from the triangles (RMS, singular values) still uses every row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_BUCKETS = 2048  # envelope buckets per signal (the figures draw ~2000 points per line)
MAX_ROWS = 8192  # equation rows kept per log (all rows of the shipped 60 s, 100 Hz sample)


def _extremes(x: np.ndarray, y: np.ndarray, idx0: int, width: int, largest: bool,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per run of ``width`` consecutive samples of y (m, k), m a multiple of ``width`` (one
    run if ``width`` is m): each column's first smallest (``largest``: largest) value, NaN
    ignored, with its sample index (from ``idx0``) and x. Returns i, x, y of shape (g, k)."""
    m, k = y.shape
    runs = y.reshape(m // width, width, k)
    fill = -np.inf if largest else np.inf
    nan = np.isnan(runs)
    clean = np.where(nan, fill, runs) if nan.any() else runs
    pick = (np.argmax if largest else np.argmin)(clean, axis=1)  # (g, k)
    rows = pick + (np.arange(m // width) * width)[:, None]
    return idx0 + rows, x[rows], np.take_along_axis(y, rows, axis=0)


def _merge_neighbours(group: np.ndarray, ext: dict[str, tuple[np.ndarray, ...]],
                      ) -> tuple[np.ndarray, dict[str, tuple[np.ndarray, ...]]]:
    """Entries in sample order whose group equals the next one's (pairs at most) merged into
    one: the smaller (``lo``) or larger (``hi``) value, the earlier one on a tie or NaN."""
    same = np.flatnonzero(group[1:] == group[:-1])
    if not same.size:
        return group, ext
    keep = np.ones(group.size, bool)
    keep[same + 1] = False
    out: dict[str, tuple[np.ndarray, ...]] = {}
    for side, (i, x, y) in ext.items():
        a, b = y[same], y[same + 1]
        with np.errstate(invalid="ignore"):
            later = (b > a if side == "hi" else b < a) | (np.isnan(a) & ~np.isnan(b))
        i, x, y = i.copy(), x.copy(), y.copy()
        for arr in (i, x, y):
            arr[same] = np.where(later, arr[same + 1], arr[same])
        out[side] = (i[keep], x[keep], y[keep])
    return group[keep], out


class Envelope:
    """Streaming min/max decimation of columns ``y`` (n, k) over ``x`` (n,)."""

    def __init__(self, max_buckets: int = MAX_BUCKETS) -> None:
        self.max_buckets = max(int(max_buckets), 1)
        self.size = 1  # samples per bucket
        self.seen = 0
        # bucket ids (g,) and per extreme (lo, hi): sample index, x and y (g, k)
        self.group = np.zeros(0, dtype=np.int64)
        self.ext: dict[str, tuple[np.ndarray, ...]] = {}

    def push(self, x: np.ndarray, y: np.ndarray) -> None:
        x = np.asarray(x, float)
        y = np.asarray(y, float).reshape(len(x), -1)
        m, size, s0 = len(x), self.size, self.seen
        if not m:
            return
        self.seen += m
        # a partial bucket at each end, whole buckets between (merged with the neighbours
        # of the same bucket: the last one kept and the next block's first)
        a = min(m, -s0 % size)
        b = a + (m - a) // size * size
        pieces = [(lo, hi, w) for lo, hi, w in ((0, a, a), (a, b, size), (b, m, m - b)) if hi > lo]
        groups, ext = [self.group], {side: [v] for side, v in self.ext.items()}
        for lo, hi, w in pieces:
            groups.append((s0 + lo) // size + np.arange((hi - lo) // w))
            for side in ("lo", "hi"):
                ext.setdefault(side, []).append(
                    _extremes(x[lo:hi], y[lo:hi], s0 + lo, w, side == "hi"))
        group = np.concatenate(groups)
        joined = {side: tuple(np.concatenate(v) for v in zip(*parts, strict=True))
                  for side, parts in ext.items()}
        self.group, self.ext = _merge_neighbours(group, joined)
        while self.group.size > self.max_buckets:
            self.size *= 2
            self.group, self.ext = _merge_neighbours(self.group // 2, self.ext)

    def lines(self, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """x (m, k) and y (m, k): each column's extremes in the order of the samples."""
        if not self.group.size:
            return np.zeros((0, k)), np.zeros((0, k))
        (i_lo, x_lo, y_lo), (i_hi, x_hi, y_hi) = self.ext["lo"], self.ext["hi"]
        if self.size == 1:  # every sample is its own bucket
            return x_lo, y_lo
        first = i_lo <= i_hi
        xs = np.stack([np.where(first, x_lo, x_hi), np.where(first, x_hi, x_lo)], axis=1)
        ys = np.stack([np.where(first, y_lo, y_hi), np.where(first, y_hi, y_lo)], axis=1)
        return xs.reshape(-1, xs.shape[-1]), ys.reshape(-1, ys.shape[-1])


class RowSample:
    """Every ``stride``-th row of a stream of rows (t, A, b, q̇ and the rows' state), at most
    ``max_rows`` kept."""

    def __init__(self, max_rows: int = MAX_ROWS) -> None:
        self.max_rows = max(int(max_rows), 1)
        self.stride = 1
        self.seen = 0
        self.parts: list[tuple[np.ndarray, ...]] = []
        self.kept = 0

    def push(self, t: np.ndarray, *arrays: np.ndarray) -> None:
        idx = self.seen + np.arange(len(t))
        self.seen += len(t)
        keep = idx % self.stride == 0
        if not keep.any():
            return
        self.parts.append((idx[keep], t[keep], *(v[keep] for v in arrays)))
        self.kept += int(keep.sum())
        while self.kept > self.max_rows:
            self.stride *= 2
            joined = self.arrays(with_index=True)
            keep = joined[0] % self.stride == 0
            self.parts = [tuple(v[keep] for v in joined)]
            self.kept = int(keep.sum())

    def arrays(self, with_index: bool = False) -> tuple[np.ndarray, ...]:
        """(t, A, b, q̇, …) of the kept rows (with their row numbers first if asked)."""
        if not self.parts:
            raise ValueError("no rows")
        joined = tuple(np.concatenate(v) for v in zip(*self.parts, strict=True))
        self.parts = [joined]
        return joined if with_index else joined[1:]


@dataclass
class LogPlot:
    """What the report draws of one log (bounded in size; see the module docstring)."""

    t_rows: np.ndarray  # (r,) time of the kept equation rows
    a_rows: np.ndarray  # (r, 3, p) filtered A_ID,ext at those rows
    b_rows: np.ndarray  # (r, 3) filtered b_ID
    qd_rows: np.ndarray  # (r, 3) base velocities
    row_stride: int  # kept one in every row_stride rows
    path: tuple[np.ndarray, np.ndarray]  # envelope of y_b over x_b: x (m, 1), y (m, 1)
    start: np.ndarray  # first and last pose (3,)
    end: np.ndarray
    velocity: tuple[np.ndarray, np.ndarray]  # t (m, 3), q̇ (m, 3)
    turning: tuple[np.ndarray, np.ndarray]  # t (m, w), unwrapped turning angles (m, w) [rad]
    torque: tuple[np.ndarray, np.ndarray]  # t (m, A), actuator torques (m, A) [N m]
    samples: int  # samples the log gave (before resampling)
    duration: float  # [s]
    has_pose: bool  # the tracker's pose columns were given
    dt: float  # sample time of the grid [s]
    span_samples: int  # the smoother's span
    row_step: int  # samples between equation rows
    # the rows' state (q, q̈, unit angles, their rates, actuator torques), for the model's
    # free-running simulation (:func:`ropod_sysid.validate.simulated_velocity`); None if not kept
    state_rows: tuple[np.ndarray, ...] | None = None


class PlotGather:
    """Collects a :class:`LogPlot` from the blocks of one streamed log."""

    def __init__(self, max_points: int = MAX_BUCKETS, max_rows: int = MAX_ROWS) -> None:
        self.rows = RowSample(max_rows)
        self.path = Envelope(max_points)
        self.velocity = Envelope(max_points)
        self.turning = Envelope(max_points)
        self.torque = Envelope(max_points)
        self.start: np.ndarray | None = None
        self.end: np.ndarray | None = None
        self.widths = (0, 0)  # turning angles, torques

    def push_samples(self, t: np.ndarray, q: np.ndarray, qd: np.ndarray, turning: np.ndarray,
                     torque: np.ndarray) -> None:
        """Consecutive grid samples: pose q (m, 3), q̇ (m, 3), raw unwrapped turning angles
        (the wrapped channels: swivel pivots) (m, w), actuator torques (m, A)."""
        if not len(t):
            return
        if self.start is None:
            self.start = q[0].copy()
        self.end = q[-1].copy()
        self.path.push(q[:, 0], q[:, 1])
        self.velocity.push(t, qd)
        self.widths = (turning.shape[1], torque.reshape(len(t), -1).shape[1])
        if turning.shape[1]:  # (fixed wheels have no turning angle)
            self.turning.push(t, turning)
        self.torque.push(t, torque.reshape(len(t), -1))

    def push_rows(self, t: np.ndarray, a: np.ndarray, b: np.ndarray, qd: np.ndarray,
                  *state: np.ndarray) -> None:
        """Rows: times, filtered A_ID,ext and b_ID, q̇, and their state (q, q̈, angles, angle
        rates, torques)."""
        self.rows.push(t, a, b, qd, *state)

    def result(self, samples: int, duration: float, has_pose: bool, dt: float,
               span_samples: int, row_step: int) -> LogPlot:
        t, a, b, qd, *state = self.rows.arrays()
        assert self.start is not None and self.end is not None
        w, n_tau = self.widths
        turning = self.turning.lines(w) if w else (np.zeros((0, 0)), np.zeros((0, 0)))
        return LogPlot(t, a, b, qd, self.rows.stride, self.path.lines(), self.start, self.end,
                       self.velocity.lines(3), turning, self.torque.lines(n_tau),
                       samples, duration, has_pose, dt, span_samples, row_step,
                       tuple(state) if len(state) == 5 and state[4].ndim == 2 else None)
