"""The HTML fit report: one self-contained file an engineer opens in any browser.

:func:`render_fit_report` returns the page as a string, :func:`write_fit_report` writes it
atomically (a failure leaves no partial file). The page is a Jinja2 template with autoescaping
on — everything that comes from a log (file names, unit names, notes) is escaped — and the
figures are PNGs embedded as ``data:`` URIs; there is no script and nothing is loaded over the
network.

A report needs a :class:`~ropod_sysid.fit.FitResult`. Without refitting, one is rebuilt from a
parameter file by :func:`result_from_parameter_file`: the file's values and standard deviations,
with the residuals, singular values, rank and null space of the given logs.

What is computed (parameters, RMS per log and DOF, singular values) always uses every row, from
the logs' triangles; what is plotted is gathered while each log streams, in bounded memory
(:mod:`ropod_sysid.plotdata`: min/max envelopes of the inputs, every s-th equation row for the
fit, its error, histograms and the error against velocity) and decimated for drawing
(:mod:`ropod_sysid.report.figures`). A log is read once, by the fit or by
:func:`result_from_parameter_file`.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from itertools import islice
from pathlib import Path
from typing import Any

import jinja2
import numpy as np

from ropod_sysid import __version__
from ropod_sysid.chunks import Source, check_source
from ropod_sysid.crosscheck import RECIPE_LIMITED, recipe_limited
from ropod_sysid.errors import InputError
from ropod_sysid.fit import (
    MIN_ROBUST_STRETCHES,
    ROBUST_METHODS,
    FitOptions,
    FitResult,
    LogFit,
    fit_systems,
    mean_correlation,
)
from ropod_sysid.fitfile import fit_settings, parameters_of
from ropod_sysid.forked import default_processes
from ropod_sysid.io import check_distinct
from ropod_sysid.io.atomic import atomic_write_text
from ropod_sysid.io.log import Log
from ropod_sysid.io.paramfile import ParameterFile, read_parameters
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import (
    DESCRIPTION,
    UNITS_OF,
    DynamicParameters,
    kind_of,
    parameter_names,
)
from ropod_sysid.platform import Platform
from ropod_sysid.plotdata import LogPlot
from ropod_sysid.progress import Progress
from ropod_sysid.regressor import Span
from ropod_sysid.report.correlation import correlation_table
from ropod_sysid.report.painter import Drawn, Painter
from ropod_sysid.robust import Robust
from ropod_sysid.solve import STRETCH_S, combined_rms
from ropod_sysid.stream import StreamResult, stream_log, stream_pieces
from ropod_sysid.summary import (
    compared_values,
    difference,
    identifiability_verdict,
    implausible,
    model_error_ratio,
    relative_std,
)
from ropod_sysid.validate import (
    FORCE_THRESHOLD,
    TORQUE_THRESHOLD,
    base_frame,
    fit_percentage,
    numpy_free_run_seconds,
    runs_compiled,
    simulated_velocity,
    validate_logs,
)

__all__ = ["read_comparison", "render_fit_report", "result_from_parameter_file",
           "write_fit_report"]

WEAK_RELATIVE_STD = 0.2  # the summary's threshold for "weakly determined"


# ---------------------------------------------------------------------------------------------
# a FitResult from a parameter file (no refit)


def result_from_parameter_file(platform: Platform, logs: Sequence[Source], pfile: ParameterFile,
                               span: Span | None = None, where: str = "<parameters>",
                               split_gaps: bool = False, quiet: bool = True,
                               threads: int | None = None) -> tuple[FitResult, list[str]]:
    """What a report needs, from a parameter file and logs, without refitting.

    The values and standard deviations are the file's; the per-log and total residual RMS are
    those of these values on ``logs``; the singular values, rank, condition number and null
    space are those of the weighted stacked regressor of ``logs`` (the least-squares solution
    of these logs is computed for that, but its values are not shown). The friction model,
    span (unless ``span`` is given), input delay and fixed parameters come from the file.

    ``logs`` are in-memory logs or log files; each is streamed once (:mod:`ropod_sysid.stream`),
    gathering also what the report draws of it (:attr:`LogFit.plot`); with ``split_gaps`` each
    piece between gaps in time is a log of its own (:func:`ropod_sysid.stream.stream_pieces`).
    ``threads`` logs are streamed at a time (default
    :func:`ropod_sysid.forked.default_processes`: 2 on a machine with two CPUs or more).

    The file is checked first (:func:`ropod_sysid.fitfile.parameters_of`). Returns the result and
    notes for the reader (e.g. that the values are those of a bounded fit).
    """
    if not logs:
        raise InputError("no logs given; pass one or more log files")
    stds = pfile.stds()
    notes: list[str] = []
    friction, values = parameters_of(pfile, platform, where)
    names = parameter_names(platform, friction)
    file_span, delay, row_step = fit_settings(pfile, where)
    # a --span given keeps the file's smoother
    span = span.with_smoother(file_span.smoother) if span is not None else file_span
    fixed = {k: values[k] for k in names
             if k in values and pfile.parameters[k].get("fixed") is True}
    extra_fixed = pfile.extras.get("fixed")
    if isinstance(extra_fixed, dict):
        fixed.update({str(k): float(v) for k, v in extra_fixed.items()
                      if str(k) in names and isinstance(v, int | float)})
    robust_extra = pfile.extras.get("robust")
    method = robust_extra.get("method") if isinstance(robust_extra, dict) else None
    robust: Robust = next((m for m in ROBUST_METHODS if m == method), "none")
    counts = pfile.extras.get("encoder_counts")
    counts = int(counts) if isinstance(counts, int) and not isinstance(counts, bool) else None
    period = pfile.extras.get("control_period_s")
    period = float(period) if isinstance(period, int | float) and not isinstance(
        period, bool) and math.isfinite(period) and 0 <= period <= 0.05 else 0.0
    # (the file's input_delay_s already holds half the control period; for the account only)
    options = FitOptions(friction=friction, span=span, fix=fixed, input_delay=delay,
                         row_step=row_step, robust=robust,
                         encoder_counts=counts, control_period=period)

    check_distinct([log for log in logs if not isinstance(log, Log)])
    for log in logs:
        check_source(log, platform)
    def pieces(log: Source) -> list[StreamResult]:
        return stream_pieces(log, platform, span, delay, friction, row_step=row_step,
                             split_gaps=split_gaps, plot=True, encoder_counts=counts)

    streamed: list[StreamResult] = []
    n_threads = min(len(logs), default_processes() if threads is None else max(int(threads), 1))
    # logs side by side (their smoothing and the encoders' gram are numpy, which releases the
    # GIL: 0.86 -> 0.67 s for the sample's four logs with their gram), in order
    with Progress(len(logs), "logs", quiet=quiet) as bar:  # (a bar on a terminal only)
        for done in _in_order(pieces, logs, n_threads):
            streamed += done
            bar.update(1)
    systems = [res.triangles for res in streamed]
    if robust != "none" and sum(len(st) for s in systems for st in s.stretches) \
            < MIN_ROBUST_STRETCHES:
        notes.append(f"the parameter file's fit was robust (--robust {robust}); these logs are too "
                     "short to weigh their stretches, so the comparison fit is a plain one")
        options = dataclasses.replace(options, robust="none")
    sol, weights = fit_systems(systems, names, options)

    m = np.array([values.get(k, 0.0) for k in names])
    std = np.array([np.nan if (v := stds.get(k)) is None else v for k in names])
    combination = sol.combination.copy()
    combinations = {}
    for j, k in enumerate(names):
        entry = pfile.parameters.get(k, {})
        if entry.get("combination") is True:
            combination[j] = True
            combinations[k] = str(entry.get("meaning") or "flagged as a combination in the "
                                  "parameter file")
        elif sol.combination[j]:
            combinations[k] = f"{sol.combinations.get(k, '')} (with these logs)"
    basis = pfile.extras.get("std_basis")  # what the file's σ are (shown), not these logs'
    solution = dataclasses.replace(sol, values=m, std=std, combination=combination,
                                   combinations=combinations, fixed=fixed,
                                   std_basis=basis if isinstance(basis, str) else sol.std_basis)
    per_log = [LogFit(res.source, res.triangles.samples, w, res.triangles.rms(m), res.notes,
                      res.triangles, res.plot) for res, w in zip(streamed, weights, strict=True)]
    result = FitResult(platform, options, solution, per_log, combined_rms(systems, m), delay)
    check = pfile.extras.get("recipe_check")  # the file's σ hold the shift to a second recipe
    if isinstance(check, dict) and isinstance(check.get("shift"), dict):
        result.recipe_shift = {str(k): float(v) for k, v in check["shift"].items()
                               if isinstance(v, int | float) and not isinstance(v, bool)}
        result.recipe_reference = str(check.get("reference", ""))
    if pfile.extras.get("physical") is True:
        notes.append("the values are those of a physically consistent (bounded) fit")
    file_rms = [pfile.rms.get(k, math.nan) for k in ("translation", "rotation")]
    here = [result.rms["translation"], result.rms["rotation"]]
    if all(math.isfinite(v) for v in file_rms) and any(
            abs(a - b) > 0.01 * max(abs(b), 1e-12) for a, b in zip(here, file_rms, strict=True)):
        notes.append(f"the parameter file reports an RMS residual of {file_rms[0]:.4g} N / "
                     f"{file_rms[1]:.4g} N m on the logs it was fitted to; on these logs it is "
                     f"{here[0]:.4g} N / {here[1]:.4g} N m")
    return result, notes


def _in_order(func: Callable[[Any], Any], items: Sequence[Any], threads: int) -> Iterator[Any]:
    """``func`` of each of ``items``, in order, ``threads`` of them at a time in threads; the
    next begins only when the earliest is taken, so that an error (raised where its result is
    taken) leaves the items not yet begun unread, and at most ``threads`` are held."""
    if threads <= 1:
        yield from map(func, items)
        return
    pool = ThreadPoolExecutor(threads, thread_name_prefix="ropod-sysid-log")
    try:
        rest = iter(items)
        running = deque(pool.submit(func, item) for item in islice(rest, threads))
        while running:
            result = running.popleft().result()
            for item in islice(rest, 1):
                running.append(pool.submit(func, item))
            yield result
    finally:  # an error: the item begun beside it ends in the background
        pool.shutdown(wait=False, cancel_futures=True)


# ---------------------------------------------------------------------------------------------
# rendering


@lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("ropod_sysid.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["num"] = _num
    env.filters["pct"] = _pct
    return env


def _num(value: Any, digits: int = 4) -> str:
    """A number for a table cell: ``digits`` significant digits; — when unknown."""
    if value is None:
        return "—"
    v = float(value)
    if math.isnan(v):
        return "—"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    # 2438, not 2.44e+03
    text = f"{v:.0f}" if 10**digits <= abs(v) < 1e7 else f"{v:.{digits}g}"
    return text.replace("-", "−")


def _pct(value: Any, digits: int = 1) -> str:
    if value is None or not math.isfinite(float(value)):
        return "—"
    text = f"{100 * float(value):.{digits}f}"
    if float(text) == 0:
        text = text.lstrip("-")  # no "-0.0 %"
    return text.replace("-", "−") + " %"


def _short(source: str) -> str:
    """The file name of a log's source, for narrow table cells (the full path is shown too)."""
    return Path(source).name or source


