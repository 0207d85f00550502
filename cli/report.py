"""``ropod-sysid report``: the HTML report of a parameter file on logs, without refitting."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

# the fit and the report are imported in the command, after the drawing processes have been
# forked (ropod_sysid.report.painter): they load matplotlib meanwhile
from ropod_sysid.cli.common import (
    INPUT,
    LOG_INPUT,
    SpanType,
    platform_option,
    quiet_option,
    reports_errors,
    split_gaps_option,
    writes,
)
from ropod_sysid.platform import load_platform

if TYPE_CHECKING:
    from ropod_sysid.platform import Platform
    from ropod_sysid.regressor import Span
    from ropod_sysid.report.painter import Painter


@click.command("report", short_help="Write the HTML report of a parameter file on logs (no refit).")
@click.argument("logs", nargs=-1, required=True, type=LOG_INPUT)
@platform_option
@click.option("--params", "params_path", required=True, type=INPUT,
              help="Parameter file of a fit (json, yaml or ros2).")
@click.option("--out", "out_path", required=True, type=click.Path(),
              help="HTML report to write (one self-contained file).")
@click.option("--compare", "compare_path", type=INPUT, default=None,
              help="Another parameter file shown side by side (e.g. a fixed-masses fit or the "
                   "truth of a simulation).")
@click.option("--validate", "validate_paths", multiple=True, type=INPUT,
              help="Validation log (repeatable): residuals and the disturbance observer.")
@click.option("--span", type=SpanType(), default=None,
              help="LOESS span: an odd number of samples (21) or seconds (0.1s). Default: the "
                   "parameter file's.")
@split_gaps_option
@quiet_option
@reports_errors
@writes(outputs={"out_path": "--out"},
        inputs={"logs": "LOGS", "platform_path": "--platform", "params_path": "--params",
                "compare_path": "--compare", "validate_paths": "--validate"})
def command(logs: tuple[str, ...], platform_path: str, params_path: str, out_path: str,
            compare_path: str | None, validate_paths: tuple[str, ...], span: Span | None,
            split_gaps: bool, quiet: bool) -> None:
    """Write the HTML report of the parameters in --params on LOGS (the fit's logs).

    No refit: the values and standard deviations are the file's; residuals, singular values,
    rank and null space are computed on LOGS.
    """
    from ropod_sysid.report.painter import Painter

    platform = load_platform(platform_path)
    # the figures' processes load matplotlib while this one reads the logs
    with Painter(layout=platform.layout) as painter:
        from ropod_sysid.validate import preload_free_run  # (after the fork: it loads the fit)

        preload_free_run(platform)  # numba for the free runs, while the logs are read
        _report(platform, logs, params_path, out_path, compare_path, validate_paths, span,
                split_gaps, quiet, painter)
    if not quiet:
        click.echo(f"wrote {out_path}", err=True)


def _report(platform: Platform, logs: tuple[str, ...], params_path: str, out_path: str,
            compare_path: str | None, validate_paths: tuple[str, ...], span: Span | None,
            split_gaps: bool, quiet: bool, painter: Painter) -> None:
    """The report command's work, its figures drawn by ``painter``."""
    from ropod_sysid.cli.fit import pieces_of
    from ropod_sysid.fitfile import fit_settings
    from ropod_sysid.io.paramfile import read_parameter_file
    from ropod_sysid.report import read_comparison, result_from_parameter_file, write_fit_report

    pfile = read_parameter_file(params_path)
    # a fit's parameter file, or a flat name → value mapping (a simulation's truth)
    compare, compare_label = read_comparison(compare_path, None, platform)
    file_span, _, row_step = fit_settings(pfile, params_path)
    validation = pieces_of(validate_paths, platform, split_gaps, span or file_span, row_step)
    # each log streamed once: triangles and what the report draws
    result, notes = result_from_parameter_file(platform, list(logs), pfile, span,
                                               where=params_path, split_gaps=split_gaps,
                                               quiet=quiet)
    write_fit_report(result, None, out_path, compare=compare, compare_label=compare_label,
                     validation_logs=validation, params_source=params_path, notes=notes,
                     painter=painter)
