"""Validation of a fitted model on logs it was not fitted on.

Two views: the residual of the direct equations of motion (as in the fit, per DOF), and the
thesis's disturbance observer (Sec. VII-B): F̂_b from eq. 40, low-passed at 10 Hz, compared with
the thresholds 40 N / 10 N m of Sec. VII-C. A log with no user input should stay below them.
:func:`validate_log` takes a log in memory; :func:`validate_source` and
:func:`validate_sources` read log files in chunks (:mod:`ropod_sysid.stream`).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.chunks import DEFAULT_CHUNK, Source, check_source
from ropod_sysid.io.log import Log
from ropod_sysid.lowpass import lowpass
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import DynamicParameters, friction_of, parameter_names
from ropod_sysid.platform import Platform
from ropod_sysid.regressor import Preprocessed, Span, preprocess, row_inputs, triangles

if TYPE_CHECKING:
    from ropod_sysid.stream import StreamResult

FORCE_THRESHOLD = 40.0  # N, Sec. VII-C
TORQUE_THRESHOLD = 10.0  # N m
OBSERVER_CUTOFF_HZ = 10.0  # Sec. VII-B


@dataclass
class ObserverStats:
    """Running figures of the low-passed disturbance estimate F̂_b over the kept samples."""

    sum_sq: np.ndarray = field(default_factory=lambda: np.zeros(3))
    max_abs: np.ndarray = field(default_factory=lambda: np.zeros(3))
    above_force: int = 0
    above_torque: int = 0
    count: int = 0
    t: list[np.ndarray] = field(default_factory=list)
    f_hat: list[np.ndarray] = field(default_factory=list)

    def add(self, f_hat: np.ndarray, t: np.ndarray, keep_series: bool) -> None:
        """Take the low-passed estimates ``f_hat`` (M, 3) at the kept samples' times ``t``
        (M,) [s] into the figures (and their series, with ``keep_series``)."""
        self.sum_sq += (f_hat ** 2).sum(axis=0)
        if len(f_hat):
            self.max_abs = np.maximum(self.max_abs, np.abs(f_hat).max(axis=0))
        self.above_force += int(np.count_nonzero(np.hypot(f_hat[:, 0], f_hat[:, 1])
                                                 > FORCE_THRESHOLD))
        self.above_torque += int(np.count_nonzero(np.abs(f_hat[:, 2]) > TORQUE_THRESHOLD))
        self.count += len(f_hat)
        if keep_series:
            self.t.append(t.copy())
            self.f_hat.append(f_hat.copy())


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
    f_hat = lowpass(f_b, pre.dt * step, cutoff_hz)
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


# longest integration step of the compiled free-running simulation [s]: on the shipped ropod
# (100 Hz, caster offset 1 cm) the fit % of 5 ms steps is within 0.002 points of 1 ms steps'
# (10 ms: 0.004) at a fifth of the time; RK4 stays stable while a pivot's relaxation rate
# v / s_w stays under 2.8 / step (5.5 m/s at s_w = 1 cm)
FREE_RUN_STEP = 5e-3
# platforms with constraint rows (steered wheels) step at most 2 ms, compiled or not: on the
# steered sample (true parameters, its first two logs) the fit % of v_x and ω is then within
# 0.001 points of 1 ms steps', 5 ms lose up to 0.8 points over a log's first 5 s (0.08 over 30 s)
FREE_RUN_CONSTRAINED_STEP = 2e-3
# where a unit type has no compiled kernel (wheels on legs) the numpy path takes each step in
# Python: it steps at most 2 ms, and the report's free run covers the first log's first
# FREE_RUN_NUMPY_S
FREE_RUN_NUMPY_STEP = 2e-3
FREE_RUN_NUMPY_S = 5.0
# ... for platforms of up to this many unit groups; each group costs its Python overhead per
# step (a legged unit is a group of its own), so more groups cover proportionally less
FREE_RUN_NUMPY_GROUPS = 2


def numpy_free_run_seconds(model: PlatformModel) -> float:
    """How much of the first log the report's free run covers on the numpy path [s]:
    :data:`FREE_RUN_NUMPY_S`, shortened for platforms of more than
    :data:`FREE_RUN_NUMPY_GROUPS` unit groups (four units on legs: 2.5 s)."""
    return FREE_RUN_NUMPY_S * min(1.0, FREE_RUN_NUMPY_GROUPS / max(len(model.groups), 1))


def free_run(model: PlatformModel, params: DynamicParameters, t: np.ndarray,
             q0: np.ndarray, qd0: np.ndarray, angles0: np.ndarray, tau: np.ndarray,
             max_step: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fitted model simulated forward from the measured state at t[0] under the measured
    torques alone — no controller, nothing measured after the start: pose (M, 3), generalized
    velocity (M, D) and unit angles (M, J) at the times t (M,) [s].

    q0 (3,), qd0 (D,) [world frame; then the units' own coordinates' rates], angles0 (J,) the
    start; tau (M, A) the actuator torques, linearly interpolated between the samples and held
    over each integration step at its middle. RK4 (eq. 33; with constraints their projection
    and Baumgarte's term, as the simulator) in steps of at most ``max_step`` (default
    :data:`FREE_RUN_STEP` compiled — the simulator's loop :func:`ropod_sysid.simulate_jit.run`
    with given torques, where every unit type has a kernel and t is uniform —,
    :data:`FREE_RUN_CONSTRAINED_STEP` compiled with constraint rows and
    :data:`FREE_RUN_NUMPY_STEP` on the numpy path)."""
    from ropod_sysid.simulate import derivatives, rk4_step

    t = np.asarray(t, float)
    friction = friction_of(params)
    dts = np.diff(t)
    groups = _compiled_groups(model, params, t)
    if groups is None:
        step = max_step or FREE_RUN_NUMPY_STEP
    else:
        from ropod_sysid import simulate_jit

        cons = simulate_jit.constraint_scratch(groups)  # None without constraint rows
        step = max_step or (FREE_RUN_STEP if cons is None else FREE_RUN_CONSTRAINED_STEP)
    n_sub = max(1, int(np.ceil(float(np.max(dts, initial=0.0)) / step - 1e-9)))
    # each step holds the torques interpolated at its middle (zero-order hold, as the drives)
    frac = (np.arange(n_sub) + 0.5) / n_sub
    if t.size < 2:
        return (np.asarray(q0, float)[None], np.asarray(qd0, float)[None],
                np.asarray(angles0, float)[None])
    held = (tau[:-1, None, :] * (1.0 - frac)[None, :, None]
            + tau[1:, None, :] * frac[None, :, None])  # (M − 1, n_sub, A)
    if groups is not None:
        n_steps = (t.size - 1) * n_sub
        n_act = tau.shape[1]
        x = np.concatenate([q0, qd0, angles0]).astype(float)[None]
        given = np.zeros((n_steps + 1, 1, n_act))
        given[:-1, 0] = held.reshape(-1, n_act)
        rec = (np.empty((t.size, 1, 3)), np.empty((t.size, 1, qd0.size)),
               np.empty((t.size, 1, 3)),
               np.empty((t.size, 1, angles0.size)), np.empty((t.size, 1, n_act)),
               np.zeros((t.size, 1, 3)), np.empty((t.size, 1)), np.zeros((t.size, 1, n_act)))
        with simulate_jit.first_compile(cons):
            simulate_jit.run(groups, cons, simulate_jit.base_parameters(model, params, friction),
                             np.array([dts[0] / n_sub, 1.0]), np.zeros((4, n_act)), n_sub, 0,
                             n_steps, np.array([n_steps]), np.zeros((1, 1, 3)),
                             np.zeros((1, 1, 0)), np.zeros((1, 1, 3)), False, x,
                             np.zeros((1, n_act)), *rec, given)
        return rec[0][:, 0], rec[1][:, 0], rec[3][:, 0]
    y: tuple[np.ndarray, ...] = (q0[None].astype(float), qd0[None].astype(float),
                                 angles0[None].astype(float))
    out = [y]

    def rates(q: np.ndarray, qd: np.ndarray, ang: np.ndarray, torque: np.ndarray
              ) -> tuple[np.ndarray, ...]:
        return derivatives(model, params, friction, q, qd, ang, torque)

    for i in range(t.size - 1):  # the time steps are sequential; each step is vectorised
        dt = dts[i] / n_sub
        for sub in range(n_sub):
            now = held[i, sub][None]
            y = rk4_step(rates, y, dt, (now, now, now, now))
        out.append(y)
    return tuple(np.concatenate([o[k] for o in out]) for k in range(3))  # type: ignore[return-value]