def _verdict_class(text: str) -> str:
    if text.startswith("well"):
        return "good"
    if text.startswith("rank deficient"):
        return "bad"
    return "warn"


def _plots(result: FitResult, logs: Sequence[Source] | None) -> list[LogPlot]:
    """Per log its plot data (:class:`ropod_sysid.plotdata.LogPlot`), gathered by the fit's
    pass or, when the result has none, by one streamed pass over ``logs``."""
    opts = result.options
    plots = []
    for k, lf in enumerate(result.logs):
        plot = lf.plot
        if plot is None:
            if logs is None:
                raise InputError(f"{lf.source}: the fit kept no plot data; give the fit's logs")
            res = stream_log(logs[k], result.platform, opts.span, result.input_delay,
                             opts.friction, row_step=opts.row_step, plot=True)
            plot = res.plot
            assert plot is not None
        plots.append(plot)
    return plots


def _log_views(result: FitResult, plots: Sequence[LogPlot], shown: np.ndarray,
               painter: Painter) -> tuple[list[dict[str, Any]], np.ndarray, np.ndarray,
                                          list[tuple[np.ndarray, np.ndarray]]]:
    """Per log: the figures and numbers; the kept rows' errors and velocities of all logs;
    per log its kept rows' times and errors.

    The numbers (rows, RMS per DOF) come from the log's triangles, so they cover every row;
    the figures from its plot data. The free run is :func:`_free_run_views`'.
    """
    platform = result.platform
    views, errs, vels = [], [], []
    series: list[tuple[np.ndarray, np.ndarray]] = []
    fig13: list[tuple[np.ndarray, np.ndarray, np.ndarray, list[float]]] = []
    for k, (lf, plot) in enumerate(zip(result.logs, plots, strict=True)):
        fit = plot.a_rows @ shown
        err = plot.b_rows - fit
        errs.append(err)
        series.append((plot.t_rows, err))
        vels.append(plot.qd_rows)
        rms = lf.triangles.rms(shown)
        views.append({
            "index": k,
            "id": f"log-{k + 1}",
            "source": lf.source,
            "name": _short(lf.source),
            "samples": lf.triangles.equations,
            "raw_samples": plot.samples,
            "duration": plot.duration,
            "rate": 1.0 / plot.dt if plot.dt > 0 else float("nan"),
            "weight": lf.weight,
            "rms": rms,
            "notes": list(lf.notes),
            "span_samples": plot.span_samples,
            "row_step": plot.row_step,
            "pose_source": "tracker (x_b, y_b, θ_b columns)" if plot.has_pose
            else "odometry",
        })
        fig13.append((plot.t_rows, plot.b_rows, fit, [rms["x"], rms["y"], rms["theta"]]))
    # each kind of figure for every log in one piece of work, on shared axes where it can
    for view, drawn in zip(views, painter.draw_each("fit_vs_measured_logs", len(views), fig13),
                           strict=True):
        view["fig13"] = drawn
    for view, drawn in zip(views, painter.draw_each("inputs_logs", len(views), list(plots),
                                                    platform.layout), strict=True):
        view["inputs"] = drawn
    all_err = np.concatenate(errs) if errs else np.zeros((0, 3))
    all_vel = np.concatenate(vels) if vels else np.zeros((0, 3))
    return views, all_err, all_vel, series


