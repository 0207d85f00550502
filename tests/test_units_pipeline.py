"""Every unit type through the one pipeline: simulate → log file → fit, for omni-wheeled robots
(004's 5DPO, a three-wheeled one), body-axis friction, and a platform mixing smart wheels
and omni wheels.

The simulator holds each control step's torque over the step (zero-order hold) and logs it at
the step's start, so the logged torque leads the motion by half a step: the noise-free fits use
``input_delay = dt/2``, the delay a real drive's log has too (at dt = 1 ms, without it J_rot,o
comes out 1.4 % high on the 5DPO at every log rate and span; with it 0.01 %). The runs here are
integrated at 400 Hz (dt = 2.5 ms) to keep the suite fast; a 10 s typical run is the shortest
that turns wheels 0 and 2 of the 5DPO enough to separate their friction (at 8 s the fit's rank
analysis reports fov_0 as not identifiable).
"""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.fit import FitOptions, fit_files, fit_logs
from ropod_sysid.io import read_log, write_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.model.base import BODY_FRICTION
from ropod_sysid.model.units.omni import OmniSpec
from ropod_sysid.model.units.swivel import SwivelSpec
from ropod_sysid.odometry import odometry
from ropod_sysid.params import Parameters, parameter_names, typical_parameters
from ropod_sysid.platform import load_platform, platform_from_dict, platform_of
from ropod_sysid.simulate import Controller, Sensors, record, simulate
from ropod_sysid.trajectory import typical, variants

from .conftest import four_variants
from .test_omni import PLATFORM as OMNI_PLATFORM

DT = 2.5e-3
HALF_STEP = DT / 2  # the zero-order hold's lead of the logged torque
OMNI_CONTROL = Controller(kp=0.02, ki=0.4, torque_limit=0.6)
PAPER_BODY = {"fbv_x": -0.4978, "fbv_y": -0.6763, "fbv_w": -0.0141,  # 004 Table III, added
              "fbc_x": -1.8738, "fbc_y": -2.2198, "fbc_w": -0.1385}


def runs(duration: float, v_max: float = 0.6, w_max: float = 2.0) -> list:
    """The four variants of a typical run as setpoints (no pivots to plan for)."""
    return [v.to_setpoints() for v in variants(typical(duration=duration, v_max=v_max,
                                                       w_max=w_max, pivot_rate_max=None,
                                                       seed=1)).values()]


def errors(result, truth: Parameters) -> dict[str, float]:
    names = result.solution.names
    true = truth.vector(names)
    return dict(zip(names, (result.solution.values - true) / np.abs(true), strict=True))


@pytest.fixture(scope="module")
def five_dpo():
    pf = load_platform(OMNI_PLATFORM)
    truth = typical_parameters(pf, 2.34, 0.0228)
    return pf, truth, simulate(pf, truth, runs(10.0), rate=200.0, dt=DT,
                              controller=OMNI_CONTROL)


def three_wheel_platform():
    ang = np.radians([90.0, 210.0, 330.0])
    specs = [OmniSpec(f"w{i}", (0.12 * np.cos(a), 0.12 * np.sin(a)), a + np.pi / 2, 0.03,
                      0.12) for i, a in enumerate(ang)]
    return platform_of(specs, "three-wheel")


# ------------------------------------------------------------------ omni: files and odometry
def test_omni_log_round_trips_through_csv_and_json_mcap(tmp_path, five_dpo) -> None:
    pf, _, sims = five_dpo
    log = sims[0].log
    assert pf.layout.columns() == ["phi_0", "cur_0", "phi_1", "cur_1", "phi_2", "cur_2",
                                   "phi_3", "cur_3"]
    for name in ("run.csv", "run.mcap"):
        write_log(log, tmp_path / name, pf)
        back = read_log(tmp_path / name, pf)
        np.testing.assert_array_equal(back.angles, log.angles)
        np.testing.assert_array_equal(back.currents, log.currents)
    head = (tmp_path / "run.csv").read_text().splitlines()[0]
    assert head == "t," + ",".join(pf.layout.columns())


def test_omni_wheel_odometry_follows_the_true_pose(five_dpo) -> None:
    pf, _, sims = five_dpo
    r = sims[1]
    pose = odometry(PlatformModel(pf), r.log.angles)
    np.testing.assert_allclose(pose, r.q - r.q[0], atol=1e-5)


