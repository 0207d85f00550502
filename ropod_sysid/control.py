"""The centralised model-based control law of Stöger et al. (001) eq. 26, for the simulator.

001 writes the law with an orthonormal basis N (D × δ) of the motions the constraints allow:

    u = (NᵀB)⁺_W [NᵀM q̈_d + NᵀC q̇_d + Nᵀf + D e_v + P e_p],                        (26)
    e_v = Nᵀ(q̇_d − q̇),   e_p = ∫₀ᵗ e_v dτ,                                            (27)

with D, P (δ × δ) positive definite. Our models give the projector P_N = N Nᵀ = I − G⁺G
(:meth:`ropod_sysid.model.PlatformModel.projector`; the identity without constraints) rather
than N. Since N has full column rank, Nᵀ B u = Nᵀ Q ⟺ P_N B u = P_N Q: the same torques solve
both, and the weighted right inverse of P_N B_τ is 001's (eqs. 19–23,
:func:`ropod_sysid.model.assembly.weighted_right_inverse`). The errors become D-vectors in the
range of P_N: ε_v = P_N (q̇_d − q̇) = N e_v, ε_p = ∫ ε_v dτ (the current P_N applied once more
where it is used: the allowed motions turn with the configuration).

Gains. We take D = k_d M̃ and P = k_i M̃ with M̃ = NᵀMN, the projected mass matrix of the
*controller's* model (positive definite as 001 requires), so that the feedback is an
acceleration of the allowed motions and the bracket of (26) is the inverse dynamics at

    q̈_c = q̈_d + P_N (k_d ε_v + k_i ε_p):                                              (26')

u = :meth:`~ropod_sysid.model.PlatformModel.inverse_dynamics` (q̈_c) with W = diag(1/τ_max²).
With an exact model (and the allowed motions held fixed) the error of every allowed motion
obeys ë + k_d ė + k_i e = 0 (001's closed loop (30) with M̃ factored out): k_d [1/s] and
k_i [1/s²] are the same for every platform and every kind of row (translations, rotation,
steering angles), the model's inertias giving the forces [N], torques [N m] their units.
Defaults k_d = 40 1/s, k_i = 400 1/s²: a double pole at 20 rad/s (critically damped, time
constant 50 ms), well inside a 1 kHz control rate.

Model terms. M, the velocity products and friction are the controller's model (its parameters
may differ from the plant's), evaluated at the measured pose and velocity as in 001. Our models
give the velocity products only as the vector b_dir(q, q̇) = −C(q, q̇) q̇, not C itself: the law
uses C(q, q̇) q̇ for 001's C q̇_d; the two agree at zero tracking error. Friction is compensated
at the measured rates, and — as in :meth:`inverse_dynamics` — the distributed torque is the
total actuator torque τ + τ_f (motor plus friction), from which τ_f is then subtracted.

Desired motion. q̇_d = (R(θ) ν_d, ṡ_d): the base twist setpoint ν_d (base frame) turned into
the world frame at the measured heading θ, and the planned rates of the units' own coordinates
(the steering angles of :meth:`PlatformModel.plans`, which the decentralised steering loops
track too); q̈_d = (R(θ)(ν̇_d + ω_d S ν_d), ω̇_d, s̈_d), S the 90° turn, ν̇_d the setpoints'
rate. s̈_d is the plan's rate differenced once more, by central differences over ± the
setpoints' own sample interval: the plan is a smooth step while a wheel stands still and
follows the wheel-centre velocity (an arctangent of linearly interpolated setpoints)
otherwise, whose rate jumps at every setpoint sample; the wide difference carries each jump
as a pulse of the right area spread over the interval (over one 1 ms step it would be a pulse
that saturates the steering motors), rather than leaving it out as an analytic derivative
between the samples would.

Integral. The base rows of ε_p are integrated (from zero: the base has no desired pose, only
a velocity); a run whose torques the limits clip does not integrate them (anti-windup, as the
PI loops of :class:`ropod_sysid.simulate.Controller`). The own coordinates' planned values are
known, and the rows of P_N that belong to them are identity rows as long as no constraint
involves their rates (the steered wheels' do not involve β̇; a unit type whose constraints did
would need the integral): their integral ∫(ṡ_d − ṡ) dτ, started at the error s_d(0) − s(0),
is the error s_d − s itself, which the law takes directly — without the integration's drift
and without the anti-windup's pauses, which left a steering offset behind (measured with the
mass 30 % high on the shipped typical run, whose start clips: 1°, and a sideways velocity of
5 mm/s for the rest of the run). For the steered wheels it is the angle error of 001's
steering PD loops (eq. 25).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.model import PlatformModel, State
from ropod_sysid.model.assembly import weighted_right_inverse
from ropod_sysid.params import Friction, Parameters, friction_of

KD = 40.0  # [1/s] default k_d of (26'): D = k_d M̃
KI = 400.0  # [1/s²] default k_i of (26'): P = k_i M̃


@dataclass(frozen=True)
class ModelControl:
    """Settings of the model-based law: the controller's parameters (a fit's output, which may
    differ from the plant's) and the gains k_d [1/s], k_i [1/s²] of D = k_d M̃, P = k_i M̃."""

    params: Parameters
    kd: float = KD
    ki: float = KI

    @property
    def friction(self) -> Friction:
        return friction_of(self.params)

    def check(self) -> None:
        """One-line :class:`InputError` naming the option of a bad gain."""
        for name, value, unit in (("--model-kd", self.kd, "1/s"),
                                  ("--model-ki", self.ki, "1/s²")):
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name} {value:g}: must be a finite number ≥ 0 {unit}")


