"""Outputs never cost a user data: an output that is an input, or another output, or not a
regular file is refused before any work; a symbolic link is written through; a command writes
all of its files or none; usage errors and warnings are one line; options do their job."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.io import write_log
from ropod_sysid.io.atomic import OutputSet, atomic_path, atomic_write_text, check_outputs
from ropod_sysid.platform import save_platform
from tests.test_cli import one_line_error

INPUT = "writing it would destroy the input; give another file name"


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def files(tmp_path_factory, off_square, truth, runs_off_square):
    """platform.yaml, truth.json, run0.csv, run1.csv, params.json (a fit), traj.csv."""
    d = tmp_path_factory.mktemp("outputs")
    save_platform(off_square, d / "platform.yaml")
    (d / "truth.json").write_text(json.dumps(truth.to_mapping()))
    for k in (0, 1):
        write_log(runs_off_square[k].log, d / f"run{k}.csv")
    r = run("fit", d / "run0.csv", d / "run1.csv", "--platform", d / "platform.yaml", "--out",
            d / "params.json", "--quiet")
    assert r.exit_code == 0, r.output
    r = run("trajectory", "typical", "--duration", "4", "--out", d / "traj", "--quiet")
    assert r.exit_code == 0, r.output
    (d / "traj.csv").write_bytes((d / "traj" / "original.csv").read_bytes())
    return d


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file below ``folder`` (links not followed): its bytes and mtime."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            out[str(p.relative_to(folder))] = (os.readlink(p).encode(), 0)
        elif p.is_file():
            out[str(p.relative_to(folder))] = (p.read_bytes(), p.stat().st_mtime_ns)
    return out


@pytest.fixture()
def work(files, tmp_path):
    """A fresh folder with the fixture's inputs (copied), and a check that the failing command
    left it exactly as it was: inputs unchanged, no output, no temporary file."""
    for name in ("platform.yaml", "truth.json", "run0.csv", "run1.csv", "params.json",
                 "traj.csv"):
        (tmp_path / name).write_bytes((files / name).read_bytes())
    before = snapshot(tmp_path)
    yield tmp_path
    assert snapshot(tmp_path) == before


def commands(d: Path) -> dict[str, list[object]]:
    """Every command that writes, with ``OUT`` where its output goes."""
    pf = ["--platform", d / "platform.yaml"]
    return {
        "fit --out": ["fit", d / "run0.csv", d / "run1.csv", *pf, "--out", "OUT"],
        "fit --report": ["fit", d / "run0.csv", d / "run1.csv",
                         *pf, "--out", d / "p.json", "--report", "OUT"],
        "fit --format yaml": ["fit", d / "run0.csv", d / "run1.csv",
                              *pf, "--format", "yaml", "--out", "OUT"],
        "report --out": ["report", d / "run0.csv", *pf, "--params", d / "params.json",
                         "--out", "OUT"],
        "simulate --out": ["simulate", *pf, "--params", d / "truth.json", "--trajectory",
                           d / "traj.csv", "--out", "OUT"],
        "convert OUT": ["convert", d / "run0.csv", "OUT", *pf],
        "trajectory check --plot": ["trajectory", "check", d / "traj.csv", *pf, "--plot",
                                    "OUT"],
    }


def with_out(args: list[object], out: object) -> list[object]:
    return [out if a == "OUT" else a for a in args]


LABEL = {"convert OUT": "OUT", "trajectory check --plot": "--plot"}
INPUT_OF = {  # the input each command's output is aimed at, and its name there
    "fit --out": ("LOGS", "run0.csv"), "fit --report": ("LOGS", "run0.csv"),
    "fit --format yaml": ("--platform", "platform.yaml"),
    "report --out": ("--params", "params.json"), "simulate --out": ("--trajectory", "traj.csv"),
    "convert OUT": ("IN", "run0.csv"), "trajectory check --plot": ("TRAJ.csv", "traj.csv"),
}


@pytest.mark.parametrize("how", ["same path", "symlink", "hard link", "dot-dot"])
@pytest.mark.parametrize("cmd", list(INPUT_OF))
def test_an_output_that_is_an_input_is_refused(tmp_path_factory, files, cmd, how):
    d = tmp_path_factory.mktemp("in")
    for name in ("platform.yaml", "truth.json", "run0.csv", "params.json", "traj.csv"):
        (d / name).write_bytes((files / name).read_bytes())
    in_label, name = INPUT_OF[cmd]
    suffix = {"--plot": ".png", "simulate --out": ".csv"}.get(LABEL.get(cmd, cmd), "")
    if how == "same path":
        out = d / name
    elif how == "dot-dot":
        (d / "sub").mkdir()
        out = Path(f"{d}/sub/../{name}")
    else:
        out = d / f"alias{suffix or Path(name).suffix}"
        (out.symlink_to if how == "symlink" else out.hardlink_to)(d / name)
    before = snapshot(d)
    r = run(*with_out(commands(d)[cmd], out))
    label = LABEL.get(cmd, cmd.split()[-1] if cmd.split()[-1].startswith("--") else "--out")
    one_line_error(r, f"{label} {out}: is also the input {in_label} {d / name}; {INPUT}")
    assert snapshot(d) == before


def test_the_same_file_as_two_outputs_is_refused(work):
    d = work
    r = run("fit", d / "run0.csv", d / "run1.csv",
            "--platform", d / "platform.yaml", "--out", d / "x.json",
            "--report", d / "x.json")
    one_line_error(r, f"--out {d / 'x.json'} and --report {d / 'x.json'}: are the same file; "
                      "give each output its own name")
    (d / "sub").mkdir()
    r = run("fit", d / "run0.csv", d / "run1.csv",
            "--platform", d / "platform.yaml", "--out", d / "x.json",
            "--report", f"{d}/sub/../x.json")
    one_line_error(r, "are the same file")
    (d / "sub").rmdir()


@pytest.mark.parametrize("cmd", list(INPUT_OF))
def test_a_fifo_or_a_device_is_refused(work, cmd):
    fifo = work / ("out.png" if "plot" in cmd else "out.csv")
    os.mkfifo(fifo)
    r = run(*with_out(commands(work)[cmd], fifo))
    label = LABEL.get(cmd, cmd.split()[-1] if cmd.split()[-1].startswith("--") else "--out")
    one_line_error(r, f"{label} {fifo}: is a FIFO; only a regular file is written; give a "
                      "file name")
    assert fifo.is_fifo()
    fifo.unlink()
    if "plot" not in cmd and "simulate" not in cmd and "convert" not in cmd:
        r = run(*with_out(commands(work)[cmd], "/dev/null"))
        one_line_error(r, f"{label} /dev/null: is a character device; only a regular file "
                          "is written; give a file name")
        assert Path("/dev/null").is_char_device()


@pytest.mark.parametrize("cmd", list(INPUT_OF))
def test_an_unwritable_folder_is_one_line_before_the_work(work, cmd, monkeypatch):
    import ropod_sysid.cli.simulate as sim

    def no_work(*a, **k):
        raise AssertionError("the work started")

    monkeypatch.setattr(sim, "simulate", no_work)
    out = "/proc/out.png" if "plot" in cmd else "/proc/out.csv"
    r = run(*with_out(commands(work)[cmd], out))
    label = LABEL.get(cmd, cmd.split()[-1] if cmd.split()[-1].startswith("--") else "--out")
    one_line_error(r, f"{label} {out}: cannot write in /proc (", "); give a writable folder")
    r = run(*with_out(commands(work)[cmd], out.replace("/proc/", "/proc/nope/")))
    one_line_error(r, f"{label} {out.replace('/proc/', '/proc/nope/')}: cannot create the "
                      "directory /proc/nope (", "); give a writable folder")


def test_a_symlink_is_written_through(files, tmp_path):
    d = files
    target = tmp_path / "target.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    r = run("fit", d / "run0.csv", d / "run1.csv",
            "--platform", d / "platform.yaml", "--out", link, "--quiet")
    assert r.exit_code == 0, r.output
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert json.loads(target.read_text()) == json.loads((d / "params.json").read_text())
    # convert, simulate and trajectory's CSVs go through the same atomic_path
    csv_target = tmp_path / "log.csv"
    csv_target.write_text("old")
    (tmp_path / "log_link.csv").symlink_to(csv_target)
    r = run("convert", d / "run0.csv", tmp_path / "log_link.csv", "--platform",
            d / "platform.yaml", "--quiet")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "log_link.csv").is_symlink()
    assert csv_target.read_bytes() == (d / "run0.csv").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "log.csv",
                                                          "log_link.csv", "target.json"]


def test_a_failing_command_leaves_none_of_its_files(work):
    d = work
    pf = ["--platform", d / "platform.yaml"]
    base = ["fit", d / "run0.csv", d / "run1.csv", *pf, "--out", d / "new" / "p.json", "--report",
            d / "new" / "r.html"]
    one_line_error(run(*base, "--compare", d / "missing.json"), "missing.json",
                   "no such parameter file")
    # the validation log is read after the parameter file is done: still nothing is left
    one_line_error(run(*base, "--validate", d / "missing.csv"), "missing.csv")
    assert not (d / "new").exists()  # the folder made for the outputs is gone too
    one_line_error(run("report", d / "run0.csv", *pf, "--params", d / "params.json", "--out",
                       d / "r.html", "--validate", d / "missing.csv"), "missing.csv")


def test_trajectory_writes_four_files_or_none(work, monkeypatch):
    from ropod_sysid.trajectory import Trajectory

    write_csv = Trajectory.write_csv
    calls = []

    def disk_full_at_the_third(self, path):
        calls.append(path)
        if len(calls) % 4 == 3:
            raise OSError(28, "No space left on device")
        write_csv(self, path)

    monkeypatch.setattr(Trajectory, "write_csv", disk_full_at_the_third)
    out = work / "runs"
    r = run("trajectory", "typical", "--duration", "4", "--out", out)
    one_line_error(r, f"{out / 'negated.csv'}: cannot write (No space left on device)")
    assert len(calls) == 3 and not out.exists()
    out.mkdir()
    (out / "mirrored.csv").write_text("keep")
    r = run("trajectory", "optimize", "--platform", work / "platform.yaml", "--duration", "5",
            "--harmonics", "1", "--maxiter", "1", "--out", out, "--quiet")
    # the last of the four fails this time
    one_line_error(r, f"{out / 'mirrored_negated.csv'}: cannot write (No space left on device)")
    assert len(calls) == 7
    assert [p.name for p in out.iterdir()] == ["mirrored.csv"]  # the old file, untouched
    assert (out / "mirrored.csv").read_text() == "keep"
    (out / "mirrored.csv").unlink()
    out.rmdir()


def test_trajectory_out_refuses_a_fifo_and_an_input(work):
    (work / "runs").mkdir()
    os.mkfifo(work / "runs" / "negated.csv")
    r = run("trajectory", "typical", "--out", work / "runs")
    one_line_error(r, f"--out {work / 'runs' / 'negated.csv'}: is a FIFO")
    (work / "runs" / "negated.csv").unlink()
    (work / "runs" / "original.csv").symlink_to(work / "platform.yaml")
    r = run("trajectory", "optimize", "--platform", work / "platform.yaml", "--out",
            work / "runs")
    one_line_error(r, f"--out {work / 'runs' / 'original.csv'}: is also the input --platform "
                      f"{work / 'platform.yaml'}")
    (work / "runs" / "original.csv").unlink()
    (work / "runs").rmdir()


def test_library_check_outputs_and_output_set(tmp_path):
    (tmp_path / "in.csv").write_text("data")
    with pytest.raises(InputError, match=r"^--out .*in.csv: is also the input LOGS"):
        check_outputs([("--out", tmp_path / "in.csv")], [("LOGS", tmp_path / "in.csv")])
    with pytest.raises(InputError, match="is a directory; give the file name inside it"):
        check_outputs([("--out", tmp_path)])
    check_outputs([("--out", tmp_path / "new.json"), ("--report", None)],
                  [("LOGS", tmp_path / "missing.csv")])
    # all or nothing: a failure after two writes leaves neither, nor a temporary file
    with pytest.raises(RuntimeError), OutputSet([("a", tmp_path / "a"), ("b", tmp_path / "b")]):
        atomic_write_text(tmp_path / "a", "A")
        atomic_write_text(tmp_path / "b", "B")
        assert sorted(p.name for p in tmp_path.iterdir())[0].startswith(".a.")
        raise RuntimeError
    assert [p.name for p in tmp_path.iterdir()] == ["in.csv"]
    with OutputSet([("a", tmp_path / "a"), ("b", tmp_path / "b")]):
        atomic_write_text(tmp_path / "a", "A")
        atomic_write_text(tmp_path / "b", "B")
        assert not (tmp_path / "a").exists()  # renamed only at the end of the block
    assert (tmp_path / "a").read_text() + (tmp_path / "b").read_text() == "AB"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b", "in.csv"]


def test_the_folder_of_an_output_is_made_and_removed_on_failure(work):
    d = work
    out = d / "a" / "b" / "p.json"
    r = run("fit", d / "run0.csv", d / "run1.csv",
            "--platform", d / "platform.yaml", "--out", out, "--quiet")
    assert r.exit_code == 0, r.output
    assert json.loads(out.read_text())["parameters"]
    out.unlink()
    out.parent.rmdir()
    out.parent.parent.rmdir()
    (d / "file").write_text("x")
    r = run("fit", d / "run0.csv", d / "run1.csv",
            "--platform", d / "platform.yaml", "--out", d / "file" / "p")
    one_line_error(r, f"--out {d / 'file' / 'p'}: its folder {d / 'file'} exists and is not a "
                      "directory; give a directory")
    (d / "file").unlink()


@pytest.mark.parametrize("args, message", [
    (["fit", "x.csv"], "error: Missing option '--platform' (see 'ropod-sysid fit --help')"),
    (["fit", "x.csv", "--platform", "p", "--out", "o", "--format", "xml"],
     "error: Invalid value for '--format': 'xml' is not one of 'json', 'yaml', 'ros2', 'kelo' "
     "(see 'ropod-sysid fit --help')"),
    (["fitt"], "error: No such command 'fitt' (see 'ropod-sysid --help')"),
    (["trajectory", "check"],
     "error: Missing argument 'TRAJ.csv' (see 'ropod-sysid trajectory check --help')"),
    (["simulate", "--rate", "fast"], "error: Invalid value for '--rate': 'fast' is not a "
                                     "valid float (see 'ropod-sysid simulate --help')"),
])
def test_usage_errors_are_one_line(args, message):
    r = run(*args)
    one_line_error(r)
    assert r.output.strip() == message


def test_compare_without_report_prints_the_comparison(files, truth, off_square):
    d = files
    r = run("fit", d / "run0.csv", d / "run1.csv", "--platform", d / "platform.yaml", "--out",
            d / "cmp.json", "--compare", d / "truth.json")
    assert r.exit_code == 0, r.output
    fitted = json.loads((d / "cmp.json").read_text())["parameters"]
    true = truth.to_mapping()
    assert "compared with truth.json" in r.output
    row = next(ln for ln in r.output.splitlines() if ln.startswith("fpv_1 "))
    value, std = fitted["fpv_1"]["value"], fitted["fpv_1"]["std"]
    diff = value - true["fpv_1"]
    assert f" {true['fpv_1']:.5g} " in row
    assert f" {100 * diff / abs(true['fpv_1']):+.1f}% " in row
    assert f" {diff / std:+.2f} " in row
    assert not list(d.glob("*.html"))
    q = run("fit", d / "run0.csv", d / "run1.csv", "--platform", d / "platform.yaml", "--out",
            d / "cmp.json", "--compare", d / "truth.json", "--quiet")
    assert q.exit_code == 0 and row in q.output.splitlines()  # its output, even with --quiet


def test_validate_without_report_prints_what_validate_prints(files):
    d = files
    pf = ["--platform", d / "platform.yaml"]
    r = run("fit", d / "run0.csv", d / "run1.csv",
            *pf, "--out", d / "val.json", "--validate", d / "run1.csv",
            "--quiet")
    assert r.exit_code == 0, r.output
    v = run("validate", d / "run1.csv", *pf, "--params", d / "val.json")
    assert v.exit_code == 0, v.output
    assert r.output.splitlines()[-len(v.output.splitlines()):] == v.output.splitlines()
    assert "validation of the fitted values on the --validate logs:" in r.output


def _cli(*args: object) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "ropod-sysid"
    return subprocess.run([str(script), *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def test_dask_start_up_says_nothing_on_stderr(files, tmp_path):
    pytest.importorskip("distributed")
    d = files
    p = _cli("fit", d / "run0.csv", d / "run1.csv", "--platform", d / "platform.yaml", "--out",
             tmp_path / "p.json", "--workers", "1", "--quiet")
    assert p.returncode == 0, p.stderr
    assert p.stderr == ""


def test_a_numpy_warning_is_one_line(files, tmp_path):
    """A RuntimeWarning raised in a command prints as one ``warning:`` line."""
    code = ("import numpy as np, sys\n"
            "import ropod_sysid.cli.inspect as ins\n"
            "real = ins.inspect_file\n"
            "def noisy(*a, **k):\n"
            "    np.log(np.zeros(3))\n"
            "    return real(*a, **k)\n"
            "ins.inspect_file = noisy\n"
            "from ropod_sysid.cli.main import main\n"
            "main(sys.argv[1:], prog_name='ropod-sysid')\n")
    p = subprocess.run([sys.executable, "-c", code, "inspect", str(files / "run0.csv"),
                        "--platform", str(files / "platform.yaml")], capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stderr == "warning: divide by zero encountered in log\n"


def test_options_that_would_do_nothing_are_errors(work):
    d = work
    r = run("simulate", "--platform", d / "platform.yaml", "--params", d / "truth.json",
            "--trajectory", d / "traj.csv", "--out", d / "s.csv", "--seed", "3")
    one_line_error(r, "--seed 3: seeds the current noise and timestamp jitter, and neither is "
                      "on; give --current-noise or --jitter, or leave out --seed")
    r = run("trajectory", "typical", "--out", d / "runs", "--no-pivot-limit",
            "--pivot-rate-max", "2")
    one_line_error(r, "--pivot-rate-max 2 and --no-pivot-limit: give one of them")
    r = run("trajectory", "check", d / "traj.csv", "--platform", d / "platform.yaml",
            "--no-pivot-limit", "--pivot-rate-max", "2")
    one_line_error(r, "--pivot-rate-max 2 and --no-pivot-limit: give one of them")


def test_a_full_disk_is_one_line_and_leaves_no_file(tmp_path):
    full = r"out.csv: cannot write \(No space left on device\)$"
    with pytest.raises(InputError, match=full), atomic_path(tmp_path / "out.csv") as tmp:
        tmp.write_text("part")
        raise OSError(28, "No space left on device")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("where", ["LOGS", "--platform", "--params"])
def test_an_input_that_is_a_fifo_is_refused_not_waited_on(files, tmp_path, where):
    """Opening a FIFO for reading blocks until something writes to it: refused when parsed."""
    d = files
    fifo = tmp_path / "stream"
    os.mkfifo(fifo)
    paths = {"LOGS": d / "run0.csv", "--platform": d / "platform.yaml",
             "--params": d / "params.json"}
    paths[where] = fifo
    p = subprocess.run([str(Path(sys.executable).parent / "ropod-sysid"), "validate",
                        str(paths["LOGS"]), "--platform", str(paths["--platform"]),
                        "--params", str(paths["--params"])],
                       capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().splitlines() == [
        f"error: {where} {fifo}: is a FIFO, not a regular file; give the file itself (copy a "
        "stream to a file first)"]
