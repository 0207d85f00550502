"""`trajectory typical|optimize|check` for every unit type: the 5DPO's omni wheels, a platform
mixing smart wheels and omni wheels, and the unit types' angle predictions behind them."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.io.paramfile import read_truth_parameters
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import parameter_names, typical_parameters
from ropod_sysid.platform import load_platform, save_platform
from ropod_sysid.trajectory import (
    VARIANTS,
    Limits,
    Trajectory,
    check,
    optimize,
    predict_angles,
    predict_pivots,
    read_trajectory_csv,
    typical,
    variants,
)
from tests.test_units_pipeline import mixed_platform

ROOT = Path(__file__).resolve().parents[1]
OMNI = ROOT / "datasets" / "omni" / "platform.yaml"
TRUTH = ROOT / "datasets" / "omni" / "truth.json"


def sub_platform(platform, kind: str):
    """The platform's units of one type only (same settings)."""
    return replace(platform, units=tuple(u for u in platform.units if u.type == kind))


@pytest.fixture(scope="module")
def omni():
    return load_platform(OMNI)


@pytest.fixture(scope="module")
def omni_truth(omni):
    return read_truth_parameters(TRUTH, omni)


@pytest.fixture(scope="module")
def mixed():
    return mixed_platform()


def within(traj: Trajectory, limits: Limits) -> None:
    assert traj.speed().max() <= limits.v_max
    assert traj.acceleration().max() <= limits.a_max
    assert np.abs(traj.omega).max() <= limits.w_max
    assert np.abs(traj.twist_rates()[:, 2]).max() <= limits.alpha_max


# --------------------------------------------------------------------------- predicted angles


def test_omni_wheel_angles_integrate_the_actuator_rates(omni):
    """Along an arc at a constant twist, each wheel turns at (h·v + c ω)/r (O1) and its angle
    grows linearly; along a typical run the wheel angles are the trapezoidal integral of the
    model's actuator rates evaluated in the world frame (the heading turns)."""
    t = np.linspace(0.0, 4.0, 401)
    twist = np.tile([0.3, -0.1, 0.5], (t.size, 1))
    pred = predict_angles(t, twist[None], omni)
    heads = np.array([u.heading for u in omni.units])
    pos = omni.positions
    rate = (np.cos(heads) * 0.3 - np.sin(heads) * 0.1
            + (pos[:, 0] * np.sin(heads) - pos[:, 1] * np.cos(heads)) * 0.5) / 0.0325
    np.testing.assert_allclose(pred.rates[0], np.broadcast_to(rate, (t.size, 4)), atol=1e-12)
    np.testing.assert_allclose(pred.angles[0], np.outer(t, rate), atol=1e-12)
    np.testing.assert_array_equal(pred.actuator_rates, pred.rates)
    assert not pred.turning_units.any() and pred.flags == {}
    traj = typical(duration=12.0, platform=omni)
    q, qd, _ = traj.kinematics()
    world = PlatformModel(omni).actuator_rates(q, qd, np.zeros((t.size, 4)))
    pred = predict_angles(traj.t, traj.twist(), omni, initial=np.arange(4.0))
    np.testing.assert_allclose(pred.rates, world, atol=1e-9)
    steps = 0.5 * (world[1:] + world[:-1]) * np.diff(traj.t)[:, None]
    integral = np.arange(4.0) + np.vstack([np.zeros(4), np.cumsum(steps, axis=0)])
    np.testing.assert_allclose(pred.angles, integral, atol=1e-9)


