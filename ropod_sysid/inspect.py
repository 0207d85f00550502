"""Look at a log before fitting: timing, gaps, dropped frames, channel ranges, and whether the
log is long and varied enough to identify the parameters.

The verdict is a rule of thumb (thresholds in :class:`Criteria`): the fit needs motion — at least
10 s of it — in every base degree of freedom (forward, sideways, turning; from wheel odometry, as
the range between the 1st and 99th percentile of each base-frame velocity), and every pivot
must turn through a good part of the circle (pivot friction and the hub inertia are seen only
when the units swivel). On platforms whose wheels constrain the base (steered wheels) the fit
leaves out the base rows near singular configurations and where the wheels slip: the verdict
asks that it keeps them for at least half of the moving time, and it does not ask for sideways
motion where sideways translation is itself a singular configuration (two steered wheels whose
axles then lie on one line).

It also says how to fit the log (:func:`fit_suggestion`): where the angles move by whole counts
of an encoder, ``--encoder-counts`` with them, and where the default 0.1 s span holds the
quartic smoother's 17 samples or more, ``--smoother quartic --input-delay auto`` besides (on
ten minutes of 1 kHz logs the default LOESS's bias left 41–83 % of the values within 2σ, these
options 90–100 %: docs/accuracy.md, "Long logs").
"""

from __future__ import annotations

import re
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import GAP_RULE, check_times
from ropod_sysid.model import PlatformModel
from ropod_sysid.odometry import base_twist, unwrap_angles
from ropod_sysid.platform import Platform
from ropod_sysid.quantisation import log_encoder_counts
from ropod_sysid.regressor import Span

_DROPPED = re.compile(r"dropped (\d+) of \d+ smart-wheel frames")


@dataclass(frozen=True)
class Criteria:
    """Thresholds of the 'enough to fit' verdict.

    min_moving : seconds of motion [s]; moving means base speed above ``moving_speed`` [m/s] or
    turn rate above ``moving_turn`` [rad/s]; min_vx, min_vy [m/s], min_omega [rad/s] : range of
    each base velocity; min_pivot_coverage : degrees of the circle each pivot visits;
    gap_factor : a sample interval longer than this many median intervals is a gap;
    min_base_rows : share of the moving time whose base rows the fit must keep (constrained
    platforms).
    """

    min_moving: float = 10.0
    moving_speed: float = 0.02
    moving_turn: float = 0.05
    min_vx: float = 0.2
    min_vy: float = 0.2
    min_omega: float = 0.3
    min_pivot_coverage: float = 90.0
    gap_factor: float = 2.0
    min_base_rows: float = 0.5


@dataclass
class Gap:
    """A sample interval longer than ``gap_factor`` median intervals."""

    index: int       # sample before the gap
    t: float         # its time [s]
    dt: float        # length of the interval [s]


