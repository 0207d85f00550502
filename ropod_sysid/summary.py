"""Plain-text summaries of fits and validations for the terminal."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ropod_sysid.crosscheck import recipe_limited
from ropod_sysid.fit import FitResult
from ropod_sysid.io.paramfile import ParameterFile
from ropod_sysid.params import UNITS_OF, is_inertial, kind_of
from ropod_sysid.solve import Solution
from ropod_sysid.validate import LogValidation

MODEL_ERROR_RATIO = 2.0  # calibrated σ / white-noise σ above which model error dominates


def model_error_ratio(result: FitResult) -> float:
    """Median over the parameters of the calibrated σ over the white-noise σ
    (:attr:`ropod_sysid.solve.Solution.std_white`): about 1 when sensor noise dominates the
    residual; well above 1 when the residual is structured in time (model or discretisation
    error), which the σ covers only as far as it varies, not a bias common to the whole run."""
    sol = result.shown
    ok = np.isfinite(sol.std) & np.isfinite(sol.std_white) & (sol.std_white > 0)
    return float(np.median(sol.std[ok] / sol.std_white[ok])) if np.any(ok) else 1.0


def identifiability_verdict(result: FitResult) -> str:
    """One sentence on how well the data determine the parameters: the rank analysis, the
    calibrated σ and how much of the residual is model error (:func:`model_error_ratio`);
    never "well determined" when one of them says otherwise."""
    sol = result.solution
    free = len(sol.names) - len(sol.fixed)
    if sol.rank < free:
        return (f"rank deficient: {free - sol.rank} parameter combination(s) cannot be "
                f"separated by these logs; {int(sol.combination.sum())} values are determined "
                f"only in combination (see the null space){_loess_caveat(result)}")
    rel = relative_std(result)
    worst = int(np.nanargmax(rel)) if np.any(np.isfinite(rel)) else 0
    if sol.condition_number > 1e4 or rel[worst] > 0.2:
        return (f"full rank but weakly determined: condition number "
                f"{sol.condition_number:.3g}, worst relative std {100 * rel[worst]:.1f}% "
                f"({sol.names[worst]})")
    ratio = model_error_ratio(result)
    if ratio > MODEL_ERROR_RATIO:
        if result.recipe_shift is not None:
            return (f"full rank; the residual is mostly model or discretisation error, not "
                    f"sensor noise (σ {ratio:.2g}× the white-noise σ), and σ includes each "
                    f"value's shift to a second recipe (the recipe check), not a bias both "
                    f"share; condition number {sol.condition_number:.3g}, worst relative std "
                    f"{100 * rel[worst]:.1f}% ({sol.names[worst]})")
        return (f"full rank, but the residual is mostly model or discretisation error, not "
                f"sensor noise (σ {ratio:.2g}× the white-noise σ): values may be biased "
                f"beyond σ; condition number {sol.condition_number:.3g}, worst relative std "
                f"{100 * rel[worst]:.1f}% ({sol.names[worst]}){_bias_hint(result)}")
    return (f"well determined: full rank, condition number {sol.condition_number:.3g}, "
            f"worst relative std {100 * rel[worst]:.1f}% ({sol.names[worst]})"
            f"{_loess_caveat(result)}")


# relative σ of an inertial value below which the LOESS's discretisation bias, common to every
# log of a run and so not in σ, may lie outside 2σ: benchmarks/longlog.py's exact 60 s run at
# 1 kHz (0.1 s span) has m_b −2.2 %, m_wh −9.3 % (its σ 2.0 % and 8.7 %); ten noisy copies
# shrink σ to 1.1–2.1 % and 41–83 % of the values stay within 2σ, against 90–100 % with
# --smoother quartic --input-delay auto --encoder-counts (docs/accuracy.md, "Long logs")
LOESS_CAVEAT_STD = 0.02


def _loess_caveat(result: FitResult) -> str:
    """The caveat of a "well determined" (or rank-deficient) verdict whose σ has grown small
    enough that the LOESS's discretisation bias may exceed it (:data:`LOESS_CAVEAT_STD`),
    where the quartic smoother is an option (every log's span at least
    :data:`ropod_sysid.recipe.QUARTIC_MIN_SAMPLES` samples)."""
    o = result.options
    if result.recipe_shift is not None:  # σ holds the shift to the other recipe
        return ""
    steps = [lf.sample_time for lf in result.logs if lf.sample_time > 0]
    if not steps or not all(o.span.quartic_would_fit(dt) for dt in steps):
        return ""
    rel = relative_std(result)
    inertial = [j for j, n in enumerate(result.shown.names)
                if is_inertial(n) and np.isfinite(rel[j])]
    if not inertial or min(rel[j] for j in inertial) >= LOESS_CAVEAT_STD:
        return ""
    counts = "" if o.encoder_counts else " and --encoder-counts where the angles are quantised"
    return ("; σ this small may not cover the LOESS's discretisation bias, common to every log "
            f"of a run (m_b −2.2 % on a 1 kHz run): --smoother quartic with --input-delay "
            f"auto{counts} removes most of it, --recipe-check folds it into σ")


def _bias_hint(result: FitResult) -> str:
    """What removes most of a discretisation bias that the fit did not already remove: the
    quartic smoother's derivatives and the drives' hold or lag searched for (on noise-free
    200 Hz logs under a 1 ms hold: largest error 2.8 % → 0.3 %; docs/method.md)."""
    o = result.options
    wanted = []
    if o.span.degree == 2:
        wanted.append("--smoother quartic")
    if o.input_delay != "auto" and not o.control_period and not result.input_delay:
        wanted.append("--input-delay auto (or the drives' --control-period)")
    if not wanted:
        return "; --recipe-check folds the recipe's bias into σ"
    return (f"; on clean logs of 200 Hz or more, {' with '.join(wanted)} removes most of a "
            "discretisation bias, --recipe-check folds it into σ")


def relative_std(result: FitResult) -> np.ndarray:
    """|σ / value| of the values the fit reports (:attr:`FitResult.shown`)."""
    sol = result.shown
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(sol.std / sol.values)


def implausible(name: str, value: float) -> bool:
    """Physically implausible: negative mass or inertia."""
    return is_inertial(name) and value < 0


def difference(value: float, std: float, other: float | None
               ) -> tuple[float | None, float | None, float | None]:
    """A fitted value against a compared one: (Δ = value − other, Δ/|other|, Δ/σ), each None
    where it is undefined (no compared value, other = 0, no standard deviation)."""
    if other is None or not math.isfinite(other):
        return None, None, None
    diff = value - other
    return (diff, diff / abs(other) if other != 0 else None,
            diff / std if math.isfinite(std) and std > 0 else None)


def _comparison_cells(value: float, std: float, other: float | None) -> str:
    diff, rel, z = difference(value, std, other)
    shown = "" if other is None or not math.isfinite(other) else f"{other:.5g}"
    return (f" {shown:>12} {'' if rel is None else f'{100 * rel:+.1f}%':>8}"
            f" {'' if z is None else f'{z:+.2f}':>6}")


def compared_values(sol: Solution, other: dict[str, float]) -> dict[str, float]:
    """The compared file's values as the fit reports its own: where the logs determine a value
    only in combination (the dependent parameters set to 0, the others standing for
    name + K·dependent), the compared values moved along the fit's null space so that its
    dependent parameters are 0 too — its value of the same combination, not its raw value.
    Other names (and compared files that lack a parameter of the combination) as given."""
    out = dict(other)
    dep = [j for j, n in enumerate(sol.names) if sol.combination[j]
           and sol.combinations.get(n, "").startswith("not identifiable")]
    ns = sol.null_space
    if not dep or ns.shape[1] == 0 or not all(n in other for n in sol.names):
        return out
    x = np.array([other[n] for n in sol.names], float)
    c, *_ = np.linalg.lstsq(ns[dep], -x[dep], rcond=None)
    moved = x + ns @ c
    for j, n in enumerate(sol.names):
        if sol.combination[j]:
            out[n] = float(0.0 if j in dep else moved[j])
    return out


def format_fit(result: FitResult, compare: ParameterFile | None = None,
               compare_label: str | None = None) -> str:
    """Parameter table, RMS per translation/rotation and per log, rank and condition; with
    ``compare`` its values beside the fitted ones, the relative difference and Δ/σ."""
    sol = result.shown
    shown = sol.values
    rel = relative_std(result)
    other = compared_values(sol, compare.values()) if compare is not None else {}
    lines = []
    head = "physically consistent fit" if result.physical is not None else "fit"
    lines.append(f"{head}: {len(result.logs)} log(s), {result.samples} samples, "
                 f"friction {result.options.friction}, span {result.options.span}")
    if compare is not None:
        lines.append(f"compared with {compare_label or 'the comparison'}: Δ% = (value − "
                     "compared)/|compared|, Δ/σ = (value − compared)/std; a combination is "
                     "compared with the compared values' same combination")
    columns = (f" {'compared':>12} {'Δ%':>8} {'Δ/σ':>6}" if compare is not None else "")
    lines.append(f"{'parameter':<10} {'value':>12} {'std':>10} {'rel.std':>8}{columns}  "
                 "unit        note")
    for j, name in enumerate(sol.names):
        notes = []
        if name in sol.fixed:
            notes.append("fixed")
        if sol.at_bound.size and sol.at_bound[j]:
            notes.append(f"at its bound ({shown[j]:g}): held there, no σ")
        if sol.combination[j]:
            notes.append("combination: " + sol.combinations.get(name, ""))
        if implausible(name, shown[j]):
            notes.append("implausible (negative)")
        shift = (result.recipe_shift or {}).get(name)
        if shift is not None and recipe_limited(float(sol.std[j]), shift):
            notes.append(f"recipe-limited (shift {shift:+.3g})")
        std = "" if not np.isfinite(sol.std[j]) else f"{sol.std[j]:.4g}"
        rs = "" if not np.isfinite(rel[j]) else f"{100 * rel[j]:.1f}%"
        unit = UNITS_OF.get(kind_of(name), "")
        cells = (_comparison_cells(float(shown[j]), float(sol.std[j]), other.get(name))
                 if compare is not None else "")
        lines.append(f"{name:<10} {shown[j]:>12.5g} {std:>10} {rs:>8}{cells}  {unit:<11} "
                     + "; ".join(notes))
    missing = [k for k in other if k not in sol.names]
    if missing:
        lines.append(f"not in this fit, only in {compare_label or 'the comparison'}: "
                     + ", ".join(missing))
    lines.append(f"RMS residual: translation {result.rms['translation']:.4g} N, rotation "
                 f"{result.rms['rotation']:.4g} N m (all logs, unweighted)")
    if result.physical_rms is not None:
        lines.append(f"RMS of the physically consistent fit: translation "
                     f"{result.physical_rms['translation']:.4g} N, rotation "
                     f"{result.physical_rms['rotation']:.4g} N m")
    for lf in result.logs:
        lines.append(f"  {lf.source}: {lf.samples} samples, RMS {lf.rms['translation']:.4g} N"
                     f" / {lf.rms['rotation']:.4g} N m, rotation weight {lf.weight:.3g}")
        for note in lf.notes:
            lines.append(f"    note: {note}")
    lines.append(f"std: {sol.std_basis}")
    if result.robust_text():
        lines.append(result.robust_text())
    if result.corrections_text():
        lines.append(result.corrections_text())
    if sol.note:
        lines.append(f"note: {sol.note}")
    sol = result.solution
    free = len(sol.names) - len(sol.fixed)
    part = "" if sol.rank == free else ", of the identifiable part"
    lines.append(f"rank {sol.rank} of {free} free parameters, condition number "
                 f"{sol.condition_number:.4g} (column-scaled{part})")
    if result.input_delay:
        lines.append(f"input delay {1000 * result.input_delay:.2f} ms")
    for text in sol.null_space_text():
        lines.append(f"  not separable: {text} = 0 direction")
    lines.append(identifiability_verdict(result))
    return "\n".join(lines)


def format_validation(results: Sequence[LogValidation]) -> str:
    lines = [f"{'log':<30} {'samples':>8} {'x [N]':>8} {'y [N]':>8} {'θ [Nm]':>8} "
             f"{'F̂ rms':>8} {'T̂ rms':>8} {'>40N':>6} {'>10Nm':>6}"]
    for v in results:
        f_rms = float(np.hypot(v.observer_rms["F_bx"], v.observer_rms["F_by"]))
        lines.append(f"{v.source[-30:]:<30} {v.samples:>8} {v.rms['x']:>8.3g} "
                     f"{v.rms['y']:>8.3g} {v.rms['theta']:>8.3g} {f_rms:>8.3g} "
                     f"{v.observer_rms['T_bz']:>8.3g} {100 * v.share_above['force']:>5.1f}% "
                     f"{100 * v.share_above['torque']:>5.1f}%")
    lines.append(validation_verdict(results))
    return "\n".join(lines)


def validation_verdict(results: Sequence[LogValidation]) -> str:
    """One line: whether the disturbance observer stays below its thresholds (Sec. VII-C:
    40 N, 10 N m) on every log — the fitted model explains the motion — and where not."""
    from ropod_sysid.validate import FORCE_THRESHOLD, TORQUE_THRESHOLD

    bad = [v for v in results if v.share_above["force"] > 0 or v.share_above["torque"] > 0]
    if not bad:
        return (f"verdict    the model explains every log: the observer stays below "
                f"{FORCE_THRESHOLD:g} N and {TORQUE_THRESHOLD:g} N m throughout")
    worst = max(bad, key=lambda v: max(v.share_above["force"], v.share_above["torque"]))
    return (f"verdict    the observer exceeds its thresholds on {len(bad)} of {len(results)} "
            f"log{'s' if len(results) > 1 else ''} (worst {worst.source}: "
            f"{100 * worst.share_above['force']:.1f} % of the samples above "
            f"{FORCE_THRESHOLD:g} N, {100 * worst.share_above['torque']:.1f} % above "
            f"{TORQUE_THRESHOLD:g} N m): a collision, a push, or a model that does not fit")
