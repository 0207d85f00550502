"""``ropod-sysid fit``: logs in, the controller's parameter file out."""

from __future__ import annotations

import contextlib
import math
import re
from typing import Literal, cast

import click

from ropod_sysid.cli.common import (
    INPUT,
    LOG_INPUT,
    SpanType,
    given,
    platform_option,
    quiet_option,
    reports_errors,
    split_gaps_option,
    writes,
)
from ropod_sysid.crosscheck import AUTO_MAX_SAMPLES, PREFIX_SAMPLES, REFERENCE_WINDOWS
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, FitResult, WeightRotation, fit_files
from ropod_sysid.inspect import motion_shortfall
from ropod_sysid.io import read_logs
from ropod_sysid.io.log import Log
from ropod_sysid.io.paramfile import DEFAULT_NODE, Format, ParameterFile, write_parameter_file
from ropod_sysid.params import Friction
from ropod_sysid.platform import Platform, load_platform
from ropod_sysid.regressor import Span, check_input_delay, usable_pieces
from ropod_sysid.robust import ROBUST_METHODS, Robust
from ropod_sysid.solve import RCOND
from ropod_sysid.summary import format_fit, format_validation
from ropod_sysid.validate import validate_sources

workers_option = click.option(
    "--workers", type=int, default=None, metavar="N",
    help="Reduce the logs in parallel on a local Dask cluster of N worker processes "
         "(needs: pip install 'ropod-sysid[dask]').")
dask_option = click.option(
    "--dask", "dask_address", default=None, metavar="ADDRESS",
    help="Reduce the logs on the workers of a running Dask scheduler, e.g. tcp://host:8786.")


def parse_fix(items: tuple[str, ...]) -> dict[str, float]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise InputError(f"--fix {item!r}: use NAME=VALUE, e.g. --fix m_b=35.1") from None
        if not math.isfinite(out[name.strip()]):
            raise InputError(f"--fix {item!r}: the value must be a finite number, e.g. "
                             "--fix m_b=35.1")
    return out


def parse_weight(text: str) -> WeightRotation:
    if text == "auto" or text == "none":
        return "auto" if text == "auto" else "none"
    try:
        w = float(text)
    except ValueError:
        raise InputError(f"--weight-rotation {text!r}: use auto, none or a positive number"
                         ) from None
    if not (math.isfinite(w) and w > 0):
        raise InputError(f"--weight-rotation {text!r}: the weight must be a finite number > 0")
    return w


def parse_delay(text: str, span: Span | None = None) -> float | Literal["auto"]:
    """auto, or seconds, (when ``span`` is in seconds) at most one span either way."""
    if text == "auto":
        return "auto"
    try:
        d = float(text.removesuffix("s"))
    except ValueError:
        raise InputError(f"--input-delay {text!r}: use auto or seconds, e.g. 0.0025") from None
    check_input_delay(d, span.value if span is not None and span.seconds else None)
    return d


def parse_row_step(text: str) -> int | None:
    if text == "auto":
        return None
    try:
        step = int(text)
    except ValueError:
        step = 0
    if step < 1:
        raise InputError(f"--row-step {text!r}: use auto or a positive whole number of samples "
                         "(1 = every sample)")
    return step


def fit_options(friction: str, span: Span | str | None, fix: tuple[str, ...],
                weight_rotation: str, physical: bool, input_delay: str, rcond: float,
                row_step: str = "auto", split_gaps: bool = False,
                robust: str = "none", control_period: float = 0.0,
                encoder_counts: int | None = None, smoother: str = "loess",
                recipe_check: bool | None = None) -> FitOptions:
    sp = Span.parse(span).with_smoother(smoother)
    # friction and robust: click's Choice of FRICTION_VARIANTS and ROBUST_METHODS
    return FitOptions(friction=cast(Friction, friction),
                      span=sp, fix=parse_fix(fix),
                      weight_rotation=parse_weight(weight_rotation),
                      physical=physical, input_delay=parse_delay(input_delay, sp),
                      rcond=rcond, row_step=parse_row_step(row_step), split_gaps=split_gaps,
                      robust=cast(Robust, robust), control_period=control_period,
                      encoder_counts=encoder_counts,
                      recipe_check="auto" if recipe_check is None else recipe_check)


def pieces_of(paths: tuple[str, ...], platform: Platform, split_gaps: bool, span: Span | None,
              row_step: int | None) -> list[Log]:
    """Logs read whole for a report: with --split-gaps their pieces long enough to fit."""
    if not split_gaps:
        return read_logs(paths, platform)
    return [p for log in read_logs(paths, platform, "allow")
            for p in usable_pieces(log, span, row_step)]


