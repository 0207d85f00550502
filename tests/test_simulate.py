"""The simulator and odometry: energy, no-slip constraints, pose reconstruction, sensors."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.model import PlatformModel
from ropod_sysid.odometry import base_twist, odometry
from ropod_sysid.params import thesis_fixed_masses
from ropod_sysid.platform import ropod_platform
from ropod_sysid.signals import central_difference
from ropod_sysid.simulate import Controller, ForceSchedule, Sensors, Setpoints, record, simulate
from tests.swivel_arrays import D, P, angles_of


def test_energy_is_conserved_without_torque_and_friction():
    """Pushed by an external force, then left alone with zero wheel torque and no friction:
    the kinetic energy ½ q̇ᵀ M_dir q̇ stays constant (App. C, eq. 33 integrated by RK4)."""
    pf = ropod_platform()
    p = thesis_fixed_masses(pf.unit_names).without_friction()
    t = np.array([0.0, 0.3, 0.31, 2.0])
    force = ForceSchedule(t, np.array([[30.0, 20.0, 6.0], [30.0, 20.0, 6.0], [0, 0, 0],
                                       [0, 0, 0]]))
    still = Setpoints(t, 0 * t, 0 * t, 0 * t)
    (res,) = simulate(pf, p, still, controller=Controller(0.0, 0.0, 1.0), force=force,
                      initial=angles_of(np.array([0.3, -1.0, 2.0, 0.5])), rate=200.0)
    after = res.energy[res.log.t > 0.35]
    assert after.mean() > 0.1  # it moves
    assert np.ptp(after) < 1e-6 * after.mean()
    # the pivots swing (the casters turn) while the energy stays put
    assert np.ptp(D(res)[res.log.t > 0.35]) > 0.1


@pytest.fixture(scope="module")
def run(off_square, runs_off_square):
    return off_square, runs_off_square[1]


def test_no_slip_constraints_hold_along_a_run(run):
    """Eq. 7 (no side slip of the kinematic centre) and eq. 11 (rolling) on the recorded
    states, with rates from central differences of the 200 Hz samples."""
    pf, r = run
    dt = 1 / 200
    qd = central_difference(r.q, dt)
    delta_dot = central_difference(D(r), dt)
    phi_dot = central_difference(P(r), dt)
    theta_i = r.q[:, 2:3] + D(r)
    theta_i_dot = qd[:, 2:3] + delta_dot
    c_b, s_b = np.cos(r.q[:, 2:3]), np.sin(r.q[:, 2:3])
    px, py = pf.positions[:, 0], pf.positions[:, 1]
    # pivot velocity (5b) and kinematic-centre velocity (6b)
    xd_ib = qd[:, 0:1] + qd[:, 2:3] * (-s_b * px - c_b * py)
    yd_ib = qd[:, 1:2] + qd[:, 2:3] * (c_b * px - s_b * py)
    s_w = pf.units[0].caster_offset
    xd_i = xd_ib + theta_i_dot * s_w * np.sin(theta_i)
    yd_i = yd_ib - theta_i_dot * s_w * np.cos(theta_i)
    side = -np.sin(theta_i) * xd_i + np.cos(theta_i) * yd_i  # eq. 7
    speed = np.abs(qd[:, :2]).max()
    assert np.abs(side[2:-2]).max() < 2e-3 * speed
    # eq. 11 through the model's wheel rates
    model = PlatformModel(pf)
    want = model.actuator_rates(r.q, qd, r.angles).reshape(phi_dot.shape)
    assert np.abs((want - phi_dot)[2:-2]).max() < 2e-3 * np.abs(phi_dot).max()


def test_odometry_reproduces_the_pose(run):
    pf, r = run
    pose = odometry(PlatformModel(pf), r.log.angles)
    assert np.abs(pose[:, :2] - r.q[:, :2]).max() < 1e-4
    assert np.abs(pose[:, 2] - r.q[:, 2]).max() < 1e-4
    assert np.abs(r.q[:, :2]).max() > 1.0  # it went somewhere


def test_base_twist_inverts_the_wheel_rates(run):
    pf, r = run
    model = PlatformModel(pf)
    st = model.state(r.q, r.qd, r.angles)
    twist = base_twist(model, r.angles, st.angle_rate)
    c, s = np.cos(r.q[:, 2]), np.sin(r.q[:, 2])
    body = np.column_stack([c * r.qd[:, 0] + s * r.qd[:, 1], -s * r.qd[:, 0] + c * r.qd[:, 1],
                            r.qd[:, 2]])
    np.testing.assert_allclose(twist, body, atol=1e-10)


def test_controller_tracks_the_setpoints(run):
    from tests.conftest import four_variants

    pf, r = run
    sp = four_variants(8.0)[1]
    t = r.log.t
    want = sp.at(t)
    c, s = np.cos(r.q[:, 2]), np.sin(r.q[:, 2])
    vx = c * r.qd[:, 0] + s * r.qd[:, 1]
    vy = -s * r.qd[:, 0] + c * r.qd[:, 1]
    err = np.abs(np.column_stack([vx, vy, r.qd[:, 2]]) - want)
    assert err[t > 1.0].max() < 0.1


def test_sensor_effects(run):
    pf, r = run
    rng = np.random.default_rng(0)
    log = record(pf, r, r.log.t, Sensors(encoder_counts=4096, current_noise=0.05, jitter=1e-3),
                 rng, "noisy")
    step = 2 * np.pi / 4096
    np.testing.assert_allclose(P(log) / step, np.round(P(log) / step), atol=1e-9)
    assert np.all(np.diff(log.t) > 0)
    assert 0 < np.abs(log.t - r.log.t).max() <= 1e-3
    noise = log.currents - r.tau / pf.torque_constants()
    assert noise.std() == pytest.approx(0.05, rel=0.05)


def test_current_average_is_the_mean_over_the_log_interval(off_square, truth) -> None:
    """``Sensors(current_average=True)`` logs each current as the mean of the torques held over
    the control steps of the log interval centred on its sample (ten 1 ms steps at 100 Hz:
    exactly centred; fewer at the ends), while the run's ``tau`` keeps the torque at the
    sample instant (the default log's point sample) — both checked against a 1 kHz log of the
    same run, and the two differ (the speed loops' torques change within a log interval)."""
    t = np.arange(0.0, 0.41, 0.01)
    run = Setpoints(t, 0.8 * t, 0.3 * t, 1.0 * t)  # speeding up from rest in every direction
    k_t = off_square.torque_constants()
    fine = simulate(off_square, truth, run, rate=1000.0, engine="numba")[0]
    mean = simulate(off_square, truth, run, rate=100.0, engine="numba",
                    sensors=Sensors(current_average=True))[0]
    expect = np.array([fine.tau[max(10 * k - 5, 0):10 * k + 5].mean(axis=0)
                       for k in range(mean.log.t.size)])
    np.testing.assert_allclose(mean.log.currents, expect / k_t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mean.tau, fine.tau[::10], rtol=0, atol=1e-12)
    assert np.abs(mean.tau_mean - mean.tau).max() > 1e-4 * np.abs(mean.tau).max()
