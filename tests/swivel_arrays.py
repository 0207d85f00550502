"""Test helpers: the smart-wheel (swivel) arrays of a log or simulated run of an all-swivel
platform, as views into its unit-major channels (writes go through), and logs built from them.

δ (N, n), φ (N, n, 2) (wheels L, R) and currents (N, n, 2) are what the swivel tests speak in;
the library itself keeps every unit type's channels in ``angles`` (N, J) and ``currents``
(N, A) (:class:`ropod_sysid.io.log.Log`)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ropod_sysid.io.log import Log
from ropod_sysid.model.units.swivel import SwivelSpec, angles_of
from ropod_sysid.platform import Layout, platform_of


def D(x: Any) -> np.ndarray:
    """Pivot angles δ (N, n): a view into ``x.angles``."""
    return x.angles[:, 0::3]


def P(x: Any) -> np.ndarray:
    """Wheel angles φ (N, n, 2): a view into ``x.angles``."""
    a = x.angles
    return a.reshape(a.shape[0], -1, 3)[..., 1:]


def C(log: Log) -> np.ndarray:
    """Motor currents (N, n, 2): a view into ``log.currents``."""
    c = log.currents
    return c.reshape(c.shape[0], -1, 2)


def T(res: Any) -> np.ndarray:
    """Applied wheel torques (N, n, 2) of a simulated run: a view into ``res.tau``."""
    return res.tau.reshape(res.tau.shape[0], -1, 2)


def layout_of(units: list[str]) -> Layout:
    """The channel layout of smart-wheel units with these names."""
    return platform_of([SwivelSpec(str(u), (0.0, 0.0)) for u in units]).layout


def make_log(t: np.ndarray, units: list[str] | Layout, delta: np.ndarray, phi: np.ndarray,
             current: np.ndarray, pose: np.ndarray | None = None, source: str = "<memory>",
             notes: list[str] | None = None, piece: int = 0) -> Log:
    """A log of smart-wheel units from δ (N, n), φ (N, n, 2) and currents (N, n, 2)."""
    layout = units if isinstance(units, Layout) else layout_of(list(units))
    delta = np.asarray(delta, float)
    n, k = delta.shape
    angles = np.empty((n, k, 3))
    angles[..., 0] = delta
    angles[..., 1:] = phi
    return Log(np.asarray(t, float), layout, angles.reshape(n, 3 * k),
               np.ascontiguousarray(np.asarray(current, float).reshape(n, 2 * k)), pose, source,
               list(notes or []), piece)


def with_arrays(log: Log, *, delta: np.ndarray | None = None, phi: np.ndarray | None = None,
                current: np.ndarray | None = None, **changes: Any) -> Log:
    """A copy of ``log`` with its swivel arrays (and other fields) replaced."""
    out = make_log(log.t, log.layout, D(log) if delta is None else delta,
                   P(log) if phi is None else phi, C(log) if current is None else current,
                   log.pose, log.source, log.notes, log.piece)
    return dataclasses.replace(out, **changes) if changes else out


__all__ = ["C", "D", "P", "T", "angles_of", "layout_of", "make_log", "with_arrays"]
