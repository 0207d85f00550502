"""``--smoother quartic``: the discretisation bias of the derivatives on clean, fast logs."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid import stream
from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import parameter_names
from ropod_sysid.regressor import RowGrid, Span, preprocess, row_inputs, triangles

QUARTIC = Span.parse(None).with_smoother("quartic")


def largest_error(fit, truth, platform) -> np.ndarray:
    return np.abs(fit.solution.values / truth.vector(parameter_names(platform, "per-wheel")) - 1)


def test_quartic_smoother_fits_noise_free_runs_within_0_3_percent(off_square, truth,
                                                                  runs_off_square):
    """Noise-free 200 Hz runs under the simulator's 1 ms hold (--control-period 0.001),
    default row step: the largest error over the 29 parameters is 0.57 % or 0.45 % (by the
    rows' phase to the simulator's 100 Hz setpoints) with the LOESS and three-point
    differences, 0.27 % at either phase with the quartic, five-point differences and the
    rows' torque weights (m_b −0.001 %)."""
    logs = [r.log for r in runs_off_square]
    loess = largest_error(fit_logs(logs, off_square, FitOptions(control_period=0.001)),
                          truth, off_square)
    assert loess.max() > 0.004
    for drop in (0, 1):  # the rows' other phase
        cut = [dataclasses.replace(lg, t=lg.t[drop:], angles=lg.angles[drop:],
                                   currents=lg.currents[drop:]) for lg in logs]
        fit = fit_logs(cut, off_square, FitOptions(control_period=0.001, span=QUARTIC))
        quartic = largest_error(fit, truth, off_square)
        assert quartic.max() < 0.003 and quartic[:2].max() < 0.001
    assert fit.parameter_file().extras["smoother"] == "quartic"
    assert "five-point differences (--smoother quartic)" in fit.corrections_text()


