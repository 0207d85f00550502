#!/usr/bin/env python
"""Excitation that earns its name: ``trajectory optimize`` against the typical run.

    python benchmarks/excitation.py [--seconds 37] [--seeds 20] [--rate 100]

On the off-square ropod (pivots 1–3 cm off the square, every parameter identifiable), plans the
typical run (thesis Sec. VI-A) and an optimised one (``optimize``, objective ``sigma``, target
the inertial parameters, the default sensor model: 30 mA current noise, 2¹⁴-count encoders) of
the same duration within the same limits and floor; predicts the fit's σ and the encoders' bias
of both (``trajectory check`` with the same sensor model); simulates the four variants of each
once (1 ms RK4 under the speed loops) and records them with ``--seeds`` noise seeds of those
sensors at ``--rate`` (current noise, and each encoder's zero at a random place within a
count); fits every seed and prints, per inertial parameter, the predicted σ and bias, the mean
fitted σ, the mean and RMS error over the seeds and the share of seeds whose error is within 2
predicted σ of the predicted bias, and the same of fits with ``--encoder-counts`` (corrected
for the encoders' errors in A); then the ratios of the typical run's σ and errors to the
optimised run's (goal: at least 2×, judged on the corrected fits, whose σ match their errors:
the plain fits' jackknife σ also carry the encoders' errors in A, which vary from stretch to
stretch) and the optimiser's time. Last, ``fit``'s default (the recipe check): the σ
``trajectory check`` predicts for it (√(σ² + Δ²), Δ the shift on the run's exact logs), the
mean fitted σ and the share of seeds within 2 fitted σ.
"""


from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.noise import SensorNoise
from ropod_sysid.params import is_inertial, thesis_fixed_masses
from ropod_sysid.platform import ropod_platform
from ropod_sysid.simulate import Sensors, record, simulate
from ropod_sysid.trajectory import optimize, typical
from ropod_sysid.trajectory.precheck import check
from ropod_sysid.trajectory.run_variants import variants

OFF_SQUARE = np.array([[0.23, 0.20], [-0.19, 0.22], [-0.21, -0.18], [0.20, -0.23]])


def quantised(log, counts, rng):
    """The log's angles as encoders with ``counts`` per revolution read them, each encoder's
    zero at a random place within a count (a new one per seed: the quantisation error differs
    from robot to robot)."""
    if not counts:
        return log
    q = 2 * np.pi / counts
    offset = rng.uniform(0.0, q, log.angles.shape[1])
    return dataclasses.replace(log, angles=np.round((log.angles + offset) / q) * q - offset)


