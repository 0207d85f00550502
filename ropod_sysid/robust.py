"""``fit --robust``: iteratively reweighted least squares over the logs' 2 s stretches, for logs
with a few bumps or collisions (Huber's weights, then optionally Tukey's bisquare). Each
stretch's weight is a function of its RMS residual over the median stretch's."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np

from ropod_sysid.solve import Solution, gram_triangle, solve

if TYPE_CHECKING:
    from ropod_sysid.fit import FitOptions

MIN_ROBUST_STRETCHES = 6
HUBER_C = 2.0  # Huber: a stretch whose RMS residual exceeds HUBER_C × the median's counts less
BISQUARE_C = 4.685  # bisquare: a stretch beyond BISQUARE_C × the median's counts not at all
ROBUST_ITERATIONS = 50
DOWN_WEIGHTED = 0.5  # a stretch weighted below this is listed as down-weighted
Robust = Literal["none", "huber", "bisquare"]
ROBUST_METHODS: tuple[Robust, ...] = ("none", "huber", "bisquare")


def stretch_rms(values: np.ndarray, stretches: np.ndarray) -> np.ndarray:
    """The root of each stretch's residual sum of squares at ``values``: zᵀ G_k z with
    z = (m, −1) and G_k the stretch's Gram matrix of [A | b] (K,)."""
    z = np.append(values, -1.0)
    return np.sqrt(np.maximum(np.einsum("i,kij,j->k", z, stretches, z), 0.0))


def robust_scale(rms: np.ndarray) -> float:
    """The median of the stretches' positive RMS residuals (a stretch at rest has none): a
    robust scale, which a few spoiled stretches do not move."""
    positive = rms[rms > 0]
    return float(np.median(positive)) if positive.size else 1.0


def huber_weights(rms: np.ndarray, scale: float, c: float = HUBER_C) -> np.ndarray:
    """Huber's weights w_k = min(1, c·s / r_k) on the stretches' RMS residuals r_k, s the
    scale (:func:`robust_scale`): a stretch's influence is bounded by c times a typical one's."""
    return np.minimum(1.0, c * scale / np.maximum(rms, 1e-300))


def bisquare_weights(rms: np.ndarray, scale: float, c: float | None = None) -> np.ndarray:
    """Tukey's bisquare weights w_k = (1 − (r_k / c s)²)² for r_k < c s, else 0: a stretch
    far beyond the others (a collision) drops out of the fit; c = :data:`BISQUARE_C` unless
    given."""
    u = np.minimum(rms / ((BISQUARE_C if c is None else c) * scale), 1.0)
    return (1.0 - u * u) ** 2


def robust_solve(sol: Solution, stretches: np.ndarray, rows: int, names: Sequence[str],
                 options: FitOptions, correlation: float) -> Solution:
    """``--robust``: iteratively reweighted least squares over the logs' 2 s stretches
    (:data:`STRETCH_S`), the weights a function of a stretch's RMS residual over the median's.
    ``huber`` (:func:`huber_weights`) is convex: one solution, a bump's influence bounded.
    ``bisquare`` (:func:`bisquare_weights`) starts from Huber's solution and redescends: a
    collision's stretches drop out; the weight scale is held at Huber's. Each step reduces the
    weighted normal equations Σ w_k G_k to a triangle (:func:`gram_triangle`) and solves as the
    fit solves; the jackknife σ comes from the weighted stretches, the row count from the
    weights' sum. A phase ends when no weight moves by 1e-6 (at most
    :data:`ROBUST_ITERATIONS` steps); the weights are kept in ``Solution.stretch_weights``."""
    w = np.ones(len(stretches))
    phases = ["huber"] + (["bisquare"] if options.robust == "bisquare" else [])
    scale = robust_scale(stretch_rms(sol.values, stretches))
    for phase in phases:
        for _ in range(ROBUST_ITERATIONS):
            rms = stretch_rms(sol.values, stretches)
            if phase == "huber":
                scale = robust_scale(rms)
                new = huber_weights(rms, scale)
            else:
                new = bisquare_weights(rms, scale)
            if np.max(np.abs(new - w)) < 1e-6:
                break
            w = new
            weighted = w[:, None, None] * stretches
            sol = solve(gram_triangle(weighted.sum(axis=0)), max(1, round(rows * w.mean())),
                        names, options.fix, options.rcond, correlation=correlation,
                        stretches=weighted)
    sol.stretch_weights = w
    sol.std_basis += (f"; the stretches weighted by --robust {options.robust}, the weights taken "
                      "as given")
    return sol
