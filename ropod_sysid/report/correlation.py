"""The report's parameter correlation as an HTML table: a heat map whose cells carry the
names and the value (a figure's rotated tick labels cost more to draw than the rest of the
report's figures together, and cannot be searched or hovered)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

STRONG = 0.9  # |r| from which a cell writes its value: the pair trades one against the other
# the diverging scale: r = −1, 0, +1 (ColorBrewer RdBu ends and a light grey-white middle)
_ANCHORS = np.array([[33, 102, 172], [247, 247, 247], [178, 24, 43]], float)
UNDETERMINED = "#dddddd"  # fixed, or determined only in combination


def correlation(covariance: np.ndarray, p: int) -> np.ndarray:
    """cov_ij / √(cov_ii cov_jj) (p, p) in [−1, 1]; NaN where a variance is not positive or
    ``covariance`` is not (p, p) (no covariance: nothing determined)."""
    cov = np.asarray(covariance, float)
    if cov.shape != (p, p):
        return np.full((p, p), np.nan)
    var = np.diag(cov)
    d = np.sqrt(np.where(var > 0, var, np.nan))
    return np.clip(cov / np.outer(d, d), -1.0, 1.0)


def colours(r: np.ndarray) -> np.ndarray:
    """Hex colours of correlations ``r`` (any shape) on the blue–white–red scale; grey for
    NaN."""
    r = np.asarray(r, float)
    u = np.nan_to_num(r)[..., None]
    rgb = np.where(u < 0, _ANCHORS[1] + u * (_ANCHORS[1] - _ANCHORS[0]),
                   _ANCHORS[1] + u * (_ANCHORS[2] - _ANCHORS[1]))
    rgb = np.rint(rgb).astype(int)
    hexes = np.array([f"#{a:02x}{b:02x}{c:02x}" for a, b, c in rgb.reshape(-1, 3)])
    return np.where(np.isnan(r), UNDETERMINED, hexes.reshape(r.shape))


def correlation_table(names: Sequence[str], covariance: np.ndarray) -> dict[str, Any]:
    """The template's view of the correlation: ``names`` and per row its cells, each with
    its value (None: not determined), background, text colour, written value (|r| ≥
    :data:`STRONG` off the diagonal) and hover title."""
    names = list(names)
    r = correlation(covariance, len(names))
    bg = colours(r)
    rows = []
    for i, a in enumerate(names):
        cells = []
        for j, b in enumerate(names):
            v = None if np.isnan(r[i, j]) else float(r[i, j])
            strong = v is not None and i != j and abs(v) >= STRONG
            cells.append({
                "value": v, "bg": str(bg[i, j]),
                "fg": "#ffffff" if v is not None and abs(v) > 0.6 else "#222222",
                "text": f"{v:.2f}".replace("0.", ".") if strong else "",
                "title": f"{a} – {b}: " + ("not determined" if v is None else f"r = {v:+.3f}"),
            })
        rows.append({"name": a, "cells": cells})
    return {"names": names, "rows": rows, "strong": STRONG}
