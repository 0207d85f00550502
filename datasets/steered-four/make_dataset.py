"""Remake the exact logs of four centred steered wheels at a rectangle's corners: the four
variants of a 30 s typical run and of a 30 s optimised run, simulated without sensor noise (a
check of the method: the tests add the noise, ``ropod_sysid.simulate.sensed``).

    python datasets/steered-four/make_dataset.py

Writes, beside this script: ``truth.json`` (001's m_C = 93 kg and Θ_C = 4.51 kg m², its B_i and
C_i, and its friction coefficients ±10 % per unit), ``trajectory/typical_*.csv.gz`` (as
``ropod-sysid trajectory typical --platform datasets/steered-four/platform.yaml --duration 30
--v-max 0.4 --w-max 1 --no-pivot-limit`` writes them: it drives and turns, or crabs, never
both at once, so every wheel on the left rolls as fast as its partner on the right and their
drive friction cannot be told apart), ``trajectory/optimized_*.csv.gz`` (as ``ropod-sysid
trajectory optimize --platform datasets/steered-four/platform.yaml --params
datasets/steered-four/truth.json --target all --v-max 0.4 --w-max 1 --no-pivot-limit`` writes
them: it drives, crabs and turns at once) and the logs ``typical_original.csv.gz`` …
``optimized_mirrored_negated.csv.gz``: 100 Hz (angles rounded to 1e-7 rad, currents to 1e-5
A) under the decentralised controllers of 001 (eqs. 24–25): PI speed loops on the drives (kp
20 N m s/rad, ki 200 N m/rad, 25.6 N m limit) and PD loops on the steering angles (D_s 40 N m
s/rad, P_s 800 N m/rad, 129 N m limit), each current the mean over its 10 ms log interval
(``simulate --current-average``: sampled at the log instant, the currents alias the steering
loops' fast torques and J_st comes out 2.3 % high, 4–6σ with sensor noise).
``platform.yaml`` (with its comments) is read, not written. Takes about six minutes.
"""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.params import typical_parameters
from ropod_sysid.platform import load_platform
from ropod_sysid.samples import write_dataset
from ropod_sysid.simulate import Controller, Sensors
from ropod_sysid.trajectory import Limits, optimize, typical, variants

HERE = Path(__file__).resolve().parent
RATE = 100.0
CONTROLLER = Controller(kp=20.0, ki=200.0, torque_limit=25.6, steer_kp=40.0, steer_ki=800.0,
                        steer_torque_limit=129.0)
M_B, JZZ_B = 93.0, 4.51  # 001 Table 1: m_C, Θ_C
LIMITS = Limits(v_max=0.4, w_max=1.0, pivot_rate_max=None)


def main() -> None:
    platform = load_platform(HERE / "platform.yaml")
    truth = typical_parameters(platform, M_B, JZZ_B)
    plain = typical(duration=30.0, v_max=0.4, w_max=1.0, pivot_rate_max=None, platform=platform)
    best = optimize(platform, 30.0, limits=LIMITS, target="all", params=truth.to_mapping(),
                    progress=True).trajectory
    runs = {f"{kind}_{name}": run for kind, traj in (("typical", plain), ("optimized", best))
            for name, run in variants(traj).items()}
    write_dataset(HERE, platform, truth, runs, rate=RATE, sensors=Sensors(current_average=True),
                  controller=CONTROLLER, write_platform=False, quiet=False)


if __name__ == "__main__":
    main()
