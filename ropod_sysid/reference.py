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
    from ropod_sysid.stream import _Blocks

__all__ = ["Reference", "ReferenceBudget", "ReferenceTee"]


@dataclass(frozen=True)
class Reference:
    """The recipe check's reference pieces of a log, formed in the fit's own pass
    (:func:`ropod_sysid.stream.piece_triangles_checked`): the reference recipe's span and what
    its b_ID was formed at (a delay, or the search's bracket), as
    :func:`ropod_sysid.crosscheck.reference_options` gave them for the log's sample time."""

    span: Span
    delay: float | DelayBracket
    pieces: list[tuple[str, Triangles, list[str], LogPlot | None]]


@dataclass
class ReferenceBudget:
    """Samples the recipe check's reference may still be formed for, over the logs of one fit
    (``fit``'s automatic check: :data:`ropod_sysid.crosscheck.AUTO_MAX_SAMPLES` in all; None,
    ``--recipe-check``: no limit). Serially every log draws on the same budget; on Dask workers
    each log has a copy, so a log alone is bounded."""

    left: int | None

    def take(self, n: int) -> bool:
        """Draw ``n`` samples; False when fewer are left, and the budget is then spent (the
        fit's samples are over the limit: later logs need no reference either)."""
        if self.left is None:
            return True
        if n > self.left:
            self.left = -1  # spent: later logs too
            return False
        self.left -= n
        return True


class ReferenceTee:
    """The grid's sink of a pass that also forms the recipe check's reference triangles
    (:mod:`ropod_sysid.crosscheck`) from the same samples, so that the check needs no second
    reading of the log. The reference's blocks are made once the sample time is known (its
    span and delay bracket depend on it); an :class:`InputError` of the reference (a log too
    short for its span) or more samples than its ``budget`` holds drops it, and the check then
    reads the log again (or is left out)."""

    def __init__(self, blocks: _Blocks, make: Callable[[float], _Blocks],
                 budget: ReferenceBudget) -> None:
        self.blocks = blocks
        self.make = make
        self.budget = budget
        self.drawn = 0  # samples drawn from the budget
        self.ref: _Blocks | None = None

    def start(self, dt: float, jitter: float = 0.0) -> None:
        self.blocks.start(dt, jitter)
        try:
            self.ref = self.make(dt)
            self.ref.start(dt, jitter)
        except InputError:
            self.drop()

    def push(self, samples: _Samples) -> None:
        self.blocks.push(samples)
        if self.ref is None:
            return
        if not self.budget.take(len(samples)):
            self.drop()
            return
        self.drawn += len(samples)
        try:
            self.ref.push(samples)
        except InputError:
            self.drop()

    def finish(self) -> tuple[Triangles, float | DelayBracket] | None:
        """The reference's triangles and what its b_ID was formed at; None if dropped."""
        if self.ref is None:
            return None
        ref = self.ref
        try:
            tri = ref.finish()[0]
        except InputError:
            self.drop()
            return None
        return tri, (ref.bracket if ref.bracket is not None else float(ref.delay))

    def refund(self) -> None:
        """Give the samples drawn back to the budget (the piece will be passed again)."""
        if self.budget.left is not None and self.budget.left >= 0:
            self.budget.left += self.drawn
        self.drawn = 0

    def drop(self) -> None:
        self.close()
        self.ref = None

    def close(self) -> None:
        if self.ref is not None:
            self.ref.close()
