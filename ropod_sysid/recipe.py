"""The fit recipe's settings: the smoother's span and degree (``--span``, ``--smoother``), the
grid of equation rows (``--row-step``) and the input delay (``--input-delay``, its bracket for
``auto``), each checked as given. :mod:`ropod_sysid.regressor` forms the system with them (and
re-exports :class:`Span`, :class:`RowGrid`, :class:`DelayBracket`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ropod_sysid import signals
from ropod_sysid.errors import InputError
from ropod_sysid.solve import STRETCH_S

DEFAULT_SPAN_S = 0.1
MIN_SPAN_SAMPLES = 5  # the shortest LOESS window of a span given in samples
ROWS_PER_SPAN = 10  # default row grid: about this many equation rows per smoother span
SMOOTHERS = {"loess": 2, "quartic": 4}  # --smoother: the local polynomial's degree
# the quartic smoother over fewer samples passes 5–8× the LOESS's acceleration noise power; on
# 200 Hz runs with 2¹⁴-count encoders and --encoder-counts it broke down below 17 samples
# (m_b −88 % at 13), the LOESS below 13 (−95 % at 9)
QUARTIC_MIN_SAMPLES = 17
DIFFERENCE_REACH = {2: 2, 4: 4}  # samples each side two differences reach (3- / 5-point)


@dataclass
class Span:
    """Smoother span: a number of samples, or seconds (``"0.25s"``), and the smoother's
    degree (``--smoother``): 2, MATLAB's LOESS with three-point differences; 4, a local
    quartic with five-point differences (:func:`smooth`, :func:`difference`)."""

    value: float
    seconds: bool
    degree: int = 2

    @classmethod
    def parse(cls, text: Span | str | float | None) -> Span:
        """``None``: the default 0.1 s; ``"0.25s"``: seconds (finite, > 0); a bare number: a
        count of samples, an odd whole number ≥ :data:`MIN_SPAN_SAMPLES` (LOESS needs a
        centred window). Anything else is a one-line :class:`InputError`."""
        if isinstance(text, Span):
            return text
        if text is None:
            return cls(DEFAULT_SPAN_S, True)
        s = str(text).strip()
        seconds = s.endswith("s")
        try:
            v = float(s[:-1] if seconds else s)
        except ValueError:
            raise InputError(f"--span {text!r}: give an odd number of samples (e.g. 21) or "
                             "seconds (e.g. 0.1s)") from None
        if seconds:
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"--span {text!r}: seconds must be a finite number > 0, "
                                 "e.g. 0.1s")
            return cls(v, True)
        if math.isfinite(v) and v.is_integer() and v >= MIN_SPAN_SAMPLES and v % 2 == 1:
            return cls(v, False)
        if not math.isfinite(v) or v <= 0:
            hint = "e.g. 21 (samples) or 0.1s"
        elif v < MIN_SPAN_SAMPLES:
            hint = f"did you mean {s}s?"
        else:
            odd = 2 * math.floor((v - 1) / 2) + 1
            hint = f"did you mean {odd} or {odd + 2}?"
        raise InputError(f"--span {text!r}: a number without 's' is a count of samples and "
                         f"must be an odd whole number ≥ {MIN_SPAN_SAMPLES}; {hint}")

    def with_smoother(self, name: str) -> Span:
        """This span with the ``--smoother`` ``name`` (``loess`` or ``quartic``)."""
        if name not in SMOOTHERS:
            raise InputError(f"--smoother {name!r}: use {' or '.join(SMOOTHERS)}")
        return Span(self.value, self.seconds, SMOOTHERS[name])

    @property
    def smoother(self) -> str:
        """The ``--smoother`` name of the degree."""
        return next(name for name, d in SMOOTHERS.items() if d == self.degree)

    @property
    def reach(self) -> int:
        """Samples each side of a sample that its acceleration's two differences reach."""
        return DIFFERENCE_REACH[self.degree]

    def samples(self, dt: float, n: int) -> int:
        """Odd window length k in samples for sample time ``dt`` and ``n`` samples."""
        k = self.value / dt if self.seconds else self.value
        k = max(int(round(k)), 3)
        return k if k % 2 else k + 1

    def quartic_would_fit(self, dt: float) -> bool:
        """A LOESS span that holds the quartic smoother's :data:`QUARTIC_MIN_SAMPLES` at sample
        time ``dt``: where the fit's notes, its verdict and ``inspect`` name the quartic (with
        the correction, it keeps the LOESS's discretisation bias out of long logs)."""
        return self.degree == 2 and dt > 0 and self.samples(dt, 0) >= QUARTIC_MIN_SAMPLES

    def __str__(self) -> str:
        return f"{self.value:g}s" if self.seconds else f"{int(self.value)} samples"


