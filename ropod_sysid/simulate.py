"""Simulate logs with known parameters: forward dynamics (eq. 33) under a velocity controller.

The controller is model-free by default, like the robot's own low-level one: the base-twist
setpoint goes through each unit type's inverse kinematics at the *current* unit angles (for the
swivel: eqs. 8a, 11 at the current pivot angles) to actuator-rate setpoints, tracked by one PI
loop per actuator with a torque limit, updated at the integration rate (zero-order hold). With
``control=`` :class:`ropod_sysid.control.ModelControl` the centralised model-based law of
Stöger et al. (001) eq. 26 replaces those loops (:mod:`ropod_sysid.control`). The plant —
the base pose and twist and every unit angle, whose rates each type gives — is integrated with
fixed-step RK4 (default 1 kHz).

Several runs of equal or different length can be simulated together: the model is vectorised
over samples, and here the sample axis holds the runs (a batch), so four variants cost little
more than one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ropod_sysid.control import ModelControl, ModelLaw, desired_motion, generalized_desired
from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.model import PlatformModel, State
from ropod_sysid.params import DynamicParameters, Friction, friction_of
from ropod_sysid.platform import Platform
from ropod_sysid.progress import Progress


@dataclass(frozen=True)
class Setpoints:
    """Base-twist setpoints in the base frame: t [s], vx, vy [m/s], omega [rad/s]; (M,) each;
    ``planned``: setpoints of own coordinates a run plans besides, by log column (a leg's
    extension ``leg_u`` [m]; :attr:`PlatformModel.planned_columns`)."""

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    omega: np.ndarray
    planned: dict[str, np.ndarray] = field(default_factory=dict)

    def planned_at(self, t: np.ndarray | float, columns: Sequence[str]) -> np.ndarray:
        """The planned coordinates ``columns`` (…, L) at t, interpolated linearly and held
        beyond the ends; NaN for a column not planned."""
        t = np.asarray(t, float)
        out = [np.interp(t, self.t, self.planned[c]) if c in self.planned
               else np.full(t.shape, np.nan) for c in columns]
        return np.stack(out, axis=-1) if out else np.zeros((*t.shape, 0))

    def at(self, t: np.ndarray | float) -> np.ndarray:
        """Linearly interpolated setpoint (…, 3); zero outside [t0, t_end]."""
        out = np.stack([np.interp(t, self.t, v, left=0.0, right=0.0)
                        for v in (self.vx, self.vy, self.omega)], axis=-1)
        return out

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])


@dataclass(frozen=True)
class ForceSchedule:
    """External force on the base in the base frame: t [s], F_bx, F_by [N], T_bz [N m]."""

    t: np.ndarray
    f: np.ndarray  # (M, 3)

    def at(self, t: np.ndarray | float) -> np.ndarray:
        """Linearly interpolated force (…, 3); zero outside the schedule."""
        return np.stack([np.interp(t, self.t, self.f[:, j], left=0.0, right=0.0)
                         for j in range(3)], axis=-1)


@dataclass(frozen=True)
class Controller:
    """Per-wheel PI speed loops with a torque limit (no dynamic model), and PD loops on the
    angle of position-controlled actuators (a steered wheel's steering, 001 eq. 25).

    kp [N m s/rad], ki [N m/rad], torque_limit [N m]: the speed loops (001 eq. 24: D_r, P_r).
    steer_kp [N m s/rad], steer_ki [N m/rad], steer_torque_limit [N m]: D_s, P_s of the
    steering loops and their limit.
    """

    kp: float = 1.5
    ki: float = 15.0
    torque_limit: float = 4.0
    steer_kp: float = 40.0
    steer_ki: float = 800.0
    steer_torque_limit: float = 129.0

    def gains(self, position: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kp, ki, limit) per actuator (A,), ``position`` marking the position-controlled."""
        return (np.where(position, self.steer_kp, self.kp),
                np.where(position, self.steer_ki, self.ki),
                np.where(position, self.steer_torque_limit, self.torque_limit))


BAUMGARTE = 50.0  # [1/s] the simulator's pull back onto constraints it does not eliminate


@dataclass(frozen=True)
class Sensors:
    """Sensor effects of the recorded log (all off by default: an exact log).

    encoder_counts : counts per revolution of wheel and pivot encoders (None: exact angles)
    current_noise : standard deviation of the current measurement [A]
    jitter : half-width of a uniform timestamp jitter [s]
    seed : random seed
    current_average : log each current as the mean over its log interval (the control steps
        nearest the sample, :attr:`SimResult.tau_mean`: an averaging current measurement, or
        a 1 kHz bus decimated by averaging) instead of its value at the sample instant (a
        point sample, which aliases the control loops' fast torques into a slower log)
    """

    encoder_counts: int | None = None
    current_noise: float = 0.0
    jitter: float = 0.0
    seed: int = 0
    current_average: bool = False


MAX_DT = 1e-3  # the longest integration step of the simulate command [s]
MIN_ENCODER_COUNTS = 16  # fewer counts per revolution leave no motion in the angles
MAX_SEED = 2**32 - 1
ENGINES = ("auto", "numba", "numpy")  # of :func:`simulate`
# "auto" integrates runs shorter than this many steps with numpy: loading numba and the compiled
# loop costs about 0.8 s once per process, what numpy takes for about 500 steps of the ropod
MIN_COMPILED_STEPS = 500


def check_run(rate: float, dt: float, controller: Controller, sensors: Sensors) -> None:
    """The settings of :func:`simulate` make a log its readers accept: a one-line
    :class:`InputError` naming the ``simulate`` option otherwise (before any work)."""
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"--dt {dt:g}: the integration step must be a finite number > 0 s")
    top = 1.0 / dt
    if not (math.isfinite(rate) and 0 < rate <= top * (1 + 1e-9)):
        raise InputError(f"--rate {rate:g}: must be a finite number in (0, {top:g}] Hz (at "
                         "most the integration rate 1/--dt)")
    stride = top / rate
    if abs(stride - round(stride)) > 1e-9:
        ok = ", ".join(f"{top / k:g}" for k in (1, 2, 4, 5, 10))
        raise InputError(f"--rate {rate:g}: must divide the integration rate 1/--dt = {top:g} "
                         f"Hz, e.g. {ok}")
    j = sensors.jitter
    if not (math.isfinite(j) and 0 <= j < 0.5 / rate):
        raise InputError(f"--jitter {j:g}: must be a finite number in [0, {0.5 / rate:g}) s, "
                         "less than half the sample step 1/--rate (a larger one reorders the "
                         "samples)")
    n = sensors.encoder_counts
    if n is not None and not (int(n) == n and n >= MIN_ENCODER_COUNTS):
        raise InputError(f"--encoder-counts {n}: must be a whole number ≥ "
                         f"{MIN_ENCODER_COUNTS} counts per revolution (or left out for exact "
                         "angles)")
    if not (math.isfinite(sensors.current_noise) and sensors.current_noise >= 0):
        raise InputError(f"--current-noise {sensors.current_noise:g}: must be a finite number "
                         "≥ 0 A")
    if not (int(sensors.seed) == sensors.seed and 0 <= sensors.seed <= MAX_SEED):
        raise InputError(f"--seed {sensors.seed}: must be a whole number in [0, {MAX_SEED}]")
    for name, value, low in (("--kp", controller.kp, 0.0), ("--ki", controller.ki, 0.0),
                             ("--torque-limit", controller.torque_limit, None),
                             ("--steer-kp", controller.steer_kp, 0.0),
                             ("--steer-ki", controller.steer_ki, 0.0),
                             ("--steer-torque-limit", controller.steer_torque_limit, None)):
        if not (math.isfinite(value) and (value > 0 if low is None else value >= low)):
            raise InputError(f"{name} {value:g}: must be a finite number "
                             f"{'> 0' if low is None else '≥ 0'}")


