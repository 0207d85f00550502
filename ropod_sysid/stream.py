"""Chunked identification: a log of any length in bounded memory, equal to the in-memory path.

A log is read in chunks (:func:`ropod_sysid.io.csvlog.iter_csv_log` for CSV, also ``.csv.gz``;
:func:`ropod_sysid.io.mcaplog.iter_mcap_log` for MCAP, the robot's smart-wheel layout
included; a smart-wheel CSV is read whole and then processed in chunks) and goes
through the steps of :func:`ropod_sysid.regressor.preprocess` and
:func:`ropod_sysid.regressor.triangles` block by block:

1. pivot angles (and a tracker heading) unwrapped, continued across chunks;
2. the sample time from the head of the log (:func:`ropod_sysid.io.timebase.grid_step`); a log
   whose steps all stay on it is used as sampled, a jittered one is put on the uniform grid
   ``t0 + k dt`` by linear interpolation continued across chunks — the grid of the in-memory
   path. A step off the grid found after the head restarts the pass in resampling mode;
3. per block of kept samples [s, e): LOESS of the angles over the block with a halo of
   (k−1)/2 + 2 + h samples (the smoother's half-window for the angles, two samples for the two
   central differences — four for the quartic smoother's five-point ones, ``Span.reach`` —
   the rows' halo h = :attr:`ropod_sysid.regressor.RowGrid.halo`),
   odometry continued from the pose carried from the previous block, central differences,
   the rows of A_ID,ext and b_ID on the row grid (:class:`ropod_sysid.regressor.RowGrid`)
   and their LOESS, and the QR triangles of the block's rows merged into the log's (TSQR),
   with the normal-equation pieces of its 2 s stretches for the jackknife σ
   (:class:`ropod_sysid.solve.Triangles`; a block ending inside a stretch leaves it to the
   next). With ``--input-delay auto`` b_ID is formed for each node delay of the bracket
   (:class:`ropod_sysid.regressor.DelayBracket`), the window reaching back and ahead by the
   largest delays; without ``--encoder-counts``, when the first chunk's angles move by whole
   counts (:func:`ropod_sysid.quantisation.detect_encoder_counts`), also the error gram of those
   counts (:func:`ropod_sysid.noise.fit_error_gram`, on the search's sparser rows:
   :func:`ropod_sysid.noise.search_gram_stride`), for the search's criterion alone
   (:func:`ropod_sysid.delay.delay_search`).

Every sample's value is computed from the same neighbours by the same formula as in one pass,
so the triangles equal the in-memory ones to rounding (the FFT convolution of long windows is
the only step whose rounding depends on the block). Memory is bounded by the chunk size plus
the halo. The rotational weight needs the mean squares of b_ID, which the per-DOF triangles
give after the pass (:meth:`Triangles.mean_square_b`).

The chunks come from :mod:`ropod_sysid.chunks` (:func:`iter_chunks`, read ahead in a thread)
and steps 1–2 are :mod:`ropod_sysid.grid`; this module holds step 3 (the block reducer), the
passes over a log or its pieces and the entry points.

:func:`ropod_sysid.validate.validate_source` does the same for validation: the disturbance
observer's causal low-pass keeps its filter state across blocks. The recipe check's reference
recipe can take the same samples beside the fit's (:mod:`ropod_sysid.reference`).

The chunks' time base is checked as they come (:mod:`ropod_sysid.io.timebase`): a gap in time
is an error, or with ``split_gaps`` (:func:`stream_pieces`) the end of one piece and the start
of the next, each passed through steps 1–3 as a log of its own.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid import crosscheck
from ropod_sysid.chunks import (
    DEFAULT_CHUNK,
    Source,
    _prefetch,
    estimated_samples,
    fewest_samples,
    iter_chunks,
    single_thread_blas,
    source_name,
)
from ropod_sysid.errors import InputError
from ropod_sysid.grid import _Grid, _OffGrid, _Samples
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import piece_name, piece_note, split_chunks
from ropod_sysid.lowpass import butter2_lowpass
from ropod_sysid.model import PlatformModel
from ropod_sysid.odometry import OdometryState
from ropod_sysid.params import DynamicParameters, Friction
from ropod_sysid.platform import Platform
from ropod_sysid.plotdata import LogPlot, PlotGather
from ropod_sysid.recipe import delay_reach
from ropod_sysid.reference import (
    KeptRows,
    PieceReference,
    Reference,
    ReferenceBudget,
    ReferenceTee,
)
from ropod_sysid.regressor import (
    DelayBracket,
    Preprocessed,
    RowGrid,
    Span,
    TooShort,
    add_error_gram,
    block_triangles,
    check_input_delay,
    check_length,
    check_piece_samples,
    delayed,
    derivatives,
    left_out,
    no_piece_left,
    row_inputs,
    row_system,
    smooth,
    smoother_note,
)
from ropod_sysid.solve import Triangles
from ropod_sysid.validate import (
    OBSERVER_CUTOFF_HZ,
    ObserverStats,
    observer_samples,
    observer_step,
)

if TYPE_CHECKING:
    from ropod_sysid.fit import FitOptions

ROWS_IN_FLIGHT = 2  # blocks whose rows the worker thread may still be reducing


# ---------------------------------------------------------------------------------------------
# results


@dataclass
class StreamResult:
    """What one streamed log gives: its triangles, the reading notes and its grid."""

    source: str
    triangles: Triangles
    notes: list[str]
    samples: int  # samples on the grid, before trimming
    dt: float
    span_samples: int
    observer: ObserverStats | None = field(default=None, repr=False)
    plot: LogPlot | None = field(default=None, repr=False)  # what the report draws


# ---------------------------------------------------------------------------------------------
# the pass: step 3


class _Blocks:
    """Step 3: blocks of kept samples with their halo, through to the merged triangles."""

    def __init__(self, platform: Platform, span: Span, input_delay: float | DelayBracket,
                 friction: Friction,
                 chunk: int, source: str, params: DynamicParameters | None,
                 keep_series: bool, row_step: int | None = None, threaded: bool = True,
                 plot: bool = False, encoder_counts: int | None = None) -> None:
        self.platform = platform
        self.encoder_counts = encoder_counts
        # --input-delay auto without encoder_counts: the counts detected on the first chunk
        # (_Run.push), whose gram corrects the search's criterion alone (delay.delay_search)
        self.search_counts: int | None = None
        self.model = PlatformModel(platform)
        self.k_t = platform.torque_constants()
        self.span = span
        self.reach = span.reach  # samples each side the two differences reach
        self.bracket = input_delay if isinstance(input_delay, DelayBracket) else None
        self.delay: float | np.ndarray = (0.0 if isinstance(input_delay, DelayBracket)
                                          else float(input_delay))
        self.friction = friction
        self.chunk = max(int(chunk), 1)
        self.row_step = row_step
        self.source = source
        self.params = params
        self.keep_series = keep_series
        self.gather = PlotGather() if plot else None
        self.parts: list[_Samples] = []
        self.flushed = False  # the last samples reduced (flush)
        self.g0 = 0  # index of the first buffered sample
        self.avail = 0  # samples received
        self.tri: Triangles | None = None
        self.odo: OdometryState | None = None
        self.jitter = 0.0  # half-width of the sample instants' jitter (start(): grid_jitter)
        self.obs = ObserverStats() if params is not None else None
        self.keep = KeptRows()  # rows also kept apart (keep_rows)
        # the rows of block i are reduced in a worker thread while block i+1 is smoothed (numpy
        # releases the GIL in its loops); one worker keeps the merge order of the triangles
        self.worker = (ThreadPoolExecutor(1, thread_name_prefix="ropod-sysid-rows")
                       if threaded else None)
        self.pending: deque[Future[None]] = deque()

    def start(self, dt: float, jitter: float = 0.0) -> None:
        self.dt = dt
        self.jitter = jitter
        self.k = self.span.samples(dt, 0)
        if self.bracket is not None:
            self.delay = self.bracket.nodes(dt)  # b_ID at each node delay
        else:
            check_input_delay(float(self.delay), self.k * dt)
        self.c = (self.k - 1) // 2
        self.grid = RowGrid.for_span(self.k, self.row_step, self.span.degree)
        self.halo = self.grid.halo
        self.trim = self.grid.trim(self.k)
        d = self.grid.step  # blocks start on the row grid
        self.block = max(self.chunk // d, 1) * d
        self.s = self.trim  # next kept sample to reduce
        self.lookback, self.lookahead = delay_reach(self.delay, dt)
        if self.params is not None:
            self.obs_step = observer_step(dt, self.grid.step)
            self.lowpass = butter2_lowpass(dt * self.obs_step, OBSERVER_CUTOFF_HZ)
            self.m_params = self.params.vector(self.model.parameter_names(self.friction))

    def push(self, samples: _Samples) -> None:
        if len(samples):
            self.parts.append(samples)
            self.avail += len(samples)
            self._drain(None)

    def flush(self) -> None:
        """Reduce the last samples (their rows' thread may still be at work: :meth:`finish`
        waits for it); the samples themselves are then released."""
        n = self.avail
        check_length(self.source, n, self.k, self.dt, self.trim)
        self._drain(n)
        self.parts = []
        self.flushed = True

    def finish(self) -> tuple[Triangles, ObserverStats | None, int]:
        n = self.avail
        if not self.flushed:
            self.flush()
        self._wait(0)
        if self.tri is None:  # pragma: no cover - excluded by the length check
            raise InputError(f"{self.source}: no samples left after trimming the smoother's ends")
        for index, (start, stop) in enumerate(self.keep.ranges):
            self.keep.close(index, self.tri)  # (where the piece ended in the range)
            kept = self.keep.kept[index]
            if kept is not None and kept is not self.tri:
                a = self.trim if start is None else start
                self._finish_triangles(kept, min(stop, n - self.trim) - a + 2 * self.trim)
        self._finish_triangles(self.tri, n)
        return self.tri, self.obs, n

    def _finish_triangles(self, tri: Triangles, n: int) -> None:
        """What the triangles of the rows of n samples carry besides the rows."""
        tri.samples = n - 2 * self.trim
        tri.duration = (n - 1) * self.dt
        tri.correlation = self.grid.correlation
        if self.bracket is not None:
            tri.delays = np.asarray(self.delay)  # (the bracket's node delays)
            tri.delay_order = self.bracket.order(self.dt)

    def keep_rows(self, start: int | None, stop: int) -> int:
        """Keep the triangles of the rows of kept samples [``start``, ``stop``) apart (None:
        from the first row; both taken up to the row grid) in :attr:`KeptRows.kept`, after
        :meth:`finish`, at the index returned: blocks end there. Ranges come in order, each
        ahead of the rows reduced so far. The recipe check's reference windows
        (:class:`ropod_sysid.reference.ReferenceTee`) are compared with them."""
        step = self.grid.step

        def on_grid(index: int) -> int:
            return self.trim + max(0, -(-(index - self.trim) // step)) * step

        a = None if start is None else max(on_grid(start), self.s)
        index = self.keep.add(a, max(on_grid(stop), a or self.s))
        if self.keep.ranges[index][1] == self.s:  # (the rows already reach it)
            self._submit(self._close_range, index)
        return index

    def drop_kept(self, index: int) -> None:
        """Keep the rows of range ``index`` no more (its reference window was left out)."""
        self.keep.dropped.add(index)
        self._submit(self._close_range, index)

    def _close_range(self, index: int) -> None:
        """(In the rows' thread, after the blocks of the range.)"""
        self.keep.close(index, self.tri)

    def close(self) -> None:
        """Stop the worker thread (also after an error: queued blocks are dropped)."""
        if self.worker is not None:
            self.worker.shutdown(wait=True, cancel_futures=True)
            self.worker = None

    def _submit(self, work: Callable[..., None], *args: object) -> None:
        if self.worker is None:
            work(*args)
            return
        self.pending.append(self.worker.submit(work, *args))
        self._wait(ROWS_IN_FLIGHT)

    def _wait(self, in_flight: int) -> None:
        """Wait until at most ``in_flight`` blocks are pending; their errors surface here."""
        while len(self.pending) > in_flight:
            self.pending.popleft().result()

    def _drain(self, n: int | None) -> None:
        c = self.c
        while True:
            s = self.s
            mark = self.keep.next_edge(s)
            if n is not None:
                end = n - self.trim
                if s >= end:
                    return
                e = min(s + self.block, end, mark or end)
                last = e == end
            else:
                e = min(s + self.block, mark or s + self.block)
                if e + self.halo + self.reach + max(c, self.lookahead) > self.avail:
                    return
                last = False
            self._reduce(s, e, last, n)
            self.s = e
            for index, (_, b) in enumerate(self.keep.ranges):
                if b == e:
                    self._submit(self._close_range, index)
            # keep what the next block reaches back to
            keep = max(0, min(e - self.halo - self.reach - c, e - self.halo - self.lookback))
            self._drop_before(keep)

    def _window(self, r0: int, r1: int) -> _Samples:
        buf = _Samples.join(self.parts)
        self.parts = [buf]
        return buf.take(r0 - self.g0, r1 - self.g0)

    def _drop_before(self, index: int) -> None:
        if index <= self.g0:
            return
        buf = _Samples.join(self.parts)
        cut = index - self.g0
        self.parts = [buf.take(cut, len(buf))]
        self.g0 = index

    def _reduce(self, s: int, e: int, last: bool, n: int | None) -> None:
        """Reduce kept samples [s, e) to triangles (and observer figures)."""
        c, k, dt, halo = self.c, self.k, self.dt, self.halo
        first = s == self.trim
        reach, degree = self.reach, self.span.degree  # the differences' samples each side
        qa = 0 if first else s - halo - reach  # first sample of the pose
        r0 = max(0, min(qa - c, s - halo - self.lookback))  # first raw sample
        r1 = n if last else e + halo + reach + max(c, self.lookahead)
        assert r1 is not None
        w = self._window(r0, r1)
        q1 = r1 if last else e + halo + reach
        i0, i1 = qa - r0, q1 - r0
        angles = smooth(w.angles, k, degree)[i0:i1]
        pose = None if w.pose is None else smooth(w.pose, k, degree)[i0:i1]
        q, qd, qdd, rates, corr = derivatives(self.model, angles, pose, dt,
                                              None if first else self.odo, degree)
        if w.pose is None and not last:
            j = (e - halo - reach) - qa  # the next block's first pose sample
            self.odo = OdometryState(q[j].copy(), corr[j].copy())
        tau = delayed(w.t, self.k_t * w.currents, self.delay)
        # samples [pa, pb) are preprocessed: the rows need [s - halo, e + halo); the
        # observer, every sample from 0 to n
        pa, pb = s - halo, e + halo
        oa, ob = (0 if first else s), (r1 if last else e)
        if self.obs is not None:
            pa, pb = min(pa, oa), max(pb, ob)
        if self.gather is not None:  # every sample once, as the observer sees them
            jo, jp = slice(oa - r0, ob - r0), slice(oa - qa, ob - qa)
            self.gather.push_samples(w.t[jo], q[jp], qd[jp],
                                     w.angles[jo][:, self.platform.layout.wrapped],
                                     self.k_t * w.currents[jo])
        jq = slice(pa - qa, pb - qa)
        jr = slice(pa - r0, pb - r0)
        pre = Preprocessed(w.t[jr], q[jq], qd[jq], qdd[jq], angles[jq], rates[jq], tau[jr],
                           self.source, k, dt, [], 0, self.grid, degree=degree,
                           jitter=self.jitter)
        self._submit(self._rows, pre, s - pa, len(range(s, e, self.grid.step)), pa, oa, ob,
                     last, self.keep.inside(s, e))

    def _rows(self, pre: Preprocessed, first: int, count: int, pa: int, oa: int, ob: int,
              last: bool, keep: int | None = None) -> None:
        """The block's rows to its triangles, merged in order (and the observer's samples);
        also into the triangles of kept range ``keep``."""
        a, b = row_system(self.model, pre, first, count, self.friction)
        if self.gather is not None:
            rows = first + self.grid.step * np.arange(count)
            self.gather.push_rows(pre.t[rows], a, b, pre.qd[rows], pre.q[rows], pre.qdd[rows],
                                  pre.angles[rows], pre.angle_rates[rows], pre.tau[rows])
        row0 = (pa + first - self.trim) // self.grid.step  # the log's row number of the first
        block = block_triangles(a, b, self.source, row0, self.grid.stretch_rows(self.dt))
        add_error_gram(block, self.model, pre, first + self.grid.step * np.arange(count),
                       self.friction, row0, self.encoder_counts, self.search_counts)
        self.tri = block if self.tri is None else self.tri.merge(block)
        if keep is not None:
            self.keep.merge(keep, block)
        if self.obs is not None:
            self._observe(pre, pa, oa, ob, last)

    def _observe(self, pre: Preprocessed, pa: int, oa: int, ob: int, last: bool) -> None:
        """The disturbance observer (eq. 40, causal 10 Hz low-pass) on its samples in
        [oa, ob) (:func:`ropod_sysid.validate.observer_samples`); ``pre`` starts at ``pa``."""
        assert self.obs is not None and self.params is not None
        step = self.obs_step
        idx = observer_samples(oa, ob - step // 2 if last else ob, step)
        at = row_inputs(pre, idx - pa, step)
        st = self.model.state(at.q, at.qd, at.angles, at.angle_rates)
        f_b = self.model.disturbance(st, self.params, at.qdd, at.tau, self.friction)
        f_hat = self.lowpass(f_b)
        keep = (idx >= self.trim) & ((idx < ob - self.trim) if last else True)
        self.obs.add(f_hat[keep], at.t[keep], self.keep_series)


# ---------------------------------------------------------------------------------------------
# entry points


class _Run:
    """The pass over one log, or over one piece of it (--split-gaps); with ``check`` (the
    fit's options) and ``budget`` also the recipe check's reference (:class:`ReferenceTee`)."""

    def __init__(self, name: str, piece: int, first: int, resample: bool,
                 blocks: _Blocks, check: FitOptions | None = None,
                 budget: ReferenceBudget | None = None) -> None:
        self.name = name
        self.piece = piece
        self.first = first  # the piece's first sample in the log
        self.blocks = blocks
        self.tee: ReferenceTee | None = None
        self.detected: int | None = None  # the counts the first chunk's angles move by
        if check is not None and budget is not None:
            self.tee = ReferenceTee(blocks, lambda dt: self._reference_blocks(check, dt),
                                    budget, name, first)
        self.grid = _Grid(name, resample, self.tee or blocks)
        self.notes: list[str] = []
        self.raw = 0  # samples read
        self.t0 = self.t1 = 0.0

    def _reference_blocks(self, check: FitOptions, dt: float) -> _Blocks:
        """The reference recipe's blocks (:func:`ropod_sysid.crosscheck.reference_options`
        at this log's sample time ``dt``), as the primary's otherwise."""
        options = crosscheck.reference_options(check, dt)
        own = self.blocks
        ref = _Blocks(own.platform, options.span, options.reduce_delay(), own.friction,
                      own.chunk, own.source, None, False, own.row_step,
                      threaded=own.worker is not None, encoder_counts=own.encoder_counts)
        if ref.bracket is not None and ref.encoder_counts is None:
            ref.search_counts = self.detected
        return ref

    def reference(self) -> PieceReference | None:
        """The piece's reference (:class:`PieceReference`) after :meth:`finish`; None without
        one (no check asked, or dropped: an error of the reference recipe)."""
        if self.tee is None:
            return None
        return self.tee.finish()

    def close(self) -> None:
        self.blocks.close()
        if self.tee is not None:
            self.tee.close()

    def push(self, log: Log) -> None:
        if not self.raw:
            from ropod_sysid.quantisation import counts_note, log_encoder_counts

            self.t0 = float(log.t[0])
            detected = self.detected = log_encoder_counts(log)
            quartic = log.n_samples > 1 and self.blocks.span.quartic_would_fit(
                float(np.median(np.diff(log.t))))
            note = counts_note(self.name, detected, self.blocks.encoder_counts,
                               self.blocks.model.constrained, quartic)
            if note is not None:
                self.notes.append(note)
            if self.blocks.bracket is not None and self.blocks.encoder_counts is None:
                self.blocks.search_counts = detected  # before the first block is reduced
        self.raw += log.n_samples
        self.t1 = float(log.t[-1])
        self.notes.extend(n for n in log.notes if n not in self.notes)  # (MCAP damage: last)
        self.grid.push(log)

    def finish(self) -> StreamResult:
        notes = self.notes + self.grid.finish()
        blocks = self.blocks
        tri, obs, n = blocks.finish()
        note = smoother_note(self.name, blocks.k, blocks.span.degree, blocks.dt)
        notes += [note] if note else []
        shown = None
        if blocks.gather is not None:
            shown = blocks.gather.result(self.raw, self.t1 - self.t0, bool(self.grid.has_pose),
                                         blocks.dt, blocks.k, blocks.grid.step)
        return StreamResult(self.name, tri, notes, n, blocks.dt, blocks.k, obs, shown)


def _pass(source: Source, platform: Platform, span: Span, input_delay: float | DelayBracket,
          friction: Friction, chunk: int, params: DynamicParameters | None, keep_series: bool,
          resample: bool, prefetch: bool, row_step: int | None, split_gaps: bool,
          done: list[StreamResult | None], dropped: list[str], plot: bool = False,
          encoder_counts: int | None = None, check: FitOptions | None = None,
          done_ref: list[PieceReference | None] | None = None,
          budget: ReferenceBudget | None = None) -> None:
    """One pass over a log; with ``split_gaps`` over each piece between its gaps as a log of
    its own. Finished pieces go to ``done`` (None: too short, with a note in ``dropped``);
    pieces already there (from a pass stopped by :class:`_OffGrid`) are skipped, and
    ``resample`` puts the first of the others on the uniform grid from its start; ``plot``
    gathers what the report draws of each piece. With ``check`` (the fit's options) and
    ``budget`` each piece's recipe-check reference goes to ``done_ref`` beside it
    (:class:`ReferenceTee`; None where it was dropped)."""
    name = source_name(source)
    restart = len(done)  # the piece the pass restarts at
    chunks = iter_chunks(source, platform, chunk, "allow" if split_gaps else "error")
    if prefetch and not isinstance(source, Log):
        chunks = _prefetch(chunks)
    if split_gaps:
        chunks = split_chunks(chunks, name)
    run: _Run | None = None
    first = 0  # samples of the log before this chunk

    def finish(run: _Run, last: bool) -> None:
        if split_gaps and not (last and run.piece == 0):  # a log without gaps keeps its name
            run.name = run.grid.source = run.blocks.source = piece_name(name, run.piece)
        ref = None
        try:
            check_piece_samples(run.name, run.raw)
            res = run.finish()
            ref = run.reference()
        except TooShort as exc:
            if not split_gaps:
                raise
            done.append(None)
            if done_ref is not None:
                done_ref.append(None)
            dropped.append(left_out(exc))
            return
        finally:
            run.close()
        if run.name != name:
            res.triangles.label = run.name
            res.notes.insert(0, piece_note(run.name, name, run.first, run.raw, run.t0, run.t1))
            for window, main in [] if ref is None else ref.windows:
                window.triangles.label = window.source = run.name
                if main is not None:
                    main.label = run.name
        done.append(res)
        if done_ref is not None:
            done_ref.append(ref)

    try:
        for log in chunks:
            if log.piece >= len(done):
                if run is not None and log.piece != run.piece:
                    finish(run, last=False)
                    run = None
                if run is None:
                    blocks = _Blocks(platform, span, input_delay, friction, chunk, name, params,
                                     keep_series, row_step, threaded=prefetch, plot=plot,
                                     encoder_counts=encoder_counts)
                    run = _Run(name, log.piece, first, resample and log.piece == restart,
                               blocks, check, budget)
                run.push(log)
            first += log.n_samples
        if run is not None:
            finish(run, last=True)
            run = None
    except _OffGrid:
        if run is not None and run.tee is not None:  # the piece is passed again
            run.tee.refund()
        raise
    finally:
        if run is not None:
            run.close()


def stream_pieces(source: Source, platform: Platform, span: Span | None = None,
                  input_delay: float | DelayBracket = 0.0, friction: Friction = "per-wheel",
                  chunk: int = DEFAULT_CHUNK, params: DynamicParameters | None = None,
                  keep_series: bool = False, prefetch: bool = True,
                  row_step: int | None = None, split_gaps: bool = False, plot: bool = False,
                  encoder_counts: int | None = None, check: FitOptions | None = None,
                  references: list[PieceReference | None] | None = None,
                  budget: ReferenceBudget | None = None) -> list[StreamResult]:
    """:func:`stream_log`; with ``split_gaps`` a log with gaps in time
    (:mod:`ropod_sysid.io.timebase`) gives one result per piece between them, each a log of
    its own (its grid, its smoother ends), named ``run.csv[2]`` …; a piece too short for the
    smoother span is left out with a note (on the first piece kept); none left is an error.
    Without ``split_gaps`` a gap is an error. ``plot``: see :func:`stream_log`.
    ``encoder_counts``: also the encoders' error gram of A (``fit --encoder-counts``).
    ``check`` (the fit's options, with ``references``): also the recipe check's reference of
    each piece kept, into ``references`` (:func:`piece_triangles_checked`), drawing on
    ``budget`` (one for the whole log by default)."""
    span = span or Span.parse(None)
    if chunk < 1:
        raise InputError(f"chunk size {chunk}: must be a positive number of samples")
    RowGrid.check_step(row_step)  # a bad row step fails before the file is opened
    done: list[StreamResult | None] = []
    done_ref: list[PieceReference | None] = []
    dropped: list[str] = []
    resample = False
    if check is not None and budget is None:  # the pieces of a log share one
        name = source_name(source)
        budget = ReferenceBudget.for_logs(check.recipe_check, [name], [fewest_samples(source)],
                                          lambda _: estimated_samples(source))
    with single_thread_blas():
        while True:
            try:
                _pass(source, platform, span, input_delay, friction, chunk, params,
                      keep_series, resample, prefetch, row_step, split_gaps, done, dropped,
                      plot, encoder_counts, check, done_ref if check is not None else None,
                      budget)
                break
            except _OffGrid:
                # a step off the grid after the head: the log (piece) is jittered after all;
                # again, on the uniform grid from its start
                resample = True
    kept = [r for r in done if r is not None]
    if not kept:
        raise no_piece_left(source_name(source), dropped)
    kept[0].notes.extend(dropped)
    if references is not None:
        references.extend(ref for r, ref in zip(done, done_ref, strict=True) if r is not None)
    return kept


def stream_log(source: Source, platform: Platform, span: Span | None = None,
               input_delay: float | DelayBracket = 0.0, friction: Friction = "per-wheel",
               chunk: int = DEFAULT_CHUNK, params: DynamicParameters | None = None,
               keep_series: bool = False, prefetch: bool = True,
               row_step: int | None = None, plot: bool = False) -> StreamResult:
    """One pass over a log (a file, or an in-memory :class:`Log`) in chunks of ``chunk``
    samples: its QR triangles per DOF, equal to ``triangles(model, preprocess(log, …))`` to
    rounding; with ``params`` also the disturbance observer's figures (``keep_series``: and
    its low-passed series, O(N) memory). ``row_step``: samples between equation rows
    (:class:`ropod_sysid.regressor.RowGrid`; None: about ten per smoother span). ``plot``:
    also gather what the report draws (:class:`ropod_sysid.plotdata.LogPlot`, bounded size).

    ``prefetch`` reads the next chunk in a background thread while one is processed, and
    reduces a block's rows in another while the next block is smoothed.
    """
    return stream_pieces(source, platform, span, input_delay, friction, chunk, params,
                         keep_series, prefetch, row_step, plot=plot)[0]


def log_triangles(source: Source, platform: Platform, span: Span | None = None,
                  input_delay: float = 0.0, friction: Friction = "per-wheel",
                  chunk: int = DEFAULT_CHUNK, row_step: int | None = None,
                  ) -> tuple[Triangles, list[str]]:
    """A log's triangles and reading notes."""
    res = stream_log(source, platform, span, input_delay, friction, chunk, row_step=row_step)
    return res.triangles, res.notes


def piece_triangles(source: Source, platform: Platform, span: Span | None = None,
                    input_delay: float | DelayBracket = 0.0, friction: Friction = "per-wheel",
                    chunk: int = DEFAULT_CHUNK, row_step: int | None = None,
                    split_gaps: bool = False, plot: bool = False,
                    encoder_counts: int | None = None,
                    ) -> list[tuple[str, Triangles, list[str], LogPlot | None]]:
    """(name, triangles, reading notes, plot data) of a log, or of each of its pieces with
    ``split_gaps`` (:func:`stream_pieces`): the unit of work of a fit, run on Dask workers.
    ``plot``: also what the report draws (bounded size), else None."""
    return [(r.source, r.triangles, r.notes, r.plot)
            for r in stream_pieces(source, platform, span, input_delay, friction, chunk,
                                   row_step=row_step, split_gaps=split_gaps, plot=plot,
                                   encoder_counts=encoder_counts)]


def piece_triangles_checked(source: Source, platform: Platform, check: FitOptions,
                            input_delay: float | DelayBracket = 0.0,
                            chunk: int = DEFAULT_CHUNK, plot: bool = False,
                            budget: ReferenceBudget | None = None,
                            ) -> tuple[list[tuple[str, Triangles, list[str], LogPlot | None]],
                                       Reference | None]:
    """:func:`piece_triangles` under the fit's options ``check`` (their span, friction, row
    step, pieces and encoder counts; b_ID at ``input_delay``), and from the same samples the
    recipe check's reference (:mod:`ropod_sysid.crosscheck`): the pieces the reference fit's
    own pass would give, so that the check reads the log once. The samples it is formed on are
    drawn from ``budget`` (default: :func:`ropod_sysid.crosscheck.reference_budget` of the
    log; :class:`ReferenceBudget`, which the logs of one fit share when they are reduced
    serially): where it ends inside the log the reference is cut there and
    :attr:`Reference.main` holds the fit's own rows up to the same sample
    (:attr:`Reference.partial`). The reference is None where it could not be formed here — a
    piece too short for its span, or pieces whose sample times give different reference
    spans — and the check then reads the log again (or is left out)."""
    refs: list[PieceReference | None] = []
    res = stream_pieces(source, platform, check.span, input_delay, check.friction, chunk,
                        row_step=check.row_step, split_gaps=check.split_gaps, plot=plot,
                        encoder_counts=check.encoder_counts, check=check, references=refs,
                        budget=budget)
    pieces = [(r.source, r.triangles, r.notes, r.plot) for r in res]
    return pieces, Reference.of_pieces(pieces, refs)