def measure(name, traj, platform, truth, sensors, seeds):
    rep = check(traj, platform, sensors=sensors, recipe=True)
    inert = [j for j, n in enumerate(rep.names) if is_inertial(n)]
    runs = simulate(platform, truth, [v.to_setpoints() for v in variants(traj).values()],
                    rate=sensors.log_rate)
    sens = Sensors(current_noise=sensors.current_noise)
    stds, errs, stds_c, errs_c, stds_k, errs_k = [], [], [], [], [], []
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        logs = [quantised(record(platform, r, r.log.t, sens, rng, f"{name}{k}"),
                          sensors.encoder_counts, rng) for k, r in enumerate(runs)]
        tv = np.array([truth[n] for n in rep.names])
        # σ as the optimiser and trajectory check predict it: the jackknife's, no recipe shift
        sol = fit_logs(logs, platform, FitOptions(recipe_check=False)).solution
        stds.append(sol.std)
        errs.append(sol.values - tv)
        sol = fit_logs(logs, platform, FitOptions(encoder_counts=sensors.encoder_counts,
                                                  recipe_check=False)).solution
        stds_c.append(sol.std)
        errs_c.append(sol.values - tv)
        # fit's default, the recipe check (trajectory check predicts its σ: the white-noise
        # σ and the shift on the run's exact logs)
        sol = fit_logs(logs, platform).solution
        stds_k.append(sol.std)
        errs_k.append(sol.values - tv)
    stds, errs = np.array(stds), np.array(errs)
    stds_c, errs_c = np.array(stds_c), np.array(errs_c)
    stds_k, errs_k = np.array(stds_k), np.array(errs_k)
    checked = rep.checked_std
    print(f"\n{name}: {traj.duration:g} s, condition number {rep.condition_number:.4g}, "
          f"peaks " + ", ".join(f"{k} {v:.2f}" for k, v in rep.peaks.items()))
    print(f"{'parameter':<10} {'true':>8} {'pred σ':>9} {'pred bias':>10} {'fit σ':>9} "
          f"{'mean err':>9} {'RMS err':>9} {'in 2σ':>6} | --encoder-counts: {'fit σ':>9} "
          f"{'mean err':>9} {'RMS err':>9} {'in 2fσ':>6} | the check: {'pred σ':>9} "
          f"{'fit σ':>9} {'in 2fσ':>6}")
    for j in inert:
        # within 2 predicted σ of the predicted bias; corrected: within 2 of its fitted σ
        within = np.mean(np.abs(errs[:, j] - rep.bias[j]) < 2 * rep.std[j])
        within_c = np.mean(np.abs(errs_c[:, j]) < 2 * stds_c[:, j])
        print(f"{rep.names[j]:<10} {rep.true_values[j]:>8.4g} {rep.std[j]:>9.3g} "
              f"{rep.bias[j]:>+10.3g} {stds[:, j].mean():>9.3g} {errs[:, j].mean():>+9.3g} "
              f"{np.sqrt(np.mean(errs[:, j] ** 2)):>9.3g} {100 * within:>5.0f}% | "
              f"{'':>17} {stds_c[:, j].mean():>9.3g} {errs_c[:, j].mean():>+9.3g} "
              f"{np.sqrt(np.mean(errs_c[:, j] ** 2)):>9.3g} {100 * within_c:>5.0f}% | "
              f"{'':>11}{checked[j]:>9.3g} {stds_k[:, j].mean():>9.3g} "
              f"{100 * np.mean(np.abs(errs_k[:, j]) < 2 * stds_k[:, j]):>5.0f}%")
    return rep, inert, stds, errs, stds_c, errs_c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=37.0)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--rate", type=float, default=100.0)
    args = ap.parse_args()
    platform = ropod_platform().with_positions(OFF_SQUARE)
    truth = thesis_fixed_masses(platform.unit_names)
    sensors = SensorNoise(0.03, 2**14, args.rate)
    t0 = time.perf_counter()
    opt = optimize(platform, args.seconds, objective="sigma", target="inertial",
                   sensors=sensors)
    t_opt = time.perf_counter() - t0
    print(f"sensor model: {sensors.describe()}; {args.seeds} noise seeds")
    rt, inert, st_t, er_t, sc_t, ec_t = measure("typical", typical(args.seconds,
                                                                   platform=platform),
                                                platform, truth, sensors, args.seeds)
    ro, _, st_o, er_o, sc_o, ec_o = measure("optimised", opt.trajectory, platform, truth,
                                            sensors, args.seeds)
    ratio_pred = rt.std[inert] / ro.std[inert]
    ratio_fit = st_t[:, inert].mean(axis=0) / st_o[:, inert].mean(axis=0)
    ratio_err = np.sqrt((er_t[:, inert] ** 2).mean(axis=0) / (er_o[:, inert] ** 2).mean(axis=0))
    print("\ntypical / optimised, per inertial parameter: predicted σ "
          + " ".join(f"{x:.2f}" for x in ratio_pred) + "; fitted σ "
          + " ".join(f"{x:.2f}" for x in ratio_fit) + "; RMS error "
          + " ".join(f"{x:.2f}" for x in ratio_err))
    rc_fit = sc_t[:, inert].mean(axis=0) / sc_o[:, inert].mean(axis=0)
    rc_err = np.sqrt((ec_t[:, inert] ** 2).mean(axis=0) / (ec_o[:, inert] ** 2).mean(axis=0))
    print("with --encoder-counts: fitted σ " + " ".join(f"{x:.2f}" for x in rc_fit)
          + "; RMS error " + " ".join(f"{x:.2f}" for x in rc_err))
    # the goal (issue 14): the optimised run's inertial σ at least 2× smaller. The plain fits'
    # jackknife σ carries the encoders' errors in A stretch by stretch (an error common to
    # the run, not noise), far above their own errors on the optimised run; the corrected
    # fits' σ are their errors' (the tables above), so the goal is judged on those.
    over = st_o[:, inert].mean(axis=0) / np.sqrt((er_o[:, inert] ** 2).mean(axis=0))
    print(f"goal ≥ 2: with --encoder-counts the smallest fitted-σ ratio is {rc_fit.min():.2f}"
          f" ({'met' if rc_fit.min() >= 2 else 'NOT met'}; RMS error ratios "
          f"{rc_err.min():.2f}–{rc_err.max():.2f}); plain fits {ratio_fit.min():.2f}, their "
          f"σ {over.min():.1f}–{over.max():.1f}× their RMS error on the optimised run")
    print(f"optimize took {t_opt:.1f} s ({opt.evaluations} candidates)")


if __name__ == "__main__":
    main()
