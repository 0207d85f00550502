"""The checks of a log's time base, shared by every reader (whole or in chunks).

Over the sample times ``t`` of a log, in this order:

* time strictly increases (a repeated time is named as a duplicated timestamp);
* the median step of the head (the first :data:`HEAD_STEPS` steps, the steps the grid step
  comes from, :func:`grid_step`) lies in [:data:`MIN_STEP_S`,
  :data:`MAX_STEP_S`): outside it, ``t`` is not in seconds (milliseconds, most often);
* no gap: a step longer than :data:`GAP_STEPS` median steps and :data:`GAP_FLOOR_S` would be
  bridged by linear interpolation on the resampling grid — a gap of 10 s in a 100 Hz log
  becomes 1000 invented samples, and a jump of 10⁶ s a grid of 10⁸. Single dropped samples
  (a step of 2 median steps, as a smart-wheel log has after a dropped frame) and timestamp
  jitter pass. With ``gaps="allow"`` the gaps are recorded instead (:attr:`TimeBase.gaps`),
  for ``--split-gaps``, which fits the pieces between them as separate logs
  (:func:`split_log`, :func:`split_chunks`).

A chunked reader feeds its chunks in order (:func:`checked_chunks`); the check carries the last
time of the previous chunk, so a gap or a repeat across a chunk boundary is found, and holds
the first chunks back until the head is complete, so that nothing is yielded unchecked.
Messages name the sample by the reader's ``locate`` (file lines, MCAP messages, frames).

The sample grid a fit puts a log on also comes from the head: the sample time
(:func:`grid_step`, the slope of the head's times), whether every step stays on it
(:func:`on_grid`; else the log is resampled, :func:`jitter_note`) and the half-width of the
instants' jitter (:func:`grid_jitter`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Literal

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log

HEAD_STEPS = 10_000   # the median step (and the grid step) come from the first this many steps
GRID_STEPS = HEAD_STEPS  # the sample time comes from the first this many steps
UNIFORM_RTOL = 1e-3  # a log whose every step is this close to it is used as sampled
GAP_STEPS = 5.0       # a step longer than this many median steps …
GAP_FLOOR_S = 0.02    # … and longer than this [s] is a gap
MIN_STEP_S = 1e-4     # median steps below this (above 10 kHz) or …
MAX_STEP_S = 0.5      # … from this on (2 Hz or slower) mean t is not in seconds
MIN_SAMPLES_PIECE = 3  # a piece with fewer samples is no log at all
GAP_RULE = (f"a step longer than {GAP_STEPS:g} median steps and {GAP_FLOOR_S:g} s is a gap")
Gaps = Literal["error", "allow"]
Locate = Callable[[Sequence[int]], list[str]]


def sample_numbers(indices: Sequence[int]) -> list[str]:
    """``locate`` for a log without file positions: the sample numbers (from 0)."""
    return [f"sample {k}" for k in indices]


def message_numbers(offsets: np.ndarray | None = None) -> Locate:
    """``locate`` for messages (``offsets``: the file's message numbers of the samples)."""
    def locate(indices: Sequence[int]) -> list[str]:
        return [f"message {k if offsets is None else int(offsets[k])}" for k in indices]
    return locate


class TimeBase:
    """The time checks of one log, fed its sample times in order (:meth:`check`, then
    :meth:`finish`). ``gaps="allow"``: a gap is recorded in :attr:`gaps` (the index of the
    first sample after it) instead of raising."""

    def __init__(self, where: str, locate: Locate = sample_numbers, gaps: Gaps = "error",
                 ) -> None:
        self.where = where
        self.locate = locate
        self.allow = gaps == "allow"
        self.n = 0                      # samples checked
        self.t_last: float | None = None
        self.median: float | None = None
        self.head: list[np.ndarray] = []
        self.gaps: list[int] = []

    @property
    def ready(self) -> bool:
        """Whether the median step is known (every time fed so far is checked)."""
        return self.median is not None

    def check(self, t: np.ndarray) -> None:
        """Check the next sample times (held until the head is complete)."""
        t = np.asarray(t, dtype=float)
        if self.median is None:
            self.head.append(t)
            if sum(h.size for h in self.head) > HEAD_STEPS:
                self._start()
            return
        self._check(t)

    def finish(self) -> None:
        """The end of the log: check what is held."""
        if self.median is None:
            self._start()

    def _start(self) -> None:
        t = np.concatenate(self.head) if self.head else np.zeros(0)
        self.head = []
        self._order(t)
        steps = np.diff(t[: HEAD_STEPS + 1])
        self.median = float(np.median(steps)) if steps.size else 0.0
        if steps.size:
            self._unit(self.median, t.size)
        self._check(t, ordered=True)

    def _check(self, t: np.ndarray, ordered: bool = False) -> None:
        if not t.size:
            return
        if not ordered:
            self._order(t)
        ext = t if self.t_last is None else np.concatenate([[self.t_last], t])
        first = self.n - (0 if self.t_last is None else 1)   # sample index of ext[0]
        steps = np.diff(ext)
        med = self.median or 0.0
        gap: np.ndarray | list[int] = (
            np.flatnonzero((steps > GAP_STEPS * med) & (steps > GAP_FLOOR_S)) if med else [])
        if len(gap):
            if not self.allow:
                k = int(gap[0])
                before, after = self.locate([first + k, first + k + 1])
                raise InputError(
                    f"{self.where}: {after}: a gap of {steps[k]:.6g} s "
                    f"({steps[k] / med:.4g} median steps of {med:.4g} s) after t="
                    f"{float(ext[k])!r} on {before}; {GAP_RULE}, which resampling would fill "
                    "with invented samples — give --split-gaps to fit the pieces as separate "
                    "logs, or cut the log there")
            self.gaps.extend(first + int(k) + 1 for k in gap)
        self.n += t.size
        self.t_last = float(t[-1])

    def _order(self, t: np.ndarray) -> None:
        check_order(t, self.where, self.locate, self.t_last, self.n)

    def _unit(self, median: float, n: int) -> None:
        span = f"the first {min(n - 1, HEAD_STEPS)} steps"
        if median >= MAX_STEP_S:
            raise InputError(
                f"{self.where}: the median time step of {span} is {median:.4g} s (a rate of "
                f"{1 / median:.3g} Hz); is `t` in milliseconds? t must be in seconds — divide "
                "it by 1000 (by 1e9 for nanoseconds)")
        if median < MIN_STEP_S:
            raise InputError(
                f"{self.where}: the median time step of {span} is {median:.4g} s, under "
                f"{1000 * MIN_STEP_S:g} ms (a rate above {1 / MIN_STEP_S / 1000:g} kHz); is `t` "
                "in another unit (minutes, hours)? t must be in seconds")


def check_order(t: np.ndarray, where: str, locate: Locate = sample_numbers,
                t_prev: float | None = None, first: int = 0) -> None:
    """Time strictly increasing over samples ``first``… (``t_prev``: the time of sample
    ``first`` − 1), else a one-line :class:`InputError` naming both samples."""
    ext = t if t_prev is None else np.concatenate([[t_prev], t])
    k0 = first - (0 if t_prev is None else 1)   # sample index of ext[0]
    bad = np.flatnonzero(~(np.diff(ext) > 0))
    if bad.size:
        k = int(bad[0])
        before, after = locate([k0 + k, k0 + k + 1])
        a, b = float(ext[k]), float(ext[k + 1])
        if a == b:
            raise InputError(
                f"{where}: {after}: time t={b!r} repeats t={a!r} of {before} (a duplicated "
                "timestamp); time must strictly increase — remove the repeated sample")
        raise InputError(
            f"{where}: {after}: time t={b!r} is not after t={a!r} on {before}; time must "
            "strictly increase — sort the rows or remove repeated samples")


def check_times(t: np.ndarray, where: str, locate: Locate = sample_numbers,
                gaps: Gaps = "error") -> TimeBase:
    """All checks of the sample times of a whole log (returns the checker: its gaps)."""
    tb = TimeBase(where, locate, gaps)
    tb.check(t)
    tb.finish()
    return tb


def checked_chunks(chunks: Iterable[Log], tb: TimeBase) -> Iterator[Log]:
    """The chunks of a log after :meth:`TimeBase.check` of their times; the first ones are
    held back until the head is complete, so that no chunk is yielded unchecked."""
    held: list[Log] = []
    for log in chunks:
        tb.check(log.t)
        if not tb.ready:
            held.append(log)
            continue
        yield from held
        held = []
        yield log
    tb.finish()
    yield from held


def piece_name(source: str, piece: int) -> str:
    """The name of a piece of a log split at its gaps: ``run.csv[2]`` (counted from 1)."""
    return f"{source}[{piece + 1}]"


def split_chunks(chunks: Iterable[Log], where: str) -> Iterator[Log]:
    """The chunks of a log (checked by its reader with ``gaps="allow"``) cut at its gaps; each
    carries the number of its piece in :attr:`Log.piece`."""
    tb = TimeBase(where, gaps="allow")
    start = 0       # sample index of the chunk's first sample
    piece = 0
    cut = 0         # gaps already cut at
    for log in checked_chunks(chunks, tb):
        n = log.n_samples
        at = 0
        for g in tb.gaps[cut:]:
            if g >= start + n:
                break
            if g > start + at:
                yield _piece(log.slice(at, g - start), piece)
            at = g - start
            piece += 1
            cut += 1
        if at < n:
            yield _piece(log.slice(at, n) if at else log, piece)
        start += n


def _piece(log: Log, piece: int) -> Log:
    log.piece = piece
    return log


def split_log(log: Log) -> list[Log]:
    """A whole log (read with ``gaps="allow"``) as the pieces between its gaps, each named
    :func:`piece_name` and noting where it lies in the log (a log without gaps: itself)."""
    gaps = check_times(log.t, log.source, gaps="allow").gaps
    if not gaps:
        return [log]
    bounds = [0, *gaps, log.n_samples]
    pieces = []
    for j, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        piece = log.slice(a, b)
        piece.source = piece_name(log.source, j)
        piece.piece = j
        piece.notes.insert(0, piece_note(piece.source, log.source, a, b - a, float(log.t[a]),
                                      float(log.t[b - 1])))
        pieces.append(piece)
    return pieces


def piece_note(name: str, source: str, first: int, samples: int, t0: float, t1: float) -> str:
    """The note of a piece: which samples of the log it holds."""
    return (f"{name}: samples {first}–{first + samples - 1} of {source} (t {t0:.6g}–{t1:.6g} s), "
            "fitted as a separate log (--split-gaps)")


# ---------------------------------------------------------------------------------------------
# the sample grid of a log (its sample time from the head; jitter)


def grid_step(t: np.ndarray) -> float:
    """Sample time [s] of a log, from its first :data:`GRID_STEPS` time steps.

    The least-squares slope of those sample times against their sample numbers, each step
    counted as its whole number of median steps (so that a dropped sample keeps its place).
    The slope averages out timestamp jitter that a median step keeps: a 100 Hz log with ±1 ms
    jitter gets 0.01 s, not 0.009997 s. Only the head of the log is used, so that a streaming
    pass (:mod:`ropod_sysid.stream`) knows the grid after one chunk and chooses exactly the
    grid of the in-memory path.
    """
    head = np.asarray(t[: GRID_STEPS + 1], dtype=float)
    steps = np.diff(head)
    dt0 = float(np.median(steps))
    if head.size < 3 or not dt0 > 0:
        return dt0
    k = np.concatenate([[0.0], np.cumsum(np.maximum(np.round(steps / dt0), 1.0))])
    k -= k.mean()
    slope = float(k @ (head - head.mean()) / (k @ k))
    return slope if slope > 0 else dt0


def grid_jitter(t: np.ndarray, dt: float) -> float:
    """The half-width [samples] of a uniform jitter of a log's sample instants, from its first
    :data:`GRID_STEPS` sample times (as :func:`grid_step`, so that a streaming pass finds the
    same): √3 × the standard deviation of their distances from the best straight line through
    them at the step ``dt``; 0 for a log on its grid (:func:`on_grid`). A jittered instant
    dithers where the encoders' count grid falls (:func:`ropod_sysid.quantisation.tone_share`)."""
    head = np.asarray(t[: GRID_STEPS + 1], dtype=float)
    if head.size < 3 or not dt > 0 or on_grid(np.diff(head), dt):
        return 0.0
    k = np.round((head - head[0]) / dt)
    dev = head - dt * k
    return float(math.sqrt(3.0) * np.std(dev - dev.mean()) / dt)


def on_grid(steps: np.ndarray, dt: float) -> bool:
    """Whether every time step is within :data:`UNIFORM_RTOL` of the sample time ``dt``."""
    steps = np.asarray(steps, dtype=float)
    return bool(steps.size == 0 or np.max(np.abs(steps - dt)) <= UNIFORM_RTOL * dt)


def jitter_note(source: str, max_step: float, min_step: float, dt: float) -> str:
    """The note of a log whose sample times were put on a uniform grid."""
    return (f"{source}: sample times jitter (max step {max_step:.4g} s, min {min_step:.4g} s); "
            f"resampled to a uniform {dt:.4g} s grid")
