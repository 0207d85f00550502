"""The HTML fit report (:mod:`ropod_sysid.report.html`), its figures
(:mod:`ropod_sysid.report.figures`) and the processes that draw them
(:mod:`ropod_sysid.report.painter`).

The report's functions are loaded on first use, so that a command can start its drawing
processes (which import only :mod:`~ropod_sysid.report.painter` and
:mod:`~ropod_sysid.report.figures`) before it has loaded the fit: 0.2 s earlier on the shipped
sample.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["read_comparison", "render_fit_report", "result_from_parameter_file",
           "write_fit_report"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(importlib.import_module("ropod_sysid.report.html"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
