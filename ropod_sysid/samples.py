"""Simulated sample datasets: the four variants of a run (thesis Sec. VI-A), simulated with
known parameters and written as a user would record them (the ``datasets/`` folders).

:func:`write_dataset` writes into a folder: ``platform.yaml``, ``truth.json`` (the parameters
the simulation used), ``trajectory/<variant>.csv.gz`` (the setpoints, as ``ropod-sysid
trajectory typical`` writes them) and ``<variant>.csv.gz``, the simulated logs. Values are
rounded far below any sensor's resolution (angles to 1e-7 rad, currents to 1e-5 A, time to
1 µs) and gzip-compressed with a fixed timestamp, so that a remake is byte-identical.
"""

from __future__ import annotations

import dataclasses
import gzip
import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ropod_sysid.io import write_log
from ropod_sysid.io.atomic import atomic_write_bytes
from ropod_sysid.params import Parameters
from ropod_sysid.platform import Platform, save_platform
from ropod_sysid.simulate import Controller, Sensors, simulate
from ropod_sysid.trajectory import Trajectory, trajectory_csv_text


def write_dataset(folder: str | Path, platform: Platform, truth: Parameters,
                  runs: Mapping[str, Trajectory], *, rate: float, sensors: Sensors,
                  controller: Controller | None = None, dt: float = 1e-3,
                  write_platform: bool = True, quiet: bool = False) -> None:
    """Simulate ``runs`` (variant name → trajectory) together and write the dataset
    (``write_platform=False``: keep a hand-written ``platform.yaml``)."""
    here = Path(folder)
    if write_platform:
        save_platform(platform, here / "platform.yaml")
    (here / "truth.json").write_text(json.dumps(truth.to_mapping(), indent=2) + "\n")
    (here / "trajectory").mkdir(exist_ok=True)
    for name, traj in runs.items():
        data = gzip.compress(trajectory_csv_text(traj).encode("utf-8"), mtime=0)
        atomic_write_bytes(here / "trajectory" / f"{name}.csv.gz", data)
    results = simulate(platform, truth, [tr.to_setpoints() for tr in runs.values()],
                       rate=rate, dt=dt, sensors=sensors, controller=controller, quiet=quiet)
    for name, res in zip(runs, results, strict=True):
        log = res.log
        log = dataclasses.replace(log, t=np.round(log.t, 6), angles=np.round(log.angles, 7),
                                  currents=np.round(log.currents, 5))
        write_log(log, here / f"{name}.csv.gz")
        if not quiet:
            print(f"{name}: {log.n_samples} samples, {log.duration:.1f} s")