def check_enough(result: FitResult, logs: tuple[str, ...]) -> None:
    """A fit of logs shorter than the motion ``inspect`` calls enough to fit is no result."""
    seconds = sum(lf.triangles.duration for lf in result.logs)
    reason = motion_shortfall(seconds, "of log")
    if reason is not None:
        names = ", ".join(logs[:3]) + (", …" if len(logs) > 3 else "")
        raise InputError(f"{names}: {reason} of motion: the values of a shorter fit are noise "
                         "(ropod-sysid inspect shows what a log lacks)")


@click.command("fit", short_help="Fit the parameters to logs; write the parameter file.")
@click.argument("logs", nargs=-1, required=True, type=LOG_INPUT)
@platform_option
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Parameter file to write.")
@click.option("--format", "fmt", type=click.Choice(["json", "yaml", "ros2", "kelo"]),
              default="json", show_default=True, help="Parameter file format.")
@click.option("--node-name", default=DEFAULT_NODE, show_default=True,
              help="With --format ros2: the ROS 2 node the parameters are for (letters, digits "
                   "and underscores, not starting with a digit).")
@click.option("--friction", type=click.Choice(["per-wheel", "shared", "body"]),
              default="per-wheel", show_default=True,
              help="Friction coefficients per wheel and pivot, shared by the wheels (and the "
                   "pivots) of a unit type, or along the base's own axes (body: fbv_x … fbc_w, "
                   "the units carrying none).")
@click.option("--span", type=SpanType(), default=None,
              help="LOESS span: an odd number of samples (21) or seconds (0.1s). Default 0.1s.")
@click.option("--smoother", type=click.Choice(["loess", "quartic"]), default="loess",
              show_default=True,
              help="How the angles are smoothed and differentiated: loess (MATLAB's local "
                   "quadratic, three-point differences) or quartic (a local quartic, five-point "
                   "differences: less discretisation bias, for spans of 17 samples or more; "
                   "on quantised angles with --encoder-counts, which it needs: without, about "
                   "1.6× the σ at the same span). On long 1 kHz logs its σ cover the truth "
                   "where the loess's bias outgrows them.")
@click.option("--row-step", default="auto", show_default=True, metavar="N|auto",
              help="Form an equation row every N samples (at most one span); auto: about ten "
                   "per span (every 10th sample at 1 kHz with 0.1s, every sample at 100 Hz). "
                   "1 = every sample.")
@click.option("--fix", multiple=True, metavar="NAME=VALUE",
              help="Hold a parameter fixed (repeatable), e.g. the weighed masses.")
@click.option("--weight-rotation", default="auto", show_default=True,
              help="auto (Sec. VI-A), none, or a number.")
@click.option("--physical", is_flag=True,
              help="Physically consistent fit (bounded least squares); RMS cost reported.")
@click.option("--robust", type=click.Choice(ROBUST_METHODS), default="none",
              show_default=True,
              help="Iteratively reweighted least squares over 2 s stretches of the logs, for "
                   "logs with bumps or collisions. huber: a stretch whose RMS residual is above "
                   "2× the median counts less; bisquare: from there, a stretch beyond 4.7× "
                   "drops out. Needs at least 12 s of log.")
@click.option("--input-delay", default="0", show_default=True,
              help="Lag of the motion behind the logged torque: seconds, at most one span "
                   "either way (negative: the motion leads the logged torque), or auto "
                   "(searched within ±20 ms, at most one span).")
@click.option("--control-period", default=0.0, show_default=True, type=float, metavar="S",
              help="The drives' control period [s], e.g. 0.001 for 1 kHz: each torque is held "
                   "that long after it is logged (zero-order hold), so the motion lags it by "
                   "half a period on average; added to --input-delay (not with auto, which "
                   "searches the whole lag).")
@click.option("--encoder-counts", type=int, default=None, metavar="N",
              help="Counts per revolution of the wheel and pivot encoders: correct the fit "
                   "for their quantisation, whose errors in the accelerations sit in A_ID,ext "
                   "and shrink the values (corrected least squares; docs/method.md). Costs "
                   "about 2× the fit's time (the shipped sample; 10- and 30-minute 1 kHz logs).")
@click.option("--recipe-check/--no-recipe-check", default=None,
              help="Fit the logs a second time, differentiated the other way (the quartic for "
                   "the loess, or the loess for the quartic) with the drives' lag searched, and "
                   "add each value's shift between the two fits to its σ in quadrature: σ then "
                   "includes the recipe's own bias, which the jackknife over stretches cannot "
                   "see (ten varied 60 s runs at 200 Hz and 1 kHz: 100 % of the values within "
                   "2σ on every run, against 34–100 % without; with --encoder-counts one run "
                   "66 %; docs/accuracy.md). The second recipe is formed in the same pass over "
                   "the logs: 1.4–1.8× the fit's time. Default: on for logs of up to "
                   f"{AUTO_MAX_SAMPLES:,} samples in all (the shipped sample: 24,000; 16 minutes "
                   "at 1 kHz); on longer logs the shift is measured on part of them, with a "
                   f"note: {PREFIX_SAMPLES:,} samples in {REFERENCE_WINDOWS} windows spread over "
                   "them where their length is known beforehand (CSV), else their first "
                   f"{AUTO_MAX_SAMPLES:,}.")
