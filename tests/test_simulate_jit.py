"""The compiled simulator (numba) against the numpy path, the reference: the same runs to
round-off on the ropod, the 5DPO, a platform mixing smart wheels and omni wheels, and the
steered wheels of 001 (two, four over-constrained ones, and mixed with swivel or omni wheels;
their steering loops and constraint rows), with friction (per wheel, shared, body axes), sensor
effects and an external force; free runs of a steered platform; and the numpy fallback when
numba or a kernel is missing."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import ropod_sysid
from ropod_sysid.errors import InputError
from ropod_sysid.model import PlatformModel
from ropod_sysid.model.units.omni import OmniUnits
from ropod_sysid.params import Parameters, thesis_fixed_masses, typical_parameters
from ropod_sysid.platform import load_platform, platform_from_dict
from ropod_sysid.simulate import (
    MIN_COMPILED_STEPS,
    Controller,
    ForceSchedule,
    Sensors,
    Setpoints,
    simulate,
)

from .conftest import DATASETS, four_variants, smooth_setpoints
from .test_omni import PLATFORM as OMNI_PLATFORM
from .test_steered import ENTRY, FOUR, MIXED
from .test_units_pipeline import OMNI_CONTROL, PAPER_BODY, mixed_platform

FIELDS = ("q", "qd", "qdd", "angles", "tau", "f_b", "energy", "tau_mean")
STEER_CONTROL = Controller(kp=20.0, ki=200.0, torque_limit=25.6)  # 001's drives (datasets/steered)
PUSH = ForceSchedule(np.array([0.0, 0.4, 0.5, 0.9]),
                     np.array([[0.0, 0.0, 0.0], [12.0, -8.0, 2.0], [12.0, -8.0, 2.0],
                               [0.0, 0.0, 0.0]]))


def assert_same_runs(a: list, b: list, rtol: float = 1e-10) -> None:
    """Every array of the runs equal to round-off (relative to the array's largest value)."""
    assert len(a) == len(b)
    for ra, rb in zip(a, b, strict=True):
        for f in FIELDS:
            x, y = getattr(ra, f), getattr(rb, f)
            assert x.shape == y.shape, f
            scale = max(np.abs(y).max(), 1e-300)
            assert np.abs(x - y).max() <= rtol * scale, (f, np.abs(x - y).max() / scale)
        np.testing.assert_array_equal(ra.log.t, rb.log.t)
        np.testing.assert_allclose(ra.log.angles, rb.log.angles, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ra.log.currents, rb.log.currents, rtol=0, atol=1e-9)


def assert_identical(a: list, b: list) -> None:
    """The runs of the same engine: bitwise equal arrays."""
    for ra, rb in zip(a, b, strict=True):
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(ra, f), getattr(rb, f))


def brisk(duration: float) -> list[Setpoints]:
    """The four variants of a short run that still moves: 0.3 s ramps, 0.1 s at rest (the
    engines are compared step by step; a long run adds time, not cases)."""
    return four_variants(duration, ramp=0.3, rest=0.1)


def both(*args: object, **kwargs: object) -> tuple[list, list]:
    return simulate(*args, engine="numba", **kwargs), simulate(*args, engine="numpy", **kwargs)


def test_ropod_runs_of_two_lengths_with_force_and_sensors(off_square) -> None:
    """Two runs of different length batched (the shorter one stops at its own end), pushed by
    an external force, recorded with quantised encoders, current noise and jitter."""
    truth = thesis_fixed_masses(off_square.unit_names)
    runs = [smooth_setpoints(0.7, 1, 1, ramp=0.3, rest=0.1),
            smooth_setpoints(0.5, -1, -1, ramp=0.3, rest=0.1)]
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03, jitter=2e-4, seed=3)
    fast, ref = both(off_square, truth, runs, rate=500.0, force=PUSH, sensors=sensors)
    assert [len(r.log.t) for r in fast] == [351, 251]
    assert np.abs(fast[0].f_b).max() == 12.0
    assert np.abs(fast[0].q[:, :2]).max() > 0.02  # it moved
    assert np.abs(fast[0].tau).max() > 0.5
    assert_same_runs(fast, ref)


