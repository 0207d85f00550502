"""What a parameter file says about the fit that wrote it, read back for a platform: the recipe
it was fitted with (:func:`fit_settings`: span and smoother, input delay, row step) and its
values (:func:`parameters_of`), each bad entry a one-line :class:`InputError` naming the file.
``report``, ``validate`` and ``simulate`` read a fit's file through these, without the fit's
machinery (:meth:`ropod_sysid.fit.FitResult.parameter_file` writes the file).
"""

from __future__ import annotations

import math

from ropod_sysid.errors import InputError
from ropod_sysid.io.paramfile import ParameterFile
from ropod_sysid.model.units import FRICTION_VARIANTS
from ropod_sysid.params import Friction, friction_names, friction_of, parameter_names
from ropod_sysid.platform import Platform
from ropod_sysid.recipe import Span

__all__ = ["fit_settings", "parameters_of"]


def _span_of(pfile: ParameterFile, where: str) -> Span:
    text = pfile.extras.get("span")
    smoother = pfile.extras.get("smoother", "loess")
    try:
        span = Span.parse(None if text is None else str(text).replace(" samples", "").strip())
    except InputError:
        raise InputError(f"{where}: key 'span' is {text!r}; expected e.g. '0.1s' or "
                         "'21 samples', or give --span") from None
    try:
        return span.with_smoother(str(smoother))
    except InputError:
        raise InputError(f"{where}: key 'smoother' is {smoother!r}; expected 'loess' or "
                         "'quartic'") from None


def _row_step_of(pfile: ParameterFile, where: str) -> int | None:
    step = pfile.extras.get("row_step")
    if step is None or step == "auto":
        return None
    if isinstance(step, bool) or not isinstance(step, int) or step < 1:
        raise InputError(f"{where}: key 'row_step' must be 'auto' or a positive whole number "
                         f"of samples, got {step!r}")
    return step


def _delay_of(pfile: ParameterFile, where: str) -> float:
    d = pfile.extras.get("input_delay_s")
    if d is None:
        return 0.0
    if isinstance(d, bool) or not isinstance(d, int | float) or not math.isfinite(d):
        raise InputError(f"{where}: key 'input_delay_s' must be a finite number of seconds, "
                         f"got {d!r}")
    return float(d)


def fit_settings(pfile: ParameterFile, where: str) -> tuple[Span, float, int | None]:
    """The preprocessing a parameter file was fitted with: (span, input delay [s], row step or
    None for auto), from its extras; files without them get the defaults. A bad value is a
    one-line :class:`InputError` naming ``where``."""
    return _span_of(pfile, where), _delay_of(pfile, where), _row_step_of(pfile, where)


def parameters_of(pfile: ParameterFile, platform: Platform, where: str,
                  ) -> tuple[Friction, dict[str, float]]:
    """The friction model and name → value of a fit's parameter file, for ``platform``.

    Refused with a one-line :class:`InputError` naming ``where``: a file of another platform,
    a ``friction`` other than per-wheel or shared, names that are no parameters of that model
    and these units, values that are null, NaN or infinite, and parameters of the model that
    are missing (a unit's friction left out would silently be 0).
    """
    if pfile.platform != platform.name:
        raise InputError(f"{where}: the parameter file is for platform '{pfile.platform}', the "
                         f"platform file describes '{platform.name}'; give the matching files")
    values = pfile.values()
    declared = pfile.extras.get("friction")
    if declared is not None and declared not in FRICTION_VARIANTS:
        raise InputError(f"{where}: key 'friction' is {declared!r}; use per-wheel, shared or "
                         "body")
    shared = friction_names(platform, "shared")
    friction: Friction = declared or (
        "body" if friction_of(values) == "body" else
        "shared" if any(k in values for k in shared) else "per-wheel")
    units = platform.unit_names
    names = parameter_names(platform, friction)
    unknown = [k for k in values if k not in names]
    if unknown:
        raise InputError(
            f"{where}: parameter(s) {', '.join(unknown[:6])} are not parameters of the "
            f"{friction} friction model of units {', '.join(units)}; is this the parameter file "
            "of this platform?")
    bad = [k for k, v in values.items() if not math.isfinite(v)]
    if bad:
        raise InputError(f"{where}: parameter '{bad[0]}' is null, NaN or infinite; a parameter "
                         "file gives a finite value for every parameter")
    missing = [k for k in names if k not in values]
    if missing:
        raise InputError(f"{where}: parameter(s) {', '.join(missing[:6])}"
                         f"{' …' if len(missing) > 6 else ''} missing; the {friction} friction "
                         f"model of units {', '.join(units)} needs all of {len(names)}")
    return friction, values
