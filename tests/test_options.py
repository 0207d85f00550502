"""Bad option values and parameter files: one line naming the option, the value and the allowed
range, exit status 2, no output file, before any work; results that are no result are errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ropod_sysid.errors import IdentifiabilityError
from ropod_sysid.inspect import Criteria
from ropod_sysid.io import write_log
from ropod_sysid.solve import Triangles, solve
from tests.swivel_arrays import C, with_arrays
from tests.test_cli import files, one_line_error, run  # noqa: F401  (files: a fixture)

SPAN = "a number without 's' is a count of samples and must be an odd whole number ≥ 5"
DELAY_RANGE = ("must be a finite number of seconds, e.g. 0.0025 (negative: the motion leads the "
               "logged torque), or auto")
RCOND = "must be a finite number in (0, 1), e.g. 0.0001"

FIT_CASES = [
    (["--span", "nan"], f"--span 'nan': {SPAN}; e.g. 21 (samples) or 0.1s"),
    (["--span", "inf"], f"--span 'inf': {SPAN}; e.g. 21 (samples) or 0.1s"),
    (["--span", "0"], f"--span '0': {SPAN}; e.g. 21 (samples) or 0.1s"),
    (["--span", "-1"], f"--span '-1': {SPAN}; e.g. 21 (samples) or 0.1s"),
    (["--span", "2"], f"--span '2': {SPAN}; did you mean 2s?"),
    (["--span", "0.1"], f"--span '0.1': {SPAN}; did you mean 0.1s?"),
    (["--span", "20"], f"--span '20': {SPAN}; did you mean 19 or 21?"),
    (["--span", "infs"], "--span 'infs': seconds must be a finite number > 0, e.g. 0.1s"),
    (["--rcond", "nan"], f"--rcond nan: {RCOND}"),
    (["--rcond", "2"], f"--rcond 2: {RCOND}"),
    (["--rcond", "0"], f"--rcond 0: {RCOND}"),
    (["--input-delay", "nan"], f"--input-delay nan: {DELAY_RANGE}"),
    (["--input-delay", "inf"], f"--input-delay inf: {DELAY_RANGE}"),
    (["--input-delay", "1e9"], "--input-delay 1e+09: longer than the smoother span (0.1 s); give "
                               "at most 0.1 s, auto, or a longer --span"),
    (["--input-delay", "0.3", "--span", "0.25s"],
     "--input-delay 0.3: longer than the smoother span (0.25 s); give at most 0.25 s, auto, or "
     "a longer --span"),
    # negative delays (the motion leads the logged torque) are accepted up to one span (issue 14)
    (["--input-delay", "-0.3"], "--input-delay -0.3: longer than the smoother span (0.1 s); give "
                                "at most 0.1 s either way, auto, or a longer --span"),
    (["--fix", "m_b=nan"], "--fix 'm_b=nan': the value must be a finite number, e.g. --fix "
                           "m_b=35.1"),
    (["--fix", "m_b=-inf"], "--fix 'm_b=-inf': the value must be a finite number, e.g. --fix "
                            "m_b=35.1"),
    (["--weight-rotation", "inf"], "--weight-rotation 'inf': the weight must be a finite "
                                   "number > 0"),
    (["--workers", "-2"], "--workers -2: give a positive number of worker processes"),
]


def refused(result, message: str, out) -> None:
    """One line, exactly ``error: message``, exit status 2, and ``out`` not written."""
    one_line_error(result)
    assert result.output.strip() == f"error: {message}"
    assert not out.exists()


@pytest.mark.parametrize(("args", "message"), FIT_CASES, ids=[" ".join(a) for a, _ in FIT_CASES])
def test_fit_numeric_options(tmp_path, files, args, message):  # noqa: F811
    d, logs = files
    out = tmp_path / "p.json"
    r = run("fit", *map(str, logs), "--platform", str(d / "platform.yaml"), "--out", str(out),
            *args)
    refused(r, message, out)


def test_input_delay_beyond_a_span_in_samples(tmp_path, files):  # noqa: F811
    """A span in samples is known in seconds only from the log: checked when it is read."""
    d, logs = files
    out = tmp_path / "p.json"
    r = run("fit", str(logs[0]), "--platform", str(d / "platform.yaml"), "--out", str(out),
            "--span", "21", "--input-delay", "0.2")
    refused(r, "--input-delay 0.2: longer than the smoother span (0.105 s); give at most "
               "0.105 s, auto, or a longer --span", out)


def test_row_step_beyond_the_span(tmp_path, files):  # noqa: F811
    d, logs = files
    out = tmp_path / "p.json"
    r = run("fit", str(logs[0]), "--platform", str(d / "platform.yaml"), "--out", str(out),
            "--row-step", "50")
    refused(r, "--row-step 50: more than the smoother span of 21 samples; rows farther apart "
               "than a span are not filtered like the samples (eq. 36 on both sides); give at "
               "most 21, auto, or a longer --span", out)


def setpoint_csv(path) -> str:
    t = np.arange(0.0, 1.0001, 0.01)
    np.savetxt(path, np.column_stack([t, 0.3 * np.sin(np.pi * t), 0 * t, 0 * t]),
               delimiter=",", header="t,vx,vy,omega", comments="")
    return str(path)


SIM_CASES = [
    (["--rate", "inf"], "--rate inf: must be a finite number in (0, 1000] Hz (at most the "
                        "integration rate 1/--dt)"),
    (["--rate", "0"], "--rate 0: must be a finite number in (0, 1000] Hz (at most the "
                      "integration rate 1/--dt)"),
    (["--rate", "300"], "--rate 300: must divide the integration rate 1/--dt = 1000 Hz, e.g. "
                        "1000, 500, 250, 200, 100"),
    (["--dt", "0.002"], "--dt 0.002: must be a finite number in (0, 0.001] s"),
    (["--dt", "nan"], "--dt nan: must be a finite number in (0, 0.001] s"),
    (["--seed", "-1"], "--seed -1: must be a whole number in [0, 4294967295]"),
    (["--jitter", "0.0025"], "--jitter 0.0025: must be a finite number in [0, 0.0025) s, less "
                             "than half the sample step 1/--rate (a larger one reorders the "
                             "samples)"),
    (["--jitter", "-0.001"], "--jitter -0.001: must be a finite number in [0, 0.0025) s, less "
                             "than half the sample step 1/--rate (a larger one reorders the "
                             "samples)"),
    (["--encoder-counts", "0"], "--encoder-counts 0: must be a whole number ≥ 16 counts per "
                                "revolution (or left out for exact angles)"),
    (["--encoder-counts", "-4096"], "--encoder-counts -4096: must be a whole number ≥ 16 counts "
                                    "per revolution (or left out for exact angles)"),
    (["--torque-limit", "0"], "--torque-limit 0: must be a finite number > 0"),
    (["--torque-limit", "-4"], "--torque-limit -4: must be a finite number > 0"),
    (["--current-noise", "nan"], "--current-noise nan: must be a finite number ≥ 0 A"),
    (["--kp", "inf"], "--kp inf: must be a finite number ≥ 0"),
]


@pytest.mark.parametrize(("args", "message"), SIM_CASES, ids=[" ".join(a) for a, _ in SIM_CASES])
def test_simulate_numeric_options(tmp_path, files, args, message):  # noqa: F811
    d, _ = files
    out = tmp_path / "sim.csv"
    r = run("simulate", "--platform", str(d / "platform.yaml"), "--params",
            str(d / "truth.json"), "--trajectory", setpoint_csv(tmp_path / "sp.csv"), "--out",
            str(out), *args)
    refused(r, message, out)


@pytest.mark.parametrize(("name", "value", "message"), [
    ("m_b", -35.1, "parameter 'm_b' is -35.1 kg; the platform base mass must be > 0"),
    ("m_b", 0.0, "parameter 'm_b' is 0 kg; the platform base mass must be > 0"),
    ("Jzz_wh", -0.01, "parameter 'Jzz_wh' is -0.01 kg m²; the smart-wheel unit inertia about z "
                      "must be ≥ 0"),
])
def test_simulate_refuses_negative_masses_and_inertias(tmp_path, files, name, value,  # noqa: F811
                                                       message):
    d, _ = files
    truth = json.loads((d / "truth.json").read_text())
    truth[name] = value
    params = tmp_path / "neg.json"
    params.write_text(json.dumps(truth))
    out = tmp_path / "sim.csv"
    r = run("simulate", "--platform", str(d / "platform.yaml"), "--params", str(params),
            "--trajectory", setpoint_csv(tmp_path / "sp.csv"), "--out", str(out))
    refused(r, f"{params}: {message}", out)


TRAJ_CASES = [
    (["typical", "--duration", "0"], "--duration 0: must be a finite number in (0, 3600] s"),
    (["typical", "--duration", "-5"], "--duration -5: must be a finite number in (0, 3600] s"),
    (["typical", "--duration", "1e9"], "--duration 1e9: must be a finite number in (0, 3600] s"),
    (["typical", "--duration", "nan"], "--duration nan: must be a finite number in (0, 3600] s"),
    (["typical", "--dt", "0"], "--dt 0: must be a finite number in (0, 0.1] s"),
    (["typical", "--v-max", "nan"], "--v-max nan: must be a finite number > 0"),
    (["typical", "--a-max", "-1"], "--a-max -1: must be a finite number > 0"),
    (["typical", "--pivot-rate-max", "inf"], "--pivot-rate-max inf: must be a finite number > 0"),
    (["typical", "--seed", "-1"], "--seed -1: must be a whole number in [0, 4294967295]"),
    (["optimize", "--harmonics", "0"], "--harmonics 0: must be a whole number in [1, 20]"),
    (["optimize", "--maxiter", "0"], "--maxiter 0: must be a whole number ≥ 1"),
    (["optimize", "--duration", "1e9"], "--duration 1e9: must be a finite number in [5, 600] s"),
    (["optimize", "--seed", "1.5"], "--seed 1.5: must be a whole number in [0, 4294967295]"),
    (["check", "--noise", "0"], "--noise 0: must be a finite number > 0"),
    (["check", "--log-rate", "inf"], "--log-rate inf: must be a finite number > 0 Hz"),
]


@pytest.mark.parametrize(("args", "message"), TRAJ_CASES,
                         ids=[" ".join(a) for a, _ in TRAJ_CASES])
def test_trajectory_numeric_options(tmp_path, files, args, message):  # noqa: F811
    d, _ = files
    out = tmp_path / "runs"
    sub, *rest = args
    where = {"typical": ["--out", str(out)],
             "optimize": ["--out", str(out), "--platform", str(d / "platform.yaml")],
             "check": [setpoint_csv(tmp_path / "sp.csv"), "--platform",
                       str(d / "platform.yaml")]}[sub]
    r = run("trajectory", sub, *where, *rest)
    refused(r, message, out)


# ---------------------------------------------------------------------------------------------
# results that are no result


def test_all_zero_currents_are_an_error(tmp_path, files, runs_off_square):  # noqa: F811
    d, _ = files
    paths = []
    for k, res in enumerate(runs_off_square):
        p = tmp_path / f"quiet{k}.csv"
        write_log(with_arrays(res.log, current=0 * C(res.log)), p)
        paths.append(str(p))
    out = tmp_path / "p.json"
    r = run("fit", *paths, "--platform", str(d / "platform.yaml"), "--out", str(out))
    refused(r, f"{paths[0]}: the motor currents are all zero, so there is no torque to fit the "
               "parameters to; check the log's current columns", out)


def test_a_log_shorter_than_inspect_calls_enough_is_an_error(tmp_path, files,  # noqa: F811
                                                              runs_off_square):
    """m_b = −403 kg came from a 2 s log; the threshold is inspect's (Criteria.min_moving)."""
    d, _ = files
    p = tmp_path / "short.csv"
    write_log(runs_off_square[0].log.slice(0, 401), p)  # 2 s at 200 Hz
    out = tmp_path / "p.json"
    r = run("fit", str(p), "--platform", str(d / "platform.yaml"), "--out", str(out))
    need = Criteria().min_moving
    refused(r, f"{p}: only 2.0 s of log; record at least {need:g} s of motion: the values of a "
               "shorter fit are noise (ropod-sysid inspect shows what a log lacks)", out)


