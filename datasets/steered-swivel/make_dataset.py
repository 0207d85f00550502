"""Remake the exact logs of a platform mixing steered wheels and swivel casters: the four
variants of a 30 s optimised run, simulated without sensor noise (a check of the method: the
tests add the noise, ``ropod_sysid.simulate.sensed``).

    python datasets/steered-swivel/make_dataset.py

Writes, beside this script: ``truth.json`` (001's m_C = 93 kg and Θ_C = 4.51 kg m², the unit
types' typical values, every friction coefficient then scaled by 1 ± 10 % at random, seed 1),
``trajectory/*.csv.gz`` (the setpoints of the four variants, as ``ropod-sysid trajectory
optimize --platform datasets/steered-swivel/platform.yaml --params
datasets/steered-swivel/truth.json --target all --v-max 0.4 --w-max 1`` writes them; the
typical run never crabs and turns at once, and determines the casters' pivot friction to
13 % only) and ``original.csv.gz`` … ``mirrored_negated.csv.gz``: 100 Hz logs (angles rounded
to 1e-7 rad, currents to 1e-5 A) under the decentralised controllers (PI speed loops on every
drive: kp 20 N m s/rad, ki 200 N m/rad, 25.6 N m limit; PD loops on the steering angles: D_s
40 N m s/rad, P_s 800 N m/rad, 129 N m limit), each current the mean over its 10 ms log
interval (``simulate --current-average``: point samples alias the loops' torques, and the
casters' J_zz,wh comes out up to 19 % low). ``platform.yaml`` (with its comments) is read, not
written. Takes about four minutes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ropod_sysid.params import Parameters, typical_parameters
from ropod_sysid.platform import load_platform
from ropod_sysid.samples import write_dataset
from ropod_sysid.simulate import Controller, Sensors
from ropod_sysid.trajectory import Limits, optimize, variants

HERE = Path(__file__).resolve().parent
RATE = 100.0
CONTROLLER = Controller(kp=20.0, ki=200.0, torque_limit=25.6, steer_kp=40.0, steer_ki=800.0,
                        steer_torque_limit=129.0)
M_B, JZZ_B = 93.0, 4.51  # 001 Table 1: m_C, Θ_C
LIMITS = Limits(v_max=0.4, w_max=1.0)


def main() -> None:
    platform = load_platform(HERE / "platform.yaml")
    rng = np.random.default_rng(1)
    truth = Parameters({k: v * (1 + 0.1 * rng.uniform(-1, 1)) if k[0] == "f" else v
                        for k, v in typical_parameters(platform, M_B, JZZ_B).to_mapping().items()})
    best = optimize(platform, 30.0, limits=LIMITS, target="all", params=truth.to_mapping(),
                    progress=True).trajectory
    write_dataset(HERE, platform, truth, variants(best), rate=RATE,
                  sensors=Sensors(current_average=True), controller=CONTROLLER,
                  write_platform=False, quiet=False)


if __name__ == "__main__":
    main()
