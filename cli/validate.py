"""``ropod-sysid validate``: a fitted model on logs it was not fitted on."""

from __future__ import annotations

import click

from ropod_sysid.cli.common import (
    INPUT,
    LOG_INPUT,
    SpanType,
    json_text,
    platform_option,
    quiet_option,
    reports_errors,
    split_gaps_option,
)
from ropod_sysid.cli.fit import dask_option, workers_option
from ropod_sysid.fitfile import fit_settings, parameters_of
from ropod_sysid.io.paramfile import read_parameters
from ropod_sysid.params import DynamicParameters
from ropod_sysid.platform import load_platform
from ropod_sysid.regressor import Span
from ropod_sysid.summary import format_validation
from ropod_sysid.validate import FORCE_THRESHOLD, TORQUE_THRESHOLD, validate_sources


@click.command("validate", short_help="Check a fitted model on logs it was not fitted on.")
@click.argument("logs", nargs=-1, required=True, type=LOG_INPUT)
@platform_option
@click.option("--params", "params_path", required=True, type=INPUT,
              help="Parameter file of a fit, or a flat name: value mapping (a simulation's "
                   "truth).")
@click.option("--span", type=SpanType(), default=None,
              help="LOESS span: an odd number of samples or seconds (default: the fit's).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object for scripts.")
@split_gaps_option
@workers_option
@dask_option
@quiet_option
@reports_errors
def command(logs: tuple[str, ...], platform_path: str, params_path: str, span: Span | None,
            as_json: bool, split_gaps: bool, workers: int | None, dask_address: str | None,
            quiet: bool) -> None:
    """Residual RMS per log and DOF, and the disturbance observer's view (eq. 40).

    Each log is read and processed in chunks; with --workers or --dask the logs are processed
    in parallel on Dask workers."""
    platform = load_platform(platform_path)
    pfile = read_parameters(params_path, platform)  # a fit's file, or a flat truth.json
    _, values = parameters_of(pfile, platform, params_path)
    params = DynamicParameters.from_mapping(values, platform, params_path)
    file_span, delay, row_step = fit_settings(pfile, params_path)  # as the fit was made
    sp = span.with_smoother(file_span.smoother) if span is not None else file_span
    results = validate_sources(list(logs), platform, params, sp, delay, workers=workers,
                               dask_address=dask_address, row_step=row_step, quiet=quiet,
                               split_gaps=split_gaps)
    if as_json:
        click.echo(json_text({
            "params": params_path, "span": str(sp),
            "thresholds": {"force_N": FORCE_THRESHOLD, "torque_Nm": TORQUE_THRESHOLD},
            "logs": [r.to_dict() for r in results]}))
    else:
        click.echo(format_validation(results))
