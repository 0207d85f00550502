"""The smart-wheel ("swivel") unit: a passive pivot with caster offset s_w and two driven wheels.

Thesis Sec. V-B (kinematics, eqs. 5–12), V-C (wheel and hub dynamics, eqs. 13–21),
V-D (parametrisations, eqs. 22–31) and App. B (matrix parametrisation, eqs. 43–48).
Everything is vectorised over samples N and the k units of the group: arrays are (N, k, …).

The parametrisations of eqs. 5–31 (the kinematics the dynamics below are built from, and
their notation) are in :mod:`ropod_sysid.model.units.swivel_kinematics`.

The unit type ``swivel`` (:mod:`ropod_sysid.model.units`). Per unit the log has the pivot angle
δ and the wheel angles φ_L, φ_R (in this order, the unit's angle channels) and the two motor
currents; its parameters are m_wh, J_zz,wh, J_rot,w (shared by all swivel units) and the roll and
pivot friction of App. D (eqs. 53–60).

Odometry (Sec. VI-B). Per sample interval the base twist that best explains the wheel and pivot
rates solves the no-slip constraints (8a) and (11), written in the base frame for unit i at pivot
(x, y) with angle δ:

    R_w φ̇_iL = c_δ v_x + s_δ v_y + ω (x s_δ − y c_δ) − (d_w/2)(ω + δ̇)     (11), wheel L
    R_w φ̇_iR = c_δ v_x + s_δ v_y + ω (x s_δ − y c_δ) + (d_w/2)(ω + δ̇)     (11), wheel R
    s_w (ω + δ̇) = −s_δ v_x + c_δ v_y + ω (x c_δ + y s_δ)                 (8a)

(v_x, v_y, ω: base twist in the base frame).

Friction (App. D). Roll friction τ_fw = f_wv φ̇ + f_wc tanh(α φ̇) is added to each wheel torque
(eqs. 53, 56–57); pivot friction τ_fp = f_pv δ̇ + f_pc tanh(α δ̇) acts on the base through B_τfp
(eqs. 58–60, 64). Dissipative roll friction has f_wv, f_wc ≤ 0, dissipative pivot friction
f_pv, f_pc ≥ 0.
"""

from __future__ import annotations

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
    swivel_kinematics,
    swivel_motion,
    unit_major,
)
from ropod_sysid.model.units.entry import check_keys, number, resolved, unit_name
from ropod_sysid.model.units.swivel_kinematics import SwivelData

GEOMETRY = ("wheel_radius", "wheel_distance", "caster_offset", "hub_com_offset")
KEY_TEXT = {"wheel_radius": "the wheel radius R_w in metres",
            "wheel_distance": "the distance d_w between the two wheels of a unit in metres",
            "torque_constant": "k_t in N m/A"}


@dataclass(frozen=True)
class SwivelSpec:
    """One smart-wheel unit as the platform file describes it (SI units).

    Attributes
    ----------
    name : str
        Unit name used in log columns (``delta_<name>``, ``phi_<name>L`` …).
    pivot : tuple[float, float]
        Attachment point r_ib/b^b in the base frame [m] (Table I, in metres).
    wheel_radius, wheel_distance, caster_offset, hub_com_offset : float
        R_w, d_w, s_w and Δx [m]: the platform-wide values unless the entry overrides them.
    torque_constant : float
        k_t [N m/A], gearing included.
    left_motor : int
        For the smart-wheel data layout: which motor (1 or 2) drives the left wheel.
    sign_left, sign_right : int
        Sign of each motor's encoder and current relative to the log's conventions (+1 or -1).
    pivot_offset : float
        Pivot encoder calibration [rad], subtracted from the raw pivot angle.
    """

    name: str
    pivot: tuple[float, float]
    wheel_radius: float = 0.0525
    wheel_distance: float = 0.08
    caster_offset: float = 0.01
    hub_com_offset: float = -0.005
    torque_constant: float = 0.28
    left_motor: int = 1
    sign_left: int = 1
    sign_right: int = 1
    pivot_offset: float = 0.0
    type: str = "swivel"
    ethercat_number: int | None = None  # the drive's EtherCAT slave number (KELO driver)

    @property
    def position(self) -> tuple[float, float]:
        return self.pivot

    @property
    def s_cm(self) -> float:
        """Pivot axis to hub centre of mass, s_cm = s_w − Δx [m] (below eq. 9)."""
        return self.caster_offset - self.hub_com_offset

    def moved(self, position: Sequence[float]) -> SwivelSpec:
        """The same unit attached at ``position`` [m]."""
        return replace(self, pivot=(float(position[0]), float(position[1])))

    def to_entry(self, defaults: Mapping[str, Any]) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "pivot": [self.pivot[0], self.pivot[1]]}
        for key in (*GEOMETRY, "torque_constant"):
            if getattr(self, key) != defaults.get(key):
                d[key] = getattr(self, key)
        for key, plain in (("left_motor", 1), ("sign_left", 1), ("sign_right", 1),
                           ("pivot_offset", 0.0), ("ethercat_number", None)):
            if getattr(self, key) != plain:
                d[key] = getattr(self, key)
        return d


