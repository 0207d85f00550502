"""The recipe check: fold the recipe's own bias into σ by fitting the logs a second way
(``fit``'s default, on longer logs than :data:`AUTO_MAX_SAMPLES` samples measured on part of
them; ``--recipe-check``, ``--no-recipe-check``).

σ (:func:`ropod_sysid.solve.jackknife_covariance`) is the spread of the values over the logs'
stretches: it sees errors that vary from stretch to stretch and none that every stretch shares.
On the least-squares solution the stretches' scores sum to zero, so a bias common to them —
the smoother's and the differences' attenuation of fast transients, the drives' hold — cannot
show in any statistic of one fit's residuals, and once a log is long σ falls below it
(``benchmarks/varied.py``: exact 200 Hz runs of 60 s keep 34–100 % of their values within 2σ,
ten of them jointly 55 %).

The bias can be seen by changing the recipe. The reference fit differentiates the other way —
the LOESS's three-point differences against the local quartic's five-point ones
(:class:`ropod_sysid.recipe.Span`) — with the drives' lag searched (``--input-delay auto``)
unless the hold is given (``--control-period``) or the delay is; everything else (friction
model, fixed values, the encoders' correction, weights, bounds, ``--robust``) is the fit's own.
The quartic's span holds at least :data:`ropod_sysid.recipe.QUARTIC_MIN_SAMPLES` samples of
the slowest log. The two recipes' biases differ, so their difference Δ bounds the larger; each
parameter's σ becomes √(σ² + Δ²) (:func:`fold_shift`). On noisy logs Δ also holds the two
recipes' different noise, so σ grows a little where there is no bias (median 1.06–1.17× on
the benchmark's noisy single runs). What no recipe sees stays out: a bias both share, such as
point-sampled currents' aliasing (100 Hz logs of the speed loops' ripple).

:func:`ropod_sysid.fit.fit_files` forms the reference recipe's triangles in the fit's own pass
over the logs (:mod:`ropod_sysid.reference`), so the check costs the second recipe's
smoothing, rows and solves but no second reading; ``trajectory check`` predicts its shift for
a planned run (:mod:`ropod_sysid.trajectory.recipe_shift`).

Longer logs. The bias is a property of the recipe on the run, which more data do not shrink,
so the automatic check does not need all of a long log, only a fair sample of it: over its
budget (:func:`reference_budget`) the reference is formed in the fit's pass on windows spread
over the logs (:func:`reference_windows`), each a log of its own, the fit's own rows over
them kept apart (:meth:`ropod_sysid.stream._Blocks.keep_rows`), and Δ is the difference of
the two recipes' fits of those windows, folded into the whole fit's σ (:func:`checked`, with
a note; in memory the same, :func:`window_samples`). Where a log's length is not known
before it is read (MCAP) the window is its first samples, cut where the budget ends.
Measured on twenty joined copies of a noisy 60 s 1 kHz run (1.2 million samples): the
jackknife's σ alone keep 79 % of the values within 2σ, the shift over all samples 97 %, over
the first 200,000 97 % and over the first 1,000,000 (streamed from a CSV file too short for
its length to be known beforehand) 100 %. On a log whose first minutes differ from the rest
the first samples are no fair sample (below, :data:`PREFIX_SAMPLES`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, TypeAlias

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.recipe import QUARTIC_MIN_SAMPLES, Span

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from ropod_sysid.fit import FitOptions, FitResult
    from ropod_sysid.io.log import Log
    from ropod_sysid.solve import Solution

    # the recipe check's fits of part of the logs under the reference's options: the fit's
    # recipe, the reference's, and whether the part is windows spread over the logs (else
    # their first samples); None where they were not formed
    Part: TypeAlias = Callable[[FitOptions], tuple[FitResult, FitResult, bool] | None]

# With ``recipe_check="auto"`` (``fit``'s default) the check runs on logs of at most this many
# samples in all: the shipped sample (24,000), up to 16 minutes at 1 kHz. Its reference is
# formed in the fit's own pass over the logs (:func:`ropod_sysid.stream.piece_triangles_checked`),
# which it lengthens by 0.3-0.8 s up to here (a 10-minute 1 kHz CSV log 1.1-1.3 -> 2.0-2.1 s).
# Longer logs are checked on part of them (below); ``--recipe-check``: on all of them.
AUTO_MAX_SAMPLES = 1_000_000
# On longer logs the automatic check measures the shift on part of the logs: where their
# length is known beforehand (CSV logs surely longer, :func:`ropod_sysid.chunks.fewest_samples`,
# placed by :func:`ropod_sysid.chunks.estimated_samples`; in-memory logs) this many samples in
# REFERENCE_WINDOWS windows spread over them (:func:`reference_windows`), else (MCAP, whose
# length is found while reading) the first AUTO_MAX_SAMPLES. The shift is a property of the
# recipe on the run, not of the amount of data: on twenty joined copies of a noisy 60 s 1 kHz
# run (1.2 million samples) the shift over its first 100,000 to 1,000,000 samples was
# 0.99-1.04 times (median over the values) that over all of it, with the same share of the
# values within 2σ (97 %). But a log's first minutes need not be like the rest: 20 minutes at
# 1 kHz whose first 4 drive gently kept 72 % of the values within 2σ with the shift of the
# first 200,000 samples, 100 % with it over four windows (97 % over all samples).
PREFIX_SAMPLES = 200_000
REFERENCE_WINDOWS = 4


def reference_budget(mode: bool | str, fewest: int) -> int | None:
    """The samples the recipe check's reference may be formed on
    (:class:`ropod_sysid.reference.ReferenceBudget`) for ``recipe_check`` ``mode`` and logs of
    at least ``fewest`` samples (:func:`ropod_sysid.chunks.fewest_samples`; 0: not known):
    None (all) for ``True``, else :data:`AUTO_MAX_SAMPLES`, or :data:`PREFIX_SAMPLES` (not
    more) for logs surely longer than that."""
    if mode is True:
        return None
    if fewest > AUTO_MAX_SAMPLES:
        return min(PREFIX_SAMPLES, AUTO_MAX_SAMPLES)
    return AUTO_MAX_SAMPLES


def log_step(result: FitResult) -> float:
    """The longest sample time [s] among the fit's logs
    (:attr:`ropod_sysid.fit.LogFit.sample_time`)."""
    return max((lf.sample_time for lf in result.logs), default=0.0)


def reference_span(span: Span, dt: float) -> Span:
    """The other smoother at ``span``; the quartic's widened to hold
    :data:`QUARTIC_MIN_SAMPLES` samples at sample time ``dt`` [s]."""
    if span.degree == 4:
        return span.with_smoother("loess")
    if not span.seconds:
        return Span(max(span.value, QUARTIC_MIN_SAMPLES), False).with_smoother("quartic")
    # the span's samples are rounded (Span.samples): 16.5 of them make 17; to 10 ms up, which
    # also covers dt estimated a little long (log_step)
    need = math.ceil((QUARTIC_MIN_SAMPLES - 0.5) * dt * 100.0 - 1e-9) / 100.0
    return Span(max(span.value, need), True).with_smoother("quartic")


def reference_options(options: FitOptions, dt: float) -> FitOptions:
    """The reference fit's options (see the module docstring): the other smoother, the lag
    searched unless the hold or a delay is given, no second check."""
    search = options.input_delay == "auto" or (options.input_delay == 0.0
                                               and not options.control_period)
    return dataclasses.replace(options, span=reference_span(options.span, dt),
                               input_delay="auto" if search else options.input_delay,
                               recipe_check=False)


def describe(options: FitOptions) -> str:
    """The reference recipe as ``fit`` flags."""
    delay = ("--input-delay auto" if options.input_delay == "auto" else
             f"--control-period {options.control_period:g}" if options.control_period else
             f"--input-delay {options.input_delay:g}")
    span = options.span
    width = f"{span.value:g}s" if span.seconds else f"{int(span.value)}"
    return f"--smoother {span.smoother} --span {width} {delay}"


def folded(sol: Solution, shift: np.ndarray, reference: str) -> Solution:
    """``sol`` with σ → √(σ² + Δ²) for the recipe shift Δ (p,) (NaN σ, fixed or at a bound,
    stay NaN), and its basis saying so."""
    std = np.sqrt(sol.std**2 + np.nan_to_num(shift) ** 2)
    return dataclasses.replace(
        sol, std=std,
        std_basis=f"{sol.std_basis}; and in quadrature the shift of each value to a fit with "
                  f"{reference} (the recipe check: the recipe's bias, which the jackknife does "
                  "not see)")


def fold_shift(result: FitResult, reference: FitResult,
               base: FitResult | None = None, spread: bool = False) -> FitResult:
    """``result`` with the recipe shift Δ = values − reference values folded into σ (the
    shown solution's: the bounded one with ``--physical``), and recorded
    (:attr:`FitResult.recipe_shift`). Values the two fits determine differently (one a
    combination, the other not) get no shift: they are not the same quantity. ``base``: the
    fit of the samples the reference was fitted to, when those are only part of the logs
    (:func:`checked`; ``spread``: see :func:`part_text`): Δ = its values − the reference's,
    for the values ``result`` determines as ``base`` does."""
    mine, theirs = (base or result).shown, reference.shown
    same = (mine.combination == theirs.combination) & (result.shown.combination
                                                       == mine.combination)
    shift = np.where(same, mine.values - theirs.values, 0.0)
    shift[[mine.names.index(k) for k in mine.fixed]] = 0.0
    text = describe(reference.options)
    if base is not None:
        text += f" on {part_text(base, spread)}"
    out = dataclasses.replace(result, recipe_shift=dict(zip(mine.names, map(float, shift),
                                                            strict=True)),
                              recipe_reference=text)
    if result.physical is not None:
        out.physical = folded(result.physical, shift, text)
    else:
        out.solution = folded(result.solution, shift, text)
    return out


# what a value whose σ is mostly its recipe shift is flagged with (report, printed table)
RECIPE_LIMITED = ("recipe-limited: its shift to the second recipe exceeds the jackknife's σ, so "
                  "its σ is mostly the recipe's bias, which more logs of the same kind do not "
                  "shrink (a higher log rate, slower transients or the drives' --control-period "
                  "may)")


def recipe_limited(std: float, shift: float) -> bool:
    """Whether σ ``std`` (with the shift folded in, √(σ_j² + Δ²)) is mostly the recipe shift
    ``shift`` Δ: |Δ| above the jackknife's own σ_j = √(σ² − Δ²)."""
    return bool(math.isfinite(std) and math.isfinite(shift)
                and 2.0 * shift * shift > std * std)


def wanted(result: FitResult) -> bool:
    """Whether ``result``'s options ask for the check on its logs (``"auto"``: at most
    :data:`AUTO_MAX_SAMPLES` samples)."""
    mode = result.options.recipe_check
    return mode is True or (mode == "auto" and result.samples <= AUTO_MAX_SAMPLES)


def skipped_note(samples: int) -> str:
    """The note of a fit whose logs were too long for the automatic check, and whose first
    samples could not be checked either (:func:`checked`)."""
    return (f"recipe check left out: the logs have {samples:,} samples, more than the "
            f"{AUTO_MAX_SAMPLES:,} up to which fit runs it by default; σ is the jackknife's "
            "alone and does not include the recipe's bias (docs/accuracy.md); add "
            "--recipe-check to include it (1.4-1.8 times the fit's time)")


def part_text(base: FitResult, spread: bool) -> str:
    """Which of the logs' samples the recipe shift was measured on: ``base`` is the fit's
    recipe on them, a log per window (``spread``, :func:`reference_windows`), or on the first
    samples of logs whose length was not known beforehand."""
    if spread:
        return (f"{base.samples:,} samples in {len(base.logs)} windows spread over the "
                "logs")
    return f"the logs' first {base.samples:,} samples"


def part_note(base: FitResult, samples: int, spread: bool) -> str:
    """The note of a fit whose recipe shift was measured on part of its logs' ``samples``
    (:func:`part_text`)."""
    where = (f"{base.samples:,} of the logs' {samples:,} samples, in {len(base.logs)} windows "
             "spread over them" if spread else
             f"the logs' first {base.samples:,} of {samples:,} samples")
    return (f"recipe check on {where} (fit checks all of them by default up to "
            f"{AUTO_MAX_SAMPLES:,}): σ includes the shift between the two recipes measured "
            "there, the recipe's bias, which more data do not shrink; add --recipe-check to "
            "measure it on all of them (1.4-1.8 times the fit's time)")


def reference_windows(lengths: Sequence[int], budget: int,
                      count: int = REFERENCE_WINDOWS) -> list[list[tuple[int, int]]]:
    """Where the recipe check's reference goes in logs of ``lengths`` samples (in the fit's
    order) over its ``budget``: ``count`` windows of ``budget // count`` samples, centred at
    about (i + ½)/``count`` of their samples in all, as (start, stop) samples of each log; a
    window across two logs is split, and a part under a quarter of a window left out. All of
    each log when they fit the budget. Windows start on a multiple of 2,520 samples (60 for
    windows shorter than that), which every row step up to 10 divides: the rows of a window
    fitted as a log of its own are the whole log's (at 200 Hz, rows every 2nd sample at the
    odd ones moved m_b by 3.7 % on simulated runs: docs/accuracy.md, "Stops and restarts")."""
    total = sum(lengths)
    if total <= budget:
        return [[(0, n)] for n in lengths]
    each = budget // count
    align = window_align(budget, count)
    starts = np.cumsum([0, *lengths])
    out: list[list[tuple[int, int]]] = [[] for _ in lengths]
    stop = 0
    for i in range(count):
        a = max(round((i + 0.5) * total / count - each / 2), 0) // align * align
        a = max(a, -(-stop // align) * align)
        if a + each > total:  # (pushed past the end by the one before)
            a = (total - each) // align * align
            if a < stop:
                break
        stop = a + each
        for j, n in enumerate(lengths):
            lo, hi = max(a, int(starts[j])), min(stop, int(starts[j]) + n)
            if hi - lo >= max(each // 4, 1):
                out[j].append((lo - int(starts[j]), hi - int(starts[j])))
    return out


def window_align(budget: int, count: int = REFERENCE_WINDOWS) -> int:
    """The samples that :func:`reference_windows`' windows start on a multiple of."""
    return 2520 if budget // count >= 2520 else 60


def window_samples(logs: Sequence[Log], budget: int | None) -> list[Log]:
    """The in-memory logs' samples the reference is formed on (:func:`reference_windows`;
    None: all), each window a log of its own, as the fit's pass over log files forms them
    (:class:`ropod_sysid.reference.ReferenceBudget`)."""
    if budget is None:
        return list(logs)
    plan = reference_windows([log.n_samples for log in logs], budget)
    return [log if (a, b) == (0, log.n_samples) else log.slice(a, b)
            for log, windows in zip(logs, plan, strict=True) for a, b in windows]


def checked(result: FitResult, refit: Callable[[FitOptions], FitResult],
            say: Callable[[str], None],
            prefix: Part | None = None) -> FitResult:
    """The fit ``result`` with the recipe check (:attr:`ropod_sysid.fit.FitOptions.recipe_check`)
    when :func:`wanted`: the reference fit by ``refit`` (``fit_logs`` or ``fit_files`` of the
    same logs) under :func:`reference_options`, folded in (:func:`fold_shift`). With
    ``"auto"`` on longer logs, ``prefix(reference options)`` gives the fit's recipe and the
    reference's on part of the logs (:func:`reference_budget`: windows spread over them, or
    their first samples; :data:`Part`), whose shift is folded into ``result``'s σ, with a
    note; where it gives None, ``result`` itself with a note that
    the check was left out. With ``"auto"``, a reference recipe that cannot be fitted (an
    :class:`InputError`, e.g. logs too short for its span) leaves σ as it is, with a note
    saying why."""
    mode = result.options.recipe_check
    if not wanted(result):
        if mode == "auto" and result.logs:
            return _checked_first(result, prefix, say)
        return result
    say("reference fit (recipe check)")
    options = reference_options(result.options, log_step(result))
    try:
        reference = refit(options)
    except InputError as exc:
        if mode is True:
            raise
        result.logs[0].notes.append(f"recipe check left out: its reference fit "
                                    f"({describe(options)}) failed: {exc}")
        return result
    return fold_shift(result, reference)


def _checked_first(result: FitResult, prefix: Part | None,
                   say: Callable[[str], None]) -> FitResult:
    """:func:`checked` of logs over :data:`AUTO_MAX_SAMPLES`: the shift measured on part of
    them."""
    options = reference_options(result.options, log_step(result))
    got = None
    if prefix is not None:
        say("reference fit (recipe check, on part of the logs)")
        try:
            got = prefix(options)
        except InputError as exc:
            result.logs[0].notes.append(f"recipe check left out: its fits of part of the "
                                        f"logs ({describe(options)}) failed: {exc}")
            return result
    if got is None:
        result.logs[0].notes.append(skipped_note(result.samples))
        return result
    base, reference, spread = got
    out = fold_shift(result, reference, base, spread)
    out.logs[0].notes.append(part_note(base, result.samples, spread))
    return out
