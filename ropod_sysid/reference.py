"""The recipe check's reference formed in the fit's own pass over a log
(:func:`ropod_sysid.stream.piece_triangles_checked`).

``fit``'s recipe check (:mod:`ropod_sysid.crosscheck`) fits the logs a second way. Reading and
decoding a log is about half of a fit's work, so the second recipe's blocks
(:class:`ropod_sysid.stream._Blocks`, at the reference's span and delay bracket) take the same
grid samples as the fit's own, through :class:`ReferenceTee`, and the reference fit then solves
from their triangles (:class:`Reference`). The automatic check runs on logs of up to
:data:`ropod_sysid.crosscheck.AUTO_MAX_SAMPLES` samples in all, which the logs of one fit draw
on (:class:`ReferenceBudget`); past it, or where the reference recipe does not fit a log (a
piece too short for its span), the reference is dropped and the check reads the logs again
when it still runs.
"""

from __future__ import annotations

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

__all__ = ["PieceReference", "Reference", "ReferenceBudget", "ReferenceTee"]


@dataclass(frozen=True)
class PieceReference:
    """The reference of one piece of a log (a log without gaps is one piece), from its
    :class:`ReferenceTee`: the reference recipe's span, delay and triangles (``result``;
    None with the span and delay when the budget was spent before the piece), and where the
    budget ended inside the piece the fit's own triangles of the rows up to the same sample
    (``main``; None: the piece's own)."""

    span: Span | None
    delay: float | DelayBracket | None
    result: StreamResult | None
    main: Triangles | None = None


@dataclass(frozen=True)
class Reference:
    """The recipe check's reference pieces of a log, formed in the fit's own pass
    (:func:`ropod_sysid.stream.piece_triangles_checked`): the reference recipe's span and what
    its b_ID was formed at (a delay, or the search's bracket), as
    :func:`ropod_sysid.crosscheck.reference_options` gave them for the log's sample time."""

    span: Span | None  # (None: no piece of the log within the budget)
    delay: float | DelayBracket | None
    pieces: list[tuple[str, Triangles, list[str], LogPlot | None]]
    # the fit's own pieces over the reference's samples (the rows up to the cut in a piece the
    # budget ended in; none of the pieces past it)
    main: list[tuple[str, Triangles, list[str], LogPlot | None]]
    partial: bool = False  # the budget ended inside the log, or before it

    @staticmethod
    def of_pieces(pieces: list[tuple[str, Triangles, list[str], LogPlot | None]],
                  refs: list[PieceReference | None]) -> Reference | None:
        """The log's reference from its pieces' (``refs``, beside the fit's ``pieces``); None
        where one was dropped or their spans or delays differ."""
        if any(ref is None for ref in refs):
            return None
        got = [(piece, ref) for piece, ref in zip(pieces, refs, strict=True)
               if ref is not None and ref.result is not None]
        partial = len(got) < len(refs) or any(ref.main is not None for _, ref in got)
        if not got:
            return Reference(None, None, [], [], partial)
        span, delay = got[0][1].span, got[0][1].delay
        if any(ref.span != span or ref.delay != delay for _, ref in got):
            return None
        return Reference(
            span, delay,
            [(r.source, r.triangles, r.notes, r.plot) for _, ref in got
             if (r := ref.result) is not None],
            [(name, tri if ref.main is None else ref.main, [], None)
             for (name, tri, _, _), ref in got], partial)


@dataclass
class ReferenceBudget:
    """Samples the recipe check's reference may still be formed for, over the logs of one fit
    (``fit``'s automatic check: :data:`ropod_sysid.crosscheck.AUTO_MAX_SAMPLES` in all; None,
    ``--recipe-check``: no limit). Serially every log draws on the same budget; on Dask workers
    each log has a copy, so a log alone is bounded."""

    left: int | None

    def take(self, n: int) -> int:
        """Draw ``n`` samples: how many were left of them (all but where the budget ends)."""
        if self.left is None:
            return n
        got = min(n, self.left)
        self.left -= got
        return got

    @property
    def spent(self) -> bool:
        return self.left is not None and self.left <= 0


class ReferenceTee:
    """The grid's sink of a pass that also forms the recipe check's reference triangles
    (:mod:`ropod_sysid.crosscheck`) from the same samples, so that the check needs no second
    reading of the log. The reference's blocks are made once the sample time is known (its
    span and delay bracket depend on it). Where the ``budget`` ends the reference is cut: its
    triangles are finished there and the fit's rows up to the same sample kept apart
    (:meth:`ropod_sysid.stream._Blocks.mark_rows`); a budget spent before the piece starts
    forms none (:attr:`past`). An :class:`InputError` of the reference (a log too short for
    its span) drops it, and the check then reads the log again (or is left out)."""

    def __init__(self, blocks: _Blocks, make: Callable[[float], _Blocks],
                 budget: ReferenceBudget) -> None:
        self.blocks = blocks
        self.make = make
        self.budget = budget
        self.before = budget.left  # (refund)
        self.ref: _Blocks | None = None
        self.past = False  # the budget was spent before this piece
        self.cut: tuple[Triangles, float | DelayBracket] | None = None

    def start(self, dt: float, jitter: float = 0.0) -> None:
        self.blocks.start(dt, jitter)
        if self.budget.spent:
            self.past = True
            return
        try:
            self.ref = self.make(dt)
            self.ref.start(dt, jitter)
        except InputError:
            self.drop()

    def push(self, samples: _Samples) -> None:
        if self.ref is not None and self.cut is None:  # (first: the fit's rows not yet past
            n = self.budget.take(len(samples))         # the cut)
            try:
                self.ref.push(samples if n == len(samples) else samples.take(0, n))
            except InputError:
                self.drop()
            else:
                if self.budget.spent:
                    self._cut()
        self.blocks.push(samples)

    def _cut(self) -> None:
        """The budget ends here: the reference's triangles of the samples it has, and the
        fit's rows up to its last kept sample kept apart; too few samples for the reference
        recipe's span, and the piece has none (:attr:`past`)."""
        ref = self.ref
        assert ref is not None
        try:
            self.cut = _finished(ref)
        except InputError:
            self.past = True
            self.drop()
            return
        self.blocks.mark_rows(ref.avail - ref.trim)
        ref.close()
        ref.parts = []  # (its samples: not needed any more)

    def finish(self) -> tuple[Triangles, float | DelayBracket] | None:
        """The reference's triangles and what its b_ID was formed at; None if dropped."""
        if self.cut is not None:
            return self.cut
        if self.ref is None:
            return None
        try:
            return _finished(self.ref)
        except InputError:
            self.drop()
            return None

    def refund(self) -> None:
        """Give the budget back what it held before this piece (it will be passed again)."""
        self.budget.left = self.before

    def drop(self) -> None:
        self.close()
        self.ref = None

    def close(self) -> None:
        if self.ref is not None:
            self.ref.close()


def _finished(ref: _Blocks) -> tuple[Triangles, float | DelayBracket]:
    """The reference's triangles of the samples it has, and what its b_ID was formed at."""
    return ref.finish()[0], (ref.bracket if ref.bracket is not None else float(ref.delay))
