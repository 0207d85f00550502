"""Remake the shipped sample: four variants of a ~60 s typical run of the ropod, simulated.

    python datasets/ropod/make_dataset.py

Writes, beside this script: ``platform.yaml`` (the thesis's ropod), ``truth.json`` (the
parameters the simulation used), ``trajectory/*.csv.gz`` (the setpoints of the four variants of
thesis Sec. VI-A, as ``ropod-sysid trajectory typical --duration 60`` writes them) and
``original.csv.gz`` … ``mirrored_negated.csv.gz``, their simulated runs: 100 Hz logs with
2¹⁴-count encoders, 30 mA current noise and 0.5 ms timestamp jitter. Values are rounded far
below the sensor resolution (angles to 1e-7 rad, currents to 1e-5 A, time to 1 µs) and
gzip-compressed, which keeps the set under 5 MB. Takes a few seconds (RK4 at 1 kHz, compiled;
minutes with the numpy path).
"""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.params import thesis_fixed_masses
from ropod_sysid.platform import ropod_platform
from ropod_sysid.samples import write_dataset
from ropod_sysid.simulate import Sensors
from ropod_sysid.trajectory import typical, variants

HERE = Path(__file__).resolve().parent
RATE = 100.0
SENSORS = Sensors(encoder_counts=2**14, current_noise=0.03, jitter=0.0005, seed=2021)


def main() -> None:
    platform = ropod_platform()
    truth = thesis_fixed_masses(platform.unit_names)
    runs = variants(typical(duration=60.0, platform=platform, seed=0))
    write_dataset(HERE, platform, truth, runs, rate=RATE, sensors=SENSORS)


if __name__ == "__main__":
    main()