@dataclass
class SimResult:
    """A simulated run: the log as the robot records it, and the truth at the log samples."""

    log: Log
    q: np.ndarray  # (N, 3) true pose
    qd: np.ndarray  # (N, 3)
    qdd: np.ndarray  # (N, 3)
    angles: np.ndarray  # (N, J) true unit angles (platform channel order)
    tau: np.ndarray  # (N, A) applied actuator torques
    f_b: np.ndarray  # (N, 3) applied external force (base frame)
    energy: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (N,) kinetic energy
    # (N, A) the torques' mean over the control steps nearest each sample (those of the log
    # interval centred on it; fewer at the ends)
    tau_mean: np.ndarray = field(default_factory=lambda: np.zeros(0))


def first_twist(setpoints: Setpoints) -> np.ndarray:
    """The first nonzero base-frame twist (vx, vy, ω) of the setpoints (zero if none)."""
    sp = np.stack([setpoints.vx, setpoints.vy, setpoints.omega], axis=-1)
    moving = np.flatnonzero(np.abs(sp).sum(axis=1) > 1e-9)
    return sp[moving[0]] if moving.size else np.zeros(3)


def initial_angles(platform: Platform, setpoints: Setpoints) -> np.ndarray:
    """Unit angles at rest that suit the first motion of the setpoints (a swivel unit trails
    it: every wheel behind its pivot); (J,)."""
    return PlatformModel(platform).initial_angles(first_twist(setpoints))


