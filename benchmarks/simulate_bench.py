"""The simulate figures of ``benchmarks/run.py`` (issue 13): the compiled loop against the numpy
path, as ratios to real time and to the numpy baseline measured in the same run.

    python benchmarks/run.py --only simulate [--quick]

- compile: the first call in a process whose numba cache directory is empty (compiles every
  function), and the first call of a second process on that cache (import + cache load); each
  minus the same call again in its process;
- the CLI: ``ropod-sysid simulate`` of a short run (2 s at 200 Hz) with ``--engine numba``
  and ``--engine numpy``, whole processes;
- the baseline: the numpy path, one 2 s ropod run and four batched (the faster of two);
- the compiled loop: 10 s and 60 s ropod runs (the typical run of Sec. VI-A and its four
  variants), one run and four batched; the 5DPO likewise (10 s);
- equality: the largest difference of every SimResult array between the two paths over the
  four 10 s ropod runs, relative to the array's largest value;
- steered wheels (the shipped sample's platform, ``datasets/steered``: 001's two-wheeled
  vehicle, its truth and controller): one 5 s typical run and its four variants, numpy and
  compiled in the same run (the faster of two each) and their largest difference; and the
  first call of the loop's specialization for platforms with constraint rows on an empty
  cache and on its cache (as for the ropod).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
OMNI = HERE.parent / "datasets" / "omni" / "platform.yaml"
STEERED = HERE.parent / "datasets" / "steered"
OFF_SQUARE = [[0.23, 0.20], [-0.19, 0.22], [-0.21, -0.18], [0.20, -0.23]]
FIELDS = ("q", "qd", "qdd", "angles", "tau", "energy")

FIRST_CALLS = """
import time
t0 = time.perf_counter()
from ropod_sysid.params import thesis_fixed_masses
from ropod_sysid.platform import ropod_platform
from ropod_sysid.simulate import Setpoints, simulate
import numpy as np
pf = ropod_platform()
p = thesis_fixed_masses(pf.unit_names)
t = np.array([0.0, 0.05])
sp = Setpoints(t, 0.1 + 0 * t, 0 * t, 0 * t)
t1 = time.perf_counter()
simulate(pf, p, sp, engine="numba")
t2 = time.perf_counter()
simulate(pf, p, sp, engine="numba")
print(t1 - t0, t2 - t1, time.perf_counter() - t2)
"""
# the same for the loop's specialization with constraint rows (the steered sample's platform)
FIRST_CALLS_STEERED = FIRST_CALLS.replace(
    "pf = ropod_platform()\np = thesis_fixed_masses(pf.unit_names)",
    f"from ropod_sysid.platform import load_platform\nfrom ropod_sysid.params import Parameters"
    f"\nimport json\npf = load_platform({str(STEERED / 'platform.yaml')!r})\n"
    f"p = Parameters(json.load(open({str(STEERED / 'truth.json')!r})))")
# the shipped steered sample's controller (datasets/steered/make_dataset.py)
STEER_CONTROL = dict(kp=20.0, ki=200.0, torque_limit=25.6, steer_kp=40.0, steer_ki=800.0,
                     steer_torque_limit=129.0)


def runs(duration: float, **kwargs: Any) -> list:
    from ropod_sysid.trajectory import typical, variants

    return [v.to_setpoints() for v in variants(typical(duration=duration, seed=1,
                                                       **kwargs)).values()]


def head(sp: Any, seconds: float) -> Any:
    """The first ``seconds`` of setpoints."""
    keep = sp.t <= sp.t[0] + seconds
    return type(sp)(sp.t[keep], sp.vx[keep], sp.vy[keep], sp.omega[keep])


def timed(f: Any, *args: Any, **kwargs: Any) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = f(*args, **kwargs)
    return time.perf_counter() - t0, out


def first_calls(script: str = FIRST_CALLS) -> dict[str, float]:
    """Compile time (empty cache) and cache-load time of the first call in a process."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = {}
        for key in ("cold", "warm"):
            r = subprocess.run([sys.executable, "-c", script], env=env, check=True,
                               capture_output=True, text=True)
            imports, first, again = map(float, r.stdout.split())
            out[f"{key}_imports_s"] = imports
            out[f"{key}_first_s"] = first
            out[f"{key}_extra_s"] = first - again
    return out


