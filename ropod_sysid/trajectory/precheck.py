"""The pre-run check of a planned run (thesis Sec. VI-A): :func:`check`.

Limits and where they are broken, the floor, the unit angles predicted along all four variants
by every unit type (:func:`ropod_sysid.trajectory.prediction.predict_angles`): turning rates and
flags of the types that have them (the swivel: pivot rates of eq. 8a and wheel flips) and the
rate of every driven wheel, and the identifiability the run promises: the condition number and
rank of the stacked regressor A_ID,ext of the four variants and the predicted standard deviation
of every parameter (:mod:`ropod_sysid.trajectory.identifiability`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.noise import SensorNoise, predicted_fit_std, require_base_rows
from ropod_sysid.params import Parameters
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.identifiability import (
    Conditioning,
    _regressor_rows,
    _world_motion,
    conditioning,
    predicted_std,
    with_own_coordinates,
)
from ropod_sysid.trajectory.limits import DEFAULT_FLOOR, Floor, Limits, _check_floor
from ropod_sysid.trajectory.prediction import Prediction, _variant_prediction
from ropod_sysid.trajectory.run_variants import VARIANTS, variants
from ropod_sysid.trajectory.setpoints import Trajectory


@dataclass
class Finding:
    """A limit, floor or pivot finding: what, where (time range [s], variant) and how much."""

    what: str
    limit: float
    peak: float
    t_start: float
    t_end: float
    variant: str = "all"

    def text(self) -> str:
        return (f"{self.what}: {self.peak:.3g} > {self.limit:.3g} from t={self.t_start:.2f} s "
                f"to {self.t_end:.2f} s ({self.variant})")


def _runs(mask: np.ndarray, t: np.ndarray, values: np.ndarray, what: str, limit: float,
          variant: str) -> list[Finding]:
    """Contiguous runs of ``mask`` as findings (peak of ``values`` in each)."""
    out = []
    if not np.any(mask):
        return out
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        out.append(Finding(what, limit, float(np.max(values[a:b])), float(t[a]),
                           float(t[b - 1]), variant))
    return out


@dataclass
class CheckReport:
    """Everything :func:`check` found out about a planned run.

    Attributes
    ----------
    duration, samples : of the run
    limits, floor : what it was checked against
    peaks : name → maximum over the four variants of |v|, |a|, |ω|, |ω̇|, the turning rate
        (``pivot_rate``: nan without units that turn) and the wheel rate
    findings : limits broken (with time range and variant), floor left, wheel flips
    pivot_peak : (4, n) maximum turning rate |δ̇| per variant and unit [rad/s] (nan for units
        without a turning joint); pivot_peak_time (4, n) [s]
    extent : (4, 4) x_min, x_max, y_min, y_max of the planned path of each variant [m]
    names : parameter names (per-wheel or shared friction)
    conditioning : of the stacked regressor of the four variants
    true_values, std, relative_std : (p,) parameters, predicted standard deviations and
        std / |true value| for noise σ_b = ``noise`` at ``log_rate``
    wheel_peak : (4, A) maximum |φ̇| per variant and actuated joint [rad/s]; actuators : the
        actuators' current channels (``cur_1L`` …), naming them
    """

    duration: float
    samples: int
    platform: str
    units: list[str]
    limits: Limits
    floor: Floor
    peaks: dict[str, float]
    findings: list[Finding]
    pivot_peak: np.ndarray
    pivot_peak_time: np.ndarray
    extent: np.ndarray
    names: list[str]
    conditioning: Conditioning
    noise: float
    log_rate: float
    true_values: np.ndarray
    std: np.ndarray
    relative_std: np.ndarray
    friction: str = "per-wheel"
    wheel_peak: np.ndarray = field(default_factory=lambda: np.zeros((4, 0)))
    actuators: list[str] = field(default_factory=list)
    sensors: SensorNoise | None = None  # the sensor model of the std (else white σ_b = noise)
    sigma_hat: float = math.nan  # with sensors: the predicted σ̂ of the fit's weighted rows
    bias: np.ndarray = field(default_factory=lambda: np.zeros(0))  # with sensors: of q̈'s errors

    @property
    def turning(self) -> list[int]:
        """Indices of the units with a turning joint."""
        return [j for j in range(len(self.units)) if np.isfinite(self.pivot_peak[:, j]).all()]

    @property
    def condition_number(self) -> float:
        return self.conditioning.condition_number

    @property
    def rank(self) -> int:
        return self.conditioning.rank

    @property
    def ok(self) -> bool:
        """True when the run breaks no limit, stays on the floor and flips no wheel."""
        return not self.findings

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready summary."""
        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "duration": self.duration, "samples": self.samples, "platform": self.platform,
            "limits": {"v_max": self.limits.v_max, "a_max": self.limits.a_max,
                       "w_max": self.limits.w_max, "alpha_max": self.limits.alpha_max,
                       "pivot_rate_max": self.limits.pivot_rate_max,
                       "wheel_rate_max": self.limits.wheel_rate_max},
            "floor": list(self.floor),
            "peaks": {k: num(v) for k, v in self.peaks.items()},
            "ok": self.ok,
            "findings": [f.__dict__ for f in self.findings],
            "pivot_rate_max": {v: {self.units[j]: num(self.pivot_peak[i, j])
                                   for j in self.turning}
                               for i, v in enumerate(VARIANTS)},
            "wheel_rate_max": {v: {a: num(self.wheel_peak[i, j])
                                   for j, a in enumerate(self.actuators)}
                               for i, v in enumerate(VARIANTS)},
            "extent": {v: [float(e) for e in self.extent[i]] for i, v in enumerate(VARIANTS)},
            "friction": self.friction,
            "rank": self.rank, "parameters": len(self.names),
            "condition_number": num(self.condition_number),
            "condition_number_full": num(self.conditioning.condition_number_full),
            "noise": self.noise, "log_rate": self.log_rate,
            "predicted": {n: {"value": float(v), "std": num(s), "relative_std": num(r),
                              **({"bias": num(float(self.bias[j]))}
                                 if self.bias.size == len(self.names) else {})}
                          for j, (n, v, s, r) in enumerate(zip(
                              self.names, self.true_values, self.std, self.relative_std,
                              strict=True))},
            **({"sensors": self.sensors.describe(), "sigma_hat": num(self.sigma_hat)}
               if self.sensors is not None else {}),
        }

    def text(self) -> str:
        """A readable account (table) for the terminal."""
        lim = self.limits
        out = [f"run: {self.duration:.2f} s, {self.samples} setpoints; platform {self.platform} "
               f"({len(self.units)} units); variants: {', '.join(VARIANTS)}"]
        rows = [("speed |v|", "m/s", self.peaks["speed"], lim.v_max),
                ("acceleration |a|", "m/s²", self.peaks["acceleration"], lim.a_max),
                ("rotation rate |ω|", "rad/s", self.peaks["omega"], lim.w_max),
                ("rot. acceleration |ω̇|", "rad/s²", self.peaks["alpha"], lim.alpha_max)]
        if self.turning:
            rows.append(("pivot rate |δ̇| (predicted)", "rad/s", self.peaks["pivot_rate"],
                         lim.pivot_rate_max))
        rows.append(("wheel rate |φ̇| (predicted)", "rad/s", self.peaks["wheel_rate"],
                     lim.wheel_rate_max))
        out.append("")
        out.append(f"{'limit':<36}{'max':>10}{'limit':>10}  status")
        for name, unit, peak, limit in rows:
            status = "-" if limit is None else ("ok" if peak <= limit * (1 + 1e-9) else
                                                 "EXCEEDED")
            lim_s = "none" if limit is None else f"{limit:.3g}"
            out.append(f"{name + ' [' + unit + ']':<36}{peak:>10.3f}{lim_s:>10}  {status}")
        x0, x1, y0, y1 = self.floor
        ext = self.extent
        inside = not any(f.what.startswith("floor") for f in self.findings)
        out.append(f"{'floor x [' + f'{x0:g}, {x1:g}' + '] m':<36}{ext[:, 0].min():>10.2f}"
                   f"{ext[:, 1].max():>10.2f}  {'ok' if inside else 'LEFT'}")
        out.append(f"{'floor y [' + f'{y0:g}, {y1:g}' + '] m':<36}{ext[:, 2].min():>10.2f}"
                   f"{ext[:, 3].max():>10.2f}  {'ok' if inside else 'LEFT'}")
        out.append("")
        if self.turning:
            out.append("max predicted pivot rate per unit [rad/s] (trailing start, eq. 8a):")
            out.append(f"{'variant':<18}" + "".join(f"{'unit ' + self.units[j]:>12}"
                                                    for j in self.turning))
            for i, v in enumerate(VARIANTS):
                cells = [f"{self.pivot_peak[i, j]:>6.2f} @{self.pivot_peak_time[i, j]:>3.0f}s"
                         for j in self.turning]
                out.append(f"{v:<18}" + "".join(f"{c:>12}" for c in cells))
            out.append("")
        if self.actuators:
            out.append("max predicted wheel rate per motor (current channel) [rad/s]:")
            out.append(f"{'variant':<18}" + "".join(f"{a:>9}" for a in self.actuators))
            for i, v in enumerate(VARIANTS):
                out.append(f"{v:<18}" + "".join(f"{self.wheel_peak[i, j]:>9.2f}"
                                                for j in range(len(self.actuators))))
            out.append("")
        if self.findings:
            out.append(f"findings ({len(self.findings)}):")
            for f in self.findings[:40]:
                out.append(f"  - {f.text()}")
            if len(self.findings) > 40:
                out.append(f"  … and {len(self.findings) - 40} more (see --json)")
        else:
            out.append("findings: none (every limit respected, inside the floor, no wheel flip)")
        out.append("")
        c = self.conditioning
        out.append(f"stacked regressor A_ID,ext of the four variants ({self.friction} friction): "
                   f"{len(self.names)} parameters, rank {c.rank}")
        out.append(f"  condition number (column-scaled, identifiable subspace): "
                   f"{c.condition_number:.4g}")
        if c.rank < len(self.names):
            out.append(f"  condition number (all columns): inf — {len(self.names) - c.rank} "
                       "combination(s) not identifiable (e.g. symmetric unit positions: "
                       "thesis Sec. VI-C)")
        else:
            out.append(f"  condition number (all columns): {c.condition_number_full:.4g}")
        out.append("")
        if self.sensors is not None:
            out.append(f"predicted standard deviation of the fit (its white-noise σ) for "
                       f"{self.sensors.describe()}: σ̂ = {self.sigma_hat:.3g} N of the "
                       f"weighted rows, {1 / self.sensors.grid.correlation:.3g} of a row "
                       "independent:")
        else:
            out.append(f"predicted standard deviation for white noise σ_b = {self.noise:g} N / "
                       f"N m on b_ID at {self.log_rate:g} Hz:")
        has_bias = self.sensors is not None and self.bias.size == len(self.names)
        out.append(f"{'parameter':<12}{'value':>12}{'std':>12}{'rel. std':>12}"
                   + (f"{'bias':>12}{'rel. bias':>11}" if has_bias else ""))
        for j, (n, v, sd, r) in enumerate(zip(self.names, self.true_values, self.std,
                                              self.relative_std, strict=True)):
            sd_s = f"{sd:.3g}" if math.isfinite(sd) else "n/a"
            r_s = (f"{100 * r:.3g} %" if math.isfinite(r) else
                   "combined" if not math.isfinite(sd) else "value 0")
            line = f"{n:<12}{v:>12.4g}{sd_s:>12}{r_s:>12}"
            if has_bias:
                b = float(self.bias[j])
                rb = f"{100 * b / abs(v):+.3g} %" if math.isfinite(b) and v else ""
                line += (f"{b:>+12.3g}" if math.isfinite(b) else f"{'':>12}") + f"{rb:>11}"
            out.append(line)
        if has_bias:
            out.append("bias: what the encoders' quantisation does to the values through the "
                       "errors of q̈ in A_ID,ext (errors in the variables: a fit shrinks the "
                       "columns they blur); it does not average out over a longer run")
        return "\n".join(out)


