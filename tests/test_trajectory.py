"""Excitation trajectories: typical run, variants, pivot prediction, check, optimize, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.model import PlatformModel
from ropod_sysid.noise import SensorNoise
from ropod_sysid.platform import ropod_platform, save_platform
from ropod_sysid.trajectory import (
    VARIANTS,
    Limits,
    PlanningError,
    Trajectory,
    check,
    optimize,
    predict_pivots,
    read_trajectory_csv,
    typical,
    variants,
)
from tests.swivel_arrays import angles_of

FLOOR = (-3.0, 3.0, -2.0, 2.0)
OFF_SQUARE = [[0.25, 0.18], [-0.2, 0.22], [-0.23, -0.2], [0.19, -0.24]]


@pytest.fixture(scope="module")
def ropod():
    return ropod_platform()


@pytest.fixture(scope="module")
def off_square(ropod):
    return ropod.with_positions(OFF_SQUARE)


@pytest.fixture(scope="module")
def cli_typical(tmp_path_factory):
    """The default typical run written by the CLI and read back."""
    out = tmp_path_factory.mktemp("typical")
    res = CliRunner().invoke(main, ["trajectory", "typical", "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    return {v: read_trajectory_csv(out / f"{v}.csv") for v in VARIANTS}


def assert_within(traj: Trajectory, limits: Limits | None = None, floor=FLOOR) -> None:
    limits = limits or Limits()
    rates = traj.twist_rates()
    assert traj.speed().max() <= limits.v_max
    assert traj.acceleration().max() <= limits.a_max
    assert np.abs(traj.omega).max() <= limits.w_max
    assert np.abs(rates[:, 2]).max() <= limits.alpha_max
    assert floor[0] <= traj.x.min() and traj.x.max() <= floor[1]
    assert floor[2] <= traj.y.min() and traj.y.max() <= floor[3]


# --------------------------------------------------------------------------- typical


def test_typical_from_cli_respects_every_limit_and_the_floor(cli_typical):
    for traj in cli_typical.values():
        assert traj.duration == pytest.approx(60.0)
        assert_within(traj)
        # from rest to rest
        assert np.abs(traj.twist()[[0, -1]]).max() < 1e-9
    orig = cli_typical["original"]
    # it moves: straights at speed, rotations both ways, lateral moves
    assert orig.speed().max() > 0.6
    assert orig.omega.max() > 0.5 and orig.omega.min() < -0.5
    assert np.abs(orig.vy).max() > 0.3
    assert orig.vx.min() < -0.5  # backwards too


def test_variants_relations(cli_typical):
    o, m = cli_typical["original"], cli_typical["mirrored"]
    n, mn = cli_typical["negated"], cli_typical["mirrored_negated"]
    np.testing.assert_array_equal(m.vx, o.vx)
    np.testing.assert_array_equal(m.vy, -o.vy)
    np.testing.assert_array_equal(m.omega, -o.omega)
    np.testing.assert_array_equal(n.twist(), -o.twist())
    np.testing.assert_array_equal(mn.twist(), -m.twist())
    # the mirrored run is the original reflected in the x axis (left and right swapped)
    np.testing.assert_allclose(m.x, o.x, atol=1e-12)
    np.testing.assert_allclose(m.y, -o.y, atol=1e-12)
    np.testing.assert_allclose(m.theta, -o.theta, atol=1e-12)
    # the planned pose is the integral of the twist
    again = Trajectory.from_twist(o.t, o.vx, o.vy, o.omega)
    np.testing.assert_allclose(again.x, o.x, atol=1e-12)
    assert set(variants(o)) == set(VARIANTS)


def test_typical_pivot_rates_stay_below_the_limit(cli_typical, ropod):
    t = cli_typical["original"].t
    twists = np.stack([cli_typical[v].twist() for v in VARIANTS])
    pred = predict_pivots(t, twists, ropod)
    assert np.abs(pred.rate).max() < 1.5
    assert not pred.pulling.any()  # no unit ever leads its pivot: no wheel flip


def test_typical_is_smooth(cli_typical):
    traj = cli_typical["original"]
    acc = traj.twist_rates()
    dt = np.diff(traj.t)[0]
    jumps = np.abs(np.diff(acc, axis=0)).max(axis=0)
    # continuous acceleration: per 5 ms step it changes by a jerk × dt, far below any step
    assert jumps.max() < 0.03, jumps
    assert jumps.max() / dt < 6.0  # jerk [m/s³, rad/s³]
    assert np.abs(acc[[0, -1]]).max() < 1e-3


def test_predicted_pivot_rates_are_the_models(ropod):
    traj = typical(duration=15.0)
    pred = predict_pivots(traj.t, traj.twist(), ropod)
    q, qd, _ = traj.kinematics()
    rates = PlatformModel(ropod).angle_rates(q, qd, angles_of(pred.delta))
    model_rates = rates[:, 0::3]  # δ̇ of each unit
    np.testing.assert_allclose(pred.rate, model_rates, atol=1e-9)


@pytest.mark.parametrize("kwargs", [
    {"floor": (-2.0, 2.0, -1.5, 1.5)},
    {"seed": 3, "duration": 40.0},
    {"a_max": 0.5, "w_max": 0.6, "duration": 40.0},
])
def test_typical_other_settings_stay_inside(kwargs, ropod):
    traj = typical(**kwargs)
    limits = Limits(1.0, kwargs.get("a_max", 1.0), kwargs.get("w_max", 1.0), 1.0)
    floor = kwargs.get("floor", FLOOR)
    for vt in variants(traj).values():
        assert_within(vt, limits, floor)


def test_typical_bad_settings_are_one_line_errors():
    with pytest.raises(PlanningError, match="too short") as exc:
        typical(duration=2.0)
    assert "\n" not in str(exc.value)
    with pytest.raises(InputError, match="v_max"):
        typical(v_max=-1.0)
    with pytest.raises(InputError, match="floor"):
        typical(floor=(1.0, 2.0, -1.0, 1.0))


# --------------------------------------------------------------------------- CSV


@pytest.mark.parametrize("text, message", [
    ("t,vx,omega\n0,0,0\n1,0,0\n", r"column 'vy' missing"),
    ("t,vx,vy,omega\n0,0,0,0\n0.1,abc,0,0\n", r"line 3, column 'vx' has 'abc', which is not a"),
    ("t,vx,vy,omega\n0,0,0,0\n0.1,0,nan,0\n", r"line 3, column 'vy' is NaN"),
    ("t,vx,vy,omega\n0,0,0,0\n0.1,0,0,0\n0.1,0,0,0\n",
     r"line 4: time t=0.1 repeats t=0.1 of line 3 \(a duplicated timestamp\)"),
    ("t,vx,vy,omega,x\n0,0,0,0,0\n1,0,0,0,0\n", r"'y', 'theta' missing while 'x' present"),
    ("", r"empty"),
    ("t,vx,vy,omega\n0,0,0,0\n", r"only 1 data row"),
    ("t,vx,vy,omega\n0,0,0,0\n1,0,0\n", r"line \(3\) has 3 of 4 fields"),
])
def test_bad_trajectory_csv_messages(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as exc:
        read_trajectory_csv(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_twist_only_csv_gets_an_integrated_pose(tmp_path):
    path = tmp_path / "twist.csv"
    t = np.linspace(0, 4, 401)
    path.write_text("t,vx,vy,omega,extra\n" + "".join(
        f"{a:.17g},0.5,0,0.25,x\n" for a in t))
    traj = read_trajectory_csv(path)
    assert traj.theta[-1] == pytest.approx(1.0)
    # an arc of radius 2 m: x = 2 sin θ, y = 2 (1 − cos θ)
    assert traj.x[-1] == pytest.approx(2 * np.sin(1.0), abs=1e-5)
    assert traj.y[-1] == pytest.approx(2 * (1 - np.cos(1.0)), abs=1e-5)
    traj.write_csv(tmp_path / "back.csv")
    back = read_trajectory_csv(tmp_path / "back.csv")
    np.testing.assert_array_equal(back.y, traj.y)  # %.17g: exact


# --------------------------------------------------------------------------- check


def test_check_predicts_rank_condition_and_stds(ropod, off_square):
    traj = typical(duration=20.0)
    rep = check(traj, ropod)
    assert rep.ok
    assert len(rep.names) == 29
    # symmetric pivots: one combination of the inertial parameters is not identifiable
    assert rep.rank == 28 and np.isfinite(rep.condition_number)
    assert np.isinf(rep.conditioning.condition_number_full)
    assert np.all(np.isinf(rep.std[:5])) and np.all(np.isfinite(rep.std[5:]))
    rep_off = check(traj, off_square)
    assert rep_off.rank == 29 and np.all(np.isfinite(rep_off.std))
    # the predicted std scales with the noise
    rep2 = check(traj, off_square, noise=2.0)
    np.testing.assert_allclose(rep2.std, 2 * rep_off.std, rtol=1e-9)


def test_check_reports_violations_as_findings(ropod):
    t = np.linspace(0.0, 10.0, 1001)
    ramp = np.clip(t, 0, 1) * np.clip(10 - t, 0, 1)
    traj = Trajectory.from_twist(t, 2.0 * ramp, 0 * t, 0 * t)  # 2 m/s straight: 20 m
    rep = check(traj, ropod)
    assert not rep.ok
    whats = {f.what for f in rep.findings}
    assert any(w.startswith("speed") for w in whats)
    assert any(w.startswith("acceleration") for w in whats)
    assert any(w.startswith("floor") for w in whats)
    speed = next(f for f in rep.findings if f.what.startswith("speed"))
    assert speed.peak == pytest.approx(2.0) and speed.t_start == pytest.approx(0.5, abs=0.02)


# --------------------------------------------------------------------------- optimize


@pytest.fixture(scope="module")
def ropod_pair(ropod):
    d = 20.0
    return typical(duration=d), optimize(ropod, duration=d, maxiter=5, seed=0, objective="cond")


@pytest.fixture(scope="module")
def off_pair(off_square):
    d = 10.0
    return (typical(duration=d, platform=off_square),
            optimize(off_square, duration=d, maxiter=5, seed=0, objective="cond"))


def test_optimize_beats_typical_on_the_ropod(ropod, ropod_pair):
    typ, opt = ropod_pair
    rep_t, rep_o = check(typ, ropod), check(opt.trajectory, ropod)
    assert rep_t.rank == rep_o.rank == opt.structural_rank == 28
    assert rep_o.condition_number * 2 < rep_t.condition_number
    assert rep_o.condition_number == pytest.approx(opt.condition_number)
    for rep in (rep_t, rep_o):
        assert rep.ok, [f.text() for f in rep.findings]


def test_optimize_beats_typical_off_the_square(off_square, off_pair):
    typ, opt = off_pair
    rep_t, rep_o = check(typ, off_square), check(opt.trajectory, off_square)
    assert rep_t.rank == rep_o.rank == 29
    assert rep_o.condition_number * 2 < rep_t.condition_number
    for rep in (rep_t, rep_o):
        assert rep.ok, [f.text() for f in rep.findings]
    for vt in variants(opt.trajectory).values():
        assert_within(vt)
    acc = opt.trajectory.twist_rates()
    assert np.abs(np.diff(acc, axis=0)).max() < 0.03  # continuous acceleration


def test_the_objective_is_the_same_in_two_processes(ropod):
    """Split over two processes, each candidate's value is the same to the last digit as in
    one process (whole batches per process: a value can differ in its last digits with the
    other candidates of its batch), for populations that batch unevenly."""
    from ropod_sysid.trajectory.excitation import (
        DEFAULT_FLOOR,
        _check_floor,
        _Objective,
        sigma_target,
    )
    from ropod_sysid.trajectory.limits import Limits

    sig = sigma_target(ropod, "inertial", "per-wheel", SensorNoise())
    objs = [_Objective(ropod, 8.0, 5, Limits(), _check_floor(DEFAULT_FLOOR), "sigma",
                       "per-wheel", 10.0, 2.0, sigma=sig, processes=n) for n in (1, 2)]
    rng = np.random.default_rng(3)
    first = rng.uniform(-1.0, 1.0, (objs[0].n_base, 20))
    for obj in objs:
        obj(first)  # fixes the rows' variances; the split starts with the next call
    for n in (150, 131):  # three batches: one process takes one, the other two
        x = rng.uniform(-1.0, 1.0, (objs[0].n_base, n))
        one, two = objs[0](x), objs[1](x)
        assert objs[1].split is not None and objs[1].split.processes == 2
        np.testing.assert_array_equal(one, two)
    objs[1].close()


def test_optimize_is_repeatable_and_checks_its_input(ropod):
    a = optimize(ropod, duration=10.0, harmonics=3, maxiter=2, seed=4, objective="cond")
    # the candidates split over two processes: the same search, value for value
    b = optimize(ropod, duration=10.0, harmonics=3, maxiter=2, seed=4, objective="cond",
                 processes=2)
    np.testing.assert_array_equal(a.trajectory.vx, b.trajectory.vx)
    assert (a.value, a.evaluations) == (b.value, b.evaluations)
    assert a.coefficients.shape == (3, 7)
    with pytest.raises(InputError, match="objective"):
        optimize(ropod, objective="trace")
    with pytest.raises(InputError, match="harmonics"):
        optimize(ropod, harmonics=0)


@pytest.mark.slow
def test_fit_on_simulated_runs_optimised_at_least_as_good(off_square, off_pair):
    """Simulate the four variants of both runs (one batched simulation), fit each set."""
    from ropod_sysid.fit import FitOptions, fit_logs
    from ropod_sysid.params import parameter_names, thesis_fixed_masses
    from ropod_sysid.simulate import Sensors, simulate

    typ, opt = off_pair
    truth = thesis_fixed_masses(off_square.unit_names)
    runs = ([v.to_setpoints() for v in variants(typ).values()]
            + [v.to_setpoints() for v in variants(opt.trajectory).values()])
    res = simulate(off_square, truth, runs, rate=100.0, dt=2e-3,
                   sensors=Sensors(current_noise=0.05, seed=1))
    true_vec = truth.vector(parameter_names(off_square))
    rel_std, rel_err = [], []
    for part in (res[:4], res[4:]):
        fit = fit_logs([r.log for r in part], off_square, FitOptions())
        assert fit.solution.rank == 29
        rel_std.append(fit.solution.std / np.abs(true_vec))
        rel_err.append(np.abs(fit.solution.values - true_vec) / np.abs(true_vec))
    # the mean relative standard deviation over all parameters: the optimised run's is lower
    # (about half: friction is better excited); the inertial parameters alone are not (the
    # typical run accelerates harder)
    assert np.mean(rel_std[1]) <= np.mean(rel_std[0])
    assert np.mean(rel_err[1]) <= np.mean(rel_err[0])  # and so is the mean relative error


# --------------------------------------------------------------------------- CLI


@pytest.fixture(scope="module")
def platform_file(tmp_path_factory, ropod):
    path = tmp_path_factory.mktemp("pf") / "ropod.yaml"
    save_platform(ropod, path)
    return path


def test_cli_check_prints_condition_number_and_stds(cli_typical, platform_file, tmp_path):
    traj = cli_typical["original"]
    path = tmp_path / "run.csv"
    traj.write_csv(path)
    runner = CliRunner()
    res = runner.invoke(main, ["trajectory", "check", str(path), "--platform",
                               str(platform_file), "--plot", str(tmp_path / "run.png")])
    assert res.exit_code == 0, res.output
    assert "condition number (column-scaled, identifiable subspace)" in res.output
    assert "rank 28" in res.output
    for name in ("m_b", "fwv_1L", "fpc_4"):
        assert f"\n{name} " in res.output
    assert "rel. std" in res.output
    assert (tmp_path / "run.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = runner.invoke(main, ["trajectory", "check", str(path), "--platform",
                               str(platform_file), "--json", "--noise", "2"])
    assert res.exit_code == 0
    data = json.loads(res.output)
    assert data["rank"] == 28 and data["condition_number"] > 1
    assert data["predicted"]["fwv_1L"]["std"] > 0 and data["noise"] == 2.0


def test_cli_check_violations_exit_zero_bad_input_exit_two(platform_file, tmp_path):
    fast = tmp_path / "fast.csv"
    fast.write_text("t,vx,vy,omega\n0,0,0,0\n1,2,0,0\n2,2,0,0\n3,0,0,0\n")
    runner = CliRunner()
    res = runner.invoke(main, ["trajectory", "check", str(fast), "--platform",
                               str(platform_file)])
    assert res.exit_code == 0 and "EXCEEDED" in res.output
    bad = tmp_path / "bad.csv"
    bad.write_text("t,vx,vy,omega\n0,0,0,0\n0.1,x,0,0\n")
    for args in (["check", str(bad), "--platform", str(platform_file)],
                 ["check", str(fast), "--platform", str(platform_file), "--plot", "a.pdf"],
                 ["check", str(tmp_path / "none.csv"), "--platform", str(platform_file)],
                 ["typical", "--out", str(tmp_path / "o"), "--floor", "1", "2", "-1", "1"],
                 ["typical", "--out", str(tmp_path / "o"), "--duration", "1"]):
        res = runner.invoke(main, ["trajectory", *args])
        assert res.exit_code == 2, (args, res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), res.output


def test_cli_optimize_writes_the_variants(platform_file, tmp_path):
    out = tmp_path / "opt"
    res = CliRunner().invoke(main, ["trajectory", "optimize", "--platform", str(platform_file),
                                    "--duration", "10", "--harmonics", "3", "--maxiter", "2",
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "condition number" in res.output
    runs = {v: read_trajectory_csv(out / f"{v}.csv") for v in VARIANTS}
    np.testing.assert_array_equal(runs["negated"].vx, -runs["original"].vx)
    for traj in runs.values():
        assert_within(traj)
