"""The in-memory log: the log channels (``docs/file-formats.md``) as arrays over samples."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ropod_sysid.platform import Layout


@dataclass
class Log:
    """One recorded (or simulated) run, in contract units.

    Attributes
    ----------
    t : (N,) float64
        Time [s], strictly increasing.
    layout : Layout
        The platform's channels (:attr:`ropod_sysid.platform.Platform.layout`): unit names,
        the names of the angle and current columns.
    angles : (N, J) float64
        Encoder angles [rad] of every unit, in ``layout.angle_names`` order (for a smart
        wheel: pivot δ, wheels φ_L, φ_R); wheel angles unwrapped.
    currents : (N, A) float64
        Motor currents [A] in ``layout.current_names`` order.
    pose : (N, 3) float64 or None
        Base pose x_b, y_b, θ_b from an external tracker, when the log has it; a tracker
        slower than the log leaves NaN rows between its frames.
    source : str
        File the log came from (for messages).
    notes : list[str]
        What reading did to the data (resampling, dropped frames, …), for the user.
    piece : int
        Which piece of the file, counted from 0, when a log split at its time gaps is read in
        chunks (:func:`ropod_sysid.io.timebase.split_chunks`); else 0.
    """

    t: np.ndarray
    layout: Layout
    angles: np.ndarray
    currents: np.ndarray
    pose: np.ndarray | None = None
    source: str = "<memory>"
    notes: list[str] = field(default_factory=list)
    piece: int = 0

    @property
    def units(self) -> list[str]:
        return list(self.layout.units)

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n_samples else 0.0

    def channel(self, name: str) -> np.ndarray:
        """One contract column by name (``delta_1``, ``cur_3``, ``x_b`` …), shape (N,)."""
        return self.columns()[name]

    def columns(self) -> dict[str, np.ndarray]:
        """The log as contract columns (``t``, then per unit its angles and currents)."""
        lay = self.layout
        by_name = dict(zip(lay.angle_names, self.angles.T, strict=True))
        by_name |= dict(zip(lay.current_names, self.currents.T, strict=True))
        cols: dict[str, np.ndarray] = {"t": self.t}
        for name in lay.columns():
            cols[name] = by_name[name]
        if self.pose is not None:
            cols["x_b"], cols["y_b"], cols["theta_b"] = self.pose.T
        return cols

    def slice(self, start: int, stop: int) -> Log:
        """Samples ``start:stop`` as a new log."""
        pose = None if self.pose is None else self.pose[start:stop]
        return Log(self.t[start:stop], self.layout, self.angles[start:stop],
                   self.currents[start:stop], pose, self.source, list(self.notes), self.piece)


def join_logs(parts: list[Log], notes: list[str] | None = None) -> Log:
    """Consecutive pieces of one log as one log (the notes given, else the pieces')."""
    if len(parts) == 1 and notes is None:
        return parts[0]
    first = parts[0]

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])

    pose = None if first.pose is None else cat("pose")
    return Log(cat("t"), first.layout, cat("angles"), cat("currents"), pose, first.source,
               [n for p in parts for n in p.notes] if notes is None else notes, first.piece)