def test_ros2_mcap_refuses_omni_units_in_one_line(tmp_path, five_dpo) -> None:
    from ropod_sysid.errors import InputError
    from ropod_sysid.io.mcapwrite import write_mcap_log

    pf, _, sims = five_dpo
    with pytest.raises(InputError, match="carries smart-wheel .swivel. units only"):
        write_mcap_log(sims[0].log, tmp_path / "x.mcap", "ros2")
    assert not (tmp_path / "x.mcap").exists()


# ------------------------------------------------------------------ omni: identification
def test_omni_noise_free_fit_recovers_every_parameter_to_one_percent(five_dpo) -> None:
    pf, truth, sims = five_dpo
    result = fit_logs([r.log for r in sims], pf, FitOptions(input_delay=HALF_STEP))
    assert result.solution.names == parameter_names(pf)
    assert result.solution.rank == len(result.solution.names)
    err = errors(result, truth)
    assert max(abs(e) for e in err.values()) < 0.01, err
    shared = fit_logs([r.log for r in sims], pf, FitOptions(friction="shared",
                                                            input_delay=HALF_STEP))
    assert shared.solution.names == ["m_b", "Jzz_b", "Jrot_o", "fov", "foc"]


def test_omni_fit_with_sensor_noise_is_within_three_sigma(five_dpo) -> None:
    """2¹⁴-count encoders and 30 mA current noise on the same runs: every error within 3σ."""
    pf, truth, sims = five_dpo
    rng = np.random.default_rng(4)
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03)
    logs = [record(pf, r, r.log.t, sensors, rng, f"noisy{k}") for k, r in enumerate(sims)]
    result = fit_logs(logs, pf, FitOptions(input_delay=HALF_STEP))
    z = (result.solution.values - truth.vector(result.solution.names)) / result.solution.std
    assert np.all(np.abs(z) < 3.0), dict(zip(result.solution.names, np.round(z, 2),
                                             strict=True))


def test_three_wheel_robot_is_identified() -> None:
    pf = three_wheel_platform()
    truth = typical_parameters(pf, 3.1, 0.04)
    sims = simulate(pf, truth, runs(10.0), rate=200.0, dt=DT, controller=OMNI_CONTROL)
    result = fit_logs([r.log for r in sims], pf, FitOptions(input_delay=HALF_STEP))
    assert [n for n in result.solution.names if n.startswith("fov")] == ["fov_w0", "fov_w1",
                                                                          "fov_w2"]
    err = errors(result, truth)
    assert max(abs(e) for e in err.values()) < 0.01, err


def test_body_axis_friction_of_seed_004_is_identified() -> None:
    """The paper's own friction model (004 eqs. 6–8, Table III values): simulated with it,
    fitted with ``friction="body"`` (the wheels then carry none)."""
    pf = load_platform(OMNI_PLATFORM)
    truth = Parameters({"m_b": 2.34, "Jzz_b": 0.0228, "Jrot_o": 2e-4} | PAPER_BODY)
    sims = simulate(pf, truth, four_variants(8.0), rate=200.0, dt=DT,
                    controller=Controller(kp=0.05, ki=1.0, torque_limit=0.6))
    result = fit_logs([r.log for r in sims], pf, FitOptions(friction="body",
                                                            input_delay=HALF_STEP))
    assert result.solution.names == ["m_b", "Jzz_b", "Jrot_o", *BODY_FRICTION]
    err = errors(result, truth)
    assert max(abs(e) for e in err.values()) < 0.01, err


# ------------------------------------------------------------------ a mixed platform
def mixed_platform():
    """Two smart wheels at the back, two omni wheels at the front of a ropod-sized base."""
    return platform_from_dict({
        "name": "mixed", "wheel_radius": 0.0525, "wheel_distance": 0.08,
        "caster_offset": 0.01, "hub_com_offset": -0.005, "torque_constant": 0.28,
        "units": [
            {"name": "1", "type": "omni", "position": [0.25, 0.2], "heading": 2.0,
             "wheel_radius": 0.05},
            {"name": "2", "pivot": [-0.21, 0.21]},
            {"name": "3", "pivot": [-0.21, -0.21]},
            {"name": "4", "type": "omni", "position": [0.25, -0.2], "heading": 1.0,
             "wheel_radius": 0.05},
        ]}, "mixed.yaml")


