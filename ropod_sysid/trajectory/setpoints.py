"""The setpoints of a run (:class:`Trajectory`) and their CSV file.

A run is a series of base-twist setpoints in the *base* frame — t [s], vx, vy [m/s], ω [rad/s] —
that the robot's velocity controller tracks; its planned pose x, y [m], θ [rad] in the world
frame follows by integration from zero (:func:`integrate_pose`). The CSV file holds the columns
``t, vx, vy, omega, x, y, theta`` (the pose columns optional on reading), and for a platform
whose units plan coordinates of their own (a leg's extension) their log columns (``leg_u``
[m]) after them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ropod_sysid.io.atomic import atomic_write_text
from ropod_sysid.io.csvlog import read_numeric_table
from ropod_sysid.simulate import Setpoints

COLUMNS = ("t", "vx", "vy", "omega", "x", "y", "theta")
TWIST_COLUMNS = ("t", "vx", "vy", "omega")
POSE_COLUMNS = ("x", "y", "theta")


def integrate_pose(t: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                   omega: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World pose (x, y [m], θ [rad]) from base-frame twist setpoints, starting at zero.

    θ is the trapezoidal integral of ω; the world velocity R(θ)(vx, vy) is integrated the same
    way (second order in the sample interval). Arrays (..., N) over the last axis.
    """
    t = np.asarray(t, float)
    dt = np.diff(t)

    def cumtrapz(f: np.ndarray) -> np.ndarray:
        out = np.zeros_like(f)
        out[..., 1:] = np.cumsum(0.5 * (f[..., 1:] + f[..., :-1]) * dt, axis=-1)
        return out

    theta = cumtrapz(np.asarray(omega, float))
    c, s = np.cos(theta), np.sin(theta)
    x = cumtrapz(c * vx - s * vy)
    y = cumtrapz(s * vx + c * vy)
    return x, y, theta



