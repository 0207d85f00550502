"""The centred steered wheel: a driven wheel on an actuated steering axis through its centre.

Stöger, Müller and Gattringer, *Dynamic model-based control of redundantly actuated, non-
holonomic, omnidirectional vehicles* (JKU Linz; cited as 001): n centred orientable wheels,
each with a drive and a steering motor and no caster offset. The printed copy of 001 lost its
minus signs; every formula here is derived again below and checked by ``tests/test_steered.py``
(a hand derivation, Kane's method with finite-difference Jacobians, energy). Everything is
vectorised over samples N and the k units of the group: arrays are (N, k, …).

Geometry. Unit i has its steering axis at p_i (base frame), steering angle β_i (w.r.t. the
base x axis) and wheel radius r. With ψ_i = θ + β_i the wheel's world heading,
t_i = (cos ψ_i, sin ψ_i) its rolling direction and n_i = (−sin ψ_i, cos ψ_i) its axle, the
wheel-centre velocity is ṙ + θ̇ S R(θ) p_i (S a 90° turn), and

    rolling   r φ̇_i = t_iᵀ ṙ + c_i θ̇,   c_i = p_x sin β_i − p_y cos β_i   (001 eq. 3)   (S1)
    lateral       0 = n_iᵀ ṙ + e_i θ̇,   e_i = p_x cos β_i + p_y sin β_i   (001 eq. 4)   (S2)

(c_i and e_i are p_i × h_i and p_i · h_i with h_i = (cos β_i, sin β_i): invariant under the
base's rotation). S1 is the omni wheel's row O1 with a heading that turns, J_i =
(1/r)[cos ψ_i, sin ψ_i, c_i]; S2 is the constraint the omni wheel's rollers leave free. Time
derivatives along the motion (ψ̇ = θ̇ + β̇, ċ = β̇ e, ė = −β̇ c):

    J̇_i q̇_b = (1/r) [ψ̇_i (n_iᵀ ṙ) + β̇_i e_i θ̇]                                     (S3)
    Ġ_i q̇_b = −ψ̇_i (t_iᵀ ṙ) − β̇_i c_i θ̇,   G_i = [n_iᵀ, e_i]                        (S4)

Coordinates. The platform's generalized coordinates are q_b = (x, y, θ) followed by every
steered unit's β_i (the units' *own coordinates*): the steering angle is actuated, and the
motion of the base is not a function of the base twist alone. The wheel angles φ_i are
eliminated by S1, as for the omni wheel.

Dynamics. The unit (steering motor's rotor side, fork and wheel) turns about its axis with
inertia J_st; wheel and drive rotor spin about the axle with J_rot,s (gearing reflected). The
unit's mass moves with the base point p_i (the axis passes through the wheel centre), so it is
part of m_b; the gyroscopic moments of the spinning wheel act about horizontal axes and are
taken by the floor. Kinetic energy T_i = ½ J_st (θ̇ + β̇_i)² + ½ J_rot,s φ̇_i². By
d'Alembert's principle (Kane's method: the rolling constraint is not integrable) with the floor's
rolling reaction λ_i eliminated as for the omni wheel, the unit adds to the equations
M q̈ = B_τ (τ + τ_f) + b + G_ᵀ λ_lat in the coordinates (q_b, β):

    M_add = J_rot,s Σ J_iᵀ J_i (base block) + J_st Σ (e_θ + e_βi)(e_θ + e_βi)ᵀ          (S5)
    b_dir = −J_rot,s Σ J_iᵀ (J̇_i q̇_b)                                                  (S6)
    B_τ: drive i → [J_iᵀ; 0], steer i → e_βi   (virtual power τ_D φ̇ + τ_S β̇)           (S7)

The lateral floor forces λ_lat act through G_iᵀ on the base rows only (S2 does not contain β̇):
they are removed by projecting onto the null space of G (001 eqs. 11–15; see
:func:`ropod_sysid.model.assembly.null_projector`). The steering rows carry no constraint
force, which is 001's decoupling of the steering torques (eq. 17):

    J_st (θ̈ + β̈_i) = τ_S,i + τ_fs,i                                                    (S8)

Friction (001 Sec. 3.1, signs as for the ropod: added to the motor torque, dissipative values
≤ 0): τ_fd,i = f_dv φ̇_i + f_dc tanh(α φ̇_i) on the drive, τ_fs,i = f_sv β̇_i + f_sc tanh(α β̇_i)
on the steering axis. 001's µ_rv, µ_rc, µ_sv, µ_sc are −f_dv, −f_dc, −f_sv, −f_sc.

Identifiable combinations. The base may only turn about the instantaneous centre c where the
wheels' axles meet; for units with Σ p_i = 0 the kinetic energy is then
½ θ̇² [(m_b + n J_rot,s/r²)|c|² + J_zz,b + (J_rot,s/r²) Σ|p_i|²] + the steering terms, so the
base rows determine m_b and J_zz,b only together with J_rot,s: the fit's rank analysis finds
that combination (as for the symmetric ropod).
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ropod_sysid.model.units import (
    AnglePrediction,
    Channel,
    FrictionVariant,
    check_variant,
    integrated,
    series,
    unit_major,
)
from ropod_sysid.model.units.entry import check_keys, point, resolved, unit_name

STEER, DRIVE = 0, 1  # a unit's angle channels: steering angle, then wheel angle
HOLD_SPEED = 1e-3  # below this wheel-centre speed [m/s] a steering setpoint holds its angle
PLAN_SPEED = 0.01  # below this base speed [m/s] (ω counted at 1 m) planned steering turns smoothly
PLAN_LENGTH = 1.0  # [m]: the base speed of a twist is |(v_x, v_y, PLAN_LENGTH ω)|


def _slerp(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Unit vectors (M, 3) along the great circle from unit vector a (3,) to b (3,) at
    fractions s (M,) of the way."""
    om = float(np.arccos(np.clip(a @ b, -1.0, 1.0)))
    if om < 1e-9:
        return np.broadcast_to(a, (s.size, 3)).copy()
    return (np.sin((1.0 - s) * om)[:, None] * a + np.sin(s * om)[:, None] * b) / np.sin(om)