def free_run_view(platform: Platform, params: DynamicParameters, plot: LogPlot, first: bool
                  ) -> tuple[dict[str, float] | None, float | None, tuple[Any, ...] | None]:
    """A log's free run (every log where it is compiled, else the first log's first
    :func:`~ropod_sysid.validate.numpy_free_run_seconds`): its fit % per DOF, the time it
    covers [s] and, on the first log, the arguments of its figure
    (:func:`ropod_sysid.report.figures.predicted_velocity`); all None where there is none."""
    model = PlatformModel(platform)
    compiled = runs_compiled(model, params, plot.t_rows)
    if plot.state_rows is None or len(plot.t_rows) <= 2 or not (compiled or first):
        return None, None, None
    predicted = simulated_velocity(model, params, plot.t_rows, plot.qd_rows, plot.state_rows,
                                   None if compiled else numpy_free_run_seconds(model))
    measured = base_frame(plot.state_rows[0][:, 2], plot.qd_rows)
    fit_pct = dict(zip(("x", "y", "theta"), map(float, fit_percentage(measured, predicted)),
                       strict=True))
    span = float(plot.t_rows[np.isfinite(predicted[:, 0])][-1] - plot.t_rows[0])
    figure = (plot.t_rows, measured, predicted, fit_pct) if first else None
    return fit_pct, span, figure


