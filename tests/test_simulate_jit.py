"""The compiled simulator (numba) against the numpy path, the reference: the same runs to
round-off on the ropod, the 5DPO and a platform mixing smart wheels and omni wheels, with
friction (per wheel, shared, body axes), sensor effects and an external force; and the numpy
fallback when numba or a kernel is missing."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import ropod_sysid
from ropod_sysid.errors import InputError
from ropod_sysid.model.units.omni import OmniUnits
from ropod_sysid.params import Parameters, thesis_fixed_masses, typical_parameters
from ropod_sysid.platform import load_platform
from ropod_sysid.simulate import (
    MIN_COMPILED_STEPS,
    Controller,
    ForceSchedule,
    Sensors,
    Setpoints,
    simulate,
)

from .conftest import four_variants, smooth_setpoints
from .test_omni import PLATFORM as OMNI_PLATFORM
from .test_units_pipeline import OMNI_CONTROL, PAPER_BODY, mixed_platform

FIELDS = ("q", "qd", "qdd", "angles", "tau", "f_b", "energy", "tau_mean")
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


def test_numpy_fallback_without_a_kernel(monkeypatch, off_square) -> None:
    """A unit type without ``compiled`` is simulated by the numpy path under ``auto``; asking
    for the compiled loop names the platform's types."""
    pf = mixed_platform()
    truth = Parameters(dict(typical_parameters(pf, 30.0, 3.0)) | {"Jrot_o": 0.004})
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