def planned_twist_direction(t: np.ndarray, twists: np.ndarray, slow: float = PLAN_SPEED
                            ) -> np.ndarray:
    """The direction (V, N, 3) of base-frame twists (V, N, 3) (ω scaled by
    :data:`PLAN_LENGTH`), carried across the stretches where the base is slower than ``slow``:
    there it turns along a great circle from the direction before to the one after (or its
    opposite, whichever is nearer: the same wheel axes) by a minimum-jerk step. Before the
    first motion it turns from the first nonzero twist's direction; after the last it holds.
    Every steering angle derived from one direction is consistent with one instantaneous
    centre, so units planned from it never lock the base (with three or more wheels a unit
    turned on its own would). Zero where the twists are zero throughout. Loops over the slow
    stretches only."""
    scaled = np.asarray(twists, float) * np.array([1.0, 1.0, PLAN_LENGTH])
    norm = np.linalg.norm(scaled, axis=-1)
    unit = scaled / np.where(norm > 0, norm, 1.0)[..., None]
    out = np.zeros_like(unit)
    for v in range(unit.shape[0]):
        idx = np.flatnonzero(norm[v] >= slow)
        nonzero = np.flatnonzero(norm[v] > 0)
        if idx.size == 0:  # never fast: its own direction where it has one
            idx = nonzero
        if idx.size == 0:
            continue
        d = unit[v].copy()
        first = nonzero[0] if nonzero[0] < idx[0] else idx[0]
        d[:first] = d[first]
        d[idx[-1] + 1:] = d[idx[-1]]
        # stretches to carry across: (last sample with a direction, next moving sample)
        gaps = np.flatnonzero(np.diff(idx) > 1)
        bridges = [(int(idx[g]), int(idx[g + 1])) for g in gaps]
        if first < idx[0]:
            bridges.insert(0, (int(first), int(idx[0])))
        for i0, i1 in bridges:
            a, b = d[i0], d[i1]
            if a @ b < 0:  # the opposite direction gives the same axles: turn less
                b = -b
            x = (t[i0:i1 + 1] - t[i0]) / (t[i1] - t[i0])
            # minimum-jerk step 10x³ − 15x⁴ + 6x⁵: rate and acceleration zero at both ends
            d[i0:i1 + 1] = _slerp(a, b, x**3 * (10.0 - 15.0 * x + 6.0 * x * x))
        out[v] = d
    return out