def simulate(platform: Platform, params: DynamicParameters,
             setpoints: Setpoints | Sequence[Setpoints], *, rate: float = 200.0,
             dt: float = 1e-3, controller: Controller | None = None,
             sensors: Sensors | None = None, force: ForceSchedule | None = None,
             initial: np.ndarray | str | None = "auto", quiet: bool = True,
             source: str = "<simulation>", engine: str = "auto",
             control: ModelControl | None = None) -> list[SimResult]:
    """Simulate one run per setpoint series, all integrated together.

    Parameters
    ----------
    rate : log sample rate [Hz]; ``dt`` : integration and control step [s] (≤ 1 ms).
    initial : (J,) unit angles at rest, ``"auto"`` to suit the first motion
        (:func:`initial_angles`), or None for all zero (swivel units aligned with the base x
        axis). The friction variant follows from the parameter names
        (:func:`ropod_sysid.params.friction_of`).
    engine : ``"numba"`` integrates with the compiled loop (:mod:`ropod_sysid.simulate_jit`),
        ``"numpy"`` with the vectorised model (the reference), ``"auto"`` with the compiled
        loop when numba is installed, every unit type of the platform has a kernel and the
        runs are at least :data:`MIN_COMPILED_STEPS` steps long. Both give the same results
        to round-off.
    control : None for the decentralised loops of ``controller``; a
        :class:`~ropod_sysid.control.ModelControl` for the model-based law of 001 eq. 26
        (numpy engine only), whose torques ``controller``'s limits weigh and clip.

    Returns one :class:`SimResult` per setpoint series, sampled at ``rate``.
    """
    runs = [setpoints] if isinstance(setpoints, Setpoints) else list(setpoints)
    controller = controller or Controller()
    sensors = sensors or Sensors()
    check_run(rate, dt, controller, sensors)
    if engine not in ENGINES:
        raise InputError(f"engine {engine!r}: use {', '.join(ENGINES)}")
    if control is not None:
        control.check()
        if PlatformModel(platform).planned_columns:
            raise InputError(f"{platform.source}: the model-based control law does not plan "
                             "legs; use the decentralised controllers (leave out --control "
                             "model)")
        if engine == "numba":
            raise InputError("engine 'numba': the compiled loop has the decentralised "
                             "controllers only; use engine 'numpy' (or 'auto') with the "
                             "model-based control law")
        engine = "numpy"
    params.check_physical()
    friction = friction_of(params)
    model = PlatformModel(platform)
    n_ang, n_act = platform.layout.n_angles, platform.layout.n_currents
    n_runs = len(runs)
    durations = np.array([r.duration for r in runs])
    t0 = np.array([r.t[0] for r in runs])
    steps = int(np.ceil(durations.max() / dt))
    if engine == "auto" and steps < MIN_COMPILED_STEPS:
        engine = "numpy"
    groups = compiled_groups(model, params, friction, engine)
    stride = int(round(1.0 / (rate * dt)))  # whole (check_run)

    if isinstance(initial, str):
        ang0 = np.stack([initial_angles(platform, r) for r in runs])
    elif initial is None:
        ang0 = np.zeros((n_runs, n_ang))
    else:
        ang0 = np.broadcast_to(np.asarray(initial, float), (n_runs, n_ang)).copy()
    columns = model.planned_columns  # legs: each run starts at its planned extension
    first = np.stack([r.planned_at(r.t[0], columns) for r in runs]).reshape(n_runs, -1)
    ang0[:, model.planned_angles] = np.where(np.isfinite(first), first,
                                             ang0[:, model.planned_angles])

    n_dof = model.n_dof
    q = np.zeros((n_runs, 3))
    qd = np.zeros((n_runs, n_dof))  # the base twist, then the units' own coordinates' rates
    angles = ang0
    integ = np.zeros((n_runs, n_act))

    n_rec = steps // stride + 1
    rec_q = np.empty((n_rec, n_runs, 3))
    rec_qd = np.empty_like(rec_q)
    rec_qdd = np.empty_like(rec_q)
    rec_ang = np.empty((n_rec, n_runs, n_ang))
    rec_tau = np.empty((n_rec, n_runs, n_act))
    rec_fb = np.zeros((n_rec, n_runs, 3))
    rec_e = np.empty((n_rec, n_runs))
    rec_tau_sum = np.zeros((n_rec, n_runs, n_act))  # τ summed over the steps nearest a record

    def deriv(q: np.ndarray, qd: np.ndarray, angles: np.ndarray, tau: np.ndarray,
              f_b: np.ndarray | None, st: State | None = None) -> tuple[np.ndarray, ...]:
        return derivatives(model, params, friction, q, qd, angles, tau, f_b, st)

    # setpoints and external force on the step grid, interpolated once: (steps + 1, runs, 3)
    grid = t0[None, :] + dt * np.arange(steps + 1)[:, None]
    sp_all = np.stack([r.at(grid[:, k]) for k, r in enumerate(runs)], axis=1)
    sp_rate = np.gradient(sp_all, dt, axis=0) if steps else np.zeros_like(sp_all)
    f_all = None if force is None else np.stack([force.at(grid[:, k]) for k in range(n_runs)],
                                                axis=1)

    n_keep = np.floor(durations * rate + 1e-9).astype(np.int64) + 1  # log samples per run
    records = (rec_q, rec_qd, rec_qdd, rec_ang, rec_tau, rec_fb, rec_e, rec_tau_sum)
    # planned angles of position-controlled joints (steering), on the step grid
    planned = np.stack([r.planned_at(grid[:, k], columns) for k, r in enumerate(runs)])
    plans = model.plans(grid[:, 0] - t0[0], np.swapaxes(sp_all, 0, 1), planned)
    with Progress(steps, "simulate", quiet=quiet) as bar:
        if groups is not None:
            from ropod_sysid import simulate_jit

            # the loops' gains per actuator: PD on the angle where it has an angle error
            _, angle_err = model.setpoints(q, sp_all[0], sp_rate[0], angles, plans, 0)
            position = ~np.isnan(angle_err[0])
            simulate_jit.integrate(
                groups, simulate_jit.base_parameters(model, params, friction),
                np.array([dt, 0.0]), np.stack([*controller.gains(position), position]),
                stride, steps, np.minimum((n_keep - 1) * stride, steps), sp_all,
                simulate_jit.planned(plans, steps + 1, n_runs), f_all, ang0, n_act, records,
                bar)
        else:
            kp, ki, limit = None, None, None
            law, desired = None, None
            if control is not None:
                _, angle_err = model.setpoints(q, sp_all[0], sp_rate[0], angles, plans, 0)
                law = ModelLaw(model, control, controller.gains(~np.isnan(angle_err[0]))[2])
                spacing = max(float(np.median(np.diff(r.t))) if r.t.size > 1 else 0.0
                              for r in runs)  # the setpoints' sample interval
                desired = desired_motion(model, grid[:, 0] - t0[0], sp_all, sp_rate, plans,
                                         window=spacing)
                integ = np.zeros((n_runs, n_dof))  # ε_p's base rows (R, D)
            for step in range(steps + 1):
                # controller (zero-order hold over the step)
                st = model.state(q, qd, angles)
                if law is not None and desired is not None:  # model-based (001 eq. 26)
                    qd_d, qdd_d = generalized_desired(q, desired.twist[step],
                                                      desired.twist_rate[step],
                                                      desired.coord_rate[step],
                                                      desired.coord_acc[step])
                    tau, integ = law.torques(st, qd_d, qdd_d, desired.coord[step], integ, dt)
                else:  # decentralised: IK for the current unit angles
                    want, angle_err = model.setpoints(q, sp_all[step], sp_rate[step], angles,
                                                      plans, step)
                    if kp is None:
                        kp, ki, limit = controller.gains(~np.isnan(angle_err[0]))
                    err = want - st.actuator_rate
                    # PI on the rate (the integral), or PD on the angle (its error given)
                    held = np.where(np.isnan(angle_err), integ + err * dt, angle_err)
                    tau_raw = kp * err + ki * held
                    assert limit is not None  # set with kp
                    tau = np.clip(tau_raw, -limit, limit)
                    saturated = tau != tau_raw
                    integ = np.where(saturated, integ, integ + err * dt)  # anti-windup
                f_b = None if f_all is None else f_all[step]
                near = (step + stride // 2) // stride
                if near < n_rec:
                    rec_tau_sum[near] += tau
                k1 = deriv(q, qd, angles, tau, f_b, st)
                if step % stride == 0:
                    k = step // stride
                    rec_q[k], rec_qd[k], rec_qdd[k] = q, qd[:, :3], k1[1][:, :3]
                    rec_ang[k], rec_tau[k] = angles, tau
                    if f_b is not None:
                        rec_fb[k] = f_b
                    rec_e[k] = model.kinetic_energy(st, params)
                if step == steps:
                    break
                # RK4 with τ held over the step
                # mypy: an argument after a *tuple of unknown length is one too many
                q, qd, angles = rk4_step(lambda *y, f=f_b: deriv(*y, f), (q, qd, angles), dt,  # type: ignore[call-arg]
                                         (tau, tau, tau, tau), k1)
                bar.update(1)

    rng = np.random.default_rng(sensors.seed)
    results = []
    for r in range(n_runs):
        t_true = t0[r] + np.arange(n_keep[r]) / rate
        sl = (slice(0, n_keep[r]), r)
        last = steps if groups is None else min((n_keep[r] - 1) * stride, steps)
        count = np.bincount((np.arange(last + 1) + stride // 2) // stride, minlength=n_rec)
        res = SimResult(
            log=None,  # type: ignore[arg-type]
            q=rec_q[sl].copy(), qd=rec_qd[sl].copy(), qdd=rec_qdd[sl].copy(),
            angles=rec_ang[sl].copy(), tau=rec_tau[sl].copy(),
            f_b=rec_fb[sl].copy(), energy=rec_e[sl].copy(),
            tau_mean=rec_tau_sum[sl] / count[:n_keep[r], None],
        )
        res.log = record(platform, res, t_true, sensors, rng, source)
        results.append(res)
    return results


def derivatives(model: PlatformModel, params: DynamicParameters, friction: Friction,
                q: np.ndarray, qd: np.ndarray, angles: np.ndarray, tau: np.ndarray,
                f_b: np.ndarray | None = None, st: State | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rates of the simulated state (pose q (R, 3), generalized velocity q̇ (R, D), unit
    angles (R, J)) under torques τ (R, A): (q̇ of the base, q̈ by the constrained forward
    dynamics with Baumgarte's term, the unit angles' rates)."""
    st = st if st is not None else model.state(q, qd, angles)
    qdd = model.forward_dynamics(st, params, tau, f_b, friction, stabilize=BAUMGARTE)
    return qd[:, :3], qdd, st.angle_rate


def rk4_step(deriv: Callable[..., tuple[np.ndarray, ...]], y: tuple[np.ndarray, ...],
             dt: float, taus: tuple[np.ndarray, ...], k1: tuple[np.ndarray, ...] | None = None
             ) -> tuple[np.ndarray, ...]:
    """One classical Runge–Kutta step of the state ``y`` = (q, q̇, angles) over ``dt`` [s],
    ``deriv(q, q̇, angles, τ)`` its rates, ``taus`` the torques at the four stages (at t,
    t + dt/2 twice, t + dt), ``k1`` the rates at y if known."""
    k1 = deriv(*y, taus[0]) if k1 is None else k1
    y2 = tuple(a + 0.5 * dt * b for a, b in zip(y, k1, strict=True))
    k2 = deriv(*y2, taus[1])
    y3 = tuple(a + 0.5 * dt * b for a, b in zip(y, k2, strict=True))
    k3 = deriv(*y3, taus[2])
    y4 = tuple(a + dt * b for a, b in zip(y, k3, strict=True))
    k4 = deriv(*y4, taus[3])
    return tuple(a + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
                 for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4, strict=True))


def compiled_groups(model: PlatformModel, params: DynamicParameters, friction: str,
                    engine: str) -> tuple[np.ndarray, ...] | None:
    """The unit groups as the compiled loop takes them, or None for the numpy path: with
    ``engine="numpy"``, or ``"auto"`` when numba is missing or a unit type has no kernel."""
    if engine == "numpy":
        return None
    try:
        from ropod_sysid import simulate_jit
    except ImportError:
        if engine == "numba":
            raise InputError("engine 'numba': numba is not installed; pip install numba, or "
                             "use engine 'numpy'") from None
        return None
    groups = simulate_jit.groups_of(model, params, friction)
    if groups is None and engine == "numba":
        raise InputError(f"engine 'numba': a unit type of {model.platform.source} "
                         f"({', '.join(model.platform.types)}) has no compiled kernel; use "
                         "engine 'numpy'")
    return groups


def record(platform: Platform, res: SimResult, t: np.ndarray, sensors: Sensors,
           rng: np.random.Generator, source: str) -> Log:
    """The contract log of a simulated run, with the sensor effects of ``sensors``."""
    current = (res.tau_mean if sensors.current_average else res.tau) / platform.torque_constants()
    exact = Log(t.copy(), platform.layout, np.array(res.angles), current, None, source, [])
    return sensed(exact, platform, sensors, rng)


def sensed(log: Log, platform: Platform, sensors: Sensors, rng: np.random.Generator) -> Log:
    """An exact log (true angles and currents at its sample times) as its sensors record it:
    timestamps jittered (the angles interpolated to the jittered instants), angle encoders
    quantised to ``sensors.encoder_counts`` (a leg's extension is not an angle) and current
    noise added; :attr:`Sensors.current_average` is the exact log's to apply."""
    t, angles = log.t, log.angles
    t_log = t.copy()
    if sensors.jitter > 0:
        # the sample is taken at a jittered instant; the angles are those at that instant
        jit = rng.uniform(-sensors.jitter, sensors.jitter, size=t.shape)
        jit[0] = 0.0
        t_log = t + jit
        t_log[1:] = np.maximum(t_log[1:], t_log[:-1] + 1e-6)
        angles = _interp_rows(t_log, t, angles)
    if sensors.encoder_counts:  # the angle encoders (a leg's extension is not an angle)
        step = 2 * np.pi / sensors.encoder_counts
        rad = platform.layout.encoders
        angles = np.array(angles)
        angles[:, rad] = np.round(angles[:, rad] / step) * step
    current = log.currents
    if sensors.current_noise > 0:
        current = current + rng.normal(0.0, sensors.current_noise, size=current.shape)
    return Log(t_log, platform.layout, np.array(angles), current, None, log.source, [])


def _interp_rows(t_new: np.ndarray, t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Linear interpolation of (N, …) rows at times t_new."""
    flat = y.reshape(y.shape[0], -1)
    idx = np.clip(np.searchsorted(t, t_new) - 1, 0, len(t) - 2)
    w = ((t_new - t[idx]) / (t[idx + 1] - t[idx]))[:, None]
    return ((1 - w) * flat[idx] + w * flat[idx + 1]).reshape(y.shape)