@dataclass
class Inspection:
    """What :func:`inspect_log` found. Times in s, rates in Hz, ranges as (min, max)."""

    source: str
    units: list[str]
    samples: int
    duration: float
    rate: float                 # mean sample rate [Hz]
    dt_median: float            # median sample interval [s]
    jitter: float               # standard deviation of the sample interval [s]
    gap_count: int
    gaps: list[Gap]             # the first 20
    dropped_frames: int
    notes: list[str]
    ranges: dict[str, tuple[float, float]]
    velocity_ranges: dict[str, tuple[float, float]]   # vx, vy, omega: 1st and 99th percentile
    moving_time: float
    pivot_coverage: dict[str, float]                  # unit → degrees of the circle visited
    enough_to_fit: bool
    reasons: list[str] = field(default_factory=list)  # why not, when not
    base_rows_used: float | None = None  # share of the moving time with base rows in the fit
    sideways_singular: bool = False  # sideways translation is a singular configuration
    warnings: list[str] = field(default_factory=list)
    column_units: dict[str, str] = field(default_factory=dict)  # column → SI unit
    encoder_counts: int | None = None  # counts per revolution the angles move by, if whole
    fit_options: list[str] = field(default_factory=list)  # what to give fit (fit_suggestion)
    fit_advice: str = ""  # why

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data."""
        d = asdict(self)
        d["ranges"] = {k: list(v) for k, v in self.ranges.items()}
        d["velocity_ranges"] = {k: list(v) for k, v in self.velocity_ranges.items()}
        return d


def inspect_log(log: Log, platform: Platform, criteria: Criteria | None = None) -> Inspection:
    """Timing, gaps, ranges and the fit verdict of ``log`` (units as in ``platform``)."""
    c = criteria or Criteria()
    t = np.asarray(log.t, dtype=float)
    n = t.size
    dt = np.diff(t)
    dt_med = float(np.median(dt)) if dt.size else 0.0
    jitter = float(np.std(dt)) if dt.size else 0.0
    duration = float(t[-1] - t[0]) if n else 0.0
    rate = (n - 1) / duration if duration > 0 else 0.0
    gap_idx = np.flatnonzero(dt > c.gap_factor * dt_med) if dt.size else np.zeros(0, int)
    gaps = [Gap(int(k), float(t[k]), float(dt[k])) for k in gap_idx[:20]]
    dropped = sum(int(m.group(1)) for note in log.notes for m in _DROPPED.finditer(note))
    ranges = {k: (float(np.nanmin(v)) + 0.0, float(np.nanmax(v)) + 0.0)  # (no "-0")
              for k, v in log.columns().items()}

    model = PlatformModel(platform)
    vel, moving, widths, used = _base_velocity(log, model, t, dt_med, c)
    moving_time = float(np.sum(widths[moving]))
    sideways = _sideways_singular(model)
    base_used = (None if used is None or moving_time == 0
                 else float(np.sum(widths[moving & used]) / moving_time))
    names = ("vx", "vy", "omega")
    vel_ranges = {k: ((float(np.percentile(vel[:, j], 1)), float(np.percentile(vel[:, j], 99)))
                      if vel.shape[0] else (0.0, 0.0)) for j, k in enumerate(names)}
    coverage = {}  # per unit with a turning joint (a wrapped angle: a swivel's pivot, a steering)
    joint = {}  # its column
    lay = log.layout
    for j in np.flatnonzero(lay.wrapped):
        wrapped = np.mod(log.angles[:, j], 2 * np.pi)
        bins = np.unique(np.floor(wrapped / (2 * np.pi) * 36).astype(int))
        coverage[lay.units[lay.angle_unit[j]]] = 10.0 * float(bins.size)
        joint[lay.units[lay.angle_unit[j]]] = lay.angle_names[j]

    reasons = []
    short = motion_shortfall(moving_time, "of motion", c)
    if short is not None:
        reasons.append(short)
    spans = [("vx", c.min_vx, "m/s"), ("vy", c.min_vy, "m/s"), ("omega", c.min_omega, "rad/s")]
    if sideways:
        del spans[1]
    for key, need, unit in spans:
        lo, hi = vel_ranges[key]
        if hi - lo < need:
            reasons.append(f"{key} spans only {hi - lo:.3g} {unit} (1st–99th percentile); "
                           f"drive it through at least {need:g} {unit}")
    if base_used is not None and base_used < c.min_base_rows:
        reasons.append(f"the fit keeps the base rows for only {100 * base_used:.0f} % of the "
                       "moving time (near singular configurations or slipping wheels); drive "
                       "so that the wheels' axles cross away from the line through them")
    low = [u for u, deg in coverage.items() if deg < c.min_pivot_coverage]
    if low:
        reasons.append(f"{', '.join(joint[u] for u in low)} turn{'' if len(low) > 1 else 's'} "
                       "through less "
                       f"than {c.min_pivot_coverage:g}° (min "
                       f"{min(coverage[u] for u in low):.0f}°); change the driving direction more")
    notes_w = []
    if gap_idx.size:
        worst = int(gap_idx[np.argmax(dt[gap_idx])])
        notes_w.append(f"{gap_idx.size} gap{'s' if gap_idx.size > 1 else ''} longer than "
                       f"{c.gap_factor:g}× the median interval, the longest "
                       f"{float(dt[worst]):.4g} s at t={float(t[worst]):.3f} s")
    refused = check_times(t, log.source, gaps="allow").gaps if n else []
    if refused:
        notes_w.append(f"{len(refused)} of them the fit refuses ({GAP_RULE}): give fit, validate "
                       f"and report --split-gaps to fit the {len(refused) + 1} pieces as "
                       "separate logs")
    if dt_med > 0 and jitter > 0.1 * dt_med:
        notes_w.append(f"sample interval jitter {jitter:.3g} s is over 10% of the median "
                       f"{dt_med:.3g} s")
    if dropped:
        notes_w.append(f"{dropped} corrupt frame{'s' if dropped > 1 else ''} dropped on reading")
    counts = log_encoder_counts(log) if n else None
    options, advice = fit_suggestion(counts, Span.parse(None), dt_med, model.constrained)
    return Inspection(
        source=log.source, units=list(log.units), samples=n, duration=duration, rate=rate,
        dt_median=dt_med, jitter=jitter, gap_count=int(gap_idx.size), gaps=gaps,
        dropped_frames=dropped, notes=list(log.notes), ranges=ranges,
        velocity_ranges=vel_ranges, moving_time=moving_time, pivot_coverage=coverage,
        enough_to_fit=not reasons, reasons=reasons, warnings=notes_w,
        column_units=_column_units(log), base_rows_used=base_used, sideways_singular=sideways,
        encoder_counts=counts, fit_options=options, fit_advice=advice,
    )


def fit_suggestion(counts: int | None, span: Span, dt: float, constrained: bool = False
                   ) -> tuple[list[str], str]:
    """The fit options a log of sample time ``dt`` [s] calls for, and why: ``--encoder-counts``
    for angles that move by whole ``counts`` per revolution (its quantisation shrinks a plain
    fit's values), and with them, where the ``span`` holds the quartic smoother's samples
    (:meth:`ropod_sysid.recipe.Span.quartic_would_fit`), the quartic with the drives' lag
    searched (the LOESS's discretisation bias, which σ does not include, outgrows a long
    log's σ). Nothing for angles not on a count grid: the quartic passes more of an unknown
    noise. ``constrained``: steered wheels or legs, where the correction can over-correct."""
    if counts is None:
        return [], ""
    options = [f"--encoder-counts {counts}"]
    why = "to correct for the encoders' quantisation, which shrinks a plain fit's values"
    if span.quartic_would_fit(dt):
        options += ["--smoother quartic", "--input-delay auto"]
        why += (f"; the {span} span holds {span.samples(dt, 0)} samples, enough for the quartic "
                "smoother's five-point differences, which keep the LOESS's bias out of a long "
                "log's values (with the drives' lag searched)")
    if constrained:
        why += "; with steered wheels or legs the correction can over-correct: compare a plain fit"
    return options, why


def _column_units(log: Log) -> dict[str, str]:
    """The SI unit of every column of the log (each unit type's channels)."""
    lay = log.layout
    out = {"t": "s"}
    out |= {n: c.unit for n, c in zip(lay.angle_names, lay.angle_channels, strict=True)}
    out |= {n: c.unit for n, c in zip(lay.current_names, lay.current_channels, strict=True)}
    return out | {"x_b": "m", "y_b": "m", "theta_b": "rad"}


def motion_shortfall(seconds: float, what: str = "of motion",
                     criteria: Criteria | None = None) -> str | None:
    """The verdict's first rule: why ``seconds`` (of motion, or ``what``) are too few to fit,
    or None when they are enough (:attr:`Criteria.min_moving`). A fit checks its logs'
    length with it: a log shorter than that cannot hold enough motion."""
    c = criteria or Criteria()
    if seconds < c.min_moving:
        return f"only {seconds:.1f} s {what}; record at least {c.min_moving:g} s"
    return None


def _base_velocity(log: Log, model: PlatformModel, t: np.ndarray, dt_med: float,
                   c: Criteria) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Base-frame twist (N, 3) from the encoders (rates smoothed over ~50 ms), the samples
    that move (N,), each sample's share of the time axis [s] (N,), and (constrained platforms,
    else None) the samples whose base rows the fit keeps (N,)."""
    if t.size < 3:
        return np.zeros((0, 3)), np.zeros(t.size, bool), np.zeros(t.size), None
    angles, _ = unwrap_angles(model.platform.layout.wrapped, log.angles)
    rates = np.gradient(angles, t, axis=0)
    w = max(1, int(round(0.05 / dt_med))) if dt_med > 0 else 1
    if w > 1:
        from scipy.ndimage import uniform_filter1d  # (0.4-0.8 s to import: only here)

        rates = uniform_filter1d(rates, w, axis=0, mode="nearest")
    vel = base_twist(model, angles, rates)
    moving = (np.hypot(vel[:, 0], vel[:, 1]) > c.moving_speed) | \
        (np.abs(vel[:, 2]) > c.moving_turn)
    used = None
    if model.constrained:
        st = model.state(np.zeros((t.size, 3)), vel, angles, rates)
        proj = model.identification_projector(st)
        assert proj is not None  # constrained
        used = np.abs(proj[:, :3, :3]).max(axis=(1, 2)) > 0.5
    return vel, moving, np.gradient(t), used


def _sideways_singular(model: PlatformModel) -> bool:
    """Whether pure sideways translation puts the platform in a singular configuration (its
    base rows left out of the fit)."""
    if not model.constrained:
        return False
    twist = np.array([0.0, 1.0, 0.0])
    angles = model.initial_angles(twist)[None]
    st = model.state(np.zeros((1, 3)), twist[None], angles, np.zeros_like(angles))
    proj = model.identification_projector(st)
    assert proj is not None  # constrained
    return bool(np.abs(proj[0, :3, :3]).max() < 0.5)


def inspect_file(path: str | Path, platform: Platform,
                 criteria: Criteria | None = None) -> Inspection:
    """Read a log (any format and layout) and inspect it; reading warnings end up in notes."""
    from ropod_sysid.io import read_log

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = read_log(path, platform, gaps="allow")  # gaps are a finding here
    return inspect_log(log, platform, criteria)


def format_inspection(ins: Inspection) -> str:
    """The inspection as text for the terminal."""
    lines = [
        f"log        {ins.source}",
        f"units      {', '.join(ins.units)}",
        f"samples    {ins.samples} over {ins.duration:.3f} s",
        f"rate       {ins.rate:.2f} Hz mean (median interval {1e3 * ins.dt_median:.3f} ms, "
        f"jitter {1e3 * ins.jitter:.3f} ms std)",
        f"gaps       {ins.gap_count}"
        + ("" if not ins.gaps else "  (" + ", ".join(
            f"{g.dt:.4g} s at t={g.t:.3f} s" for g in ins.gaps[:5])
            + (", …" if ins.gap_count > 5 else "") + ")"),
        f"dropped    {ins.dropped_frames} frame{'s' if ins.dropped_frames != 1 else ''}",
        f"moving     {ins.moving_time:.1f} s",
        "velocity   " + ", ".join(f"{k} [{lo:.3g}, {hi:.3g}]"
                                  for k, (lo, hi) in ins.velocity_ranges.items())
        + "  (1st–99th percentile, base frame; m/s, m/s, rad/s)",
        *(["turning    " + ", ".join(f"{u}: {deg:.0f}°"
                                     for u, deg in ins.pivot_coverage.items())
           + "  of the circle visited (pivots, steering)"] if ins.pivot_coverage else []),
        *([f"base rows  kept by the fit for {100 * ins.base_rows_used:.0f} % of the moving "
           "time (the rest near singular configurations or slipping)"]
          if ins.base_rows_used is not None else []),
        *(["sideways   a singular configuration of this platform (its axles then on one "
           "line): not asked for"] if ins.sideways_singular else []),
        "ranges",
    ]
    width = max((len(k) for k in ins.ranges), default=0)
    for k, (lo, hi) in ins.ranges.items():
        lines.append(f"  {k:<{width}}  {lo:>12.6g}  {hi:>12.6g}  {ins.column_units.get(k, '')}")
    for note in ins.notes:
        lines.append(f"note       {note}")
    for w in ins.warnings:
        lines.append(f"warning    {w}")
    if ins.encoder_counts is not None:
        lines.append(f"encoders   the angles move by whole counts of 2π/{ins.encoder_counts}")
    if ins.fit_options:
        lines.append(f"fit with   {' '.join(ins.fit_options)} ({ins.fit_advice})")
    if ins.enough_to_fit:
        lines.append("verdict    enough to fit: long and varied enough")
    else:
        lines.append("verdict    not enough to fit: " + "; ".join(ins.reasons))
    return "\n".join(lines)