def planned_steering(t: np.ndarray, twists: np.ndarray, positions: np.ndarray,
                     slow: float = PLAN_SPEED) -> np.ndarray:
    """Steering angles (V, N, k) of units at ``positions`` (k, 2) [m] for base-frame twists
    (V, N, 3) at times t (N,): along each wheel centre's velocity for the planned twist
    direction (:func:`planned_twist_direction`), continuous modulo π (the drive reverses
    rather than the unit turning round); where a wheel centre stands still (on the
    instantaneous centre) the angle is interpolated from its neighbours; 0 for a platform
    that never moves."""
    d = planned_twist_direction(t, twists, slow)
    u_x = d[..., 0:1] - d[..., 2:3] / PLAN_LENGTH * positions[:, 1]
    u_y = d[..., 1:2] + d[..., 2:3] / PLAN_LENGTH * positions[:, 0]
    speed = np.hypot(u_x, u_y)
    raw = np.arctan2(u_y, u_x)
    out = np.zeros(raw.shape)
    for v, j in zip(*np.nonzero((speed > 1e-9).any(axis=1)), strict=True):
        idx = np.flatnonzero(speed[v, :, j] > 1e-9)
        b = 0.5 * np.unwrap(2.0 * raw[v, idx, j])
        out[v, :, j] = np.interp(np.arange(raw.shape[1]), idx, b)
    return out


@dataclass(frozen=True)
class SteeredSpec:
    """One steered unit as its platform-file entry describes it (SI units)."""

    name: str
    position: tuple[float, float]  # p_i, the steering axis in the base frame [m]
    wheel_radius: float  # r [m]
    torque_constant: float  # drive k_t [N m/A], gearing included
    steer_torque_constant: float  # steering k_t [N m/A], gearing included
    type: str = "steered"

    def moved(self, position: Sequence[float]) -> SteeredSpec:
        """The same unit attached at ``position`` [m]."""
        return replace(self, position=(float(position[0]), float(position[1])))

    def to_entry(self, defaults: Mapping[str, Any]) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "type": self.type,
                             "position": [self.position[0], self.position[1]]}
        for key in ("wheel_radius", "torque_constant", "steer_torque_constant"):
            if getattr(self, key) != defaults.get(key):
                d[key] = getattr(self, key)
        return d