@pytest.mark.parametrize("step", [2, 3, 10])
def test_quartic_rows_weigh_torques_without_second_moment_or_row_rate(step):
    """After the quartic the rows' torque weights over 2·step + 1 samples sum to 1, have no
    second moment and null the row rate's harmonics; the LOESS's rows keep the mean."""
    w = RowGrid(step, 11, 4).torque_kernel
    j = np.arange(-step, step + 1)
    assert w.size == 2 * step + 1 and RowGrid(step, 11, 4).halo == 5 * step + step
    assert w.sum() == pytest.approx(1.0) and w @ j**2 == pytest.approx(0.0, abs=1e-12)
    for m in range(1, step // 2 + 1):
        assert w @ np.cos(2 * np.pi * m * j / step) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(RowGrid(2, 11, 4).torque_kernel, np.array([-1, 4, 10, 4, -1]) / 16)
    mean = RowGrid(step, 11).torque_kernel
    np.testing.assert_allclose(mean, 1.0 / (2 * (step // 2) + 1))
    np.testing.assert_array_equal(RowGrid(1, 11, 4).torque_kernel, [1.0])


def test_rows_take_the_grids_torque_weights(off_square, runs_off_square):
    pre = preprocess(runs_off_square[0].log, off_square, QUARTIC, row_step=3)
    idx = pre.row_samples()
    rows = row_inputs(pre, idx)
    w, j = pre.grid.torque_kernel, 11
    np.testing.assert_allclose(rows.tau[j], w @ pre.tau[idx[j] - 3: idx[j] + 4], rtol=1e-13)
    # the observer's step keeps its mean
    obs = row_inputs(pre, idx, 3)
    np.testing.assert_allclose(obs.tau[j], pre.tau[idx[j] - 1: idx[j] + 2].mean(axis=0),
                               rtol=1e-13)


@pytest.mark.parametrize(("step", "chunk"), [(3, 97), (None, 250)])
def test_quartic_streams_like_in_memory(off_square, runs_off_square, step, chunk):
    """The streamed blocks reach four samples each side for the five-point differences."""
    model = PlatformModel(off_square)
    log = runs_off_square[1].log
    ref = triangles(model, preprocess(log, off_square, QUARTIC, row_step=step))
    res = stream.stream_log(log, off_square, QUARTIC, chunk=chunk, row_step=step)
    assert res.triangles.rows == ref.rows
    ga = np.einsum("dij,dik->djk", ref.r, ref.r)
    gb = np.einsum("dij,dik->djk", res.triangles.r, res.triangles.r)
    assert np.abs(ga - gb).max() <= 1e-12 * np.abs(ga).max()
    plain = triangles(model, preprocess(log, off_square, row_step=step))
    gp = np.einsum("dij,dik->djk", plain.r, plain.r)
    assert np.abs(ga - gp).max() > 1e-6 * np.abs(ga).max()  # a different recipe


def test_short_quartic_span_gets_a_note(off_square, runs_off_square):
    """Below 17 samples the quartic passes 5–8× the LOESS's acceleration noise (on noisy
    logs the fit broke down there): in memory and streamed, a note says so."""
    log = runs_off_square[0].log
    short = Span.parse("13").with_smoother("quartic")
    note = ("the quartic smoother over 13 samples passes 5–8× the acceleration noise of the "
            "LOESS; on logs with noisy angles (encoder counts) use --span 0.085s or longer "
            "(17 samples)")
    assert any(note in n for n in preprocess(log, off_square, short).notes)
    assert any(note in n for n in stream.stream_log(log, off_square, short).notes)
    assert not any("quartic" in n for n in preprocess(log, off_square, QUARTIC).notes)
    assert not any("quartic" in n for n in preprocess(log, off_square, Span.parse("13")).notes)


def test_unknown_smoother_is_one_line_error():
    with pytest.raises(InputError, match="--smoother 'cubic': use loess or quartic"):
        Span.parse(None).with_smoother("cubic")


def test_cli_smoother_in_the_parameter_file(tmp_path, off_square, runs_off_square):
    """fit --smoother quartic writes it to the file; validate fits its rows as the fit did
    (a given --span keeps it); a bad value in the file is a one-line error."""
    from ropod_sysid.platform import save_platform

    pf = str(tmp_path / "platform.yaml")
    save_platform(off_square, pf)
    logs = []
    for k, r in enumerate(runs_off_square[:2]):
        logs.append(str(tmp_path / f"run{k}.csv"))
        write_csv_log(r.log, logs[-1])
    out = tmp_path / "p.json"
    r = CliRunner().invoke(main, ["fit", *logs, "--platform", pf, "--out", str(out), "--quiet",
                                  "--smoother", "quartic", "--control-period", "0.001"])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert data["smoother"] == "quartic" and data["span"] == "0.1s"

    def validate(*extra: str):
        return CliRunner().invoke(main, ["validate", logs[0], "--platform", pf, "--params",
                                         str(out), "--json", "--quiet", *extra])

    v = validate()
    assert v.exit_code == 0, v.output
    rms = json.loads(v.output)["logs"][0]["rms"]
    assert json.loads(validate("--span", "0.1s").output)["logs"][0]["rms"] == rms
    data.pop("smoother")
    out.write_text(json.dumps(data))
    assert json.loads(validate().output)["logs"][0]["rms"] != rms  # the LOESS: other rows
    data["smoother"] = "spline"
    out.write_text(json.dumps(data))
    bad = validate()
    assert bad.exit_code == 2
    assert bad.output.strip() == (f"error: {out}: key 'smoother' is 'spline'; expected "
                                  "'loess' or 'quartic'")


def test_quartic_with_the_delay_searched_fits_noise_free_runs_within_0_3_percent(
        off_square, truth, runs_off_square):
    """Not told the hold: --smoother quartic --input-delay auto finds the 1 ms hold's half
    step between the search's nodes (0.49-0.50 ms; the parabola through three nodes had
    0.56 ms and 0.42 %) and every parameter within 0.3 % at either phase of the rows; the
    LOESS's search keeps the parabola's delay."""
    from ropod_sysid import delay as delay_module

    logs = [r.log for r in runs_off_square]
    for drop in (0, 1):
        cut = [dataclasses.replace(lg, t=lg.t[drop:], angles=lg.angles[drop:],
                                   currents=lg.currents[drop:]) for lg in logs]
        fit = fit_logs(cut, off_square, FitOptions(input_delay="auto", span=QUARTIC))
        assert abs(fit.input_delay - 0.0005) < 2e-5, fit.input_delay
        assert largest_error(fit, truth, off_square).max() < 0.003
    called = []
    real = delay_module.between_nodes

    def spy(*args, **kwargs):
        called.append(1)
        return real(*args, **kwargs)

    delay_module.between_nodes = spy
    try:
        fit_logs(logs, off_square, FitOptions(input_delay="auto", recipe_check=False))
    finally:
        delay_module.between_nodes = real
    assert not called


def test_between_nodes_is_the_least_interpolated_criterion():
    """With b_ID linear between nodes one sample apart the criterion along each interval is
    a quadratic that one evaluation at its middle fixes: between_nodes returns the least
    value of ‖w(d)ᵀB‖² over the two intervals beside the least node, to rounding."""
    from ropod_sysid.delay import between_nodes
    from ropod_sysid.solve import node_weights

    rng = np.random.default_rng(5)
    nodes = 0.005 * np.arange(-4, 5)
    k = np.arange(len(nodes))[:, None]
    u, v, z = rng.normal(size=(3, 50))
    b = u + (k - 4.9) * v + 0.3 * (k - 4.9) ** 2 * z  # smooth in the delay, least near +4.5 ms

    def cost(d: float) -> float:
        return float(np.sum((node_weights(nodes, d) @ b) ** 2))

    costs = np.array([cost(d) for d in nodes])
    grid = np.linspace(nodes[0], nodes[-1], 80_001)
    best = grid[np.argmin([cost(d) for d in grid])]
    got = between_nodes(nodes, costs, cost, float(nodes[np.argmin(costs)]))
    assert abs(got - best) <= grid[1] - grid[0]
    assert cost(got) <= cost(float(best)) * (1 + 1e-12)  # no point of the grid lies lower
    assert not np.any(np.isclose(got, nodes, atol=1e-6))  # between the nodes


def test_mean_currents_let_the_default_fit_find_the_hold_on_a_typical_run(off_square, truth):
    """A 20 s typical run at 200 Hz, noise-free, not told the hold: with the currents logged
    as interval means the default LOESS and --input-delay auto find the 1 ms hold's half step
    and every parameter within 0.3 % (measured 0.504 ms, 0.15 %); point-sampled, the speed
    loops' fast corrections alias into the slow band (3.9 %, the delay 0.35 ms), which no
    fit undoes (docs/method.md, "On other runs: the log's currents")."""
    from ropod_sysid.simulate import Sensors, simulate
    from ropod_sysid.trajectory import typical
    from ropod_sysid.trajectory.run_variants import variants

    setpoints = [v.to_setpoints()
                 for v in variants(typical(20.0, platform=off_square, seed=1)).values()]
    found = {}
    for mean in (True, False):
        runs = simulate(off_square, truth, setpoints, rate=200.0,
                        sensors=Sensors(current_average=mean))
        fit = fit_logs([r.log for r in runs], off_square, FitOptions(input_delay="auto"))
        found[mean] = (fit.input_delay, largest_error(fit, truth, off_square).max())
    assert abs(found[True][0] - 0.0005) < 3e-5 and found[True][1] < 0.003, found
    assert found[False][1] > 0.01, found