def test_ropod_torque_limit_zero_angles_and_body_friction(off_square) -> None:
    """The anti-windup branch (a saturated controller), all-zero initial angles and body-axis
    friction in place of the units' (a swivel kernel without friction)."""
    truth = Parameters(dict(thesis_fixed_masses(off_square.unit_names).without_friction())
                       | {n: 10 * v for n, v in PAPER_BODY.items()})
    t = np.array([0.0, 0.05, 0.06, 0.5])
    step = Setpoints(t, np.array([0, 0, 0.8, 0.8]), 0 * t, np.array([0, 0, 1.0, 1.0]))
    fast, ref = both(off_square, truth, [step, brisk(0.5)[1]], rate=1000.0,
                     controller=Controller(kp=3.0, ki=30.0, torque_limit=0.8), initial=None)
    assert np.isclose(np.abs(fast[0].tau).max(), 0.8)
    assert_same_runs(fast, ref)


@pytest.mark.parametrize("friction", ["per-wheel", "body"])
def test_5dpo(friction: str) -> None:
    pf = load_platform(OMNI_PLATFORM)
    values = dict(typical_parameters(pf, 2.34, 0.0228))
    if friction == "body":
        values = {n: v for n, v in values.items() if n[:3] not in ("fov", "foc")} | PAPER_BODY
    truth = Parameters(values)
    fast, ref = both(pf, truth, brisk(0.8)[1:3], rate=200.0, controller=OMNI_CONTROL,
                     force=PUSH)
    assert np.abs(fast[0].qd[:, :2]).max() > 0.05
    assert_same_runs(fast, ref)


def test_mixed_platform_with_shared_friction() -> None:
    """Two groups (omni, swivel) whose channels interleave; friction given by its shared
    coefficients only (each unit reads the shared one)."""
    pf = mixed_platform()
    truth = Parameters({"m_b": 30.0, "Jzz_b": 3.0, "Jrot_o": 0.004, "m_wh": 4.2,
                        "Jzz_wh": 0.012, "Jrot_w": 0.0105, "fwv": -0.04, "fwc": -0.2,
                        "fpv": 0.18, "fpc": 0.02, "fov": -0.01, "foc": -0.05})
    fast, ref = both(pf, truth, brisk(0.6)[:2], rate=200.0, force=PUSH,
                     sensors=Sensors(current_noise=0.01, seed=1))
    assert np.abs(fast[1].q[:, :2]).max() > 1e-3
    assert_same_runs(fast, ref)


def steered_truth(pf: object) -> Parameters:
    """001's vehicle (Table 1: m_C, Θ_C; its units' values and friction ±10 % per unit)."""
    return typical_parameters(pf, 93.0, 4.51)


def steering(pf: object, res: object) -> np.ndarray:
    """The steering angles (N, E) of a run."""
    return res.angles[:, PlatformModel(pf).coordinate_channels]


def test_steered_runs_of_two_lengths_with_force_and_sensors() -> None:
    """001's two-wheeled vehicle: two runs of different length batched (the steering loops
    track the planned steering through the starts and stops), pushed by an external force,
    recorded with quantised encoders, current noise, jitter and interval-mean currents (2 ms
    steps: the numpy path takes about 3 ms a step for these units)."""
    pf = platform_from_dict(ENTRY, "<test>")
    runs = [smooth_setpoints(0.5, 1, 1, ramp=0.2, rest=0.1),
            smooth_setpoints(0.4, -1, -1, ramp=0.2, rest=0.1)]
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03, jitter=2e-4, seed=3,
                      current_average=True)
    fast, ref = both(pf, steered_truth(pf), runs, rate=250.0, dt=2e-3, force=PUSH,
                     sensors=sensors, controller=STEER_CONTROL)
    assert [len(r.log.t) for r in fast] == [126, 101]
    assert np.abs(fast[0].qd[:, :2]).max() > 0.05  # it moved
    assert np.ptp(steering(pf, fast[0]), axis=0).min() > 0.02  # and steered
    assert np.abs(fast[0].tau).max() > 1.0
    assert_same_runs(fast, ref)


def test_four_steered_wheels_with_body_friction() -> None:
    """Four steered wheels at a rectangle's corners: more constraint rows than their
    consistent rank (taken at rank 2), with body-axis friction (the drives then have none,
    the steering keeps its own)."""
    pf = platform_from_dict(FOUR, "<test>")
    values = {n: v for n, v in steered_truth(pf).items() if n[:3] not in ("fdv", "fdc")}
    truth = Parameters(values | {n: 10 * v for n, v in PAPER_BODY.items()})
    fast, ref = both(pf, truth, brisk(0.5)[2:3], rate=500.0, dt=2e-3, controller=STEER_CONTROL)
    assert np.abs(fast[0].qd[:, :2]).max() > 0.05
    assert_same_runs(fast, ref)