@dataclass
class SteeredData:
    """Per-sample kinematics of k steered units (shapes (N, k, …))."""

    qd: np.ndarray  # (N, 3) base twist, world coordinates
    psi: np.ndarray  # (N, k) world heading θ + β
    c: np.ndarray  # (N, k) p × h (S1)
    e: np.ndarray  # (N, k) p · h (S2)
    jac: np.ndarray  # (N, k, 3) J_i = ∂φ̇_i/∂q̇_b (S1)
    jac_dot_qd: np.ndarray  # (N, k) J̇_i q̇_b (S3)
    steer_rate: np.ndarray  # (N, k) β̇
    wheel_rate: np.ndarray  # (N, k) φ̇: measured, or J_i q̇_b

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ (N, 3 + k, 2k) over the base rows and the units' β rows (S7); actuators unit by
        unit, drive then steering."""
        n, k = self.psi.shape
        out = np.zeros((n, 3 + k, k, 2))
        out[:, :3, :, 0] = np.swapaxes(self.jac, 1, 2)
        out[:, 3 + np.arange(k), np.arange(k), 1] = 1.0
        return out.reshape(n, 3 + k, 2 * k)

    @property
    def angle_rate(self) -> np.ndarray:
        return np.stack([self.steer_rate, self.wheel_rate], axis=-1).reshape(
            self.psi.shape[0], -1)

    @property
    def actuator_rate(self) -> np.ndarray:
        return np.stack([self.wheel_rate, self.steer_rate], axis=-1).reshape(
            self.psi.shape[0], -1)


class SteeredUnits:
    """k centred steered wheels of 001: the ``steered`` unit type."""

    type_name = "steered"
    angles = (Channel("steer_{u}", "steer", "rad", "steering angle w.r.t. the base x axis",
                      wrapped=True),
              Channel("phi_{u}", "phi", "rad", "wheel encoder angle, unwrapped"))
    currents = (Channel("cur_{u}D", "cur_D", "A", "drive motor current"),
                Channel("cur_{u}S", "cur_S", "A", "steering motor current"))
    coordinates = (STEER,)  # the unit's angles that are coordinates of the platform
    platform_keys = ("wheel_radius", "torque_constant", "steer_torque_constant")
    attachment_key = "position"  # the entry's attachment point (a leg replaces it)
    entry_keys = ("name", "type", "position", "wheel_radius", "torque_constant",
                  "steer_torque_constant")
    inertial_names = ("Jst", "Jrot_s")
    parameter_info = {
        "Jst": ("kg m²", "steered unit inertia about its steering axis"),
        "Jrot_s": ("kg m²", "steered wheel + drive rotor inertia about the axle"),
        "fdv": ("N m s/rad", "viscous drive friction of a steered wheel"),
        "fdc": ("N m", "Coulomb drive friction of a steered wheel"),
        "fsv": ("N m s/rad", "viscous steering friction"),
        "fsc": ("N m", "Coulomb steering friction"),
    }
    friction_signs = {"fdv": -1, "fdc": -1, "fsv": -1, "fsc": -1}  # of dissipative friction
    turning = None  # the steering is actuated: the unit does not trail its attachment point
    steering = "steering rate"  # β̇, its steering motor's rate (the steering-rate limit)
    steering_current = 1  # that motor among the unit's currents: cur_uS (no wheel)

    def __init__(self, specs: Sequence[SteeredSpec], friction_tanh_gain: float = 10.0) -> None:
        self.specs = tuple(specs)
        self.names = [s.name for s in self.specs]
        self.n_units = len(self.specs)
        self.positions = np.array([s.position for s in self.specs], float).reshape(-1, 2)
        self.r = np.array([s.wheel_radius for s in self.specs], float)
        self.k_t = np.array([(s.torque_constant, s.steer_torque_constant)
                             for s in self.specs], float).reshape(-1)
        self.alpha = float(friction_tanh_gain)

    # ------------------------------------------------------------ declaration
    @classmethod
    def parse_entry(cls, entry: Mapping[str, Any], k: int, where: str,
                    defaults: Mapping[str, float]) -> SteeredSpec:
        """Validate the platform-file entry ``units[k]`` of a steered unit; one-line errors."""
        name = unit_name(entry, k, where, '{name: "1", type: steered, position: [x, y]}')
        at = f"{where}: 'units[{k}]' (unit '{name}')"
        check_keys(entry, cls.entry_keys, at, cls.type_name)
        pos = point(entry, "position", at, "the steering axis in the base frame")
        radius = resolved(entry, "wheel_radius", at, where, defaults, True,
                          "the wheel radius in metres")
        k_d = resolved(entry, "torque_constant", at, where, defaults, True,
                       "the drive motor's k_t in N m/A")
        k_s = resolved(entry, "steer_torque_constant", at, where, defaults, True,
                       "the steering motor's k_t in N m/A")
        return SteeredSpec(name, pos, radius, k_d, k_s)

    @classmethod
    def group_key(cls, spec: SteeredSpec) -> Hashable:
        return ()  # radius and torque constants are per unit

    @classmethod
    def from_specs(cls, specs: Sequence[SteeredSpec], friction_tanh_gain: float = 10.0
                   ) -> SteeredUnits:
        return cls(specs, friction_tanh_gain)

    @classmethod
    def typical_parameters(cls, units: Sequence[str]) -> dict[str, float]:
        """The test vehicle of 001 (Table 1): J_st = C_i, J_rot,s = B_i, the friction
        coefficients µ with the contract's signs, ±10 % per unit."""
        rng = np.random.default_rng(2001)
        out = {"Jst": 0.2234, "Jrot_s": 20.5e-3}
        for u in units:
            f = 1.0 + 0.1 * (2 * rng.random(4) - 1)
            out |= {f"fdv_{u}": -0.35 * f[0], f"fdc_{u}": -0.88 * f[1],
                    f"fsv_{u}": -2.08 * f[2], f"fsc_{u}": -2.11 * f[3]}
        return out

    def torque_constants(self) -> np.ndarray:
        return self.k_t.copy()

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        """Steering angles along the first motion's wheel-centre velocities (however slow;
        0 for a wheel that does not move), wheel angles 0: the start of the planned steering
        (:meth:`predict_angles`)."""
        u_x, u_y = self.centre_velocity(twist)
        beta = np.where(np.hypot(u_x, u_y) > 0, np.arctan2(u_y, u_x), 0.0)
        return np.stack([beta, np.zeros(self.n_units)], axis=-1).reshape(-1)

    @staticmethod
    def friction_names(units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """Friction parameter names, ordered as :meth:`friction_columns`. With ``body``
        friction the drives have none; the steering axes keep theirs (per unit)."""
        if check_variant(variant) == "shared":
            return ["fdv", "fdc", "fsv", "fsc"]
        if variant == "body":
            return [n for u in units for n in (f"fsv_{u}", f"fsc_{u}")]
        return [n for u in units for n in (f"fdv_{u}", f"fdc_{u}", f"fsv_{u}", f"fsc_{u}")]

    # ------------------------------------------------------------ kinematics
    def _heading_terms(self, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """c = p × h and e = p · h (S1, S2) at steering angles β (N, k)."""
        cb, sb = np.cos(beta), np.sin(beta)
        px, py = self.positions[:, 0], self.positions[:, 1]
        return px * sb - py * cb, px * cb + py * sb

    def centre_velocity(self, twists: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The wheel centres' velocity v + ω × p_i [m/s] in the base frame for base-frame
        twists (…, 3) (or their rates: the centres' accelerations less the centripetal
        term): (u_x, u_y), each (…, k)."""
        tw = np.asarray(twists, float)
        px, py = self.positions[:, 0], self.positions[:, 1]
        return tw[..., 0:1] - tw[..., 2:3] * py, tw[..., 1:2] + tw[..., 2:3] * px

    def kinematics(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
                   angle_rates: np.ndarray | None = None,
                   coordinate_rates: np.ndarray | None = None) -> SteeredData:
        """J_i, J̇_i q̇_b (S1, S3) at base pose q and twist qd (N, 3) (world) and the unit
        angles (N, 2k); β̇ from ``coordinate_rates`` (N, k) or the measured ``angle_rates``
        (N, 2k), φ̇ measured or from S1."""
        q = np.asarray(q, float)
        qd = np.asarray(qd, float)
        ang = unit_major(angles, 2)
        beta = ang[..., STEER]
        if coordinate_rates is not None:
            steer_rate = np.asarray(coordinate_rates, float)
        elif angle_rates is not None:
            steer_rate = unit_major(angle_rates, 2)[..., STEER]
        else:
            raise ValueError("steered units need their steering rates (measured or states)")
        psi = q[:, 2:3] + beta
        cp, sp = np.cos(psi), np.sin(psi)
        c, e = self._heading_terms(beta)
        jac = np.stack([cp, sp, c], axis=-1) / self.r[:, None]
        n_dot_v = -sp * qd[:, 0:1] + cp * qd[:, 1:2]
        jdq = ((qd[:, 2:3] + steer_rate) * n_dot_v + steer_rate * e * qd[:, 2:3]) / self.r
        if angle_rates is not None and coordinate_rates is None:
            wheel_rate = unit_major(angle_rates, 2)[..., DRIVE]
        else:
            wheel_rate = np.einsum("nkc,nc->nk", jac, qd)
        return SteeredData(qd, psi, c, e, jac, jdq, steer_rate, np.asarray(wheel_rate, float))

    def constraint_jacobian(self, data: SteeredData) -> tuple[np.ndarray, np.ndarray]:
        """The lateral no-slip rows G (N, k, 3 + k) on (q̇_b, β̇) (S2) and Ġ q̇ (N, k) (S4)."""
        n, k = data.psi.shape
        cp, sp = np.cos(data.psi), np.sin(data.psi)
        g = np.zeros((n, k, 3 + k))
        g[..., 0], g[..., 1], g[..., 2] = -sp, cp, data.e
        qd = data.qd
        psi_rate = qd[:, 2:3] + data.steer_rate
        g_dot = (-psi_rate * (cp * qd[:, 0:1] + sp * qd[:, 1:2])
                 - data.steer_rate * data.c * qd[:, 2:3])
        return g, g_dot

    def steering_setpoints(self, twist: np.ndarray, twist_rate: np.ndarray, beta: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The decentralised controllers' setpoints (001 eqs. 24–25) for base-frame twists
        (N, 3) and their rates (N, 3) at the current steering angles β (N, k): the steering
        angle β_d nearest β that points the wheel along its velocity (the drive reverses
        rather than the unit turning by more than 90°), its rate β̇_d and the wheel rate φ̇_d
        (all (N, k)). Below :data:`HOLD_SPEED` the unit holds its angle."""
        u_x, u_y = self.centre_velocity(twist)
        du_x, du_y = self.centre_velocity(twist_rate)
        speed2 = u_x**2 + u_y**2
        moving = speed2 > HOLD_SPEED**2
        raw = np.arctan2(u_y, u_x)
        # nearest of raw + m π to β: the steering turns by at most 90°, the drive may reverse
        target = raw + np.pi * np.round((beta - raw) / np.pi)
        beta_d = np.where(moving, target, beta)
        beta_rate = np.where(moving, (u_x * du_y - u_y * du_x) / np.where(moving, speed2, 1.0),
                             0.0)
        wheel = (np.cos(beta_d) * u_x + np.sin(beta_d) * u_y) / self.r
        return beta_d, beta_rate, np.where(moving, wheel, 0.0)

    def controller_setpoints(self, twist: np.ndarray, twist_rate: np.ndarray,
                             angles: np.ndarray, plan: tuple[np.ndarray, np.ndarray] | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
        """Per actuator (N, 2k), drive then steering: the rate setpoints (φ̇_d, β̇_d) and the
        angle errors (NaN for the speed-controlled drive, β_d − β for the steering) of the
        decentralised controllers (001 eqs. 24–25). ``plan`` = (β_d, β̇_d) (N, k) planned
        steering (:meth:`predict_angles`), else :meth:`steering_setpoints` from the twist
        alone (which jumps where a wheel restarts in a new direction)."""
        beta = unit_major(angles, 2)[..., STEER]
        if plan is None:
            beta_d, beta_rate, wheel = self.steering_setpoints(twist, twist_rate, beta)
        else:
            beta_d, beta_rate = plan
            u_x, u_y = self.centre_velocity(twist)
            wheel = (np.cos(beta_d) * u_x + np.sin(beta_d) * u_y) / self.r
        rates = np.stack([wheel, beta_rate], axis=-1).reshape(beta.shape[0], -1)
        errors = np.stack([np.full_like(beta, np.nan), beta_d - beta], axis=-1)
        return rates, errors.reshape(beta.shape[0], -1)

    def controller_plan(self, t: np.ndarray, twists: np.ndarray,
                        prediction: AnglePrediction | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """The planned steering angles and rates (N, R, k) that :meth:`controller_setpoints`
        tracks along base-frame twists (R, N, 3) at times t (N,): :meth:`predict_angles`, or
        the given ``prediction`` of the unit angles (R, N, 2k)."""
        pred = self.predict_angles(t, twists) if prediction is None else prediction
        shape = (*pred.angles.shape[:2], self.n_units, 2)
        return (np.swapaxes(pred.angles.reshape(shape)[..., STEER], 0, 1),
                np.swapaxes(pred.rates.reshape(shape)[..., STEER], 0, 1))

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Drive rates J_i q̇_b (S1) at the current steering angles, steering rates 0 (the
        steering is position-controlled: :meth:`steering_setpoints`); (N, 2k)."""
        qd = np.asarray(qd, float)
        beta = unit_major(angles, 2)[..., STEER]
        psi = np.asarray(q, float)[:, 2:3] + beta
        c, _ = self._heading_terms(beta)
        wheel = (np.cos(psi) * qd[:, 0:1] + np.sin(psi) * qd[:, 1:2] + c * qd[:, 2:3]) / self.r
        return np.stack([wheel, np.zeros_like(wheel)], axis=-1).reshape(wheel.shape[0], -1)

    def angle_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Wheel rates from S1; the steering rates are states, not implied: 0 here."""
        rates = unit_major(self.actuator_rates(q, qd, angles), 2)
        return rates[..., ::-1].reshape(rates.shape[0], -1)

    def predict_angles(self, t: np.ndarray, twists: np.ndarray,
                       initial: np.ndarray | None = None) -> AnglePrediction:
        """The planned unit angles along base-frame twists (…, N, 3): each wheel steered along
        its wheel-centre velocity (continuous modulo π: the drive reverses rather than the
        unit turning round); while the base is slower than :data:`PLAN_SPEED` the twist's
        direction turns from its last value to its next one along a minimum-jerk step (zero
        rate and acceleration at both ends), so that the steering never jumps and every
        unit's angle suits one instantaneous centre (:func:`planned_steering`); wheel angles
        integrated from S1 at those angles.
        The simulator's steering loops track these angles (:meth:`controller_setpoints`)."""
        tw, lead = series(twists)
        n_var, n, _ = tw.shape
        k = self.n_units
        t = np.asarray(t, float)
        u_x, u_y = self.centre_velocity(tw)  # (V, N, k)
        beta = planned_steering(t, tw, self.positions)
        if initial is not None:
            start = unit_major(np.broadcast_to(np.asarray(initial, float).reshape(-1, 2 * k),
                                               (n_var, 2 * k)), 2)
            beta = beta + np.pi * np.round((start[:, None, :, STEER] - beta[:, :1]) / np.pi)
        beta_rate = np.gradient(beta, t, axis=1) if n > 1 else np.zeros_like(beta)
        wheel = (np.cos(beta) * u_x + np.sin(beta) * u_y) / self.r
        phi0 = np.zeros((n_var, k)) if initial is None else start[..., DRIVE]
        phi = integrated(t, wheel, phi0)
        angles = np.stack([beta, phi], axis=-1).reshape(n_var, n, 2 * k)
        rates = np.stack([beta_rate, wheel], axis=-1).reshape(n_var, n, 2 * k)
        actuator = np.stack([wheel, beta_rate], axis=-1).reshape(n_var, n, 2 * k)
        return AnglePrediction(angles.reshape(*lead, n, -1), rates.reshape(*lead, n, -1),
                               actuator.reshape(*lead, n, -1))

    def quasi_steady_angles(self, t: np.ndarray, twists: np.ndarray,
                            twist_rates: np.ndarray) -> AnglePrediction:
        """The steering follows its setpoint: :meth:`predict_angles`."""
        return self.predict_angles(t, twists)

    def constraint_rows(self, angles: np.ndarray, rates: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Odometry rows A (N, 2k, 3), b (N, 2k) with A ν = b in the base-frame twist
        ν = (v, v_n, ω): per unit the rolling row S1 (r φ̇ = h·v + c ω) and the lateral row S2
        (0 = h⊥·v + e ω). ``rates`` may be increments."""
        ang = unit_major(angles, 2)
        beta = ang[..., STEER]
        wheel = unit_major(rates, 2)[..., DRIVE]
        cb, sb = np.cos(beta), np.sin(beta)
        c, e = self._heading_terms(beta)
        a = np.stack([np.stack([cb, sb, c], axis=-1), np.stack([-sb, cb, e], axis=-1)],
                     axis=2)  # (N, k, 2, 3)
        b = np.stack([wheel * self.r, np.zeros_like(wheel)], axis=-1)
        return a.reshape(a.shape[0], -1, 3), b.reshape(b.shape[0], -1)

    def normal_equations(self, angles: np.ndarray, increments: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """AᵀA (N, 3, 3) and Aᵀb (N, 3) of :meth:`constraint_rows`."""
        a, b = self.constraint_rows(angles, increments)
        return np.einsum("nrc,nrd->ncd", a, a), np.einsum("nrc,nr->nc", a, b)

    # ------------------------------------------------------------ dynamics
    def mass_terms(self, data: SteeredData,
                   params: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(M_add (N, 3 + k, 3 + k), b_dir (N, 3 + k)) of the group (S5, S6)."""
        n, k = data.psi.shape
        j_rot, j_st = float(params["Jrot_s"]), float(params["Jst"])
        m = np.zeros((n, 3 + k, 3 + k))
        m[:, :3, :3] = j_rot * np.einsum("nkc,nkd->ncd", data.jac, data.jac)
        m[:, 2, 2] += k * j_st
        idx = 3 + np.arange(k)
        m[:, 2, idx] = m[:, idx, 2] = j_st
        m[:, idx, idx] = j_st
        b = np.zeros((n, 3 + k))
        b[:, :3] = -j_rot * np.einsum("nkc,nk->nc", data.jac, data.jac_dot_qd)
        return m, b

    def a_id(self, data: SteeredData, qdd: np.ndarray) -> np.ndarray:
        """Columns of A_ID for (J_st, J_rot,s) at accelerations q̈ = (q̈_b, β̈) (N, 3 + k):
        the coefficients of each in M_add q̈ − b_dir (S5, S6); shape (N, 3 + k, 2)."""
        n, k = data.psi.shape
        out = np.zeros((n, 3 + k, 2))
        turn = qdd[:, 2:3] + qdd[:, 3:]  # θ̈ + β̈_i
        out[:, 2, 0] = turn.sum(axis=1)
        out[:, 3:, 0] = turn
        wheel_acc = np.einsum("nkc,nc->nk", data.jac, qdd[:, :3]) + data.jac_dot_qd
        out[:, :3, 1] = np.einsum("nkc,nk->nc", data.jac, wheel_acc)
        return out

    def _coefficients(self, params: Mapping[str, float], variant: FrictionVariant
                      ) -> np.ndarray:
        """(f_dv, f_dc, f_sv, f_sc) per unit, (k, 4); the drives' zero with ``body``."""
        fam = ("fdv", "fdc", "fsv", "fsc")
        out = np.array([[float(params.get(f"{f}_{u}", params.get(f, 0.0))) for f in fam]
                        for u in self.names]).reshape(-1, 4)
        if variant == "body":
            out[:, :2] = 0.0
        return out

    def friction_torques(self, data: SteeredData, params: Mapping[str, float],
                         variant: FrictionVariant = "per-wheel") -> np.ndarray:
        """τ_f per actuator (N, 2k), drive then steering of each unit, added to the motor
        torques: f_v rate + f_c tanh(α rate)."""
        f = self._coefficients(params, check_variant(variant))
        rates = np.stack([data.wheel_rate, data.steer_rate], axis=-1)  # (N, k, 2)
        tau = f[:, 0::2] * rates + f[:, 1::2] * np.tanh(self.alpha * rates)
        return tau.reshape(tau.shape[0], -1)

    def friction_force(self, data: SteeredData, params: Mapping[str, float],
                       variant: FrictionVariant = "per-wheel") -> None:
        """Every joint is actuated: all friction enters through B_τ."""
        return None

    def friction_columns(self, data: SteeredData, variant: FrictionVariant = "per-wheel",
                         out: np.ndarray | None = None) -> np.ndarray:
        """Columns of A_ID,ext for :meth:`friction_names`: −B_τ,a [rate_a, tanh(α rate_a)]
        per actuator a (per unit, or summed over the units when shared); (N, 3 + k, p_f)."""
        n, k = data.psi.shape
        rates = np.stack([data.wheel_rate, data.steer_rate], axis=-1)  # (N, k, 2)
        a_f = np.stack([rates, np.tanh(self.alpha * rates)], axis=-1)  # (N, k, 2 act, 2)
        b = data.b_tau.reshape(n, 3 + k, k, 2)
        full = -b[..., None] * a_f[:, None]  # (N, 3+k, k, 2 act, 2)
        full = full.reshape(n, 3 + k, k, 4)  # fdv, fdc, fsv, fsc
        if check_variant(variant) == "shared":
            cols = full.sum(axis=2)
        elif variant == "body":
            cols = full[..., 2:].reshape(n, 3 + k, -1)
        else:
            cols = full.reshape(n, 3 + k, -1)
        if out is not None:
            out[...] = cols
            return out
        return cols

    def compiled(self, params: Mapping[str, float], variant: FrictionVariant = "per-wheel"
                 ) -> tuple[Any, np.ndarray, np.ndarray]:
        """The compiled one-sample kernel (:mod:`ropod_sysid.model.units.steered_jit`: S1–S8,
        the steering loops along the planned steering) and its geometry and parameter arrays
        (ImportError without numba)."""
        from ropod_sysid.model.units import steered_jit

        return steered_jit, *steered_jit.arrays(self, params, variant)

    def kinetic_energy(self, data: SteeredData, params: Mapping[str, float]) -> np.ndarray:
        """Σ_i ½ J_st (θ̇ + β̇_i)² + ½ J_rot,s φ̇_i² [J]; shape (N,)."""
        turn = data.qd[:, 2:3] + data.steer_rate
        return 0.5 * (float(params["Jst"]) * (turn**2).sum(axis=1)
                      + float(params["Jrot_s"]) * (data.wheel_rate**2).sum(axis=1))

    # ------------------------------------------------------------ report / inspect
    def unit_table(self) -> list[dict[str, float | str]]:
        """One row per unit for the report and ``inspect``: geometry and constants."""
        return [{"name": s.name, "type": self.type_name, "x [m]": s.position[0],
                 "y [m]": s.position[1], "wheel radius [m]": s.wheel_radius,
                 "torque constant [N m/A]": s.torque_constant,
                 "steer torque constant [N m/A]": s.steer_torque_constant}
                for s in self.specs]

    def quantities(self, data: SteeredData, q_fit: np.ndarray | None = None
                   ) -> dict[str, tuple[str, np.ndarray]]:
        """Per-unit signals (N, k) for the report and ``inspect``: steering and wheel rates,
        rim speed, and given a base twist ``q_fit`` (N, 3) the rolling and lateral slip (S1,
        S2 residuals) [m/s]."""
        out = {"steering rate": ("rad/s", data.steer_rate),
               "wheel rate": ("rad/s", data.wheel_rate),
               "rim speed": ("m/s", data.wheel_rate * self.r)}
        if q_fit is not None:
            cp, sp = np.cos(data.psi), np.sin(data.psi)
            out["slip"] = ("m/s", data.wheel_rate * self.r
                           - np.einsum("nkc,nc->nk", data.jac, q_fit) * self.r)
            out["lateral slip"] = ("m/s", -sp * q_fit[:, 0:1] + cp * q_fit[:, 1:2]
                                   + data.e * q_fit[:, 2:3])
        return out

