"""The omni-wheel unit: one driven wheel with free rollers, fixed to the base (no pivot).

Conceição, Moreira and Costa's model of the 5DPO robot (cited as 004): kinematics 004 eqs. 1–5,
dynamics 004 eqs. 6–13. Everything is vectorised over samples N and the k units of the group:
arrays are (N, k, …).

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
dissipative friction has f_ov, f_oc ≤ 0. Per body axis as 004 eqs. 6–8 model it, the friction
acts on the base (:func:`ropod_sysid.model.base.body_friction_force`) and the wheels have none.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.model.units import (
    AnglePrediction,
    Channel,
    FrictionVariant,
    check_variant,
    integrated,
    series,
    trailing_start,
)
from ropod_sysid.model.units.entry import check_keys, number, point, resolved, unit_name


@dataclass(frozen=True)
class OmniSpec:
    """One omni unit as its platform-file entry describes it (SI units)."""

    name: str
    position: tuple[float, float]  # p_i in the base frame [m]
    heading: float  # a_i [rad]
    wheel_radius: float  # r_i [m]
    torque_constant: float  # k_t,i [N m/A], gearing included (004 eq. 13: l K_t)
    type: str = "omni"

    def moved(self, position: Sequence[float]) -> OmniSpec:
        """The same unit attached at ``position`` [m]."""
        return replace(self, position=(float(position[0]), float(position[1])))

    def to_entry(self, defaults: Mapping[str, Any]) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "type": self.type,
                             "position": [self.position[0], self.position[1]],
                             "heading": self.heading}
        for key in ("wheel_radius", "torque_constant"):
            if getattr(self, key) != defaults.get(key):
                d[key] = getattr(self, key)
        return d


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

    @property
    def angle_rate(self) -> np.ndarray:
        return self.wheel_rate

    @property
    def actuator_rate(self) -> np.ndarray:
        return self.wheel_rate


class OmniUnits:
    """k omni wheels of 004, fixed to the base: the ``omni`` unit type."""

    type_name = "omni"
    angles = (Channel("phi_{u}", "phi", "rad", "wheel encoder angle, unwrapped"),)
    currents = (Channel("cur_{u}", "cur", "A", "motor current"),)
    platform_keys = ("wheel_radius", "torque_constant")
    attachment_key = "position"  # the entry's attachment point (a leg replaces it)
    entry_keys = ("name", "type", "position", "heading", "wheel_radius", "torque_constant")
    inertial_names = ("Jrot_o",)
    parameter_info = {
        "Jrot_o": ("kg m²", "omni wheel + rotor inertia about the axle"),
        "fov": ("N m s/rad", "viscous omni-wheel friction"),
        "foc": ("N m", "Coulomb omni-wheel friction"),
    }
    friction_signs = {"fov": -1, "foc": -1}  # of dissipative friction (added to the torque)
    turning = None  # fixed to the base: no turning joint, nothing to plan for
    steering = None  # no actuated steering

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
    def parse_entry(cls, entry: Mapping[str, Any], k: int, where: str,
                    defaults: Mapping[str, float]) -> OmniSpec:
        """Validate the platform-file entry ``units[k]`` of an omni unit; one-line errors.

        ``defaults`` holds the platform-wide ``wheel_radius`` and ``torque_constant`` that the
        entry may override.
        """
        name = unit_name(entry, k, where, '{name: "1", type: omni, position: [x, y], '
                                          'heading: a}')
        at = f"{where}: 'units[{k}]' (unit '{name}')"
        check_keys(entry, cls.entry_keys, at, cls.type_name)
        pos = point(entry, "position", at, "the wheel centre in the base frame")
        if "heading" not in entry:
            raise InputError(f"{at}: missing key 'heading'; give the rolling direction in the "
                             "base frame [rad]")
        heading = number(entry, "heading", at)
        radius = resolved(entry, "wheel_radius", at, where, defaults, True,
                          "the wheel radius in metres")
        k_t = resolved(entry, "torque_constant", at, where, defaults, True, "k_t in N m/A")
        return OmniSpec(name, pos, heading, radius, k_t)

    @classmethod
    def group_key(cls, spec: OmniSpec) -> Hashable:
        return ()  # radius, heading and torque constant are per unit

    @classmethod
    def from_specs(cls, specs: Sequence[OmniSpec], friction_tanh_gain: float = 10.0
                   ) -> OmniUnits:
        return cls(specs, friction_tanh_gain)

    @classmethod
    def from_platform_dict(cls, data: Mapping[str, Any], where: str = "<platform>") -> OmniUnits:
        """The omni units of a parsed platform file (entries with ``type: omni``)."""
        from ropod_sysid.platform import platform_from_dict

        units = data.get("units")
        ours = [e for e in units if isinstance(e, Mapping) and e.get("type") == cls.type_name] \
            if isinstance(units, list) else []
        if not ours:
            raise InputError(f"{where}: no unit has 'type: omni'")
        platform = platform_from_dict(dict(data, units=ours), where, min_units=1)
        return cls(platform.units, platform.friction_tanh_gain)

    @classmethod
    def typical_parameters(cls, units: Sequence[str]) -> dict[str, float]:
        """Values of the order of the 5DPO robot's (004 Table III; the wheel inertia of a
        32.5 mm wheel with a 5:1 gear motor) with dissipative per-wheel friction."""
        rng = np.random.default_rng(2004)
        out = {"Jrot_o": 2.0e-4}
        for u in units:
            out[f"fov_{u}"] = -float(0.004 + 0.002 * rng.random())
            out[f"foc_{u}"] = -float(0.010 + 0.010 * rng.random())
        return out

    def torque_constants(self) -> np.ndarray:
        return self.k_t.copy()

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        return np.zeros(self.n_units)

    @staticmethod
    def friction_names(units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """Friction parameter names, ordered as :meth:`friction_columns`."""
        if check_variant(variant) == "shared":
            return ["fov", "foc"]
        if variant == "body":
            return []
        return [n for u in units for n in (f"fov_{u}", f"foc_{u}")]

    # ------------------------------------------------------------ kinematics
    def _world_headings(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ang = np.asarray(q, float)[:, 2:3] + self.headings  # θ + a_i, (N, k)
        return np.cos(ang), np.sin(ang)

    def kinematics(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray | None = None,
                   angle_rates: np.ndarray | None = None) -> OmniData:
        """J_i, J̇_i q̇_b (O1, O2) for base pose q and twist qd (N, 3) in world coordinates.

        ``angle_rates`` (measured φ̇, (N, k)) is used for friction and energy; when omitted it
        follows from the constraint O1. The wheel angles themselves do not enter.
        """
        wheel_rate = angle_rates
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

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray,
                       angles: np.ndarray | None = None) -> np.ndarray:
        """φ̇_i = J_i q̇_b (O1) the base motion asks of the wheels; shape (N, k)."""
        ch, sh = self._world_headings(q)
        qd = np.asarray(qd, float)
        return (ch * qd[:, 0:1] + sh * qd[:, 1:2] + self.moment_arm * qd[:, 2:3]) / self.r

    def angle_rates(self, q: np.ndarray, qd: np.ndarray,
                    angles: np.ndarray | None = None) -> np.ndarray:
        """The wheel rates (N, k) the base motion implies (O1)."""
        return self.actuator_rates(q, qd)

    def predict_angles(self, t: np.ndarray, twists: np.ndarray,
                       initial: np.ndarray | None = None) -> AnglePrediction:
        """Wheel angles along base-frame twists (…, N, 3): the integral (trapezoidal rule) of
        the wheel rates O1 asks for (θ-independent, so taken at θ = 0) from ``initial`` (…, k)
        (default :meth:`initial_angles`: zero). No turning joint, nothing to flag."""
        tw, lead = series(twists)
        n_var, n, _ = tw.shape
        rates = self.actuator_rates(np.zeros((n_var * n, 3)),
                                    tw.reshape(-1, 3)).reshape(n_var, n, self.n_units)
        start = trailing_start(self, tw) if initial is None else np.broadcast_to(
            np.asarray(initial, float).reshape(-1, self.n_units), (n_var, self.n_units))
        angles = integrated(t, rates, start)
        rates = rates.reshape(*lead, n, -1)
        return AnglePrediction(angles.reshape(*lead, n, -1), rates, rates)

    def quasi_steady_angles(self, t: np.ndarray, twists: np.ndarray,
                            twist_rates: np.ndarray) -> AnglePrediction:
        """The wheels follow the base without lag: :meth:`predict_angles`."""
        return self.predict_angles(t, twists)

    def constraint_rows(self, angles: np.ndarray, rates: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Rows A (N, k, 3), b (N, k) with A ν = b in the base-frame twist ν = (v, v_n, ω)
        from measured φ̇ (N, k) (O1 with θ = 0, in m/s; 004 eq. 2).

        Each row is the rim-speed equation r_i φ̇_i = h_iᵀ v + c_i ω; wheel odometry stacks
        the rows of every unit and solves them by least squares. ``rates`` may be increments
        (displacements instead of a twist).
        """
        rates = np.asarray(rates, float)
        a = np.empty((rates.shape[0], self.n_units, 3))
        a[..., 0] = np.cos(self.headings)
        a[..., 1] = np.sin(self.headings)
        a[..., 2] = self.moment_arm
        return a, rates * self.r

    def normal_equations(self, angles: np.ndarray, increments: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """AᵀA (N, 3, 3) and Aᵀb (N, 3) of :meth:`constraint_rows` (AᵀA is constant)."""
        a, b = self.constraint_rows(angles, increments)
        row = a[0]
        ata = np.broadcast_to(row.T @ row, (b.shape[0], 3, 3)).copy()
        return ata, b @ row

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

        A per-wheel coefficient missing from ``params`` is the shared one, else zero; with
        ``body`` friction the wheels have none.
        """
        if check_variant(variant) == "body":
            return np.zeros_like(data.wheel_rate)
        fov, foc = self._coefficients(params, variant)
        phid = data.wheel_rate
        return fov * phid + foc * np.tanh(self.alpha * phid)

    def _coefficients(self, params: Mapping[str, float], variant: FrictionVariant
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(f_ov, f_oc) per unit (k,): zero with ``body`` friction."""
        if variant == "body":
            return np.zeros(self.n_units), np.zeros(self.n_units)
        if variant == "shared":
            return (np.full(self.n_units, float(params.get("fov", 0.0))),
                    np.full(self.n_units, float(params.get("foc", 0.0))))
        return (np.array([float(params.get(f"fov_{u}", params.get("fov", 0.0)))
                          for u in self.names]),
                np.array([float(params.get(f"foc_{u}", params.get("foc", 0.0)))
                          for u in self.names]))

    def compiled(self, params: Mapping[str, float], variant: FrictionVariant = "per-wheel"
                 ) -> tuple[Any, np.ndarray, np.ndarray]:
        """The compiled one-sample kernel (:mod:`ropod_sysid.model.units.omni_jit`) and its
        geometry and parameter arrays (ImportError without numba)."""
        from ropod_sysid.model.units import omni_jit

        return omni_jit, *omni_jit.arrays(self, params, variant)

    def friction_force(self, data: OmniData, params: Mapping[str, float],
                       variant: FrictionVariant = "per-wheel") -> None:
        """No unactuated joint: all friction enters through B_τ (or the base's body axes)."""
        return None

    def friction_columns(self, data: OmniData, variant: FrictionVariant = "per-wheel",
                         out: np.ndarray | None = None) -> np.ndarray:
        """Columns of A_ID,ext for :meth:`friction_names` (thesis eq. 66); (N, 3, p_f).

        −B_τ,i [φ̇_i, tanh(α φ̇_i)] (per wheel) or their sums (shared); none with ``body``.
        """
        phid = data.wheel_rate
        if check_variant(variant) == "body":
            cols = np.zeros((phid.shape[0], 3, 0))
        else:
            a_f = np.stack([phid, np.tanh(self.alpha * phid)], axis=-1)  # (N, k, 2)
            full = -data.b_tau[..., None] * a_f[:, None]  # (N, 3, k, 2)
            cols = full.sum(axis=2) if variant == "shared" else full.reshape(
                full.shape[0], 3, -1)
        if out is not None:
            out[...] = cols
            return out
        return cols

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