def simulated_velocity(model: PlatformModel, params: DynamicParameters, t: np.ndarray,
                       qd: np.ndarray, state: tuple[np.ndarray, ...],
                       horizon: float | None = None) -> np.ndarray:
    """The base twist (M, 3) in the base frame (v_x, v_y [m/s], ω [rad/s]) of the fitted model
    simulated forward under the measured torques (:func:`free_run`) from the measured state at
    t[0]: measured base velocity ``qd`` (M, 3, world frame) and ``state`` = (q, q̈, angles,
    angle rates, τ) at the times t (the rows'); NaN after ``horizon`` [s] from the start when
    given. In the base frame the simulation's heading error, which grows without bound in an
    open-loop run, does not turn its velocities (the dynamics do not depend on the heading)."""
    q, _, angles, rates, tau = state
    m = t.size if horizon is None else int(np.searchsorted(t, t[0] + horizon, "right"))
    own = rates[0, model.coordinate_channels] if model.n_dof > 3 else np.zeros(0)
    sim_q, sim_qd, _ = free_run(model, params, t[:m], q[0], np.concatenate([qd[0], own]),
                                angles[0], tau[:m])
    out = np.full((t.size, 3), np.nan)
    out[:m] = base_frame(sim_q[:, 2], sim_qd[:, :3])
    return out


