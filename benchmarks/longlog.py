#!/usr/bin/env python
"""Long logs: does σ stay honest as the data grow? (issue 14: long logs got over-confident)

    python benchmarks/longlog.py [--copies 10] [--seconds 60] [--rate 1000]

Simulates ``benchmarks/run.py``'s rest-to-rest run on the off-square ropod (every parameter
identifiable) once, exact, at ``--rate``, and records it ``--copies`` times with the sensors of
that benchmark: 2¹⁴-count encoders, each copy's encoder zeros at random within a count, and
30 mA of current noise, a new draw per copy. Then, for each option set below, fits

- each copy alone (the share of all its values within 2σ of the truth, over the copies),
- all copies as separate logs, and
- all copies joined into one log (t and the wheel angles continued, the pivots by whole turns:
  the robot stops, holds and starts again at every seam),

printing the share of the 29 values within 2σ of the truth, the largest |error|/σ, m_b's error
and σ, and the verdict's first words; and first the exact log's own fit, whose error every
copy shares (a bias of the recipe, not of the sensors: σ does not include it, so it shows
once the copies have shrunk σ below it).

Measured (10 copies of 60 s at 1 kHz; docs/accuracy.md, "Long logs"): one copy alone keeps
97–100 % of its values within 2σ with every option set; ten minutes of them, joined or
separate, keep 79–83 % with the default LOESS and 48–52 % with ``--encoder-counts 16384``:
the LOESS's three-point differences attenuate the run's fast accelerations (the exact log:
m_b −2.2 %, m_wh −9.3 %, J_rot,w +7.8 %, one weakly determined combination, 1.1σ of one copy),
which ten copies' σ no longer cover; ``--smoother quartic --encoder-counts 16384
--input-delay auto`` (five-point differences, the hold's half step found) keeps all 29.
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

from excitation import quantised  # noqa: E402
from run import OFF_SQUARE, setpoints  # noqa: E402
from stops import tile  # noqa: E402

from ropod_sysid.fit import FitOptions, fit_logs  # noqa: E402
from ropod_sysid.params import parameter_names, thesis_fixed_masses  # noqa: E402
from ropod_sysid.platform import ropod_platform  # noqa: E402
from ropod_sysid.regressor import Span  # noqa: E402
from ropod_sysid.simulate import Sensors, Setpoints, record, simulate  # noqa: E402
from ropod_sysid.summary import identifiability_verdict  # noqa: E402

COUNTS = 2**14
CURRENT_NOISE = 0.03
QUARTIC = Span.parse(None).with_smoother("quartic")
# fit's default (the recipe check, on up to 1,000,000 samples: here every fit), then the
# jackknife's σ alone (--no-recipe-check): what the copies do to it is what is measured
OPTIONS = {
    "(default: the recipe check)": FitOptions(),
    "--encoder-counts 16384 (the recipe check)": FitOptions(encoder_counts=COUNTS),
    "--no-recipe-check": FitOptions(recipe_check=False),
    "--encoder-counts 16384": FitOptions(encoder_counts=COUNTS, recipe_check=False),
    "--encoder-counts 16384 --input-delay auto": FitOptions(encoder_counts=COUNTS,
                                                            input_delay="auto",
                                                            recipe_check=False),
    "--smoother quartic --encoder-counts 16384 --input-delay auto": FitOptions(
        encoder_counts=COUNTS, input_delay="auto", span=QUARTIC, recipe_check=False),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--copies", type=int, default=10)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    args = ap.parse_args()
    pf = ropod_platform().with_positions(np.array(OFF_SQUARE))
    truth = thesis_fixed_masses(pf.unit_names)
    ref = truth.vector(parameter_names(pf))
    s = setpoints(args.seconds)
    (run,) = simulate(pf, truth, [Setpoints(s[:, 0], s[:, 1], s[:, 2], s[:, 3])],
                      rate=args.rate)
    exact = run.log
    copies = []
    for k in range(args.copies):
        rng = np.random.default_rng(2000 + k)
        rec = record(pf, run, exact.t, Sensors(current_noise=CURRENT_NOISE), rng, f"copy{k}")
        copies.append(quantised(rec, COUNTS, rng))
    long = dataclasses.replace(tile(exact, len(copies), copies), source="joined")

    def row(label: str, fit) -> None:
        sol = fit.solution
        err = sol.values - ref
        z = np.abs(err) / sol.std
        verdict = identifiability_verdict(fit).split(":")[0].split(",")[0]
        print(f"  {label:<22} {100 * np.mean(z < 2):5.0f} % {z.max():7.2f}σ "
              f"{100 * err[0] / ref[0]:+7.2f} ± {100 * sol.std[0] / ref[0]:.2f} %   {verdict}",
              flush=True)

    t0 = time.perf_counter()
    print(f"{args.copies} copies of a {args.seconds:g} s run at {args.rate:g} Hz "
          f"({len(exact.t)} samples each); off-square ropod, 2¹⁴ counts, 30 mA")
    print(f"  {'':<22} {'in 2σ':>7} {'worst':>8} {'m_b error ± σ':>17}   verdict")
    print("the exact log (no sensor effects), default options:")
    row("exact", fit_logs([exact], pf, FitOptions(recipe_check=False)))
    for label, opts in OPTIONS.items():
        print(f"{label}:")
        each = []
        for lg in copies:
            sol = fit_logs([lg], pf, opts).solution
            each.append(np.mean(np.abs(sol.values - ref) < 2 * sol.std))
        print(f"  {'each copy alone':<22} {100 * min(each):3.0f}–{100 * max(each):.0f} % "
              f"(mean {100 * np.mean(each):.0f} %)")
        row("separate logs", fit_logs(copies, pf, opts))
        row("joined", fit_logs([long], pf, opts))
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
