"""Remake the shipped steered-wheel sample: four variants of a 30 s typical run of 001's
test vehicle (two centred steered wheels mounted diametrically, r = 0.1 m), simulated.

    python datasets/steered/make_dataset.py

Writes, beside this script: ``truth.json`` (the parameters the simulation used: 001 Table 1's
m_C, Θ_C, B_i and C_i, and its friction coefficients ±10 % per unit, signed as the contract
adds them), ``trajectory/*.csv.gz`` (the setpoints of the four variants, as ``ropod-sysid
trajectory typical --platform datasets/steered/platform.yaml --duration 30 --v-max 0.4
--w-max 1`` writes them) and ``original.csv.gz`` … ``mirrored_negated.csv.gz``: 100 Hz logs
with 2¹⁴-count encoders, 30 mA current noise and 0.5 ms timestamp jitter, under 001's
decentralised controllers (eqs. 24–25): PI speed loops on the drives (kp 20 N m s/rad, ki
200 N m/rad, 25.6 N m limit) and PD loops on the steering angles (D_s 40 N m s/rad, P_s
800 N m/rad, 129 N m limit). ``platform.yaml`` (with its comments) is read, not written. Takes
about two minutes.
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
SENSORS = Sensors(encoder_counts=2**14, current_noise=0.03, jitter=0.0005, seed=2001)
CONTROLLER = Controller(kp=20.0, ki=200.0, torque_limit=25.6, steer_kp=40.0, steer_ki=800.0,
                        steer_torque_limit=129.0)
M_B, JZZ_B = 93.0, 4.51  # 001 Table 1: m_C, Θ_C


def main() -> None:
    platform = load_platform(HERE / "platform.yaml")
    truth = typical_parameters(platform, M_B, JZZ_B)
    runs = variants(typical(duration=30.0, v_max=0.4, w_max=1.0, pivot_rate_max=None,
                            platform=platform, seed=0))
    write_dataset(HERE, platform, truth, runs, rate=RATE, sensors=SENSORS,
                  controller=CONTROLLER, write_platform=False, quiet=False)


if __name__ == "__main__":
    main()