def check(traj: Trajectory, platform: Platform, limits: Limits | None = None,
          floor: Sequence[float] = DEFAULT_FLOOR, noise: float = 1.0,
          params: Mapping[str, float] | None = None, friction: str = "per-wheel",
          log_rate: float = 100.0, eval_rate: float = 20.0,
          sensors: SensorNoise | None = None) -> CheckReport:
    """Check a planned run before putting the robot on the floor (thesis Sec. VI-A).

    Parameters
    ----------
    traj : the run (original variant); the other three variants are derived from it
    platform : unit types and geometry for the predicted angles and the regressor
    limits : :class:`Limits` (default the thesis's); floor : (x_min, x_max, y_min, y_max) [m]
    noise : σ_b [N, N m] of white noise on b_ID for the predicted standard deviations
    params : true parameter values (name → value) for the relative standard deviations (see
        :func:`true_parameters`); default :func:`ropod_sysid.params.thesis_fixed_masses` for a
        smart-wheel platform
    friction : ``"per-wheel"``, ``"shared"`` or ``"body"`` friction coefficients
    log_rate : sample rate [Hz] of the logs the fit will use
    eval_rate : rate [Hz] at which the regressor is evaluated (the information is scaled to
        ``log_rate``)
    sensors : a sensor model (:class:`~ropod_sysid.noise.SensorNoise`): the standard
        deviations are then those the fit will report (its white-noise σ, with σ̂ and the
        rows' correlation predicted from current noise and encoder quantisation), and
        ``noise`` and ``log_rate`` are not used

    Returns
    -------
    CheckReport
        Limits and where they are broken, floor, predicted turning rates per unit and wheel
        flips (the swivel's, eq. 8a), wheel rates per motor (all four variants), and the stacked
        regressor A_ID,ext over the four variants along the planned motion (q, q̇, q̈ in the
        world frame, unit angles as each type predicts them): its condition number and rank
        (column-scaled), and the predicted standard deviation of every parameter. Violations
        are findings, not errors.
    """
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.model.units import check_variant
    from ropod_sysid.params import parameter_names

    limits = limits or Limits()
    floor = _check_floor(floor)
    check_variant(friction)
    if not (noise > 0 and math.isfinite(noise)):
        raise InputError(f"noise must be a positive number (N, N m), got {noise!r}")
    truth = true_parameters(platform, params)
    model = PlatformModel(platform)
    var = variants(traj)
    findings: list[Finding] = []
    # limits: the same for all variants (sign changes only)
    rates = traj.twist_rates()
    speed, accel = traj.speed(), traj.acceleration()
    omega, alpha = np.abs(traj.omega), np.abs(rates[:, 2])
    checks = [("speed |v| [m/s]", speed, limits.v_max),
              ("acceleration |a| [m/s²]", accel, limits.a_max),
              ("rotation rate |ω| [rad/s]", omega, limits.w_max),
              ("rotational acceleration |ω̇| [rad/s²]", alpha, limits.alpha_max)]
    for what, values, limit in checks:
        findings += _runs(values > limit * (1 + 1e-9), traj.t, values, what, limit, "all")
    # floor, per variant (the planned path)
    extent = np.zeros((4, 4))
    for i, (name, vt) in enumerate(var.items()):
        extent[i] = [vt.x.min(), vt.x.max(), vt.y.min(), vt.y.max()]
        out_x = np.maximum(floor[0] - vt.x, vt.x - floor[1])
        out_y = np.maximum(floor[2] - vt.y, vt.y - floor[3])
        findings += _runs(out_x > 0, vt.t, out_x, "floor left in x [m beyond]", 0.0, name)
        findings += _runs(out_y > 0, vt.t, out_y, "floor left in y [m beyond]", 0.0, name)
    # unit angles (on a fine grid: the pivot ODE is stiff)
    fine, twists, pred = _variant_prediction(traj, model)
    findings += _unit_findings(platform, limits, fine.t, pred)
    prate = np.abs(pred.turning)
    pivot_peak = np.where(pred.turning_units, prate.max(axis=1), np.nan)
    pivot_peak_time = np.where(pred.turning_units, fine.t[prate.argmax(axis=1)], np.nan)
    wheel = np.abs(pred.actuator_rates)
    peaks = {"speed": float(speed.max()), "acceleration": float(accel.max()),
             "omega": float(omega.max()), "alpha": float(alpha.max()),
             "pivot_rate": pred.turning_peak, "wheel_rate": float(wheel.max())}
    # the stacked regressor along the planned motion (unit angles as predicted)
    names = parameter_names(platform, friction)  # type: ignore[arg-type]
    true_values = truth.vector(names)
    s_hat = math.nan
    bias = np.full(len(names), np.nan)
    if sensors is None:
        a, dt_eval = stacked_regressor(fine, twists, pred, model, friction, eval_rate)
        std = predicted_std(a, noise, rows_per_second=log_rate * dt_eval)
    else:
        require_base_rows(model, "the sensor model (--current-noise, --encoder-counts)")
        (a, var, gram), dt_eval = stacked_regressor(fine, twists, pred, model,  # type: ignore[misc]
                                                    friction, eval_rate, noise=(truth, sensors))
        std, bias, s_hat, _ = predicted_fit_std(a, var, true_values, sensors,
                                                sensors.rows_per_second * dt_eval, gram)
        log_rate = sensors.log_rate
    cond = conditioning(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.abs(true_values) > 0, std / np.abs(true_values), math.inf)
    findings.sort(key=lambda f: (f.t_start, f.what))
    return CheckReport(traj.duration, traj.n_samples, platform.name, platform.unit_names,
                       limits, floor, peaks, findings, pivot_peak, pivot_peak_time, extent,
                       names, cond, float(noise), float(log_rate), true_values, std, rel,
                       friction, wheel.max(axis=1), list(platform.layout.current_names),
                       sensors, s_hat, bias)


