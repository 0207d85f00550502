"""Validation of a fitted model on logs it was not fitted on.

Two views: the residual of the direct equations of motion (as in the fit, per DOF), and the
thesis's disturbance observer (Sec. VII-B): F̂_b from eq. 40, low-passed at 10 Hz, compared with
the thresholds 40 N / 10 N m of Sec. VII-C. A log with no user input should stay below them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ropod_sysid import signals
from ropod_sysid.io.log import Log
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import DynamicParameters, friction_of
from ropod_sysid.platform import Platform
from ropod_sysid.regressor import Preprocessed, Span, preprocess, row_inputs, triangles

FORCE_THRESHOLD = 40.0  # N, Sec. VII-C
TORQUE_THRESHOLD = 10.0  # N m
OBSERVER_CUTOFF_HZ = 10.0  # Sec. VII-B


@dataclass
class LogValidation:
    """Figures of one validation log."""

    source: str
    samples: int
    rms: dict[str, float]  # direct-EOM residual: x, y, theta, translation, rotation
    observer_rms: dict[str, float]  # low-passed F̂_b: F_bx, F_by [N], T_bz [N m]
    observer_max: dict[str, float]
    share_above: dict[str, float]  # fraction of samples above the thresholds
    t: np.ndarray = field(repr=False)
    f_hat: np.ndarray = field(repr=False)  # (M, 3) low-passed disturbance estimate

    def to_dict(self) -> dict[str, object]:
        return {"file": self.source, "samples": self.samples, "rms": self.rms,
                "observer_rms": self.observer_rms, "observer_max": self.observer_max,
                "share_above_threshold": self.share_above}


def observer_step(dt: float, row_step: int, cutoff_hz: float = OBSERVER_CUTOFF_HZ) -> int:
    """Samples between the observer's evaluations: the fit's row step, as long as that keeps
    the observer's rate at least five times its cut-off (100 Hz for a 1 kHz log)."""
    return max(1, min(int(row_step), int(1.0 / (5.0 * cutoff_hz * dt))))


def observer_samples(start: int, stop: int, step: int) -> np.ndarray:
    """The observer's sample indices in [start, stop): ⌊step/2⌋ + step·j, so that each has
    the half step of samples before it that its torque average needs."""
    h = step // 2
    first = h + step * max(0, -(-(start - h) // step))
    return np.arange(first, stop, step)


def disturbance_estimate(model: PlatformModel, pre: Preprocessed, params: DynamicParameters,
                         cutoff_hz: float = OBSERVER_CUTOFF_HZ,
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Times (M,) and F̂_b (M, 3) in the base frame: eq. 40 on the preprocessed signals, then a
    causal second-order 10 Hz low-pass as on the robot. Evaluated every
    :func:`observer_step` samples (torques averaged over the step), trimmed like the fit."""
    step = observer_step(pre.dt, pre.grid.step, cutoff_hz)
    n = len(pre.t)
    idx = observer_samples(0, n - step // 2, step)
    at = row_inputs(pre, idx, step)
    st = model.state(at.q, at.qd, at.angles, at.angle_rates)
    f_b = model.disturbance(st, params, at.qdd, at.tau, friction_of(params))
    f_hat = signals.lowpass(f_b, pre.dt * step, cutoff_hz)
    keep = (idx >= pre.trim) & (idx < n - pre.trim)
    return pre.t[idx[keep]], f_hat[keep]


def validate_log(log: Log, platform: Platform, params: DynamicParameters,
                 span: Span | None = None, input_delay: float = 0.0,
                 row_step: int | None = None) -> LogValidation:
    """Residual and observer figures of one log for given parameters (``span``,
    ``input_delay`` and ``row_step`` as the fit's)."""
    model = PlatformModel(platform)
    pre = preprocess(log, platform, span, input_delay, row_step)
    friction = friction_of(params)
    m = params.vector(model.parameter_names(friction))
    tri = triangles(model, pre, friction)
    t, f_hat = disturbance_estimate(model, pre, params)
    force = np.hypot(f_hat[:, 0], f_hat[:, 1])
    return LogValidation(
        source=log.source, samples=tri.samples, rms=tri.rms(m),
        observer_rms={k: float(np.sqrt(np.mean(f_hat[:, j] ** 2)))
                      for j, k in enumerate(("F_bx", "F_by", "T_bz"))},
        observer_max={k: float(np.max(np.abs(f_hat[:, j])))
                      for j, k in enumerate(("F_bx", "F_by", "T_bz"))},
        share_above={"force": float(np.mean(force > FORCE_THRESHOLD)),
                     "torque": float(np.mean(np.abs(f_hat[:, 2]) > TORQUE_THRESHOLD))},
        t=t, f_hat=f_hat)


def validate_logs(logs: Sequence[Log], platform: Platform, params: DynamicParameters,
                  span: Span | None = None, input_delay: float = 0.0,
                  row_step: int | None = None) -> list[LogValidation]:
    """:func:`validate_log` for each log."""
    return [validate_log(log, platform, params, span, input_delay, row_step) for log in logs]


PREDICTION_WINDOW_S = 2.0  # the predicted velocity restarts from the measured one this often


def predicted_velocity(model: PlatformModel, params: DynamicParameters, t: np.ndarray,
                       qd: np.ndarray, state: tuple[np.ndarray, ...],
                       window: float = PREDICTION_WINDOW_S) -> np.ndarray:
    """The base velocity (N, 3) the fitted model predicts under the measured torques: from
    the measured q̇ at the start of each ``window`` [s], the trapezoidal integral of the
    model's accelerations q̈ = M_dir⁻¹ (B_τ (τ + τ_f) + f_f + b_dir) (eq. 33) at the measured
    pose and unit angles. ``state`` = (q, q̈, angles, angle rates, τ) at the times ``t``."""
    q, _, angles, rates, tau = state
    st = model.state(q, qd, angles, rates)
    # the base's accelerations (with constraints: those they allow, the constraint forces
    # solved for, eqs. 33 and 001 eqs. 11–15)
    qdd = model.forward_dynamics(st, params, tau, friction=friction_of(params))[:, :3]
    steps = 0.5 * (qdd[1:] + qdd[:-1]) * np.diff(t)[:, None]
    integral = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
    seg = np.floor((t - t[0]) / window).astype(int)
    start = np.searchsorted(seg, seg)  # first row of each row's window
    return qd[start] + integral - integral[start]


def fit_percentage(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) per column (the fit of MATLAB's ``compare`` and WPILib's
    SysId): 100 is a perfect prediction, 0 no better than the mean."""
    err = np.linalg.norm(measured - predicted, axis=0)
    spread = np.linalg.norm(measured - measured.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spread > 0, 100.0 * (1.0 - err / spread), np.nan)
