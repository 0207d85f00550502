"""The base plus the sum over wheel units: the direct equations of motion (thesis eqs. 32, 65)

    M_dir q̈_b = B_Fb F_b + B_τ (τ + τ_fw) + B_τfp τ_fp + b_dir,

forward dynamics (33), minimum-norm inverse dynamics (34), the disturbance estimate (40) and
the identification regressor A_ID,ext (eqs. 35, 36, 66) — all from the same per-unit pieces.

Shapes: q, qd, qdd (N, 3); δ (N, n); τ (N, n, 2) with wheels ordered L, R per unit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ropod_sysid.model import base
from ropod_sysid.model.swivel import SwivelUnits
from ropod_sysid.model.unit import UnitData, UnitModel
from ropod_sysid.params import DynamicParameters, Friction, parameter_names
from ropod_sysid.platform import Platform

UNIT_TYPES: dict[str, type] = {"swivel": SwivelUnits}


@dataclass
class State:
    """Kinematic data of the whole platform at N samples."""

    q: np.ndarray  # (N, 3)
    qd: np.ndarray  # (N, 3)
    delta: np.ndarray  # (N, n)
    units: list[UnitData]  # one per unit group

    @property
    def wheel_rate(self) -> np.ndarray:
        """φ̇ (N, n, 2) in platform unit order."""
        return np.concatenate([u.wheel_rate for u in self.units], axis=1)

    @property
    def pivot_rate(self) -> np.ndarray:
        """δ̇ (N, n)."""
        return np.concatenate([u.pivot_rate for u in self.units], axis=1)

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ (N, 3, n, 2) (eq. 32)."""
        return np.concatenate([u.b_tau for u in self.units], axis=2)

    @property
    def b_tau_fp(self) -> np.ndarray:
        """B_τfp (N, 3, n) (eq. 64)."""
        return np.concatenate([u.b_tau_fp for u in self.units], axis=2)


@dataclass
class DirectEOM:
    """The terms of eq. 65 at N samples."""

    m_dir: np.ndarray  # (N, 3, 3)
    b_fb: np.ndarray  # (N, 3, 3)
    b_tau: np.ndarray  # (N, 3, n, 2)
    b_tau_fp: np.ndarray  # (N, 3, n)
    b_dir: np.ndarray  # (N, 3)
    tau_fw: np.ndarray  # (N, n, 2) roll friction torques (eq. 56/57)
    tau_fp: np.ndarray  # (N, n) pivot friction torques (eq. 59/60)

    def generalized_force(self, tau: np.ndarray, f_b: np.ndarray | None = None) -> np.ndarray:
        """Right-hand side of eq. 65 for wheel torques τ (N, n, 2) and F_b (N, 3)."""
        rhs = (np.einsum("ncuw,nuw->nc", self.b_tau, tau + self.tau_fw)
               + np.einsum("ncu,nu->nc", self.b_tau_fp, self.tau_fp) + self.b_dir)
        if f_b is not None:
            rhs = rhs + np.einsum("ncd,nd->nc", self.b_fb, f_b)
        return rhs