def test_steered_wheels_mixed_with_swivel_casters() -> None:
    """The shipped mixed platform (datasets/steered-swivel): two steered wheels and two swivel
    casters, whose pivots turn freely beside the steering motors."""
    pf = load_platform(DATASETS / "steered-swivel" / "platform.yaml")
    truth = Parameters(json.loads((DATASETS / "steered-swivel" / "truth.json").read_text()))
    run = smooth_setpoints(0.4, 1, -1, ramp=0.15, rest=0.05)
    fast, ref = both(pf, truth, run, rate=250.0, dt=2e-3, controller=STEER_CONTROL,
                     sensors=Sensors(current_noise=0.01, seed=2))
    assert np.abs(fast[0].qd[:, :2]).max() > 0.02
    assert_same_runs(fast, ref)


def test_steered_wheel_between_omni_wheels_with_shared_friction() -> None:
    """A steered wheel whose group comes after an omni group (its coordinate, constraint row
    and plan at their offsets; its channels between the omni wheels'), friction by shared
    coefficients."""
    entry = dict(MIXED, units=[MIXED["units"][1], MIXED["units"][0], MIXED["units"][2]])
    pf = platform_from_dict(entry, "<test>")
    truth = Parameters({"m_b": 30.0, "Jzz_b": 2.0, "Jst": 0.2, "Jrot_s": 0.02,
                        "Jrot_o": 0.004, "fdv": -0.3, "fdc": -0.8, "fsv": -2.0, "fsc": -2.1,
                        "fov": -0.01, "foc": -0.05})
    assert [g.type.type_name for g in pf.groups] == ["omni", "steered"]
    fast, ref = both(pf, truth, brisk(0.5)[3:], rate=250.0, dt=2e-3,
                     controller=STEER_CONTROL, force=PUSH)
    assert np.abs(fast[0].q[:, :2]).max() > 1e-3
    assert_same_runs(fast, ref)


def test_steered_free_run(monkeypatch) -> None:
    """A free run under given torques (:func:`ropod_sysid.validate.free_run`) of four steered
    wheels from a moving state: compiled and numpy the same to round-off, the generalized
    velocity with the steering rates (D columns) on both."""
    from ropod_sysid import simulate_jit
    from ropod_sysid.validate import free_run

    pf = platform_from_dict(FOUR, "<test>")
    truth = steered_truth(pf)
    (res,) = simulate(pf, truth, brisk(0.6)[:1], rate=100.0, controller=STEER_CONTROL,
                      engine="numba")
    model = PlatformModel(pf)
    k = 30  # from the middle of the run, 0.15 s
    rates = np.gradient(steering(pf, res), res.log.t, axis=0)
    args = (res.log.t[k:46], res.q[k], np.concatenate([res.qd[k], rates[k]]), res.angles[k],
            res.tau[k:46])
    compiled = free_run(model, truth, *args, max_step=1e-3)
    monkeypatch.setattr(simulate_jit, "groups_of", lambda *a: None)
    plain = free_run(model, truth, *args, max_step=1e-3)
    assert compiled[1].shape == (16, 7)
    for c, n in zip(compiled, plain, strict=True):
        assert c.shape == n.shape
        assert np.abs(c - n).max() <= 1e-10 * np.abs(n).max()


def test_numpy_fallback_without_a_kernel(monkeypatch, off_square) -> None:
    """A unit type without ``compiled``, or whose ``compiled`` declines the parameters
    (returns None), is simulated by the numpy path under ``auto``; asking for the compiled
    loop names the platform's types."""
    from ropod_sysid import simulate_jit

    pf = mixed_platform()
    truth = Parameters(dict(typical_parameters(pf, 30.0, 3.0)) | {"Jrot_o": 0.004})
    model = PlatformModel(pf)
    assert simulate_jit.groups_of(model, truth, "per-wheel") is not None
    with monkeypatch.context() as m:
        m.setattr(OmniUnits, "compiled", lambda self, params, variant="per-wheel": None)
        assert simulate_jit.groups_of(model, truth, "per-wheel") is None
    monkeypatch.setattr(ropod_sysid.simulate, "MIN_COMPILED_STEPS", 100)
    runs = brisk(0.25)[:1]  # 250 steps: long enough for the compiled loop (at this threshold)
    ref = simulate(pf, truth, runs, engine="numpy")
    monkeypatch.delattr(OmniUnits, "compiled")
    assert_identical(simulate(pf, truth, runs), ref)
    with pytest.raises(InputError, match=r"^engine 'numba': a unit type of mixed.yaml "
                                         r"\(omni, swivel\) has no compiled kernel; use engine "
                                         r"'numpy'$"):
        simulate(pf, truth, runs, engine="numba")