def _unit_findings(platform: Platform, limits: Limits, t: np.ndarray,
                   pred: Prediction) -> list[Finding]:
    """Per variant and unit: turning rates above their limit and flagged states (the
    swivel's pivot rate and wheel flips), and wheel rates above ``wheel_rate_max``."""
    from ropod_sysid.model.units import UNIT_TYPES

    out: list[Finding] = []
    lay = platform.layout
    for i, name in enumerate(VARIANTS):
        for j, u in enumerate(platform.units):
            label = UNIT_TYPES[u.type].turning
            if label is not None and limits.pivot_rate_max is not None:
                rate = np.abs(pred.turning[i, :, j])
                out += _runs(rate > limits.pivot_rate_max, t, rate,
                             f"{label} of unit {u.name} [rad/s]", limits.pivot_rate_max, name)
            for what, mask in pred.flags.items():
                out += _runs(mask[i, :, j], t, np.ones(t.size), f"unit {u.name} {what}", 0.0,
                             name)
        if limits.wheel_rate_max is not None:
            for k, col in enumerate(lay.current_names):
                rate = np.abs(pred.actuator_rates[i, :, k])
                out += _runs(rate > limits.wheel_rate_max * (1 + 1e-9), t, rate,
                             f"wheel rate of unit {lay.units[lay.current_unit[k]]}, motor {col} "
                             "[rad/s]", limits.wheel_rate_max, name)
    return out


