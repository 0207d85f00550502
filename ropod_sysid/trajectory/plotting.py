"""Plot of a planned run: the path of the four variants on the floor [m], and the speed [m/s],
acceleration [m/s²], rotation rate and, for units with a turning joint, the predicted turning
rates (the swivel's pivot rates, eq. 8a), for units with an actuated steering the planned
steering rates [rad/s] over time."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.limits import DEFAULT_FLOOR, Limits, _check_floor
from ropod_sysid.trajectory.prediction import (
    _variant_prediction,
    steering_points,
    trailing_points,
)
from ropod_sysid.trajectory.run_variants import variants
from ropod_sysid.trajectory.setpoints import Trajectory


def plot(traj: Trajectory, path: str | Path, floor: Sequence[float] = DEFAULT_FLOOR,
         limits: Limits | None = None, platform: Platform | None = None) -> None:
    """Plot the planned path of the four variants on the floor, and the speeds, rotation rate
    and predicted pivot rates (units with a turning joint) over time; PNG or SVG by the file
    suffix (written atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ropod_sysid.io.atomic import atomic_path

    path = Path(path)
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in ("png", "svg"):
        raise InputError(f"{path}: plot format {path.suffix or '(none)'!r} unknown; use a .png "
                         "or .svg file name")
    limits = limits or Limits()
    floor = _check_floor(floor)
    var = variants(traj)
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [1.2, 1]})
    x0, x1, y0, y1 = floor
    ax0.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ls="--", color="0.4"))
    for name, vt in var.items():
        ax0.plot(vt.x, vt.y, lw=1.2 if name == "original" else 0.7, label=name,
                 alpha=1.0 if name == "original" else 0.6)
    ax0.plot([0], [0], "ko", ms=4)
    ax0.set_aspect("equal")
    ax0.set_xlabel("x [m]")
    ax0.set_ylabel("y [m]")
    ax0.set_title("planned path of the base origin")
    ax0.legend(fontsize=8, loc="upper right")
    ax1.plot(traj.t, traj.speed(), label="|v| [m/s]")
    ax1.plot(traj.t, traj.acceleration(), label="|a| [m/s²]", lw=0.8)
    ax1.plot(traj.t, traj.omega, label="ω [rad/s]", lw=0.8)
    if platform is not None and (trailing_points(platform) is not None
                                 or steering_points(platform) is not None):
        fine, _, pred = _variant_prediction(traj, platform)
        for rates, which, label, limit, ls in (
                (pred.turning, pred.turning_units, "max |δ̇| [rad/s]", limits.pivot_rate_max, ":"),
                (pred.steering, pred.steering_units, "max |β̇| [rad/s]", limits.steer_rate_max,
                 "-.")):
            if rates is None or not which.any():
                continue
            ax1.plot(fine.t, np.abs(rates[..., which]).max(axis=(0, 2)), label=label, lw=0.8)
            if limit is not None:
                ax1.axhline(limit, color="0.5", ls=ls, lw=0.8)
    ax1.axhline(limits.v_max, color="0.5", ls="--", lw=0.8)
    ax1.set_xlabel("t [s]")
    ax1.set_title("setpoints and limits")
    ax1.legend(fontsize=8)
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt, dpi=110)
    except OSError as exc:
        raise InputError(f"{path}: cannot write the plot ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)
