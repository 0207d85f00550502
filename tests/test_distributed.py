"""Logs reduced on Dask workers give the serial result; Dask stays optional."""

from __future__ import annotations

import importlib.util
import json
import logging
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.fit import fit_files
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.platform import save_platform
from ropod_sysid.validate import validate_sources

pytestmark = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                reason="the dask extra is not installed")


@pytest.fixture(scope="module")
def files(tmp_path_factory, off_square, truth, runs_off_square):
    d = tmp_path_factory.mktemp("dask")
    save_platform(off_square, d / "platform.yaml")
    paths = []
    for k, r in enumerate(runs_off_square):
        p = d / f"run{k}.csv"
        write_csv_log(r.log, p)
        paths.append(p)
    return d, paths


@pytest.fixture(scope="module")
def cluster():
    """Two workers of one thread each, in threads of this process (processes=False): the
    client, scheduler and task path of a process cluster without its start-up, which takes
    2 s on an idle machine here and over 10 s on a busy one. Worker processes are exercised
    by benchmarks/run.py (`fit --workers 2`); what they add — pickling the arguments and
    results — is checked by test_task_arguments_and_results_pickle."""
    import distributed  # here, not at collection: every test worker collects every file

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None, silence_logs=logging.ERROR) as c:
        yield c


def test_two_worker_cluster_equals_serial(off_square, files, cluster):
    _, paths = files
    serial = fit_files(paths, off_square)
    fit = fit_files(paths, off_square, dask_address=cluster.scheduler_address)
    err = np.abs(fit.solution.values - serial.solution.values) / np.abs(serial.solution.values)
    assert err.max() <= 1e-12
    for a, b in zip(serial.logs, fit.logs, strict=True):
        assert a.source == b.source and a.samples == b.samples and a.weight == b.weight
        np.testing.assert_allclose(b.triangles.r, a.triangles.r, rtol=0,
                                   atol=1e-12 * np.abs(a.triangles.r).max())


def test_validate_on_the_cluster_equals_serial(off_square, truth, files, cluster):
    _, paths = files
    serial = validate_sources(paths, off_square, truth)
    dask = validate_sources(paths, off_square, truth, dask_address=cluster.scheduler_address)
    for a, b in zip(serial, dask, strict=True):
        assert a.to_dict() == b.to_dict()


def test_a_bad_log_on_a_worker_is_a_one_line_error(tmp_path, off_square, files, cluster):
    _, paths = files
    lines = paths[0].read_text().splitlines()
    f = lines[40].split(",")
    f[2] = "oops"
    lines[40] = ",".join(f)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"bad\.csv: line 41, column 'phi_1L'"):
        fit_files([paths[1], bad], off_square, dask_address=cluster.scheduler_address)


def run(*args: str):
    return CliRunner().invoke(main, list(args))


def test_task_arguments_and_results_pickle(off_square, files):
    import pickle

    from ropod_sysid.regressor import Span
    from ropod_sysid.stream import log_triangles

    _, paths = files
    tri, notes = log_triangles(paths[0], off_square, Span.parse("0.1s"))
    for obj in (off_square, Span.parse("21"), tri, InputError("x.csv: line 3, bad")):
        back = pickle.loads(pickle.dumps(obj))
        assert type(back) is type(obj)
    assert np.array_equal(pickle.loads(pickle.dumps(tri)).r, tri.r)
    assert str(pickle.loads(pickle.dumps(InputError("a  b")))) == "a b"


def test_cli_workers_equal_serial(monkeypatch, tmp_path, files):
    """`fit --workers 2` (a local cluster of two workers; threads here, see `cluster`) writes
    the serial parameter file."""
    from ropod_sysid import distributed as dist

    monkeypatch.setattr(dist, "PROCESSES", False)
    d, paths = files
    common = [*map(str, paths), "--platform", str(d / "platform.yaml"), "--quiet"]
    r1 = run("fit", *common, "--out", str(tmp_path / "serial.json"))
    assert r1.exit_code == 0, r1.output
    r2 = run("fit", *common, "--out", str(tmp_path / "dask.json"), "--workers", "2")
    assert r2.exit_code == 0, r2.output
    a = json.loads((tmp_path / "serial.json").read_text())
    b = json.loads((tmp_path / "dask.json").read_text())
    for name, entry in a["parameters"].items():
        assert b["parameters"][name]["value"] == pytest.approx(entry["value"], rel=1e-12)


def test_cli_validate_dask_address(files, cluster, tmp_path):
    d, paths = files
    pf = ["--platform", str(d / "platform.yaml")]
    r = run("fit", *map(str, paths), *pf, "--out", str(tmp_path / "p.json"), "--quiet")
    assert r.exit_code == 0, r.output
    args = ["validate", *map(str, paths[:2]), *pf, "--params", str(tmp_path / "p.json"),
            "--json"]
    serial = json.loads(run(*args).output)
    dask = run(*args, "--dask", cluster.scheduler_address)
    assert dask.exit_code == 0, dask.output
    assert json.loads(dask.output) == serial


def test_without_dask_the_flags_name_the_extra(monkeypatch, tmp_path, files):
    d, paths = files
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    # two logs: one 8 s log is shorter than a fit needs
    common = [*map(str, paths[:2]), "--platform", str(d / "platform.yaml"), "--quiet"]
    for flags in (["--workers", "2"], ["--dask", "tcp://127.0.0.1:8786"]):
        r = run("fit", *common, "--out", str(tmp_path / "x.json"), *flags)
        assert r.exit_code == 2
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and "pip install 'ropod-sysid[dask]'" in lines[0], r.output
        assert not (tmp_path / "x.json").exists()
    r = run("fit", *common, "--out", str(tmp_path / "serial.json"))  # no flags: serial
    assert r.exit_code == 0, r.output


@pytest.mark.parametrize("flags, fragment", [
    (["--workers", "0"], "--workers 0: give a positive number"),
    (["--workers", "2", "--dask", "tcp://127.0.0.1:1"], "give one of them"),
    (["--dask", "tcp://127.0.0.1:1"], "cannot start or reach the Dask cluster"),
])
def test_bad_flags_are_one_line_errors(monkeypatch, tmp_path, files, flags, fragment):
    from ropod_sysid import distributed as dist

    monkeypatch.setattr(dist, "CONNECT_TIMEOUT", "1s")
    d, paths = files
    r = run("fit", str(paths[0]), "--platform", str(d / "platform.yaml"), "--quiet", "--out",
            str(tmp_path / "x.json"), *flags)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and fragment in lines[0], r.output