def stacked_regressor(fine: Trajectory, twists: np.ndarray, pred: Prediction, model: object,
                      friction: str, eval_rate: float = 20.0,
                      noise: tuple[object, SensorNoise] | None = None) -> tuple[np.ndarray, float]:
    """A_ID,ext (4M, 3, p) of the four variants (twists (4, N, 3) on the grid of ``fine``,
    predicted angles ``pred``) at ``eval_rate`` [Hz], and the interval [s] each row stands for.
    With ``noise`` = (true parameters, sensors) A is returned with the rows' variances (4M, 3)
    and the error gram of A (:func:`ropod_sysid.noise.row_variances`,
    :func:`~ropod_sysid.noise.regressor_error_gram`)."""
    dt = float(np.median(np.diff(fine.t)))
    step = max(int(round(1.0 / (eval_rate * dt))), 1)
    idx = np.arange(0, fine.n_samples, step)
    q, qd, qdd = _world_motion(fine.t, twists)
    qd, qdd = with_own_coordinates(model, fine.t, qd, qdd, pred.rates)
    n_var, d = twists.shape[0], qd.shape[-1]
    a = _regressor_rows(model, q[:, idx].reshape(-1, 3), qd[:, idx].reshape(-1, d),
                        qdd[:, idx].reshape(-1, d),
                        pred.angles[:, idx].reshape(n_var * idx.size, -1), friction,
                        noise=noise)
    return a, step * dt  # type: ignore[return-value]