def test_mixed_prediction_is_each_type_in_its_channels(mixed):
    """Every group predicts its own channels: the swivel units' pivot angles are those of the
    platform of the swivel units alone (eq. 8a), the omni wheels' those of the omni units alone;
    and every predicted rate is the model's angle rate at the predicted angles."""
    traj = typical(duration=12.0, platform=mixed)
    twists = np.stack([v.twist() for v in variants(traj).values()])
    pred = predict_angles(traj.t, twists, mixed)
    lay = mixed.layout
    np.testing.assert_array_equal(pred.turning_units, [False, True, True, False])
    piv = predict_pivots(traj.t, twists, sub_platform(mixed, "swivel"))
    delta = [lay.angle_names.index(f"delta_{u}") for u in "23"]
    np.testing.assert_array_equal(pred.angles[..., delta], piv.delta)
    np.testing.assert_array_equal(pred.turning[..., 1:3], piv.rate)
    assert not piv.pulling.any() and np.abs(piv.rate).max() < 1.5
    assert not pred.flags["pulling (wheel flip)"].any()
    omni_only = predict_angles(traj.t, twists, sub_platform(mixed, "omni"))
    phi = [lay.angle_names.index(f"phi_{u}") for u in "14"]
    np.testing.assert_allclose(pred.angles[..., phi], omni_only.angles, atol=1e-12)
    q, qd, _ = traj.kinematics()
    model = PlatformModel(mixed)
    np.testing.assert_allclose(pred.rates[0], model.angle_rates(q, qd, pred.angles[0]),
                               atol=1e-9)
    np.testing.assert_allclose(pred.actuator_rates[0],
                               model.actuator_rates(q, qd, pred.angles[0]), atol=1e-9)


# --------------------------------------------------------------------------- typical


def test_typical_on_omni_plans_no_pivots(omni):
    """No turning joint: the run is the one planned without a pivot-rate limit."""
    traj = typical(duration=20.0, platform=omni)
    np.testing.assert_array_equal(traj.twist(), typical(duration=20.0,
                                                        pivot_rate_max=None).twist())
    for vt in variants(traj).values():
        within(vt, Limits())


def test_typical_keeps_the_wheel_rate_limit(omni, mixed):
    for pf in (omni, mixed):
        free = typical(duration=20.0, platform=pf)
        limit = 0.7 * float(np.abs(predict_angles(free.t, free.twist(), pf).actuator_rates).max())
        traj = typical(duration=20.0, platform=pf, wheel_rate_max=limit)
        pred = predict_angles(traj.t, np.stack([v.twist() for v in variants(traj).values()]),
                              pf)
        assert 0.5 * limit < np.abs(pred.actuator_rates).max() <= limit
        assert not pred.flagged
        assert np.isnan(pred.turning_peak) if pf is omni else pred.turning_peak < 1.5
        assert traj.duration == pytest.approx(20.0)


# --------------------------------------------------------------------------- check


def test_check_on_omni_wheel_rates_and_identifiability(omni, omni_truth):
    t = np.linspace(0.0, 6.0, 1201)
    ramp = np.clip(t, 0, 1) * np.clip(6 - t, 0, 1)
    straight = Trajectory.from_twist(t, 0.5 * ramp, 0 * t, 0 * t)
    rep = check(straight, omni, Limits(wheel_rate_max=10.0), params=omni_truth)
    # along x only wheels 1 and 3 (headings ±π, 0) roll: |φ̇| = v / r
    np.testing.assert_allclose(rep.wheel_peak[:, [1, 3]], 0.5 / 0.0325, rtol=1e-12)
    np.testing.assert_allclose(rep.wheel_peak[:, [0, 2]], 0.0, atol=1e-12)
    assert rep.actuators == ["cur_0", "cur_1", "cur_2", "cur_3"]
    whats = {f.what for f in rep.findings}
    assert whats == {"wheel rate of unit 1, motor cur_1 [rad/s]",
                     "wheel rate of unit 3, motor cur_3 [rad/s]"}
    assert np.isnan(rep.pivot_peak).all() and np.isnan(rep.peaks["pivot_rate"])
    text = rep.text()
    assert "pivot rate" not in text and "EXCEEDED" in text
    assert "wheel rate |φ̇| (predicted) [rad/s]" in text
    # a typical run identifies every parameter of the 5DPO (per-wheel friction)
    rep = check(typical(duration=12.0, platform=omni), omni, params=omni_truth)
    assert rep.ok and rep.names == parameter_names(omni)
    assert rep.rank == len(rep.names) == 11 and np.all(np.isfinite(rep.std))
    data = rep.to_dict()
    assert data["pivot_rate_max"] == {v: {} for v in VARIANTS}
    assert set(data["wheel_rate_max"]["original"]) == {"cur_0", "cur_1", "cur_2", "cur_3"}
    body = check(typical(duration=12.0, platform=omni), omni, params=omni_truth,
                 friction="body")
    assert body.names[-6:] == ["fbv_x", "fbv_y", "fbv_w", "fbc_x", "fbc_y", "fbc_w"]


