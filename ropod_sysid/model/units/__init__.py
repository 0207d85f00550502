"""Wheel-unit types: what one type of wheel unit declares so that the pipeline can use it.

A unit type is one module; nothing outside it names its joints. It declares (see
``docs/unit-types.md``):

- its platform-file entry: the keys, their defaults and validation (:meth:`UnitType.parse_entry`,
  one-line :class:`~ropod_sysid.errors.InputError` messages naming the unit, the key and the fix);
- its log channels, column names and units (:attr:`UnitType.angles`, :attr:`UnitType.currents`):
  per unit first its encoder angles, then its motor currents;
- its parameter names: inertial (shared by all units of the type) and friction, per wheel or
  shared (:attr:`UnitType.inertial_names`, :meth:`UnitType.friction_names`);
- its constraint rows, linear in the base twist, from its measured joint rates: wheel odometry of
  any mix of types is one least-squares solve over the rows of all units
  (:meth:`UnitType.normal_equations`);
- its contributions to the direct equations of motion (thesis eq. 65)
  M_dir q̈_b = B_Fb F_b + B_τ (τ + τ_f) + b_dir: M_add and b_dir (:meth:`UnitType.mass_terms`),
  the actuator input matrix (``data.b_tau``), the friction torques and forces and the columns of
  A_ID,ext (eq. 66) for its inertial and friction parameters (:meth:`UnitType.a_id`,
  :meth:`UnitType.friction_columns`);
- its actuator rates for a base twist: the simulator's model-free controller and the trajectory
  check's joint-rate limits (:meth:`UnitType.actuator_rates`), and the rates of all its angles
  that the simulator integrates (:meth:`UnitType.angle_rates`);
- its angles along a planned motion (:meth:`UnitType.predict_angles`, integrated from the unit's
  kinematics; :meth:`UnitType.quasi_steady_angles`, cheap, for the excitation search): the
  trajectory planner and check ask every group and never name a joint. A type with a turning
  joint (the swivel's pivot: :attr:`UnitType.turning`) reports its rate, for the turning-rate
  limit, and flags (the swivel's "pulling (wheel flip)"); a type with an actuated steering
  (:attr:`UnitType.steering`, the steered wheel) names its steering motor, whose rate the
  steering-rate limit bounds instead of the wheel-rate limit;
- the per-unit quantities the report and ``inspect`` show (:meth:`UnitType.unit_table`,
  :meth:`UnitType.quantities`).

A *group* object holds k units of one type that share their geometry, and is vectorised over
samples N and its units. Its angles arrive as an (N, k·a) array, unit-major (the a angle
channels of unit 1, then of unit 2 …), its currents and torques as (N, k·m). Parameters are
passed by name (a mapping name → value), so that a type owns its names.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Protocol

import numpy as np

FrictionVariant = Literal["per-wheel", "shared", "body"]
FRICTION_VARIANTS: tuple[FrictionVariant, ...] = ("per-wheel", "shared", "body")


@dataclass(frozen=True)
class Channel:
    """One log channel of a unit type.

    ``template`` is the CSV column with ``{u}`` for the unit name (``phi_{u}L``); ``field`` the
    key of the unit's entry in a JSON MCAP message (``phi_L``); ``wrapped`` marks an angle that
    may be logged modulo 2π (a pivot or steering angle) and is unwrapped before smoothing;
    ``held``: the rate below which an own coordinate counts as held still and the fit locks
    it (None: :data:`ropod_sysid.regressor.HELD_RATE` / friction_tanh_gain, for encoders
    whose counts make a slow joint's rate unreliable).
    """

    template: str
    field: str
    unit: str
    description: str
    wrapped: bool = False
    held: float | None = None  # below this rate [unit/s] a joint counts as held (None: the fit's)

    def column(self, unit: str) -> str:
        """The CSV column of this channel for the unit named ``unit``."""
        return self.template.format(u=unit)


class UnitSpec(Protocol):
    """One unit as its platform-file entry describes it."""

    name: str
    type: str

    @property
    def position(self) -> tuple[float, float]:
        """Attachment point in the base frame [m]."""
        ...

    def to_entry(self, defaults: Mapping[str, Any]) -> dict[str, Any]:
        """The platform-file entry (keys equal to the platform-wide ``defaults`` left out)."""
        ...


class UnitData(Protocol):
    """Per-sample kinematics of a group (pinocchio's "data")."""

    b_tau: np.ndarray  # (N, 3, k·m) actuator input matrix B_τ
    angle_rate: np.ndarray  # (N, k·a) rates of the unit angles
    actuator_rate: np.ndarray  # (N, k·m) rates of the actuated joints


@dataclass
class AnglePrediction:
    """A group's unit angles along V planned motions of N samples (:meth:`UnitType.predict_angles`).

    angles, rates : (V, N, k·a) the unit angles [rad] and their rates [rad/s], unit-major
    actuator : (V, N, k·m) rates of the actuated joints [rad/s] (:meth:`UnitType.actuator_rates`
        at the predicted angles)
    turning : (V, N, k) rate of each unit's turning joint [rad/s] (the swivel's δ̇), None when
        the type has none
    flags : finding → (V, N, k) bool where a unit is in a state to avoid (the swivel:
        ``"pulling (wheel flip)"``)
    lag : (V, N, k) quasi-steady only: sin of the lag of a trailing unit behind the direction
        it trails (meaningful while well below 1), None otherwise
    """

    angles: np.ndarray
    rates: np.ndarray
    actuator: np.ndarray
    turning: np.ndarray | None = None
    flags: dict[str, np.ndarray] = field(default_factory=dict)
    lag: np.ndarray | None = None


def series(twists: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
    """Base-frame twists (…, N, 3) as (V, N, 3) series, and the leading shape (…)."""
    tw = np.asarray(twists, float)
    return tw.reshape(-1, *tw.shape[-2:]), tw.shape[:-2]


def trailing_start(unit: Any, twists: np.ndarray) -> np.ndarray:
    """Initial angles (V, k·a) of V twist series (V, N, 3): the type's
    :meth:`UnitType.initial_angles` at each series' first nonzero twist (at rest if none)."""
    first = np.zeros((twists.shape[0], 3))
    for v, tw in enumerate(twists):
        moving = np.flatnonzero(np.abs(tw).sum(axis=1) > 1e-9)
        if moving.size:
            first[v] = tw[moving[0]]
    return np.stack([unit.initial_angles(f) for f in first])


def integrated(t: np.ndarray, rates: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Angles (V, N, c) from their rates (V, N, c) by the trapezoidal rule from ``start``
    (V, c)."""
    from scipy.integrate import cumulative_trapezoid

    return start[:, None, :] + cumulative_trapezoid(rates, np.asarray(t, float), axis=1,
                                                    initial=0.0)


class UnitType(Protocol):
    """A wheel-unit type: declarations (class level) and a group of k units (instance)."""

    type_name: ClassVar[str]  # the platform file's ``type:``
    angles: ClassVar[tuple[Channel, ...]]  # encoder channels per unit
    currents: ClassVar[tuple[Channel, ...]]  # motor-current channels per unit (one per actuator)
    platform_keys: ClassVar[tuple[str, ...]]  # platform-wide keys an entry may override
    inertial_names: ClassVar[tuple[str, ...]]  # inertial parameters, shared by the type's units
    parameter_info: ClassVar[Mapping[str, tuple[str, str]]]  # family → (SI unit, description)
    friction_signs: ClassVar[Mapping[str, int]]  # friction family → sign when dissipative
    # the rate of the unit's turning joint in words ("pivot rate"), None: no turning joint.
    # Its units trail the velocity of their attachment point: planning keeps that velocity
    # from reversing and turning faster than the turning-rate limit.
    turning: ClassVar[str | None]
    # the rate of the unit's actuated steering joint in words ("steering rate"), None: none.
    # It is an actuator (``steering_current``: its index among the unit's ``currents``),
    # limited by the steering-rate limit rather than the wheel-rate limit.
    steering: ClassVar[str | None]

    n_units: int
    names: list[str]

    @classmethod
    def parse_entry(cls, entry: Mapping[str, Any], k: int, where: str,
                    defaults: Mapping[str, float]) -> UnitSpec:
        """Validate ``units[k]`` of the platform file ``where``; ``defaults`` are the
        platform-wide keys the entry may override."""
        ...

    @classmethod
    def group_key(cls, spec: Any) -> Hashable:
        """Units with equal keys share one group (their common geometry)."""
        ...

    @classmethod
    def from_specs(cls, specs: Sequence[Any], friction_tanh_gain: float) -> UnitType:
        """The group of these units."""
        ...

    @staticmethod
    def friction_names(units: Sequence[str], variant: FrictionVariant = "per-wheel"
                       ) -> list[str]:
        """Friction parameter names for the units, ordered as :meth:`friction_columns`."""
        ...

    @classmethod
    def typical_parameters(cls, units: Sequence[str]) -> dict[str, float]:
        """Plausible inertial and per-wheel friction values (to simulate with)."""
        ...

    def normal_equations(self, angles: np.ndarray, increments: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """AᵀA (N, 3, 3), Aᵀb (N, 3) of the constraint rows A ν = b in the base-frame twist
        ν = (v_x, v_y, ω), at the angles (N, k·a) for their rates or increments."""
        ...

    def kinematics(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
                   angle_rates: np.ndarray | None = None) -> UnitData:
        """Per-sample kinematics for base pose q and twist qd (N, 3), world coordinates."""
        ...

    def angle_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Rates (N, k·a) of the unit angles implied by the base motion."""
        ...

    def actuator_rates(self, q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> np.ndarray:
        """Actuator rates (N, k·m) the base twist asks for (inverse kinematics)."""
        ...

    def torque_constants(self) -> np.ndarray:
        """Torque per motor current of each actuator (k·m,) [N m/A]."""
        ...

    def initial_angles(self, twist: np.ndarray) -> np.ndarray:
        """Unit angles (k·a,) at rest before a first motion with base-frame twist (3,)."""
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
        """Friction torques (N, k·m), added to the actuator torques through ``b_tau``."""
        ...

    def friction_force(self, data: Any, params: Mapping[str, float],
                       variant: FrictionVariant = "per-wheel") -> np.ndarray | None:
        """Generalized friction force (N, 3) of unactuated joints (None: none)."""
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


def check_variant(variant: str) -> FrictionVariant:
    """A friction variant name, else a one-line error."""
    from ropod_sysid.errors import InputError

    if variant not in FRICTION_VARIANTS:
        raise InputError(f"unknown friction model {variant!r}; use per-wheel, shared or body")
    return variant


def turn(v: np.ndarray) -> np.ndarray:
    """S v for S = [[0, −1], [1, 0]]: vectors (…, 2) turned by 90°."""
    out = np.empty(np.shape(v))
    np.negative(v[..., 1], out=out[..., 0])
    out[..., 1] = v[..., 0]
    return out


def unit_major(values: np.ndarray, per_unit: int) -> np.ndarray:
    """(N, k·a) → (N, k, a) view of a group's channels."""
    values = np.asarray(values, float)
    return values.reshape(values.shape[0], -1, per_unit)


# The registry of unit types by their platform-file ``type:`` name. Imported last: a type's module
# imports Channel and FrictionVariant from here.
from ropod_sysid.model.units.legs import legged  # noqa: E402
from ropod_sysid.model.units.omni import OmniUnits  # noqa: E402
from ropod_sysid.model.units.steered import SteeredUnits  # noqa: E402
from ropod_sysid.model.units.swivel import SwivelUnits  # noqa: E402

WHEEL_TYPES: dict[str, Any] = {cls.type_name: cls for cls in (SwivelUnits, OmniUnits,
                                                               SteeredUnits)}
# every wheel type also on a leg (an entry with ``leg:``): type names ``<type>+leg``
UNIT_TYPES: dict[str, Any] = WHEEL_TYPES | {f"{name}+leg": legged(cls)
                                            for name, cls in WHEEL_TYPES.items()}
