#!/usr/bin/env python
"""Fits of logs with bumps: plain least squares against ``--robust huber`` and ``bisquare``.

    python benchmarks/robust.py [--seeds 5] [--seconds 20] [--force 0 20 80]

Simulates the four variants (original, mirrored, negated, mirrored-negated) of a smooth
rest-to-rest run of the off-square ropod at 200 Hz, noise-free and with 2¹⁴-count encoders and
30 mA current noise, each pushed twice by an external force the model does not know of (0.3 s,
ramped over 50 ms, at random times, in a random direction of the floor, with a torque of up
to a third of the force times 1 m), fits them with each method and prints, over the seeds, the
median and worst error of m_b and of the worst inertial parameter, the share of all parameters
within 2σ of the truth, and the fit's time against the plain fit's in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.params import is_inertial, thesis_fixed_masses
from ropod_sysid.platform import ropod_platform
from ropod_sysid.simulate import ForceSchedule, Sensors, Setpoints, simulate

OFF_SQUARE = np.array([[0.23, 0.20], [-0.19, 0.22], [-0.21, -0.18], [0.20, -0.23]])
METHODS = ("none", "huber", "bisquare")


def smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def variants(duration: float) -> list[Setpoints]:
    """Sinusoids under a C² envelope; sx negates the translations, sw mirrors."""
    t = np.arange(0.0, duration + 0.005, 0.01)
    env = smoothstep(t / 1.5) * smoothstep((duration - 0.5 - t) / 1.5)
    out = []
    for sx, sw in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        out.append(Setpoints(t, sx * env * (0.6 + 0.4 * np.sin(2 * np.pi * t / 6)),
                             sx * sw * 0.3 * np.sin(2 * np.pi * t / 8) * env,
                             sw * 0.8 * np.sin(2 * np.pi * t / 5) * env))
    return out


def pushes(rng: np.random.Generator, duration: float, force: float) -> ForceSchedule:
    t, f = [0.0], [np.zeros(3)]
    for t0 in np.sort(rng.uniform(2.0, duration - 3.0, 2)):
        angle = rng.uniform(0, 2 * np.pi)
        push = force * np.array([np.cos(angle), np.sin(angle), rng.uniform(-1, 1) / 3])
        t += [t0, t0 + 0.05, t0 + 0.25, t0 + 0.3]
        f += [np.zeros(3), push, push, np.zeros(3)]
    return ForceSchedule(np.array(t), np.array(f))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--force", type=float, nargs="+", default=[0.0, 20.0, 80.0])
    args = ap.parse_args()
    pf = ropod_platform().with_positions(OFF_SQUARE)
    truth = thesis_fixed_masses(pf.unit_names)
    runs = variants(args.seconds)
    print(f"{args.seeds} seeds × 4 runs of {args.seconds:g} s at 200 Hz, two 0.3 s pushes "
          "per run; errors: median / worst over the seeds")
    print(f"{'sensors':<9} {'push':>5} {'method':<9} {'m_b error':>16} {'worst inertial':>16} "
          f"{'within 2σ':>10} {'time':>6}")
    for noisy in (False, True):
        sensors = Sensors(encoder_counts=2**14, current_noise=0.03) if noisy else None
        for force in args.force:
            rows: dict[str, list[tuple[float, float, float, float]]] = {m: [] for m in METHODS}
            for seed in range(args.seeds):
                rng = np.random.default_rng(seed)
                logs = [simulate(pf, truth, [sp], force=pushes(rng, args.seconds, force),
                                 rate=200.0, sensors=sensors)[0].log for sp in runs]
                base = None
                for method in METHODS:
                    t0 = time.perf_counter()
                    sol = fit_logs(logs, pf, FitOptions(robust=method, recipe_check=False)).solution  # type: ignore[arg-type]
                    dt = time.perf_counter() - t0
                    base = dt if base is None else base
                    tv = np.array([truth[n] for n in sol.names])
                    rel = np.abs(sol.values / tv - 1.0)
                    inertial = [j for j, n in enumerate(sol.names) if is_inertial(n)]
                    rows[method].append((float(sol.values[0] / tv[0] - 1.0),
                                         float(rel[inertial].max()),
                                         float(np.mean(np.abs(sol.values - tv) < 2 * sol.std)),
                                         dt / base))
            for method in METHODS:
                a = np.array(rows[method])
                mb = np.abs(a[:, 0])
                print(f"{'noisy' if noisy else 'exact':<9} {force:>4g}N {method:<9} "
                      f"{100 * np.median(mb):>6.2f}% / {100 * mb.max():>5.2f}% "
                      f"{100 * np.median(a[:, 1]):>6.2f}% / {100 * a[:, 1].max():>5.1f}% "
                      f"{100 * a[:, 2].mean():>9.0f}% {np.median(a[:, 3]):>5.2f}×", flush=True)


if __name__ == "__main__":
    main()
