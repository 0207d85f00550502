"""Identification: logs in, parameters and an honest account of how well they are determined.

The thesis's method (Sec. VI, App. D-C): per log, A_ID,ext m_ext = b_ID (eq. 36) over all
samples; the rotational rows are weighted so that their mean square of b_ID equals the
translational rows' (Sec. VI-A); the weighted systems of all logs are stacked (eq. 37) and
solved in the least-squares sense (eq. 38) — here by QR triangles (:mod:`ropod_sysid.solve`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.io.paramfile import ParameterFile
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import Friction, kind_of
from ropod_sysid.platform import Platform
from ropod_sysid.regressor import Span, preprocess, triangles
from ropod_sysid.solve import RCOND, Solution, Triangles, combined_rms, solve, stack_triangles

if TYPE_CHECKING:
    from ropod_sysid.plotdata import LogPlot

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
    max_delay: float = 0.05
    row_step: int | None = None  # samples between equation rows; None: ~10 per span


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

    @property
    def names(self) -> list[str]:
        return self.solution.names

    @property
    def samples(self) -> int:
        return sum(lf.samples for lf in self.logs)

    def values(self) -> dict[str, float]:
        sol = self.physical or self.solution
        return dict(zip(sol.names, map(float, sol.values), strict=True))

    def parameter_file(self) -> ParameterFile:
        """The controller's parameter file (data contract), with the fit's account in extras."""
        sol = self.solution
        values = self.physical.values if self.physical is not None else sol.values
        params: dict[str, dict[str, object]] = {}
        for j, name in enumerate(sol.names):
            std = sol.std[j]
            entry: dict[str, object] = {"value": float(values[j]),
                                        "std": None if not np.isfinite(std) else float(std)}
            if sol.combination[j]:
                entry["combination"] = True
                entry["meaning"] = sol.combinations.get(name, "")
            if name in sol.fixed:
                entry["fixed"] = True
            params[name] = entry
        rms = self.physical_rms if self.physical_rms is not None else self.rms
        extras: dict[str, object] = {
            "friction": self.options.friction,
            "span": str(self.options.span),
            "row_step": self.options.row_step or "auto",
            "weight_rotation": [lf.weight for lf in self.logs],
            "input_delay_s": self.input_delay,
            "logs": [{"file": lf.source, "samples": lf.samples, "rows": lf.triangles.rows,
                      "rms": {"translation": lf.rms["translation"],
                              "rotation": lf.rms["rotation"]}} for lf in self.logs],
        }
        if sol.fixed:
            extras["fixed"] = dict(sol.fixed)
        if sol.null_space.shape[1]:
            extras["null_space"] = sol.null_space_text()
        if self.physical is not None:
            extras["physical"] = True
            extras["rms_free_fit"] = dict(self.rms)
        return ParameterFile(self.platform.name, params,  # type: ignore[arg-type]
                             {"translation": rms["translation"], "rotation": rms["rotation"]},
                             sol.condition_number, sol.rank, self.samples, extras)


def _span_of(pfile: ParameterFile, where: str) -> Span:
    text = pfile.extras.get("span")
    if text is None:
        return Span.parse(None)
    try:
        return Span.parse(str(text).replace(" samples", "").strip())
    except InputError:
        raise InputError(f"{where}: key 'span' is {text!r}; expected e.g. '0.1s' or "
                         "'21 samples', or give --span") from None


def _row_step_of(pfile: ParameterFile, where: str) -> int | None:
    step = pfile.extras.get("row_step")
    if step is None or step == "auto":
        return None
    if isinstance(step, bool) or not isinstance(step, int) or step < 1:
        raise InputError(f"{where}: key 'row_step' must be 'auto' or a positive whole number "
                         f"of samples, got {step!r}")
    return step


def _delay_of(pfile: ParameterFile, where: str) -> float:
    d = pfile.extras.get("input_delay_s")
    if d is None:
        return 0.0
    if isinstance(d, bool) or not isinstance(d, int | float) or not math.isfinite(d) or d < 0:
        raise InputError(f"{where}: key 'input_delay_s' must be a non-negative number of "
                         f"seconds, got {d!r}")
    return float(d)


def fit_settings(pfile: ParameterFile, where: str) -> tuple[Span, float, int | None]:
    """The preprocessing a parameter file was fitted with: (span, input delay [s], row step or
    None for auto), from its extras; files without them get the defaults. A bad value is a
    one-line :class:`InputError` naming ``where``."""
    return _span_of(pfile, where), _delay_of(pfile, where), _row_step_of(pfile, where)


def physical_bounds(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a physically consistent fit: masses and inertias ≥ 0; friction dissipative
    (roll friction ≤ 0 since it is added to the wheel torque, pivot friction ≥ 0; see params)."""
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    for j, name in enumerate(names):
        kind = kind_of(name)
        if kind in ("m_b", "Jzz_b", "m_wh", "Jzz_wh", "Jrot_w", "fpv", "fpc"):
            lo[j] = 0.0
        elif kind in ("fwv", "fwc"):
            hi[j] = 0.0
    return lo, hi


