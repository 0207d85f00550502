"""Wheel units on movable legs: any wheel type on a passive prismatic joint (DLR's Justin base).

Robuffo Giordano, Fuchs, Albu-Schäffer and Hirzinger, *On the kinematic modeling and control of
a mobile platform equipped with steering wheels and movable legs* (cited as 002) give the
kinematics of centred steering wheels whose legs extend and retract horizontally; the legs have
no motor, the wheels' rolling forces move them. 002 gives no dynamics: they are derived here for
any wheel type, and checked by ``tests/test_legs.py`` (a hand derivation of 002's rows, the
constant-leg reduction, a Lagrangian with finite-difference Jacobians, energy).

Geometry. Unit i's leg has its hip h_i and unit axis a_i in the base frame and extension λ_i;
its wheel unit is attached at P_i = h_i + λ_i a_i. The leg's end carries a frame L_i that
translates with the leg and turns with the base: origin r + R(θ) λ_i a_i, heading θ. In L_i the
wheel unit sits at the fixed point h_i, so every formula of its type holds unchanged in L_i's
coordinates q_L = (x_L, y_L, θ). With d_i = R(θ) λ_i a_i and â_i = R(θ) a_i (world)

    q̇_L = T q̇,     T = [[I₂, S d_i, â_i], [0, 1, 0]]                                  (L1)
    q̈_L = T q̈ + Ṫ q̇,   Ṫ q̇ = (−θ̇² d_i + 2 θ̇ λ̇_i S â_i, 0)                          (L2)

(columns: x, y, θ, λ_i; S a 90° turn; the unit's own coordinates pass through unchanged). By
the virtual power of the unit's forces through q̇_L = T q̇, its contributions transform as

    M_add = Tᵀ M_add,L T,   b_dir = Tᵀ (b_dir,L − M_add,L Ṫ q̇),   B_τ = Tᵀ B_τ,L       (L3)
    G = G_L T,   Ġ q̇ = Ġ_L q̇_L + G_L Ṫ q̇                                             (L4)

and the identification columns are Tᵀ A_ID,L at q̈_L of (L2). For a steered wheel G_L is 001's
lateral row; at h = 0, a = (cos α, sin α) it is 002 eq. (17) with Γ_i = sin(α_i − φ_i):

    −sin(θ + β_i) ẋ + cos(θ + β_i) ẏ + (P_i · h_β) θ̇ + sin(α_i − β_i) λ̇_i = 0            (L5)

Solved for the steering angle it gives 002 eq. (18) with the cos α_i / sin α_i factors its
print lacks (those of eq. 12): β_i = atan2(v_y + λ_i cos α_i θ̇ + sin α_i λ̇_i,
v_x − λ_i sin α_i θ̇ + cos α_i λ̇_i) in the base frame.

The leg. The mass m_leg that moves with the attachment point (the leg's carriage and, for a
centred wheel, the wheel unit: its type keeps that mass in m_b when fixed) is a point mass at
P_i, world velocity v_P = A_P q̇ with A_P = [I₂, S R P_i, â_i] (x, y, θ, λ_i):

    M_add += m_leg A_Pᵀ A_P,   b_dir += −m_leg A_Pᵀ (−θ̇² R P_i + 2 θ̇ λ̇_i S â_i)          (L6)

(its own inertia about a vertical axis is constant and stays in J_zz,b). The joint is passive:
no actuator; its friction f_lv λ̇ + f_lc tanh(α λ̇) [N] acts on the λ_i row (signs as for the
ropod: dissipative values ≤ 0). A constant leg (λ̇ = 0 and P_i the fixed attachment point)
gives exactly the fixed unit plus the point mass m_leg at P_i.

Identifiable combinations: a centred wheel that cannot slip sideways carries its spin inertia
like a point mass J_rot/r² at its centre, so along the leg only m_leg + J_rot,s/r² is
determined (the fit's rank analysis names that combination); with legs that never move m_leg
lumps with m_b and J_zz,b, and the leg friction has no rows.

Odometry. A unit's constraint rows A ν_L = b on L_i's base-frame twist ν_L = Tᵦ ν + (λ̇ a, 0),
Tᵦ = [[I₂, S λ a], [0, 1]] (base frame), become rows on the base twist with right-hand side
b − A (λ̇ a, 0) (:meth:`LeggedUnits.normal_equations`).

One group holds one legged unit (its transform is its own); the legs' mass is one parameter.
"""

from __future__ import annotations

import zlib
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, overload

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.model.units import (
    AnglePrediction,
    Channel,
    FrictionVariant,
    check_variant,
    integrated,
    series,
    turn,
)
from ropod_sysid.model.units.entry import unit_name
from ropod_sysid.model.units.leg_entry import LeggedSpec, parse_leg

LEG_HELD = 0.002  # [m/s]: a leg slower than this is held (by static friction): locked
LEG_CHANNEL = Channel("leg_{u}", "leg", "m", "leg extension lambda (attachment point hip + "
                      "lambda * axis)", held=LEG_HELD)