class PlatformModel:
    """The modular model of a platform: the base and its groups of wheel units.

    Units of one type form one group (vectorised over the group); groups are summed (eq. 32).
    """

    def __init__(self, platform: Platform) -> None:
        self.platform = platform
        self.alpha = platform.friction_tanh_gain
        self.n_units = platform.n_units
        self.groups: list[tuple[list[int], UnitModel]] = []
        for utype, cls in UNIT_TYPES.items():
            idx = [i for i, u in enumerate(platform.units) if u.type == utype]
            if idx:
                self.groups.append((idx, cls.from_platform(platform, idx)))
        order = [i for idx, _ in self.groups for i in idx]
        # permutation from group-concatenated order back to platform order
        self._perm = np.argsort(order)
        self._identity = order == list(range(self.n_units))

    def _to_platform_order(self, a: np.ndarray, axis: int) -> np.ndarray:
        return a if self._identity else np.take(a, self._perm, axis=axis)

    # ------------------------------------------------------------ kinematics
    def state(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray,
              delta_dot: np.ndarray | None = None) -> State:
        """Kinematics of every unit group for base motion (q, qd) and pivot angles δ."""
        q = np.atleast_2d(np.asarray(q, float))
        qd = np.atleast_2d(np.asarray(qd, float))
        delta = np.atleast_2d(np.asarray(delta, float))
        units = []
        for idx, group in self.groups:
            dd = None if delta_dot is None else np.asarray(delta_dot, float)[:, idx]
            units.append(group.kinematics(q, qd, delta[:, idx], dd))
        st = State(q, qd, delta, units)
        if not self._identity:  # expose platform order through a reordered single view
            st = _ReorderedState(st, self)
        return st

    def joint_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """δ̇ implied by the base motion (N, n) (eq. 8a)."""
        parts = [g.joint_rates(q, qd, delta[:, idx]) for idx, g in self.groups]
        return self._to_platform_order(np.concatenate(parts, axis=1), 1)

    def wheel_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """φ̇ (N, n, 2) that the base motion (q, qd) asks of the wheels at pivots δ (eqs. 8a,
        10b, 11): the inverse kinematics a velocity controller uses."""
        parts = [g.wheel_rates(q, qd, delta[:, idx]) for idx, g in self.groups]
        return self._to_platform_order(np.concatenate(parts, axis=1), 1)

    # ------------------------------------------------------------ dynamics
    def friction(self, st: State, params: DynamicParameters) -> tuple[np.ndarray, np.ndarray]:
        """Roll friction τ_fw (N, n, 2) (eqs. 53, 57) and pivot friction τ_fp (N, n) (58, 60)."""
        phid, deltad = st.wheel_rate, st.pivot_rate
        tau_fw = params.fwv * phid + params.fwc * np.tanh(self.alpha * phid)
        tau_fp = params.fpv * deltad + params.fpc * np.tanh(self.alpha * deltad)
        return tau_fw, tau_fp

    def direct_eom(self, st: State, params: DynamicParameters) -> DirectEOM:
        """M_dir, B_Fb, B_τ, B_τfp, b_dir and the friction torques (eqs. 32, 64, 65)."""
        n = st.q.shape[0]
        m_dir = base.m_b(params.m_b, params.Jzz_b, n)  # (49): M_dir = M_b + Σ M_i,add
        b_dir = np.zeros((n, 3))
        for (_, group), data in zip(self.groups, st.units, strict=True):
            m_add, b_add = group.mass_terms(data, params)
            m_dir = m_dir + m_add
            b_dir = b_dir + b_add
        tau_fw, tau_fp = self.friction(st, params)
        return DirectEOM(m_dir, base.b_fb(st.q[:, 2]), st.b_tau, st.b_tau_fp, b_dir, tau_fw,
                         tau_fp)

    def forward_dynamics(self, st: State, params: DynamicParameters, tau: np.ndarray,
                         f_b: np.ndarray | None = None) -> np.ndarray:
        """q̈_b = M_dir⁻¹ (B_Fb F_b + B_τ (τ + τ_fw) + B_τfp τ_fp + b_dir) (eqs. 33, 65)."""
        eom = self.direct_eom(st, params)
        rhs = eom.generalized_force(tau, f_b)
        return np.linalg.solve(eom.m_dir, rhs[..., None])[..., 0]

    def inverse_dynamics(self, st: State, params: DynamicParameters, qdd: np.ndarray,
                         f_b: np.ndarray | None = None) -> np.ndarray:
        """Minimum-norm wheel torques τ = B_τ⁺ (M_dir q̈ − B_Fb F_b − b_dir) − τ_fw (eq. 34).

        Friction is compensated: the returned τ plus τ_fw is the minimum-norm solution for the
        total wheel torque, with pivot friction moved to the right-hand side.
        """
        eom = self.direct_eom(st, params)
        need = np.einsum("ncd,nd->nc", eom.m_dir, qdd) - eom.b_dir
        need -= np.einsum("ncu,nu->nc", eom.b_tau_fp, eom.tau_fp)
        if f_b is not None:
            need -= np.einsum("ncd,nd->nc", eom.b_fb, f_b)
        n = qdd.shape[0]
        b = eom.b_tau.reshape(n, 3, -1)
        total = np.einsum("nuc,nc->nu", np.linalg.pinv(b), need)
        return total.reshape(n, -1, 2) - eom.tau_fw

    def disturbance(self, st: State, params: DynamicParameters, qdd: np.ndarray,
                    tau: np.ndarray) -> np.ndarray:
        """F_b = B_Fb⁻¹ (M_dir q̈ − B_τ (τ + τ_fw) − B_τfp τ_fp − b_dir) (eq. 40); (N, 3)."""
        eom = self.direct_eom(st, params)
        resid = np.einsum("ncd,nd->nc", eom.m_dir, qdd) - eom.generalized_force(tau)
        # B_Fb is a rotation about z (det = 1, eq. 3): its inverse is its transpose
        return np.einsum("ndc,nd->nc", eom.b_fb, resid)

    def kinetic_energy(self, st: State, params: DynamicParameters) -> np.ndarray:
        """Total kinetic energy of base and units [J]; equals ½ q̇ᵀ M_dir q̇ (App. C)."""
        t = base.kinetic_energy_base(params.m_b, params.Jzz_b, st.qd)
        for (_, group), data in zip(self.groups, st.units, strict=True):
            t = t + group.kinetic_energy(data, params)
        return t

    # ------------------------------------------------------------ identification
    def a_id_ext(self, st: State, qdd: np.ndarray,
                 friction: Friction = "per-wheel") -> np.ndarray:
        """A_ID,ext (N, 3, p) with columns ordered as :func:`parameter_names` (eq. 66).

        [A_ID | −B_τ A_fw | −B_τfp A_fp]: base and unit inertial columns (35), then roll
        friction (56/57) and pivot friction (59/60) columns.
        """
        n = qdd.shape[0]
        n_units = self.n_units
        n_fw, n_fp = (2, 2) if friction == "shared" else (4 * n_units, 2 * n_units)
        out = np.empty((n, 3, 5 + n_fw + n_fp))
        out[:, :, :2] = base.a_id_base(qdd)
        out[:, :, 2:5] = 0.0
        for (_, group), data in zip(self.groups, st.units, strict=True):
            out[:, :, 2:5] += group.a_id(data, qdd)
        phid, deltad = st.wheel_rate, st.pivot_rate
        a_fw = np.stack([phid, np.tanh(self.alpha * phid)], axis=-1)  # (N, n, 2, 2)
        a_fp = np.stack([deltad, np.tanh(self.alpha * deltad)], axis=-1)  # (N, n, 2)
        b_tau, b_tau_fp = st.b_tau, st.b_tau_fp
        fw = out[:, :, 5:5 + n_fw]
        fp = out[:, :, 5 + n_fw:]
        if friction == "shared":
            fw[...] = -np.einsum("ncuw,nuwf->ncf", b_tau, a_fw)
            fp[...] = -np.einsum("ncu,nuf->ncf", b_tau_fp, a_fp)
        else:
            np.multiply(b_tau[..., None], a_fw[:, None], out=fw.reshape(n, 3, n_units, 2, 2))
            np.negative(fw, out=fw)
            np.multiply(b_tau_fp[..., None], a_fp[:, None], out=fp.reshape(n, 3, n_units, 2))
            np.negative(fp, out=fp)
        return out

    def b_id(self, st: State, tau: np.ndarray, f_b: np.ndarray | None = None) -> np.ndarray:
        """b_ID = B_Fb F_b + B_τ τ (eq. 35); (N, 3). F_b is zero in identification runs."""
        out = np.einsum("ncuw,nuw->nc", st.b_tau, tau)
        if f_b is not None:
            out = out + np.einsum("ncd,nd->nc", base.b_fb(st.q[:, 2]), f_b)
        return out

    def parameter_names(self, friction: Friction = "per-wheel") -> list[str]:
        return parameter_names(self.platform.unit_names, friction)


class _ReorderedState(State):
    """A :class:`State` whose per-unit arrays follow platform order across several groups."""

    def __init__(self, st: State, model: PlatformModel) -> None:
        super().__init__(st.q, st.qd, st.delta, st.units)
        self._model = model

    @property
    def wheel_rate(self) -> np.ndarray:
        return self._model._to_platform_order(super().wheel_rate, 1)

    @property
    def pivot_rate(self) -> np.ndarray:
        return self._model._to_platform_order(super().pivot_rate, 1)

    @property
    def b_tau(self) -> np.ndarray:
        return self._model._to_platform_order(super().b_tau, 2)

    @property
    def b_tau_fp(self) -> np.ndarray:
        return self._model._to_platform_order(super().b_tau_fp, 2)