def cli_runs(ropod_sysid: list[str], workdir: Path) -> dict[str, float]:
    """``ropod-sysid simulate`` of a 2 s run at 200 Hz with each engine (whole processes; the
    fastest of two)."""
    from ropod_sysid.params import thesis_fixed_masses
    from ropod_sysid.platform import ropod_platform, save_platform

    pf = ropod_platform().with_positions(np.array(OFF_SQUARE))
    save_platform(pf, workdir / "sim_platform.yaml")
    (workdir / "sim_truth.json").write_text(json.dumps(
        thesis_fixed_masses(pf.unit_names).to_mapping()))
    sp = head(runs(10.0)[0], 2.0)
    np.savetxt(workdir / "sim_traj.csv", np.column_stack([sp.t, sp.vx, sp.vy, sp.omega]),
               delimiter=",", header="t,vx,vy,omega", comments="", fmt="%.9g")
    out: dict[str, float] = {}
    for engine in ("numba", "numpy", "numba", "numpy"):
        cmd = [*ropod_sysid, "simulate", "--platform", str(workdir / "sim_platform.yaml"),
               "--params", str(workdir / "sim_truth.json"), "--trajectory",
               str(workdir / "sim_traj.csv"), "--out", str(workdir / f"sim_{engine}.csv"),
               "--engine", engine, "--quiet"]
        wall, _ = timed(subprocess.run, cmd, check=True)
        out[engine] = min(out.get(engine, np.inf), wall)
    return out


def max_rel_diff(a: list, b: list) -> float:
    return max(float(np.abs(getattr(x, f) - getattr(y, f)).max()
                     / max(np.abs(getattr(y, f)).max(), 1e-300))
               for x, y in zip(a, b, strict=True) for f in FIELDS)


def simulate_figures(ropod_sysid: list[str], workdir: Path, quick: bool = False
                     ) -> tuple[dict[str, Any], list[tuple[str, str, str, str]]]:
    from ropod_sysid.params import thesis_fixed_masses, typical_parameters
    from ropod_sysid.platform import load_platform, ropod_platform
    from ropod_sysid.simulate import Controller, simulate

    res: dict[str, Any] = {"first_calls": first_calls(), "cli_2s": cli_runs(ropod_sysid,
                                                                           workdir)}
    pf = ropod_platform().with_positions(np.array(OFF_SQUARE))
    truth = thesis_fixed_masses(pf.unit_names)
    simulate(pf, truth, runs(10.0)[0], engine="numba")  # the cache loaded
    long_s = 20.0 if quick else 60.0
    ten, long = runs(10.0), runs(long_s)
    short = [head(sp, 2.0) for sp in ten]
    simulate(pf, truth, head(ten[0], 0.2), engine="numpy")
    b1 = min(timed(simulate, pf, truth, short[:1], engine="numpy")[0] for _ in range(2))
    b4 = min(timed(simulate, pf, truth, short, engine="numpy")[0] for _ in range(2))
    res["numpy_2s"] = {"one_s": b1, "four_s": b4}
    rows = [("simulate numpy (baseline), ropod 2 s: one / four runs", f"{b1:.2f} s / {b4:.2f} s",
             f"{2 / b1:.2f}× / {8 / b4:.2f}× real time", "(baseline)")]
    fast: dict[str, Any] = {}
    for label, span, sps in (("10 s", 10.0, ten), (f"{long_s:g} s", long_s, long)):
        w1, _ = timed(simulate, pf, truth, sps[:1], engine="numba")
        w4, _ = timed(simulate, pf, truth, sps, engine="numba")
        fast[label] = {"one_s": w1, "four_s": w4}
        rows.append((f"simulate compiled, ropod {label}: one / four runs",
                     f"{w1:.3f} s / {w4:.3f} s",
                     f"{span / w1:.0f}× / {4 * span / w4:.0f}× real time; "
                     f"{(span / w1) / (2 / b1):.0f}× / {(4 * span / w4) / (8 / b4):.0f}× "
                     "numpy", "≥ 100× real time"))
    res["ropod_compiled"] = fast
    omni = load_platform(OMNI)
    o_truth = typical_parameters(omni, 2.34, 0.0228)
    o_runs = runs(10.0, v_max=0.6, w_max=2.0, pivot_rate_max=None)
    ctrl = Controller(kp=0.02, ki=0.4, torque_limit=0.6)
    simulate(omni, o_truth, o_runs[0], controller=ctrl, engine="numba")
    o1, _ = timed(simulate, omni, o_truth, o_runs[:1], controller=ctrl, engine="numba")
    o4, _ = timed(simulate, omni, o_truth, o_runs, controller=ctrl, engine="numba")
    res["omni_compiled_10s"] = {"one_s": o1, "four_s": o4}
    rows.append(("simulate compiled, 5DPO 10 s: one / four runs", f"{o1:.3f} s / {o4:.3f} s",
                 f"{10 / o1:.0f}× / {40 / o4:.0f}× real time", "—"))
    t_ref, ref = timed(simulate, pf, truth, ten, engine="numpy")
    diff = max_rel_diff(simulate(pf, truth, ten, engine="numba"), ref)
    res["equality_10s"] = {"numpy_four_s": t_ref, "max_rel_diff": diff}
    rows.append(("compiled vs numpy, four 10 s ropod runs", f"max rel. diff {diff:.1e}",
                 f"numpy {t_ref:.1f} s", "≤ 1e-9"))
    res["steered"], steered_rows = steered_figures(quick)
    rows.extend(steered_rows)
    fc, cli = res["first_calls"], res["cli_2s"]
    rows.append(("first call: compile (empty cache) / cache load",
                 f"{fc['cold_extra_s']:.1f} s / {fc['warm_extra_s']:.2f} s",
                 f"imports {fc['warm_imports_s']:.2f} s", "(once per install)"))
    sc = res["steered"]["first_calls"]
    rows.append(("first call, steered specialization: compile / cache load",
                 f"{sc['cold_extra_s']:.1f} s / {sc['warm_extra_s']:.2f} s",
                 f"imports {sc['warm_imports_s']:.2f} s", "(once per install)"))
    rows.append(("CLI simulate 2 s at 200 Hz: numba / numpy", f"{cli['numba']:.2f} s / "
                 f"{cli['numpy']:.2f} s", f"{cli['numpy'] / cli['numba']:.1f}× faster",
                 "not slower"))
    return res, rows


