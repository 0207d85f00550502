"""Steps 1–2 of the chunked pass (:mod:`ropod_sysid.stream`): unwrapping and the sample grid.

Chunk by chunk, the wrapped unit angles (pivots; and a tracker heading) are unwrapped, continued
across chunks (bit-identical to one :func:`numpy.unwrap`); the sample time is taken from the
head of the log (:func:`ropod_sysid.io.timebase.grid_step`). A log whose steps all stay on it is
passed on as sampled; a jittered one is put on the uniform grid ``t0 + k dt`` by linear
interpolation continued across chunks — the grid of the in-memory path. A step off the grid
found after the head raises :class:`_OffGrid`, on which the pass restarts in resampling mode.
The grid samples go to a sink (the block reducer of :mod:`ropod_sysid.stream`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import GRID_STEPS, grid_jitter, grid_step, jitter_note, on_grid
from ropod_sysid.odometry import unwrap_from, wrap_jumps


class _OffGrid(Exception):
    """A step off the sample grid found after the head of a log (of a piece of it, with
    --split-gaps): the pass restarts, resampling that piece."""


@dataclass
class _Samples:
    """Consecutive grid samples: t (m,), angles (m, J) (wrapped ones unwrapped), currents
    (m, A), pose (m, 3) or None."""

    t: np.ndarray
    angles: np.ndarray
    currents: np.ndarray
    pose: np.ndarray | None

    def __len__(self) -> int:
        return self.t.shape[0]

    def take(self, start: int, stop: int) -> _Samples:
        pose = None if self.pose is None else self.pose[start:stop]
        return _Samples(self.t[start:stop], self.angles[start:stop],
                        self.currents[start:stop], pose)

    @staticmethod
    def join(parts: list[_Samples]) -> _Samples:
        if len(parts) == 1:
            return parts[0]
        pose = None if parts[0].pose is None else np.concatenate([p.pose for p in parts])
        return _Samples(np.concatenate([p.t for p in parts]),
                        np.concatenate([p.angles for p in parts]),
                        np.concatenate([p.currents for p in parts]), pose)


class _Sink(Protocol):
    """Where the grid samples go (:class:`ropod_sysid.stream._Blocks`)."""

    def start(self, dt: float, jitter: float = 0.0) -> None: ...

    def push(self, samples: _Samples) -> None: ...


class _Grid:
    """Steps 1–2: unwrapping and the uniform grid, continued from chunk to chunk."""

    def __init__(self, source: str, resample: bool, sink: _Sink) -> None:
        self.source = source
        self.resample = resample
        self.sink = sink
        self.head: list[_Samples] = []
        self.dt: float | None = None
        self.t0 = 0.0
        self.tail: _Samples | None = None  # last two samples (steps, interpolation brackets)
        self.next_k = 0  # next grid index to emit (resampling)
        self.max_step = -np.inf
        self.min_step = np.inf
        self.unwrap_angles: _Unwrap | None = None
        self.unwrap_theta: _Unwrap | None = None
        self.unwrap_grid: _Unwrap | None = None
        self.has_pose: bool | None = None

    def push(self, log: Log) -> None:
        if log.n_samples == 0:
            return
        if self.has_pose is None:
            self.has_pose = log.pose is not None
        elif self.has_pose != (log.pose is not None):
            raise InputError(f"{self.source}: the tracker pose is given on part of the log "
                             "only; give x_b, y_b, theta_b on every sample or on none")
        angles = np.asarray(log.angles, float)
        if log.layout.wrapped.any():
            angles, self.unwrap_angles = _unwrap_columns(
                angles, np.flatnonzero(log.layout.wrapped), self.unwrap_angles)
        pose = None
        if log.pose is not None:
            theta, self.unwrap_theta = _unwrap(log.pose[:, 2], self.unwrap_theta)
            pose = np.column_stack([log.pose[:, :2], theta])
        raw = _Samples(np.asarray(log.t, float), angles, np.asarray(log.currents, float), pose)
        if self.dt is None:
            self.head.append(raw)
            if sum(len(h) for h in self.head) > GRID_STEPS:
                self._start(final=False)
            return
        self._emit(raw, final=False)

    def _start(self, final: bool) -> None:
        head = _Samples.join(self.head)
        self.head = []
        self.dt = grid_step(head.t)
        self.t0 = float(head.t[0])
        if not self.resample and not on_grid(np.diff(head.t), self.dt):
            self.resample = True
        self.sink.start(self.dt, grid_jitter(head.t, self.dt))
        self._emit(head, final)

    def _emit(self, raw: _Samples, final: bool) -> None:
        # (the steps from the previous chunk's last sample on; the chunks are joined only to
        # resample, which needs the bracketing samples)
        t = raw.t if self.tail is None else np.concatenate([self.tail.t[-1:], raw.t])
        steps = np.diff(t)
        if steps.size:  # (time increases: iter_chunks checked it, ropod_sysid.io.timebase)
            self.max_step = max(self.max_step, float(steps.max()))
            self.min_step = min(self.min_step, float(steps.min()))
        if not self.resample:
            assert self.dt is not None  # (_emit follows _start)
            if not on_grid(steps, self.dt):
                raise _OffGrid
            self.sink.push(raw)
            src = raw  # (only its last sample is used on)
        else:
            src = raw if self.tail is None else _Samples.join([self.tail, raw])
            self._resample(src, final)
        self.tail = src.take(max(len(src) - 2, 0), len(src))

    def _resample(self, src: _Samples, final: bool) -> None:
        """Grid points t0 + k dt among the samples seen so far, by the formula of
        :func:`ropod_sysid.signals.resample_uniform` on the whole log (the last point, at the
        end, clipped to the last sample time)."""
        t, dt = src.t, self.dt
        assert dt is not None
        if final:
            m = int(np.floor((t[-1] - self.t0) / dt * (1 + 1e-12) + 1e-9)) + 1
        else:
            m = int(np.floor((t[-1] - self.t0) / dt)) + 2
        tk = self.t0 + dt * np.arange(self.next_k, max(m, self.next_k), dtype=float)
        tk = np.minimum(tk, t[-1]) if final else tk[tk < t[-1]]
        if not tk.size:
            return
        if len(t) < 2:
            raise InputError(f"{self.source}: only one sample; a log needs more")
        idx = np.clip(np.searchsorted(t, tk, side="right") - 1, 0, len(t) - 2)
        frac = (tk - t[idx]) / (t[idx + 1] - t[idx])

        def at(y: np.ndarray) -> np.ndarray:
            f = frac.reshape((-1,) + (1,) * (y.ndim - 1))
            return y[idx] + f * (y[idx + 1] - y[idx])

        pose = None
        if src.pose is not None:
            pose = at(src.pose)
            pose[:, 2], self.unwrap_grid = _unwrap(pose[:, 2], self.unwrap_grid)
        self.sink.push(_Samples(tk, at(src.angles), at(src.currents), pose))
        self.next_k += tk.size

    def finish(self) -> list[str]:
        if self.dt is None:
            if not self.head:
                raise InputError(f"{self.source}: the log has no samples")
            self._start(final=True)
        elif self.resample:
            assert self.tail is not None
            self._resample(self.tail, final=True)
        notes = []
        if self.resample:
            assert self.dt is not None  # (started above)
            notes.append(jitter_note(self.source, self.max_step, self.min_step, self.dt))
        return notes


@dataclass
class _Unwrap:
    """Where np.unwrap of a signal stands after a piece: last raw sample, its correction."""

    last: np.ndarray
    corr: np.ndarray


def _unwrap_columns(angles: np.ndarray, idx: np.ndarray, state: _Unwrap | None
                    ) -> tuple[np.ndarray, _Unwrap]:
    """:func:`_unwrap` of the columns ``idx`` of ``angles`` (m, J). Where none steps by half a
    turn, the correction carried in is added (the angles themselves come back when it is zero),
    as :func:`unwrap_from`'s sum of zero steps would."""
    p = np.take(angles, idx, axis=1)
    corr = np.zeros(idx.size) if state is None else state.corr
    if wrap_jumps(p).any() or (state is not None and wrap_jumps(np.stack([state.last, p[0]])
                                                                ).any()):
        out = angles.copy()
        out[:, idx], new = _unwrap(p, state)
        return out, new
    new = _Unwrap(p[-1].copy(), corr)
    if not corr.any():
        return angles, new
    out = angles.copy()
    out[:, idx] = p + corr
    return out, new


def _unwrap(p: np.ndarray, state: _Unwrap | None) -> tuple[np.ndarray, _Unwrap]:
    """np.unwrap along axis 0 of the next piece of a signal (bit-identical to one call)."""
    p = np.asarray(p, float)
    if state is None:
        up, corr = unwrap_from(p)
    else:
        up, corr = unwrap_from(np.concatenate([state.last[None], p]), state.corr)
        up, corr = up[1:], corr[1:]
    return up, _Unwrap(p[-1].copy(), corr[-1].copy())
