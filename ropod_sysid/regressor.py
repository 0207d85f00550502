"""From a log to the identification system A_ID,ext m_ext = b_ID (eqs. 35, 36, 66).

Preprocessing follows Sec. VI-B: encoder angles are smoothed with zero-phase LOESS (MATLAB
``smooth(…, 'loess')`` semantics), the base pose follows by odometry (or comes from the log's
tracker columns), velocities and accelerations by central differences; currents times the
torque constant give the wheel torques. The rows of A_ID,ext and b_ID are then filtered with the
same LOESS on both sides of the equation, and the ends, where the smoother's window is
shifted, are trimmed.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ropod_sysid import signals
from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.model import PlatformModel
from ropod_sysid.odometry import odometry_from
from ropod_sysid.params import Friction
from ropod_sysid.platform import Platform
from ropod_sysid.solve import Triangles, qr_triangle

DEFAULT_SPAN_S = 0.1
QR_LEAF_ROWS = 256  # rows per leaf QR of a block's TSQR (small: fast, cache-resident)
GRID_STEPS = 10_000  # the sample time is the median of the first this many steps
UNIFORM_RTOL = 1e-3  # a log whose every step is this close to it is used as sampled


def grid_step(t: np.ndarray) -> float:
    """Sample time [s] of a log: the median of its first :data:`GRID_STEPS` time steps.

    Only the head of the log is used, so that a streaming pass (:mod:`ropod_sysid.stream`)
    knows the grid after one chunk and chooses exactly the grid of the in-memory path.
    """
    return float(np.median(np.diff(np.asarray(t[: GRID_STEPS + 1], dtype=float))))


def on_grid(steps: np.ndarray, dt: float) -> bool:
    """Whether every time step is within :data:`UNIFORM_RTOL` of the sample time ``dt``."""
    steps = np.asarray(steps, dtype=float)
    return bool(steps.size == 0 or np.max(np.abs(steps - dt)) <= UNIFORM_RTOL * dt)


def jitter_note(source: str, max_step: float, min_step: float, dt: float) -> str:
    """The note of a log whose sample times were put on a uniform grid."""
    return (f"{source}: sample times jitter (max step {max_step:.4g} s, min {min_step:.4g} s); "
            f"resampled to a uniform {dt:.4g} s grid")


@dataclass
class Span:
    """Smoother span: a number of samples, or seconds (``"0.25s"``)."""

    value: float
    seconds: bool

    @classmethod
    def parse(cls, text: str | float | None) -> Span:
        if text is None:
            return cls(DEFAULT_SPAN_S, True)
        if isinstance(text, int | float):
            return cls(float(text), False)
        s = str(text).strip()
        try:
            if s.endswith("s"):
                v = float(s[:-1])
                if v <= 0:
                    raise ValueError
                return cls(v, True)
            v = float(s)
            if v <= 0:
                raise ValueError
            return cls(v, False)
        except ValueError:
            raise InputError(f"--span {text!r}: give a positive number of samples (e.g. 21) or "
                             "seconds (e.g. 0.1s)") from None

    def samples(self, dt: float, n: int) -> int:
        """Odd window length k in samples for sample time ``dt`` and ``n`` samples."""
        k = self.value / dt if self.seconds else self.value
        k = max(int(round(k)), 3)
        return k if k % 2 else k + 1

    def __str__(self) -> str:
        return f"{self.value:g}s" if self.seconds else f"{int(self.value)} samples"


@dataclass
class Preprocessed:
    """Smoothed signals of one log on a uniform grid, ends trimmed (shapes (M, …))."""

    t: np.ndarray
    q: np.ndarray  # (M, 3) pose
    qd: np.ndarray
    qdd: np.ndarray
    delta: np.ndarray  # (M, n)
    delta_dot: np.ndarray
    phi_dot: np.ndarray  # (M, n, 2)
    tau: np.ndarray  # (M, n, 2) wheel torques
    source: str
    span_samples: int
    dt: float
    notes: list[str] = field(default_factory=list)
    trim: int = 0  # samples dropped at each end after filtering the equations

    def window(self, start: int, stop: int) -> Preprocessed:
        """Samples start:stop (untrimmed indices) as a new block."""
        sl = slice(start, stop)
        return Preprocessed(self.t[sl], self.q[sl], self.qd[sl], self.qdd[sl], self.delta[sl],
                            self.delta_dot[sl], self.phi_dot[sl], self.tau[sl], self.source,
                            self.span_samples, self.dt, self.notes, 0)

    @property
    def n_samples(self) -> int:
        """Samples that enter the fit (after trimming)."""
        return len(self.t) - 2 * self.trim


def preprocess(log: Log, platform: Platform, span: Span | None = None,
               input_delay: float = 0.0) -> Preprocessed:
    """Smooth, differentiate and trim one log (Sec. VI-B).

    ``input_delay`` [s] shifts the torques: the torque logged at t acts on the motion at
    t + delay.
    """
    span = span or Span.parse(None)
    notes = list(log.notes)
    t = log.t
    delta = np.unwrap(log.delta, axis=0)
    phi, current = log.phi, log.current
    pose = log.pose
    dt = grid_step(t)
    steps = np.diff(t)
    if not on_grid(steps, dt):
        t_new, delta = signals.resample_uniform(t, delta, dt)
        _, phi = signals.resample_uniform(t, phi, dt)
        _, current = signals.resample_uniform(t, current, dt)
        if pose is not None:
            _, pose = signals.resample_uniform(t, np.column_stack(
                [pose[:, :2], np.unwrap(pose[:, 2])]), dt)
        notes.append(jitter_note(log.source, steps.max(), steps.min(), dt))
        t = t_new
    n = len(t)
    k = span.samples(dt, n)
    trim = k  # the shifted end windows of both filter stages
    if n < 2 * trim + k:
        raise InputError(
            f"{log.source}: {n} samples are too few for a smoother span of {k} samples "
            f"({k * dt:.3g} s); record a longer run or use a shorter --span")
    delta_s = signals.loess(delta, k)
    phi_s = signals.loess(phi, k)
    if pose is None:
        q, _ = odometry_from(platform, delta_s, phi_s)
    else:
        q = signals.loess(np.column_stack([pose[:, :2], np.unwrap(pose[:, 2])]), k)
    qd = signals.central_difference(q, dt)
    qdd = signals.central_difference(qd, dt)
    delta_dot = signals.central_difference(delta_s, dt)
    phi_dot = signals.central_difference(phi_s, dt)
    tau = platform.torque_constant * current
    if input_delay:
        flat = tau.reshape(n, -1)
        tau = np.stack([np.interp(t - input_delay, t, flat[:, j]) for j in range(flat.shape[1])],
                       axis=1).reshape(tau.shape)
    return Preprocessed(t, q, qd, qdd, delta_s, delta_dot, phi_dot, tau, log.source, k, dt,
                        notes, trim)


def raw_system(model: PlatformModel, pre: Preprocessed,
               friction: Friction = "per-wheel") -> tuple[np.ndarray, np.ndarray]:
    """A_ID,ext (M, 3, p) and b_ID (M, 3) sample by sample, before filtering (eqs. 36, 66)."""
    st = model.state(pre.q, pre.qd, pre.delta, pre.delta_dot)
    return model.a_id_ext(st, pre.qdd, friction), model.b_id(st, pre.tau)


def system(model: PlatformModel, pre: Preprocessed, friction: Friction = "per-wheel",
           chunk: int = 20000) -> Iterator[tuple[slice, np.ndarray, np.ndarray]]:
    """Filtered A_ID,ext and b_ID in blocks of at most ``chunk`` kept samples.

    Both sides of eq. 36 pass through the same zero-phase LOESS, column by column, so that
    fast events the smoother cannot follow (Coulomb friction switching at a wheel-rate zero
    crossing, the speed loops' transients) are attenuated alike in A_ID,ext and b_ID. Blocks
    overlap by the half window, which makes the result equal to filtering the whole log at
    once. Yields (slice into the untrimmed samples, A (m, 3, p), b (m, 3)).
    """
    k = pre.span_samples
    half = (k - 1) // 2
    n = len(pre.t)
    for start in range(pre.trim, n - pre.trim, chunk):
        stop = min(start + chunk, n - pre.trim)
        lo, hi = max(start - half, 0), min(stop + half, n)
        a, b = raw_system(model, pre.window(lo, hi), friction)
        a = signals.loess(a, k)
        b = signals.loess(b, k)
        yield slice(start, stop), a[start - lo: stop - lo], b[start - lo: stop - lo]


def filtered_system(model: PlatformModel, pre: Preprocessed,
                    friction: Friction = "per-wheel") -> tuple[np.ndarray, np.ndarray]:
    """The whole filtered, trimmed system of one log: A (M, 3, p), b (M, 3)."""
    parts = list(system(model, pre, friction))
    return (np.concatenate([a for _, a, _ in parts]), np.concatenate([b for _, _, b in parts]))


def block_triangles(a: np.ndarray, b: np.ndarray, label: str = "") -> Triangles:
    """:meth:`Triangles.from_rows` of A (m, 3, p) and b (m, 3) by a two-level TSQR: leaves of
    :data:`QR_LEAF_ROWS` rows reduced by one batched QR, their triangles by one more. Same
    triangle up to rounding (and row signs), several times faster on tall blocks."""
    m, _, p = a.shape
    full = m // QR_LEAF_ROWS * QR_LEAF_ROWS
    r = np.empty((3, p + 1, p + 1))
    rows = np.empty((m, p + 1))
    for d in range(3):
        rows[:, :p] = a[:, d, :]
        rows[:, p] = b[:, d]
        parts = []
        if full:
            leaves = np.linalg.qr(rows[:full].reshape(-1, QR_LEAF_ROWS, p + 1), mode="r")
            parts.append(leaves.reshape(-1, p + 1))
        if m > full:
            parts.append(rows[full:])
        r[d] = qr_triangle(np.vstack(parts))
    return Triangles(r, m, label)


def triangles(model: PlatformModel, pre: Preprocessed, friction: Friction = "per-wheel",
              chunk: int = 20000) -> Triangles:
    """The log's QR triangles per DOF, built block by block (memory bounded by ``chunk``)."""
    tri: Triangles | None = None
    for _, a, b in system(model, pre, friction, chunk):
        block = block_triangles(a, b, pre.source)
        tri = block if tri is None else tri.merge(block)
    if tri is None:
        raise InputError(f"{pre.source}: no samples left after trimming the smoother's ends")
    return tri