def test_an_all_zero_solution_is_an_error():
    """Rows that move (A ≠ 0) with b = 0 everywhere solve to m = 0: no result."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(200, 3, 6))
    tri = Triangles.from_rows(a, np.zeros((200, 3)))
    assert tri.torque_free()
    with pytest.raises(IdentifiabilityError, match="^the solution is all zeros"):
        solve(tri.weighted(1.0), 600, [f"p{j}" for j in range(6)])
    full = Triangles.from_rows(a, a[:, :, 0])  # b = first column: m = e_0, not zero
    assert not full.torque_free()
    sol = solve(full.weighted(1.0), 600, [f"p{j}" for j in range(6)])
    np.testing.assert_allclose(sol.values, np.eye(6)[0], atol=1e-10)


# ---------------------------------------------------------------------------------------------
# parameter files of validate and report


@pytest.fixture(scope="module")
def fitted(files):  # noqa: F811
    d, logs = files
    out = d / "options-fit.json"
    r = run("fit", *map(str, logs), "--platform", str(d / "platform.yaml"), "--out", str(out),
            "--quiet")
    assert r.exit_code == 0, r.output
    return out.read_text()


def _set(text: str, name: str, raw: str) -> str:
    data = json.loads(text)
    data["parameters"][name]["value"] = "@@"
    return json.dumps(data, indent=2).replace('"@@"', raw)


def _drop(text: str, name: str) -> str:
    data = json.loads(text)
    del data["parameters"][name]
    return json.dumps(data)


def _rename(text: str, old: str, new: str) -> str:
    data = json.loads(text)
    data["parameters"][new] = data["parameters"].pop(old)
    return json.dumps(data)


def _platform(text: str, name: str) -> str:
    data = json.loads(text)
    data["platform"] = name
    return json.dumps(data)


PARAM_CASES = {
    "null": (lambda t: _set(t, "m_b", "null"),
             "parameter 'm_b' is null, NaN or infinite; a parameter file gives a finite value "
             "for every parameter"),
    "NaN": (lambda t: _set(t, "Jzz_b", "NaN"),
            "parameter 'Jzz_b' is null, NaN or infinite; a parameter file gives a finite value "
            "for every parameter"),
    "Infinity": (lambda t: _set(t, "fpv_2", "-Infinity"),
                 "parameter 'fpv_2' is null, NaN or infinite; a parameter file gives a finite "
                 "value for every parameter"),
    "unknown name": (lambda t: _rename(t, "fpc_4", "fpc_9"),
                     "parameter(s) fpc_9 are not parameters of the per-wheel friction model of "
                     "units 1, 2, 3, 4; is this the parameter file of this platform?"),
    "friction missing": (lambda t: _drop(t, "fwv_3L"),
                         "parameter(s) fwv_3L missing; the per-wheel friction model of units 1, "
                         "2, 3, 4 needs all of 29"),
    "platform": (lambda t: _platform(t, "kelo-4"),
                 "the parameter file is for platform 'kelo-4', the platform file describes "
                 "'ropod'; give the matching files"),
}


@pytest.mark.parametrize("command", ["validate", "report"])
@pytest.mark.parametrize("case", sorted(PARAM_CASES))
def test_bad_parameter_files_are_refused(tmp_path, files, fitted, command, case):  # noqa: F811
    d, logs = files
    edit, message = PARAM_CASES[case]
    params = tmp_path / "bad.json"
    params.write_text(edit(fitted))
    out = tmp_path / "report.html"
    extra = ["--out", str(out)] if command == "report" else []
    r = run(command, str(logs[3]), "--platform", str(d / "platform.yaml"), "--params",
            str(params), *extra)
    refused(r, f"{params}: {message}", out)


# ---------------------------------------------------------------------------------------------
# --json is always strict JSON


def _strict(text: str):
    def refuse(token: str):
        raise AssertionError(f"bare {token} in the JSON output")

    return json.loads(text, parse_constant=refuse)


def test_json_outputs_are_strict_json(tmp_path, files, fitted):  # noqa: F811
    from ropod_sysid.cli.common import json_text

    d, logs = files
    pf = str(d / "platform.yaml")
    params = tmp_path / "p.json"
    params.write_text(fitted)
    r = run("validate", str(logs[3]), "--platform", pf, "--params", str(params), "--json",
            "--quiet")
    assert r.exit_code == 0, r.output
    assert _strict(r.output)["logs"][0]["file"] == str(logs[3])
    r = run("inspect", str(logs[0]), "--platform", pf, "--json")
    assert r.exit_code == 0, r.output
    assert _strict(r.output)["samples"] == 1601
    # non-finite numbers (numpy or Python, nested) become null, never a bare NaN token
    data = {"a": math.nan, "b": np.float64(np.inf), "c": [1.5, np.array([np.nan, 2.0])],
            "d": {"e": (np.int64(3), -math.inf)}}
    assert _strict(json_text(data)) == {"a": None, "b": None, "c": [1.5, [None, 2.0]],
                                        "d": {"e": [3, None]}}
