"""The base plus the sum over wheel units: the direct equations of motion (thesis eqs. 32, 65)

    M_dir q̈_b = B_Fb F_b + B_τ (τ + τ_f) + f_f + b_dir,

forward dynamics (33), minimum-norm inverse dynamics (34), the disturbance estimate (40) and
the identification regressor A_ID,ext (eqs. 35, 36, 66) — all from the same per-unit pieces.
τ holds every actuator's torque, τ_f the friction torques added to them, and f_f the
generalized friction force of unactuated joints (the swivel's pivots: B_τfp τ_fp, eq. 64) and,
with body-axis friction, of the base (:func:`ropod_sysid.model.base.body_friction_force`).

Shapes: q, qd (N, 3); unit angles (N, J) and actuator torques (N, A) in the platform's
channel order (:class:`ropod_sysid.platform.Layout`).

Own coordinates and constraints. A unit type may add coordinates of its own (the steered
wheel's actuated steering angle β: its ``coordinates``) and constraints on the generalized
velocity that it does not eliminate (the steered wheel's lateral no-slip rows G q̇ = 0). The
generalized coordinates are then q = (q_b, s): D = 3 + E rows, the base's three first, then the
groups' own coordinates in platform order; q̈ (N, D), M_dir (N, D, D), B_τ (N, D, A). The
constraint forces Gᵀλ are removed by the orthogonal projector P = I − G⁺G onto the null space
of G (001 eqs. 11–15; :func:`null_projector`): P Gᵀ = 0, and P (M q̈ − B_τ(τ + τ_f) − b) = 0
are the equations of motion and, linear in the parameters, the identification rows
P A_ID,ext m = P b_ID. P is found by an SVD with a rank tolerance, so a configuration in which
the constraints lose rank (001 Property 3–4: all wheel axles on one line) gives the right
projection, never a division by zero. Without constraints P = I and D = 3 for the ropod.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ropod_sysid.model import base
from ropod_sysid.model.blocks import cells, gather, placed, spot, take
from ropod_sysid.model.units import FrictionVariant, UnitData, check_variant
from ropod_sysid.params import Friction, parameter_names

if TYPE_CHECKING:
    from ropod_sysid.platform import Group, Platform


RANK_TOLERANCE = 1e-9  # singular values of G below this × the largest count as zero
# identification rows leave out the base rows where the constraints are this close to losing
# rank (σ_min/σ_max of the base block of G, over the rank the platform has when regular)
SINGULAR_MARGIN = 0.1
# Rigid wheels that roll without slipping sideways leave a moving base one degree of freedom at
# least: their axles meet at the instantaneous centre, and their lateral rows (on the base
# twist) have rank 2 at most. Three or more wheels whose measured or tracked angles miss that
# by a little would, taken exactly, lock the base (rank 3); the real wheels slip by that
# little instead. The constraints are therefore taken as their nearest rank-2 set (Eckart and
# Young: the SVD truncated), the rest counted as slip.
CONSISTENT_RANK = 2
# where the measured angles miss a common instantaneous centre by more than this (the base
# block's third singular value over its first, about the angle error in rad) the wheels slip
# and the base rows are left out of identification
SLIP_MARGIN = 0.01
# the simulator's constraint forces leave out directions in which G's singular values are below
# this × its largest (S = G M⁻¹ Gᵀ below its square): near a singular configuration the
# steering loops' small errors make the exact constraints inconsistent, and the forces that
# would enforce them grow as 1/σ² (the wheels scrub instead); 1e-10 made runs without
# steering friction diverge
SLIP_RANK = 1e-3


def null_projector(g: np.ndarray, n_dof: int, margin: float = 0.0, slip: float = 0.0,
                   rank: int = CONSISTENT_RANK) -> np.ndarray:
    """P = I − G⁺G (N, D, D), the orthogonal projector onto the null space of constraint rows
    G (N, C, D): by an SVD, singular values below :data:`RANK_TOLERANCE` × the largest
    dropped (001 eqs. 11–15 with a rank tolerance instead of Algorithm 1's divisions), and G
    taken at ``rank`` at most (:func:`consistent_constraints`; rigid wheels:
    :data:`CONSISTENT_RANK`, wheels on legs: every row, :attr:`PlatformModel.motion_rank`).

    ``margin`` > 0 (identification): where the base block of G is near singular — its
    smallest singular value of the regular rank below ``margin`` × its largest — the base rows
    are removed altogether (P's base block zero). There the null direction turns with the
    smallest error of the measured angles, and the constraint forces, large near a singular
    configuration, would leak into the rows; the units' own rows are free of them and stay.
    ``slip`` > 0: so are they where G has more than ``rank`` rows and its next
    singular value exceeds ``slip`` × its largest (the wheels' angles miss a common centre:
    they slip, and the odometry with them)."""
    _, sv, vt = np.linalg.svd(g, full_matrices=False)  # vt (N, min(C, D), D)
    keep = sv > RANK_TOLERANCE * np.maximum(sv[:, :1], np.finfo(float).tiny)
    keep[:, rank:] = False
    v = vt * keep[..., None]
    proj = np.eye(n_dof) - np.einsum("nri,nrj->nij", v, v)
    if margin > 0 or slip > 0:
        near = base_singular_ratio(g, min(g.shape[1], rank)) < margin
        if slip > 0 and g.shape[1] > rank:
            near |= base_singular_ratio(g, rank + 1) > slip
        proj[near, :3, :] = 0.0
        proj[near, :, :3] = 0.0
    return proj


def locked_projector(proj: np.ndarray | None, held: np.ndarray, n_dof: int) -> np.ndarray:
    """The projector (N, D, D) onto the motions ``proj`` allows (None: all) with the own
    coordinates ``held`` (N, E) fixed as well: P − P Eᵀ (E P Eᵀ)⁺ E P with E the unit rows of
    the held coordinates (zero rows where not held)."""
    n, e = held.shape
    rows = np.zeros((n, e, n_dof))
    rows[:, np.arange(e), 3 + np.arange(e)] = held
    p = np.broadcast_to(np.eye(n_dof), (n, n_dof, n_dof)) if proj is None else proj
    pe = p @ np.swapaxes(rows, 1, 2)  # (N, D, E)
    s_inv = np.linalg.pinv(rows @ pe, rcond=1e-9, hermitian=True)
    return p - pe @ s_inv @ np.swapaxes(pe, 1, 2)


def consistent_constraints(g: np.ndarray, c: np.ndarray, rank: int = CONSISTENT_RANK
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The constraints G q̇ = 0 (G (N, C, D)) and their right-hand side c (N, C) projected onto
    the ``rank`` leading left singular directions of G: the nearest set of that rank (unchanged
    where G has no more rows)."""
    if g.shape[1] <= rank:
        return g, c
    u, _, _ = np.linalg.svd(g, full_matrices=False)
    ur = u[:, :, :rank]
    keep = np.einsum("nci,nei->nce", ur, ur)  # (N, C, C) projector onto the leading rows
    return np.einsum("nce,ned->ncd", keep, g), np.einsum("nce,ne->nc", keep, c)


def base_singular_ratio(g: np.ndarray, regular: int | None = None) -> np.ndarray:
    """How near each sample's constraint rows G (N, C, D) are to losing rank: σ_r / σ_1 (N,)
    of G, σ_r its r-th largest singular value, r the rank the platform has when regular —
    ``regular``, else that of C rows consistent with one instantaneous centre,
    min(C, :data:`CONSISTENT_RANK`). For rigid wheels G's own columns are zero (the lateral
    rows hold no steering rate) and these are the base block's values; a leg's extension
    rate adds a column of its own. 0 where the rows have lost rank (001 Property 3–4: all
    wheel axles on one line); :func:`null_projector` leaves out the base rows where it is
    below its ``margin``. (With ``regular`` = CONSISTENT_RANK + 1: how far the rows miss one
    centre, its slip test.)"""
    base = np.linalg.svd(g, compute_uv=False)  # (N, min(C, D))
    if regular is None:
        regular = min(g.shape[1], CONSISTENT_RANK)
    regular = min(max(regular, 1), base.shape[1])
    return base[:, regular - 1] / np.maximum(base[:, 0], np.finfo(float).tiny)


@dataclass
class State:
    """Kinematic data of the whole platform at N samples (pinocchio's "data")."""

    q: np.ndarray  # (N, 3)
    qd: np.ndarray  # (N, 3) base twist
    angles: np.ndarray  # (N, J)
    units: list[UnitData]  # one per unit group
    groups: tuple[Group, ...]
    n_angles: int
    n_actuators: int
    rows: tuple[np.ndarray, ...] = ()  # per group, its rows among the D generalized coordinates
    n_dof: int = 3
    # (N, E) own coordinates held still in a measured record (static friction holds them):
    # identification locks them (:meth:`PlatformModel.identification_projector`)
    held: np.ndarray | None = None

    @property
    def b_tau(self) -> np.ndarray:
        """B_τ (N, D, A) over every actuator (eq. 32)."""
        return gather([(g.currents, placed(d.b_tau, r, self.n_dof))
                        for g, d, r in zip(self.groups, self.units, self.rows, strict=True)],
                       self.n_actuators, 2)

    @property
    def angle_rate(self) -> np.ndarray:
        """Rates of the unit angles (N, J)."""
        return gather([(g.angles, d.angle_rate) for g, d in zip(self.groups, self.units,
                                                                strict=True)],
                       self.n_angles, 1)

    @property
    def actuator_rate(self) -> np.ndarray:
        """Rates of the actuated joints (N, A)."""
        return gather([(g.currents, d.actuator_rate) for g, d in zip(self.groups, self.units,
                                                                     strict=True)],
                       self.n_actuators, 1)


@dataclass
class DirectEOM:
    """The terms of eq. 65 at N samples."""

    m_dir: np.ndarray  # (N, D, D)
    b_fb: np.ndarray  # (N, D, 3)
    b_tau: np.ndarray  # (N, D, A)
    b_dir: np.ndarray  # (N, D)
    tau_f: np.ndarray  # (N, A) friction torques added to the actuator torques (eqs. 56/57)
    f_f: np.ndarray | None  # (N, D) other friction, as a generalized force (eq. 64: B_τfp τ_fp)

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
        # per group its units: a UnitType instance, whose optional members (own coordinates,
        # constraints, controller plans) are probed with hasattr
        self.groups: list[tuple[Group, Any]] = [
            (g, g.type.from_specs(g.specs, self.alpha)) for g in platform.groups]
        self._columns: dict[str, list[tuple[np.ndarray | slice, np.ndarray | slice]]] = {}
        # the units' own coordinates: per group its rows among the D, and their angle channels
        rows, channels, extra = [], [], 3
        for g, _ in self.groups:
            own = tuple(getattr(g.type, "coordinates", ()))
            k = len(g.specs)
            rows.append(np.concatenate([np.arange(3), extra + np.arange(k * len(own))]))
            per = g.angles.reshape(k, -1)
            channels.append(per[:, list(own)].reshape(-1) if own else np.zeros(0, int))
            extra += k * len(own)
        self.rows = tuple(rows)
        self.n_dof = extra  # D = 3 + E
        self.coordinate_channels = np.concatenate(channels).astype(int)  # (E,) angle channels
        self.constrained = any(hasattr(u, "constraint_jacobian") for _, u in self.groups)
        self._motion_rank: int | None = None

    @property
    def row_kinds(self) -> np.ndarray:
        """Per generalized coordinate (D,): 0, 1 for x, y (forces [N]), 2 for θ and the units'
        own angles (torques [N m]): the rows that share one triangle and one weight."""
        return np.array([0, 1] + [2] * (self.n_dof - 2))

    # ------------------------------------------------------------ kinematics
    def state(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
              angle_rates: np.ndarray | None = None) -> State:
        """Kinematics of every unit group for base motion (q, qd) and unit angles (N, J);
        ``angle_rates`` (N, J) are the measured rates where a type uses them. ``qd`` may be
        the whole generalized velocity (N, D): its columns after the base twist are the rates
        of the units' own coordinates (the simulator's states); else they are taken from
        ``angle_rates``."""
        q = np.atleast_2d(np.asarray(q, float))
        qd = np.atleast_2d(np.asarray(qd, float))
        angles = np.atleast_2d(np.asarray(angles, float))
        own = qd[:, 3:] if qd.shape[1] > 3 else None
        qd = qd[:, :3]
        units = []
        for (g, unit), rows in zip(self.groups, self.rows, strict=True):
            rates = None if angle_rates is None else take(angle_rates, g.angles, 1)
            if rows.size > 3:
                coord = None if own is None else own[:, rows[3:] - 3]
                units.append(unit.kinematics(q, qd, take(angles, g.angles, 1), rates,
                                             coordinate_rates=coord))
            else:
                units.append(unit.kinematics(q, qd, take(angles, g.angles, 1), rates))
        return State(q, qd, angles, units, tuple(g for g, _ in self.groups),
                     self.layout.n_angles, self.layout.n_currents, self.rows, self.n_dof)

    def constraints(self, st: State, exact: bool = False
                    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The constraint rows G (N, C, D) the units do not eliminate (the steered wheels'
        lateral no-slip) and Ġ q̇ (N, C), as their nearest consistent set
        (:func:`consistent_constraints`; ``exact``: as the angles give them); None without
        any."""
        if not self.constrained:
            return None
        parts = [unit.constraint_jacobian(data)
                 for (_, unit), data in zip(self.groups, st.units, strict=True)
                 if hasattr(unit, "constraint_jacobian")]
        rows = [r for (_, unit), r in zip(self.groups, self.rows, strict=True)
                if hasattr(unit, "constraint_jacobian")]
        g = np.concatenate([placed(p[0], r, self.n_dof, (2,)) for p, r in zip(parts, rows,
                                                                           strict=True)],
                           axis=1)
        c = np.concatenate([p[1] for p in parts], axis=1)
        return (g, c) if exact else consistent_constraints(g, c, self.motion_rank or 0)

    @property
    def motion_rank(self) -> int | None:
        """Rank of the constraint rows while the platform moves regularly: the largest over
        three generic twists, every unit at the angles it takes for that motion
        (:meth:`initial_angles`: steered wheels along their centre velocities, so that the
        axles meet at the instantaneous centre; 2 for rigid wheels, every row for wheels on
        legs, whose extension rates enter the rows); None without constraints. (Angles that
        fit no motion — measured ones, with noise — may give a higher rank: the constraints
        are taken at this rank, :func:`consistent_constraints`.)"""
        if not self.constrained:
            return None
        if self._motion_rank is None:
            twists = np.array([[0.31, 0.17, 0.53], [-0.23, 0.41, -0.37], [0.11, -0.29, 0.83]])
            angles = np.stack([self.initial_angles(tw) for tw in twists])
            st = self.state(np.zeros((3, 3)), twists, angles, np.zeros_like(angles))
            g = self.constraints(st, exact=True)[0]  # type: ignore[index]
            sv = np.linalg.svd(g, compute_uv=False)
            self._motion_rank = int(np.sum(sv > RANK_TOLERANCE * sv[:, :1], axis=1).max())
        return self._motion_rank

    def consistent_motion(self, st: State, qdd: np.ndarray) -> tuple[State, np.ndarray]:
        """Measured rates and accelerations moved onto the motions the constraints allow:
        q̇ ← P q̇ and q̈ ← q̈ − G⁺ (G q̈ + Ġ q̇) (the least change; G at its consistent rank,
        :meth:`constraints`), where the rows are regular (:meth:`singular_ratio` at least
        :data:`SINGULAR_MARGIN`; elsewhere unchanged). The model's lumps — a centred wheel's
        spin inertia acting as a point mass at its centre — are then exact in the rows, so
        the fit's rank analysis names them; with the smoothed measurements' small violations
        they were only nearly collinear. Unchanged without constraints."""
        con = self.constraints(st)
        if con is None:
            return st, qdd
        g, _ = con
        regular = base_singular_ratio(g, self.motion_rank) >= SINGULAR_MARGIN
        qd = np.concatenate([st.qd, self.own_rates(st)], axis=1)
        g_pinv = np.linalg.pinv(g, rcond=RANK_TOLERANCE)
        fixed = qd - np.einsum("ndc,nc->nd", g_pinv, np.einsum("ncd,nd->nc", g, qd))
        fixed[~regular] = qd[~regular]
        rates = st.angle_rate.copy()  # the other measured rates (wheels) are kept
        rates[:, self.coordinate_channels] = fixed[:, 3:]
        st_c = self.state(st.q, fixed[:, :3], st.angles, rates)
        g, g_dot_qd = self.constraints(st_c)  # type: ignore[misc]
        viol = np.einsum("ncd,nd->nc", g, qdd) + g_dot_qd
        qdd_c = qdd - np.einsum("ndc,nc->nd", np.linalg.pinv(g, rcond=RANK_TOLERANCE), viol)
        qdd_c[~regular] = qdd[~regular]
        return st_c, qdd_c

    def singular_ratio(self, st: State) -> np.ndarray | None:
        """σ_r / σ_1 (N,) of the base block of the constraint rows at ``st``, r the
        :attr:`motion_rank` (:func:`base_singular_ratio`); None without constraints. Below
        :data:`SINGULAR_MARGIN` the identification leaves out the base rows."""
        con = self.constraints(st)
        return None if con is None else base_singular_ratio(con[0], self.motion_rank)

    def projector(self, st: State) -> np.ndarray | None:
        """P = I − G⁺G (N, D, D) onto the motions the constraints allow (None: unconstrained)."""
        con = self.constraints(st)
        return None if con is None else null_projector(con[0], self.n_dof,
                                                       rank=self.motion_rank or 0)

    def angle_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Rates of the unit angles implied by the base motion (N, J) (for the swivel: δ̇ of
        eq. 8a and φ̇ of eq. 11)."""
        parts = [(g.angles, u.angle_rates(q, qd, take(angles, g.angles, 1)))
                 for g, u in self.groups]
        return gather(parts, self.layout.n_angles, 1)

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Actuator rates (N, A) that the base motion (q, qd) asks for at the unit angles: the
        inverse kinematics a velocity controller uses."""
        parts = [(g.currents, u.actuator_rates(q, qd, take(angles, g.angles, 1)))
                 for g, u in self.groups]
        return gather(parts, self.layout.n_currents, 1)

    @property
    def planned_columns(self) -> list[str]:
        """The log columns of the own coordinates that a run's setpoints may plan besides
        the base twist (a leg's extension, ``leg_u``), in platform order."""
        return [ch.column(name) for g, u in self.groups for name in u.names
                for ch in getattr(g.type, "planned_channels", ())]

    @property
    def planned_angles(self) -> np.ndarray:
        """The angle channels (L,) of :attr:`planned_columns`."""
        index = {n: i for i, n in enumerate(self.layout.angle_names)}
        return np.array([index[c] for c in self.planned_columns], int)

    def plans(self, t: np.ndarray, twists: np.ndarray, planned: np.ndarray | None = None
              ) -> list[tuple[np.ndarray, ...] | None]:
        """Per group, what its controllers track along base-frame twists (R, N, 3) at times
        t (N,) — its type's ``controller_plan``: the steered wheels' planned steering angles
        and rates (N, R, k); a leg's planned extension, its rates and then its wheel's plan —
        or None. ``planned`` (R, N, L): the :attr:`planned_columns` (NaN: not planned)."""
        out: list[tuple[np.ndarray, ...] | None] = []
        start = 0
        for g, u in self.groups:
            n_planned = len(getattr(g.type, "planned_channels", ())) * u.n_units
            mine = None if planned is None else planned[..., start:start + n_planned]
            start += n_planned
            if not hasattr(u, "controller_setpoints"):
                out.append(None)
            elif n_planned:
                out.append(u.controller_plan(t, twists, mine))
            else:
                out.append(u.controller_plan(t, twists))
        return out

    def setpoints(self, q: np.ndarray, twist: np.ndarray, twist_rate: np.ndarray,
                  angles: np.ndarray, plans: list[tuple[np.ndarray, ...] | None] | None = None,
                  step: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """The low-level controllers' setpoints for base-frame twists (N, 3) and their rates:
        actuator-rate setpoints (N, A), and the angle errors (N, A) of the position-controlled
        actuators (the steered wheels' steering, 001 eq. 25; at sample ``step`` of the
        :meth:`plans` when given), NaN where an actuator is speed-controlled (its setpoint
        from the inverse kinematics, :meth:`actuator_rates`)."""
        c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
        world = np.stack([c * twist[:, 0] - s * twist[:, 1], s * twist[:, 0] + c * twist[:, 1],
                          twist[:, 2]], axis=-1)
        rates, errors = [], []
        for i, (g, u) in enumerate(self.groups):
            ang = take(angles, g.angles, 1)
            if hasattr(u, "controller_setpoints"):
                plan = None if plans is None or plans[i] is None else tuple(
                    p[step] for p in plans[i])  # type: ignore[union-attr]
                r, e = u.controller_setpoints(twist, twist_rate, ang, plan)
            else:
                r, e = u.actuator_rates(q, world, ang), None
            rates.append((g.currents, r))
            errors.append((g.currents, np.full_like(r, np.nan) if e is None else e))
        n_a = self.layout.n_currents
        return gather(rates, n_a, 1), gather(errors, n_a, 1)

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        """Unit angles (J,) at rest before a first motion with base-frame twist (3,)."""
        parts = [(g.angles, u.initial_angles(twist)[None]) for g, u in self.groups]
        return gather(parts, self.layout.n_angles, 1)[0]

    # ------------------------------------------------------------ dynamics
    def friction(self, st: State, params: Mapping[str, float], friction: Friction = "per-wheel"
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """Friction torques τ_f (N, A) added to the actuator torques and the generalized
        friction force f_f (N, D) of the unactuated joints and the base (or None)."""
        check_variant(friction)
        parts, f_f = [], None
        for (g, unit), data, rows in zip(self.groups, st.units, self.rows, strict=True):
            parts.append((g.currents, unit.friction_torques(data, params, friction)))
            f = unit.friction_force(data, params, friction)
            if f is not None:  # on the base rows, or on the group's rows (a leg's friction)
                f = placed(f, rows if f.shape[1] == rows.size else np.arange(3), self.n_dof)
                f_f = f if f_f is None else f_f + f
        if friction == "body":
            f = placed(base.body_friction_force(st.q[:, 2], st.qd, params, self.alpha),
                      np.arange(3), self.n_dof)
            f_f = f if f_f is None else f_f + f
        return gather(parts, self.layout.n_currents, 1), f_f

    def direct_eom(self, st: State, params: Mapping[str, float],
                   friction: Friction = "per-wheel") -> DirectEOM:
        """M_dir, B_Fb, B_τ, b_dir and the friction terms (eqs. 32, 64, 65)."""
        n, d = st.q.shape[0], self.n_dof
        m_dir = placed(base.m_b(params["m_b"], params["Jzz_b"], n), np.arange(3), d, (1, 2))
        b_dir = np.zeros((n, d))  # (49): M_dir = M_b + Σ M_i,add
        for (_, unit), data, rows in zip(self.groups, st.units, self.rows, strict=True):
            m_add, b_add = unit.mass_terms(data, params)
            m_dir = m_dir + placed(m_add, rows, d, (1, 2))
            b_dir = b_dir + placed(b_add, rows, d)
        tau_f, f_f = self.friction(st, params, friction)
        return DirectEOM(m_dir, placed(base.b_fb(st.q[:, 2]), np.arange(3), d), st.b_tau, b_dir,
                         tau_f, f_f)

    def forward_dynamics(self, st: State, params: Mapping[str, float], tau: np.ndarray,
                         f_b: np.ndarray | None = None,
                         friction: Friction = "per-wheel",
                         stabilize: float = 0.0) -> np.ndarray:
        """q̈ = M_dir⁻¹ (B_Fb F_b + B_τ (τ + τ_f) + f_f + b_dir) (eqs. 33, 65); (N, D).

        With constraints G q̇ = 0 the accelerations also satisfy G q̈ = −Ġ q̇ − ``stabilize`` G q̇
        (Baumgarte's term [1/s] against drift): Udwadia and Kalaba's
        q̈ = a + M⁻¹Gᵀ (G M⁻¹ Gᵀ)⁺ (c − G a), a = M⁻¹ Q, whose pseudo-inverse keeps
        configurations where G loses rank regular (directions below :data:`SLIP_RANK` are
        left free: slip).
        """
        eom = self.direct_eom(st, params, friction)
        rhs = eom.generalized_force(tau, f_b)
        acc = np.linalg.solve(eom.m_dir, rhs[..., None])[..., 0]
        con = self.constraints(st)
        if con is None:
            return acc
        g, g_dot_qd = con
        qd = np.concatenate([st.qd, self.own_rates(st)], axis=1)
        c = -g_dot_qd - stabilize * np.einsum("ncd,nd->nc", g, qd)
        m_inv_gt = np.linalg.solve(eom.m_dir, np.swapaxes(g, 1, 2))  # (N, D, C)
        s_mat = np.einsum("ncd,nde->nce", g, m_inv_gt)
        lam = np.einsum("nce,ne->nc", _symmetric_pinv(s_mat, SLIP_RANK**2),
                        c - np.einsum("ncd,nd->nc", g, acc))
        return acc + np.einsum("ndc,nc->nd", m_inv_gt, lam)

    def own_rates(self, st: State) -> np.ndarray:
        """Rates (N, E) of the units' own coordinates at ``st``."""
        rate = st.angle_rate
        return rate[:, self.coordinate_channels]

    def inverse_dynamics(self, st: State, params: Mapping[str, float], qdd: np.ndarray,
                         f_b: np.ndarray | None = None,
                         friction: Friction = "per-wheel",
                         torque_max: np.ndarray | None = None) -> np.ndarray:
        """Actuator torques τ for accelerations q̈ (N, D): the solution of
        P B_τ (τ + τ_f) = P (M_dir q̈ − B_Fb F_b − f_f − b_dir) that minimises (τ + τ_f)ᵀ W
        (τ + τ_f) with W = diag(1/τ_max²) (eq. 34; with constraints 001 eqs. 19–23, whose
        steering torques decouple, eq. 17); W = I when ``torque_max`` (A,) is not given.
        (N, A). P = I without constraints.

        Friction is compensated: the returned τ plus τ_f is the weighted minimum-norm solution
        for the total actuator torque, with the other friction moved to the right-hand side.
        """
        eom = self.direct_eom(st, params, friction)
        need = np.einsum("ncd,nd->nc", eom.m_dir, qdd) - eom.b_dir
        if eom.f_f is not None:
            need -= eom.f_f
        if f_b is not None:
            need -= np.einsum("ncd,nd->nc", eom.b_fb, f_b)
        proj = self.projector(st)
        b_tau = eom.b_tau
        if proj is not None:
            need = np.einsum("nij,nj->ni", proj, need)
            b_tau = np.einsum("nij,nja->nia", proj, b_tau)
        return weighted_right_inverse(b_tau, need, torque_max) - eom.tau_f

    def disturbance(self, st: State, params: Mapping[str, float], qdd: np.ndarray, tau: np.ndarray,
                    friction: Friction = "per-wheel") -> np.ndarray:
        """F_b = B_Fb⁻¹ (M_dir q̈ − B_τ (τ + τ_f) − f_f − b_dir) (eq. 40); (N, 3)."""
        eom = self.direct_eom(st, params, friction)
        resid = np.einsum("ncd,nd->nc", eom.m_dir, qdd) - eom.generalized_force(tau)
        proj = self.identification_projector(st)
        if proj is not None:  # the constraint forces Gᵀλ are not a disturbance; near a
            # singular configuration they leak into the projection: none is estimated there
            resid = np.einsum("nij,nj->ni", proj, resid)
        # B_Fb is a rotation about z (det = 1, eq. 3): its inverse is its transpose
        return np.einsum("ndc,nd->nc", eom.b_fb[:, :3], resid[:, :3])

    def kinetic_energy(self, st: State, params: Mapping[str, float]) -> np.ndarray:
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
                spots.append((spot([index[n] for n in g.type.inertial_names]),
                              spot([index[n] for n in g.type.friction_names(unit.names,
                                                                             friction)])))
            self._columns[friction] = spots
        return self._columns[friction]

    def a_id_ext(self, st: State, qdd: np.ndarray,
                 friction: Friction = "per-wheel", projected: bool = True) -> np.ndarray:
        """A_ID,ext (N, 3, p) with columns ordered as :func:`parameter_names` (eq. 66).

        [A_ID | friction columns]: the base and unit inertial columns (35), then each unit
        type's friction columns (for the swivel: −B_τ A_fw, −B_τfp A_fp, eqs. 56/57, 59/60),
        or the base's body-axis friction columns. ``projected`` False: before the
        :meth:`identification_projector` (which the caller applies once to several).
        """
        check_variant(friction)
        n, d = qdd.shape[0], self.n_dof
        names = self.parameter_names(friction)
        out = np.zeros((n, d, len(names)))
        out[:, :3, :2] = base.a_id_base(qdd)
        spots = self._layout(friction)
        shared = self._shared_spots(spots)
        for (_, unit), data, (inert, fric), rows in zip(self.groups, st.units, spots,
                                                        self.rows, strict=True):
            own = rows.size > 3
            if own:
                out[(slice(None), *cells(rows, inert))] += unit.a_id(data, qdd[:, rows])
            else:
                out[:, :3, inert] += unit.a_id(data, qdd[:, :3])
            if friction == "body" and not own:
                continue
            if own:
                out[(slice(None), *cells(rows, fric))] += unit.friction_columns(data, friction)
            elif isinstance(fric, slice) and fric not in shared:
                unit.friction_columns(data, friction, out=out[:, :3, fric])
            else:
                out[:, :3, fric] += unit.friction_columns(data, friction)
        if friction == "body":
            body = slice(len(names) - len(base.BODY_FRICTION), len(names))
            out[:, :3, body] = base.body_friction_columns(st.q[:, 2], st.qd, self.alpha)
        return self._projected(st, out) if projected else out

    def _projected(self, st: State, rows: np.ndarray) -> np.ndarray:
        """P rows (N, D, …): the constraint forces removed (unchanged without constraints);
        near-singular configurations leave out the base rows (:func:`null_projector`)."""
        proj = self.identification_projector(st)
        return rows if proj is None else np.einsum("nij,nj...->ni...", proj, rows)

    def identification_projector(self, st: State) -> np.ndarray | None:
        """P (N, D, D) for rows built from measured angles (None: unconstrained and nothing
        held): the constraint forces removed, and the base rows left out near singular
        configurations and where the wheels slip (:func:`null_projector` with
        :data:`SINGULAR_MARGIN`, :data:`SLIP_MARGIN`). Own coordinates held still
        (``st.held``) are locked: a joint that static friction holds carries an unknown force,
        a constraint force like the others, so its direction is projected out too
        (:func:`locked_projector`; its own row then vanishes, and so does what the other
        constraints' projection would carry of it into the base rows, as for a leg whose
        lateral rows hold its rate)."""
        con = self.constraints(st, exact=True)
        proj = None if con is None else null_projector(con[0], self.n_dof, SINGULAR_MARGIN,
                                                       SLIP_MARGIN, self.motion_rank or 0)
        if st.held is not None and np.any(st.held):
            proj = locked_projector(proj, st.held, self.n_dof)
        return proj

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
        """b_ID = P (B_Fb F_b + B_τ τ) (eq. 35); (N, D). F_b is zero in identification runs;
        τ (N, A), or (N, A, n) at n node delays (then (N, D, n))."""
        out = np.einsum("nca,na...->nc...", st.b_tau, tau)
        if f_b is not None:
            out[:, :3] += np.einsum("ncd,nd->nc", base.b_fb(st.q[:, 2]), f_b)
        return self._projected(st, out)

    def parameter_names(self, friction: Friction = "per-wheel") -> list[str]:
        return parameter_names(self.platform, friction)


def weighted_right_inverse(b: np.ndarray, q_d: np.ndarray,
                           torque_max: np.ndarray | None = None) -> np.ndarray:
    """u (N, A) with B u = Q_d (N, D) for B (N, D, A) that minimises uᵀ W u, W =
    diag(1/τ_max²) (001 eqs. 19–21: u = W⁻¹Bᵀ(B W⁻¹ Bᵀ)⁻¹ Q_d, here by a pseudo-inverse of
    B W^(−1/2), which also serves a B without full row rank — the projected B_τ — and an
    inconsistent Q_d, in the least-squares sense). W = I without ``torque_max`` (A,).

    Singular values below :data:`RANK_TOLERANCE` × the largest count as zero: a projected B_τ
    has exact zeros that round-off makes about 1e-15 of the largest, which numpy's default
    cut-off (a few ε × the largest) sometimes keeps, adding an arbitrary component in
    the null space (wheels pushing against each other; seen up to 0.2 N m on the steered
    sample)."""
    if torque_max is None:
        return np.einsum("nac,nc->na", np.linalg.pinv(b, rcond=RANK_TOLERANCE), q_d)
    scale = np.asarray(torque_max, float)  # W^(−1/2)
    return scale * np.einsum("nac,nc->na", np.linalg.pinv(b * scale, rcond=RANK_TOLERANCE),
                             q_d)


def _symmetric_pinv(s: np.ndarray, rcond: float) -> np.ndarray:
    """The pseudo-inverse of symmetric positive semi-definite matrices ``s`` (N, C, C) from
    their eigen-decomposition (eigenvalues below ``rcond`` × the largest count as zero): what
    ``np.linalg.pinv`` gives, at a fraction of its cost for the small matrices of a step."""
    lam, vec = np.linalg.eigh(s)
    keep = lam > rcond * np.max(lam, axis=-1, keepdims=True)
    inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
    return np.einsum("nij,nj,nkj->nik", vec, inv, vec)
