"""``--robust``: iteratively reweighted least squares over the logs' 2 s stretches, tested on
logs with injected bumps (external pushes the model does not know of)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.robust import (
    BISQUARE_C,
    HUBER_C,
    bisquare_weights,
    huber_weights,
    robust_scale,
    stretch_rms,
)
from ropod_sysid.simulate import ForceSchedule, Sensors, simulate
from ropod_sysid.solve import gram_triangle
from tests.conftest import smooth_setpoints
from tests.test_cli import one_line_error, run

DURATION = 20.0
BUMPS = [(5.1, 16.0), (11.9, 12.6), (7.9, 9.2), (8.0, 11.2)]  # push times per run [s]


def pushes(times: tuple[float, float], force: float) -> ForceSchedule:
    """Two 0.3 s pushes (ramped over 50 ms) the model does not know of: the first along the
    base's x axis, the second sideways with a small torque."""
    t, f = [0.0], [[0.0, 0.0, 0.0]]
    for t0, direction in zip(times, ((1.0, 0.0, 0.0), (0.0, 1.0, 0.1)), strict=True):
        push = force * np.array(direction)
        t += [t0, t0 + 0.05, t0 + 0.25, t0 + 0.3]
        f += [[0.0, 0.0, 0.0], push, push, [0.0, 0.0, 0.0]]
    return ForceSchedule(np.array(t), np.array(f))


def runs(platform, truth, force: float) -> list:
    """The four 20 s variants at 200 Hz with 2¹⁴-count encoders and 30 mA current noise, each
    pushed twice with ``force`` [N]."""
    variants = [smooth_setpoints(DURATION, sx, sw) for sx, sw in ((1, 1), (1, -1), (-1, 1),
                                                                  (-1, -1))]
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03)
    return [simulate(platform, truth, [sp], force=pushes(b, force), rate=200.0,
                     sensors=sensors, source=f"pushed{k}.csv")[0].log
            for k, (sp, b) in enumerate(zip(variants, BUMPS, strict=True))]


@pytest.fixture(scope="module")
def clean(off_square, truth):
    return runs(off_square, truth, 0.0)


@pytest.fixture(scope="module")
def pushed(off_square, truth):
    return runs(off_square, truth, 80.0)


def mass_error(result, truth) -> float:
    j = result.names.index("m_b")
    return float(result.solution.values[j] / truth["m_b"] - 1.0)


def test_the_weights_are_hubers_and_tukeys():
    rms = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 100.0])
    assert robust_scale(rms) == 3.0  # the median of the positive ones
    np.testing.assert_allclose(huber_weights(rms, 1.0), [1, 1, 1, HUBER_C / 3, HUBER_C / 4,
                                                         HUBER_C / 100])
    u = rms / BISQUARE_C
    np.testing.assert_allclose(bisquare_weights(rms, 1.0),
                               np.where(u < 1, (1 - u**2) ** 2, 0.0))
    assert bisquare_weights(np.array([BISQUARE_C * 2.0]), 2.0)[0] == 0.0  # at c·s: 0


def test_stretch_rms_and_the_triangle_of_a_gram_matrix():
    rng = np.random.default_rng(1)
    ab = rng.normal(size=(3, 40, 5))  # three stretches of rows [A | b]
    grams = np.einsum("kri,krj->kij", ab, ab)
    m = rng.normal(size=4)
    np.testing.assert_allclose(stretch_rms(m, grams),
                               np.linalg.norm(ab[:, :, :4] @ m - ab[:, :, 4], axis=1))
    r = gram_triangle(grams.sum(axis=0))
    np.testing.assert_allclose(r.T @ r, grams.sum(axis=0), atol=1e-9)
    assert np.allclose(r, np.triu(r))
    singular = np.outer([1.0, 2.0, 0.0], [1.0, 2.0, 0.0])  # semi-definite: rank 1
    r = gram_triangle(singular)
    np.testing.assert_allclose(r.T @ r, singular, atol=1e-12)