def test_check_true_values_of_other_platforms(omni, mixed):
    traj = typical(duration=12.0, platform=mixed)
    with pytest.raises(InputError, match=r"mixed\.yaml: no default true parameter values for "
                       r"a platform with omni and swivel units .*--params\) with at least m_b "
                       "and Jzz_b") as exc:
        check(traj, mixed)
    assert "\n" not in str(exc.value)
    rep = check(traj, mixed, params={"m_b": 30.0, "Jzz_b": 3.0})
    np.testing.assert_array_equal(rep.true_values,
                                  typical_parameters(mixed, 30.0, 3.0).vector(rep.names))
    assert rep.ok and rep.rank == len(rep.names) == 22
    assert rep.turning == [1, 2]
    data = rep.to_dict()
    assert set(data["pivot_rate_max"]["original"]) == {"2", "3"}
    assert len(data["wheel_rate_max"]["original"]) == 6
    assert "unit 2      unit 3" in rep.text()


# --------------------------------------------------------------------------- optimize


@pytest.mark.parametrize("kind", ["omni", "mixed"])
def test_optimize_other_platforms(kind, omni, mixed, omni_truth):
    pf = omni if kind == "omni" else mixed
    params = omni_truth if kind == "omni" else {"m_b": 30.0, "Jzz_b": 3.0}
    limits = Limits(wheel_rate_max=12.0)
    opt = optimize(pf, duration=10.0, harmonics=3, maxiter=8, seed=0, limits=limits,
                   objective="cond")
    rep = check(opt.trajectory, pf, limits, params=params)
    assert rep.ok, [f.text() for f in rep.findings]
    assert rep.peaks["wheel_rate"] <= 12.0
    assert rep.condition_number == pytest.approx(opt.condition_number)
    assert opt.rank == opt.structural_rank == len(rep.names)
    for vt in variants(opt.trajectory).values():
        within(vt, limits)
    typ = check(typical(duration=10.0, platform=pf, wheel_rate_max=12.0), pf, params=params)
    assert opt.condition_number * 2 < typ.condition_number


# --------------------------------------------------------------------------- CLI


def one_line(res) -> str:
    assert res.exit_code == 2, res.output
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in res.output
    return lines[0]


