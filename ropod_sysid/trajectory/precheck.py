"""The pre-run check of a planned run (thesis Sec. VI-A): :func:`check`.

Limits and where they are broken, the floor, the pivot rates predicted with eq. 8a per unit and
wheel flips (all four variants), and the identifiability the run promises: the condition number
and rank of the stacked regressor A_ID,ext of the four variants and the predicted standard
deviation of every parameter (:mod:`ropod_sysid.trajectory.identifiability`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.identifiability import (
    Conditioning,
    _regressor_rows,
    _world_motion,
    conditioning,
    predicted_std,
)
from ropod_sysid.trajectory.limits import DEFAULT_FLOOR, Floor, Limits, _check_floor
from ropod_sysid.trajectory.pivots import _variant_pivots
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
    peaks : name → maximum over the four variants of |v|, |a|, |ω|, |ω̇| and the pivot rate
    findings : limits broken (with time range and variant), floor left, wheel flips
    pivot_peak : (4, n) maximum |δ̇| per variant and unit [rad/s]; pivot_peak_time (4, n) [s]
    extent : (4, 4) x_min, x_max, y_min, y_max of the planned path of each variant [m]
    names : parameter names (per-wheel or shared friction)
    conditioning : of the stacked regressor of the four variants
    true_values, std, relative_std : (p,) parameters, predicted standard deviations and
        std / |true value| for noise σ_b = ``noise`` at ``log_rate``
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
                       "pivot_rate_max": self.limits.pivot_rate_max},
            "floor": list(self.floor),
            "peaks": {k: num(v) for k, v in self.peaks.items()},
            "ok": self.ok,
            "findings": [f.__dict__ for f in self.findings],
            "pivot_rate_max": {v: {u: num(self.pivot_peak[i, j])
                                   for j, u in enumerate(self.units)}
                               for i, v in enumerate(VARIANTS)},
            "extent": {v: [float(e) for e in self.extent[i]] for i, v in enumerate(VARIANTS)},
            "friction": self.friction,
            "rank": self.rank, "parameters": len(self.names),
            "condition_number": num(self.condition_number),
            "condition_number_full": num(self.conditioning.condition_number_full),
            "noise": self.noise, "log_rate": self.log_rate,
            "predicted": {n: {"value": float(v), "std": num(s), "relative_std": num(r)}
                          for n, v, s, r in zip(self.names, self.true_values, self.std,
                                                self.relative_std, strict=True)},
        }

    def text(self) -> str:
        """A readable account (table) for the terminal."""
        lim = self.limits
        out = [f"run: {self.duration:.2f} s, {self.samples} setpoints; platform {self.platform} "
               f"({len(self.units)} units); variants: {', '.join(VARIANTS)}"]
        rows = [("speed |v|", "m/s", self.peaks["speed"], lim.v_max),
                ("acceleration |a|", "m/s²", self.peaks["acceleration"], lim.a_max),
                ("rotation rate |ω|", "rad/s", self.peaks["omega"], lim.w_max),
                ("rot. acceleration |ω̇|", "rad/s²", self.peaks["alpha"], lim.alpha_max),
                ("pivot rate |δ̇| (predicted)", "rad/s", self.peaks["pivot_rate"],
                 lim.pivot_rate_max)]
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
        out.append("max predicted pivot rate per unit [rad/s] (trailing start, eq. 8a):")
        out.append(f"{'variant':<18}" + "".join(f"{'unit ' + u:>12}" for u in self.units))
        for i, v in enumerate(VARIANTS):
            cells = [f"{self.pivot_peak[i, j]:>6.2f} @{self.pivot_peak_time[i, j]:>3.0f}s"
                     for j in range(len(self.units))]
            out.append(f"{v:<18}" + "".join(f"{c:>12}" for c in cells))
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
                       "combination(s) not identifiable (symmetric pivots: thesis Sec. VI-C)")
        else:
            out.append(f"  condition number (all columns): {c.condition_number_full:.4g}")
        out.append("")
        out.append(f"predicted standard deviation for white noise σ_b = {self.noise:g} N / N m "
                   f"on b_ID at {self.log_rate:g} Hz:")
        out.append(f"{'parameter':<12}{'value':>12}{'std':>12}{'rel. std':>12}")
        for n, v, sd, r in zip(self.names, self.true_values, self.std, self.relative_std,
                               strict=True):
            sd_s = f"{sd:.3g}" if math.isfinite(sd) else "n/a"
            r_s = f"{100 * r:.3g} %" if math.isfinite(r) else "combined"
            out.append(f"{n:<12}{v:>12.4g}{sd_s:>12}{r_s:>12}")
        return "\n".join(out)


def check(traj: Trajectory, platform: Platform, limits: Limits | None = None,
          floor: Sequence[float] = DEFAULT_FLOOR, noise: float = 1.0,
          params: Mapping[str, float] | None = None, friction: str = "per-wheel",
          log_rate: float = 100.0, eval_rate: float = 20.0) -> CheckReport:
    """Check a planned run before putting the robot on the floor (thesis Sec. VI-A).

    Parameters
    ----------
    traj : the run (original variant); the other three variants are derived from it
    platform : geometry for the pivot rates and the regressor
    limits : :class:`Limits` (default the thesis's); floor : (x_min, x_max, y_min, y_max) [m]
    noise : σ_b [N, N m] of white noise on b_ID for the predicted standard deviations
    params : true parameter values (name → value) for the relative standard deviations; default
        :func:`ropod_sysid.params.thesis_fixed_masses`
    friction : ``"per-wheel"`` or ``"shared"`` friction coefficients
    log_rate : sample rate [Hz] of the logs the fit will use
    eval_rate : rate [Hz] at which the regressor is evaluated (the information is scaled to
        ``log_rate``)

    Returns
    -------
    CheckReport
        Limits and where they are broken, floor, predicted pivot rates per unit and wheel flips
        (all four variants), and the stacked regressor A_ID,ext over the four variants along the
        planned motion (q, q̇, q̈ in the world frame, pivots integrated with eq. 8a): its
        condition number and rank (column-scaled), and the predicted standard deviation of
        every parameter. Violations are findings, not errors.
    """
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.params import DynamicParameters, parameter_names, thesis_fixed_masses

    limits = limits or Limits()
    floor = _check_floor(floor)
    if friction not in ("per-wheel", "shared"):
        raise InputError(f"unknown friction model {friction!r}; use per-wheel or shared")
    if not (noise > 0 and math.isfinite(noise)):
        raise InputError(f"noise must be a positive number (N, N m), got {noise!r}")
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
    # pivots (on a fine grid: the pivot ODE is stiff)
    fine, twists, pred = _variant_pivots(traj, platform)
    prate = np.abs(pred.rate)
    pivot_peak = prate.max(axis=1)
    pivot_peak_time = fine.t[prate.argmax(axis=1)]
    for i, name in enumerate(VARIANTS):
        for j, u in enumerate(platform.unit_names):
            if limits.pivot_rate_max is not None:
                findings += _runs(prate[i, :, j] > limits.pivot_rate_max, fine.t, prate[i, :, j],
                                  f"pivot rate of unit {u} [rad/s]", limits.pivot_rate_max, name)
            findings += _runs(pred.pulling[i, :, j], fine.t,
                              np.ones(fine.n_samples), f"unit {u} pulling (wheel flip)", 0.0,
                              name)
    peaks = {"speed": float(speed.max()), "acceleration": float(accel.max()),
             "omega": float(omega.max()), "alpha": float(alpha.max()),
             "pivot_rate": float(prate.max())}
    # the stacked regressor along the planned motion (pivots as predicted)
    step = max(int(round(1.0 / (eval_rate * float(np.median(np.diff(fine.t)))))), 1)
    idx = np.arange(0, fine.n_samples, step)
    q, qd, qdd = _world_motion(fine.t, twists)
    n_var = len(VARIANTS)
    a = _regressor_rows(model, q[:, idx].reshape(-1, 3), qd[:, idx].reshape(-1, 3),
                        qdd[:, idx].reshape(-1, 3),
                        pred.delta[:, idx].reshape(n_var * idx.size, -1), friction)
    cond = conditioning(a)
    names = parameter_names(platform, friction)  # type: ignore[arg-type]
    if params is None:
        truth = thesis_fixed_masses(platform.unit_names)
    else:
        truth = DynamicParameters.from_mapping(params, platform, "parameters")
    true_values = truth.vector(names)
    dt_eval = step * float(np.median(np.diff(fine.t)))
    std = predicted_std(a, noise, rows_per_second=log_rate * dt_eval)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.abs(true_values) > 0, std / np.abs(true_values), math.inf)
    findings.sort(key=lambda f: (f.t_start, f.what))
    return CheckReport(traj.duration, traj.n_samples, platform.name, platform.unit_names,
                       limits, floor, peaks, findings, pivot_peak, pivot_peak_time, extent,
                       names, cond, float(noise), float(log_rate), true_values, std, rel,
                       friction)
