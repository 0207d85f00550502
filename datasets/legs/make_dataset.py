"""Remake the shipped legged sample: four variants of a 30 s typical run of a Justin-like base
(002: four centred steered wheels on passive legs), simulated.

    python datasets/legs/make_dataset.py

Writes, beside this script: ``truth.json`` (the parameters the simulation used: a 126 kg base
and four 6 kg leg carriages — about 150 kg —, 001's steering and wheel inertias and friction
coefficients and a linear guide's leg friction, −15 N s/m and −4 N, ±10 % per unit),
``trajectory/*.csv.gz`` (the setpoints of the four variants with the legs' planned
extensions, as ``ropod-sysid trajectory typical --platform datasets/legs/platform.yaml
--duration 30 --v-max 0.4 --w-max 0.5 --floor -5 5 -4 4 --curvature-radius-min 0`` writes
them: the sample predates the least curvature radius, whose default now plans another run) and
``original.csv.gz`` … ``mirrored_negated.csv.gz``: 250 Hz logs with 2¹⁴-count angle encoders
(the leg extensions exact), 30 mA current noise and 0.5 ms timestamp jitter, under 002's
low-level control: PI speed loops on the drives (kp 20 N m s/rad, ki 200 N m/rad, 30 N m
limit) and PD loops on the steering angles (D 10 N m s/rad, P 200 N m/rad, 28 N m limit), the
wheels' rates and angles from the kinematic model for the base twist and the legs' planned
rates. ``platform.yaml`` (with its comments) is read, not written. Takes about two minutes.
"""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.params import typical_parameters
from ropod_sysid.platform import load_platform
from ropod_sysid.samples import write_dataset
from ropod_sysid.simulate import Controller, Sensors
from ropod_sysid.trajectory import typical, variants

HERE = Path(__file__).resolve().parent
RATE = 250.0
SENSORS = Sensors(encoder_counts=2**14, current_noise=0.03, jitter=0.0005, seed=2002)
CONTROLLER = Controller(kp=20.0, ki=200.0, torque_limit=30.0, steer_kp=10.0, steer_ki=200.0,
                        steer_torque_limit=28.0)
M_B, JZZ_B = 126.0, 8.0  # the base without its legs


def main() -> None:
    platform = load_platform(HERE / "platform.yaml")
    truth = typical_parameters(platform, M_B, JZZ_B)
    runs = variants(typical(duration=30.0, v_max=0.4, w_max=0.5, pivot_rate_max=None,
                            floor=(-5.0, 5.0, -4.0, 4.0), platform=platform, seed=0))
    write_dataset(HERE, platform, truth, runs, rate=RATE, sensors=SENSORS,
                  controller=CONTROLLER, dt=2e-3, write_platform=False, quiet=False)


if __name__ == "__main__":
    main()
