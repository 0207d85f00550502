"""``ropod-sysid convert``: a log between CSV, MCAP (JSON) and MCAP (ROS 2), either layout."""

from __future__ import annotations

import warnings

import click

from ropod_sysid.cli.common import (
    LOG_INPUT,
    platform_option,
    quiet_option,
    reports_errors,
    writes,
)
from ropod_sysid.errors import InputError
from ropod_sysid.io import log_format, read_log
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.io.mcapwrite import write_mcap_log
from ropod_sysid.io.smartwheel import write_smartwheel
from ropod_sysid.platform import load_platform


@click.command("convert", short_help="Convert a log between CSV, MCAP (JSON) and MCAP (ROS 2).")
@click.argument("in_path", metavar="IN", type=LOG_INPUT)
@click.argument("out_path", metavar="OUT", type=click.Path(dir_okay=False))
@platform_option
@click.option("--encoding", type=click.Choice(["json", "ros2"]), default=None,
              help="Message encoding of an .mcap OUT (default json).")
@click.option("--layout", type=click.Choice(["contract", "smartwheel"]), default="contract",
              show_default=True,
              help="Layout of OUT: the tool's own log columns, or the smart-wheel "
                   "(sens_ROPOD_SmartWheel_t) layout using the platform's per-unit settings "
                   "(see docs/file-formats.md).")
@quiet_option
@reports_errors
@writes(outputs={"out_path": "OUT"}, inputs={"in_path": "IN", "platform_path": "--platform"})
def command(in_path: str, out_path: str, platform_path: str, encoding: str | None, layout: str,
            quiet: bool) -> None:
    """Convert log IN to OUT (.csv, .csv.gz or .mcap); the input layout is recognised by itself.
    IN may also be a ROS 1 .bag or a rosbag2 recording (a directory).

    OUT is written atomically; reading notes (dropped frames, damage) are printed.
    """
    suffix = log_format(out_path)  # .csv for .csv and .csv.gz
    if suffix == ".bag":
        raise InputError(f"{out_path}: ropod-sysid reads ROS bags but does not write them; give "
                         "a .mcap name (ROS 2 tools replay it) or .csv")
    if layout == "smartwheel" and out_path.lower().endswith(".gz"):
        raise InputError(f"{out_path}: the smart-wheel layout is written as .csv or .mcap, "
                         "not compressed; give a .csv or .mcap name")
    if encoding is not None and suffix != ".mcap":
        raise InputError(f"--encoding {encoding}: applies to .mcap output only, not {out_path}")
    platform = load_platform(platform_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the same text is in log.notes
        log = read_log(in_path, platform, gaps="allow")  # copied as is; fit checks gaps
    enc = encoding or "json"
    if layout == "smartwheel":
        write_smartwheel(log, out_path, platform, encoding=enc)
    elif suffix == ".csv":
        write_csv_log(log, out_path)
    else:
        write_mcap_log(log, out_path, encoding=enc)
    for note in log.notes:
        click.echo(f"warning: {' '.join(note.split())}", err=True)
    if not quiet:
        kind = "CSV" if suffix == ".csv" else f"MCAP ({enc})"
        click.echo(f"wrote {out_path}: {kind}, {layout} layout, {log.n_samples} samples, "
                   f"{log.duration:.3f} s", err=True)
