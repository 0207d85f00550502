"""Remake the shipped sample: four variants of a ~60 s typical run of the ropod, simulated.

    python datasets/ropod/make_dataset.py

Writes, beside this script: ``platform.yaml`` (the thesis's ropod), ``truth.json`` (the
parameters the simulation used), ``trajectory/*.csv.gz`` (the setpoints of the four variants of
thesis Sec. VI-A, as ``ropod-sysid trajectory typical --duration 60`` writes them) and
``original.csv.gz`` … ``mirrored_negated.csv.gz``, their simulated runs: 100 Hz logs with
2¹⁴-count encoders, 30 mA current noise and 0.5 ms timestamp jitter. Values are rounded far
below the sensor resolution (angles to 1e-7 rad, currents to 1e-5 A, time to 1 µs) and
gzip-compressed, which keeps the set under 5 MB. Takes a few minutes (RK4 at 1 kHz).
"""

from __future__ import annotations

import dataclasses
import gzip
import json
from pathlib import Path

import numpy as np

from ropod_sysid.io import write_log
from ropod_sysid.io.atomic import atomic_write_bytes
from ropod_sysid.params import thesis_fixed_masses
from ropod_sysid.platform import ropod_platform, save_platform
from ropod_sysid.simulate import Sensors, simulate
from ropod_sysid.trajectory import trajectory_csv_text, typical, variants

HERE = Path(__file__).resolve().parent
RATE = 100.0
SENSORS = Sensors(encoder_counts=2**14, current_noise=0.03, jitter=0.0005, seed=2021)


def main() -> None:
    platform = ropod_platform()
    truth = thesis_fixed_masses(platform.unit_names)
    save_platform(platform, HERE / "platform.yaml")
    (HERE / "truth.json").write_text(
        json.dumps(truth.to_mapping(), indent=2) + "\n")
    runs = variants(typical(duration=60.0, platform=platform, seed=0))
    (HERE / "trajectory").mkdir(exist_ok=True)
    for name, traj in runs.items():
        data = gzip.compress(trajectory_csv_text(traj).encode("utf-8"), mtime=0)
        atomic_write_bytes(HERE / "trajectory" / f"{name}.csv.gz", data)
    results = simulate(platform, truth, [tr.to_setpoints() for tr in runs.values()],
                       rate=RATE, sensors=SENSORS, quiet=False)
    for name, res in zip(runs, results, strict=True):
        log = res.log
        log = dataclasses.replace(log, t=np.round(log.t, 6), angles=np.round(log.angles, 7),
                                  currents=np.round(log.currents, 5))
        write_log(log, HERE / f"{name}.csv.gz")
        print(f"{name}: {log.n_samples} samples, {log.duration:.1f} s")


if __name__ == "__main__":
    main()
