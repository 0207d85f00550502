"""``ropod-sysid fit``: logs in, the controller's parameter file out."""

from __future__ import annotations

import click

from ropod_sysid.cli.common import platform_option, quiet_option, reports_errors
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_files
from ropod_sysid.io import read_log
from ropod_sysid.io.paramfile import write_parameter_file
from ropod_sysid.platform import load_platform
from ropod_sysid.regressor import Span
from ropod_sysid.solve import RCOND
from ropod_sysid.summary import format_fit

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
    return out


def parse_weight(text: str) -> str | float:
    if text in ("auto", "none"):
        return text
    try:
        w = float(text)
    except ValueError:
        raise InputError(f"--weight-rotation {text!r}: use auto, none or a positive number"
                         ) from None
    if not w > 0:
        raise InputError(f"--weight-rotation {text!r}: the weight must be positive")
    return w


def parse_delay(text: str) -> str | float:
    if text == "auto":
        return text
    try:
        d = float(text.removesuffix("s"))
    except ValueError:
        raise InputError(f"--input-delay {text!r}: use auto or seconds, e.g. 0.0025") from None
    if d < 0:
        raise InputError(f"--input-delay {text!r}: the delay cannot be negative")
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


def fit_options(friction: str, span: str | None, fix: tuple[str, ...], weight_rotation: str,
                physical: bool, input_delay: str, rcond: float,
                row_step: str = "auto") -> FitOptions:
    return FitOptions(friction=friction,  # type: ignore[arg-type]
                      span=Span.parse(span), fix=parse_fix(fix),
                      weight_rotation=parse_weight(weight_rotation),  # type: ignore[arg-type]
                      physical=physical, input_delay=parse_delay(input_delay),  # type: ignore
                      rcond=rcond, row_step=parse_row_step(row_step))


@click.command("fit", short_help="Fit the parameters to logs; write the parameter file.")
@click.argument("logs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@platform_option
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Parameter file to write.")
@click.option("--format", "fmt", type=click.Choice(["json", "yaml", "ros2", "kelo"]),
              default="json", show_default=True, help="Parameter file format.")
@click.option("--friction", type=click.Choice(["per-wheel", "shared"]), default="per-wheel",
              show_default=True, help="Friction coefficients per wheel and pivot, or shared.")
@click.option("--span", default=None,
              help="LOESS span: samples (21) or seconds (0.1s). Default 0.1s.")
@click.option("--row-step", default="auto", show_default=True, metavar="N|auto",
              help="Form an equation row every N samples; auto: about ten per span (every "
                   "10th sample at 1 kHz with 0.1s, every sample at 100 Hz). 1 = every sample.")
@click.option("--fix", multiple=True, metavar="NAME=VALUE",
              help="Hold a parameter fixed (repeatable), e.g. the weighed masses.")
@click.option("--weight-rotation", default="auto", show_default=True,
              help="auto (Sec. VI-A), none, or a number.")
@click.option("--physical", is_flag=True,
              help="Physically consistent fit (bounded least squares); RMS cost reported.")
@click.option("--input-delay", default="0", show_default=True,
              help="Lag of the motion behind the logged torque: seconds or auto.")
@click.option("--rcond", default=RCOND, show_default=True,
              help="Relative singular value below which a direction counts as unidentifiable.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the HTML fit report here.")
@click.option("--compare", "compare_path", type=click.Path(dir_okay=False), default=None,
              help="With --report: a parameter file shown side by side.")
@click.option("--validate", "validate_logs", multiple=True, type=click.Path(dir_okay=False),
              help="With --report: validation log (repeatable).")
@workers_option
@dask_option
@quiet_option
@reports_errors
def command(logs: tuple[str, ...], platform_path: str, out_path: str, fmt: str, friction: str,
            span: str | None, row_step: str, fix: tuple[str, ...], weight_rotation: str,
            physical: bool,
            input_delay: str, rcond: float, report_path: str | None, compare_path: str | None,
            validate_logs: tuple[str, ...], workers: int | None, dask_address: str | None,
            quiet: bool) -> None:
    """Fit the dynamic parameters to LOGS (stacked) and write the parameter file.

    Each log is read and reduced in chunks, so its length is not limited by memory; with
    --workers or --dask the logs are reduced in parallel on Dask workers.
    """
    platform = load_platform(platform_path)
    options = fit_options(friction, span, fix, weight_rotation, physical, input_delay, rcond,
                          row_step)

    def say(msg: str) -> None:
        if not quiet:
            click.echo(msg, err=True)

    # with --report, the fit's pass also gathers what the report draws: no second reading
    result = fit_files(list(logs), platform, options, workers=workers,
                       dask_address=dask_address, quiet=quiet, plots=report_path is not None)
    write_parameter_file(result.parameter_file(), out_path, fmt, platform)  # type: ignore[arg-type]
    if report_path is not None:
        from ropod_sysid.report import write_fit_report

        write_fit_report(result, None, report_path, compare=compare_path,
                         validation_logs=[read_log(p, platform) for p in validate_logs])
        say(f"wrote {report_path}")
    if not quiet:
        click.echo(format_fit(result))
    say(f"wrote {out_path}")
