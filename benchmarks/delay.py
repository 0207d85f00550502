#!/usr/bin/env python
"""Benchmark of ``fit --input-delay auto`` against a plain ``fit`` (issue 14, goal ≤ 1.5×).

    python benchmarks/delay.py [--fresh]

The delay search forms b_ID for a few node delays in the same single pass as a plain fit
(:class:`ropod_sysid.regressor.DelayBracket`), so it should cost little more than one. Each
command runs in its own process, best of three wall times:

- the shipped sample (``datasets/ropod/*.csv.gz``: four 60 s runs at 100 Hz; nodes a sample
  apart, exact interpolation);
- four 20 s runs at 1 kHz simulated with ``ropod-sysid simulate`` from ``ropod-sysid
  trajectory typical`` (2¹⁴-count encoders, 30 mA current noise; nodes every 5 samples,
  cubic interpolation), cached in ``benchmarks/out/delay/`` (``--fresh`` simulates again);
- a long log: ``benchmarks/run.py``'s 10-minute 1 kHz log (its 60 s run ten times), if that
  benchmark has written it (the search's gram grows with the log, the rest of the fit too).

Prints the table and the delays found.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out" / "delay"
EXE = Path(sys.executable).with_name("ropod-sysid")
CLI = [str(EXE)] if EXE.exists() else [sys.executable, "-c",
                                        "from ropod_sysid.cli.main import main; main()"]


def run(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(CLI + args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def fast_logs(fresh: bool) -> list[Path]:
    """Four 20 s variants at 1 kHz (simulated once, cached)."""
    if fresh and OUT.exists():
        shutil.rmtree(OUT)
    OUT.mkdir(parents=True, exist_ok=True)
    platform = ROOT / "datasets" / "ropod" / "platform.yaml"
    truth = ROOT / "datasets" / "ropod" / "truth.json"
    traj = OUT / "trajectory"
    if not traj.exists():
        subprocess.run(CLI + ["trajectory", "typical", "--duration", "20", "--out", str(traj),
                              "--platform", str(platform)], check=True)
    logs = []
    for setpoints in sorted(traj.glob("*.csv*")):
        log = OUT / (setpoints.name.split(".")[0] + "_1k.csv")
        if not log.exists():
            subprocess.run(CLI + ["simulate", "--platform", str(platform), "--params",
                                  str(truth), "--trajectory", str(setpoints), "--out", str(log),
                                  "--rate", "1000", "--encoder-counts", "16384",
                                  "--current-noise", "0.03", "-q"], check=True)
        logs.append(log)
    return logs


def measure(label: str, logs: list[Path], platform: Path = ROOT / "datasets" / "ropod" /
            "platform.yaml") -> tuple[str, float, float, float]:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "p.json"
        base = ["fit", *map(str, logs), "--platform", str(platform), "--out", str(out),
                "--no-recipe-check"]  # the search's own cost
        plain = min(run(base) for _ in range(3))
        auto = min(run(base + ["--input-delay", "auto"]) for _ in range(3))
        delay = json.loads(out.read_text())["input_delay_s"]
    return label, plain, auto, delay


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fresh", action="store_true", help="simulate the 1 kHz runs again")
    args = ap.parse_args()
    rows = [measure("shipped sample, 4 × 60 s at 100 Hz",
                    sorted((ROOT / "datasets" / "ropod").glob("*.csv.gz"))),
            measure("4 × 20 s at 1 kHz", fast_logs(args.fresh))]
    long_log = HERE / "out" / "log_10min.csv"
    if long_log.exists():
        rows.append(measure("10 min at 1 kHz (benchmarks/run.py's)", [long_log],
                            HERE / "out" / "platform.yaml"))
    else:
        print(f"({long_log} not found: run benchmarks/run.py for the long log's row)")
    print(f"{'logs':<38} {'fit [s]':>8} {'auto [s]':>9} {'ratio':>6} {'goal':>6} delay")
    for label, plain, auto, delay in rows:
        print(f"{label:<38} {plain:>8.2f} {auto:>9.2f} {auto / plain:>5.2f}× {'≤ 1.5×':>6} "
              f"{1000 * delay:+.2f} ms")


if __name__ == "__main__":
    main()
