"""The omni-wheel unit: one driven wheel with free rollers, fixed to the base (no pivot).

Seed 004 (the 5DPO robot): kinematics 004 eqs. 1–5, dynamics 004 eqs. 6–13. Everything is
vectorised over samples N and the k units of the group: arrays are (N, k, …).

Geometry. Unit i sits at p_i (base frame) with heading h_i = (cos a_i, sin a_i): the direction in
the base frame in which the wheel centre moves when the wheel turns with φ̇_i > 0 and rolls
without slip (the paper's v_i = r ω_i). The free rollers let the contact point slide freely
across h_i, so only the component along h_i is constrained. With S = [[0, −1], [1, 0]], the base
pose q_b = (x, y, θ) and twist q̇_b in world coordinates, P_i = R(θ) p_i and H_i = R(θ) h_i,
the wheel-centre velocity is ṙ + θ̇ S P_i and

    r_i φ̇_i = H_iᵀ ṙ + θ̇ H_i·(S P_i) = H_iᵀ ṙ + θ̇ c_i,   c_i = p_i × h_i = p_x h_y − p_y h_x,

since H·(S P) = h·(S p) is invariant under the rotation. Hence φ̇_i = J_i q̇_b with

    J_i = (1/r_i) [cos(θ + a_i), sin(θ + a_i), c_i]                                     (O1)
    J̇_i q̇_b = (θ̇/r_i) (−sin(θ + a_i) ẋ + cos(θ + a_i) ẏ)                              (O2)

For the 5DPO layout (wheel i at angle i·90°, d = 0.089 m, headings tangential, counter-
clockwise: a_i = i·90° + 90°) and θ = 0, r J is the matrix of 004 eq. 2 (rows [0 1 d],
[−1 0 d], [0 −1 d], [1 0 d] on (v, v_n, ω)); its pseudo-inverse is 004 eqs. 3–5. Eq. O1 is at
once the constraint row of wheel odometry (linear in q̇_b) and the actuator-rate map.

Dynamics. The wheel and its rotor (gearing reflected) spin about the axle with inertia
J_rot,o; everything else (wheel mass, the rollers, the wheel's inertia about z) is part of the
base's m_b and J_zz,b. The unit adds the spin energy T_i = ½ J_rot,o φ̇_i². The constraint O1 is
not integrable (d(H_iᵀ dr + c_i dθ) ≠ 0), so the equations come from d'Alembert's principle
(Kane's method), not from substituting O1 into the Lagrangian: in the coordinates (q_b, φ) the
floor reaction λ_i on wheel i enters as −J_iᵀ λ_i on the base and +λ_i on the wheel,

    M_b q̈_b = −Σ J_iᵀ λ_i,   J_rot,o φ̈_i = τ_i + λ_i,   φ̈_i = J_i q̈_b + J̇_i q̇_b,

and eliminating λ_i gives the unit's share of eq. 65,

    M_add = J_rot,o Σ_i J_iᵀ J_i,   b_dir = −J_rot,o Σ_i J_iᵀ (J̇_i q̇_b),   B_τ,i = J_iᵀ  (O3)

(B_τ by virtual power: τ_i φ̇_i = (J_iᵀ τ_i)·q̇_b, so the motor torque is 004 eqs. 9–12 with
f_i = τ_i / r_i). Substituting O1 into T(q, q̇) and applying Lagrange's equations instead would
add the gyroscopic term J_rot,o Σ φ̇_i (θ̇ ∂J_iᵀ/∂θ − e_3 (∂J_i/∂θ) q̇_b): it does no work, but
it turns a single wheel at the centre into a source of torque about z (tests/test_omni.py).
Energy: d/dt ½ q̇ᵀ M_dir q̇ = q̇ᵀ (b_dir + B_τ τ) + J_rot,o Σ φ̇_i (J̇_i q̇) = Σ τ_i φ̇_i.

World frame versus 004 eqs. 6–8. In the robot frame, with body velocity (v, v_n) = R(θ)ᵀ ṙ and
ω = θ̇, r̈ = R(θ) (d/dt (v, v_n) + ω S (v, v_n)), so Newton's law reads
M (v̇ − ω v_n) = ΣF_v and M (v̇_n + ω v) = ΣF_vn. Eqs. 6–8 drop the terms M ω v_n and −M ω v;
this model works in world coordinates, where they cannot be lost.

Friction. Per wheel (like the ropod's roll friction, eq. 57 of the thesis) the friction torque
τ_f,i = f_ov,i φ̇_i + f_oc,i tanh(α φ̇_i) is added to the motor torque and enters through B_τ;
dissipative friction has f_ov, f_oc ≤ 0. Per body axis (004 eqs. 6–8: B_v, B_vn, B_ω, C_v, C_vn,
C_ω) the friction force in the base frame F_f = f_bv ⊙ ν + f_bc ⊙ tanh(α ν), ν = (v, v_n, ω),
enters through B_Fb (thesis eq. 3); f_bv = −(B_v, B_vn, B_ω), f_bc = −(C_v, C_vn, C_ω).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.model import base
from ropod_sysid.model.units import Channel, FrictionVariant
from ropod_sysid.platform import UNIT_NAME, _number

BODY_FRICTION = ("fbv_x", "fbv_y", "fbv_w", "fbc_x", "fbc_y", "fbc_w")


@dataclass(frozen=True)
class OmniSpec:
    """One omni unit as its platform-file entry describes it (SI units)."""

    name: str
    position: tuple[float, float]  # p_i in the base frame [m]
    heading: float  # a_i [rad]
    wheel_radius: float  # r_i [m]
    torque_constant: float  # k_t,i [N m/A], gearing included (004 eq. 13: l K_t)


@dataclass
class OmniData:
    """Per-sample kinematics of k omni units (shapes (N, k, …))."""

    theta: np.ndarray  # (N,) base heading θ
    qd: np.ndarray  # (N, 3) base twist in world coordinates
    jac: np.ndarray  # (N, k, 3) J_i = ∂φ̇_i/∂q̇_b (O1)
    jac_dot_qd: np.ndarray  # (N, k) J̇_i q̇_b (O2)
    wheel_rate: np.ndarray  # (N, k) φ̇_i: measured, or J_i q̇_b when not given

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ = [J_1ᵀ … J_kᵀ] (O3); shape (N, 3, k)."""
        return np.swapaxes(self.jac, 1, 2)


