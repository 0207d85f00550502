"""Entry point of ``ropod-sysid``: the command group and its commands."""

from __future__ import annotations

import importlib

import click

from ropod_sysid import __version__

# command name → module in this package that defines ``command``
COMMANDS = {
    "simulate": "simulate",
    "fit": "fit",
    "validate": "validate",
    "report": "report",
    "trajectory": "trajectory",
    "convert": "convert",
    "inspect": "inspect",
}


class LazyGroup(click.Group):
    """Imports a command's module only when that command runs (keeps ``--help`` fast)."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [name for name in COMMANDS if self._load(name) is not None]

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        return self._load(cmd_name)

    @staticmethod
    def _load(name: str) -> click.Command | None:
        module = COMMANDS.get(name)
        if module is None:
            return None
        try:
            mod = importlib.import_module(f"ropod_sysid.cli.{module}")
        except ModuleNotFoundError as exc:
            if exc.name == f"ropod_sysid.cli.{module}":
                return None
            raise
        return mod.command


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="ropod-sysid")
def main() -> None:
    """Identify the dynamic parameters of swivel-wheeled robots (ropod) from their logs."""
