"""Remake the exact logs of the Justin-like base on legs: the four variants of a 30 s typical
run, simulated without sensor noise (a check of the method: the tests add the noise,
``ropod_sysid.simulate.sensed``).

    python datasets/legs-exact/make_dataset.py

The platform and the truth are those of the noisy sample ``datasets/legs`` (``platform.yaml`` is
a copy of its file; ``truth.json`` is written: a 126 kg base, four 6 kg leg carriages, 001's
steering and wheel inertias and friction, a linear guide's leg friction, ±10 % per unit). Writes
``trajectory/*.csv.gz`` (the setpoints with the legs' planned extensions, as ``ropod-sysid
trajectory typical --platform datasets/legs-exact/platform.yaml --duration 30 --v-max 0.4
--w-max 0.5 --floor -5 5 -4 4`` writes them: the base's curvature radius at least the
platform's default, 0.81 m, 002 eq. 26) and ``original.csv.gz`` … ``mirrored_negated.csv.gz``:
250 Hz logs (angles rounded to 1e-7 rad, extensions to 1e-7 m, currents to 1e-5 A) under 002's
low-level control (PI speed loops on the drives: kp 20 N m s/rad, ki 200 N m/rad, 30 N m limit;
PD loops on the steering angles: D 10 N m s/rad, P 200 N m/rad, 28 N m limit) at a 1 ms
control step, each current the mean over its 4 ms log interval (``simulate
--current-average``). Takes about six minutes.
"""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.params import typical_parameters
from ropod_sysid.platform import load_platform
from ropod_sysid.samples import write_dataset
from ropod_sysid.simulate import Controller, Sensors
from ropod_sysid.trajectory import typical, variants
from ropod_sysid.trajectory.limits import default_curvature_radius

HERE = Path(__file__).resolve().parent
RATE = 250.0
CONTROLLER = Controller(kp=20.0, ki=200.0, torque_limit=30.0, steer_kp=10.0, steer_ki=200.0,
                        steer_torque_limit=28.0)
M_B, JZZ_B = 126.0, 8.0  # the base without its legs (as datasets/legs)


def main() -> None:
    platform = load_platform(HERE / "platform.yaml")
    truth = typical_parameters(platform, M_B, JZZ_B)
    runs = variants(typical(duration=30.0, v_max=0.4, w_max=0.5, pivot_rate_max=None,
                            floor=(-5.0, 5.0, -4.0, 4.0), platform=platform, seed=0,
                            curvature_radius_min=default_curvature_radius(platform)))
    write_dataset(HERE, platform, truth, runs, rate=RATE, sensors=Sensors(current_average=True),
                  controller=CONTROLLER, dt=1e-3, write_platform=False, quiet=False)


if __name__ == "__main__":
    main()
