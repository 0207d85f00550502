"""``--smoother quartic``: the discretisation bias of the derivatives on clean, fast logs."""

from __future__ import annotations

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
from ropod_sysid.regressor import Span, preprocess, triangles

QUARTIC = Span.parse(None).with_smoother("quartic")


def largest_error(fit, truth, platform) -> np.ndarray:
    return np.abs(fit.solution.values / truth.vector(parameter_names(platform, "per-wheel")) - 1)


def test_quartic_smoother_fits_noise_free_runs_within_0_3_percent(off_square, truth,
                                                                  runs_off_square):
    """Noise-free 200 Hz runs under the simulator's 1 ms hold (--control-period 0.001),
    default row step: the largest error over the 29 parameters is 0.57 % with the LOESS and
    three-point differences, 0.26 % with the quartic and five-point ones (m_b +0.04 %)."""
    logs = [r.log for r in runs_off_square]
    loess = largest_error(fit_logs(logs, off_square, FitOptions(control_period=0.001)),
                          truth, off_square)
    fit = fit_logs(logs, off_square, FitOptions(control_period=0.001, span=QUARTIC))
    quartic = largest_error(fit, truth, off_square)
    assert loess.max() > 0.004
    assert quartic.max() < 0.003 and quartic[:2].max() < 0.001
    assert fit.parameter_file().extras["smoother"] == "quartic"
    assert "five-point differences (--smoother quartic)" in fit.corrections_text()


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