def _free_run_views(views: list[dict[str, Any]], result: FitResult, plots: Sequence[LogPlot],
                    painter: Painter) -> None:
    """Each log's :func:`free_run_view` (fit %, time and the first log's figure) into the
    logs' ``views``: integrated here while the painter's workers draw the other figures."""
    params = result.fitted_parameters()
    drawn = None
    for k, (view, plot) in enumerate(zip(views, plots, strict=True)):
        fit_pct, span, figure = free_run_view(result.platform, params, plot, k == 0)
        if figure is not None:
            drawn = painter.draw("predicted_velocity", *figure)
        view["fit_pct"] = fit_pct
        view["prediction"] = None
        view["prediction_span"] = span
    if drawn is not None:
        views[0]["prediction"] = drawn.uri()


def _parameter_rows(result: FitResult, shown: np.ndarray,
                    compare: ParameterFile | None) -> tuple[list[dict[str, Any]], list[str]]:
    sol = result.shown
    rel = relative_std(result)
    other = compared_values(sol, compare.values()) if compare is not None else {}
    other_std = compare.stds() if compare is not None else {}
    rows = []
    for j, name in enumerate(sol.names):
        kind = kind_of(name)
        value = float(shown[j])
        std = float(sol.std[j])
        flags = []
        if name in sol.fixed:
            flags.append(("fixed", "fixed", "held fixed in the fit"))
        if sol.at_bound.size and sol.at_bound[j]:
            flags.append(("at-bound", "at bound",
                          f"on its physical bound ({value:g}) in the bounded fit: held there, "
                          "so it has no σ"))
        if sol.combination[j]:
            flags.append(("combination", "combination",
                          sol.combinations.get(name, "determined only in combination")))
        if implausible(name, value):
            flags.append(("implausible", "implausible",
                          "negative mass or inertia: physically implausible"))
        shift = (result.recipe_shift or {}).get(name)
        if shift is not None and recipe_limited(std, shift):
            flags.append(("recipe-limited", "recipe-limited", RECIPE_LIMITED))
        row: dict[str, Any] = {
            "name": name, "unit": UNITS_OF.get(kind, ""), "description": DESCRIPTION.get(kind, ""),
            "value": value, "std": std if math.isfinite(std) else None,
            "rel": float(rel[j]) if math.isfinite(rel[j]) else None,
            "weak": bool(math.isfinite(rel[j]) and rel[j] > WEAK_RELATIVE_STD),
            "flags": flags, "shift": shift,
        }
        if compare is not None:
            o = other.get(name)
            row["other"] = o
            row["other_std"] = other_std.get(name)
            row["diff"], row["rel_diff"], row["z"] = difference(value, std, o)
        rows.append(row)
    only_other = [k for k in other if k not in sol.names]
    return rows, only_other


