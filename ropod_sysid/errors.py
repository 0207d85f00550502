"""Errors the command line reports as one line, with exit status 2."""

from __future__ import annotations


class InputError(Exception):
    """Bad input: a file, a row or column, and what to do about it, in one line.

    The CLI prints ``error: <message>`` and exits with status 2. Library users catch it
    like any other exception. Messages never contain a newline.
    """

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


class IdentifiabilityError(InputError):
    """The stacked regressor cannot determine anything (rank 0) or is otherwise unusable."""


def one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                     lineno: int, line: str | None = None) -> str:
    """A :func:`warnings.formatwarning` that prints a warning (e.g. a damaged MCAP file read up
    to the damage, or numpy's RuntimeWarning) as ``warning: <message>`` on one line."""
    return f"warning: {' '.join(str(message).split())}\n"
