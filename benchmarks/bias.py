#!/usr/bin/env python
"""Where the bias of a fit of noise-free logs comes from, and the delay search under noise.

    python benchmarks/bias.py [--part options phase diagnosis delay]

The tests' runs (tests/conftest.py): four 8 s variants on the off-square ropod (the pivots
1–3 cm off the square), simulated at 1 kHz under the simulator's 1 ms zero-order hold and
logged at 100, 200 and 1000 Hz (every k-th sample). Prints, per candidate, the largest error
over the 29 parameters and the errors of m_b and J_zz,b:

- ``options``: what a user can choose (``--smoother``, ``--control-period``, ``--input-delay
  auto``, ``--row-step``, ``--span``) on the exact logs;
- ``phase``: the same with the logs' first 0–3 samples dropped (the rows' phase to the
  simulator's 100 Hz setpoints, whose ripple in the torques rows a step apart can alias);
- ``diagnosis`` (200 Hz): the regressor formed from the simulation's exact states (q, q̇, q̈,
  the unit angles and their rates) instead of the smoothed ones, one signal at a time, and
  the torques filtered like the angles;
- ``delay``: ``--input-delay auto`` on exact logs and with 2¹⁴-count encoders and 30 mA
  current noise (without ``--encoder-counts``, where the search corrects its criterion for the
  counts it detects and the fit stays plain, and with it).

About 1 minute on a 2-core machine (the first simulation compiles for about 10 s).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from ropod_sysid.fit import FitOptions, fit_logs, fit_systems  # noqa: E402
from ropod_sysid.model import PlatformModel  # noqa: E402
from ropod_sysid.params import parameter_names, thesis_fixed_masses  # noqa: E402
from ropod_sysid.platform import ropod_platform  # noqa: E402
from ropod_sysid.regressor import Preprocessed, Span, preprocess, triangles  # noqa: E402
from ropod_sysid.signals import loess  # noqa: E402
from ropod_sysid.simulate import Sensors, SimResult, record, simulate  # noqa: E402
from tests.conftest import OFF_SQUARE, four_variants, subsampled  # noqa: E402

PF = ropod_platform().with_positions(OFF_SQUARE)
TRUTH = thesis_fixed_masses(PF.unit_names)
NAMES = parameter_names(PF, "per-wheel")
TRUE = TRUTH.vector(NAMES)
QUARTIC = Span.parse(None).with_smoother("quartic")


def line(label: str, values: np.ndarray) -> None:
    err = values / TRUE - 1
    i = int(np.argmax(np.abs(err)))
    print(f"| {label} | {100 * abs(err[i]):.2f} % ({NAMES[i]}) | {100 * err[0]:+.3f} % | "
          f"{100 * err[1]:+.3f} % |", flush=True)


def options(runs: list[SimResult]) -> None:
    print("| log rate, options | largest error | m_b | J_zz,b |\n|---|---|---|---|")
    for rate in (200.0, 100.0, 1000.0):
        logs = [subsampled(PF, r, rate).log for r in runs]
        cases: list[tuple[str, dict]] = [
            ("--control-period 0.001", {"control_period": 0.001}),
            ("--smoother quartic --control-period 0.001",
             {"control_period": 0.001, "span": QUARTIC}),
        ]
        if rate == 200.0:
            cases = [("(plain)", {}), *cases,
                     ("--control-period 0.001 --row-step 1",
                      {"control_period": 0.001, "row_step": 1}),
                     ("--smoother quartic --control-period 0.001 --row-step 1",
                      {"control_period": 0.001, "span": QUARTIC, "row_step": 1}),
                     ("--span 0.08s --control-period 0.001",
                      {"control_period": 0.001, "span": Span.parse("0.08s")}),
                     ("--smoother quartic --span 0.15s --control-period 0.001",
                      {"control_period": 0.001,
                       "span": Span.parse("0.15s").with_smoother("quartic")}),
                     ("--input-delay auto", {"input_delay": "auto"}),
                     ("--smoother quartic --input-delay auto",
                      {"input_delay": "auto", "span": QUARTIC})]
        for label, kw in cases:
            fit = fit_logs(logs, PF, FitOptions(recipe_check=False, **kw))
            found = f" (finds {1000 * fit.input_delay:.2f} ms)" if kw.get("input_delay") else ""
            line(f"{rate:.0f} Hz, {label}{found}", fit.solution.values)


def phase(runs: list[SimResult]) -> None:
    """The same fits with the logs' first samples dropped: the rows' phase to the
    simulator's 100 Hz setpoints (whose ripple in the speed loops' torques the rows alias)."""
    print("| log rate, options | largest error, 0 / 1 / 2 / 3 samples dropped |\n|---|---|")
    for rate in (200.0, 1000.0):
        logs = [subsampled(PF, r, rate).log for r in runs]
        for label, kw in [("--control-period 0.001", {"control_period": 0.001}),
                          ("--smoother quartic --control-period 0.001",
                           {"control_period": 0.001, "span": QUARTIC})]:
            out = []
            for n in range(4):
                cut = [dataclasses.replace(lg, t=lg.t[n:], angles=lg.angles[n:],
                                           currents=lg.currents[n:]) for lg in logs]
                fit = fit_logs(cut, PF, FitOptions(recipe_check=False, **kw))
                err = fit.solution.values / TRUE - 1
                out.append(f"{100 * np.abs(err).max():.2f} %")
            print(f"| {rate:.0f} Hz, {label} | {' / '.join(out)} |", flush=True)


def five_point(y: np.ndarray, h: float) -> np.ndarray:
    out = np.gradient(y, h, axis=0)
    out[2:-2] = (y[:-4] - 8 * y[1:-3] + 8 * y[3:-1] - y[4:]) / (12 * h)
    return out


def diagnosis(runs: list[SimResult]) -> None:
    """The 200 Hz system with some smoothed signals replaced by the simulation's exact ones."""
    model = PlatformModel(PF)
    subs = [subsampled(PF, r, 200.0) for r in runs]
    rates = [five_point(r.angles, 0.001)[::5] for r in runs]  # exact unit angle rates
    print("| 200 Hz, the regressor from | row step | largest error | m_b | J_zz,b |\n"
          "|---|---|---|---|---|")

    def fit(label: str, exact: tuple[str, ...], delay: float, row_step: int | None,
            tau: Callable[[Preprocessed], np.ndarray] | None = None) -> None:
        pres = []
        for s, rate in zip(subs, rates, strict=True):
            pre = preprocess(s.log, PF, input_delay=delay, row_step=row_step)
            truth = {"q": s.q, "qd": s.qd, "qdd": s.qdd, "angles": s.angles,
                     "angle_rates": rate}
            for key in exact:
                setattr(pre, key, truth[key].copy())
            if tau is not None:
                pre.tau = tau(pre)
            pres.append(pre)
        sol, _ = fit_systems([triangles(model, p) for p in pres], NAMES, FitOptions())
        line(f"{label} | {row_step or 'auto (2)'}", sol.values)

    everything = ("q", "qd", "qdd", "angles", "angle_rates")
    for step in (None, 1):
        fit("smoothed states, torques delayed 0.5 ms (--control-period 0.001)", (), 5e-4,
            step)
        fit("exact states, torques not delayed (q̈ at the step's start)", everything, 0.0,
            step)
        fit("exact q̈, the rest smoothed, not delayed", ("qdd",), 0.0, step)
        fit("smoothed q̈, the rest exact, delayed 0.5 ms", everything[:2] + everything[3:],
            5e-4, step)
        fit("smoothed angle rates, the rest exact, not delayed",
            ("q", "qd", "qdd", "angles"), 0.0, step)
        fit("smoothed states, torques also through the angles' LOESS, delayed 0.5 ms", (),
            5e-4, step, lambda p: loess(p.tau, p.span_samples))