@dataclass(frozen=True)
class DesiredMotion:
    """The desired motion on the integration grid: T steps, R runs, E own coordinates.

    twist, twist_rate : (T, R, 3) base-frame twist setpoints ν_d and their rate ν̇_d
    coord, coord_rate, coord_acc : (T, R, E) planned own coordinates s_d and their rates
    """

    twist: np.ndarray
    twist_rate: np.ndarray
    coord: np.ndarray
    coord_rate: np.ndarray
    coord_acc: np.ndarray


def desired_motion(model: PlatformModel, t: np.ndarray, twist: np.ndarray,
                   twist_rate: np.ndarray,
                   plans: list[tuple[np.ndarray, ...] | None] | None = None,
                   window: float = 0.0) -> DesiredMotion:
    """The desired motion along base-frame twist setpoints (T, R, 3) and their rates at the
    step times t (T,) (uniform): the units' own coordinates from ``plans``
    (:meth:`PlatformModel.plans`, computed here when not given), their accelerations by central
    differences of the planned rates over ± ``window`` [s] (at least one step; one-sided at
    the ends). The plan follows linearly interpolated setpoints, so its rate jumps at every
    setpoint sample: differenced over one integration step each jump would become a pulse of
    height ∝ 1/dt (saturating a steering motor at 1 ms); over ± the setpoints' own sample
    interval it is spread over that interval, with the same area."""
    n_t, n_r = twist.shape[:2]
    n_e = model.n_dof - 3
    coord = np.zeros((n_t, n_r, n_e))
    rate = np.zeros_like(coord)
    if n_e:
        plans = plans if plans is not None else model.plans(t, np.swapaxes(twist, 0, 1))
        for (g, _), rows, plan in zip(model.groups, model.rows, plans, strict=True):
            own = rows[3:] - 3
            if own.size == 0:
                continue
            if plan is None:
                raise InputError(f"{model.platform.source}: unit type {g.type.type_name} has "
                                 "coordinates of its own but no planned motion; the "
                                 "model-based law needs one (use --control pid)")
            coord[:, :, own], rate[:, :, own] = plan[0], plan[1]
    acc = np.zeros_like(rate)
    if n_t > 1 and n_e:
        step = float(t[1] - t[0])
        m = max(1, int(round(window / step)))
        k = np.arange(n_t)
        hi, lo = np.minimum(k + m, n_t - 1), np.maximum(k - m, 0)
        acc = (rate[hi] - rate[lo]) / ((hi - lo) * step)[:, None, None]
    return DesiredMotion(twist, twist_rate, coord, rate, acc)


