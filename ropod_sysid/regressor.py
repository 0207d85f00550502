"""From a log to the identification system A_ID,ext m_ext = b_ID (eqs. 35, 36, 66).

Preprocessing follows Sec. VI-B: encoder angles are smoothed with zero-phase LOESS (MATLAB
``smooth(…, 'loess')`` semantics; ``--smoother quartic``: a local quartic), the base pose
follows by odometry (or comes from the log's tracker columns), velocities and accelerations by
central differences (five-point ones after the quartic); currents times the
torque constant give the wheel torques. The rows of A_ID,ext and b_ID are then filtered with the
same LOESS on both sides of the equation, and the ends, where the smoother's window is
shifted, are trimmed.

Equation rows are taken every :class:`RowGrid` ``step`` samples (by default about ten per
smoother span: every 10th sample of a 1 kHz log at ``--span 0.1s``, every sample of a 100 Hz
one). The smoothed states hardly change between neighbouring samples, so rows closer than
that repeat each other; forming every one of them is most of the cost of a fast log. The
torques of a row are averaged over the step around it (the states, already smoothed over the
whole span, are taken at the row), and the rows' LOESS covers the same time span as the
samples' (:class:`RowGrid`), so both sides of eq. 36 are still filtered alike. On noise-free
200 Hz runs the values move by 0.3 % (every 2nd sample) to 2 % (every 4th, 0.2 s span) from
the every-sample fit (tests/test_rows.py). ``step=1`` gives the sample-by-sample system.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ropod_sysid import signals
from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import (
    MIN_SAMPLES_PIECE,
    check_times,
    grid_jitter,
    grid_step,
    jitter_note,
    on_grid,
    split_log,
)
from ropod_sysid.model import PlatformModel
from ropod_sysid.odometry import OdometryState, odometry_from, unwrap_angles
from ropod_sysid.params import Friction
from ropod_sysid.platform import Platform
from ropod_sysid.recipe import (  # the recipe's settings (re-exported: Span, RowGrid, …)
    DelayBracket,
    RowGrid,
    Span,
    check_input_delay,
    smoother_note,
)
from ropod_sysid.solve import Triangles, kind_rows, per_row, qr_triangle, stretch_grams
from ropod_sysid.tracker import with_fused_pose

QR_LEAF_ROWS = 256  # rows per leaf QR of a block's TSQR (small: fast, cache-resident)
# a unit's own rows (a steered wheel's steering) are left out while the joint's measured rate is
# below HELD_RATE / friction_tanh_gain: there the Coulomb term c·tanh(α rate) is steepest and
# the rate's small errors (encoder counts, the smoother) make its column wrong; on the shipped
# steered sample (2¹⁴ counts, α = 100) they put the steering friction 5.7 % off (4.9σ), left out
# within 0.5 % (1σ)
HELD_RATE = 2.0
REST_SPEED = 0.005  # [m/s] below this base speed, turn rate and every unit angle's rate …
REST_TURN = 0.005  # [rad/s]
REST_RATE = 0.05  # [rad/s] … the platform stands still (its rows are left out)


class TooShort(InputError):
    """A log (or a piece of one, with --split-gaps) too short for the smoother span."""


def check_length(source: str, n: int, k: int, dt: float, trim: int) -> None:
    """Enough samples ``n`` on the grid for a smoother span of ``k`` samples and the ``trim``
    samples each end loses, else :class:`TooShort`."""
    if n < 2 * trim + k:
        raise TooShort(
            f"{source}: {n} samples are too few for a smoother span of {k} samples "
            f"({k * dt:.3g} s); record a longer run or use a shorter --span")


def check_piece_samples(source: str, n: int) -> None:
    """A piece between gaps needs a few samples to have a grid at all, else :class:`TooShort`."""
    if n < MIN_SAMPLES_PIECE:
        raise TooShort(f"{source}: only {n} sample{'s' if n != 1 else ''}")


def left_out(exc: TooShort) -> str:
    """The note of a piece too short to fit, left out (--split-gaps)."""
    return f"{exc} — left out: a piece between gaps too short to fit"


def no_piece_left(source: str, dropped: list[str]) -> InputError:
    """The error of a log split at its gaps whose every piece is too short to fit."""
    more = f"; and {len(dropped) - 3} more" if len(dropped) > 3 else ""
    return InputError(f"{source}: every piece between the gaps in time is too short to fit "
                      f"({'; '.join(dropped[:3])}{more}); record longer runs or use a shorter "
                      "--span")


def usable_pieces(log: Log, span: Span | None = None, row_step: int | None = None,
                  ) -> list[Log]:
    """A log (read with ``gaps="allow"``) split at its gaps
    (:func:`ropod_sysid.io.timebase.split_log`): the pieces long enough for the smoother span,
    the first one noting those left out (the criterion of :func:`preprocess` and of the
    streamed pass: the samples on the piece's own grid); none left is an error."""
    span = span or Span.parse(None)
    kept, notes = [], []
    for piece in split_log(log):
        try:
            check_piece_samples(piece.source, piece.n_samples)
            dt = grid_step(piece.t)
            n = piece.n_samples if on_grid(np.diff(piece.t), dt) else \
                len(signals.resample_uniform(piece.t, piece.t, dt)[0])
            k = span.samples(dt, n)
            check_length(piece.source, n, k, dt,
                         RowGrid.for_span(k, row_step, span.degree).trim(k))
            kept.append(piece)
        except TooShort as exc:
            notes.append(left_out(exc))
    if not kept:
        raise no_piece_left(log.source, notes)
    kept[0].notes.extend(notes)
    return kept


@dataclass
class Preprocessed:
    """Smoothed signals of one log on a uniform grid, ends trimmed (shapes (M, …))."""

    t: np.ndarray
    q: np.ndarray  # (M, 3) pose
    qd: np.ndarray
    qdd: np.ndarray
    angles: np.ndarray  # (M, J) smoothed unit angles (platform channel order)
    angle_rates: np.ndarray  # (M, J)
    tau: np.ndarray  # (M, A) actuator torques
    source: str
    span_samples: int
    dt: float
    notes: list[str] = field(default_factory=list)
    trim: int = 0  # samples dropped at each end after filtering the equations
    grid: RowGrid = field(default_factory=lambda: RowGrid(1, 3))
    delays: np.ndarray | None = None  # node delays of tau (M, A, n) (DelayBracket), or None
    delay_order: int = 1  # their interpolation order (DelayBracket.order)
    degree: int = 2  # of the smoother (Span.degree: 2 LOESS, 4 quartic)
    jitter: float = 0.0  # half-width of the sample instants' uniform jitter [samples] (grid_jitter)

    def window(self, start: int, stop: int) -> Preprocessed:
        """Samples start:stop (untrimmed indices) as a new block."""
        return self.take(slice(start, stop))

    def take(self, index: slice | np.ndarray) -> Preprocessed:
        """The samples at ``index`` (a slice or indices) as a new block, untrimmed."""
        i = index
        return Preprocessed(self.t[i], self.q[i], self.qd[i], self.qdd[i], self.angles[i],
                            self.angle_rates[i], self.tau[i], self.source,
                            self.span_samples, self.dt, self.notes, 0, self.grid, self.delays,
                            self.delay_order, self.degree, self.jitter)

    def row_samples(self) -> np.ndarray:
        """Indices of the samples that become equation rows (after trimming)."""
        return np.arange(self.trim, len(self.t) - self.trim, self.grid.step)

    @property
    def n_rows(self) -> int:
        """Equation rows that enter the fit."""
        return len(range(self.trim, len(self.t) - self.trim, self.grid.step))


def delayed(t: np.ndarray, tau: np.ndarray, input_delay: float | np.ndarray) -> np.ndarray:
    """Torques (N, A) shifted later by ``input_delay`` [s]: the torque logged at t acts on the
    motion at t + delay (linear interpolation, held at the first and last sample). Several
    delays (n,) give (N, A, n)."""
    if np.ndim(input_delay):
        return shifted(tau, np.asarray(input_delay) / float(np.median(np.diff(t))))
    if not input_delay:
        return tau
    return np.stack([np.interp(t - input_delay, t, tau[:, j]) for j in range(tau.shape[1])],
                    axis=1)


def shifted(tau: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Torques (N, A) on a uniform grid shifted later by whole numbers of samples ``shifts``
    (n,), held at the first and last sample: (N, A, n) (:class:`DelayBracket`'s nodes; equal
    to :func:`delayed` of those delays)."""
    n = len(tau)
    js = np.rint(np.asarray(shifts, float)).astype(int)
    idx = np.clip(np.arange(n)[:, None] - js[None, :], 0, n - 1)  # (N, n)
    return np.moveaxis(tau[idx], 1, 2)


def tracker_pose(pose: np.ndarray) -> np.ndarray:
    """x_b, y_b and the unwrapped θ_b of a tracker pose (N, 3)."""
    return np.column_stack([pose[:, :2], np.unwrap(pose[:, 2])])


def smooth(y: np.ndarray, k: int, degree: int = 2) -> np.ndarray:
    """The angles' (or a tracker pose's) zero-phase smoother over ``k`` samples: LOESS of
    ``degree`` 2 (MATLAB's) or 4 (local quartic)."""
    return signals.loess(y, k, degree=degree)


def difference(y: np.ndarray, dt: float, degree: int = 2) -> np.ndarray:
    """First derivative of smoothed samples: three-point central differences after the
    quadratic LOESS, five-point after the quartic (each exact for polynomials of the smoother's
    degree)."""
    if degree == 2:
        return signals.central_difference(y, dt)
    return signals.five_point_difference(y, dt)


def derivatives(model: PlatformModel, angles_s: np.ndarray, pose_s: np.ndarray | None,
                dt: float, odometry_start: OdometryState | None = None, degree: int = 2,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The recipe's step after smoothing (Sec. VI-B), shared by the in-memory and streamed
    paths: the pose by odometry from the smoothed angles (or the smoothed tracker pose), its
    differences (:func:`difference` for the smoother's ``degree``), and the angle rates.
    Returns (q, q̇, q̈, angle rates, unwrapping corrections of the angles); q̈ (N, D) holds the
    base's and then the units' own coordinates' accelerations (the steered wheels' β̈)."""
    if pose_s is None:
        q, corr = odometry_from(model, angles_s, odometry_start)
    else:
        q, corr = pose_s, np.zeros_like(angles_s)
    qd = difference(q, dt, degree)
    qdd = difference(qd, dt, degree)
    rates = difference(angles_s, dt, degree)
    if model.n_dof > 3:
        own = difference(rates[:, model.coordinate_channels], dt, degree)
        qdd = np.concatenate([qdd, own], axis=1)
    return q, qd, qdd, rates, corr


def preprocess(log: Log, platform: Platform, span: Span | None = None,
               input_delay: float | DelayBracket = 0.0, row_step: int | None = None,
               ) -> Preprocessed:
    """Smooth, differentiate and trim one log (Sec. VI-B).

    ``input_delay`` [s] shifts the torques: the torque logged at t acts on the motion at
    t + delay; a :class:`DelayBracket` gives the torques at its node delays. ``row_step``:
    samples between equation rows (:class:`RowGrid`; None: about ten
    per smoother span).
    """
    span = span or Span.parse(None)
    model = PlatformModel(platform)
    log = with_fused_pose(log, model)  # a slow tracker corrects the odometry's drift
    notes = list(log.notes)
    t = log.t
    check_times(t, log.source)  # (a log read from a file was checked by its reader)
    angles, _ = unwrap_angles(platform.layout.wrapped, log.angles)
    current = log.currents
    pose = log.pose
    dt = grid_step(t)
    jitter = grid_jitter(t, dt)
    steps = np.diff(t)
    if not on_grid(steps, dt):
        t_new, angles = signals.resample_uniform(t, angles, dt)
        _, current = signals.resample_uniform(t, current, dt)
        if pose is not None:
            _, pose = signals.resample_uniform(t, tracker_pose(pose), dt)
        notes.append(jitter_note(log.source, steps.max(), steps.min(), dt))
        t = t_new
    n = len(t)
    k = span.samples(dt, n)
    nodes: np.ndarray | None = None
    shift: float | np.ndarray  # the torques' delay, or the bracket's node delays
    if isinstance(input_delay, DelayBracket):
        shift = nodes = input_delay.nodes(dt)
        order = input_delay.order(dt)
    else:
        shift, order = float(input_delay), 1
        check_input_delay(shift, k * dt)
    grid = RowGrid.for_span(k, row_step, span.degree)
    trim = grid.trim(k)  # the shifted end windows of both filter stages
    check_length(log.source, n, k, dt, trim)
    note = smoother_note(log.source, k, span.degree, dt)
    if note:
        notes.append(note)
    angles_s = smooth(angles, k, span.degree)
    pose_s = None if pose is None else smooth(tracker_pose(pose), k, span.degree)
    q, qd, qdd, rates, _ = derivatives(model, angles_s, pose_s, dt, degree=span.degree)
    tau = delayed(t, platform.torque_constants() * current, shift)
    return Preprocessed(t, q, qd, qdd, angles_s, rates, tau, log.source, k, dt, notes, trim,
                        grid, nodes, order, span.degree, jitter)


class Motion(Protocol):
    """What :func:`at_rest` reads: a preprocessed log's (:class:`Preprocessed`) or a planned
    run's (:class:`ropod_sysid.noise.MotionRows`) rates."""

    @property
    def qd(self) -> np.ndarray: ...  # (M, D) base twist first

    @property
    def angle_rates(self) -> np.ndarray: ...  # (M, J)


def at_rest(pre: Motion) -> np.ndarray:
    """Samples (M,) at which the platform stands still: base speed below
    :data:`REST_SPEED`, turn rate below :data:`REST_TURN` and every unit angle's rate below
    :data:`REST_RATE`."""
    speed = np.hypot(pre.qd[:, 0], pre.qd[:, 1])
    return ((speed < REST_SPEED) & (np.abs(pre.qd[:, 2]) < REST_TURN)
            & (np.abs(pre.angle_rates) < REST_RATE).all(axis=1))


def held_joints(model: PlatformModel, coordinate_rates: np.ndarray) -> np.ndarray:
    """(N, E) True where a unit's own coordinate moves slower than :data:`HELD_RATE` /
    friction_tanh_gain [rad/s], or than its channel's own ``held`` rate (a leg's: 2 mm/s):
    the fit locks it (:func:`raw_system`)."""
    channels = model.layout.angle_channels
    limit = np.array([HELD_RATE / model.alpha if channels[j].held is None else channels[j].held
                      for j in model.coordinate_channels])
    return np.abs(coordinate_rates) < limit


def raw_system(model: PlatformModel, pre: Preprocessed,
               friction: Friction = "per-wheel") -> tuple[np.ndarray, np.ndarray]:
    """A_ID,ext (M, 3, p) and b_ID (M, 3) sample by sample, before filtering (eqs. 36, 66);
    b_ID (M, 3, n) for torques at n node delays (:class:`DelayBracket`).

    Rows at rest (:func:`at_rest`) are zero on both sides: standing still, static friction
    holds whatever torques the drives apply (speed loops holding opposing currents, a
    controller reset), which the friction model, zero at zero rate, cannot explain; a zero row
    holds for any parameters, so the rows' filter mixes nothing false into its neighbours.
    A unit's own joint (a steered wheel's steering, a leg) is locked while it is held, its
    measured rate below :data:`HELD_RATE` / friction_tanh_gain: its own rows are zero and
    the projection carries nothing of them into the others (``State.held``). With constraints the
    rates and accelerations are first moved onto the allowed motions
    (:meth:`PlatformModel.consistent_motion`).
    """
    st = model.state(pre.q, pre.qd, pre.angles, pre.angle_rates)
    st, qdd = model.consistent_motion(st, pre.qdd)  # (unchanged without constraints)
    if model.n_dof > 3:  # a unit's own joint held: locked (its own rows vanish)
        st.held = held_joints(model, pre.angle_rates[:, model.coordinate_channels])
    a = model.a_id_ext(st, qdd, friction)
    b = model.b_id(st, pre.tau)  # b_ID = B_τ τ (eq. 35), per node delay if τ has them
    rest = at_rest(pre)
    if rest.any():
        a[rest] = 0.0
        b[rest] = 0.0
    return a, b


def row_inputs(pre: Preprocessed, index: np.ndarray, step: int | None = None) -> Preprocessed:
    """The row samples ``index`` of a block: their states, and the torques averaged over the
    samples around each: by the row grid's :attr:`RowGrid.torque_kernel`, or with ``step``
    given (the observer's) over an odd boxcar of 2⌊step/2⌋ + 1 samples."""
    mean = step is not None or pre.grid.degree == 2
    h = (pre.grid.step if step is None else step) // 2 if mean else pre.grid.torque_reach
    rows = pre.take(index)
    if h:
        rows.tau = row_average(pre.tau, index, np.full(2 * h + 1, 1.0 / (2 * h + 1)) if mean
                               else pre.grid.torque_kernel)
    return rows


def row_average(x: np.ndarray, index: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Σ_j w_j x[i − h + j] at each row sample i of ``index`` (h = (len(w) − 1) / 2): x (N, …)
    averaged over the samples around each row, (len(index), …).

    Summed offset by offset: gathering each row's whole window at once, (rows, …, 2h + 1),
    held the reference recipe's delay-bracket torques (eight channels at its node delays over
    41 samples) in 170 MB per block and took 65 ms of it."""
    h = (len(weights) - 1) // 2
    n = len(index)
    step = int(index[1] - index[0]) if n > 1 else 1
    first = int(index[0]) - h if n else 0
    if n and step > 0 and first >= 0 and np.array_equal(index, index[0] + step * np.arange(n)):
        def at(j: int) -> np.ndarray:  # evenly spaced rows (all of the fit's): a strided view
            return x[first + j: first + j + step * (n - 1) + 1: step]
    else:
        def at(j: int) -> np.ndarray:
            return x[index - h + j]
    out = weights[0] * at(0)
    for j in range(1, len(weights)):  # (taps, not samples)
        out += weights[j] * at(j)
    return out


def row_system(model: PlatformModel, pre: Preprocessed, first: int, count: int,
               friction: Friction = "per-wheel") -> tuple[np.ndarray, np.ndarray]:
    """Filtered A_ID,ext (count, 3, p) and b_ID (count, 3) of the ``count`` rows from sample
    ``first`` of the block ``pre``, which holds :attr:`RowGrid.halo` samples beyond them.

    The rows and the half-window of rows on each side are formed (:func:`row_inputs`,
    :func:`raw_system`); both sides pass through the same zero-phase LOESS over the rows,
    column by column, so that fast events the smoother cannot follow (Coulomb friction
    switching at a wheel-rate zero crossing, the speed loops' transients) are attenuated alike
    in A_ID,ext and b_ID.
    """
    grid = pre.grid
    h = (grid.span - 1) // 2
    index = first + grid.step * np.arange(-h, count + h)
    a, b = raw_system(model, row_inputs(pre, index), friction)
    return signals.loess(a, grid.span)[h: h + count], signals.loess(b, grid.span)[h: h + count]


def system(model: PlatformModel, pre: Preprocessed, friction: Friction = "per-wheel",
           chunk: int = 20000) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Filtered A_ID,ext and b_ID (:func:`row_system`) in blocks of at most ``chunk`` rows.

    Blocks overlap by the rows' half window, which makes the result equal to filtering the
    whole log at once. Yields (sample indices of the rows (m,), A (m, 3, p), b (m, 3)).
    """
    rows = pre.row_samples()
    for r0 in range(0, len(rows), chunk):
        idx = rows[r0: r0 + chunk]
        a, b = row_system(model, pre, int(idx[0]), len(idx), friction)
        yield idx, a, b


def filtered_system(model: PlatformModel, pre: Preprocessed,
                    friction: Friction = "per-wheel") -> tuple[np.ndarray, np.ndarray]:
    """The whole filtered, trimmed system of one log: A (M, 3, p), b (M, 3)."""
    parts = list(system(model, pre, friction))
    return (np.concatenate([a for _, a, _ in parts]), np.concatenate([b for _, _, b in parts]))


def block_triangles(a: np.ndarray, b: np.ndarray, label: str = "", first_row: int = 0,
                    stretch_rows: int = 0) -> Triangles:
    """:meth:`Triangles.from_rows` of A (m, 3, p) and b (m, 3) by a two-level TSQR: leaves of
    :data:`QR_LEAF_ROWS` rows reduced by one batched QR, their triangles by one more. Same
    triangle up to rounding (and row signs), several times faster on tall blocks. With
    ``stretch_rows`` also the stretches' normal-equation pieces
    (:func:`ropod_sysid.solve.stretch_grams`; the block's first row is the log's row
    ``first_row``)."""
    m, d_rows, p = a.shape
    b = b.reshape(m, d_rows, -1)  # (m, D, n): b_ID at n node delays (DelayBracket)
    w = p + b.shape[2]
    r = np.empty((3, w, w))
    idle = m - int(np.count_nonzero(np.abs(a).sum(axis=(1, 2)) + np.abs(b).sum(axis=(1, 2))))
    ab = np.concatenate([a, b], axis=2)
    for d in range(3):
        rows = kind_rows(ab, d)  # (m·n_d, w): the rows of this kind, sample by sample
        per = rows.shape[0] // m if m else 1
        leaf = QR_LEAF_ROWS * per
        full = rows.shape[0] // leaf * leaf
        parts = []
        if full:
            leaves = np.linalg.qr(rows[:full].reshape(-1, leaf, w), mode="r")
            # numpy's stubs: a QRResult for every mode, but mode="r" returns R alone
            parts.append(leaves.reshape(-1, w))  # type: ignore[attr-defined]
        if rows.shape[0] > full:
            parts.append(rows[full:])
        r[d] = qr_triangle(np.vstack(parts))
    stretches = [stretch_grams(a, b, first_row, stretch_rows)] if stretch_rows else []
    return Triangles(r, m, label, stretches=stretches, stretch_rows=stretch_rows,
                     idle=idle, per_row=per_row(d_rows))  # (zero rows, at rest, carry no equation)


def add_error_gram(block: Triangles, model: PlatformModel, pre: Preprocessed,
                   index: np.ndarray, friction: Friction, first_row: int,
                   encoder_counts: int | None, search_counts: int | None) -> None:
    """Give a block's triangles (the rows at sample ``index`` of ``pre``, the first the log's
    row ``first_row``) the encoders' error gram: of ``encoder_counts`` (``--encoder-counts``)
    on the fit's rows (past a log's first :data:`ropod_sysid.noise.FIT_GRAM_DENSE` gram rows
    sparser), else of ``search_counts`` (counts detected in the log, for the delay search's
    criterion alone) on the search's sparser rows
    (:func:`ropod_sysid.noise.search_gram_stride`); none without either."""
    counts = encoder_counts or search_counts
    if not counts:
        return
    from ropod_sysid.noise import (
        FIT_GRAM_DENSE,
        SEARCH_GRAM_DENSE,
        SEARCH_TONE_NODES,
        fit_error_gram,
        gram_stride,
        search_gram_stride,
    )

    if encoder_counts:
        stride = gram_stride(pre.grid.span)
        block.error_gram = fit_error_gram(model, pre, index, counts, friction, first_row,
                                          stride, None, FIT_GRAM_DENSE * stride)
    else:
        stride = search_gram_stride(pre.grid.span)
        block.error_gram = fit_error_gram(model, pre, index, counts, friction, first_row,
                                          stride, SEARCH_TONE_NODES, SEARCH_GRAM_DENSE * stride)
    block.error_counts = counts


def triangles(model: PlatformModel, pre: Preprocessed, friction: Friction = "per-wheel",
              chunk: int = 20000, encoder_counts: int | None = None,
              search_counts: int | None = None) -> Triangles:
    """The log's QR triangles per DOF, built block by block (memory bounded by ``chunk``);
    with ``encoder_counts`` also the encoders' error gram of A
    (:func:`ropod_sysid.noise.fit_error_gram`); else with ``search_counts`` (the counts
    detected in the log, for ``--input-delay auto``'s criterion alone) the gram of those on
    the search's sparser rows (:func:`ropod_sysid.noise.search_gram_stride`)."""
    tri: Triangles | None = None
    per = pre.grid.stretch_rows(pre.dt)
    for idx, a, b in system(model, pre, friction, chunk):
        row0 = (int(idx[0]) - pre.trim) // pre.grid.step
        block = block_triangles(a, b, pre.source, row0, per)
        add_error_gram(block, model, pre, idx, friction, row0, encoder_counts, search_counts)
        tri = block if tri is None else tri.merge(block)
    if tri is None:
        raise InputError(f"{pre.source}: no samples left after trimming the smoother's ends")
    tri.samples = len(pre.t) - 2 * pre.trim
    tri.duration = (len(pre.t) - 1) * pre.dt
    tri.correlation = pre.grid.correlation
    tri.delays, tri.delay_order = pre.delays, pre.delay_order
    return tri