LEG_GAIN = 2.0  # [1/s]: the commanded leg rate corrects the extension's error at this rate
LEG_RATE_MAX = 0.1  # [m/s]: planned leg rates stay below this
LEG_START_SPEED = 0.05  # [m/s]: planned legs move only while the base is faster than this
LEG_SPEED_RATIO = 3.0  # planned leg rates stay below the base's speed at the leg / this
REST_SPEED = 0.01  # [m/s]: a wheel centre slower than this while the base moves is at rest
TYPE_A = "wheel at rest (type A)"  # the prediction's flag (002 §III-C)
LEG_AMPLITUDE = 0.45  # plan_search(): the largest amplitude, a fraction of the range's width
LEG_FREQUENCY_MAX = 0.3  # [Hz] plan_search(): the fastest leg oscillation


@dataclass
class LegData:
    """Per-sample kinematics of one legged unit: its wheel type's data in the leg-end frame L
    and the transform to the platform's coordinates (L1, L2)."""

    wheel: Any  # the wheel type's data at (q_L, q̇_L)
    qd: np.ndarray  # (N, 3) base twist, world
    lam: np.ndarray  # (N,) λ [m]
    lam_rate: np.ndarray  # (N,) λ̇ [m/s]
    t: np.ndarray  # (N, 3 + e, 4 + e) T of (L1) with the wheel's e own coordinates
    t_dot_qd: np.ndarray  # (N, 3 + e) Ṫ q̇ (L2)
    a_p: np.ndarray  # (N, 2, 4 + e) A_P of (L6)
    a_p_dot_qd: np.ndarray  # (N, 2) Ȧ_P q̇

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ = Tᵀ B_τ,L (L3); (N, 4 + e, m)."""
        return np.einsum("nri,nra->nia", self.t, self.wheel.b_tau)

    @property
    def angle_rate(self) -> np.ndarray:
        return np.concatenate([self.wheel.angle_rate, self.lam_rate[:, None]], axis=1)

    @property
    def actuator_rate(self) -> np.ndarray:
        return self.wheel.actuator_rate


def _rate(lam: np.ndarray, t: np.ndarray) -> np.ndarray:
    """dλ/dt (V, N) of extensions (V, N) at times t (N,): second-order differences, exactly 0
    where a leg holds (differences over uneven steps leave 1e-15 of a constant, which column
    scaling would make look like excitation)."""
    if lam.shape[1] < 2:
        return np.zeros_like(lam)
    rate = np.gradient(lam, t, axis=1)
    return np.where(np.ptp(lam, axis=1, keepdims=True) == 0.0, 0.0, rate)


def _with_lead(pred: AnglePrediction, lead: tuple[int, ...]) -> AnglePrediction:
    """A prediction over V = prod(lead) series (V, N, …) reshaped to (…lead, N, …)."""

    def shaped(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a.reshape(*lead, *a.shape[1:])

    return AnglePrediction(shaped(pred.angles), shaped(pred.rates), shaped(pred.actuator),  # type: ignore[arg-type]
                           shaped(pred.turning), {k: shaped(v) for k, v in pred.flags.items()},  # type: ignore[misc]
                           shaped(pred.lag))


class LeggedUnits:
    """One wheel unit of type ``wheel_type`` on a leg (the class is made per wheel type by
    :func:`legged`)."""

    wheel_type: ClassVar[Any]
    type_name: ClassVar[str]
    angles: ClassVar[tuple[Channel, ...]]
    currents: ClassVar[tuple[Channel, ...]]
    coordinates: ClassVar[tuple[int, ...]]
    platform_keys: ClassVar[tuple[str, ...]]
    inertial_names: ClassVar[tuple[str, ...]]
    parameter_info: ClassVar[Mapping[str, tuple[str, str]]]
    friction_signs: ClassVar[Mapping[str, int]]
    turning: ClassVar[str | None]
    steering: ClassVar[str | None]
    steering_current: ClassVar[int]
    planned_channels: ClassVar[tuple[Channel, ...]] = (LEG_CHANNEL,)  # a run plans λ
    plan_dimensions: ClassVar[int] = 3  # plan_search(): amplitude, frequency, phase
    leg_parameters: ClassVar[dict[str, tuple[str, str]]] = {
        "m_leg": ("kg", "mass moving with a leg's attachment point"),
        "flv": ("N s/m", "viscous leg friction"),
        "flc": ("N", "Coulomb leg friction"),
    }

    def __init__(self, specs: Sequence[LeggedSpec], friction_tanh_gain: float = 10.0) -> None:
        if len(specs) != 1:
            raise ValueError("a legged group holds one unit")
        self.specs = tuple(specs)
        self.spec = specs[0]
        self.leg = self.spec.leg
        self.names = [self.spec.name]
        self.n_units = 1
        self.wheel = self.wheel_type.from_specs([self.spec.wheel], friction_tanh_gain)
        self.alpha = float(friction_tanh_gain)
        self.n_own = len(getattr(self.wheel_type, "coordinates", ()))  # e
        self.axis = np.asarray(self.leg.axis, float)
        self.hip = np.asarray(self.leg.hip, float)

    # ------------------------------------------------------------ declaration
    @classmethod
    def parse_entry(cls, entry: Mapping[str, Any], k: int, where: str,
                    defaults: Mapping[str, float]) -> LeggedSpec:
        """A wheel entry with ``leg:``: the wheel attached at the leg's hip."""
        name = unit_name(entry, k, where, '{name: "1", type: steered, leg: {hip: [x, y], '
                         'axis: [ex, ey], range: [lmin, lmax]}}')
        at = f"{where}: 'units[{k}]' (unit '{name}')"
        leg = parse_leg(entry, at)
        key = cls.wheel_type.attachment_key
        if key in entry:
            raise InputError(f"{at}: key '{key}' with 'leg': the attachment point is hip + "
                             f"lambda * axis; leave out '{key}'")
        inner = {k_: v for k_, v in entry.items() if k_ != "leg"} | {key: list(leg.hip)}
        return LeggedSpec(cls.wheel_type.parse_entry(inner, k, where, defaults), leg)

    @classmethod
    def group_key(cls, spec: LeggedSpec) -> Hashable:
        return spec.name  # each legged unit is a group of its own

    @classmethod
    def from_specs(cls, specs: Sequence[LeggedSpec], friction_tanh_gain: float = 10.0
                   ) -> LeggedUnits:
        return cls(specs, friction_tanh_gain)

    @classmethod
    def friction_names(cls, units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """The wheel type's friction names, then the legs' (``flv_<u>``, ``flc_<u>``)."""
        names = list(cls.wheel_type.friction_names(units, variant))
        if check_variant(variant) == "shared":
            return names + ["flv", "flc"]
        return names + [n for u in units for n in (f"flv_{u}", f"flc_{u}")]

    @classmethod
    def typical_parameters(cls, units: Sequence[str]) -> dict[str, float]:
        """The wheel type's, a leg mass of 6 kg and the leg friction of a linear guide
        (−15 N s/m, −4 N), ±10 % per unit."""
        out = dict(cls.wheel_type.typical_parameters(units))
        rng = np.random.default_rng(2002)
        out["m_leg"] = 6.0
        for u in units:
            f = 1.0 + 0.1 * (2 * rng.random(2) - 1)
            out |= {f"flv_{u}": -15.0 * f[0], f"flc_{u}": -4.0 * f[1]}
        return out

    def torque_constants(self) -> np.ndarray:
        return self.wheel.torque_constants()

    @property
    def reach(self) -> float:
        """The farthest the attachment point comes from the base origin over the leg's range
        [m] (|h + λ a| is convex in λ: at an end of the range); planning keeps the centre of
        rotation beyond it (002 eq. 26)."""
        return float(np.linalg.norm(self.leg.point(np.asarray(self.leg.range)), axis=-1).max())

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        """The wheel's, with the leg at the middle of its range (the wheel as if attached
        there)."""
        return np.append(self._wheel_at(self.leg.middle).initial_angles(twist), self.leg.middle)

    def _wheel_at(self, extension: float) -> Any:
        """The wheel type's group attached at the leg's point for a fixed ``extension``."""
        return self.wheel_type.from_specs([self.spec.wheel.moved(self.leg.point(extension))],
                                          self.alpha)

    # ------------------------------------------------------------ kinematics
    @overload
    def _split(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...
    @overload
    def _split(self, values: None) -> tuple[None, None]: ...
    @overload
    def _split(self, values: np.ndarray | None
               ) -> tuple[np.ndarray | None, np.ndarray | None]: ...
    def _split(self, values: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
        if values is None:
            return None, None
        values = np.asarray(values, float)
        return values[:, :-1], values[:, -1]

    def kinematics(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
                   angle_rates: np.ndarray | None = None,
                   coordinate_rates: np.ndarray | None = None) -> LegData:
        """The wheel's kinematics in the leg-end frame (L1) and the transforms T, Ṫ q̇ (L2),
        A_P, Ȧ_P q̇ (L6). λ̇ is the last of ``coordinate_rates`` (the simulator's states)
        when given, else the measured rate in ``angle_rates``."""
        q = np.asarray(q, float)
        qd = np.asarray(qd, float)
        wheel_angles, lam = self._split(angles)
        wheel_rates, lam_rate_meas = self._split(angle_rates)
        wheel_coord, lam_rate = self._split(coordinate_rates)
        if lam_rate is None:
            if lam_rate_meas is None:
                raise ValueError("a leg needs its extension rate (measured or a state)")
            lam_rate = lam_rate_meas
        n, e = q.shape[0], self.n_own
        omega = qd[:, 2]
        c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
        (ax, ay), (hx, hy) = self.axis, self.hip
        awx, awy = c * ax - s * ay, s * ax + c * ay  # â = R a (world)
        dwx, dwy = lam * awx, lam * awy  # R λ a
        pwx, pwy = c * hx - s * hy + dwx, s * hx + c * hy + dwy  # R P
        t = np.zeros((n, 3 + e, 4 + e))  # (L1)
        t[:, 0, 0] = t[:, 1, 1] = t[:, 2, 2] = 1.0
        t[:, 0, 2], t[:, 1, 2] = -dwy, dwx
        t[:, 0, 3 + e], t[:, 1, 3 + e] = awx, awy
        for k in range(e):
            t[:, 3 + k, 3 + k] = 1.0
        om2, cor = omega * omega, 2.0 * omega * lam_rate
        t_dot_qd = np.zeros((n, 3 + e))  # (L2): −θ̇² R λ a + 2 θ̇ λ̇ S â
        t_dot_qd[:, 0] = -om2 * dwx - cor * awy
        t_dot_qd[:, 1] = -om2 * dwy + cor * awx
        q_l, qd_l = self.leg_kinematics(q, qd, lam, lam_rate)  # (L1)
        if e:
            wheel = self.wheel.kinematics(q_l, qd_l, wheel_angles, wheel_rates,
                                          coordinate_rates=wheel_coord)
        else:
            wheel = self.wheel.kinematics(q_l, qd_l, wheel_angles, wheel_rates)
        a_p = np.zeros((n, 2, 4 + e))  # (L6): [I₂, S R P, â]
        a_p[:, 0, 0] = a_p[:, 1, 1] = 1.0
        a_p[:, 0, 2], a_p[:, 1, 2] = -pwy, pwx
        a_p[:, 0, 3 + e], a_p[:, 1, 3 + e] = awx, awy
        a_p_dot_qd = np.stack([-om2 * pwx - cor * awy, -om2 * pwy + cor * awx], axis=-1)
        return LegData(wheel, qd, lam, lam_rate, t, t_dot_qd, a_p, a_p_dot_qd)

    def _qd_full(self, data: LegData) -> np.ndarray:
        """q̇ of the group's coordinates (N, 4 + e): base twist, own rates, λ̇."""
        own = data.wheel.angle_rate[:, list(self.wheel_type.coordinates)] if self.n_own else (
            np.zeros((data.qd.shape[0], 0)))
        return np.concatenate([data.qd, own, data.lam_rate[:, None]], axis=1)

    def wheel_accelerations(self, data: LegData, qdd: np.ndarray) -> np.ndarray:
        """q̈_L (L2) of the wheel's coordinates (N, 3 + e) for the group's q̈ (N, 4 + e)."""
        return np.einsum("nij,nj->ni", data.t, qdd) + data.t_dot_qd

    def leg_kinematics(self, q: np.ndarray, qd: np.ndarray, lam: np.ndarray,
                       lam_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The leg-end frame's pose q_L and twist q̇_L (N, 3) (world) for base motion (q, qd)
        and extensions λ, λ̇ (N,) (L1)."""
        q = np.asarray(q, float)
        qd = np.asarray(qd, float)
        c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
        awx, awy = c * self.axis[0] - s * self.axis[1], s * self.axis[0] + c * self.axis[1]
        q_l = q.copy()
        q_l[:, 0] += lam * awx
        q_l[:, 1] += lam * awy
        qd_l = qd.copy()  # ṙ + θ̇ S R λ a + λ̇ R a
        qd_l[:, 0] += -qd[:, 2] * lam * awy + lam_rate * awx
        qd_l[:, 1] += qd[:, 2] * lam * awx + lam_rate * awy
        return q_l, qd_l

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
                       leg_rate: np.ndarray | None = None) -> np.ndarray:
        """The wheel's actuator rates for the base motion with the legs moving at
        ``leg_rate`` (N,) [m/s] (0: held), from its inverse kinematics in the leg-end frame."""
        wheel_angles, lam = self._split(angles)
        rate = np.zeros(lam.shape) if leg_rate is None else np.asarray(leg_rate, float)
        q_l, qd_l = self.leg_kinematics(q, qd, lam, rate)
        return self.wheel.actuator_rates(q_l, qd_l, wheel_angles)

    def angle_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """The wheel's angle rates with the leg held; the extension's rate is a state: 0."""
        wheel_angles, lam = self._split(angles)
        q_l, qd_l = self.leg_kinematics(q, qd, lam, np.zeros(lam.shape))
        rates = self.wheel.angle_rates(q_l, qd_l, wheel_angles)
        return np.concatenate([rates, np.zeros((rates.shape[0], 1))], axis=1)

    def constraint_rows(self, angles: np.ndarray, rates: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """The wheel's odometry rows A ν_L = b moved to the base twist: ν_L = Tᵦ ν + (λ̇ a, 0)
        (module docstring, "Odometry"): A Tᵦ (N, r, 3) and b − A (λ̇ a, 0) (N, r); ``rates``
        may be increments."""
        wheel_angles, lam = self._split(angles)
        wheel_rates, lam_rate = self._split(rates)
        a, b = self.wheel.constraint_rows(wheel_angles, wheel_rates)
        n = lam.shape[0]
        tb = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        tb[:, :2, 2] = turn(lam[:, None] * self.axis)
        shift = np.zeros((n, 3))
        shift[:, :2] = lam_rate[:, None] * self.axis
        return np.einsum("nrj,nji->nri", a, tb), b - np.einsum("nrj,nj->nr", a, shift)

    def normal_equations(self, angles: np.ndarray, increments: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """AᵀA (N, 3, 3) and Aᵀb (N, 3) of :meth:`constraint_rows`."""
        a, b = self.constraint_rows(angles, increments)
        return np.einsum("nrc,nrd->ncd", a, a), np.einsum("nrc,nr->nc", a, b)

    # ------------------------------------------------------------ dynamics
    def mass_terms(self, data: LegData, params: Mapping[str, float]
                   ) -> tuple[np.ndarray, np.ndarray]:
        """(M_add, b_dir) over (q_b, own, λ) (L3, L6)."""
        m_l, b_l = self.wheel.mass_terms(data.wheel, params)
        t_t = np.swapaxes(data.t, 1, 2)
        m = t_t @ m_l @ data.t
        b = np.einsum("nir,nr->ni", t_t, b_l - np.einsum("nrs,ns->nr", m_l, data.t_dot_qd))
        m_leg = float(params["m_leg"])
        m = m + m_leg * (np.swapaxes(data.a_p, 1, 2) @ data.a_p)
        b = b - m_leg * np.einsum("nri,nr->ni", data.a_p, data.a_p_dot_qd)
        return m, b

    def a_id(self, data: LegData, qdd: np.ndarray) -> np.ndarray:
        """Columns of A_ID for m_leg and the wheel type's inertial parameters: A_Pᵀ (A_P q̈ +
        Ȧ_P q̇) (L6), and Tᵀ A_ID,L at q̈_L (L2, L3); (N, 4 + e, 1 + p)."""
        cols = self.wheel.a_id(data.wheel, self.wheel_accelerations(data, qdd))
        wheel = np.einsum("nri,nrp->nip", data.t, cols)
        acc = np.einsum("nri,ni->nr", data.a_p, qdd) + data.a_p_dot_qd
        leg = np.einsum("nri,nr->ni", data.a_p, acc)
        return np.concatenate([leg[..., None], wheel], axis=2)

    def _leg_coefficients(self, params: Mapping[str, float]) -> tuple[float, float]:
        u = self.spec.name
        return (float(params.get(f"flv_{u}", params.get("flv", 0.0))),
                float(params.get(f"flc_{u}", params.get("flc", 0.0))))

    def friction_torques(self, data: LegData, params: Mapping[str, float],
                         variant: FrictionVariant = "per-wheel") -> np.ndarray:
        return self.wheel.friction_torques(data.wheel, params, variant)

    def friction_force(self, data: LegData, params: Mapping[str, float],
                       variant: FrictionVariant = "per-wheel") -> np.ndarray:
        """The wheel's generalized friction force moved by Tᵀ, and the leg's friction
        f_lv λ̇ + f_lc tanh(α λ̇) on its row; (N, 4 + e)."""
        n = data.lam.shape[0]
        f_l = self.wheel.friction_force(data.wheel, params, variant)
        out = np.zeros((n, 4 + self.n_own))
        if f_l is not None:
            f_l = np.asarray(f_l, float)
            full = np.zeros((n, 3 + self.n_own))
            full[:, :f_l.shape[1]] = f_l
            out += np.einsum("nri,nr->ni", data.t, full)
        fv, fc = self._leg_coefficients(params)
        out[:, -1] += fv * data.lam_rate + fc * np.tanh(self.alpha * data.lam_rate)
        return out

    def friction_columns(self, data: LegData, variant: FrictionVariant = "per-wheel",
                         out: np.ndarray | None = None) -> np.ndarray:
        """The wheel's columns moved by Tᵀ, then the leg's −[λ̇, tanh(α λ̇)] on its row."""
        cols = self.wheel.friction_columns(data.wheel, variant)
        wheel = np.einsum("nri,nrp->nip", data.t, cols)
        n = data.lam.shape[0]
        leg = np.zeros((n, 4 + self.n_own, 2))
        leg[:, -1, 0] = -data.lam_rate
        leg[:, -1, 1] = -np.tanh(self.alpha * data.lam_rate)
        res = np.concatenate([wheel, leg], axis=2)
        if out is not None:
            out[...] = res
            return out
        return res

    def kinetic_energy(self, data: LegData, params: Mapping[str, float]) -> np.ndarray:
        """The wheel's kinetic energy (in L, its own) plus ½ m_leg |v_P|² [J]; (N,)."""
        v_p = np.einsum("nri,ni->nr", data.a_p, self._qd_full(data))
        return (self.wheel.kinetic_energy(data.wheel, params)
                + 0.5 * float(params["m_leg"]) * (v_p**2).sum(axis=1))

    # ------------------------------------------------------------ planning
    def predict_angles(self, t: np.ndarray, twists: np.ndarray,
                       initial: np.ndarray | None = None,
                       legs: np.ndarray | None = None) -> AnglePrediction:
        """The wheel's planned angles along base-frame twists (…, N, 3) with the leg at
        ``legs`` (…, N) [m] (held at the middle of its range when not given): the wheel's
        planning for the leg-end frame's twist (L1, in the base frame), its attachment
        point at the leg's mean extension; the extension appended."""
        tw, lead = series(twists)
        lam = self._leg_series(t, tw, legs)
        tw_l, lam_rate = self._leg_end_twist(t, tw, lam)
        wheel_init = None if initial is None else np.asarray(initial, float)[..., :-1]
        pred = self._wheel_at(self.leg.middle).predict_angles(t, tw_l, wheel_init)
        ang = np.concatenate([pred.angles.reshape(*tw.shape[:2], -1), lam[..., None]], axis=-1)
        rates = np.concatenate([pred.rates.reshape(*tw.shape[:2], -1), lam_rate[..., None]],
                               axis=-1)
        flags = dict(pred.flags)
        # 002 §III-C, the leg's case: the base moves the wheel, the leg's own motion cancels
        # it, and the wheel stands (type A: its steering undefined); where the base itself
        # leaves the wheel at rest (the centre of rotation on it) the wheel type plans
        mid = self.leg.point(self.leg.middle)
        ex, ey = (lam - self.leg.middle) * self.axis[0], (lam - self.leg.middle) * self.axis[1]
        base = np.hypot(tw[..., 0] - tw[..., 2] * (mid[1] + ey),
                        tw[..., 1] + tw[..., 2] * (mid[0] + ex))
        centre = np.hypot(tw_l[..., 0] - tw_l[..., 2] * mid[1],
                          tw_l[..., 1] + tw_l[..., 2] * mid[0])
        flags[TYPE_A] = ((base >= REST_SPEED) & (centre < REST_SPEED))[..., None]
        return _with_lead(AnglePrediction(ang, rates, pred.actuator, pred.turning, flags,
                                          pred.lag), lead)

    def plan_coordinates(self, t: np.ndarray, twists: np.ndarray, seed: int = 0,
                         rate_max: float = LEG_RATE_MAX) -> dict[str, np.ndarray]:
        """A planned extension for an identification run along base-frame twists (N, 3) at
        times t (N,) [s] (``trajectory typical``'s): :meth:`leg_profile` with A = 40 % of the
        range's width and a frequency f and phase of its own per unit (so that the legs'
        masses and frictions separate), A 2π f ≤ 0.8 ``rate_max`` [m/s]."""
        t = np.asarray(t, float)
        tw = np.asarray(twists, float).reshape(1, t.size, 3)
        amp = 0.4 * (self.leg.range[1] - self.leg.range[0])
        rng = np.random.default_rng([zlib.crc32(self.spec.name.encode()), seed])
        freq = 0.8 * rate_max / (2 * np.pi * amp) * rng.uniform(0.6, 1.0)
        phase = rng.uniform(0, 2 * np.pi)
        lam = self.leg_profile(t, tw, np.array([amp]), np.array([freq]), np.array([phase]))
        return {LEG_CHANNEL.column(self.spec.name): lam[0]}

    def leg_profile(self, t: np.ndarray, twists: np.ndarray, amplitude: np.ndarray,
                    freq: np.ndarray, phase: np.ndarray) -> np.ndarray:
        """Planned extensions (S, N) [m] along base-frame twists (S, N, 3) at times t (N,) for
        S profiles λ = middle + A sin(2π f s + φ) (amplitudes A [m], frequencies f [Hz],
        phases φ [rad], each (S,)) on a progress s that advances only while the base moves:
        ṡ = a minimum-jerk step of (speed − :data:`LEG_START_SPEED`) / (:data:`LEG_SPEED_RATIO`
        · A 2π f) clipped to [0, 1], the speed that of the base's motion at the leg's middle
        point (|v + ω × P|, the slower of the run and its mirrored variant). So the leg moves
        at most A 2π f and slower than that speed / LEG_SPEED_RATIO, no wheel comes to rest
        where the base moves it (002 §III-C, type A: up to the leg's excursion from its middle
        point), the legs stand still while the base is slow there, and λ stays within
        middle ± A."""
        t = np.asarray(t, float)
        tw = np.asarray(twists, float)
        amp, freq, phase = (np.asarray(v, float)[:, None] for v in (amplitude, freq, phase))
        px, py = self.leg.point(self.leg.middle)
        # the base's velocity at the leg's middle point, the slower of a run and its mirror
        # (v_y, ω → −v_y, −ω; the negated variants are as fast): its four variants share the plan
        vx, vy, w = tw[..., 0], tw[..., 1], tw[..., 2]
        speed = np.minimum(np.hypot(vx - w * py, vy + w * px), np.hypot(vx + w * py, -vy - w * px))
        x = np.clip((speed - LEG_START_SPEED) / (LEG_SPEED_RATIO * amp * 2 * np.pi * freq),
                    0.0, 1.0)
        gate = x**3 * (10.0 - 15.0 * x + 6.0 * x * x)  # minimum-jerk: smooth on and off
        progress = integrated(t, gate[..., None], np.zeros((gate.shape[0], 1)))[..., 0]
        return self.leg.middle + amp * np.sin(2 * np.pi * freq * progress + phase)

    def plan_search(self, t: np.ndarray, twists: np.ndarray, u: np.ndarray,
                    rate_max: float = LEG_RATE_MAX) -> dict[str, np.ndarray]:
        """Planned extensions (S, N) for ``trajectory optimize``'s search: :meth:`leg_profile`
        chosen by :attr:`plan_dimensions` = 3 numbers in [0, 1] per candidate, u (S, 3):
        amplitude A = (0.1 + 0.9 u₀) · :data:`LEG_AMPLITUDE` × the range's width, frequency
        f = (0.2 + 0.8 u₁) × the least of 0.8 ``rate_max`` / (2π A) (the rate limit) and
        :data:`LEG_FREQUENCY_MAX`, phase 2π u₂; along base-frame twists (S, N, 3)."""
        amp, freq, phase = self._searched(u, rate_max)
        lam = self.leg_profile(t, twists, amp, freq, phase)
        return {LEG_CHANNEL.column(self.spec.name): lam}

    def _searched(self, u: np.ndarray, rate_max: float = LEG_RATE_MAX
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Amplitude [m], frequency [Hz] and phase [rad] (S,) of :meth:`plan_search`'s u."""
        u = np.clip(np.asarray(u, float).reshape(-1, self.plan_dimensions), 0.0, 1.0)
        amp = (0.1 + 0.9 * u[:, 0]) * LEG_AMPLITUDE * (self.leg.range[1] - self.leg.range[0])
        f_max = np.minimum(0.8 * rate_max / (2 * np.pi * amp), LEG_FREQUENCY_MAX)
        return amp, (0.2 + 0.8 * u[:, 1]) * f_max, 2 * np.pi * u[:, 2]

    def describe_plan(self, u: np.ndarray) -> str:
        """:meth:`plan_search`'s plan of u (3,) in words."""
        amp, freq, _ = self._searched(u)
        return (f"leg {self.spec.name} ±{1000 * amp[0]:.0f} mm about {self.leg.middle:.3g} m "
                f"at {freq[0]:.3g} Hz")

    def _leg_series(self, t: np.ndarray, tw: np.ndarray, legs: np.ndarray | None
                    ) -> np.ndarray:
        if legs is None:
            return np.full(tw.shape[:2], self.leg.middle)
        return np.broadcast_to(np.asarray(legs, float).reshape(-1, tw.shape[1]),
                               tw.shape[:2]).copy()

    def quasi_steady_angles(self, t: np.ndarray, twists: np.ndarray, twist_rates: np.ndarray,
                            legs: np.ndarray | None = None) -> AnglePrediction:
        """The wheel's, for the leg-end frame's twist and its rate with the leg at ``legs``
        (…, N) (held at the middle of its range when not given)."""
        tw, lead = series(twists)
        twd = np.asarray(twist_rates, float).reshape(tw.shape)
        lam = self._leg_series(t, tw, legs)
        if legs is None:
            tw_l, twd_l = tw, twd
        else:
            tw_l, _ = self._leg_end_twist(t, tw, lam)
            twd_l = np.gradient(tw_l, t, axis=1) if tw.shape[1] > 1 else np.zeros_like(tw)
        pred = self._wheel_at(self.leg.middle).quasi_steady_angles(t, tw_l, twd_l)
        rate = _rate(lam, t)
        ang = np.concatenate([pred.angles.reshape(*tw.shape[:2], -1), lam[..., None]], axis=-1)
        rates = np.concatenate([pred.rates.reshape(*tw.shape[:2], -1), rate[..., None]],
                               axis=-1)
        return _with_lead(AnglePrediction(ang, rates, pred.actuator, pred.turning,
                                          dict(pred.flags), pred.lag), lead)

    def _leg_end_twist(self, t: np.ndarray, tw: np.ndarray, lam: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The base-frame twists (V, N, 3) of the leg-end frame moved to the leg's middle
        attachment point (what :meth:`_wheel_at` its middle sees) for base twists (V, N, 3)
        and extensions λ (V, N), and λ̇ (V, N)."""
        rate = _rate(lam, t)
        tw_l = tw.copy()
        tw_l[..., :2] += tw[..., 2:3] * turn((lam - self.leg.middle)[..., None] * self.axis)
        tw_l[..., :2] += rate[..., None] * self.axis
        return tw_l, rate

    def controller_plan(self, t: np.ndarray, twists: np.ndarray,
                        planned: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """What the controllers track along base-frame twists (R, N, 3) at times t (N,) with
        the leg's planned extension ``planned`` (R, N, 1) (NaN or None: not planned, the leg
        held): λ_d, λ̇_d, λ̈_d (N, R), then the wheel's own plan for the leg-end frame's
        motion (:meth:`predict_angles`) if its type has one."""
        tw = np.asarray(twists, float)
        lam = None if planned is None else np.asarray(planned, float)[..., 0]
        if lam is not None and not np.isfinite(lam).all():
            lam = None
        if lam is None:
            lam_d = np.full(tw.shape[:2], np.nan)
            rate = acc = np.zeros(tw.shape[:2])
        else:
            lam_d = lam
            rate = _rate(lam, t)
            acc = np.gradient(rate, t, axis=1) if lam.shape[1] > 1 else np.zeros_like(lam)
        leg = tuple(np.swapaxes(a, 0, 1) for a in (lam_d, rate, acc))
        if not hasattr(self.wheel, "controller_plan"):
            return leg
        pred = self.predict_angles(t, tw, legs=lam)
        wheel = AnglePrediction(pred.angles[..., :-1], pred.rates[..., :-1], pred.actuator)
        return leg + tuple(self.wheel.controller_plan(t, tw, wheel))

    def controller_setpoints(self, twist: np.ndarray, twist_rate: np.ndarray,
                             angles: np.ndarray, plan: tuple[np.ndarray, ...] | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
        """The wheel's setpoints for the leg-end frame's base-frame twist ν_L = Tᵦ ν + (λ̇ a, 0)
        (L1) and its rate, the leg commanded at λ̇_d + :data:`LEG_GAIN` (λ_d − λ) (002 drives
        its legs through the wheels' rates: the legs are passive). ``plan`` (one step of
        :meth:`controller_plan`): λ_d, λ̇_d, λ̈_d (R,) and the wheel's plan; without a plan
        the leg is held. A wheel type without position-controlled joints gets its inverse
        kinematics (speed control: the angle errors NaN)."""
        wheel_angles, lam = self._split(angles)
        rate = np.zeros(lam.shape)
        acc = np.zeros(lam.shape)
        wheel_plan = None
        if plan is not None:
            lam_d, rate_d, acc_d = (np.asarray(p, float).reshape(-1) for p in plan[:3])
            planned = np.isfinite(lam_d)
            rate = np.where(planned, rate_d + LEG_GAIN * (np.where(planned, lam_d, 0.0) - lam),
                            0.0)
            acc = np.where(planned, acc_d, 0.0)
            wheel_plan = tuple(plan[3:]) or None
        d = lam[:, None] * self.axis
        tw = np.array(twist, float)
        tw[:, :2] += twist[:, 2:3] * turn(d) + rate[:, None] * self.axis
        twd = np.array(twist_rate, float)
        twd[:, :2] += (twist_rate[:, 2:3] * turn(d) + twist[:, 2:3] * rate[:, None]
                       * turn(self.axis) + acc[:, None] * self.axis)
        if hasattr(self.wheel, "controller_setpoints"):
            return self.wheel.controller_setpoints(tw, twd, wheel_angles, wheel_plan)
        rates = self.wheel.actuator_rates(np.zeros((tw.shape[0], 3)), tw, wheel_angles)
        return rates, np.full_like(rates, np.nan)

    # ------------------------------------------------------------ report / inspect
    def unit_table(self) -> list[dict[str, float | str]]:
        rows = self.wheel.unit_table()
        for r in rows:
            r["type"] = self.type_name
            r.pop("x [m]", None)
            r.pop("y [m]", None)
            r |= {"hip x [m]": self.leg.hip[0], "hip y [m]": self.leg.hip[1],
                  "leg axis [deg]": float(np.degrees(np.arctan2(self.axis[1], self.axis[0]))),
                  "leg range [m]": f"{self.leg.range[0]:g}–{self.leg.range[1]:g}"}
        return rows

    def quantities(self, data: LegData, q_fit: np.ndarray | None = None
                   ) -> dict[str, tuple[str, np.ndarray]]:
        """The wheel's signals (slip against the leg-end frame's twist) and the leg's
        extension and rate."""
        q_fit_l = None
        if q_fit is not None:
            q_fit_l = np.einsum("nij,nj->ni", data.t[:, :3, :3], q_fit)
            q_fit_l[:, :2] += data.lam_rate[:, None] * data.t[:, :2, 3 + self.n_own]
        out = dict(self.wheel.quantities(data.wheel, q_fit_l))
        out["leg extension"] = ("m", data.lam[:, None])
        out["leg rate"] = ("m/s", data.lam_rate[:, None])
        return out


def legged(wheel_type: Any) -> type[LeggedUnits]:
    """The unit type ``<type>+leg``: ``wheel_type`` on a leg."""
    attrs: dict[str, Any] = {
        "wheel_type": wheel_type,
        "type_name": f"{wheel_type.type_name}+leg",
        "angles": (*wheel_type.angles, LEG_CHANNEL),
        "currents": wheel_type.currents,
        "coordinates": (*getattr(wheel_type, "coordinates", ()), len(wheel_type.angles)),
        "platform_keys": wheel_type.platform_keys,
        # m_leg first: where it lumps with the wheel's spin inertia it stands for the sum
        "inertial_names": ("m_leg", *wheel_type.inertial_names),
        "parameter_info": {**wheel_type.parameter_info, **LeggedUnits.leg_parameters},
        "friction_signs": {**wheel_type.friction_signs, "flv": -1, "flc": -1},
        "turning": wheel_type.turning,
        "steering": wheel_type.steering,
        "steering_current": getattr(wheel_type, "steering_current", 0),
    }
    bases: tuple[type, ...] = (LeggedUnits,)
    if hasattr(wheel_type, "constraint_jacobian"):
        bases = (_Constrained, LeggedUnits)
    cls = type(f"Legged{wheel_type.__name__}", bases, attrs)
    globals()[cls.__name__] = cls  # found by name, as pickle looks classes up
    return cls


class _Constrained:
    """A legged wheel whose type keeps constraint rows (the steered wheel's lateral no-slip)."""

    def constraint_jacobian(self: Any, data: LegData) -> tuple[np.ndarray, np.ndarray]:
        """G = G_L T, Ġ q̇ = Ġ_L q̇_L + G_L Ṫ q̇ (L4)."""
        g_l, g_dot = self.wheel.constraint_jacobian(data.wheel)
        g = np.einsum("ncr,nri->nci", g_l, data.t)
        return g, g_dot + np.einsum("ncr,nr->nc", g_l, data.t_dot_qd)
