"""Remake the smart-wheel sample: a short simulated ropod run as the drives record it.

    python datasets/smartwheel/make_sample.py

Writes, beside this script:

``platform.yaml``
    The ropod with slightly off-square attachment points (as measured on a real base, which
    also makes all parameters identifiable) and the per-unit smart-wheel settings of this
    sample: unit 2 has its motors swapped (``left_motor: 2``), unit 3 its right motor's sign
    flipped (``sign_right: -1``), and every unit a pivot encoder offset (``pivot_offset``, the
    calibration of ``pivots.cal``).
``truth.json``
    The parameters the simulation used.
``sample.mcap``
    16 s at 200 Hz in the smart-wheel layout (topic ``/sw_ethercat_parser/data``, JSON
    encoding, ``sensors[4]`` of ``sens_ROPOD_SmartWheel_t`` fields), ``sensor_ts`` on an
    EtherCAT clock with an arbitrary epoch, pivot encoders wrapped to [−π, π) as the drives send
    them, and six corrupt frames (two zeroed, two with an implausible bus voltage, two with a
    bad clock) that the reader drops. The sensors are otherwise exact (no quantisation or
    noise; see ``datasets/ropod`` for noisy logs), with float fields rounded to 1e-6 to keep the
    file small (which moves a fit of it by less than 1e-4 relative).

Read it like any log, e.g. ``ropod-sysid inspect datasets/smartwheel/sample.mcap --platform
datasets/smartwheel/platform.yaml`` or ``ropod-sysid convert … sample.csv``. Takes about a
minute (RK4 at 1 kHz).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ropod_sysid.io.smartwheel import write_smartwheel
from ropod_sysid.params import thesis_fixed_masses
from ropod_sysid.platform import platform_from_dict, ropod_platform, save_platform
from ropod_sysid.simulate import Sensors, Setpoints, simulate

HERE = Path(__file__).resolve().parent
DURATION = 16.0
RATE = 200.0
EPOCH_NS = 836_123_456_789_012_345          # an EtherCAT clock reading (ns since 2000)
SENSORS = Sensors()    # exact sensors: the sample is about the layout, a fit recovers the truth

# the contract's ropod with the pivots 1–2 cm off the square and the robot's per-unit quirks:
# a pivot calibration on every unit, swapped motors on unit 2, a flipped right motor on unit 3
PLATFORM = ropod_platform().to_dict() | {"units": [
    {"name": "1", "pivot": [0.22, 0.20], "pivot_offset": 0.35},
    {"name": "2", "pivot": [-0.20, 0.22], "left_motor": 2, "pivot_offset": -1.2},
    {"name": "3", "pivot": [-0.21, -0.19], "sign_right": -1, "pivot_offset": 2.6},
    {"name": "4", "pivot": [0.20, -0.22], "pivot_offset": -0.05},
]}


def setpoints(duration: float = DURATION, dt: float = 0.01) -> Setpoints:
    """Rest to rest: forward, sideways and turning sinusoids of different periods under a C²
    smoothstep envelope, so that the base moves in every direction and the pivots swivel
    (forward throughout, so that the casters never flip over)."""
    t = np.arange(0.0, duration + dt / 2, dt)

    def smoothstep(u: np.ndarray) -> np.ndarray:
        u = np.clip(u, 0.0, 1.0)
        return u**3 * (10 - 15 * u + 6 * u**2)

    env = smoothstep(t / 1.5) * smoothstep((duration - 0.5 - t) / 1.5)
    vx = env * (0.5 + 0.3 * np.sin(2 * np.pi * t / 7.0))
    vy = env * 0.45 * np.sin(2 * np.pi * t / 9.0 + 0.5)
    om = env * 0.7 * np.sin(2 * np.pi * t / 4.5 + 1.0)
    return Setpoints(t, vx, vy, om)


def main() -> None:
    platform = platform_from_dict(PLATFORM, "make_sample.py")
    truth = thesis_fixed_masses(platform.unit_names)
    save_platform(platform, HERE / "platform.yaml")
    (HERE / "truth.json").write_text(
        json.dumps(truth.to_mapping(), indent=2) + "\n")
    (res,) = simulate(platform, truth, setpoints(), rate=RATE, sensors=SENSORS, quiet=False,
                      source="sample.mcap")
    frames = write_smartwheel(res.log, HERE / "sample.mcap", platform, encoding="json",
                              t0_ns=EPOCH_NS, wrap_pivot="pi",
                              corrupt={"zeroed": 2, "voltage": 2, "time": 2}, seed=5,
                              decimals=6)
    size = (HERE / "sample.mcap").stat().st_size
    print(f"sample.mcap: {frames} frames, {res.log.duration:.1f} s, {size / 1e3:.0f} kB")


if __name__ == "__main__":
    main()
