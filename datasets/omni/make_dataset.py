"""Remake the shipped omni-wheel sample: four variants of a 60 s typical run of the 5DPO robot
(004: four omni wheels at 90°, d = 0.089 m, r = 0.0325 m, M = 2.34 kg), simulated.

    python datasets/omni/make_dataset.py

Writes, beside this script: ``truth.json`` (the parameters the simulation used: the paper's
M and J, a wheel + rotor inertia of 2·10⁻⁴ kg m² and per-wheel friction), ``trajectory/*.csv.gz``
(the setpoints of the four variants, as ``ropod-sysid trajectory typical --platform
datasets/omni/platform.yaml --duration 60 --v-max 0.6 --w-max 2`` writes them) and
``original.csv.gz`` … ``mirrored_negated.csv.gz``: 100 Hz logs with 2¹⁴-count encoders, 10 mA
current noise and 0.5 ms timestamp jitter, under wheel speed loops tuned for the small robot
(kp 0.02 N m s/rad, ki 0.4 N m/rad, 0.6 N m limit). ``platform.yaml`` (with its comments) is read,
not written. Takes about a minute.
"""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.params import typical_parameters
from ropod_sysid.platform import load_platform
from ropod_sysid.samples import write_dataset
from ropod_sysid.simulate import Controller, Sensors
from ropod_sysid.trajectory import typical, variants

HERE = Path(__file__).resolve().parent
RATE = 100.0
SENSORS = Sensors(encoder_counts=2**14, current_noise=0.01, jitter=0.0005, seed=2004)
CONTROLLER = Controller(kp=0.02, ki=0.4, torque_limit=0.6)
M_B, JZZ_B = 2.34, 0.0228  # 004 Table III


def main() -> None:
    platform = load_platform(HERE / "platform.yaml")
    truth = typical_parameters(platform, M_B, JZZ_B)
    runs = variants(typical(duration=60.0, v_max=0.6, w_max=2.0, pivot_rate_max=None,
                            platform=platform, seed=0))
    write_dataset(HERE, platform, truth, runs, rate=RATE, sensors=SENSORS,
                  controller=CONTROLLER, write_platform=False)


if __name__ == "__main__":
    main()
