"""Wheel-unit types: what one type of wheel unit declares so that the pipeline can use it.

A unit type is one module; nothing outside it names its joints. It declares (see
``docs/unit-types.md``):

- its platform-file entry: the keys, their defaults and validation (:meth:`UnitType.parse_entry`,
  one-line :class:`~ropod_sysid.errors.InputError` messages naming the unit, the key and the fix);
- its log channels, column names and units (:meth:`UnitType.channels`);
- its parameter names: inertial (shared by all units of the type) and friction, per wheel,
  shared or per body axis (:attr:`UnitType.inertial_names`, :meth:`UnitType.friction_names`);
- its constraint rows, linear in the base twist, from its measured joint rates: wheel odometry of
  any mix of types is one least-squares solve over the rows of all units
  (:meth:`UnitType.constraint_rows`);
- its contributions to the direct equations of motion (thesis eq. 65)
  M_dir q̈_b = B_Fb F_b + B_τ (τ + τ_f) + b_dir: M_add and b_dir (:meth:`UnitType.mass_terms`),
  the actuator input matrix (``data.b_tau``), the friction torques and the columns of A_ID,ext
  (eq. 66) for its inertial and friction parameters (:meth:`UnitType.a_id`,
  :meth:`UnitType.friction_columns`);
- its actuator rates for a base twist: the simulator's model-free controller and the trajectory
  check's joint-rate limits (:meth:`UnitType.actuator_rates`);
- the per-unit quantities the report and ``inspect`` show (:meth:`UnitType.unit_table`,
  :meth:`UnitType.quantities`).

A group object holds k units of one type and is vectorised over samples N and its units.
Parameters are passed by name (a mapping name → value), so that a type owns its names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

FrictionVariant = Literal["per-wheel", "shared", "body"]


@dataclass(frozen=True)
class Channel:
    """One log column of a unit: its name (``phi_3``), SI unit and meaning."""

    name: str
    unit: str
    description: str


class UnitData(Protocol):
    """Per-sample kinematics of a group; ``b_tau`` is (N, 3, m) over its m actuators."""

    b_tau: np.ndarray


class UnitType(Protocol):
    """A wheel-unit type: declarations (class level) and a group of k units (instance)."""

    type_name: str  # the platform file's ``type:``
    entry_keys: tuple[str, ...]  # keys a unit entry of this type may carry
    inertial_names: tuple[str, ...]  # inertial parameters, shared by the units of the type
    parameter_units: Mapping[str, str]  # SI unit of each parameter family
    n_units: int
    names: list[str]

    @classmethod
    def parse_entry(cls, entry: Any, k: int, where: str, defaults: Mapping[str, float]) -> Any:
        """Validate ``units[k]`` of the platform file ``where``; ``defaults`` are the
        platform-wide keys the entry may override."""
        ...

    @staticmethod
    def channels(unit: str) -> tuple[Channel, ...]:
        """Log columns of the unit named ``unit``."""
        ...

    @staticmethod
    def friction_names(units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """Friction parameter names for the units, ordered as :meth:`friction_columns`."""
        ...

    def kinematics(self, q: np.ndarray, qd: np.ndarray,
                   joint_rates: np.ndarray | None = None) -> UnitData:
        """Per-sample kinematics for base pose q and twist qd (N, 3), world coordinates."""
        ...

    def constraint_rows(self, q: np.ndarray,
                        joint_rates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A (N, r, 3), b (N, r)) with A q̇_b = b from the measured joint rates."""
        ...

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Actuator rates (N, m) the base twist asks for (inverse kinematics)."""
        ...

    def torques(self, currents: np.ndarray) -> np.ndarray:
        """Actuator torques (N, m) from the motor currents (N, m)."""
        ...

    def mass_terms(self, data: Any,
                   params: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(Σ M_add (N, 3, 3), Σ b_dir (N, 3)) of the group."""
        ...

    def a_id(self, data: Any, qdd: np.ndarray) -> np.ndarray:
        """Columns of A_ID for ``inertial_names``, summed over the group; (N, 3, p)."""
        ...

    def friction_torques(self, data: Any, params: Mapping[str, float],
                         variant: FrictionVariant = "per-wheel") -> np.ndarray:
        """Friction torques (N, m), added to the actuator torques through ``b_tau``."""
        ...

    def friction_columns(self, data: Any, variant: FrictionVariant = "per-wheel"
                         ) -> np.ndarray:
        """Columns of A_ID,ext for :meth:`friction_names`; (N, 3, p_f)."""
        ...

    def kinetic_energy(self, data: Any, params: Mapping[str, float]) -> np.ndarray:
        """Kinetic energy the group adds to the base's [J]; (N,)."""
        ...

    def unit_table(self) -> list[dict[str, float | str]]:
        """One row per unit (geometry, constants) for the report and ``inspect``."""
        ...

    def quantities(self, data: Any, q_fit: np.ndarray | None = None
                   ) -> dict[str, tuple[str, np.ndarray]]:
        """Per-unit signals name → (unit, (N, k) array) for the report and ``inspect``."""
        ...


# The registry of unit types by their platform-file ``type:`` name. Imported last: a type's module
# imports Channel and FrictionVariant from here. ``swivel``
# (:class:`~ropod_sysid.model.swivel.SwivelUnits`) still has the older interface of
# :mod:`ropod_sysid.model.unit` and is listed in ``model.assembly.UNIT_TYPES``.
from ropod_sysid.model.units.omni import OmniUnits  # noqa: E402

UNIT_TYPES: dict[str, type[UnitType]] = {OmniUnits.type_name: OmniUnits}