def test_numpy_fallback_without_numba(monkeypatch, off_square) -> None:
    truth = thesis_fixed_masses(off_square.unit_names)
    monkeypatch.setattr(ropod_sysid.simulate, "MIN_COMPILED_STEPS", 100)
    runs = brisk(0.25)[:1]  # 250 steps: the compiled loop's under auto (at this threshold)
    ref = simulate(off_square, truth, runs, engine="numpy")
    simulate(off_square, truth, runs, engine="numba")  # ropod_sysid.simulate_jit imported
    monkeypatch.setitem(sys.modules, "numba", None)  # import numba raises ImportError
    monkeypatch.delitem(sys.modules, "ropod_sysid.simulate_jit")
    monkeypatch.delattr(ropod_sysid, "simulate_jit")
    assert_identical(simulate(off_square, truth, runs), ref)
    with pytest.raises(InputError, match="^engine 'numba': numba is not installed; pip install "
                                         "numba, or use engine 'numpy'$"):
        simulate(off_square, truth, runs, engine="numba")


def test_unknown_engine(off_square) -> None:
    with pytest.raises(InputError, match="^engine 'jax': use auto, numba, numpy$"):
        simulate(off_square, thesis_fixed_masses(off_square.unit_names),
                 four_variants(0.3)[:1], engine="jax")


def test_auto_engine_by_run_length(off_square) -> None:
    """``auto`` simulates runs of fewer than MIN_COMPILED_STEPS steps with numpy (numba's
    start-up would cost more) and longer ones compiled: bitwise the results of that engine."""
    truth = thesis_fixed_masses(off_square.unit_names)
    short, long = four_variants(0.3)[:1], four_variants(1.0)[:1]
    assert round(0.3 / 1e-3) < MIN_COMPILED_STEPS <= round(1.0 / 1e-3)
    for runs, engine in ((short, "numpy"), (long, "numba")):
        assert_identical(simulate(off_square, truth, runs),
                         simulate(off_square, truth, runs, engine=engine))


def test_cli_engines_write_the_same_log(tmp_path, off_square) -> None:
    """``simulate --engine numba`` and ``--engine numpy`` write the same log to round-off (a
    0.3 s run: ``auto`` would take numpy); a bad ``--engine`` is one line."""
    from ropod_sysid.io import read_log
    from ropod_sysid.platform import save_platform

    from .test_cli import one_line_error, run

    save_platform(off_square, tmp_path / "p.yaml")
    (tmp_path / "truth.json").write_text(json.dumps(
        thesis_fixed_masses(off_square.unit_names).to_mapping()))
    t = np.arange(0, 0.305, 0.01)
    v = 1.0 * np.sin(np.pi * t / 0.3) ** 2
    np.savetxt(tmp_path / "traj.csv", np.column_stack([t, v, 0.3 * v, 0.5 * v]),
               delimiter=",", header="t,vx,vy,omega", comments="")
    args = ["simulate", "--platform", str(tmp_path / "p.yaml"), "--params",
            str(tmp_path / "truth.json"), "--trajectory", str(tmp_path / "traj.csv"),
            "--rate", "1000", "--quiet"]
    logs = []
    for engine in ("numba", "numpy"):
        out = tmp_path / f"{engine}.csv"
        r = run(*args, "--out", str(out), "--engine", engine)
        assert r.exit_code == 0, r.output
        logs.append(read_log(out, off_square))
    assert np.abs(logs[0].angles[-1] - logs[0].angles[0]).max() > 0.5  # the wheels turned
    np.testing.assert_array_equal(logs[0].t, logs[1].t)
    np.testing.assert_allclose(logs[0].angles, logs[1].angles, rtol=0, atol=1e-9)
    np.testing.assert_allclose(logs[0].currents, logs[1].currents, rtol=0, atol=1e-7)
    r = run(*args, "--out", str(tmp_path / "x.csv"), "--engine", "jax")
    one_line_error(r, "--engine")
    assert not (tmp_path / "x.csv").exists()
