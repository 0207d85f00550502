"""The in-memory log: the log channels (``docs/file-formats.md``) as arrays over samples."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Log:
    """One recorded (or simulated) run, in contract units.

    Attributes
    ----------
    t : (N,) float64
        Time [s], strictly increasing.
    units : list[str]
        Unit names in platform-file order.
    delta : (N, n) float64
        Pivot angles δ_i [rad].
    phi : (N, n, 2) float64
        Wheel angles φ_iL, φ_iR [rad], unwrapped, rolling forward positive.
    current : (N, n, 2) float64
        Motor currents of the left and right wheel [A].
    pose : (N, 3) float64 or None
        Base pose x_b, y_b, θ_b from an external tracker, when the log has it.
    source : str
        File the log came from (for messages).
    notes : list[str]
        What reading did to the data (resampling, dropped frames, …), for the user.
    piece : int
        Which piece of the file, counted from 0, when a log split at its time gaps is read in
        chunks (:func:`ropod_sysid.io.timebase.split_chunks`); else 0.
    """

    t: np.ndarray
    units: list[str]
    delta: np.ndarray
    phi: np.ndarray
    current: np.ndarray
    pose: np.ndarray | None = None
    source: str = "<memory>"
    notes: list[str] = field(default_factory=list)
    piece: int = 0

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n_samples else 0.0

    def columns(self) -> dict[str, np.ndarray]:
        """The log as contract columns (``t``, ``delta_u``, ``phi_uL`` …) in contract order."""
        cols: dict[str, np.ndarray] = {"t": self.t}
        for i, u in enumerate(self.units):
            cols[f"delta_{u}"] = self.delta[:, i]
            cols[f"phi_{u}L"] = self.phi[:, i, 0]
            cols[f"phi_{u}R"] = self.phi[:, i, 1]
            cols[f"cur_{u}L"] = self.current[:, i, 0]
            cols[f"cur_{u}R"] = self.current[:, i, 1]
        if self.pose is not None:
            cols["x_b"], cols["y_b"], cols["theta_b"] = self.pose.T
        return cols

    def slice(self, start: int, stop: int) -> Log:
        """Samples ``start:stop`` as a new log."""
        pose = None if self.pose is None else self.pose[start:stop]
        return Log(self.t[start:stop], list(self.units), self.delta[start:stop],
                   self.phi[start:stop], self.current[start:stop], pose, self.source,
                   list(self.notes), self.piece)


def join_logs(parts: list[Log], notes: list[str] | None = None) -> Log:
    """Consecutive pieces of one log as one log (the notes given, else the pieces')."""
    if len(parts) == 1 and notes is None:
        return parts[0]
    first = parts[0]

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])

    pose = None if first.pose is None else cat("pose")
    return Log(cat("t"), list(first.units), cat("delta"), cat("phi"), cat("current"), pose,
               first.source, [n for p in parts for n in p.notes] if notes is None else notes,
               first.piece)