def render_fit_report(result: FitResult, logs: Sequence[Source] | None = None, *,
                      compare: str | Path | ParameterFile | None = None,
                      compare_label: str | None = None,
                      validation_logs: Sequence[Log] | None = None,
                      params_source: str | None = None,
                      notes: Sequence[str] = (),
                      title: str | None = None, workers: int | None = None,
                      painter: Painter | None = None) -> str:
    """The report of ``result`` on ``logs`` (the fit's logs, in the fit's order) as HTML.

    ``logs`` (in-memory logs or files) are streamed once for the figures only when the result
    carries no plot data (:attr:`ropod_sysid.fit.LogFit.plot`: ``fit_files(..., plots=True)``
    and :func:`result_from_parameter_file` gather it); otherwise they may be None.

    compare : a parameter file (path or read) shown side by side with the differences
    validation_logs : logs the fit was not fitted on: residual RMS and disturbance observer
    params_source : where the values come from when the result was rebuilt from a file
    notes : further remarks for the reader (shown in the summary)
    workers : processes that draw the figures (:func:`ropod_sysid.report.painter.
        default_workers`: 2 on a machine with two CPUs or more; 1 draws them in this process)
    painter : a :class:`ropod_sysid.report.painter.Painter` already started (e.g. before the
        logs were read, so that its workers load matplotlib meanwhile); ``workers`` is then
        ignored
    """
    if painter is not None:
        return _render(result, logs, painter, compare, compare_label, validation_logs,
                       params_source, notes, title)
    with Painter(workers, result.platform.layout) as own:
        return _render(result, logs, own, compare, compare_label, validation_logs,
                       params_source, notes, title)