@click.option("--rcond", default=RCOND, show_default=True,
              help="Relative singular value below which a direction counts as unidentifiable.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the HTML fit report here.")
@click.option("--compare", "compare_path", type=INPUT, default=None,
              help="A parameter file (or flat truth mapping) shown side by side: in the "
                   "report, or without --report beside the printed parameter table.")
@click.option("--validate", "validate_logs", multiple=True, type=INPUT,
              help="Validation log (repeatable): in the report, or without --report the "
                   "printed validation summary (as 'ropod-sysid validate').")
@split_gaps_option
@workers_option
@dask_option
@quiet_option
@reports_errors
@writes(outputs={"out_path": "--out", "report_path": "--report"},
        inputs={"logs": "LOGS", "platform_path": "--platform", "compare_path": "--compare",
                "validate_logs": "--validate"})
def command(logs: tuple[str, ...], platform_path: str, out_path: str, fmt: str, node_name: str,
            friction: str,
            span: Span | None, smoother: str, row_step: str, fix: tuple[str, ...],
            weight_rotation: str,
            physical: bool, robust: str,
            input_delay: str, control_period: float, encoder_counts: int | None,
            recipe_check: bool | None, rcond: float, report_path: str | None,
            compare_path: str | None,
            validate_logs: tuple[str, ...], split_gaps: bool, workers: int | None,
            dask_address: str | None, quiet: bool) -> None:
    """Fit the dynamic parameters to LOGS (stacked) and write the parameter file.

    Each log is read and reduced in chunks, so its length is not limited by memory; with
    --workers or --dask the logs are reduced in parallel on Dask workers.
    """
    options = fit_options(friction, span, fix, weight_rotation, physical, input_delay, rcond,
                          row_step, split_gaps, robust, control_period, encoder_counts,
                          smoother, recipe_check)
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", node_name):
        raise InputError(f"--node-name {node_name!r}: a ROS 2 node name has letters, digits and "
                         "underscores and does not start with a digit, e.g. ropod_dynamic_model")
    if given("node_name") and fmt != "ros2":
        raise InputError(f"--node-name {node_name}: applies to --format ros2 only")
    platform = load_platform(platform_path)

    def say(msg: str) -> None:
        if not quiet:
            click.echo(msg, err=True)

    compare: ParameterFile | None = None
    compare_label: str | None = None
    if compare_path is not None or report_path is not None:
        # the report module only when needed: keeps a plain fit quick
        from ropod_sysid.report import read_comparison

        compare, compare_label = read_comparison(compare_path, None, platform)
    with contextlib.ExitStack() as stack:
        painter = None
        if report_path is not None:  # its workers load matplotlib while the fit reads the logs
            from ropod_sysid.report.painter import Painter
            from ropod_sysid.validate import preload_free_run

            painter = stack.enter_context(Painter(layout=platform.layout))
            preload_free_run(platform)  # numba for the free runs, while the fit reads the logs
        # with --report, the fit's pass also gathers what the report draws: no second reading
        result = fit_files(list(logs), platform, options, workers=workers,
                           dask_address=dask_address, quiet=quiet, plots=painter is not None)
        check_enough(result, logs)
        write_parameter_file(result.parameter_file(), out_path, cast(Format, fmt), platform,
                             node_name=node_name)
        validation = None
        if validate_logs and report_path is None:
            validation = validate_sources(list(validate_logs), platform,
                                          result.fitted_parameters(), options.span,
                                          result.input_delay, workers=workers,
                                          dask_address=dask_address, row_step=options.row_step,
                                          quiet=quiet, split_gaps=split_gaps)
        if report_path is not None:
            from ropod_sysid.report import write_fit_report

            write_fit_report(result, None, report_path, compare=compare,
                             compare_label=compare_label, painter=painter,
                             validation_logs=pieces_of(validate_logs, platform, split_gaps,
                                                       options.span, options.row_step))
            say(f"wrote {report_path}")
            compare = None  # shown in the report
    if not quiet or compare is not None:  # --compare without --report: the table is its output
        click.echo(format_fit(result, compare, compare_label))
    if validation is not None:
        click.echo("validation of the fitted values on the --validate logs:")
        click.echo(format_validation(validation))
    say(f"wrote {out_path}")