def smoother_note(source: str, k: int, degree: int, dt: float) -> str | None:
    """The note on the quartic smoother over fewer than :data:`QUARTIC_MIN_SAMPLES` samples
    (None otherwise)."""
    if degree == 2 or k >= QUARTIC_MIN_SAMPLES:
        return None
    return (f"{source}: the quartic smoother over {k} samples passes 5–8× the acceleration "
            "noise of the LOESS; on logs with noisy angles (encoder counts) use --span "
            f"{QUARTIC_MIN_SAMPLES * dt:.3g}s or longer ({QUARTIC_MIN_SAMPLES} samples)")


def check_input_delay(delay: float, span_seconds: float | None = None) -> None:
    """An input delay [s] is finite and at most one smoother span ``span_seconds`` either way
    (a longer lag is no transport delay; it pairs torques with unrelated motion). Positive: the
    motion lags the logged torque (the torques are shifted later); negative: the motion leads
    it (the drive logs its torque late)."""
    if not math.isfinite(delay):
        raise InputError(f"--input-delay {delay:g}: must be a finite number of seconds, e.g. "
                         "0.0025 (negative: the motion leads the logged torque), or auto")
    if span_seconds is not None and abs(delay) > span_seconds:
        either = " either way" if delay < 0 else ""
        raise InputError(f"--input-delay {delay:g}: longer than the smoother span "
                         f"({span_seconds:.3g} s); give at most {span_seconds:.3g} s{either}, "
                         "auto, or a longer --span")


MAX_DELAY_NODES = 9  # node delays of --input-delay auto's single pass (at most)


@dataclass(frozen=True)
class DelayBracket:
    """``--input-delay auto``: the delays in [−top, top] [s] are searched from one pass that
    forms b_ID for a few node delays. b_ID = B_τ τ (eq. 35) is linear in the torques, and so are
    the rows' torque average and LOESS, so the b_ID of a delay between two nodes one sample
    apart is exactly their linear interpolation (that of :func:`delayed`);
    :meth:`ropod_sysid.solve.Triangles.at_delay` forms the triangles of any delay from the
    node columns. Nodes are every sample while at most :data:`MAX_DELAY_NODES` cover the
    bracket, else every few samples, interpolated by cubics (approximate)."""

    top: float

    def _step(self, dt: float) -> tuple[int, int]:
        n = max(1, math.ceil(self.top / dt - 1e-9))
        h = max(1, math.ceil(2 * n / (MAX_DELAY_NODES - 1)))
        return h, math.ceil(n / h)

    def nodes(self, dt: float) -> np.ndarray:
        """The node delays [s] for sample time ``dt``: whole samples, covering ±``top``."""
        h, j = self._step(dt)
        return dt * h * np.arange(-j, j + 1)

    def order(self, dt: float) -> int:
        """Interpolation order between the nodes (:func:`ropod_sysid.solve.node_weights`):
        1 (exact) for nodes a sample apart, else 3."""
        return 1 if self._step(dt)[0] == 1 else 3


def delay_reach(delay: float | np.ndarray, dt: float) -> tuple[int, int]:
    """Samples before and after a torque sample that its delayed value reaches (positive and
    negative delays, with two samples to spare)."""
    d = np.atleast_1d(np.asarray(delay, float))
    back = math.ceil(max(float(d.max()), 0.0) / dt) + 2 if d.max() > 0 else 0
    ahead = math.ceil(max(-float(d.min()), 0.0) / dt) + 2 if d.min() < 0 else 0
    return back, ahead