def steered_figures(quick: bool = False) -> tuple[dict[str, Any], list[tuple[str, str, str, str]]]:
    """The shipped steered sample's platform (two centred steered wheels, 001): a 5 s typical
    run and its four variants with numpy and compiled, measured in the same run (the faster of
    two), their largest difference, and the first calls of the loop's specialization for
    platforms with constraint rows."""
    from ropod_sysid.params import Parameters
    from ropod_sysid.platform import load_platform
    from ropod_sysid.simulate import Controller, simulate
    from ropod_sysid.trajectory import typical, variants

    pf = load_platform(STEERED / "platform.yaml")
    truth = Parameters(json.loads((STEERED / "truth.json").read_text()))
    span = 5.0
    sps = [v.to_setpoints() for v in variants(typical(
        duration=span, v_max=0.4, w_max=1.0, pivot_rate_max=None, platform=pf,
        seed=0)).values()]
    ctrl = Controller(**STEER_CONTROL)
    res: dict[str, Any] = {"first_calls": first_calls(FIRST_CALLS_STEERED)}
    simulate(pf, truth, sps[0], controller=ctrl, engine="numba")  # the cache loaded
    times: dict[str, float] = {}
    out: dict[str, list] = {}
    for _ in range(1 if quick else 2):  # interleaved: numpy, compiled, numpy, compiled
        for engine in ("numpy", "numba"):
            for label, batch in (("one", sps[:1]), ("four", sps)):
                wall, out[f"{engine}_{label}"] = timed(simulate, pf, truth, batch,
                                                       controller=ctrl, engine=engine)
                key = f"{engine}_{label}_s"
                times[key] = min(times.get(key, np.inf), wall)
    res |= times
    res["max_rel_diff"] = max_rel_diff(out["numba_four"], out["numpy_four"])
    n1, n4 = times["numpy_one_s"], times["numpy_four_s"]
    c1, c4 = times["numba_one_s"], times["numba_four_s"]
    rows = [(f"simulate steered sample {span:g} s: numpy / compiled, one run",
             f"{n1:.2f} s / {c1:.3f} s", f"{n1 / c1:.0f}× faster; {span / c1:.0f}× real time",
             "—"),
            (f"simulate steered sample {span:g} s: numpy / compiled, four runs",
             f"{n4:.2f} s / {c4:.3f} s",
             f"{n4 / c4:.0f}× faster; max rel. diff {res['max_rel_diff']:.1e}", "≤ 1e-9")]
    return res, rows