def _weights(systems: Sequence[Triangles], mode: WeightRotation) -> list[float]:
    if mode == "auto":
        return [s.rotation_weight() for s in systems]
    if mode == "none":
        return [1.0 for _ in systems]
    return [float(mode) for _ in systems]


def fit_systems(systems: Sequence[Triangles], names: Sequence[str], options: FitOptions,
                ) -> tuple[Solution, list[float]]:
    """Weight, stack and solve the triangles of several logs."""
    weights = _weights(systems, options.weight_rotation)
    r = stack_triangles([s.weighted(w) for s, w in zip(systems, weights, strict=True)])
    rows = 3 * sum(s.rows for s in systems)
    return solve(r, rows, names, options.fix, options.rcond,
                 correlation=mean_correlation(systems)), weights


def mean_correlation(systems: Sequence[Triangles]) -> float:
    """The logs' :attr:`Triangles.correlation`, weighted by their rows."""
    rows = sum(s.rows for s in systems)
    return sum(s.rows * s.correlation for s in systems) / rows if rows else 1.0


# (delay, gather the report's plot data) -> per log: source, triangles, notes, plot data
Reduce = Callable[[float, bool], list[tuple[str, Triangles, list[str], "LogPlot | None"]]]


def fit_logs(logs: Sequence[Log], platform: Platform, options: FitOptions | None = None,
             progress: Callable[[str], None] | None = None) -> FitResult:
    """Fit the dynamic parameters to several in-memory logs stacked together (eqs. 36–38).

    Each log is preprocessed whole (:func:`ropod_sysid.regressor.preprocess`); for log files of
    any length use :func:`fit_files`, which streams them.
    """
    options = options or FitOptions()
    if not logs:
        raise InputError("no logs given; pass one or more log files")
    model = PlatformModel(platform)
    say = progress or (lambda _msg: None)

    def reduce(delay: float, _plot: bool) -> list[tuple[str, Triangles, list[str], None]]:
        out = []
        for log in logs:
            say(f"preprocess {log.source}")
            pre = preprocess(log, platform, options.span, delay, options.row_step)
            out.append((log.source, triangles(model, pre, options.friction), pre.notes, None))
        return out

    return _fit(reduce, platform, options)


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
    logs again for every delay it tries. With ``plots`` the last pass also gathers what the
    report draws of each log (:attr:`LogFit.plot`; bounded size), so that a report needs no
    second reading of the logs.
    """
    from ropod_sysid.distributed import pool
    from ropod_sysid.stream import DEFAULT_CHUNK, check_source, log_reduction

    options = options or FitOptions()
    if not paths:
        raise InputError("no logs given; pass one or more log files")
    paths = [str(p) for p in paths]
    for p in paths:
        check_source(p, platform)
    say = progress or (lambda _msg: None)
    with pool(workers, dask_address, quiet=quiet) as run:
        def reduce(delay: float, plot: bool) -> list[tuple[str, Triangles, list[str],
                                                           LogPlot | None]]:
            say(f"reduce {len(paths)} log{'s' if len(paths) > 1 else ''}"
                + (f" (input delay {1000 * delay:.2f} ms)" if delay else ""))
            parts = run(log_reduction, paths, platform=platform, span=options.span,
                        input_delay=delay, friction=options.friction,
                        chunk=chunk or DEFAULT_CHUNK, row_step=options.row_step,
                        plot=plot and plots)
            return [(p, *part) for p, part in zip(paths, parts, strict=True)]

        return _fit(reduce, platform, options)


def _fit(reduce: Reduce, platform: Platform, options: FitOptions) -> FitResult:
    """Weight, stack and solve the triangles ``reduce(delay)`` gives, choosing the delay."""
    model = PlatformModel(platform)
    names = model.parameter_names(options.friction)
    delay = 0.0
    if options.input_delay == "auto":
        def cost(d: float) -> float:
            sol, _ = fit_systems([tri for _, tri, _, _ in reduce(d, False)], names, options)
            return sol.sigma2

        from scipy.optimize import minimize_scalar  # imported here: only the delay search

        res = minimize_scalar(cost, bounds=(0.0, options.max_delay),
                                             method="bounded", options={"xatol": 2e-4})
        delay = float(res.x)
    else:
        delay = float(options.input_delay)
    reduced = reduce(delay, True)
    systems = [tri for _, tri, _, _ in reduced]
    solution, weights = fit_systems(systems, names, options)
    per_log = [LogFit(source, tri.samples, w, tri.rms(solution.values), notes, tri, plot)
               for (source, tri, notes, plot), w in zip(reduced, weights, strict=True)]
    result = FitResult(platform, options, solution, per_log,
                       combined_rms(systems, solution.values), delay)
    if options.physical:
        r = stack_triangles([s.weighted(w) for s, w in zip(systems, weights, strict=True)])
        result.physical = solve(r, 3 * sum(s.rows for s in systems), names, options.fix,
                                options.rcond, bounds=physical_bounds(names),
                                correlation=mean_correlation(systems))
        result.physical_rms = combined_rms(systems, result.physical.values)
    return result
