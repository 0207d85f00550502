"""The recipe check's reference formed in the fit's own pass over a log
(:func:`ropod_sysid.stream.piece_triangles_checked`).

``fit``'s recipe check (:mod:`ropod_sysid.crosscheck`) fits the logs a second way. Reading and
decoding a log is about half of a fit's work, so the second recipe's blocks
(:class:`ropod_sysid.stream._Blocks`, at the reference's span and delay bracket) take the same
grid samples as the fit's own, through :class:`ReferenceTee`, and the reference fit then solves
from their triangles (:class:`Reference`). The automatic check runs on logs of up to
:data:`ropod_sysid.crosscheck.AUTO_MAX_SAMPLES` samples in all; on longer ones on windows
spread over them, or on their first samples where their length is not known beforehand
(:class:`ReferenceBudget`). Where the reference recipe does not fit a log (a piece too short
for its span) the reference is dropped and the check reads the logs again when it still runs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ropod_sysid.errors import InputError

if TYPE_CHECKING:
    from ropod_sysid.grid import _Samples
    from ropod_sysid.plotdata import LogPlot
    from ropod_sysid.regressor import DelayBracket, Span
    from ropod_sysid.solve import Triangles
    from ropod_sysid.stream import StreamResult, _Blocks

__all__ = ["KeptRows", "PieceReference", "Reference", "ReferenceBudget", "ReferenceTee"]


@dataclass(frozen=True)
class PieceReference:
    """The reference of one piece of a log (a log without gaps is one piece), from its
    :class:`ReferenceTee`: the reference recipe's span and delay, and for each window of the
    piece its triangles (a :class:`StreamResult`) with the fit's own triangles of the rows
    over the same samples (None: the piece's own, the window being all of it). No windows
    (and span and delay None) where the budget had none in the piece."""

    span: Span | None
    delay: float | DelayBracket | None
    windows: list[tuple[StreamResult, Triangles | None]]
    spread: bool = False  # a window starts after the piece's first sample
    failure: str | None = None  # why the first window left out was (its InputError)


@dataclass(frozen=True)
class Reference:
    """The recipe check's reference of a log, formed in the fit's own pass
    (:func:`ropod_sysid.stream.piece_triangles_checked`): the reference recipe's span and what
    its b_ID was formed at (a delay, or the search's bracket), as
    :func:`ropod_sysid.crosscheck.reference_options` gave them for the log's sample time, and
    a piece of the reference for each of its windows."""

    span: Span | None  # (None: no window in the log)
    delay: float | DelayBracket | None
    pieces: list[tuple[str, Triangles, list[str], LogPlot | None]]
    # the fit's own triangles over the same samples, window for window
    main: list[tuple[str, Triangles, list[str], LogPlot | None]]
    partial: bool = False  # the windows leave out some of the log
    spread: bool = False  # they are spread over it (ReferenceBudget.windows), not its first
    failure: str | None = None  # no window: why the first left out was (PieceReference)

    @staticmethod
    def of_pieces(pieces: list[tuple[str, Triangles, list[str], LogPlot | None]],
                  refs: list[PieceReference | None]) -> Reference | None:
        """The log's reference from its pieces' (``refs``, beside the fit's ``pieces``); None
        where one was dropped or their spans or delays differ."""
        if any(ref is None for ref in refs):
            return None
        got = [(piece, ref) for piece, ref in zip(pieces, refs, strict=True)
               if ref is not None and ref.windows]
        partial = (len(got) < len(refs)
                   or any(len(ref.windows) > 1 or ref.windows[0][1] is not None
                          for _, ref in got))
        if not got:
            failure = next((ref.failure for ref in refs if ref is not None and ref.failure),
                           None)
            return Reference(None, None, [], [], partial, failure=failure)
        span, delay = got[0][1].span, got[0][1].delay
        if any(ref.span != span or ref.delay != delay for _, ref in got):
            return None
        return Reference(
            span, delay,
            [(r.source, r.triangles, r.notes, r.plot) for _, ref in got for r, _ in ref.windows],
            [(name, tri if main is None else main, [], None)
             for (name, tri, _, _), ref in got for _, main in ref.windows], partial,
            any(ref.spread for _, ref in got))


@dataclass
class ReferenceBudget:
    """Where the recipe check's reference is formed, over the logs of one fit (``fit``'s
    automatic check, :func:`ropod_sysid.crosscheck.reference_budget`): ``windows`` planned by
    log name (:func:`ropod_sysid.crosscheck.reference_windows`, samples of each log), or
    without them the first ``left`` samples (None, ``--recipe-check``: all), which serially
    every log draws on. On Dask workers each log has a copy: a log alone is bounded."""

    left: int | None
    windows: dict[str, list[tuple[int, int]]] | None = None
    align: int = 1  # the windows start on multiples of it in each piece (window_align)

    @classmethod
    def for_logs(cls, mode: bool | str, names: list[str], fewest: list[int],
                 estimated: Callable[[str], int]) -> ReferenceBudget:
        """The budget of logs ``names`` of at least ``fewest`` samples each
        (:func:`ropod_sysid.chunks.fewest_samples`), whose lengths ``estimated`` gives
        (:func:`ropod_sysid.chunks.estimated_samples`) when they are surely over it."""
        from ropod_sysid import crosscheck

        budget = crosscheck.reference_budget(mode, sum(fewest))
        if budget is None or sum(fewest) <= crosscheck.AUTO_MAX_SAMPLES:
            return cls(budget)
        plan = crosscheck.reference_windows([estimated(n) for n in names], budget)
        return cls(budget, dict(zip(names, plan, strict=True)),
                   crosscheck.window_align(budget))

    def of_piece(self, name: str, first: int) -> list[tuple[int, float]]:
        """The windows of the piece of log ``name`` from its sample ``first`` on, in the
        piece's samples (a window's stop may lie past the piece's end). A window's start moves
        up to the next multiple of :attr:`align` from the piece's start (--split-gaps: a
        piece may start anywhere), so that its rows fitted as a log of their own are on the
        piece's row grid, as they are on the log's without gaps."""
        if self.windows is not None:
            out: list[tuple[int, float]] = []
            for a, b in self.windows.get(name, []):
                start = -(-max(a - first, 0) // self.align) * self.align
                if start < b - first:
                    out.append((start, b - first))
            return out
        if self.left is None:
            return [(0, math.inf)]
        return [(0, self.left)] if self.left > 0 else []

    def spend(self, n: int) -> None:
        """``n`` samples were formed on (the first samples' budget)."""
        if self.windows is None and self.left is not None:
            self.left -= n


class KeptRows:
    """The fit's rows kept apart over the reference's windows
    (:meth:`ropod_sysid.stream._Blocks.keep_rows`): ranges of kept samples [start, stop)
    (start None: from the first row, whose triangles are the fit's own up to ``stop``), their
    triangles, and which were closed or left out (their window was)."""

    def __init__(self) -> None:
        self.ranges: list[tuple[int | None, int]] = []
        self.kept: list[Triangles | None] = []
        self.closed: list[bool] = []
        self.dropped: set[int] = set()

    def add(self, start: int | None, stop: int) -> int:
        self.ranges.append((start, stop))
        self.kept.append(None)
        self.closed.append(False)
        return len(self.ranges) - 1

    def next_edge(self, s: int) -> int | None:
        """The first edge of a range after kept sample ``s`` (a block ends there)."""
        return min((x for r in self.ranges for x in r if x is not None and x > s), default=None)

    def inside(self, s: int, e: int) -> int | None:
        """The range (not from the first row) that rows of kept samples [s, e) lie in."""
        for index, (a, b) in enumerate(self.ranges):
            if a is not None and a <= s and e <= b and index not in self.dropped:
                return index
        return None

    def merge(self, index: int, block: Triangles) -> None:
        was = self.kept[index]
        self.kept[index] = block if was is None else was.merge(block)

    def close(self, index: int, tri: Triangles | None) -> None:
        """Range ``index`` ends, the fit's triangles being ``tri`` (once)."""
        if index in self.dropped:
            self.kept[index] = None
        elif not self.closed[index] and self.ranges[index][0] is None:
            self.kept[index] = tri
        self.closed[index] = True


class ReferenceTee:
    """The grid's sink of a pass that also forms the recipe check's reference triangles
    (:mod:`ropod_sysid.crosscheck`) from the same samples, so that the check needs no second
    reading of the log. In each window of the ``budget`` in the piece the reference recipe's
    blocks (made once the sample time is known: its span and delay bracket depend on it) take
    the window's samples as a log of their own, and the fit's own blocks keep the triangles of
    their rows over the same samples apart (:meth:`ropod_sysid.stream._Blocks.keep_rows`). An
    :class:`InputError` of the reference (a window too short for its span) leaves the window
    out; at the piece's start (the log too short for its span) it drops the reference, and
    the check then reads the log again (or is left out)."""

    def __init__(self, blocks: _Blocks, make: Callable[[float], _Blocks],
                 budget: ReferenceBudget, name: str = "", first: int = 0) -> None:
        self.blocks = blocks
        self.make = make
        self.budget = budget
        self.before = budget.left  # (refund)
        self.windows = budget.of_piece(name, first)
        self.dropped = False
        self.at = 0  # samples pushed
        self.next = 0  # the next window
        self.ref: _Blocks | None = None  # the open window's blocks
        self.open: tuple[int, float, int] = (0, 0.0, 0)  # its start, stop and kept rows' index
        self.closing: list[tuple[_Blocks, int, bool]] = []  # windows ended, rows in reduction
        self.done: list[tuple[StreamResult, int, bool]] = []  # window, kept rows, whole piece
        self.spread = False  # a window opened after the piece's first sample
        self.span: Span | None = None
        self.delay: float | DelayBracket | None = None
        self.failure: str | None = None  # the first window's left out, why

    def start(self, dt: float, jitter: float = 0.0) -> None:
        self.dt, self.jitter = dt, jitter
        self.blocks.start(dt, jitter)

    def push(self, samples: _Samples) -> None:
        n, i = len(samples), 0
        while i < n and not self.dropped:
            if self.ref is None:
                if self.next >= len(self.windows) or self.windows[self.next][0] >= self.at + n:
                    break
                i = max(i, self.windows[self.next][0] - self.at)
                self._open(self.at + i)
                continue
            start, stop, _ = self.open
            j = int(min(n, stop - self.at))
            try:
                self.ref.push(samples if (i, j) == (0, n) else samples.take(i, j))
            except InputError as exc:
                self.failure = self.failure or str(exc)
                self.blocks.drop_kept(self.open[2])
                self.ref.close()
                self.ref = None
                continue
            self.budget.spend(j - i)
            i = j
            if self.at + i >= stop:
                self._close()
        self.at += n
        self.blocks.push(samples)

    def _open(self, start: int) -> None:
        """The window from the piece's sample ``start``: the reference's blocks, and the fit's
        rows over its samples kept apart; the window before it taken (long since reduced)."""
        self._take()
        stop = self.windows[self.next][1]
        self.next += 1
        try:
            ref = self.make(self.dt)
            ref.start(self.dt, self.jitter)
        except InputError:
            if start == 0:
                self.drop()
            return
        self.span, self.delay = ref.span, (ref.bracket if ref.bracket is not None
                                           else float(ref.delay))
        index = self.blocks.keep_rows(start + ref.trim if start else None,
                                      int(min(stop, 2**62)) - ref.trim)
        self.ref, self.open = ref, (start, stop, index)
        self.spread = self.spread or start > 0

    def _close(self, whole: bool = False) -> None:
        """The open window ends (``whole``: it is all of the piece): its last samples reduced
        here, its triangles taken by :meth:`_take` when the next window opens or the piece
        ends, so that the pass does not wait for its rows' thread (0.4-0.6 s of a 60-minute
        log's fit when it did); too short for the reference recipe's span, none, and the
        fit's rows over it not kept either."""
        ref = self.ref
        assert ref is not None
        _, _, index = self.open
        self.ref = None
        try:
            ref.flush()
        except InputError as exc:
            self._left_out(ref, index, whole, exc)
        else:
            self.closing.append((ref, index, whole))

    def _left_out(self, ref: _Blocks, index: int, whole: bool, exc: InputError) -> None:
        """Window ``ref`` cannot be fitted by the reference recipe (``exc`` says why): the
        fit's rows over it are not kept; a whole piece too short drops the reference."""
        self.failure = self.failure or str(exc)
        ref.close()
        self.blocks.drop_kept(index)
        if whole:
            self.dropped = True

    def _take(self) -> None:
        """The closed windows' triangles (:meth:`_close`), once their rows are reduced."""
        from ropod_sysid.stream import StreamResult

        closing, self.closing = self.closing, []
        for ref, index, whole in closing:
            try:
                tri = ref.finish()[0]
            except InputError as exc:
                self._left_out(ref, index, whole, exc)
            else:
                ref.close()
                self.done.append((StreamResult(ref.source, tri, [], ref.avail, ref.dt, ref.k),
                                  index, whole))

    def finish(self) -> PieceReference | None:
        """After the fit's blocks finished: the piece's reference (:class:`PieceReference`);
        None if dropped."""
        if self.dropped:
            return None
        if self.ref is not None:  # the piece ends in the window
            self._close(whole=self.open[0] == 0)
        self._take()
        if self.dropped:
            return None
        kept, dropped = self.blocks.keep.kept, self.blocks.keep.dropped
        windows = [(res, None if whole else kept[index]) for res, index, whole in self.done
                   if index not in dropped and (whole or kept[index] is not None)]
        if not windows:
            return PieceReference(None, None, [], failure=self.failure)
        return PieceReference(self.span, self.delay, windows, self.spread)

    def refund(self) -> None:
        """Give the budget back what it held before this piece (it will be passed again)."""
        self.budget.left = self.before

    def drop(self) -> None:
        self.close()
        self.dropped = True

    def close(self) -> None:
        if self.ref is not None:
            self.ref.close()
            self.ref = None
        for ref, _, _ in self.closing:
            ref.close()
        self.closing = []