def test_pushes_bias_a_plain_fit_and_the_robust_fits_recover(off_square, truth, clean, pushed):
    """Eight 80 N pushes of 0.3 s in 80 s of noisy log: the plain fit's m_b is 34 % high; Huber's
    weights bring it to 9 %, the bisquare's to the clean logs' 3.5 %. (σ stays honest in all:
    the jackknife sees the pushed stretches.)"""
    plain_clean = fit_logs(clean, off_square)
    plain = fit_logs(pushed, off_square)
    huber = fit_logs(pushed, off_square, FitOptions(robust="huber"))
    bisquare = fit_logs(pushed, off_square, FitOptions(robust="bisquare"))
    clean_error = abs(mass_error(plain_clean, truth))
    assert clean_error < 0.05
    assert mass_error(plain, truth) > 0.25
    assert abs(mass_error(huber, truth)) < 0.12
    assert abs(mass_error(bisquare, truth)) < clean_error + 0.01
    for res in (plain, huber, bisquare):
        sol = res.solution
        tv = np.array([truth[n] for n in sol.names])
        assert np.mean(np.abs(sol.values - tv) < 2 * sol.std) >= 0.9
    # the stretches with the pushes are those down-weighted most: 2 s each, one per push
    # (a push across a stretch's end spoils two)
    low = {(f, a) for f, a, _, w in bisquare.down_weighted() if w < 0.05}
    expected = {(f"pushed{k}.csv", 2.0 * (t // 2.0)) for k, b in enumerate(BUMPS) for t in b}
    assert expected <= low and len(low) <= len(expected) + 2
    assert bisquare.solution.stretch_weights.size == 40
    assert "--robust bisquare: " in bisquare.robust_text()


def test_on_clean_logs_huber_changes_nothing(off_square, clean):
    plain = fit_logs(clean, off_square)
    huber = fit_logs(clean, off_square, FitOptions(robust="huber"))
    assert huber.solution.stretch_weights.min() > 0.9
    np.testing.assert_allclose(huber.solution.values, plain.solution.values,
                               atol=0.1 * np.nanmin(plain.solution.std))


def test_robust_needs_six_stretches(off_square, clean):
    short = clean[0].slice(0, 1000)  # 5 s: three stretches
    with pytest.raises(InputError) as err:
        fit_logs([short], off_square, FitOptions(robust="huber"))
    assert str(err.value) == ("--robust huber needs at least 6 stretches of 2 s of log; give "
                              "longer logs or leave it out")
    with pytest.raises(InputError, match="--robust 'tukey': use none, huber, bisquare"):
        FitOptions(robust="tukey")  # type: ignore[arg-type]


def test_the_cli_writes_what_it_down_weighted(tmp_path, pushed, off_square):
    from ropod_sysid.io import write_log
    from ropod_sysid.platform import save_platform

    paths = []
    for log in pushed[:1]:
        path = tmp_path / log.source
        write_log(log, path)
        paths.append(str(path))
    platform = tmp_path / "platform.yaml"
    save_platform(off_square, platform)
    out = tmp_path / "params.json"
    res = run("fit", *paths, "--platform", str(platform), "--out", str(out), "--robust",
              "bisquare")
    assert res.exit_code == 0, res.output
    assert "--robust bisquare: " in res.output
    robust = json.loads(out.read_text())["robust"]
    assert robust["method"] == "bisquare" and robust["stretches"] == 10
    assert {d["file"] for d in robust["down_weighted"] if d["weight"] < 0.05} == set(paths)
    report = tmp_path / "r.html"
    res = run("report", *paths, "--params", str(out), "--platform", str(platform), "--out",
              str(report),
              "--quiet")
    assert res.exit_code == 0, res.output
    assert "--robust bisquare: " in report.read_text()
    one_line_error(run("fit", *paths, "--platform", str(platform), "--out", str(out),
                       "--robust", "tukey"), "--robust")