def _render(result: FitResult, logs: Sequence[Source] | None, painter: Painter,
            compare: str | Path | ParameterFile | None, compare_label: str | None,
            validation_logs: Sequence[Log] | None, params_source: str | None,
            notes: Sequence[str], title: str | None) -> str:
    if logs is not None and len(logs) != len(result.logs):
        raise InputError(f"the report needs the fit's {len(result.logs)} log(s), got "
                         f"{len(logs)}")
    compare_pf, compare_label = read_comparison(compare, compare_label, result.platform)
    platform = result.platform
    sol = result.solution
    physical = result.physical is not None
    shown = result.physical.values if result.physical is not None else sol.values
    rms = result.physical_rms if result.physical_rms is not None else result.rms
    verdict = identifiability_verdict(result)

    plots = _plots(result, logs)
    log_views, all_err, all_vel, series = _log_views(result, plots, shown, painter)
    rows, only_other = _parameter_rows(result, shown, compare_pf)
    n_free = len(sol.names) - len(sol.fixed)
    # every figure that needs no free run is drawn by the painter while this process integrates
    # the free runs (_free_run_views, below)
    figures = {
        "sv_figure": painter.draw("singular_values", sol.singular_values, sol.rank,
                                  result.options.rcond),
        "hist_figure": painter.draw("residual_histograms", all_err),
        "vel_figure": painter.draw("residual_vs_velocity", all_vel, all_err),
        "acf_figure": painter.draw("residual_autocorrelation", series, STRETCH_S),
    }

    validation = []
    if validation_logs:
        for k, v in enumerate(validate_logs(validation_logs, platform,
                                            result.fitted_parameters(), result.options.span,
                                            result.input_delay, result.options.row_step)):
            validation.append({
                "id": f"validation-{k + 1}", "source": v.source, "name": _short(v.source),
                "samples": v.samples,
                "rms": v.rms, "observer_rms": v.observer_rms, "observer_max": v.observer_max,
                "share_above": v.share_above,
                "alarm": v.share_above["force"] > 0 or v.share_above["torque"] > 0,
                "figure": painter.draw("observer", v.t, v.f_hat, FORCE_THRESHOLD,
                                       TORQUE_THRESHOLD),
            })

    _free_run_views(log_views, result, plots, painter)
    warnings = []
    n_implausible = sum(1 for r in rows if any(f[0] == "implausible" for f in r["flags"]))
    if n_implausible:
        warnings.append(f"{n_implausible} value(s) physically implausible (negative mass or "
                        "inertia): the logs may not excite them, or a combination is shown")
    if any(v["alarm"] for v in validation):
        warnings.append("the disturbance observer exceeds its threshold on a validation log")

    context = {
        "title": title or f"Fit report — {platform.name}",
        "version": __version__,
        "platform": {"name": platform.name, "source": platform.source,
                     "units": platform.unit_names, "n_units": platform.n_units,
                     "types": platform.types, "unit_groups": _unit_groups(platform)},
        "logs": log_views,
        "samples": int(sum(v["samples"] for v in log_views)),
        "correlation": mean_correlation([lf.triangles for lf in result.logs]),
        "std_basis": result.shown.std_basis,
        "model_error_ratio": model_error_ratio(result),
        "physical_note": result.shown.note,
        "robust_note": result.robust_text(),
        "corrections_note": result.corrections_text(),
        "span": str(result.options.span),
        "friction": result.options.friction,
        "rms": rms,
        "rms_free": result.rms if physical else None,
        "physical": physical,
        "rank": sol.rank,
        "n_free": n_free,
        "n_params": len(sol.names),
        "condition_number": sol.condition_number,
        "rcond": result.options.rcond,
        "input_delay_ms": 1000.0 * result.input_delay,
        "verdict": verdict,
        "verdict_class": _verdict_class(verdict),
        "params_source": params_source,
        "notes": list(notes),
        "warnings": warnings,
        "weak_threshold": WEAK_RELATIVE_STD,
        "parameters": rows,
        "recipe_shift": result.recipe_shift is not None,
        "compare_label": compare_label,
        "only_other": only_other,
        "n_implausible": n_implausible,
        "n_combination": int(np.sum(sol.combination)),
        "null_space": sol.null_space_text(),
        "combinations": [(k, v) for k, v in sol.combinations.items()],
        "corr": correlation_table(sol.names, sol.covariance),
        **figures,
        "validation": validation,
        "thresholds": {"force": FORCE_THRESHOLD, "torque": TORQUE_THRESHOLD},
    }
    return _environment().get_template("report.html").render(**_drawn(context))


