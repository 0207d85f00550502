"""The recipe check's shift predicted for a planned run: ``trajectory check --recipe-check``.

``fit`` folds into each σ the shift Δ of its value to a second recipe (the other smoother, the
drives' lag searched; :mod:`ropod_sysid.crosscheck`), by default on logs of up to
:data:`ropod_sysid.crosscheck.AUTO_MAX_SAMPLES` samples. Δ is the difference of the two
recipes' discretisation biases — the smoothers' attenuation of fast transients, the drives'
hold — which no noise model gives: it depends on the motion and on how the drives track it.
So it is predicted the way it arises: the run's four variants are simulated without sensor
noise under the default controllers (:func:`ropod_sysid.simulate.simulate`, 1 ms steps, logged
at the fit's rate) and fitted with the check (:func:`ropod_sysid.fit.fit_logs`); the fit's
shift is the prediction, and its error against the simulated truth the recipe's own bias on
that run (what a fit of the run's logs keeps however long they are).

On noisy logs the fit's Δ also holds the two recipes' different noise (σ grows by a median
1.06–1.17× on noisy single runs, docs/accuracy.md), which this prediction leaves out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Mapping

    from ropod_sysid.params import Friction, Parameters
    from ropod_sysid.platform import Platform
    from ropod_sysid.trajectory.setpoints import Trajectory


@dataclass
class RecipeShift:
    """What the recipe check will find on a run's exact logs (each (p,), in the order of
    ``names``): ``shift`` Δ, the value's shift to the second recipe (0 where the fit leaves
    it out: fixed, or determined only in combination by one recipe); ``error``, the default
    recipe's value minus the truth (a combination's minus the truth's same combination; NaN
    for the values a combination sets to 0);
    ``reference``, the second recipe as ``fit`` flags."""

    names: list[str]
    shift: np.ndarray
    error: np.ndarray
    reference: str

    def text(self, true_values: np.ndarray, checked_std: np.ndarray, log_rate: float,
             ) -> list[str]:
        """The table ``trajectory check`` prints: each value's shift, the σ a checked fit
        reports (``checked_std``, √(σ² + Δ²)) and the default recipe's error, each also
        relative to the true value; the run's logs simulated at ``log_rate`` [Hz]."""
        from ropod_sysid.crosscheck import AUTO_MAX_SAMPLES

        out = [f"the recipe check (fit's default on logs of up to {AUTO_MAX_SAMPLES:,} samples), "
               f"predicted on the run's exact logs simulated at {log_rate:g} Hz: each "
               f"value's shift to a fit with {self.reference}, the σ a checked fit reports "
               "(√(std² + shift²)) and the default recipe's own error on those logs:",
               f"{'parameter':<12}{'shift':>12}{'rel. shift':>12}{'σ checked':>12}"
               f"{'rel. σ':>10}{'error':>12}{'rel. error':>12}"]
        for j, (n, v) in enumerate(zip(self.names, true_values, strict=True)):
            sh, sd, err = float(self.shift[j]), float(checked_std[j]), float(self.error[j])

            def rel(x: float, v: float = float(v)) -> str:
                return f"{100 * x / abs(v):+.3g} %" if math.isfinite(x) and v else ""

            out.append(f"{n:<12}{sh:>+12.3g}{rel(sh):>12}"
                       + (f"{sd:>12.3g}{rel(sd).lstrip('+'):>10}" if math.isfinite(sd)
                          else f"{'n/a':>12}{'':>10}")
                       + (f"{err:>+12.3g}{rel(err):>12}" if math.isfinite(err) else ""))
        out.append("shift and error are the recipes' discretisation biases (the smoothers' "
                   "attenuation of fast transients, the drives' 1 ms hold), which no noise "
                   "model gives and a longer run does not shrink; on noisy logs the fit's shift "
                   "also holds the recipes' different noise, and on quantised logs fitted "
                   "without --encoder-counts the two recipes' different quantisation bias")
        return out


def simulation_compiled(platform: Platform, truth: Parameters, friction: Friction) -> bool:
    """Whether the run's simulation takes the compiled loop (every unit type has a kernel and
    numba is installed); else it takes the numpy path, minutes for a minute of run."""
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.simulate import compiled_groups

    return compiled_groups(PlatformModel(platform), truth, friction, "auto") is not None


def predicted_by_default(traj: Trajectory, platform: Platform,
                         params: Mapping[str, float] | None, friction: str, log_rate: float,
                         sensors: bool) -> tuple[bool, str | None]:
    """``trajectory check``'s default for ``--recipe-check``: with a sensor model (``sensors``:
    the σ is then the one a fit reports), where ``fit`` would check the four variants' logs
    at ``log_rate`` (:data:`ropod_sysid.crosscheck.AUTO_MAX_SAMPLES`) and their simulation is
    compiled (:func:`simulation_compiled`; ``params`` as
    :func:`ropod_sysid.trajectory.precheck.true_parameters` takes them); and a note where only
    the last keeps it off."""
    from ropod_sysid.crosscheck import AUTO_MAX_SAMPLES
    from ropod_sysid.model.units import check_variant
    from ropod_sysid.trajectory.precheck import true_parameters

    if not sensors or 4 * traj.duration * log_rate > AUTO_MAX_SAMPLES:
        return False, None
    if simulation_compiled(platform, true_parameters(platform, params), check_variant(friction)):
        return True, None
    return False, ("note: the recipe check's shift, which fit folds into σ by default, is not "
                   f"predicted: the simulator has no compiled kernel for {platform.source}'s "
                   "units; --recipe-check simulates the run in numpy (minutes)")


def predicted_recipe_shift(traj: Trajectory, platform: Platform, truth: Parameters,
                           friction: Friction = "per-wheel", log_rate: float = 100.0,
                           quiet: bool = True) -> RecipeShift:
    """Simulate the four variants of ``traj`` without sensor noise at ``log_rate`` [Hz] under
    ``truth`` and fit them with the recipe check (``fit``'s default recipe and ``friction``):
    the shift it folds into σ and the default recipe's error (:class:`RecipeShift`).
    ``quiet=False``: the simulation's progress bar on a terminal."""
    from ropod_sysid.fit import FitOptions, fit_logs
    from ropod_sysid.simulate import simulate
    from ropod_sysid.trajectory.run_variants import variants

    runs = simulate(platform, truth, [v.to_setpoints() for v in variants(traj).values()],
                    rate=log_rate, quiet=quiet)
    result = fit_logs([r.log for r in runs], platform,
                      FitOptions(friction=friction, recipe_check=True))
    shown = result.shown
    names = list(shown.names)
    shift = np.array([(result.recipe_shift or {}).get(n, 0.0) for n in names])
    # a combination against the truth's same combination; those set to 0: none
    error = np.where(np.isfinite(shown.std), shown.values - shown.combination_of(
        truth.vector(names)), np.nan)
    return RecipeShift(names, shift, error, result.recipe_reference)