def base_frame(theta: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """World-frame base velocities (M, 3) at headings θ (M,) as base-frame twists (M, 3)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.column_stack([c * qd[:, 0] + s * qd[:, 1], -s * qd[:, 0] + c * qd[:, 1], qd[:, 2]])


def load_free_run(platform: Platform) -> None:
    """Load what :func:`free_run` on ``platform`` needs when it is compiled (numba and the
    loop from its cache: about 0.35 s of CPU once per process) by a free run of two steps
    with unit parameters."""
    model = PlatformModel(platform)
    names = model.parameter_names("per-wheel")
    params = DynamicParameters.from_vector(np.ones(len(names)), names)
    t = np.array([0.0, 0.01])
    if _compiled_groups(model, params, t) is None:
        return
    free_run(model, params, t, np.zeros(3), np.zeros(model.n_dof),
             np.zeros(platform.layout.n_angles), np.zeros((2, platform.layout.n_currents)))


def preload_free_run(platform: Platform) -> threading.Thread:
    """:func:`load_free_run` in a thread of this process, started now: a command that will
    simulate free runs after reading logs (``fit --report``, ``report``) loads numba while
    the reading waits on numpy and Arrow, which release the interpreter (on a 10-minute
    1 kHz log, ``fit --report`` 2.9 → 2.7 s). A failure here is left to the free run itself
    to report."""

    def load() -> None:
        with contextlib.suppress(Exception):  # the free run, later, raises it where it belongs
            load_free_run(platform)

    thread = threading.Thread(target=load, name="ropod-sysid-free-run-load", daemon=True)
    thread.start()
    return thread


def _compiled_groups(model: PlatformModel, params: DynamicParameters, t: np.ndarray
                     ) -> tuple[np.ndarray, ...] | None:
    """The unit groups for the compiled loop, or None for :func:`free_run`'s numpy path: a
    unit type without a kernel, numba missing, or times ``t`` not uniform."""
    from ropod_sysid.simulate import compiled_groups

    dts = np.diff(np.asarray(t, float))
    if dts.size == 0 or not np.allclose(dts, dts[0], rtol=1e-6, atol=0.0):
        return None
    return compiled_groups(model, params, friction_of(params), "auto")


def runs_compiled(model: PlatformModel, params: DynamicParameters, t: np.ndarray) -> bool:
    """Whether :func:`free_run` at the times ``t`` takes the compiled loop (fast) rather than
    numpy steps in Python."""
    return _compiled_groups(model, params, t) is not None


def fit_percentage(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) per column (the fit of MATLAB's ``compare`` and WPILib's
    SysId): 100 is a perfect prediction, 0 no better than the mean; over the rows where the
    prediction is finite."""
    keep = np.isfinite(predicted).all(axis=1)
    measured, predicted = measured[keep], predicted[keep]
    err = np.linalg.norm(measured - predicted, axis=0)
    spread = np.linalg.norm(measured - measured.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spread > 0, 100.0 * (1.0 - err / spread), np.nan)


def validate_source(source: Source, platform: Platform, params: DynamicParameters,
                    span: Span | None = None, input_delay: float = 0.0,
                    chunk: int = DEFAULT_CHUNK, keep_series: bool = False,
                    row_step: int | None = None) -> LogValidation:
    """:func:`validate_log` of a log read in chunks. The observer series
    (``t``, ``f_hat``) are kept only with ``keep_series`` (they grow with the log)."""
    return validate_pieces(source, platform, params, span, input_delay, chunk, keep_series,
                           row_step)[0]


def validate_pieces(source: Source, platform: Platform, params: DynamicParameters,
                    span: Span | None = None, input_delay: float = 0.0,
                    chunk: int = DEFAULT_CHUNK, keep_series: bool = False,
                    row_step: int | None = None, split_gaps: bool = False,
                    ) -> list[LogValidation]:
    """:func:`validate_source` of a log, or of each of its pieces with ``split_gaps``."""
    from ropod_sysid.stream import stream_pieces  # (the stream reduces with this module's observer)

    return [_validation(res, platform, params)
            for res in stream_pieces(source, platform, span, input_delay, friction_of(params),
                                     chunk, params, keep_series, row_step=row_step,
                                     split_gaps=split_gaps)]


def _validation(res: StreamResult, platform: Platform, params: DynamicParameters,
                ) -> LogValidation:
    obs = res.observer
    assert obs is not None
    m = params.vector(parameter_names(platform, friction_of(params)))
    count = max(obs.count, 1)
    keys = ("F_bx", "F_by", "T_bz")
    t = np.concatenate(obs.t) if obs.t else np.zeros(0)
    f_hat = np.concatenate(obs.f_hat) if obs.f_hat else np.zeros((0, 3))
    return LogValidation(
        source=res.source, samples=res.triangles.samples, rms=res.triangles.rms(m),
        observer_rms={k: float(np.sqrt(obs.sum_sq[j] / count)) for j, k in enumerate(keys)},
        observer_max={k: float(obs.max_abs[j]) for j, k in enumerate(keys)},
        share_above={"force": obs.above_force / count, "torque": obs.above_torque / count},
        t=t, f_hat=f_hat)


def validate_sources(sources: list[Source], platform: Platform, params: DynamicParameters,
                     span: Span | None = None, input_delay: float = 0.0,
                     chunk: int = DEFAULT_CHUNK, workers: int | None = None,
                     dask_address: str | None = None, row_step: int | None = None,
                     quiet: bool = True, split_gaps: bool = False) -> list[LogValidation]:
    """:func:`validate_source` for each log (each of its pieces with ``split_gaps``), on Dask
    with ``workers`` or ``dask_address`` (a progress bar over the logs unless ``quiet``)."""
    from ropod_sysid.distributed import pool
    from ropod_sysid.io import check_distinct

    check_distinct([s for s in sources if not isinstance(s, Log)])
    for src in sources:
        check_source(src, platform)
    with pool(workers, dask_address, quiet=quiet) as run:
        parts = run(validate_pieces, sources, platform=platform, params=params, span=span,
                    input_delay=input_delay, chunk=chunk, row_step=row_step,
                    split_gaps=split_gaps)
    return [v for pieces in parts for v in pieces]