def test_cli_typical_then_check_on_omni(tmp_path):
    runner = CliRunner()
    out = tmp_path / "run"
    res = runner.invoke(main, ["trajectory", "typical", "--platform", str(OMNI), "--duration",
                               "12", "--wheel-rate-max", "15", "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    runs = {v: read_trajectory_csv(out / f"{v}.csv") for v in VARIANTS}
    np.testing.assert_array_equal(runs["negated"].vx, -runs["original"].vx)
    args = ["trajectory", "check", str(out / "original.csv"), "--platform", str(OMNI),
            "--wheel-rate-max", "15"]
    res = runner.invoke(main, [*args, "--params", str(TRUTH), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["ok"] and data["rank"] == data["parameters"] == 11
    assert data["limits"]["wheel_rate_max"] == 15.0
    assert max(data["wheel_rate_max"]["original"].values()) <= 15.0
    res = runner.invoke(main, [*args, "--params", str(TRUTH), "--plot", str(tmp_path / "p.png")])
    assert res.exit_code == 0 and "Jrot_o" in res.output and "fov_0" in res.output
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"
    assert "--params" in one_line(runner.invoke(main, args))
    assert "--wheel-rate-max" in one_line(runner.invoke(main, [*args, "--wheel-rate-max",
                                                               "0"]))


def test_cli_optimize_and_check_a_mixed_platform(tmp_path, mixed):
    path = tmp_path / "mixed.yaml"
    save_platform(mixed, path)
    params = tmp_path / "base.json"
    params.write_text('{"m_b": 30.0, "Jzz_b": 3.0}')
    out = tmp_path / "opt"
    runner = CliRunner()
    res = runner.invoke(main, ["trajectory", "optimize", "--platform", str(path), "--duration",
                               "8", "--harmonics", "2", "--maxiter", "2", "--out", str(out),
                               "--quiet"])
    assert res.exit_code == 2 and "give the parameters (--params)" in res.output  # sigma needs
    res = runner.invoke(main, ["trajectory", "optimize", "--platform", str(path), "--duration",
                               "8", "--harmonics", "2", "--maxiter", "2", "--out", str(out),
                               "--quiet", "--params", str(params)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(main, ["trajectory", "check", str(out / "mirrored.csv"), "--platform",
                               str(path), "--params", str(params)])
    assert res.exit_code == 0, res.output
    assert "rank 22" in res.output and "\nfpc_3 " in res.output and "\nfoc_4 " in res.output
    assert "max predicted pivot rate per unit" in res.output


# --------------------------------------------------------------------------- steered wheels

STEERED = ROOT / "datasets" / "steered" / "platform.yaml"
# four steered wheels at the corners of a 0.6 m × 0.4 m rectangle (built like 001's units)
FOUR_STEERED = {"name": "four-steered", "wheel_radius": 0.1, "torque_constant": 2.0,
                "steer_torque_constant": 10.0, "friction_tanh_gain": 100.0,
                "units": [{"name": str(k + 1), "type": "steered", "position": p}
                          for k, p in enumerate([[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2],
                                                 [0.3, -0.2]])]}
BASE = {"m_b": 93.0, "Jzz_b": 4.51}


@pytest.fixture(scope="module")
def two_steered():
    return load_platform(STEERED)


@pytest.fixture(scope="module")
def four_steered():
    from ropod_sysid.platform import platform_from_dict

    return platform_from_dict(FOUR_STEERED, "<four>")


def steering_peaks(traj: Trajectory, pf) -> np.ndarray:
    """Predicted max |β̇| per variant (4,) [rad/s]."""
    pred = predict_angles(traj.t, np.stack([v.twist() for v in variants(traj).values()]), pf)
    assert pred.steering_units.all() and not pred.turning_units.any()
    return np.abs(pred.steering).max(axis=(1, 2))


@pytest.mark.parametrize("kind", ["two", "four"])
def test_typical_keeps_the_steering_rate_limit(kind, two_steered, four_steered):
    """The planned steering of all four variants stays within the limit, the default
    (195.95 °/s) and a tighter one that the run planned without it breaks; the variants are
    mirror images (equal peaks) and within the other limits."""
    pf = two_steered if kind == "two" else four_steered
    traj = typical(duration=30.0, platform=pf)
    peaks = steering_peaks(traj, pf)
    assert 1.5 < peaks.max() <= 3.42 and np.ptp(peaks) < 1e-9
    free = steering_peaks(typical(duration=30.0, platform=pf, steer_rate_max=None), pf)
    slow = typical(duration=30.0, platform=pf, steer_rate_max=1.5)
    assert free.max() > 2.0 and steering_peaks(slow, pf).max() <= 1.5
    for vt in variants(slow).values():
        within(vt, Limits())


def turning_run(turn: float, heading: float) -> Trajectory:
    """0.3 m/s along x from rest (1 s ramp), the direction of travel turned to ``heading``
    [rad] over ``turn`` s from t = 3 s (minimum jerk), stop at 9 s, rest until 10 s; ω = 0."""
    from ropod_sysid.trajectory.blends import _quintic

    t = np.arange(2001) * 0.005
    speed = 0.3 * (_quintic(t)[0] - _quintic(t - 8.0)[0])
    gamma = heading * _quintic((t - 3.0) / turn)[0]
    return Trajectory.from_twist(t, speed * np.cos(gamma), speed * np.sin(gamma), 0 * t)


def test_check_flags_the_steering_rate(two_steered):
    """A quarter turn of the direction of travel in 0.2 s steers both wheels at
    (π/2)·1.875/0.2 s = 14.7 rad/s: the check fails on it (text and JSON); in 2 s it passes.
    (The base's lateral acceleration, 0.3 m/s × 14.7 rad/s, is allowed here.)"""
    fast = check(turning_run(0.2, np.pi / 2), two_steered, Limits(a_max=5.0), params=BASE)
    assert not fast.ok
    assert {f.what for f in fast.findings} == {"steering rate of unit 1 [rad/s]",
                                                "steering rate of unit 2 [rad/s]"}
    assert fast.peaks["steer_rate"] == pytest.approx(np.pi / 2 * 1.875 / 0.2, rel=0.01)
    assert fast.findings[0].text().startswith("steering rate of unit 1 [rad/s]: 14.")
    assert "steer rate |β̇| (predicted) [rad/s]" in fast.text() and "EXCEEDED" in fast.text()
    data = json.loads(json.dumps(fast.to_dict()))
    assert data["ok"] is False and data["limits"]["steer_rate_max"] == 3.42
    assert set(data["steer_rate_max"]) == set(VARIANTS)
    assert data["steer_rate_max"]["original"]["1"] == pytest.approx(fast.peaks["steer_rate"])
    assert set(data["wheel_rate_max"]["original"]) == {"cur_1D", "cur_2D"}  # drives only
    slow = check(turning_run(2.0, np.pi / 2), two_steered, params=BASE)
    assert slow.ok and slow.peaks["steer_rate"] == pytest.approx(np.pi / 2 * 1.875 / 2, rel=0.01)


def test_singular_report_through_and_clear_of_a_singular_configuration(two_steered):
    """Two wheels at (±0.3, 0) translating along β: the constraint rows' base block has
    σ_2/σ_1 = 0.3 |cos β| (rows (−sin β, cos β, ±0.3 cos β)), so a run that turns from x to y
    is near singular (< 0.1) from β = acos(1/3) on, through its stop and its rest; one that
    turns to 45° never is (least ratio 0.3 cos 45°)."""
    traj = turning_run(2.0, np.pi / 2)
    rep = check(traj, two_steered, params=BASE).singular
    assert rep is not None and rep.rank == 2 and rep.margin == 0.1
    from ropod_sysid.trajectory.blends import _quintic

    gamma = np.pi / 2 * _quintic((traj.t - 3.0) / 2.0)[0]
    near = 0.3 * np.abs(np.cos(gamma)) < 0.1
    moving = traj.speed() >= 0.01
    w = np.gradient(traj.t)
    np.testing.assert_allclose(rep.fraction, (near * w).sum() / w.sum(), atol=1e-3)
    np.testing.assert_allclose(rep.moving_fraction, (near & moving) @ w / (moving @ w), atol=1e-3)
    t_on = traj.t[np.argmax(near)]
    np.testing.assert_allclose(rep.longest_start, t_on)
    np.testing.assert_allclose(rep.longest, 10.0 - t_on, atol=0.01)
    assert rep.min_ratio.max() < 1e-9 and 0.3 < rep.moving_fraction[0] < rep.fraction[0]
    text = check(traj, two_steered, params=BASE).text()
    assert "the fit loses the base rows for up to " in text
    clear = check(turning_run(2.0, np.pi / 4), two_steered, params=BASE)
    data = clear.to_dict()["singular"]["variants"]
    for v in VARIANTS:
        assert data[v]["fraction"] == data[v]["moving_fraction"] == data[v]["longest"] == 0.0
        assert data[v]["longest_start"] is None
        assert data[v]["min_ratio"] == pytest.approx(0.3 * np.cos(np.pi / 4), rel=1e-6)
    assert "the fit loses" not in clear.text()


def test_typical_steers_clear_of_singular_configurations(two_steered, four_steered):
    """001's two wheels are singular in a rotation in place and a sideways crab: the
    typical run rotates about a point 0.075 m beside the origin and crabs at 60°, and is near
    singular for less than 2 % of its moving time; four wheels at the corners never are."""
    from ropod_sysid.trajectory import run_singular_report

    two = run_singular_report(typical(duration=60.0, platform=two_steered), two_steered)
    assert two is not None and 0 < two.moving_fraction.max() < 0.02 and two.longest.max() < 0.5
    four = run_singular_report(typical(duration=30.0, platform=four_steered), four_steered)
    assert four is not None and four.fraction.max() == 0.0 and four.min_ratio.min() > 0.19
    assert run_singular_report(typical(duration=12.0), load_platform(OMNI)) is None


def test_cli_steering_rate_and_singular_report(tmp_path):
    runner = CliRunner()
    out = tmp_path / "run"
    res = runner.invoke(main, ["trajectory", "typical", "--platform", str(STEERED), "--duration",
                               "30", "--steer-rate-max", "2", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "near singular configurations (the fit leaves out the base rows): 0.0 % of the " \
        "moving time" in res.output
    args = ["trajectory", "check", str(out / "original.csv"), "--platform", str(STEERED)]
    params = tmp_path / "base.json"
    params.write_text(json.dumps(BASE))
    res = runner.invoke(main, [*args, "--params", str(params), "--json", "--steer-rate-max",
                               "2"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["ok"] and data["limits"]["steer_rate_max"] == 2.0
    assert 1.0 < max(data["steer_rate_max"]["negated"].values()) <= 2.0
    assert data["singular"]["variants"]["mirrored"]["moving_fraction"] == 0.0
    res = runner.invoke(main, [*args, "--params", str(params), "--json", "--steer-rate-max",
                               "1"])
    assert json.loads(res.output)["ok"] is False
    for sub, value in [("typical", "0"), ("check", "-1"), ("optimize", "nan")]:
        where = {"typical": ["--out", str(tmp_path / "x")],
                 "check": [str(out / "original.csv"), "--platform", str(STEERED)],
                 "optimize": ["--out", str(tmp_path / "x"), "--platform", str(STEERED)]}[sub]
        line = one_line(runner.invoke(main, ["trajectory", sub, *where, "--steer-rate-max",
                                             value]))
        assert line == f"error: --steer-rate-max {value}: must be a finite number > 0 rad/s"
    assert not (tmp_path / "x").exists()


def test_optimize_for_sigma_on_a_steered_platform(tmp_path):
    """--objective sigma under a sensor model plans for steered units too (the steering's own
    rows weighted with the θ rows, as the fit weighs them): four variants written, the
    predicted σ and bias of J_st printed, within the steering-rate limit."""
    out = tmp_path / "opt"
    res = CliRunner().invoke(main, ["trajectory", "optimize", "--platform", str(STEERED),
                                    "--params", str(STEERED.parent / "truth.json"),
                                    "--objective", "sigma", "--duration", "12", "--maxiter",
                                    "1", "--encoder-counts", "16384", "--current-noise", "0.03",
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "warning" not in res.output
    assert "Jst σ" in res.output
    assert sorted(p.name for p in out.iterdir()) == [
        "mirrored.csv", "mirrored_negated.csv", "negated.csv", "original.csv"]
    check = CliRunner().invoke(main, ["trajectory", "check", str(out / "original.csv"),
                                      "--platform", str(STEERED), "--params",
                                      str(STEERED.parent / "truth.json"), "--json"])
    report = json.loads(check.output)
    assert report["ok"]
    # check names the combinations as the fit does (a wheel that cannot slip sideways carries
    # J_rot,s/r² at its centre: n/r² = 200, Σ|p|²/r² = 18 for the shipped vehicle)
    assert report["combinations"]["m_b"] == "m_b +200·Jrot_s"
    assert report["combinations"]["Jzz_b"] == "Jzz_b +18·Jrot_s"