def shifted(log, seconds: float):  # noqa: ANN001, ANN201 (a Log)
    """The log with its currents logged ``seconds`` early (the motion lags them that much
    more; as tests/test_sigma.py's ``shifted_currents``)."""
    cur = np.stack([np.interp(log.t + seconds, log.t, c) for c in log.currents.T], axis=1)
    return dataclasses.replace(log, currents=cur)


def delay(runs: list[SimResult]) -> None:
    print("| log rate | logs | delay found | m_b | largest error |\n|---|---|---|---|---|")
    for rate in (100.0, 200.0, 1000.0):
        subs = [subsampled(PF, r, rate) for r in runs]
        rng = np.random.default_rng(7)
        noisy = [record(PF, r, r.log.t, Sensors(encoder_counts=2**14, current_noise=0.03),
                        rng, f"noisy{k}") for k, r in enumerate(subs)]
        late = [shifted(lg, 0.005) for lg in noisy]
        counts = {"encoder_counts": 2**14}
        for label, logs, kw in [("exact", [r.log for r in subs], {}),
                                ("2¹⁴ counts, 30 mA", noisy, {}),
                                ("2¹⁴ counts, 30 mA, --encoder-counts 16384", noisy, counts),
                                ("2¹⁴ counts, 30 mA, currents 5 ms early", late, {}),
                                ("2¹⁴ counts, 30 mA, currents 5 ms early, --encoder-counts "
                                 "16384", late, counts)]:
            fit = fit_logs(logs, PF, FitOptions(input_delay="auto", recipe_check=False, **kw))
            err = fit.solution.values / TRUE - 1
            print(f"| {rate:.0f} Hz | {label} | {1000 * fit.input_delay:+.2f} ms | "
                  f"{100 * err[0]:+.2f} % | {100 * np.abs(err).max():.1f} % |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parts = {"options": options, "phase": phase, "diagnosis": diagnosis, "delay": delay}
    ap.add_argument("--part", nargs="+", choices=list(parts), default=list(parts))
    args = ap.parse_args()
    runs = simulate(PF, TRUTH, four_variants(8.0), rate=1000.0)
    for part in args.part:
        parts[part](runs)
        print()


if __name__ == "__main__":
    main()