def generalized_desired(q: np.ndarray, twist: np.ndarray, twist_rate: np.ndarray,
                        coord_rate: np.ndarray, coord_acc: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """q̇_d, q̈_d (N, D) in the world-frame generalized coordinates at poses q (N, 3) for
    base-frame twists ν_d and rates ν̇_d (N, 3) and the own coordinates' rates and
    accelerations (N, E): q̇_d = (R(θ) ν_d, ω_d, ṡ_d), q̈_d = (R(θ)(ν̇_d + ω_d S ν_d), ω̇_d, s̈_d)."""
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    vx, vy, om = twist[:, 0], twist[:, 1], twist[:, 2]
    ax = twist_rate[:, 0] - om * vy  # ν̇_d + ω_d S ν_d, base frame
    ay = twist_rate[:, 1] + om * vx
    qd = np.column_stack([c * vx - s * vy, s * vx + c * vy, om, coord_rate])
    qdd = np.column_stack([c * ax - s * ay, s * ax + c * ay, twist_rate[:, 2], coord_acc])
    return qd, qdd


def velocity(model: PlatformModel, st: State) -> np.ndarray:
    """The generalized velocity q̇ (N, D) of a state: the base twist (world) and the own
    coordinates' rates."""
    return np.concatenate([st.qd, model.own_rates(st)], axis=1)


def project(proj: np.ndarray | None, v: np.ndarray) -> np.ndarray:
    """P v for P (N, D, D) and v (N, D); v itself without constraints (P = I)."""
    return v if proj is None else np.einsum("nij,nj->ni", proj, v)


class ModelLaw:
    """The law (26') for a platform model, the controller's settings and the actuators'
    torque limits τ_max (A,) [N m] (the weights W = diag(1/τ_max²) and the clipping)."""

    def __init__(self, model: PlatformModel, control: ModelControl,
                 torque_max: np.ndarray) -> None:
        control.check()
        self.model = model
        self.control = control
        self.torque_max = np.asarray(torque_max, float)
        self.friction = control.friction

    def feedback(self, st: State, qd_d: np.ndarray, coord_d: np.ndarray, integral: np.ndarray,
                 dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(P_N (k_d ε_v + k_i ε_p), the base rows' integral after the step) at state ``st``
        for the desired velocity q̇_d (N, D) and own coordinates s_d (N, E) (27)."""
        proj = self.model.projector(st)
        e_v = project(proj, qd_d - velocity(self.model, st))  # ε_v = P_N (q̇_d − q̇), (27)
        e_p = integral + e_v * dt
        e_p[:, 3:] = coord_d - st.angles[:, self.model.coordinate_channels]  # ∫ of their rows
        return project(proj, self.control.kd * e_v + self.control.ki * e_p), e_p

    def torques(self, st: State, qd_d: np.ndarray, qdd_d: np.ndarray, coord_d: np.ndarray,
                integral: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Actuator torques (N, A), clipped at τ_max, and the base rows' integral after the
        step (N, D) (held for runs whose torques were clipped; start from zeros)."""
        acc, e_p = self.feedback(st, qd_d, coord_d, integral, dt)
        tau_raw = self.model.inverse_dynamics(st, self.control.params, qdd_d + acc,
                                              friction=self.friction,
                                              torque_max=self.torque_max)  # (26'), 001 19–23
        tau = np.clip(tau_raw, -self.torque_max, self.torque_max)
        clipped = np.any(tau != tau_raw, axis=1)
        return tau, np.where(clipped[:, None], integral, e_p)


def internal_torque(model: PlatformModel, st: State, tau: np.ndarray,
                    torque_max: np.ndarray | None = None) -> np.ndarray:
    """The part of actuator torques (N, A) that moves nothing: τ less the weighted
    minimum-norm torques with the same projected generalized force P_N B_τ τ (001 eqs. 19–21),
    i.e. τ's component in the null space of P_N B_τ (the wheels pushing against each other).
    Zero for the torques of the model-based law (before clipping, with friction included:
    pass τ + τ_f); W = diag(1/τ_max²) (I without ``torque_max``)."""
    b = st.b_tau
    proj = model.projector(st)
    if proj is not None:
        b = np.einsum("nij,nja->nia", proj, b)
    return tau - weighted_right_inverse(b, np.einsum("nda,na->nd", b, tau), torque_max)
