"""The command line: one-line errors with exit status 2 and no partial output, formats."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.io import write_log
from ropod_sysid.io.paramfile import read_parameter_file
from ropod_sysid.platform import save_platform
from tests.swivel_arrays import C, D, P, with_arrays


@pytest.fixture(scope="module")
def files(tmp_path_factory, off_square, truth, runs_off_square):
    d = tmp_path_factory.mktemp("cli")
    save_platform(off_square, d / "platform.yaml")
    (d / "truth.json").write_text(json.dumps(truth.to_mapping()))
    logs = []
    for k, r in enumerate(runs_off_square):
        p = d / f"run{k}.csv"
        write_log(r.log, p)
        logs.append(p)
    return d, logs


def run(*args: str):
    return CliRunner().invoke(main, list(args))


def one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("error: ")
    assert "Traceback" not in result.output
    for f in fragments:
        assert f in lines[0], (f, lines[0])


def test_help_lists_every_command_and_version():
    r = run("--help")
    assert r.exit_code == 0
    for name in ("simulate", "fit", "validate", "report", "trajectory", "convert", "inspect"):
        assert name in r.output
    r = run("--version")
    assert r.exit_code == 0 and "0.1.0" in r.output


def test_help_points_at_the_file_formats_in_the_repository():
    from pathlib import Path

    docs = Path(__file__).resolve().parent.parent / "docs"
    for command in ("fit", "validate", "report", "simulate", "convert", "inspect"):
        r = run(command, "--help")
        assert r.exit_code == 0, r.output
        text = "".join(r.output.split())  # the help is wrapped, also at hyphens
        assert "docs/file-formats.md" in text, command
        assert "contract" not in text.replace("[default:contract]", "").replace(
            "[contract|smartwheel]", ""), command
    assert (docs / "file-formats.md").is_file() and (docs / "method.md").is_file()


def test_fit_writes_each_format(files):
    d, logs = files
    for fmt in ("json", "yaml", "ros2"):
        out = d / f"p.{fmt}"
        r = run("fit", *map(str, logs), "--platform", str(d / "platform.yaml"), "--out",
                str(out), "--format", fmt, "--quiet")
        assert r.exit_code == 0, r.output
        pf = read_parameter_file(out)
        assert pf.rank == 29 and pf.samples > 6000
        assert pf.values()["m_b"] == pytest.approx(35.1, rel=0.02)
    data = json.loads((d / "p.json").read_text())
    assert list(data)[:6] == ["platform", "parameters", "rms", "condition_number", "rank",
                              "samples"]
    assert set(data["rms"]) == {"translation", "rotation"}
    ros = yaml.safe_load((d / "p.ros2").read_text())
    node = next(iter(ros.values()))["ros__parameters"]
    assert node["base_kin_model"]["d_w"] == 0.08 and "m_b" in node["dyn_model"]
    out = d / "p.kelo"
    r = run("fit", *map(str, logs[:2]), "--platform", str(d / "platform.yaml"), "--out", str(out),
            "--format", "kelo", "--quiet")
    assert r.exit_code == 2 and "needs every unit's 'ethercat_number'" in r.output
    entries = yaml.safe_load((d / "platform.yaml").read_text())
    for k, unit in enumerate(entries["units"]):
        unit["ethercat_number"] = k + 1
    (d / "kelo-platform.yaml").write_text(yaml.safe_dump(entries))
    r = run("fit", *map(str, logs[:2]), "--platform", str(d / "kelo-platform.yaml"), "--out",
            str(out), "--format", "kelo", "--quiet")
    assert r.exit_code == 0, r.output
    kelo = yaml.safe_load(out.read_text())["platform_driver"]["ros__parameters"]
    assert kelo["wheel_diameter"] == pytest.approx(0.105) and kelo["wheel0"]["ethercat_number"] == 1


def test_fit_summary_and_options(files):
    d, logs = files
    r = run("fit", *map(str, logs), "--platform", str(d / "platform.yaml"), "--out",
            str(d / "s.json"), "--span", "0.15s", "--fix", "m_b=35.1", "--weight-rotation",
            "none", "--friction", "shared")
    assert r.exit_code == 0, r.output
    for text in ("m_b", "fixed", "RMS residual: translation", "rank 8 of 8",
                 "condition number", "rotation weight 1"):
        assert text in r.output
    extras = json.loads((d / "s.json").read_text())
    assert extras["fixed"] == {"m_b": 35.1} and extras["span"] == "0.15s"


def test_validate_reports_residual_and_observer(files):
    d, logs = files
    params = d / "v.json"
    assert run("fit", *map(str, logs[:3]), "--platform", str(d / "platform.yaml"), "--out",
               str(params), "--quiet").exit_code == 0
    r = run("validate", str(logs[3]), "--platform", str(d / "platform.yaml"), "--params",
            str(params), "--json")
    assert r.exit_code == 0, r.output
    out = json.loads(r.output)
    (v,) = out["logs"]
    assert v["rms"]["translation"] < 2.0 and v["rms"]["rotation"] < 0.5
    assert v["share_above_threshold"] == {"force": 0.0, "torque": 0.0}
    assert out["thresholds"] == {"force_N": 40.0, "torque_Nm": 10.0}
    r = run("validate", str(logs[3]), "--platform", str(d / "platform.yaml"), "--params",
            str(params))
    assert r.exit_code == 0 and "run3.csv" in r.output


def test_simulate_writes_a_valid_log(tmp_path, files):
    d, _ = files
    traj = tmp_path / "traj.csv"
    t = np.arange(0, 1.5, 0.01)
    v = 0.3 * np.sin(np.pi * t / 1.5) ** 2
    np.savetxt(traj, np.column_stack([t, v, 0 * t, 0.5 * v]), delimiter=",",
               header="t,vx,vy,omega", comments="")
    out = tmp_path / "run.csv"
    r = run("simulate", "--platform", str(d / "platform.yaml"), "--params",
            str(d / "truth.json"), "--trajectory", str(traj), "--out", str(out),
            "--encoder-counts", "16384", "--current-noise", "0.03", "--jitter", "0.0005",
            "--quiet")
    assert r.exit_code == 0, r.output
    from ropod_sysid.io import read_log
    from ropod_sysid.platform import load_platform

    log = read_log(out, load_platform(d / "platform.yaml"))
    assert log.n_samples == 299 and np.all(np.diff(log.t) > 0)
    step = 2 * np.pi / 16384
    np.testing.assert_allclose(P(log) / step, np.round(P(log) / step), atol=1e-6)
    assert P(log)[-1].mean() > 0.5  # it drove forward


BAD_CASES = {
    "empty": ("", "empty"),
    "header only": ("{header}\n", "no data rows"),
    "missing column": ("{header_missing}\n{row}\n{row2}\n{row3}\n", "'cur_4R'"),
    "duplicated column": ("{header_dup}\n{row_dup}\n", "appears twice"),
    "text in a number": ("{header}\n{row}\n{row_text}\n{row3}\n", "line 3"),
    "NaN": ("{header}\n{row}\n{row_nan}\n{row3}\n", "line 3"),
    "infinity": ("{header}\n{row}\n{row_inf}\n{row3}\n", "line 3"),
    "non-increasing time": ("{header}\n{row}\n{row}\n{row3}\n", "strictly increase"),
    "truncated last line": ("{header}\n{row}\n{row2}\n{row_cut}", "line 4"),
    "unit names": ("{header_units}\n{row}\n{row2}\n{row3}\n", "expects units"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_log_gives_one_line_and_no_output(tmp_path, files, case):
    d, _ = files
    units = ["1", "2", "3", "4"]
    cols = ["t"] + [f"{p}_{u}{w}" for u in units for p, w in
                    (("delta", ""), ("phi", "L"), ("phi", "R"), ("cur", "L"), ("cur", "R"))]
    header = ",".join(cols)

    def row(t: float) -> str:
        return ",".join([str(t)] + ["0.1"] * (len(cols) - 1))

    fill = {
        "header": header,
        "header_missing": ",".join(cols[:-1]),
        "header_dup": header + ",t",
        "row_dup": row(0.0) + ",0",
        "header_units": header.replace("_1", "_A"),
        "row": row(0.0), "row2": row(0.005), "row3": row(0.01),
        "row_text": row(0.005).replace("0.1", "abc", 1),
        "row_nan": row(0.005).replace("0.1", "nan", 1),
        "row_inf": row(0.005).replace("0.1", "inf", 1),
        "row_cut": row(0.01)[: len(row(0.01)) // 2],
    }
    text, fragment = BAD_CASES[case]
    log = tmp_path / "bad.csv"
    log.write_text(text.format(**fill))
    out = tmp_path / "out.json"
    r = run("fit", str(log), "--platform", str(d / "platform.yaml"), "--out", str(out))
    one_line_error(r, "bad.csv", fragment)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [log]


def test_other_bad_inputs(tmp_path, files, runs_off_square):
    d, logs = files
    out = tmp_path / "out.json"
    pf = str(d / "platform.yaml")
    one_line_error(run("fit", str(tmp_path / "nope.csv"), "--platform", pf, "--out", str(out)),
                   "nope.csv")
    one_line_error(run("fit", str(logs[0]), "--platform", pf, "--out", str(out), "--span",
                       "5s"), "too few for a smoother span")
    one_line_error(run("fit", str(logs[0]), "--platform", pf, "--out", str(out), "--fix",
                       "m_b"), "--fix 'm_b'")
    one_line_error(run("fit", str(logs[0]), "--platform", pf, "--out", str(out),
                       "--weight-rotation", "heavy"), "--weight-rotation")
    # a log where nothing moves: the regressor has rank 0

    log = runs_off_square[0].log
    still = with_arrays(log, delta=0 * D(log), phi=0 * P(log), current=0 * C(log))
    write_log(still, tmp_path / "still.csv")
    one_line_error(run("fit", str(tmp_path / "still.csv"), "--platform", pf, "--out",
                       str(out)), "rank 0")
    bad_pf = tmp_path / "bad.yaml"
    bad_pf.write_text("wheel_radius: -1\n")
    one_line_error(run("fit", str(logs[0]), "--platform", str(bad_pf), "--out", str(out)),
                   "bad.yaml")
    assert not out.exists()


def test_simulate_from_the_shipped_trajectory(tmp_path):
    """The sample's setpoints read back as what `trajectory typical` makes, and `simulate`
    turns them into a valid log (the first 2 s, to keep the test short)."""
    from pathlib import Path

    from ropod_sysid.io import read_log
    from ropod_sysid.platform import load_platform
    from ropod_sysid.trajectory import read_trajectory_csv, typical, variants

    root = Path(__file__).resolve().parent.parent / "datasets" / "ropod"
    platform = load_platform(root / "platform.yaml")
    shipped = read_trajectory_csv(root / "trajectory" / "original.csv.gz")
    fresh = variants(typical(duration=60.0, platform=platform, seed=0))["original"]
    np.testing.assert_allclose(shipped.vx, fresh.vx, atol=1e-12)
    np.testing.assert_allclose(shipped.omega, fresh.omega, atol=1e-12)
    head = tmp_path / "head.csv"
    keep = shipped.t <= 2.0
    np.savetxt(head, np.column_stack([shipped.t[keep], shipped.vx[keep], shipped.vy[keep],
                                      shipped.omega[keep]]),
               delimiter=",", header="t,vx,vy,omega", comments="")
    out = tmp_path / "run.mcap"
    r = run("simulate", "--platform", str(root / "platform.yaml"), "--params",
            str(root / "truth.json"), "--trajectory", str(head), "--out", str(out), "--quiet")
    assert r.exit_code == 0, r.output
    log = read_log(out, platform)
    assert log.n_samples == 401 and log.units == ["1", "2", "3", "4"]
    assert np.abs(P(log)[-1]).max() > 0.1 or np.abs(D(log)[-1]).max() > 0.1


def test_a_missing_trajectory_is_named_as_a_file_not_a_log(files, tmp_path):
    d, _ = files
    r = run("simulate", "--platform", str(d / "platform.yaml"), "--params", str(d / "truth.json"),
            "--trajectory", str(tmp_path / "nope.csv"), "--out", str(tmp_path / "run.csv"))
    one_line_error(r, f"{tmp_path / 'nope.csv'}: no such file; check the path")
    r = run("trajectory", "check", str(tmp_path / "nope.csv"), "--platform",
            str(d / "platform.yaml"))
    one_line_error(r, f"{tmp_path / 'nope.csv'}: no such file; check the path")
    assert not (tmp_path / "run.csv").exists()


def test_console_script_exits_with_the_commands_status_and_flushed_output(tmp_path):
    """The console script (``run``) leaves by os._exit after the exit handlers: the status is
    the command's, everything printed reaches a pipe or a file, and an error is one line."""
    import subprocess
    import sys

    def script(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", "from ropod_sysid.cli.main import run; "
                               "run()", *args], capture_output=True, text=True, timeout=60)

    helped = script("fit", "--help")
    assert helped.returncode == 0, helped.stderr
    assert helped.stdout.startswith("Usage: ") and helped.stdout.rstrip().endswith(
        "Show this message and exit.")
    missing = script("fit", str(tmp_path / "none.csv"), "--platform", "p.yaml",
                     "--out", str(tmp_path / "o.json"))
    assert missing.returncode == 2
    assert missing.stderr.count("\n") == 1 and missing.stderr.startswith("error: ")
    assert not (tmp_path / "o.json").exists()
    unknown = script("nosuch")
    assert unknown.returncode == 2 and "No such command" in unknown.stderr
    # an exit handler registered by a command still runs
    marker = tmp_path / "handled"
    ran = subprocess.run([sys.executable, "-c", "import atexit, sys; from ropod_sysid.cli.main "
                          f"import run; atexit.register(lambda: open({str(marker)!r}, 'w')"
                          ".close()); sys.argv = ['ropod-sysid', '--version']; run()"],
                         capture_output=True, text=True, timeout=60)
    assert ran.returncode == 0 and ran.stdout.startswith("ropod-sysid, version ")
    assert marker.exists()


def test_console_script_runs_one_blas_thread_unless_told():
    """The console script limits the BLAS libraries to one thread, those loaded before it runs
    (numpy's) and after (scipy's, through the environment children inherit), unless the user
    set a BLAS thread variable: then it changes nothing."""
    import json
    import os
    import subprocess
    import sys

    probe = ("import json, os, sys; from ropod_sysid.cli.main import _one_blas_thread; "
             "_one_blas_thread(); import scipy.linalg; "
             "from threadpoolctl import threadpool_info; "
             "print(json.dumps([os.environ.get('OPENBLAS_NUM_THREADS'), "
             "sorted({i['num_threads'] for i in threadpool_info() "
             "if i['user_api'] == 'blas'})]))")
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                        "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")}

    def threads(extra: dict[str, str], limit: bool = True) -> list:
        code = probe if limit else probe.replace("_one_blas_thread(); ", "")
        out = subprocess.run([sys.executable, "-c", code], env={**env, **extra},
                             capture_output=True, text=True, timeout=60, check=True)
        return json.loads(out.stdout)

    assert threads({}) == ["1", [1]]
    told = {"OMP_NUM_THREADS": "2"}
    assert threads(told) == threads(told, limit=False)
    assert threads(told)[0] is None