class SwivelUnits:
    """k smart-wheel units of the thesis, attached at ``pivots`` (k, 2) in the base frame: the
    ``swivel`` unit type (units of one group share R_w, d_w, s_w, Δx)."""

    type_name = "swivel"
    angles = (Channel("delta_{u}", "delta", "rad", "pivot encoder angle", wrapped=True),
              Channel("phi_{u}L", "phi_L", "rad", "left wheel encoder angle, unwrapped"),
              Channel("phi_{u}R", "phi_R", "rad", "right wheel encoder angle, unwrapped"))
    currents = (Channel("cur_{u}L", "cur_L", "A", "left motor current"),
                Channel("cur_{u}R", "cur_R", "A", "right motor current"))
    platform_keys = (*GEOMETRY, "torque_constant")
    attachment_key = "pivot"  # the entry's attachment point (a leg replaces it)
    entry_keys = ("name", "type", "pivot", *GEOMETRY, "torque_constant", "left_motor",
                  "sign_left", "sign_right", "pivot_offset", "ethercat_number")
    inertial_names = ("m_wh", "Jzz_wh", "Jrot_w")
    parameter_info = {
        "m_wh": ("kg", "smart-wheel unit mass"),
        "Jzz_wh": ("kg m²", "smart-wheel unit inertia about z"),
        "Jrot_w": ("kg m²", "wheel inertia about its axle"),
        "fwv": ("N m s/rad", "viscous roll friction"),
        "fwc": ("N m", "Coulomb roll friction"),
        "fpv": ("N m s/rad", "viscous pivot friction"),
        "fpc": ("N m", "Coulomb pivot friction"),
    }
    friction_signs = {"fwv": -1, "fwc": -1, "fpv": 1, "fpc": 1}  # of dissipative friction
    turning = "pivot rate"  # δ̇: the unit trails its pivot (eq. 8a)
    steering = None  # the pivot is passive

    def __init__(self, pivots: np.ndarray, wheel_radius: float, wheel_distance: float,
                 caster_offset: float, hub_com_offset: float, names: Sequence[str] | None = None,
                 torque_constant: float | np.ndarray = 0.28,
                 friction_tanh_gain: float = 10.0) -> None:
        self.pivots = np.asarray(pivots, dtype=float).reshape(-1, 2)
        self.n_units = self.pivots.shape[0]
        self.names = list(names) if names is not None else [str(i + 1)
                                                            for i in range(self.n_units)]
        self.r_w = float(wheel_radius)
        self.d_w = float(wheel_distance)
        self.s_w = float(caster_offset)
        self.dx = float(hub_com_offset)
        self.s_cm = self.s_w - self.dx  # below eq. 9
        self.k_t = np.broadcast_to(np.asarray(torque_constant, float), (self.n_units,)).copy()
        self.alpha = float(friction_tanh_gain)
        # body-fixed vectors in the unit frame: hub CoM (9), wheel centres L, R (10)
        self.r_cm = np.array([-self.s_cm, 0.0])
        self.r_wheels = np.array([[-self.s_w, self.d_w / 2], [-self.s_w, -self.d_w / 2]])

    # ---------------------------------------------------------------- declaration
    @classmethod
    def parse_entry(cls, entry: Mapping[str, Any], k: int, where: str,
                    defaults: Mapping[str, float]) -> SwivelSpec:
        """Validate the platform-file entry ``units[k]`` of a smart-wheel unit; one-line
        errors. ``defaults`` holds the platform-wide geometry and torque constant."""
        name = unit_name(entry, k, where, '{name: "1", pivot: [x, y]}')
        key = f"units[{k}]"
        pivot = entry.get("pivot")
        if (not isinstance(pivot, list | tuple) or len(pivot) != 2
                or not all(isinstance(p, int | float) and not isinstance(p, bool)
                           for p in pivot)
                or not all(np.isfinite(float(p)) for p in pivot)):
            raise InputError(f"{where}: '{key}.pivot' must be two finite numbers [x, y] in "
                             "metres")
        at = f"{where}: '{key}' (unit '{name}')"
        check_keys(entry, cls.entry_keys, at, cls.type_name)
        left_motor = entry.get("left_motor", 1)
        if left_motor not in (1, 2):
            raise InputError(f"{where}: '{key}.left_motor' must be 1 or 2, got {left_motor!r}")
        signs = []
        for s in ("sign_left", "sign_right"):
            v = entry.get(s, 1)
            if v not in (1, -1):
                raise InputError(f"{where}: '{key}.{s}' must be 1 or -1, got {v!r}")
            signs.append(int(v))
        offset = number(entry, "pivot_offset", f"{where}: '{key}'", 0.0) \
            if "pivot_offset" in entry else 0.0
        geo = {g: resolved(entry, g, at, where, defaults, g in KEY_TEXT, KEY_TEXT.get(g, ""))
               for g in ("wheel_radius", "wheel_distance", "caster_offset")}
        dx = number(entry, "hub_com_offset", at) if "hub_com_offset" in entry else \
            float(defaults.get("hub_com_offset", 0.0))
        k_t = resolved(entry, "torque_constant", at, where, defaults, True, KEY_TEXT[
            "torque_constant"])
        if geo["caster_offset"] == 0:
            raise InputError(
                f"{at if 'caster_offset' in entry else where}: 'caster_offset' must be nonzero "
                "(the swivel model needs s_w ≠ 0); give the distance from the pivot axis to the "
                "wheel axle in metres")
        ethercat = entry.get("ethercat_number")
        if ethercat is not None and (isinstance(ethercat, bool) or not isinstance(ethercat, int)
                                     or ethercat < 1):
            raise InputError(f"{where}: '{key}.ethercat_number' must be a whole number ≥ 1 (the "
                             f"drive's EtherCAT slave number), got {ethercat!r}")
        return SwivelSpec(name, (float(pivot[0]), float(pivot[1])), geo["wheel_radius"],
                          geo["wheel_distance"], geo["caster_offset"], dx, k_t,
                          int(left_motor), signs[0], signs[1], offset, "swivel", ethercat)

    @classmethod
    def group_key(cls, spec: SwivelSpec) -> Hashable:
        return (spec.wheel_radius, spec.wheel_distance, spec.caster_offset, spec.hub_com_offset)

    @classmethod
    def from_specs(cls, specs: Sequence[SwivelSpec], friction_tanh_gain: float = 10.0
                   ) -> SwivelUnits:
        s0 = specs[0]
        return cls(np.array([s.pivot for s in specs], float), s0.wheel_radius,
                   s0.wheel_distance, s0.caster_offset, s0.hub_com_offset,
                   [s.name for s in specs], np.array([s.torque_constant for s in specs]),
                   friction_tanh_gain)

    @staticmethod
    def friction_names(units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """Roll then pivot friction (Table II order): ``fwv_1L, fwc_1L, fwv_1R, fwc_1R, …,
        fpv_1, fpc_1, …`` (eqs. 57, 60); shared ``fwv, fwc, fpv, fpc`` (56, 59)."""
        if check_variant(variant) == "body":
            return []
        if variant == "shared":
            return ["fwv", "fwc", "fpv", "fpc"]
        names = [f"{f}_{u}{w}" for u in units for w in "LR" for f in ("fwv", "fwc")]
        return names + [f"{f}_{u}" for u in units for f in ("fpv", "fpc")]

    @classmethod
    def typical_parameters(cls, units: Sequence[str]) -> dict[str, float]:
        """The ropod's values: the masses weighed in App. E, inertias and friction of the
        thesis's "fixed masses" column of Table II, made physically consistent (J ≥ 0,
        friction dissipative) so that they can drive a simulation."""
        n = len(units)
        rng = np.random.default_rng(2021)
        fwv = -np.abs(0.03 + 0.02 * rng.random((n, 2)))
        fwc = -np.abs(0.15 + 0.15 * rng.random((n, 2)))
        fpv = 0.15 + 0.07 * rng.random(n)
        fpc = 0.01 + 0.03 * rng.random(n)
        out = {"m_wh": 4.2, "Jzz_wh": 0.012, "Jrot_w": 0.0105}
        for i, u in enumerate(units):
            for j, w in enumerate("LR"):
                out[f"fwv_{u}{w}"] = float(fwv[i, j])
                out[f"fwc_{u}{w}"] = float(fwc[i, j])
        for i, u in enumerate(units):
            out[f"fpv_{u}"] = float(fpv[i])
            out[f"fpc_{u}"] = float(fpc[i])
        return out

    def torque_constants(self) -> np.ndarray:
        """k_t of each wheel (2k,), left and right per unit."""
        return np.repeat(self.k_t, 2)

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        """Pivot angles that trail a first motion with base-frame twist (vx, vy, ω): each
        pivot moves with v_i = (vx − ω y_i, vy + ω x_i) and its unit is aligned with it;
        wheel angles zero. Shape (3k,)."""
        vx, vy, w = np.asarray(twist, float)
        out = np.zeros((self.n_units, 3))
        if np.abs(twist).sum() > 1e-9:
            out[:, 0] = np.arctan2(vy + w * self.pivots[:, 0], vx - w * self.pivots[:, 1])
        return out.reshape(-1)

    # ---------------------------------------------------------------- planned motions
    def predict_angles(self, t: np.ndarray, twists: np.ndarray,
                       initial: np.ndarray | None = None) -> AnglePrediction:
        """Pivot angles along base-frame twists (…, N, 3) integrated with eq. 8a from
        ``initial`` (…, 3k) (default: trailing the first motion, :meth:`initial_angles`), the
        wheel angles integrated from the wheel rates of eq. 11 at them; turning rate δ̇ and the
        flag ``pulling (wheel flip)`` (:func:`~ropod_sysid.model.units.swivel_motion.predict`)."""
        return swivel_motion.predict(self, t, twists, initial)

    def quasi_steady_angles(self, t: np.ndarray, twists: np.ndarray,
                            twist_rates: np.ndarray) -> AnglePrediction:
        """Every unit trailing its pivot velocity at the quasi-steady lag of eq. 8a (δ̇ = ψ̇);
        wheel angles as in :meth:`predict_angles`
        (:func:`~ropod_sysid.model.units.swivel_motion.predict_quasi_steady`)."""
        return swivel_motion.predict_quasi_steady(self, t, twists, twist_rates)

    # ---------------------------------------------------------------- odometry
    def constraint_rows(self, angles: np.ndarray, rates: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Rows of eqs. 11 (L, R) and 8a in the base twist: A (N, 3k, 3) and b (N, 3k).

        ``angles`` (N, 3k) (δ, φ_L, φ_R per unit); ``rates`` (N, 3k) are rates [rad/s] (or
        increments [rad], which gives displacements instead of a twist).
        """
        delta = unit_major(angles, 3)[..., 0]
        r = unit_major(rates, 3)
        delta_rate, phi_rate = r[..., 0], r[..., 1:]
        x, y = self.pivots[:, 0], self.pivots[:, 1]
        r_w, d_w, s_w = self.r_w, self.d_w, self.s_w
        c, s = np.cos(delta), np.sin(delta)
        n_s, n_u = delta.shape
        fwd = x * s - y * c
        a = np.empty((n_s, n_u, 3, 3))
        b = np.empty((n_s, n_u, 3))
        a[..., 0, 0], a[..., 0, 1], a[..., 0, 2] = c, s, fwd - d_w / 2  # wheel L
        a[..., 1, 0], a[..., 1, 1], a[..., 1, 2] = c, s, fwd + d_w / 2  # wheel R
        a[..., 2, 0], a[..., 2, 1], a[..., 2, 2] = -s, c, x * c + y * s - s_w  # no side slip
        b[..., 0] = r_w * phi_rate[..., 0] + d_w / 2 * delta_rate
        b[..., 1] = r_w * phi_rate[..., 1] - d_w / 2 * delta_rate
        b[..., 2] = s_w * delta_rate
        return a.reshape(n_s, 3 * n_u, 3), b.reshape(n_s, 3 * n_u)

    def normal_equations(self, angles: np.ndarray, increments: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """AᵀA (N, 3, 3) and Aᵀb (N, 3) of :meth:`constraint_rows`, summed over the units
        without forming the (3k × 3) rows.

        Unit i contributes its rows L = (c, s, f − d_w/2), R = (c, s, f + d_w/2) and
        S = (−s, c, g), with f = x s_δ − y c_δ and g = x c_δ + y s_δ − s_w (eqs. 11, 8a).
        """
        x, y = self.pivots[:, :1], self.pivots[:, 1:]  # (k, 1): arrays below are (k, N)
        r_w, d_w, s_w = self.r_w, self.d_w, self.s_w
        ang = unit_major(angles, 3)
        inc = unit_major(increments, 3)
        delta_t = np.ascontiguousarray(ang[..., 0].T)
        rate_t = np.ascontiguousarray(inc[..., 0].T)
        phi_l = np.ascontiguousarray(inc[..., 1].T)
        phi_r = np.ascontiguousarray(inc[..., 2].T)
        c, s = np.cos(delta_t), np.sin(delta_t)
        f = x * s - y * c
        g = x * c + y * s - s_w
        b_sum = r_w * (phi_l + phi_r)  # b_L + b_R
        b_diff = r_w * (phi_r - phi_l) - d_w * rate_t  # b_R − b_L
        b_s = s_w * rate_t
        n_units, n = delta_t.shape
        cc = (c * c).sum(axis=0)
        ata = np.empty((n, 3, 3))
        ata[:, 0, 0] = n_units + cc
        ata[:, 0, 1] = ata[:, 1, 0] = (c * s).sum(axis=0)
        ata[:, 0, 2] = ata[:, 2, 0] = (2.0 * c * f - s * g).sum(axis=0)
        ata[:, 1, 1] = 2 * n_units - cc  # Σ 1 + s² = Σ 2 − c²
        ata[:, 1, 2] = ata[:, 2, 1] = (2.0 * s * f + c * g).sum(axis=0)
        ata[:, 2, 2] = (2.0 * f * f + g * g).sum(axis=0) + n_units * d_w * d_w / 2
        atb = np.empty((n, 3))
        atb[:, 0] = (c * b_sum - s * b_s).sum(axis=0)
        atb[:, 1] = (s * b_sum + c * b_s).sum(axis=0)
        atb[:, 2] = (f * b_sum + d_w / 2 * b_diff + g * b_s).sum(axis=0)
        return ata, atb

    # ---------------------------------------------------------------- kinematics
    def theta_i_dot(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """θ̇_i from the no-side-slip constraint (eq. 8a); shape (N, k)."""
        x, y = self.pivots[:, 0], self.pivots[:, 1]
        th_i = q[:, 2:3] + delta
        c_d, s_d = np.cos(delta), np.sin(delta)
        return (-np.sin(th_i) * qd[:, 0:1] + np.cos(th_i) * qd[:, 1:2]
                + qd[:, 2:3] * (x * c_d + y * s_d)) / self.s_w

    def joint_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """δ̇_i = θ̇_i − θ̇_b implied by the base motion (eq. 8a); shape (N, k)."""
        return self.theta_i_dot(q, qd, delta) - qd[:, 2:3]

    def wheel_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """φ̇_iw (N, k, 2) implied by the base motion: eqs. 8a, 10b and 11 in the unit frame,
        R_w φ̇_iw = c_δ v_x + s_δ v_y + θ̇_b (x s_δ − y c_δ) ∓ (d_w/2) θ̇_i (v in the base frame).
        """
        c_b, s_b = np.cos(q[:, 2:3]), np.sin(q[:, 2:3])
        vx = c_b * qd[:, 0:1] + s_b * qd[:, 1:2]  # base velocity in the base frame
        vy = -s_b * qd[:, 0:1] + c_b * qd[:, 1:2]
        w = qd[:, 2:3]
        x, y = self.pivots[:, 0], self.pivots[:, 1]
        c_d, s_d = np.cos(delta), np.sin(delta)
        th_i_dot = (-s_d * vx + c_d * vy + w * (x * c_d + y * s_d)) / self.s_w  # (8a)
        fwd = c_d * vx + s_d * vy + w * (x * s_d - y * c_d)
        half = 0.5 * self.d_w * th_i_dot
        return np.stack([fwd - half, fwd + half], axis=-1) / self.r_w

    def kinematics(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
                   angle_rates: np.ndarray | None = None) -> SwivelData:
        """:meth:`pivot_kinematics` for the group's angles (N, 3k) and their rates (the
        measured δ̇ is used; the wheel rates follow from the base motion, eq. 11)."""
        delta = unit_major(angles, 3)[..., 0]
        delta_dot = None if angle_rates is None else unit_major(angle_rates, 3)[..., 0]
        return self.pivot_kinematics(q, qd, delta, delta_dot)

    def angle_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """(δ̇ (8a), φ̇_L, φ̇_R (11)) per unit implied by the base motion; (N, 3k)."""
        return self.kinematics(q, qd, angles).angle_rate

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Wheel rates (N, 2k) the base motion asks for at the current pivot angles."""
        w = self.wheel_rates(q, qd, unit_major(angles, 3)[..., 0])
        return w.reshape(w.shape[0], -1)

    def pivot_kinematics(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray,
                         delta_dot: np.ndarray | None = None) -> SwivelData:
        """All parametrisations of eqs. 5–31 for base pose q, rate qd (N, 3), pivots δ (N, k)
        (:func:`~ropod_sysid.model.units.swivel_kinematics.pivot_kinematics`).

        ``delta_dot`` (measured δ̇) is used where the thesis uses δ̇_i (eq. 26) and to form
        θ̇_i = θ̇_b + δ̇_i; when omitted, θ̇_i follows from the constraint (8a).
        """
        return swivel_kinematics.pivot_kinematics(self, q, qd, delta, delta_dot)

    # ---------------------------------------------------------------- dynamics
    def _m_wh(self, params: Mapping[str, float]) -> np.ndarray:
        return np.diag([params["m_wh"], params["m_wh"], params["Jzz_wh"]])  # (19)

    def m_add(self, data: SwivelData, params: Mapping[str, float]) -> np.ndarray:
        """M_i,add = −B_Fixy A^{F_ixy}_{q̈_b} per unit (eqs. 22, 32, 49); shape (N, k, 3, 3).

        With F_iw = (τ_iw − J_rot,w φ̈_iw)/R_w (29) and q̈_icm (23):
        A^{F_ixyS}_{q̈_b} = A_iwh⁻¹ (M_wh A^{q̈_icm} + (J_rot,w/R_w) A_iwh2 A^{φ̈}).
        """
        inner = (self._m_wh(params) @ data.a_qcm
                 + (params["Jrot_w"] / self.r_w) * data.a_iwh2 @ data.a_phi)
        return -data.g @ inner

    def b_dir_units(self, data: SwivelData, params: Mapping[str, float]) -> np.ndarray:
        """b_dir,i = B_Fixy b^{F_ixy} per unit (eqs. 22, 32); shape (N, k, 3)."""
        inner = (np.einsum("cd,nkd->nkc", self._m_wh(params), data.b_qcm)
                 + (params["Jrot_w"] / self.r_w) * np.einsum("nkcw,nkw->nkc", data.a_iwh2,
                                                         data.b_phi))
        return np.einsum("nkcd,nkd->nkc", data.g, inner)

    def mass_terms(self, data: SwivelData,
                   params: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(Σ_i M_i,add, Σ_i b_dir,i) of the group (eq. 32)."""
        return self.m_add(data, params).sum(axis=1), self.b_dir_units(data, params).sum(axis=1)

    def a_id(self, data: SwivelData, qdd: np.ndarray) -> np.ndarray:
        """Columns of A_ID for [m_wh, J_zz,wh, J_rot,w], summed over units; (N, 3, 3).

        The unit's share of M_dir q̈_b − b_dir is −G (M_wh q̈_icm + (J_rot,w/R_w) A_iwh2 φ̈),
        linear in the three parameters (eq. 35): the same pieces as :meth:`m_add`.
        """
        qdd_cm = np.einsum("nkcq,nq->nkc", data.a_qcm, qdd) + data.b_qcm
        phidd = np.einsum("nkwq,nq->nkw", data.a_phi, qdd) + data.b_phi
        lin = qdd_cm.copy()
        lin[..., 2] = 0.0
        rot = np.zeros_like(qdd_cm)
        rot[..., 2] = qdd_cm[..., 2]
        roll = np.einsum("nkcw,nkw->nkc", data.a_iwh2, phidd) / self.r_w
        cols = np.stack([lin, rot, roll], axis=-1)  # (N, k, 3, 3)
        # (optimize: numpy then contracts by batched matmul, 4× faster here)
        return -np.einsum("nkcd,nkdp->ncp", data.g, cols, optimize=True)

    def hub_accelerations(self, data: SwivelData,
                          qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q̈_icm (N, k, 3), φ̈ (N, k, 2)) for a given base acceleration (eqs. 23, 30)."""
        qdd_cm = np.einsum("nkcq,nq->nkc", data.a_qcm, qdd) + data.b_qcm
        phidd = np.einsum("nkwq,nq->nkw", data.a_phi, qdd) + data.b_phi
        return qdd_cm, phidd

    def compiled(self, params: Mapping[str, float], variant: FrictionVariant = "per-wheel"
                 ) -> tuple[Any, np.ndarray, np.ndarray]:
        """The compiled one-sample kernel (:mod:`ropod_sysid.model.units.swivel_jit`) and its
        geometry and parameter arrays (ImportError without numba)."""
        from ropod_sysid.model.units import swivel_jit

        return swivel_jit, *swivel_jit.arrays(self, params, variant)

    def kinetic_energy(self, data: SwivelData, params: Mapping[str, float]) -> np.ndarray:
        """Σ_i ½ m_wh |ṙ_icm|² + ½ J_zz,wh θ̇_i² + ½ J_rot,w Σ_w φ̇_iw² [J]; shape (N,)."""
        t = (0.5 * params["m_wh"] * (data.rd_cm**2).sum(-1)
             + 0.5 * params["Jzz_wh"] * data.theta_i_dot**2
             + 0.5 * params["Jrot_w"] * (data.wheel_rate**2).sum(-1))
        return t.sum(axis=1)

    # ---------------------------------------------------------------- friction (App. D)
    def _coefficients(self, params: Mapping[str, float], variant: FrictionVariant
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(f_wv, f_wc (k, 2), f_pv, f_pc (k,)); a per-wheel coefficient missing from
        ``params`` is the shared one, else zero."""
        k = self.n_units
        if variant == "shared":
            return (np.full((k, 2), float(params.get("fwv", 0.0))),
                    np.full((k, 2), float(params.get("fwc", 0.0))),
                    np.full(k, float(params.get("fpv", 0.0))),
                    np.full(k, float(params.get("fpc", 0.0))))
        fwv, fwc = np.zeros((k, 2)), np.zeros((k, 2))
        for i, u in enumerate(self.names):
            for j, w in enumerate("LR"):
                fwv[i, j] = params.get(f"fwv_{u}{w}", params.get("fwv", 0.0))
                fwc[i, j] = params.get(f"fwc_{u}{w}", params.get("fwc", 0.0))
        fpv = np.array([float(params.get(f"fpv_{u}", params.get("fpv", 0.0)))
                        for u in self.names])
        fpc = np.array([float(params.get(f"fpc_{u}", params.get("fpc", 0.0)))
                        for u in self.names])
        return fwv, fwc, fpv, fpc

    def friction_torques(self, data: SwivelData, params: Mapping[str, float],
                         variant: FrictionVariant = "per-wheel") -> np.ndarray:
        """Roll friction τ_fw = f_wv φ̇ + f_wc tanh(α φ̇) (eqs. 53, 56–57); (N, 2k)."""
        n = data.wheel_rate.shape[0]
        if check_variant(variant) == "body":
            return np.zeros((n, 2 * self.n_units))
        fwv, fwc, _, _ = self._coefficients(params, variant)
        phid = data.wheel_rate
        return (fwv * phid + fwc * np.tanh(self.alpha * phid)).reshape(n, -1)

    def friction_force(self, data: SwivelData, params: Mapping[str, float],
                       variant: FrictionVariant = "per-wheel") -> np.ndarray | None:
        """Pivot friction B_τfp τ_fp with τ_fp = f_pv δ̇ + f_pc tanh(α δ̇) (eqs. 58–60, 64);
        (N, 3)."""
        if check_variant(variant) == "body":
            return None
        _, _, fpv, fpc = self._coefficients(params, variant)
        deltad = data.pivot_rate
        tau_fp = fpv * deltad + fpc * np.tanh(self.alpha * deltad)
        return np.einsum("ncu,nu->nc", data.b_tau_fp, tau_fp)

    def friction_columns(self, data: SwivelData, variant: FrictionVariant = "per-wheel",
                         out: np.ndarray | None = None) -> np.ndarray:
        """[−B_τ A_fw | −B_τfp A_fp] (eq. 66): roll friction columns (56/57), then pivot
        friction (59/60), ordered as :meth:`friction_names`; (N, 3, p_f), written into
        ``out`` when given."""
        n, k = data.pivot_rate.shape
        p_f = len(self.friction_names(self.names, variant))
        if out is None:
            out = np.empty((n, 3, p_f))
        if variant == "body":
            return out
        phid, deltad = data.wheel_rate, data.pivot_rate
        a_fw = np.stack([phid, np.tanh(self.alpha * phid)], axis=-1)  # (N, k, 2, 2)
        a_fp = np.stack([deltad, np.tanh(self.alpha * deltad)], axis=-1)  # (N, k, 2)
        b_tau, b_tau_fp = data.b_tau_w, data.b_tau_fp
        n_fw = 2 if variant == "shared" else 4 * k
        fw = out[:, :, :n_fw]
        fp = out[:, :, n_fw:]
        if variant == "shared":
            fw[...] = -np.einsum("ncuw,nuwf->ncf", b_tau, a_fw)
            fp[...] = -np.einsum("ncu,nuf->ncf", b_tau_fp, a_fp)
        else:
            # one (N, k, 2) or (N, k) plane at a time (see swivel_kinematics)
            fw5, fp4 = fw.reshape(n, 3, k, 2, 2), fp.reshape(n, 3, k, 2)
            neg_tau, neg_fp = -b_tau, -b_tau_fp
            for c in range(3):
                for f in range(2):
                    np.multiply(neg_tau[:, c], a_fw[..., f], out=fw5[:, c, :, :, f])
                    np.multiply(neg_fp[:, c], a_fp[..., f], out=fp4[:, c, :, f])
        return out

    # ---------------------------------------------------------------- report / inspect
    def unit_table(self) -> list[dict[str, float | str]]:
        """One row per unit for the report and ``inspect``: geometry and constants."""
        return [{"name": u, "type": self.type_name, "x [m]": float(p[0]), "y [m]": float(p[1]),
                 "wheel radius [m]": self.r_w, "wheel distance [m]": self.d_w,
                 "caster offset [m]": self.s_w, "torque constant [N m/A]": float(kt)}
                for u, p, kt in zip(self.names, self.pivots, self.k_t, strict=True)]

    def quantities(self, data: SwivelData, q_fit: np.ndarray | None = None
                   ) -> dict[str, tuple[str, np.ndarray]]:
        """Per-unit signals (N, k): pivot rate, the two wheel rates."""
        return {"pivot rate": ("rad/s", data.pivot_rate),
                "left wheel rate": ("rad/s", data.wheel_rate[..., 0]),
                "right wheel rate": ("rad/s", data.wheel_rate[..., 1])}


# ---------------------------------------------------------------- logs of smart-wheel platforms
def check_all_swivel(platform: Any, what: str) -> None:
    """A one-line error unless every unit of the platform is a smart wheel."""
    other = [u.name for u in platform.units if u.type != SwivelUnits.type_name]
    if other:
        raise InputError(f"{platform.source}: {what} carries smart-wheel (swivel) units only; "
                         f"unit{'s' if len(other) > 1 else ''} {', '.join(other)} "
                         f"{'are' if len(other) > 1 else 'is'} of another type")


def from_arrays(platform: Any, t: np.ndarray, delta: np.ndarray, phi: np.ndarray,
                current: np.ndarray, pose: np.ndarray | None = None,
                source: str = "<memory>", notes: list[str] | None = None) -> Any:
    """The log of an all-swivel platform from its arrays: pivot angles δ (N, n), wheel angles
    φ (N, n, 2) and currents (N, n, 2) (wheels L, R per unit)."""
    from ropod_sysid.io.log import Log

    check_all_swivel(platform, "this log")
    delta = np.asarray(delta, float)
    n, k = delta.shape
    angles = np.empty((n, k, 3))
    angles[..., 0] = delta
    angles[..., 1:] = phi
    return Log(np.asarray(t, float), platform.layout, angles.reshape(n, 3 * k),
               np.ascontiguousarray(np.asarray(current, float).reshape(n, 2 * k)), pose, source,
               list(notes or []))


def arrays(log: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(δ (N, n), φ (N, n, 2), currents (N, n, 2)) of the log of an all-swivel platform."""
    a = unit_major(log.angles, 3)
    return (np.ascontiguousarray(a[..., 0]), np.ascontiguousarray(a[..., 1:]),
            np.asarray(log.currents, float).reshape(log.currents.shape[0], -1, 2))


def angles_of(delta: np.ndarray) -> np.ndarray:
    """Unit angles (…, 3n) of an all-swivel platform with pivot angles δ (…, n) and wheel
    angles zero (the wheel angles do not enter the model: only their rates do)."""
    delta = np.asarray(delta, float)
    out = np.zeros((*delta.shape, 3))
    out[..., 0] = delta
    return out.reshape(*delta.shape[:-1], 3 * delta.shape[-1])
