"""The disturbance observer of Sec. VII-B on a simulated push (eq. 40, 10 Hz low-pass)."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.simulate import ForceSchedule, simulate
from ropod_sysid.validate import validate_log
from tests.conftest import smooth_setpoints


@pytest.fixture(scope="module")
def pushed(off_square, truth):
    """A 5 s run pushed sideways with 60 N between 2 and 3 s (base frame)."""
    t = np.array([0.0, 2.0, 2.1, 2.9, 3.0, 5.0])
    f = np.zeros((6, 3))
    f[2:4, 1] = 60.0
    (res,) = simulate(off_square, truth, smooth_setpoints(5.0, 1, 1),
                      force=ForceSchedule(t, f), rate=200.0)
    return res


def test_observer_sees_the_push_and_nothing_else(off_square, truth, pushed):
    v = validate_log(pushed.log, off_square, truth)
    t, f_hat = v.t, v.f_hat
    during = (t > 2.3) & (t < 2.9)
    quiet = (t < 1.8) | (t > 3.4)
    assert np.median(f_hat[during, 1]) == pytest.approx(60.0, rel=0.1)
    assert np.abs(f_hat[quiet]).max() < 5.0
    assert v.share_above["force"] == pytest.approx(np.mean(np.hypot(*f_hat[:, :2].T) > 40))
    assert 0.05 < v.share_above["force"] < 0.3
    assert v.share_above["torque"] == 0.0


def test_clean_run_stays_below_the_thresholds(off_square, truth, runs_off_square):
    v = validate_log(runs_off_square[2].log, off_square, truth)
    assert v.share_above == {"force": 0.0, "torque": 0.0}
    assert v.observer_max["F_bx"] < 5 and v.observer_max["T_bz"] < 2
    assert v.rms["translation"] < 0.5


def test_the_model_simulated_forward_and_its_fit_percentage(off_square, truth,
                                                              runs_off_square):
    """The fitted model simulated forward under the measured torques alone (a free run from
    the first row: no controller, no restarts): the true parameters reproduce an exact run's
    base velocity to over 99.5 % (MATLAB compare's fit), 30 % heavier masses and inertias do
    not; the compiled and the numpy integration agree; a horizon leaves NaN after it."""
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.params import Parameters
    from ropod_sysid.regressor import preprocess
    from ropod_sysid.validate import base_frame, fit_percentage, free_run, simulated_velocity

    pre = preprocess(runs_off_square[0].log, off_square, input_delay=0.0005)
    i = slice(pre.trim, len(pre.t) - pre.trim)
    state = (pre.q[i], pre.qdd[i], pre.angles[i], pre.angle_rates[i], pre.tau[i])
    model = PlatformModel(off_square)
    measured = base_frame(pre.q[i][:, 2], pre.qd[i])
    good = fit_percentage(measured, simulated_velocity(model, truth, pre.t[i], pre.qd[i], state))
    heavy = Parameters({k: (1.3 * v if k in ("m_b", "Jzz_b", "m_wh") else v)
                        for k, v in truth.items()})
    bad = fit_percentage(measured, simulated_velocity(model, heavy, pre.t[i], pre.qd[i], state))
    assert np.all(good > 99.5), good
    assert np.all(bad < good - 5.0), (good, bad)
    # the numpy path (where a unit type has no kernel) integrates the same equations
    m = 60
    args = (pre.t[i][:m], pre.q[i][0], pre.qd[i][0], pre.angles[i][0], pre.tau[i][:m])
    compiled = free_run(model, truth, *args, max_step=1e-3)
    import ropod_sysid.simulate_jit as jit

    real = jit.groups_of
    try:
        jit.groups_of = lambda *a: None  # type: ignore[assignment]
        plain = free_run(model, truth, *args, max_step=1e-3)
    finally:
        jit.groups_of = real  # type: ignore[assignment]
    for c, n in zip(compiled, plain, strict=True):
        assert np.allclose(c, n, rtol=1e-9, atol=1e-10)
    short = simulated_velocity(model, truth, pre.t[i], pre.qd[i], state, horizon=1.0)
    assert np.isnan(short[pre.t[i] > pre.t[i][0] + 1.0 + 1e-9]).all()
    assert np.isfinite(short[pre.t[i] <= pre.t[i][0] + 1.0]).all()

