#!/usr/bin/env python
"""Accuracy of a fit whose log repeats a run: stops and restarts must not bias it.

    python benchmarks/stops.py [--copies 2 3 10] [--seconds 30]

Simulates the benchmark's rest-to-rest run (benchmarks/run.py's setpoints: forward at both
ends, so the pivots trail alike at the seams) on the off-square ropod at 200 Hz, noise-free,
joins 2, 3 and 10 copies end to end as one log (t and the wheel angles continued, the pivot
angles by whole turns: at each seam the robot stands still, its speed loops holding opposing
currents, then a controller reset), and fits each joined log, the same log cut into its pieces
at the rest stretches and fitted as separate logs (issue 14: the two must agree within σ), and
one copy alone, printing the error ± σ of m_b, J_zz,b and m_wh and the largest difference of
the 29 parameters from the joined log's, in its σ.

The rows where the platform stands still carry no equation (ropod_sysid.regressor.at_rest):
without that, three copies gave m_b +17 %; REST_* thresholds a tenth of the shipped ones give
two copies +12.5 %. With it, the joined log equals its pieces cut inside the rest stretches to
0.001σ (2, 3 and 10 copies), and the seams add nothing: widening the rest mask by up to 20
rows (the smoother's and the rows' filter's reach, 10) on both sides moves m_b by at most
0.07 points.

What differs between one copy (m_b −0.08 %) and the joined log (−1.92 % for 2 and 10
copies, −1.31 % for 3) is the rows' phase, not the stops: at 200 Hz the default rows are every
2nd sample, and a run of 6001 samples puts the rows of every other copy at its odd samples.
The same copy with its rows at the odd samples (its first sample dropped) gives m_b −3.77 ±
5.5 %, m_wh −14.4 ± 22.5 % (even: −0.08 ± 2.2 %, −0.04 ± 8.6 %); the copy fitted at both
phases as two logs gives the joined log's values (−1.92 %, −7.19 %), as do its pieces cut at
even samples; cut at the seams, each piece restarts its rows at an even sample and they give
one copy's −0.08 % (0.8σ of the joined log's values at 2 and 3 copies, 2.4σ at 10, whose σ
shrinks with copies that add no new motion). The phase's effect is mostly the rows' torque
average (the mean of 3 samples) passing the speed loops' ripple at the simulator's 100 Hz
setpoints, which the states' central differences null (docs/method.md, "The rows' torque
average"): the run simulated from setpoints every 1 ms gives −0.14 % and −0.88 % by phase
(the current's second difference 2.5× smaller); with the 100 Hz setpoints, row weights that
null the row rate (RowGrid.torque_kernel's quartic rule with the LOESS's second moment 2dt²/3)
narrow the two phases to −2.30 % and −1.54 % and leave the joined log's −1.92 %, and
`--row-step 1` gives −2.44 % at either phase. Neither is applied here: the weights would
change the default fit of every log at 200 Hz and above.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from run import OFF_SQUARE, setpoints  # noqa: E402

from ropod_sysid.fit import FitOptions, fit_logs  # noqa: E402
from ropod_sysid.params import parameter_names, thesis_fixed_masses  # noqa: E402
from ropod_sysid.platform import ropod_platform  # noqa: E402
from ropod_sysid.simulate import Setpoints, simulate  # noqa: E402


def tile(log, copies: int, recordings: list | None = None):
    """``copies`` repetitions of ``log`` as one log, continued across the seams (t, the wheel
    angles by the run's motion from its first to its last sample, the pivots by whole turns);
    ``recordings``: the copies' own recordings of the run (sensor effects of their own) in
    place of ``log`` itself."""
    recs = [log] * copies if recordings is None else recordings
    dt = float(np.median(np.diff(log.t)))
    period = log.t[-1] - log.t[0] + dt
    shift = log.angles[-1] - log.angles[0]
    w = log.layout.wrapped
    shift[w] = 2 * np.pi * np.round(shift[w] / (2 * np.pi))
    return dataclasses.replace(
        recs[0], t=np.concatenate([r.t + k * period for k, r in enumerate(recs)]),
        angles=np.concatenate([r.angles + k * shift for k, r in enumerate(recs)]),
        currents=np.concatenate([r.currents for r in recs]))


def cut(log, start: int, stop: int | None = None):
    """Samples start:stop of ``log`` as a log of their own."""
    return dataclasses.replace(log, t=log.t[start:stop], angles=log.angles[start:stop],
                               currents=log.currents[start:stop])


def pieces(log, n: int, copies: int, keep_phase: bool) -> list:
    """A log of ``copies`` runs of ``n`` samples cut at its seams into separate logs: at the
    seams themselves (each piece's rows from its own first sample), or with ``keep_phase`` at
    the even sample at or before each seam (inside the rest stretch; the rows keep the joined
    log's phase when the row step is 2)."""
    cuts = [0] + [j * n - (j * n % 2 if keep_phase else 0) for j in range(1, copies)] + [None]
    return [cut(log, a, b) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--copies", type=int, nargs="+", default=[2, 3, 10])
    ap.add_argument("--seconds", type=float, default=30.0)
    args = ap.parse_args()
    pf = ropod_platform().with_positions(np.array(OFF_SQUARE))
    truth = thesis_fixed_masses(pf.unit_names)
    names = parameter_names(pf)
    ref = truth.vector(names)
    s = setpoints(args.seconds)
    (run,) = simulate(pf, truth, [Setpoints(s[:, 0], s[:, 1], s[:, 2], s[:, 3])], rate=200.0)
    n = len(run.log.t)

    def line(label: str, logs: list, against=None) -> object:
        t0 = time.perf_counter()
        sol = fit_logs(logs, pf, FitOptions(recipe_check=False)).solution
        err = 100 * (sol.values - ref) / np.abs(ref)
        std = 100 * sol.std / np.abs(ref)
        cells = " ".join(f"{e:>+7.2f} ±{d:<5.2f}" for e, d in zip(err[:3], std[:3], strict=True))
        vs = "" if against is None else \
            f"{np.max(np.abs(sol.values - against.values) / against.std):>9.3f}"
        print(f"{label:<44} {cells} {vs:>9}  {time.perf_counter() - t0:.1f} s", flush=True)
        return sol

    print(f"one run: {n} samples; errors [%] ± σ [%]; Δ/σ: the largest |difference| over the "
          f"{len(names)} parameters from the joined log's value, in σ of that")
    print(f"{'':<44} {'m_b':>14} {'Jzz_b':>14} {'m_wh':>14} {'Δ/σ':>9}")
    line("1 copy, rows at its even samples", [run.log])
    line("1 copy, rows at its odd samples", [cut(run.log, 1)])
    line("1 copy at both phases (2 logs)", [run.log, cut(run.log, 1)])
    for k in args.copies:
        joined = tile(run.log, k)
        sol = line(f"{k} copies joined", [joined])
        line("  its pieces, cut in the rests, phase kept", pieces(joined, n, k, True), sol)
        line("  its pieces, cut at the seams", pieces(joined, n, k, False), sol)


if __name__ == "__main__":
    main()
