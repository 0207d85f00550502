"""``ropod-sysid inspect``: timing, gaps, ranges of a log and whether it is enough to fit."""

from __future__ import annotations

import click

from ropod_sysid.cli.common import LOG_INPUT, json_text, platform_option, reports_errors
from ropod_sysid.inspect import format_inspection, inspect_file
from ropod_sysid.platform import load_platform


@click.command("inspect",
               short_help="Look at a log before fitting: rate, gaps, ranges, verdict, options.")
@click.argument("log_path", metavar="LOG", type=LOG_INPUT)
@platform_option
@click.option("--json", "as_json", is_flag=True, help="Print the findings as JSON.")
@reports_errors
def command(log_path: str, platform_path: str, as_json: bool) -> None:
    """Inspect LOG (.csv or .mcap, any layout): units, duration, rate and jitter, gaps,
    dropped frames, channel ranges, whether it is long and varied enough to fit, and the fit
    options its angles call for (encoder counts, smoother)."""
    platform = load_platform(platform_path)
    ins = inspect_file(log_path, platform)
    if as_json:
        click.echo(json_text(ins.to_dict()))
    else:
        click.echo(format_inspection(ins))
