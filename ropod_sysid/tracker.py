"""A base pose from an external tracker slower than the log, used next to wheel odometry.

An overhead camera (004 tracks the 5DPO robot at 25 fps, about 1 cm and 3°) gives the pose
at its own frames; the rows of the log between them leave ``x_b, y_b, theta_b`` empty (NaN in
:attr:`ropod_sysid.io.log.Log.pose`). Twice-differentiated, such a pose is useless for the
equations of motion: 1 cm of noise at 25 fps is an acceleration noise of the order of
σ_x / T² ≈ 6 m/s² per frame pair, against the run's 1 m/s². Wheel odometry is smooth and precise
over a smoother span but drifts over metres as wheels slip (omni wheels on real floors do).

So the fit uses the two as a complementary filter: the motion is wheel odometry (from the raw
encoder angles, :func:`ropod_sysid.odometry.odometry_from`), and the tracker corrects its slow
drift. At each tracker frame the residual r = tracker − odometry (heading unwrapped) is taken;
r is smoothed over the frames with a zero-phase LOESS over :data:`WINDOW_S` seconds
(:func:`ropod_sysid.signals.loess`), interpolated linearly to every sample and added to the
odometry. The sum is then used like a tracker pose on every row (smoothed with the fit's span
and differentiated): its fast part is the odometry's, its slow part the tracker's. Without
slip the result equals odometry to within the tracker noise averaged over the window; with a
drift, the pose follows the tracker on time scales longer than the window.

In a streamed pass (:func:`fused_chunks`) the log is read twice: once for the odometry at the
tracker frames (memory: the frames only), once for the pass itself.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeGuard

import numpy as np

from ropod_sysid import signals
from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.odometry import OdometryState, odometry_from

if TYPE_CHECKING:
    from ropod_sysid.model import PlatformModel

WINDOW_S = 10.0  # the residual's LOESS window [s]: the tracker corrects drift slower than this
MIN_FRAMES = 2  # tracker frames a log needs to correct anything


def is_sparse(pose: np.ndarray | None) -> TypeGuard[np.ndarray]:
    """Whether a log's pose has rows without a tracker frame (NaN)."""
    return pose is not None and bool(np.isnan(pose[:, 0]).any())


@dataclass
class Correction:
    """The smoothed residual tracker − odometry at the tracker frames: times (m,), (m, 3)."""

    t: np.ndarray
    r: np.ndarray

    def at(self, t: np.ndarray) -> np.ndarray:
        """The correction at times ``t`` (N,): linear between frames, held beyond them."""
        return np.stack([np.interp(t, self.t, self.r[:, j]) for j in range(3)], axis=1)


def correction(source: str, t: np.ndarray, residual: np.ndarray,
               window: float = WINDOW_S) -> Correction:
    """Smooth the residuals (m, 3) at the tracker frames ``t`` (m,) over ``window`` seconds."""
    if t.size < MIN_FRAMES:
        raise InputError(f"{source}: the pose columns hold {t.size} tracker frame"
                         f"{'s' if t.size != 1 else ''}; give at least {MIN_FRAMES} (or leave "
                         "x_b, y_b, theta_b out to use wheel odometry alone)")
    r = np.column_stack([residual[:, :2], np.unwrap(residual[:, 2])])
    if t.size >= 5:
        rate = (t.size - 1) / (t[-1] - t[0]) if t[-1] > t[0] else 1.0
        k = int(round(window * rate))
        k = max(5, k + 1 - k % 2)  # odd, at least the shortest LOESS window
        if k <= t.size:
            r = signals.loess(r, k)
    return Correction(t, r)


def _frames(log: Log) -> tuple[np.ndarray, np.ndarray]:
    assert log.pose is not None
    have = np.isfinite(log.pose[:, 0])
    return np.flatnonzero(have), log.pose[have]


def fused_pose(log: Log, model: PlatformModel, window: float = WINDOW_S) -> np.ndarray:
    """The pose (N, 3) of a log with a slow tracker: wheel odometry plus the smoothed tracker
    correction (see the module docstring); ``model`` is the platform's
    :class:`~ropod_sysid.model.PlatformModel`."""
    q_o, _ = odometry_from(model, log.angles)
    idx, frames = _frames(log)
    corr = correction(log.source, log.t[idx], frames - q_o[idx], window)
    return q_o + corr.at(log.t)


def with_fused_pose(log: Log, model: PlatformModel, window: float = WINDOW_S) -> Log:
    """The log with its sparse tracker pose replaced by :func:`fused_pose` (else itself)."""
    if not is_sparse(log.pose):
        return log
    return replace(log, pose=fused_pose(log, model, window))


class _Odometry:
    """Raw wheel odometry continued from chunk to chunk."""

    def __init__(self, model: PlatformModel) -> None:
        self.model = model
        self.state: OdometryState | None = None
        self.last: np.ndarray | None = None  # the previous chunk's last angles

    def push(self, angles: np.ndarray) -> np.ndarray:
        if self.last is None:
            q, corr = odometry_from(self.model, angles)
        else:
            q, corr = odometry_from(self.model, np.vstack([self.last[None], angles]),
                                    self.state)
            q, corr = q[1:], corr[1:]
        self.state = OdometryState(q[-1].copy(), corr[-1].copy())
        self.last = angles[-1].copy()
        return q


def fused_chunks(first: Log, rest: Iterator[Log], again: Callable[[], Iterator[Log]],
                 model: PlatformModel, window: float = WINDOW_S) -> Iterator[Log]:
    """The chunks ``first`` + ``rest`` of a log with a slow tracker, each with the fused pose;
    ``again`` reads the log's chunks anew for the first pass (the odometry at the frames)."""
    odo = _Odometry(model)
    ts, res = [], []
    for chunk in again():
        q = odo.push(chunk.angles)
        idx, frames = _frames(chunk)
        ts.append(chunk.t[idx])
        res.append(frames - q[idx])
    corr = correction(first.source, np.concatenate(ts), np.concatenate(res), window)
    odo = _Odometry(model)
    for chunk in _chain(first, rest):
        q = odo.push(chunk.angles)
        yield replace(chunk, pose=q + corr.at(chunk.t))


def _chain(first: Log, rest: Iterator[Log]) -> Iterator[Log]:
    yield first
    yield from rest


def dense_or_fused(chunks: Iterator[Log], again: Callable[[], Iterator[Log]],
                   model: Callable[[], PlatformModel], window: float = WINDOW_S) -> Iterator[Log]:
    """A log's chunks as they are, or — when the first one has rows without a tracker frame —
    with the fused pose (:func:`fused_chunks`); ``model`` builds the platform model."""
    first = next(chunks, None)
    if first is None:
        return
    if is_sparse(first.pose):
        yield from fused_chunks(first, chunks, again, model(), window)
        return
    for chunk in _chain(first, chunks):
        if first.pose is not None and is_sparse(chunk.pose):
            row = int(np.flatnonzero(np.isnan(chunk.pose[:, 0]))[0])
            raise InputError(f"{chunk.source}: the pose columns are empty at t = "
                             f"{chunk.t[row]:.6g} s but given on every row before; a "
                             "tracker slower than the log leaves them empty from the start "
                             "between its frames — give every row or only the frames")
        yield chunk