def test_mixed_platform_layout_and_names() -> None:
    pf = mixed_platform()
    assert pf.types == ["omni", "swivel"]
    assert pf.layout.columns() == ["phi_1", "cur_1", "delta_2", "phi_2L", "phi_2R", "cur_2L",
                                   "cur_2R", "delta_3", "phi_3L", "phi_3R", "cur_3L", "cur_3R",
                                   "phi_4", "cur_4"]
    assert parameter_names(pf) == [
        "m_b", "Jzz_b", "Jrot_o", "m_wh", "Jzz_wh", "Jrot_w", "fov_1", "foc_1", "fov_4",
        "foc_4", "fwv_2L", "fwc_2L", "fwv_2R", "fwc_2R", "fwv_3L", "fwc_3L", "fwv_3R", "fwc_3R",
        "fpv_2", "fpc_2", "fpv_3", "fpc_3"]
    assert [g.names for g in pf.groups] == [["1", "4"], ["2", "3"]]
    assert isinstance(pf.units[1], SwivelSpec)


def test_mixed_platform_is_identified() -> None:
    pf = mixed_platform()
    truth = Parameters(dict(typical_parameters(pf, 30.0, 3.0)) | {"Jrot_o": 0.004})
    sims = simulate(pf, truth, four_variants(8.0), rate=200.0, dt=DT)
    result = fit_logs([r.log for r in sims], pf, FitOptions(input_delay=HALF_STEP))
    err = errors(result, truth)
    assert result.solution.rank == len(result.solution.names)
    assert max(abs(e) for e in err.values()) < 0.01, err


# ------------------------------------------------------------------ a slow overhead tracker
def tracker_pose(r, rate: float, fps: float = 25.0, seed: int = 5) -> np.ndarray:
    """The pose a 25 fps tracker with 1 cm and 3° noise (004's) gives, NaN between
    frames, in the log's frame (zero at the start)."""
    rng = np.random.default_rng(seed)
    pose = np.full((r.log.n_samples, 3), np.nan)
    idx = np.arange(0, r.log.n_samples, int(round(rate / fps)))
    pose[idx, :2] = r.q[idx, :2] - r.q[0, :2] + rng.normal(0.0, 0.01, (idx.size, 2))
    pose[idx, 2] = r.q[idx, 2] - r.q[0, 2] + rng.normal(0.0, np.radians(3.0), idx.size)
    return pose


def test_slow_tracker_pose_reads_from_empty_cells_and_fuses_with_odometry(tmp_path,
                                                                          five_dpo) -> None:
    """The CSV's pose cells between tracker frames are empty; the fit takes the motion from
    wheel odometry and the tracker only for drift slower than 10 s, so on a run without slip it
    gives the odometry's values (a differentiated 25 fps pose would give m_b −99 %)."""
    import dataclasses

    pf, truth, sims = five_dpo
    logs = [dataclasses.replace(r.log, pose=tracker_pose(r, 200.0), source=f"tr{k}.csv")
            for k, r in enumerate(sims)]
    write_log(logs[0], tmp_path / "tr0.csv", pf)
    lines = (tmp_path / "tr0.csv").read_text().splitlines()
    assert lines[0].endswith(",x_b,y_b,theta_b") and lines[2].endswith(",,,")
    back = read_log(tmp_path / "tr0.csv", pf)
    np.testing.assert_array_equal(np.isnan(back.pose), np.isnan(logs[0].pose))
    for k, lg in enumerate(logs[1:], 1):
        write_log(lg, tmp_path / f"tr{k}.csv", pf)
    options = FitOptions(input_delay=HALF_STEP)
    plain = fit_logs([r.log for r in sims], pf, options)
    fused = fit_logs(logs, pf, options)  # in memory
    streamed = fit_files([tmp_path / f"tr{k}.csv" for k in range(4)], pf, options)
    np.testing.assert_allclose(fused.solution.values, plain.solution.values, rtol=5e-3)
    np.testing.assert_allclose(streamed.solution.values, fused.solution.values, rtol=1e-9)
    err = errors(fused, truth)
    assert max(abs(e) for e in err.values()) < 0.01, err


def test_slow_tracker_messages(tmp_path, five_dpo) -> None:
    from ropod_sysid.errors import InputError

    pf, _, sims = five_dpo
    log = sims[0].log
    pose = np.full((log.n_samples, 3), np.nan)
    pose[0] = 0.0
    import dataclasses

    write_log(dataclasses.replace(log, pose=pose), tmp_path / "one.csv", pf)
    with pytest.raises(InputError, match=r"one.csv: the pose columns hold 1 tracker frame; give "
                                         "at least 2"):
        fit_files([tmp_path / "one.csv"], pf)
    text = (tmp_path / "one.csv").read_text().splitlines()
    text[5] = text[5][:-2] + "0.1,,"
    (tmp_path / "partial.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(InputError, match="partial.csv: line 6, column 'y_b' is empty"):
        read_log(tmp_path / "partial.csv", pf)
