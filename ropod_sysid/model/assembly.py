"""The base plus the sum over wheel units: the direct equations of motion (thesis eqs. 32, 65)

    M_dir q̈_b = B_Fb F_b + B_τ (τ + τ_f) + f_f + b_dir,

forward dynamics (33), minimum-norm inverse dynamics (34), the disturbance estimate (40) and
the identification regressor A_ID,ext (eqs. 35, 36, 66) — all from the same per-unit pieces.
τ holds every actuator's torque, τ_f the friction torques added to them, and f_f the
generalized friction force of unactuated joints (the swivel's pivots: B_τfp τ_fp, eq. 64) and,
with body-axis friction, of the base (:func:`ropod_sysid.model.base.body_friction_force`).

Shapes: q, qd, qdd (N, 3); unit angles (N, J) and actuator torques (N, A) in the platform's
channel order (:class:`ropod_sysid.platform.Layout`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.model import base
from ropod_sysid.model.units import FrictionVariant, UnitData, check_variant
from ropod_sysid.params import Friction, parameter_names

if TYPE_CHECKING:
    from ropod_sysid.platform import Group, Platform


def _gather(parts: list[tuple[np.ndarray, np.ndarray]], size: int, axis: int) -> np.ndarray:
    """Per-group arrays (indices, values) placed at their indices along ``axis``."""
    if len(parts) == 1 and np.array_equal(parts[0][0], np.arange(size)):
        return parts[0][1]
    shape = list(parts[0][1].shape)
    shape[axis] = size
    out = np.empty(shape)
    for idx, values in parts:
        sl = [slice(None)] * len(shape)
        sl[axis] = idx  # type: ignore[call-overload]
        out[tuple(sl)] = values
    return out


@dataclass
class State:
    """Kinematic data of the whole platform at N samples (pinocchio's "data")."""

    q: np.ndarray  # (N, 3)
    qd: np.ndarray  # (N, 3)
    angles: np.ndarray  # (N, J)
    units: list[UnitData]  # one per unit group
    groups: tuple[Group, ...]
    n_angles: int
    n_actuators: int

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ (N, 3, A) over every actuator (eq. 32)."""
        return _gather([(g.currents, d.b_tau) for g, d in zip(self.groups, self.units,
                                                             strict=True)],
                       self.n_actuators, 2)

    @property
    def angle_rate(self) -> np.ndarray:
        """Rates of the unit angles (N, J)."""
        return _gather([(g.angles, d.angle_rate) for g, d in zip(self.groups, self.units,
                                                                strict=True)],
                       self.n_angles, 1)

    @property
    def actuator_rate(self) -> np.ndarray:
        """Rates of the actuated joints (N, A)."""
        return _gather([(g.currents, d.actuator_rate) for g, d in zip(self.groups, self.units,
                                                                     strict=True)],
                       self.n_actuators, 1)


@dataclass
class DirectEOM:
    """The terms of eq. 65 at N samples."""

    m_dir: np.ndarray  # (N, 3, 3)
    b_fb: np.ndarray  # (N, 3, 3)
    b_tau: np.ndarray  # (N, 3, A)
    b_dir: np.ndarray  # (N, 3)
    tau_f: np.ndarray  # (N, A) friction torques added to the actuator torques (eqs. 56/57)
    f_f: np.ndarray | None  # (N, 3) other friction, as a generalized force (eq. 64: B_τfp τ_fp)

    def generalized_force(self, tau: np.ndarray, f_b: np.ndarray | None = None) -> np.ndarray:
        """Right-hand side of eq. 65 for actuator torques τ (N, A) and F_b (N, 3)."""
        rhs = np.einsum("nca,na->nc", self.b_tau, tau + self.tau_f)
        if self.f_f is not None:
            rhs = rhs + self.f_f
        rhs = rhs + self.b_dir
        if f_b is not None:
            rhs = rhs + np.einsum("ncd,nd->nc", self.b_fb, f_b)
        return rhs


class PlatformModel:
    """The modular model of a platform: the base and its groups of wheel units.

    Units of one type that share their geometry form one group (vectorised over the group);
    groups are summed (eq. 32).
    """

    def __init__(self, platform: Platform) -> None:
        self.platform = platform
        self.alpha = platform.friction_tanh_gain
        self.n_units = platform.n_units
        self.layout = platform.layout
        self.groups: list[tuple[Group, object]] = [
            (g, g.type.from_specs(g.specs, self.alpha)) for g in platform.groups]
        self._columns: dict[str, list[tuple[np.ndarray | slice, np.ndarray | slice]]] = {}

    # ------------------------------------------------------------ kinematics
    def state(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
              angle_rates: np.ndarray | None = None) -> State:
        """Kinematics of every unit group for base motion (q, qd) and unit angles (N, J);
        ``angle_rates`` (N, J) are the measured rates where a type uses them."""
        q = np.atleast_2d(np.asarray(q, float))
        qd = np.atleast_2d(np.asarray(qd, float))
        angles = np.atleast_2d(np.asarray(angles, float))
        units = []
        for g, unit in self.groups:
            rates = None if angle_rates is None else _take(angle_rates, g.angles, 1)
            units.append(unit.kinematics(q, qd, _take(angles, g.angles, 1), rates))
        return State(q, qd, angles, units, tuple(g for g, _ in self.groups),
                     self.layout.n_angles, self.layout.n_currents)

    def angle_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Rates of the unit angles implied by the base motion (N, J) (for the swivel: δ̇ of
        eq. 8a and φ̇ of eq. 11)."""
        parts = [(g.angles, u.angle_rates(q, qd, _take(angles, g.angles, 1)))
                 for g, u in self.groups]
        return _gather(parts, self.layout.n_angles, 1)

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Actuator rates (N, A) that the base motion (q, qd) asks for at the unit angles: the
        inverse kinematics a velocity controller uses."""
        parts = [(g.currents, u.actuator_rates(q, qd, _take(angles, g.angles, 1)))
                 for g, u in self.groups]
        return _gather(parts, self.layout.n_currents, 1)

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        """Unit angles (J,) at rest before a first motion with base-frame twist (3,)."""
        parts = [(g.angles, u.initial_angles(twist)[None]) for g, u in self.groups]
        return _gather(parts, self.layout.n_angles, 1)[0]

    # ------------------------------------------------------------ dynamics
    def friction(self, st: State, params: object, friction: Friction = "per-wheel"
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """Friction torques τ_f (N, A) added to the actuator torques and the generalized
        friction force f_f (N, 3) of the unactuated joints and the base (or None)."""
        check_variant(friction)
        parts, f_f = [], None
        for (g, unit), data in zip(self.groups, st.units, strict=True):
            parts.append((g.currents, unit.friction_torques(data, params, friction)))
            f = unit.friction_force(data, params, friction)
            if f is not None:
                f_f = f if f_f is None else f_f + f
        if friction == "body":
            f = base.body_friction_force(st.q[:, 2], st.qd, params, self.alpha)
            f_f = f if f_f is None else f_f + f
        return _gather(parts, self.layout.n_currents, 1), f_f

    def direct_eom(self, st: State, params: object,
                   friction: Friction = "per-wheel") -> DirectEOM:
        """M_dir, B_Fb, B_τ, b_dir and the friction terms (eqs. 32, 64, 65)."""
        n = st.q.shape[0]
        m_dir = base.m_b(params["m_b"], params["Jzz_b"], n)  # (49): M_dir = M_b + Σ M_i,add
        b_dir = np.zeros((n, 3))
        for (_, unit), data in zip(self.groups, st.units, strict=True):
            m_add, b_add = unit.mass_terms(data, params)
            m_dir = m_dir + m_add
            b_dir = b_dir + b_add
        tau_f, f_f = self.friction(st, params, friction)
        return DirectEOM(m_dir, base.b_fb(st.q[:, 2]), st.b_tau, b_dir, tau_f, f_f)

    def forward_dynamics(self, st: State, params: object, tau: np.ndarray,
                         f_b: np.ndarray | None = None,
                         friction: Friction = "per-wheel") -> np.ndarray:
        """q̈_b = M_dir⁻¹ (B_Fb F_b + B_τ (τ + τ_f) + f_f + b_dir) (eqs. 33, 65)."""
        eom = self.direct_eom(st, params, friction)
        rhs = eom.generalized_force(tau, f_b)
        return np.linalg.solve(eom.m_dir, rhs[..., None])[..., 0]

    def inverse_dynamics(self, st: State, params: object, qdd: np.ndarray,
                         f_b: np.ndarray | None = None,
                         friction: Friction = "per-wheel") -> np.ndarray:
        """Minimum-norm actuator torques τ = B_τ⁺ (M_dir q̈ − B_Fb F_b − f_f − b_dir) − τ_f
        (eq. 34); (N, A).

        Friction is compensated: the returned τ plus τ_f is the minimum-norm solution for the
        total actuator torque, with the other friction moved to the right-hand side.
        """
        eom = self.direct_eom(st, params, friction)
        need = np.einsum("ncd,nd->nc", eom.m_dir, qdd) - eom.b_dir
        if eom.f_f is not None:
            need -= eom.f_f
        if f_b is not None:
            need -= np.einsum("ncd,nd->nc", eom.b_fb, f_b)
        total = np.einsum("nac,nc->na", np.linalg.pinv(eom.b_tau), need)
        return total - eom.tau_f

    def disturbance(self, st: State, params: object, qdd: np.ndarray, tau: np.ndarray,
                    friction: Friction = "per-wheel") -> np.ndarray:
        """F_b = B_Fb⁻¹ (M_dir q̈ − B_τ (τ + τ_f) − f_f − b_dir) (eq. 40); (N, 3)."""
        eom = self.direct_eom(st, params, friction)
        resid = np.einsum("ncd,nd->nc", eom.m_dir, qdd) - eom.generalized_force(tau)
        # B_Fb is a rotation about z (det = 1, eq. 3): its inverse is its transpose
        return np.einsum("ndc,nd->nc", eom.b_fb, resid)

    def kinetic_energy(self, st: State, params: object) -> np.ndarray:
        """Total kinetic energy of base and units [J]; equals ½ q̇ᵀ M_dir q̇ (App. C)."""
        t = base.kinetic_energy_base(params["m_b"], params["Jzz_b"], st.qd)
        for (_, unit), data in zip(self.groups, st.units, strict=True):
            t = t + unit.kinetic_energy(data, params)
        return t

    # ------------------------------------------------------------ identification
    def _layout(self, friction: FrictionVariant
                ) -> list[tuple[np.ndarray | slice, np.ndarray | slice]]:
        """Per group, where its inertial and friction columns go in A_ID,ext."""
        if friction not in self._columns:
            index = {n: i for i, n in enumerate(self.parameter_names(friction))}
            spots = []
            for g, unit in self.groups:
                spots.append((_spot([index[n] for n in g.type.inertial_names]),
                              _spot([index[n] for n in g.type.friction_names(unit.names,
                                                                             friction)])))
            self._columns[friction] = spots
        return self._columns[friction]

    def a_id_ext(self, st: State, qdd: np.ndarray,
                 friction: Friction = "per-wheel") -> np.ndarray:
        """A_ID,ext (N, 3, p) with columns ordered as :func:`parameter_names` (eq. 66).

        [A_ID | friction columns]: the base and unit inertial columns (35), then each unit
        type's friction columns (for the swivel: −B_τ A_fw, −B_τfp A_fp, eqs. 56/57, 59/60),
        or the base's body-axis friction columns.
        """
        check_variant(friction)
        n = qdd.shape[0]
        names = self.parameter_names(friction)
        out = np.empty((n, 3, len(names)))
        out[:, :, :2] = base.a_id_base(qdd)
        out[:, :, 2:] = 0.0
        spots = self._layout(friction)
        shared = self._shared_spots(spots)
        for (_, unit), data, (inert, fric) in zip(self.groups, st.units, spots, strict=True):
            out[:, :, inert] += unit.a_id(data, qdd)
            if friction == "body":
                continue
            if isinstance(fric, slice) and fric not in shared:
                unit.friction_columns(data, friction, out=out[:, :, fric])
            else:
                out[:, :, fric] += unit.friction_columns(data, friction)
        if friction == "body":
            out[:, :, len(names) - len(base.BODY_FRICTION):] = base.body_friction_columns(
                st.q[:, 2], st.qd, self.alpha)
        return out

    @staticmethod
    def _shared_spots(spots: list[tuple[np.ndarray | slice, np.ndarray | slice]]
                      ) -> list[slice]:
        """Friction slices that more than one group writes (shared coefficients)."""
        seen: list[slice] = []
        twice: list[slice] = []
        for _, fric in spots:
            if isinstance(fric, slice):
                if fric in seen:
                    twice.append(fric)
                seen.append(fric)
        return twice

    def b_id(self, st: State, tau: np.ndarray, f_b: np.ndarray | None = None) -> np.ndarray:
        """b_ID = B_Fb F_b + B_τ τ (eq. 35); (N, 3). F_b is zero in identification runs."""
        out = np.einsum("nca,na->nc", st.b_tau, tau)
        if f_b is not None:
            out = out + np.einsum("ncd,nd->nc", base.b_fb(st.q[:, 2]), f_b)
        return out

    def parameter_names(self, friction: Friction = "per-wheel") -> list[str]:
        return parameter_names(self.platform, friction)


def _take(values: np.ndarray, idx: np.ndarray, axis: int) -> np.ndarray:
    """``values`` at ``idx`` along ``axis``; the array itself when ``idx`` covers it all."""
    values = np.asarray(values, float)
    if idx.size == values.shape[axis] and np.array_equal(idx, np.arange(idx.size)):
        return values
    return np.take(values, idx, axis=axis)


def _spot(idx: list[int]) -> np.ndarray | slice:
    """Column indices as a slice when they are consecutive (writes in place), else an array."""
    if idx and idx == list(range(idx[0], idx[0] + len(idx))):
        return slice(idx[0], idx[0] + len(idx))
    return np.array(idx, int)