def _drawn(value: Any) -> Any:
    """``value`` with every figure being drawn (:class:`Drawn`) replaced by its URI."""
    if isinstance(value, Drawn):
        return value.uri()
    if isinstance(value, dict):
        return {k: _drawn(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_drawn(v) for v in value]
    return value


def _unit_groups(platform: Platform) -> list[dict[str, Any]]:
    """The units' geometry and constants for the report, one table per unit type (each type's
    :meth:`~ropod_sysid.model.units.UnitType.unit_table`), units in platform order."""
    rows: dict[str, list[dict[str, Any]]] = {}
    for _, unit in PlatformModel(platform).groups:
        for row in unit.unit_table():
            rows.setdefault(str(row["type"]), []).append(row)
    order = {u: k for k, u in enumerate(platform.unit_names)}
    return [{"columns": list(rs[0]), "rows": sorted(rs, key=lambda r: order[str(r["name"])])}
            for _, rs in sorted(rows.items(), key=lambda kv: platform.types.index(kv[0]))]


def read_comparison(compare: str | Path | ParameterFile | None, label: str | None,
                    platform: Platform) -> tuple[ParameterFile | None, str | None]:
    """The parameter file to show beside the fit: a fit's parameter file, or a flat
    name → value mapping such as a simulation's truth."""
    if compare is None:
        return None, None
    if isinstance(compare, ParameterFile):
        return compare, label or "comparison"
    pfile = read_parameters(compare, platform)
    return pfile, label or Path(compare).name


def write_fit_report(result: FitResult, logs: Sequence[Source] | None, path: str | Path, *,
                     compare: str | Path | ParameterFile | None = None,
                     validation_logs: Sequence[Log] | None = None,
                     **options: Any) -> None:
    """Render the report (see :func:`render_fit_report`) and write it to ``path`` atomically:
    on any error no file, not even a partial one, is left at ``path``."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory; give the report's file name, e.g. "
                         "report.html")
    html = render_fit_report(result, logs, compare=compare, validation_logs=validation_logs,
                             **options)
    try:
        atomic_write_text(path, html)
    except OSError as exc:
        raise InputError(f"{path}: cannot write the report ({exc.strerror or exc})") from None