def _variant(variant: str) -> str:
    if variant not in ("per-wheel", "shared", "body"):
        raise InputError(f"unknown friction model {variant!r}; use per-wheel, shared or body")
    return variant


def _entry_number(entry: Mapping[str, Any], key: str, where: str, default: float | None,
                  positive: bool = False) -> float:
    value = _number(dict(entry), key, where, default)
    if positive and value <= 0:
        raise InputError(f"{where}: key '{key}' must be > 0, got {value}")
    return value


class OmniUnits:
    """k omni wheels of seed 004, fixed to the base: the ``omni`` unit type."""

    type_name = "omni"
    entry_keys = ("name", "type", "position", "heading", "wheel_radius", "torque_constant")
    inertial_names = ("Jrot_o",)
    parameter_units = {"Jrot_o": "kg m²", "fov": "N m s/rad", "foc": "N m",
                       "fbv_x": "N s/m", "fbv_y": "N s/m", "fbv_w": "N m s/rad",
                       "fbc_x": "N", "fbc_y": "N", "fbc_w": "N m"}

    def __init__(self, specs: Sequence[OmniSpec], friction_tanh_gain: float = 10.0) -> None:
        self.specs = tuple(specs)
        self.names = [s.name for s in self.specs]
        self.n_units = len(self.specs)
        self.positions = np.array([s.position for s in self.specs], float).reshape(-1, 2)
        self.headings = np.array([s.heading for s in self.specs], float)
        self.r = np.array([s.wheel_radius for s in self.specs], float)
        self.k_t = np.array([s.torque_constant for s in self.specs], float)
        self.alpha = float(friction_tanh_gain)
        h = np.stack([np.cos(self.headings), np.sin(self.headings)], axis=-1)
        self.moment_arm = self.positions[:, 0] * h[:, 1] - self.positions[:, 1] * h[:, 0]  # c_i

    # ------------------------------------------------------------ declaration
    @classmethod
    def parse_entry(cls, entry: Any, k: int, where: str,
                    defaults: Mapping[str, float]) -> OmniSpec:
        """Validate the platform-file entry ``units[k]`` of an omni unit; one-line errors.

        ``defaults`` holds the platform-wide ``wheel_radius`` and ``torque_constant`` that the
        entry may override.
        """
        if not isinstance(entry, Mapping) or "name" not in entry:
            raise InputError(f"{where}: 'units[{k}]' must be a mapping like {{name: \"1\", "
                             "type: omni, position: [x, y], heading: a}")
        name = str(entry["name"])
        if not UNIT_NAME.match(name):
            raise InputError(f"{where}: 'units[{k}].name' is {name!r}; use letters, digits and "
                             "underscores only")
        at = f"{where}: 'units[{k}]' (unit '{name}')"
        unknown = sorted(set(map(str, entry)) - set(cls.entry_keys))
        if unknown:
            raise InputError(f"{at}: unknown key '{unknown[0]}' for type omni; known keys: "
                             f"{', '.join(cls.entry_keys)}")
        pos = entry.get("position")
        if (not isinstance(pos, list | tuple) or len(pos) != 2
                or not all(isinstance(p, int | float) and not isinstance(p, bool)
                           and math.isfinite(float(p)) for p in pos)):
            raise InputError(f"{at}: key 'position' must be two finite numbers [x, y] in "
                             "metres (the wheel centre in the base frame)")
        if "heading" not in entry:
            raise InputError(f"{at}: missing key 'heading'; give the rolling direction in the "
                             "base frame [rad]")
        heading = _entry_number(entry, "heading", at, None)
        radius = _entry_number(entry, "wheel_radius", at, defaults.get("wheel_radius"), True)
        k_t = _entry_number(entry, "torque_constant", at, defaults.get("torque_constant"), True)
        return OmniSpec(name, (float(pos[0]), float(pos[1])), heading, radius, k_t)

    @classmethod
    def from_platform_dict(cls, data: Mapping[str, Any], where: str = "<platform>") -> OmniUnits:
        """The omni units of a parsed platform file (entries with ``type: omni``)."""
        defaults = {}
        for key in ("wheel_radius", "torque_constant"):
            if key in data:
                defaults[key] = _entry_number(data, key, where, None, True)
        alpha = _entry_number(data, "friction_tanh_gain", where, 10.0, True)
        units = data.get("units")
        if not isinstance(units, list):
            raise InputError(f"{where}: missing key 'units' (a list of unit entries)")
        specs = [cls.parse_entry(e, k, where, defaults) for k, e in enumerate(units)
                 if isinstance(e, Mapping) and e.get("type") == cls.type_name]
        if not specs:
            raise InputError(f"{where}: no unit has 'type: omni'")
        names = [s.name for s in specs]
        for name in names:
            if names.count(name) > 1:
                raise InputError(f"{where}: unit name {name!r} is used twice; names must be "
                                 "unique")
        return cls(specs, alpha)

    @staticmethod
    def channels(unit: str) -> tuple[Channel, ...]:
        """The log columns of one omni unit."""
        return (Channel(f"phi_{unit}", "rad", "wheel encoder angle, unwrapped"),
                Channel(f"cur_{unit}", "A", "motor current"))

    @staticmethod
    def friction_names(units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """Friction parameter names, ordered as :meth:`friction_columns`."""
        if _variant(variant) == "shared":
            return ["fov", "foc"]
        if variant == "body":
            return list(BODY_FRICTION)
        return [n for u in units for n in (f"fov_{u}", f"foc_{u}")]

    # ------------------------------------------------------------ kinematics
    def _world_headings(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ang = np.asarray(q, float)[:, 2:3] + self.headings  # θ + a_i, (N, k)
        return np.cos(ang), np.sin(ang)

    def kinematics(self, q: np.ndarray, qd: np.ndarray,
                   wheel_rate: np.ndarray | None = None) -> OmniData:
        """J_i, J̇_i q̇_b (O1, O2) for base pose q and twist qd (N, 3) in world coordinates.

        ``wheel_rate`` (measured φ̇, (N, k)) is used for friction and energy; when omitted it
        follows from the constraint O1.
        """
        q = np.asarray(q, float)
        qd = np.asarray(qd, float)
        ch, sh = self._world_headings(q)
        jac = np.empty((*ch.shape, 3))
        np.divide(ch, self.r, out=jac[..., 0])
        np.divide(sh, self.r, out=jac[..., 1])
        jac[..., 2] = self.moment_arm / self.r
        jdq = qd[:, 2:3] * (-sh * qd[:, 0:1] + ch * qd[:, 1:2]) / self.r
        if wheel_rate is None:
            wheel_rate = np.einsum("nkc,nc->nk", jac, qd)
        return OmniData(q[:, 2].copy(), qd, jac, jdq, np.asarray(wheel_rate, float))

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """φ̇_i = J_i q̇_b (O1) the base motion asks of the wheels; shape (N, k)."""
        ch, sh = self._world_headings(q)
        qd = np.asarray(qd, float)
        return (ch * qd[:, 0:1] + sh * qd[:, 1:2] + self.moment_arm * qd[:, 2:3]) / self.r

    def constraint_rows(self, q: np.ndarray,
                        joint_rates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rows A (N, k, 3), b (N, k) with A q̇_b = b from measured φ̇ (N, k) (O1, in m/s).

        Each row is the rim-speed equation r_i φ̇_i = H_iᵀ ṙ + c_i θ̇; wheel odometry stacks
        the rows of every unit and solves them by least squares. With θ = 0 in ``q`` the rows
        are those of the base-frame twist (v, v_n, ω) (004 eq. 2).
        """
        ch, sh = self._world_headings(q)
        a = np.empty((*ch.shape, 3))
        a[..., 0] = ch
        a[..., 1] = sh
        a[..., 2] = self.moment_arm
        return a, np.asarray(joint_rates, float) * self.r

    def torques(self, currents: np.ndarray) -> np.ndarray:
        """Wheel torques τ_i = k_t,i i_i (004 eq. 13) from motor currents (N, k)."""
        return np.asarray(currents, float) * self.k_t

    # ------------------------------------------------------------ dynamics
    def mass_terms(self, data: OmniData,
                   params: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(M_add (N, 3, 3), b_dir (N, 3)) of the group (O3)."""
        j = float(params["Jrot_o"])
        m_add = j * np.einsum("nkc,nkd->ncd", data.jac, data.jac)
        b_dir = -j * np.einsum("nkc,nk->nc", data.jac, data.jac_dot_qd)
        return m_add, b_dir

    def wheel_accelerations(self, data: OmniData, qdd: np.ndarray) -> np.ndarray:
        """φ̈_i = J_i q̈_b + J̇_i q̇_b; shape (N, k)."""
        return np.einsum("nkc,nc->nk", data.jac, qdd) + data.jac_dot_qd

    def a_id(self, data: OmniData, qdd: np.ndarray) -> np.ndarray:
        """Column of A_ID for J_rot,o: Σ_i J_iᵀ φ̈_i, the coefficient of J_rot,o in
        M_add q̈_b − b_dir (O3, thesis eq. 35); shape (N, 3, 1)."""
        return np.einsum("nkc,nk->nc", data.jac, self.wheel_accelerations(data, qdd))[..., None]

    def friction_torques(self, data: OmniData, params: Mapping[str, float],
                         variant: FrictionVariant = "per-wheel") -> np.ndarray:
        """τ_f,i = f_ov,i φ̇_i + f_oc,i tanh(α φ̇_i), added to the motor torque; (N, k).

        Missing coefficients are zero; with ``body`` friction the wheels have none.
        """
        if _variant(variant) == "body":
            return np.zeros_like(data.wheel_rate)
        if variant == "shared":
            fov = np.full(self.n_units, float(params.get("fov", 0.0)))
            foc = np.full(self.n_units, float(params.get("foc", 0.0)))
        else:
            fov = np.array([float(params.get(f"fov_{u}", 0.0)) for u in self.names])
            foc = np.array([float(params.get(f"foc_{u}", 0.0)) for u in self.names])
        phid = data.wheel_rate
        return fov * phid + foc * np.tanh(self.alpha * phid)

    def friction_columns(self, data: OmniData, variant: FrictionVariant = "per-wheel"
                         ) -> np.ndarray:
        """Columns of A_ID,ext for :meth:`friction_names` (thesis eq. 66); (N, 3, p_f).

        Wheel friction: −B_τ,i [φ̇_i, tanh(α φ̇_i)] (per wheel) or their sums (shared); body
        friction: :func:`body_friction_columns`.
        """
        if _variant(variant) == "body":
            return body_friction_columns(data.theta, data.qd, self.alpha)
        phid = data.wheel_rate
        a_f = np.stack([phid, np.tanh(self.alpha * phid)], axis=-1)  # (N, k, 2)
        cols = -data.b_tau[..., None] * a_f[:, None]  # (N, 3, k, 2)
        if variant == "shared":
            return cols.sum(axis=2)
        return cols.reshape(cols.shape[0], 3, -1)

    def kinetic_energy(self, data: OmniData, params: Mapping[str, float]) -> np.ndarray:
        """Σ_i ½ J_rot,o φ̇_i² [J]; shape (N,)."""
        return 0.5 * float(params["Jrot_o"]) * (data.wheel_rate**2).sum(axis=1)

    # ------------------------------------------------------------ report / inspect
    def unit_table(self) -> list[dict[str, float | str]]:
        """One row per unit for the report and ``inspect``: geometry and constants."""
        return [{"name": s.name, "type": self.type_name, "x [m]": s.position[0],
                 "y [m]": s.position[1], "heading [deg]": math.degrees(s.heading),
                 "moment arm c [m]": float(c), "wheel radius [m]": s.wheel_radius,
                 "torque constant [N m/A]": s.torque_constant}
                for s, c in zip(self.specs, self.moment_arm, strict=True)]

    def quantities(self, data: OmniData, q_fit: np.ndarray | None = None
                   ) -> dict[str, tuple[str, np.ndarray]]:
        """Per-unit signals (N, k) the report and ``inspect`` show, with their units.

        ``rim speed`` is r_i φ̇_i; given a base twist ``q_fit`` (N, 3) (odometry or tracker),
        ``slip`` is the rim speed minus the speed O1 asks for: nonzero where a wheel slips.
        """
        out = {"wheel rate": ("rad/s", data.wheel_rate),
               "rim speed": ("m/s", data.wheel_rate * self.r)}
        if q_fit is not None:
            out["slip"] = ("m/s", data.wheel_rate * self.r
                           - np.einsum("nkc,nc->nk", data.jac, q_fit) * self.r)
        return out


def body_velocity(theta: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """ν = (v, v_n, ω): the world twist in the robot frame (004 eq. 1); shape (N, 3)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * qd[:, 0] + s * qd[:, 1], -s * qd[:, 0] + c * qd[:, 1], qd[:, 2]],
                    axis=-1)


def body_friction_force(theta: np.ndarray, qd: np.ndarray, params: Mapping[str, float],
                        alpha: float) -> np.ndarray:
    """Generalized body-axis friction force in world coordinates, B_Fb F_f; (N, 3).

    F_f = f_bv ⊙ ν + f_bc ⊙ tanh(α ν) in the base frame (004 eqs. 6–8 with the signs of the
    contract: added, so dissipative coefficients are negative).
    """
    nu = body_velocity(theta, qd)
    fbv = np.array([float(params.get(n, 0.0)) for n in BODY_FRICTION[:3]])
    fbc = np.array([float(params.get(n, 0.0)) for n in BODY_FRICTION[3:]])
    f = fbv * nu + fbc * np.tanh(alpha * nu)
    return np.einsum("ncd,nd->nc", base.b_fb(theta), f)


def body_friction_columns(theta: np.ndarray, qd: np.ndarray, alpha: float) -> np.ndarray:
    """Columns of A_ID,ext for ``fbv_x … fbc_w``: −B_Fb e_j ν_j and −B_Fb e_j tanh(α ν_j);
    shape (N, 3, 6)."""
    nu = body_velocity(theta, qd)
    b = base.b_fb(theta)  # (N, 3, 3)
    return -np.concatenate([b * nu[:, None, :], b * np.tanh(alpha * nu)[:, None, :]], axis=2)
