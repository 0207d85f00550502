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