@dataclass(frozen=True, eq=False)
class Trajectory:
    """Base-twist setpoints and the planned pose of one run.

    Attributes
    ----------
    t : (N,) time [s], strictly increasing
    vx, vy : (N,) base velocity in the base frame [m/s]
    omega : (N,) rotation rate [rad/s]
    x, y : (N,) planned position of the base origin in the world frame [m], zero at t[0]
    theta : (N,) planned heading [rad], zero at t[0]
    planned : log column → (N,) setpoints of own coordinates the run plans (a leg's
        extension ``leg_u`` [m]; :attr:`~ropod_sysid.model.PlatformModel.planned_columns`)
    """

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    omega: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    planned: dict[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def from_twist(cls, t: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                   omega: np.ndarray, planned: dict[str, np.ndarray] | None = None
                   ) -> Trajectory:
        """A trajectory whose pose is integrated from the twist (:func:`integrate_pose`)."""
        t, vx, vy, omega = (np.asarray(a, float).copy() for a in (t, vx, vy, omega))
        x, y, theta = integrate_pose(t, vx, vy, omega)
        return cls(t, vx, vy, omega, x, y, theta, dict(planned or {}))

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def twist(self) -> np.ndarray:
        """(N, 3) base-frame twist (vx, vy, ω)."""
        return np.stack([self.vx, self.vy, self.omega], axis=-1)

    def to_setpoints(self) -> Setpoints:
        """The setpoints the simulator and the robot's velocity controller take."""
        return Setpoints(self.t - self.t[0], self.vx.copy(), self.vy.copy(), self.omega.copy(),
                         {c: v.copy() for c, v in self.planned.items()})

    def twist_rates(self) -> np.ndarray:
        """(N, 3) time derivative of the twist (v̇x, v̇y, ω̇) by second-order differences."""
        if self.n_samples < 3:
            return np.zeros((self.n_samples, 3))
        return np.stack([np.gradient(v, self.t, edge_order=2)
                         for v in (self.vx, self.vy, self.omega)], axis=-1)

    def kinematics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World-frame q, q̇, q̈ (N, 3) of the planned motion (thesis notation q_b^0).

        q̇ = (R(θ)(vx, vy), ω), q̈ = (R(θ)(v̇ + ω S v), ω̇) with S the 90° turn.
        """
        rates = self.twist_rates()
        c, s = np.cos(self.theta), np.sin(self.theta)
        ax = rates[:, 0] - self.omega * self.vy
        ay = rates[:, 1] + self.omega * self.vx
        q = np.stack([self.x, self.y, self.theta], axis=-1)
        qd = np.stack([c * self.vx - s * self.vy, s * self.vx + c * self.vy, self.omega], -1)
        qdd = np.stack([c * ax - s * ay, s * ax + c * ay, rates[:, 2]], axis=-1)
        return q, qd, qdd

    def speed(self) -> np.ndarray:
        """|(vx, vy)| [m/s]."""
        return np.hypot(self.vx, self.vy)

    def acceleration(self) -> np.ndarray:
        """|world acceleration of the base origin| = |v̇ + ω S v| [m/s²]."""
        rates = self.twist_rates()
        return np.hypot(rates[:, 0] - self.omega * self.vy, rates[:, 1] + self.omega * self.vx)

    def planned_series(self, columns: Sequence[str]) -> np.ndarray:
        """The planned coordinates ``columns`` (N, L) (NaN for a column not planned)."""
        return np.stack([self.planned.get(c, np.full(self.t.shape, np.nan)) for c in columns],
                        axis=-1) if columns else np.zeros((self.n_samples, 0))

    def write_csv(self, path: str | Path) -> None:
        """Write ``t, vx, vy, omega, x, y, theta`` (header first, shortest exact floats)
        atomically."""
        atomic_write_text(path, trajectory_csv_text(self))


def with_planned(traj: Trajectory, platform: object, seed: int = 0) -> Trajectory:
    """``traj`` with the own coordinates its platform's units plan for a run (a leg's
    extension: the type's ``plan_coordinates``); unchanged for a platform without any."""
    from ropod_sysid.model import PlatformModel

    if platform is None:
        return traj
    model = PlatformModel(platform)  # type: ignore[arg-type]
    planned: dict[str, np.ndarray] = {}
    for _, unit in model.groups:
        if hasattr(unit, "plan_coordinates"):
            planned |= unit.plan_coordinates(traj.t, traj.twist(), seed)
    return replace(traj, planned=planned) if planned else traj


def _shortest(v: float) -> str:
    """``repr`` of a float without a trailing ``.0`` (``1.0`` → ``1``)."""
    text = repr(v)
    return text[:-2] if text.endswith(".0") else text


def trajectory_csv_text(traj: Trajectory) -> str:
    """The CSV text of a trajectory (``\\n`` line ends): every float in the shortest form that
    reads back to it (``0.005``, not ``0.0050000000000000001``), a negative zero as ``0``."""
    data = np.column_stack([traj.t, traj.vx, traj.vy, traj.omega, traj.x, traj.y, traj.theta,
                            *traj.planned.values()])
    data = data + 0.0  # −0.0 + 0.0 is +0.0
    lines = [",".join([*COLUMNS, *traj.planned])]
    lines += [",".join(map(_shortest, row)) for row in data.tolist()]
    return "\n".join(lines) + "\n"


def write_trajectory_csv(traj: Trajectory, path: str | Path) -> None:
    """Write a trajectory CSV atomically (see :meth:`Trajectory.write_csv`)."""
    traj.write_csv(path)


def read_trajectory_csv(path: str | Path, planned: Sequence[str] = ()) -> Trajectory:
    """Read a setpoint CSV: ``t, vx, vy, omega`` required, ``x, y, theta`` optional, and the
    ``planned`` columns (a platform's :attr:`~ropod_sysid.model.PlatformModel.planned_columns`,
    all or none) when present.

    Without the pose columns the pose is integrated from the twist. Extra columns are ignored.
    Every problem raises :class:`InputError` with one line naming the file, line and column
    (the checks of the log reader, :func:`ropod_sysid.io.csvlog.read_numeric_table`).
    """
    cols = read_numeric_table(path, list(TWIST_COLUMNS), optional=POSE_COLUMNS)
    extra = {}
    if planned:
        got = read_numeric_table(path, ["t"], optional=tuple(planned))
        extra = {c: got[c] for c in planned if c in got}
    # mypy spreads a *generator over every positional parameter, planned's too
    if "x" in cols:
        return Trajectory(*(cols[c] for c in COLUMNS), extra)  # type: ignore[call-arg, arg-type]
    return Trajectory.from_twist(*(cols[c] for c in TWIST_COLUMNS), extra)  # type: ignore[call-arg, arg-type]


def _fine(traj: Trajectory, dt: float = 0.005) -> Trajectory:
    """The trajectory on a grid of at most ``dt``, twist interpolated linearly (as the
    simulator's and the robot's setpoint interpolation)."""
    steps = np.diff(traj.t)
    if steps.max() <= dt * (1 + 1e-9):
        return traj
    n = int(math.ceil(traj.duration / dt))
    t = traj.t[0] + np.linspace(0.0, traj.duration, n + 1)
    tw = np.stack([np.interp(t, traj.t, v) for v in (traj.vx, traj.vy, traj.omega)], axis=-1)
    return Trajectory.from_twist(t, tw[:, 0], tw[:, 1], tw[:, 2],
                                 {c: np.interp(t, traj.t, v) for c, v in traj.planned.items()})