@dataclass(frozen=True)
class RowGrid:
    """Which samples become equation rows, and the LOESS window of the rows.

    ``step``: samples between rows; ``span``: the rows' LOESS window in rows, odd, covering
    the smoother span of ``k`` samples (``k`` itself when ``step`` is 1); ``degree``: of the
    angles' smoother (:class:`Span`), which chooses the rows' torque average
    (:attr:`torque_kernel`).
    """

    step: int
    span: int
    degree: int = 2

    @classmethod
    def for_span(cls, k: int, step: int | None = None, degree: int = 2) -> RowGrid:
        """The grid for a smoother span of ``k`` samples: ``step`` samples apart, or by
        default ⌊k / :data:`ROWS_PER_SPAN`⌋ (at least 1); ``degree``: the smoother's."""
        cls.check_step(step)
        if step is not None and step > k:
            raise InputError(f"--row-step {step}: more than the smoother span of {k} samples; "
                             "rows farther apart than a span are not filtered like the samples "
                             f"(eq. 36 on both sides); give at most {k}, auto, or a longer "
                             "--span")
        d = int(step) if step is not None else max(1, k // ROWS_PER_SPAN)
        kr = max(int(round(k / d)), 3)
        return cls(d, kr if kr % 2 else kr + 1, degree)

    @staticmethod
    def check_step(step: int | None) -> None:
        """A row step is None (auto) or a positive whole number of samples."""
        if step is not None and (int(step) != step or step < 1):
            raise InputError(f"--row-step {step!r}: give a positive whole number of samples "
                             "(1 = every sample) or leave it out for about ten rows per span")

    @property
    def torque_reach(self) -> int:
        """Samples each side of a row that its torque average (:attr:`torque_kernel`) takes."""
        if self.degree == 2:
            return self.step // 2
        return self.step if self.step > 1 else 0

    @property
    def torque_kernel(self) -> np.ndarray:
        """Weights of a row's torques over the samples around it (2 :attr:`torque_reach` + 1).

        The LOESS's rows: the mean over 2⌊step/2⌋ + 1 samples. The quartic's rows: the
        least-norm weights over 2·step + 1 samples (least current noise) that sum to 1, whose
        second moment is zero and which null the row rate's harmonics m/(step·dt). A mean's
        second moment, dt² h(h + 1)/3 (h = ⌊step/2⌋), biases b against the states taken at
        the row; the LOESS's q̈ carries the second moment of its two three-point differences,
        2dt²/3, which the mean matches at a row every 2nd sample, but the quartic's five-point
        differences carry none. And torque content at the row rate (a drive's setpoint ripple)
        aliases to a constant in b unless the weights null it: with the mean, noise-free
        200 Hz runs of the off-square ropod gave a largest error of 0.26 % or 0.48 % by the
        rows' phase to the simulator's 100 Hz setpoints; with these weights 0.27 % at any
        phase, at 1 kHz 0.14–0.21 % against 0.33–0.51 % (docs/method.md)."""
        h = self.torque_reach
        if self.degree == 2 or h == 0:
            return np.full(2 * h + 1, 1.0 / (2 * h + 1))
        j = np.arange(-h, h + 1, dtype=float)
        harmonics = [np.cos(2 * np.pi * m * j / self.step) for m in range(1, self.step // 2 + 1)]
        c = np.array([np.ones_like(j), j * j, *harmonics])
        d = np.zeros(len(c))
        d[0] = 1.0
        return c.T @ np.linalg.solve(c @ c.T, d)

    @property
    def halo(self) -> int:
        """Samples a run of rows needs on each side: the rows' half-window of LOESS, and
        the samples of the torques' average (:attr:`torque_reach`)."""
        return self.step * ((self.span - 1) // 2) + self.torque_reach

    @property
    def correlation(self) -> float:
        """Rows per independent row after the rows' LOESS: 1/Σh² of its kernel h (a residual
        white before the filter is correlated over the window after it; the standard
        deviations grow by the square root, :class:`ropod_sysid.solve.Triangles`)."""
        if self.span <= 3:  # the LOESS of three samples returns them unchanged
            return 1.0
        return float(1.0 / np.sum(signals.loess_kernel(self.span) ** 2))

    def stretch_rows(self, dt: float) -> int:
        """Rows per stretch of :data:`ropod_sysid.solve.STRETCH_S` seconds at sample time
        ``dt`` (the unit the jackknife σ leaves out; :class:`ropod_sysid.solve.Triangles`)."""
        return max(1, int(round(STRETCH_S / (dt * self.step))))

    def trim(self, k: int) -> int:
        """Samples dropped at each end of a log: the shifted end windows of the smoother
        over ``k`` samples and of the rows' LOESS (``k`` when ``step`` is 1)."""
        return (k - 1) // 2 + 1 + self.halo
