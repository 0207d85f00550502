"""The interface every wheel-unit model implements.

A unit model describes a *group* of units of one type (all smart wheels of a platform, say),
vectorised over samples N and over its k units. It turns the base motion and its own joint
measurements into its contribution to the direct equations of motion (thesis eq. 32, 64):

    M_dir   = M_b + Σ_units M_add          b_dir = Σ_units b_dir,i
    B_τ     = [B_τ,1 … B_τ,n]              B_τfp = [B_τfp,1 … B_τfp,n]

and, for identification, into its columns of A_ID (eq. 35) for its inertial parameters.
Friction (App. D) is handled by the assembly from ``wheel_rate``, ``pivot_rate``, ``b_tau``
and ``b_tau_fp``, so a new unit type only supplies the pieces below.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ropod_sysid.params import DynamicParameters


class UnitData(Protocol):
    """Per-sample quantities a unit model computes (pinocchio's "data")."""

    wheel_rate: np.ndarray  # (N, k, 2) wheel rates φ̇ [rad/s]
    pivot_rate: np.ndarray  # (N, k) pivot rates δ̇ [rad/s]
    b_tau: np.ndarray  # (N, 3, k, 2) input matrix of the wheel torques
    b_tau_fp: np.ndarray  # (N, 3, k) input matrix of the pivot friction torques


class UnitModel(Protocol):
    """A group of k wheel units of one type (pinocchio's "model": constants only)."""

    n_units: int
    inertial_names: tuple[str, ...]

    def kinematics(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray,
                   delta_dot: np.ndarray | None = None) -> UnitData:
        """Parametrise the unit motion for base pose q, rate qd (N, 3), joints δ (N, k)."""
        ...

    def mass_terms(self, data: UnitData,
                   params: DynamicParameters) -> tuple[np.ndarray, np.ndarray]:
        """(Σ_i M_i,add (N, 3, 3), Σ_i b_dir,i (N, 3)) of this group."""
        ...

    def a_id(self, data: UnitData, qdd: np.ndarray) -> np.ndarray:
        """Columns of A_ID for ``inertial_names``, summed over the group; (N, 3, p)."""
        ...

    def joint_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """δ̇ implied by the base motion (N, k), for integrating the unit joints."""
        ...

    def wheel_rates(self, q: np.ndarray, qd: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Wheel rates φ̇ (N, k, 2) implied by the base motion (inverse kinematics)."""
        ...

    def kinetic_energy(self, data: UnitData, params: DynamicParameters) -> np.ndarray:
        """Kinetic energy of the group's bodies [J], shape (N,)."""
        ...
