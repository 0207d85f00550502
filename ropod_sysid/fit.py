"""Identification: logs in, parameters and an honest account of how well they are determined.

The thesis's method (Sec. VI, App. D-C): per log, A_ID,ext m_ext = b_ID (eq. 36) over all
samples; the rotational rows are weighted so that their mean square of b_ID equals the
translational rows' (Sec. VI-A); the weighted systems of all logs are stacked (eq. 37) and
solved in the least-squares sense (eq. 38) — here by QR triangles (:mod:`ropod_sysid.solve`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from ropod_sysid.crosscheck import checked, reference_budget, window_samples
from ropod_sysid.errors import InputError
from ropod_sysid.io import check_distinct
from ropod_sysid.io.log import Log
from ropod_sysid.io.paramfile import ParameterFile
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import (
    DISSIPATIVE_SIGN,
    UNITS_OF,
    DynamicParameters,
    Friction,
    is_inertial,
    kind_of,
)
from ropod_sysid.platform import Platform
from ropod_sysid.quantisation import counts_note, log_encoder_counts
from ropod_sysid.regressor import (
    DelayBracket,
    Span,
    check_input_delay,
    preprocess,
    triangles,
    usable_pieces,
)
from ropod_sysid.robust import (
    BISQUARE_C,
    DOWN_WEIGHTED,
    HUBER_C,
    MIN_ROBUST_STRETCHES,
    ROBUST_METHODS,
    Robust,
    robust_solve,
)
from ropod_sysid.solve import (
    RCOND,
    STRETCH_S,
    Solution,
    Triangles,
    check_fixed,
    check_rcond,
    combined_rms,
    gram_triangle,
    solve,
    stack_triangles,
)

if TYPE_CHECKING:
    from ropod_sysid.plotdata import LogPlot
    from ropod_sysid.reference import Reference

WeightRotation = Literal["auto", "none"] | float


@dataclass
class FitOptions:
    """Options of a fit (the ``fit`` command's flags)."""

    friction: Friction = "per-wheel"
    span: Span = field(default_factory=lambda: Span.parse(None))
    fix: dict[str, float] = field(default_factory=dict)
    weight_rotation: WeightRotation = "auto"
    physical: bool = False
    input_delay: float | Literal["auto"] = 0.0
    rcond: float = RCOND
    max_delay: float = 0.02  # --input-delay auto searches ±this (at most one span) [s]
    row_step: int | None = None  # samples between equation rows; None: ~10 per span
    split_gaps: bool = False  # fit the pieces between gaps in time as separate logs
    robust: Robust = "none"  # down-weight stretches with bumps (huber) or collisions (bisquare)
    control_period: float = 0.0  # the drives hold each torque this long (ZOH) [s]
    encoder_counts: int | None = None  # correct for the encoders' errors in A (counts/rev)
    # fold the shift to a second recipe into σ (crosscheck; its reference formed in the fit's
    # own pass); "auto": over all samples of logs of at most crosscheck.AUTO_MAX_SAMPLES, over
    # the first ones of longer logs (crosscheck.reference_budget)
    recipe_check: bool | Literal["auto"] = "auto"

    def __post_init__(self) -> None:
        """Nonsense values are a one-line :class:`InputError` before any work."""
        check_rcond(self.rcond)
        if self.input_delay != "auto":
            check_input_delay(float(self.input_delay),
                              self.span.value if self.span.seconds else None)
        if not (math.isfinite(self.control_period) and 0.0 <= self.control_period <= 0.05):
            raise InputError(f"--control-period {self.control_period:g}: give the drives' "
                             "control period in seconds, from 0 to 0.05, e.g. 0.001 for 1 kHz")
        if self.input_delay != "auto" and self.control_period:
            check_input_delay(float(self.input_delay) + 0.5 * self.control_period,
                              self.span.value if self.span.seconds else None)
        if self.encoder_counts is not None and (int(self.encoder_counts) != self.encoder_counts
                                                or self.encoder_counts < 16):
            raise InputError(f"--encoder-counts {self.encoder_counts}: give the encoders' "
                             "counts per revolution, a whole number ≥ 16, e.g. 16384")
        if self.robust not in ROBUST_METHODS:
            raise InputError(f"--robust {self.robust!r}: use {', '.join(ROBUST_METHODS)}")
        if not (math.isfinite(self.max_delay) and self.max_delay > 0):
            raise InputError(f"max_delay {self.max_delay:g}: must be a finite number of "
                             "seconds > 0")
        w = self.weight_rotation
        if w not in ("auto", "none") and not (isinstance(w, int | float)
                                               and math.isfinite(w) and w > 0):
            raise InputError(f"--weight-rotation {w!r}: use auto, none or a finite number > 0")
        if not (self.recipe_check is True or self.recipe_check is False
                or self.recipe_check == "auto"):
            raise InputError(f"recipe_check {self.recipe_check!r}: use True (--recipe-check), "
                             "False (--no-recipe-check) or 'auto' (the default)")

    def reduce_delay(self) -> float | DelayBracket:
        """What a pass over the logs forms b_ID at: the bracket ±top of ``--input-delay
        auto`` (top = ``max_delay``, at most one span given in seconds;
        :func:`ropod_sysid.delay.delay_search`), else the delay, with half the drives'
        ``control_period`` added (:func:`hold_delay`)."""
        if self.input_delay == "auto":
            span = self.span
            return DelayBracket(min(self.max_delay, span.value) if span.seconds
                                else self.max_delay)
        # a torque held by the drives over a control period acts, on average, half a period
        # after the instant it is logged at (zero-order hold)
        return float(self.input_delay) + hold_delay(self.control_period)


@dataclass
class LogFit:
    """One log's share of the fit."""

    source: str
    samples: int  # log samples the fit's rows cover
    weight: float
    rms: dict[str, float]
    notes: list[str]
    triangles: Triangles = field(repr=False)
    plot: LogPlot | None = field(default=None, repr=False)  # what the report draws of it

    @property
    def sample_time(self) -> float:
        """The log's sample time [s]: the duration its rows come from over the samples they
        cover (0 for a log without rows)."""
        return self.triangles.duration / self.samples if self.samples > 0 else 0.0


@dataclass
class FitResult:
    """Everything a fit produced: values, uncertainty, identifiability, residuals."""

    platform: Platform
    options: FitOptions
    solution: Solution
    logs: list[LogFit]
    rms: dict[str, float]
    input_delay: float
    physical: Solution | None = None
    physical_rms: dict[str, float] | None = None
    # the counts detected in the logs whose gram corrected the delay search's criterion (not
    # the fit: --input-delay auto without --encoder-counts, delay.delay_search); () for none
    search_counts: tuple[int, ...] = ()
    # --recipe-check: each value's shift to the reference fit, and that fit's flags
    recipe_shift: dict[str, float] | None = None
    recipe_reference: str = ""

    @property
    def names(self) -> list[str]:
        return self.solution.names

    @property
    def samples(self) -> int:
        return sum(lf.samples for lf in self.logs)

    @property
    def shown(self) -> Solution:
        """The solution the fit reports: the physically consistent one if made."""
        return self.physical if self.physical is not None else self.solution

    def values(self) -> dict[str, float]:
        sol = self.shown
        return dict(zip(sol.names, map(float, sol.values), strict=True))

    def fitted_parameters(self) -> DynamicParameters:
        """The values the fit reports (the physically consistent ones if made) as a model's
        parameters, e.g. to validate them on other logs."""
        return DynamicParameters.from_vector(self.shown.values, self.solution.names)

    def down_weighted(self) -> list[tuple[str, float, float, float]]:
        """``--robust``'s stretches weighted below :data:`DOWN_WEIGHTED`: (log, start, end [s
        from the log's first row], weight), by weight; empty for a plain fit."""
        w = self.solution.stretch_weights
        if w is None:
            return []
        out = []
        k = 0
        for lf in self.logs:
            count = sum(block.shape[0] for block in lf.triangles.stretches)
            for i in np.flatnonzero(w[k:k + count] < DOWN_WEIGHTED):
                out.append((lf.source, STRETCH_S * i, min(STRETCH_S * (i + 1),
                            lf.triangles.duration), float(w[k + i])))
            k += count
        return sorted(out, key=lambda item: item[3])

    def robust_account(self) -> dict[str, object]:
        """What ``--robust`` did, for the parameter file's extras."""
        w = self.solution.stretch_weights
        assert w is not None
        c = BISQUARE_C if self.options.robust == "bisquare" else HUBER_C
        return {"method": self.options.robust, "c": c, "stretch_s": STRETCH_S,
                "stretches": int(w.size),
                "down_weighted": [{"file": f, "from_s": a, "to_s": b, "weight": round(x, 4)}
                                  for f, a, b, x in self.down_weighted()]}

    def corrections_text(self) -> str:
        """One line on the corrections the fit applied ('' for none)."""
        o = self.options
        parts = []
        if o.encoder_counts:
            parts.append(f"Corrected for the errors of {o.encoder_counts}-count encoders in "
                         "A_ID,ext (AᵀA − E[δAᵀδA], --encoder-counts)")
        if o.control_period:
            parts.append(f"The drives hold each torque {1000 * o.control_period:g} ms: half of "
                         "it is in the input delay (--control-period)")
        if o.span.degree != 2:
            parts.append("Angles smoothed by a local quartic, five-point differences "
                         "(--smoother quartic)")
        return "; ".join(parts)

    def robust_text(self) -> str:
        """One line on what ``--robust`` did ('' for a plain fit)."""
        w = self.solution.stretch_weights
        if w is None:
            return ""
        low = self.down_weighted()
        where = "; ".join(f"{f} {a:.0f}–{b:.0f} s ({x:.2f})" for f, a, b, x in low[:5])
        more = f"; … {len(low) - 5} more" if len(low) > 5 else ""
        rule = (f"bisquare weights, 0 beyond {BISQUARE_C:g}× the median RMS residual"
                if self.options.robust == "bisquare" else
                f"Huber weights, below 1 above {HUBER_C:g}× the median RMS residual")
        return (f"--robust {self.options.robust}: {len(low)} of {w.size} stretches of "
                f"{STRETCH_S:g} s weighted below {DOWN_WEIGHTED:g} ({rule}; the smallest "
                f"{w.min():.2f})"
                + (f": {where}{more}" if low else ""))

    def parameter_file(self) -> ParameterFile:
        """The controller's parameter file (``docs/file-formats.md``), with the fit's account in
        extras."""
        sol = self.solution
        shown = self.shown
        params: dict[str, dict[str, object]] = {}
        for j, name in enumerate(sol.names):
            std = shown.std[j]
            entry: dict[str, object] = {"value": float(shown.values[j]),
                                        "std": None if not np.isfinite(std) else float(std),
                                        "unit": UNITS_OF.get(kind_of(name), "")}
            if shown.combination[j]:
                entry["combination"] = True
                entry["meaning"] = shown.combinations.get(name, "")
            if name in sol.fixed:
                entry["fixed"] = True
            params[name] = entry
        rms = self.physical_rms if self.physical_rms is not None else self.rms
        extras: dict[str, object] = {
            "friction": self.options.friction,
            "span": str(self.options.span),
            **({"smoother": self.options.span.smoother} if self.options.span.degree != 2
               else {}),
            "row_step": self.options.row_step or "auto",
            "weight_rotation": [lf.weight for lf in self.logs],
            "input_delay_s": self.input_delay,
            **({"input_delay_search_counts": list(self.search_counts)}
               if self.search_counts else {}),
            **({"control_period_s": self.options.control_period}
               if self.options.control_period else {}),
            **({"encoder_counts": self.options.encoder_counts,
                "errors_in_variables": "corrected: A^T A - E[dA^T dA] of the encoders' "
                                       "quantisation"}
               if self.options.encoder_counts else {}),
            **({"split_gaps": True} if self.options.split_gaps else {}),
            **({"robust": self.robust_account()} if sol.stretch_weights is not None else {}),
            **({"recipe_check": {"reference": self.recipe_reference,
                                 "shift": self.recipe_shift}}
               if self.recipe_shift is not None else {}),
            "std_basis": shown.std_basis,
            "std_white_noise": {n: None if not np.isfinite(v) else float(v)
                                for n, v in zip(sol.names, shown.std_white, strict=True)},
            "logs": [{"file": lf.source, "samples": lf.samples, "rows": lf.triangles.equations,
                      "rms": {"translation": lf.rms["translation"],
                              "rotation": lf.rms["rotation"]}} for lf in self.logs],
        }
        extras["model"] = {
            "platform": self.platform.to_dict(),
            "conventions": MODEL_CONVENTIONS,
        }
        if sol.fixed:
            extras["fixed"] = dict(sol.fixed)
        if sol.null_space.shape[1]:
            extras["null_space"] = sol.null_space_text()
        if self.physical is not None:
            extras["physical"] = True
            extras["rms_free_fit"] = dict(self.rms)
            extras["at_bound"] = {n: float(v) for n, v, a in zip(
                sol.names, shown.values, shown.at_bound, strict=True) if a}
            if shown.note:
                extras["physical_note"] = shown.note
        return ParameterFile(self.platform.name, params,
                             {"translation": rms["translation"], "rotation": rms["rotation"]},
                             sol.condition_number, sol.rank, self.samples, extras)


MODEL_CONVENTIONS = (
    "SI units. Base pose q_b = (x_b, y_b, theta_b) in the world frame; the direct equations of "
    "motion M_dir(q) q_b'' = B_Fb F_b + B_tau (tau + tau_f) + f_f + b_dir (the thesis's eq. 65), "
    "tau = torque_constant x motor current of each actuator. Friction is added to the motor "
    "torque: c_v rate + c_c tanh(friction_tanh_gain rate), so dissipative wheel friction is "
    "negative; a smart wheel's pivot friction acts on the base with +tau_fp, dissipative >= 0; "
    "body-axis friction (fbv_*, fbc_*) is a force along the base's own axes. Values marked "
    "'combination' are determined only together with others ('meaning').")


def physical_bounds(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a physically consistent fit: masses and inertias ≥ 0; friction dissipative
    (friction added to a motor torque ≤ 0, the swivel's pivot friction ≥ 0; each type's
    ``friction_signs``, see :mod:`ropod_sysid.params`)."""
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    for j, name in enumerate(names):
        sign = DISSIPATIVE_SIGN.get(kind_of(name))
        if is_inertial(name) or sign == 1:
            lo[j] = 0.0
        elif sign == -1:
            hi[j] = 0.0
    return lo, hi


def _weights(systems: Sequence[Triangles], mode: WeightRotation) -> list[float]:
    if mode == "auto":
        return [s.rotation_weight() for s in systems]
    if mode == "none":
        return [1.0 for _ in systems]
    return [float(mode) for _ in systems]


def fit_systems(systems: Sequence[Triangles], names: Sequence[str], options: FitOptions,
                calibrate: bool = True) -> tuple[Solution, list[float]]:
    """Weight, stack and solve the triangles of several logs; ``calibrate``: with the
    jackknife σ from their stretches (else the white-noise σ only, cheaper)."""
    weights = _weights(systems, options.weight_rotation)
    r = corrected_triangle(systems, weights)
    rows = 3 * sum(s.equations for s in systems)
    robust = options.robust != "none" and calibrate
    stretches = weighted_stretches(systems, weights) if calibrate else None
    sol = solve(r, rows, names, options.fix, options.rcond,
                correlation=mean_correlation(systems), stretches=stretches)
    if robust:
        if stretches is None or len(stretches) < MIN_ROBUST_STRETCHES:
            raise InputError(f"--robust {options.robust} needs at least {MIN_ROBUST_STRETCHES} "
                             f"stretches of {STRETCH_S:g} s of log; give longer logs or leave "
                             "it out")
        sol = robust_solve(sol, stretches, rows, names, options, mean_correlation(systems))
    return sol, weights


# --encoder-counts corrects the directions with AᵀA > this × E[δAᵀδA]. Not 10: on the off-square
# ropod's 37 s runs (rows every sample) the pivots' J_zz,wh direction, the one the encoders bias
# most (E ≈ 15 % of its AᵀA), sits at 9.0–9.2 and was left uncorrected (typical m_b σ 25 kg,
# optimised J_zz,wh's bias kept); the barely excited directions this guards are at E ≳ AᵀA.
CORRECTION_MARGIN = 3.0


def corrected_triangle(systems: Sequence[Triangles], weights: Sequence[float]) -> np.ndarray:
    """The stacked triangle of the weighted systems; when they carry the encoders' error gram
    (``--encoder-counts``), of the normal equations corrected for it (corrected least squares:
    AᵀA − E[δAᵀδA], Aᵀb unchanged; errors of A shrink a plain fit's values,
    :mod:`ropod_sysid.noise`), refactored by :func:`corrected_factor`. E is applied in the
    eigen-directions of the column-scaled AᵀA that exceed :data:`CORRECTION_MARGIN` × E's
    share in them, not in those the logs barely determine."""
    r = stack_triangles([s.weighted(w) for s, w in zip(systems, weights, strict=True)])
    grams = [s.weighted_error_gram(w) for s, w in zip(systems, weights, strict=True)]
    if not grams or any(g is None for g in grams):
        return r
    p = r.shape[0] - 1
    gram = r.T @ r
    d = np.sqrt(np.maximum(np.diag(gram)[:p], 1e-300))

    def rank(g: np.ndarray) -> int:  # of the column-scaled normal equations, as the fit's rule
        lam = np.linalg.eigvalsh(g[:p, :p] / np.outer(d, d))
        return int(np.count_nonzero(lam > RCOND**2 * lam.max()))

    before = rank(gram)
    err = sum(grams) / np.outer(d, d)  # type: ignore[arg-type]  # (no None: returned above)
    # only where the data determine a direction well above the encoders' error in it: in a
    # direction the motion barely excites (a symmetric layout's friction difference) E would
    # outweigh AᵀA and the corrected equations would lose it
    lam, vec = np.linalg.eigh(gram[:p, :p] / np.outer(d, d))
    keep = vec[:, lam > CORRECTION_MARGIN * np.einsum("ik,ij,jk->k", vec, err, vec)]
    gram[:p, :p] -= (keep @ keep.T @ err @ keep @ keep.T) * np.outer(d, d)
    if rank(gram) < before:
        raise InputError("--encoder-counts: the correction for the encoders' errors is larger "
                         "than the motion in the logs can carry (the corrected normal equations "
                         "lose rank); check the counts, or fit without it")
    return corrected_factor(gram, d)


def corrected_factor(gram: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The triangle [[R, R⁻ᵀAᵀb], [0, ρ]] of corrected normal equations ``gram`` ((p+1, p+1):
    AᵀA − E, Aᵀb, bᵀb) with column scales ``d`` (p,). R comes from
    the column-scaled AᵀA − E alone (:func:`gram_triangle`, then unscaled), so that the fit
    solves (AᵀA − E) m = Aᵀb, and ρ² = bᵀb − bᵀA (AᵀA − E)⁻¹ Aᵀb = ‖b − A m‖² − mᵀE m (the
    residual less the encoders' share: the corrected σ̂², the delay search's cost), clipped at
    0. Not an eigen-factor of the whole (p+1)² matrix: that is indefinite when mᵀE m exceeds
    the residual, and clipping its negative eigenvalue moves Aᵀb and AᵀA with it (on the
    off-square ropod's 37 s typical run, rows every sample: m_b ≈ 0 for 35.1 kg)."""
    p = d.size
    scaled = gram[:p, :p] / np.outer(d, d)
    r_s = gram_triangle(scaled)  # r_sᵀ r_s = scaled, semi-definite: its null space kept
    rhs = gram[:p, p] / d
    x = np.linalg.lstsq(r_s.T, rhs, rcond=None)[0]
    resid = float(gram[p, p] - x @ x)
    out = np.zeros_like(gram)
    out[:p, :p] = r_s * d[None, :]
    out[:p, p] = x
    out[p, p] = math.sqrt(max(resid, 0.0))
    return out


def weighted_stretches(systems: Sequence[Triangles], weights: Sequence[float],
                       ) -> np.ndarray | None:
    """The stretches of all logs (:meth:`Triangles.weighted_stretches`), (K, p+1, p+1); None
    when a log with rows has none (triangles made without them): the jackknife needs every
    row in some stretch."""
    if any(s.rows and not s.stretches for s in systems):
        return None
    return np.concatenate([s.weighted_stretches(w)
                           for s, w in zip(systems, weights, strict=True)])


def mean_correlation(systems: Sequence[Triangles]) -> float:
    """The logs' :attr:`Triangles.correlation`, weighted by their rows."""
    rows = sum(s.equations for s in systems)
    return sum(s.equations * s.correlation for s in systems) / rows if rows else 1.0


# (delay or the bracket of auto, gather the report's plot data) -> per log: source,
# triangles, notes, plot data
Reduce = Callable[[float | DelayBracket, bool],
                  list[tuple[str, Triangles, list[str], "LogPlot | None"]]]


def fit_logs(logs: Sequence[Log], platform: Platform, options: FitOptions | None = None,
             progress: Callable[[str], None] | None = None) -> FitResult:
    """Fit the dynamic parameters to several in-memory logs stacked together (eqs. 36–38).

    Each log is preprocessed whole (:func:`ropod_sysid.regressor.preprocess`); for log files of
    any length use :func:`fit_files`, which streams them. With ``options.split_gaps`` a log
    with gaps in time is fitted as its pieces (:func:`ropod_sysid.regressor.usable_pieces`).
    """
    options = options or FitOptions()
    if not logs:
        raise InputError("no logs given; pass one or more log files")
    model = PlatformModel(platform)
    say = progress or (lambda _msg: None)
    if options.split_gaps:
        logs = [p for log in logs for p in usable_pieces(log, options.span, options.row_step)]

    def reduce(delay: float | DelayBracket, _plot: bool,
               ) -> list[tuple[str, Triangles, list[str], LogPlot | None]]:
        out: list[tuple[str, Triangles, list[str], LogPlot | None]] = []
        for log in logs:
            say(f"preprocess {log.source}")
            pre = preprocess(log, platform, options.span, delay, options.row_step)
            detected = log_encoder_counts(log)
            note = counts_note(log.source, detected, options.encoder_counts, model.constrained,
                               options.span.quartic_would_fit(pre.dt))
            search = detected if isinstance(delay, DelayBracket) else None  # (as the stream's)
            out.append((log.source, triangles(model, pre, options.friction,
                                              encoder_counts=options.encoder_counts,
                                              search_counts=search),
                        pre.notes + ([note] if note else []), None))
        return out

    def prefix(reference: FitOptions) -> tuple[FitResult, FitResult, bool]:
        budget = reference_budget("auto", sum(log.n_samples for log in logs))
        cut = window_samples(logs, budget)
        return (fit_logs(cut, platform, dataclasses.replace(options, recipe_check=False)),
                fit_logs(cut, platform, reference), True)

    return checked(_fit(reduce, platform, options),
                   lambda ref: fit_logs(logs, platform, ref, progress), say, prefix)


def fit_files(paths: Sequence[str | Path], platform: Platform,
              options: FitOptions | None = None, workers: int | None = None,
              dask_address: str | None = None, chunk: int | None = None,
              progress: Callable[[str], None] | None = None, quiet: bool = True,
              plots: bool = False) -> FitResult:
    """Fit the dynamic parameters to log files, each read and reduced in chunks.

    Every log is streamed (:func:`ropod_sysid.stream.stream_log`: memory bounded by ``chunk``
    samples, default :data:`ropod_sysid.stream.DEFAULT_CHUNK`) to its QR triangles per DOF; the
    result equals :func:`fit_logs` of the whole logs to rounding. With ``workers`` (a local
    Dask cluster of that many processes) or ``dask_address`` (an existing scheduler) each log
    is reduced on a worker and only the triangles come back. ``input_delay="auto"`` streams the
    logs once, forming b_ID at the node delays of its bracket (:func:`_delay_search`). A log
    listed twice is refused
    (:func:`ropod_sysid.io.check_distinct`); with ``options.split_gaps`` a log with gaps in
    time is fitted as its pieces (:func:`ropod_sysid.stream.stream_pieces`). With ``plots``
    the last pass also gathers what the report draws of each log (:attr:`LogFit.plot`;
    bounded size), so that a report needs no second reading of the logs. The recipe check's
    reference (:mod:`ropod_sysid.crosscheck`) is formed in the same pass over the logs
    (:func:`ropod_sysid.stream.piece_triangles_checked`), and the logs are read again only
    where it could not be.
    """
    from ropod_sysid.chunks import check_source

    options = options or FitOptions()
    if not paths:
        raise InputError("no logs given; pass one or more log files")
    names = [str(p) for p in paths]
    check_distinct(names)
    for p in names:
        check_source(p, platform)
    say = progress or (lambda _msg: None)
    formed: list[Reference | None] = []
    result = _fit_paths(names, platform, options, workers, dask_address, chunk, say, quiet,
                        plots, formed)
    return checked(result, lambda ref: _fit_paths(names, platform, ref, workers, dask_address,
                                                  chunk, say, quiet, False, formed), say,
                   lambda ref: formed_prefix(formed, platform, options, ref))


def formed_prefix(formed: Sequence[Reference | None], platform: Platform, options: FitOptions,
                  reference: FitOptions) -> tuple[FitResult, FitResult, bool] | None:
    """The recipe check of logs longer than its budget (:func:`ropod_sysid.crosscheck.checked`):
    the fit under ``options`` and the reference fit under ``reference``, both of the samples
    the reference was formed on in the fit's pass (:attr:`Reference.main`,
    :attr:`Reference.pieces`), and whether those are windows spread over the logs; None
    where it was not formed for every log, or at another span or delay than ``reference``
    asks. Where every window was left out (too short for the reference recipe), the
    InputError of the first, as fitting the same windows in memory raises it."""
    if not formed or any(r is None for r in formed):
        return None
    refs = [r for r in formed if r is not None and r.pieces]
    failures = [r.failure for r in formed if r is not None and r.failure]
    if not refs and failures:
        raise InputError(failures[0])
    at = reference.reduce_delay()
    if not refs or any(r.span != reference.span or r.delay != at for r in refs):
        return None
    main = [piece for r in refs for piece in r.main]
    pieces = [piece for r in refs for piece in r.pieces]
    plain = dataclasses.replace(options, recipe_check=False)
    return (_fit(lambda _delay, _plot: main, platform, plain),
            _fit(lambda _delay, _plot: pieces, platform, reference),
            any(r.spread for r in refs))


def _fit_paths(paths: list[str], platform: Platform, options: FitOptions,
               workers: int | None, dask_address: str | None, chunk: int | None,
               say: Callable[[str], None], quiet: bool, plots: bool,
               formed: list[Reference | None]) -> FitResult:
    """:func:`fit_files` of checked ``paths`` without the recipe check. ``formed``: empty, the
    fit's own pass also forms the check's reference of each log (unless
    ``options.recipe_check`` is False) and puts it there; filled, the reference fit takes its
    logs from it where they match its recipe, instead of reading them again."""
    from ropod_sysid.chunks import estimated_samples, fewest_samples
    from ropod_sysid.distributed import pool
    from ropod_sysid.reference import ReferenceBudget
    from ropod_sysid.stream import DEFAULT_CHUNK, piece_triangles, piece_triangles_checked

    at = options.reduce_delay()
    if formed and all(r is not None and not r.partial and r.span == options.span
                      and r.delay == at for r in formed):  # the reference fit, its logs
        # formed beside the fit's
        pieces = [piece for r in formed if r is not None for piece in r.pieces]
        return _fit(lambda _delay, _plot: pieces, platform, options)
    size = chunk or DEFAULT_CHUNK
    # the reference beside the fit's pass, unless the check is off; on the first samples of
    # logs over its budget
    beside = options.recipe_check is not False
    with pool(workers, dask_address, quiet=quiet) as run:
        def reduce(delay: float | DelayBracket, plot: bool,
                   ) -> list[tuple[str, Triangles, list[str], LogPlot | None]]:
            say(f"reduce {len(paths)} log{'s' if len(paths) > 1 else ''}"
                + (f" (input delays ±{1000 * delay.top:.0f} ms)"
                   if isinstance(delay, DelayBracket) else
                   f" (input delay {1000 * delay:.2f} ms)" if delay else ""))
            if beside and not formed:
                # serially the logs share one budget (on Dask each log has a copy)
                budget = ReferenceBudget.for_logs(
                    options.recipe_check, paths, [fewest_samples(p) for p in paths],
                    estimated_samples)
                both = run(piece_triangles_checked, paths, platform=platform, check=options,
                           input_delay=delay, chunk=size, plot=plot and plots, budget=budget)
                formed.extend(ref for _, ref in both)
                return [piece for pieces, _ in both for piece in pieces]
            parts = run(piece_triangles, paths, platform=platform, span=options.span,
                        input_delay=delay, friction=options.friction,
                        chunk=size, row_step=options.row_step,
                        split_gaps=options.split_gaps, plot=plot and plots,
                        encoder_counts=options.encoder_counts)
            return [piece for pieces in parts for piece in pieces]

        return _fit(reduce, platform, options)


def hold_delay(control_period: float) -> float:
    """The lag [s] of the motion behind a torque logged at the start of the ``control_period``
    over which the drives hold it (zero-order hold): half the period. Measured on noise-free
    200 Hz runs simulated under a 1 ms hold: the largest error over the 29 parameters of the
    off-square ropod falls from 2.8 % to 0.57 % (0.37 % with a row every sample)."""
    return 0.5 * control_period


def _fit(reduce: Reduce, platform: Platform, options: FitOptions) -> FitResult:
    """Weight, stack and solve the triangles ``reduce(delay)`` gives, choosing the delay.

    With one BLAS thread (:func:`ropod_sysid.chunks.single_thread_blas`), as the reduction
    has: the solves are of matrices of tens of columns, for which OpenBLAS's threads only wait
    on each other — numpy's and scipy's each spinning after a call while the other's runs. The
    delay search's 30 solves on the shipped sample took 44-45 ms with two threads, 11-12 ms
    with one."""
    from ropod_sysid.chunks import single_thread_blas

    with single_thread_blas():
        return _fit_blas(reduce, platform, options)


def _fit_blas(reduce: Reduce, platform: Platform, options: FitOptions) -> FitResult:
    model = PlatformModel(platform)
    names = model.parameter_names(options.friction)
    check_fixed(options.fix, names)  # before the logs are read
    delay = 0.0
    detected: tuple[int, ...] = ()
    if options.input_delay == "auto":
        from ropod_sysid.delay import delay_search

        reduced, delay, detected = delay_search(reduce, names, options)
    else:
        at = options.reduce_delay()
        assert not isinstance(at, DelayBracket)  # (not "auto")
        delay = at
        reduced = reduce(delay, True)
    for source, tri, _, _ in reduced:
        if tri.torque_free():
            raise InputError(f"{source}: the motor currents are all zero, so there is no torque "
                             "to fit the parameters to; check the log's current columns")
    systems = [tri for _, tri, _, _ in reduced]
    solution, weights = fit_systems(systems, names, options)
    per_log = [LogFit(source, tri.samples, w, tri.rms(solution.values), notes, tri, plot)
               for (source, tri, notes, plot), w in zip(reduced, weights, strict=True)]
    result = FitResult(platform, options, solution, per_log,
                       combined_rms(systems, solution.values), delay, search_counts=detected)
    if options.physical:
        r = corrected_triangle(systems, weights)
        rows = 3 * sum(s.equations for s in systems)
        stretches = weighted_stretches(systems, weights)
        if solution.stretch_weights is not None and stretches is not None:  # --robust
            stretches = solution.stretch_weights[:, None, None] * stretches
            r = gram_triangle(stretches.sum(axis=0))
            rows = max(1, round(rows * solution.stretch_weights.mean()))
        result.physical = solve(r, rows, names, options.fix,
                                options.rcond, bounds=physical_bounds(names),
                                correlation=mean_correlation(systems), stretches=stretches)
        result.physical_rms = combined_rms(systems, result.physical.values)
    return result