def true_parameters(platform: Platform, params: Mapping[str, float] | None) -> Parameters:
    """The true values :func:`check` divides the predicted stds by.

    ``params`` given with every inertial parameter: as given (friction not given: zero). Given
    with the base's ``m_b`` and ``Jzz_b`` only: the other parameters are each unit type's
    typical values (:func:`ropod_sysid.params.typical_parameters`). Not given: the thesis's
    fixed masses for a smart-wheel platform; for any other platform a one-line error (its
    masses are not known).
    """
    from ropod_sysid.params import (
        DynamicParameters,
        inertial_names,
        thesis_fixed_masses,
        typical_parameters,
    )

    if params is None:
        if platform.types == ["swivel"]:
            return thesis_fixed_masses(platform.unit_names)
        raise InputError(
            f"{platform.source}: no default true parameter values for a platform with "
            f"{' and '.join(platform.types)} units (the thesis's fixed masses are the ropod's); "
            "give the parameters (--params) with at least m_b and Jzz_b")
    values = dict(params)
    if (any(n not in values for n in inertial_names(platform))
            and "m_b" in values and "Jzz_b" in values):
        values = dict(typical_parameters(platform, values["m_b"], values["Jzz_b"])) | values
    return DynamicParameters.from_mapping(values, platform, "parameters")
