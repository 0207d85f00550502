#!/usr/bin/env python
"""The encoders' error gram ``fit --encoder-counts`` subtracts, against the measured one (issue 14).

    python benchmarks/counts.py steered-four [--logs 2] [--first 0] [--offsets] [--prototype]
    python benchmarks/counts.py ropod [--duration 60] [--rate 100] [--seed 0]
    python benchmarks/counts.py ropod-off [--duration 30] [--rate 1000] [--jitter 0.0005]

A shipped dataset of exact logs (steered-four, steered-swivel, legs-exact) is quantised to 2¹⁴
counts (:func:`ropod_sysid.simulate.sensed`, no current noise; ``--offsets``: with the
encoders' zeros at random; ``--jitter J``: the samples taken at instants jittered uniformly by
±J s, as the shipped ropod's, seed 2021) and both are preprocessed alike; the empirical
E[δAᵀδA] is the Gram matrix of the filtered rows' difference A_quantised − A_exact (the rows
the fit uses), the predicted one :func:`ropod_sysid.noise.fit_error_gram` at the quantised log
(or, with ``--prototype``, :func:`chain_gram`). Prints per row kind (x, y, θ with the units'
own rows) and inertial column the ratio predicted / empirical of the diagonal and of (E m)_j,
the column's share of the bias −(AᵀA)⁻¹ E m.

``ropod`` and ``ropod-off`` are simulated here instead, exact: the four variants of a
``trajectory typical`` run (``--duration``, ``--seed``) of the thesis's ropod (``ropod``: the
shipped sample's platform and truth, whose run is 60 s at 100 Hz) or of the off-square one
(attachment points of ``tests/conftest.py``), logged at ``--rate``. For these the bias of
each inertial value (of the combination a rank-deficient fit keeps) from the empirical and
the predicted gram is printed too, −(ÃᵀÃ)⁻¹ Ẽ m as a fraction of the value (:func:`bias`).

:func:`chain_gram` is the prototype of :func:`ropod_sysid.noise.recipe_error_gram` (which
``fit_error_gram`` now uses, to first order and about 20× faster): the error sources are each
encoder channel's rate and acceleration at the rows, carried through the fit's own recipe
(odometry twist, :meth:`PlatformModel.consistent_motion`, the held joints, the rows at rest,
a_id_ext) by central differences; a channel that moves less than a count per sample has the
variance of a sampled sawtooth (:func:`ropod_sysid.quantisation.sawtooth_share`), not the white one
times its counts per sample. About 10 s per 3000-row log (the library's: 0.6 s).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from ropod_sysid.io import Log  # noqa: E402
from ropod_sysid.model import PlatformModel  # noqa: E402
from ropod_sysid.noise import (  # noqa: E402
    SensorNoise,
    _encoders,
    acceleration_kernel,
    fit_error_gram,
    kind_grams,
    row_kernel,
    velocity_kernel,
)
from ropod_sysid.odometry import base_twist  # noqa: E402
from ropod_sysid.quantisation import encoder_variance, sawtooth_share  # noqa: E402
from ropod_sysid.regressor import (  # noqa: E402
    Preprocessed,
    at_rest,
    filtered_system,
    held_joints,
    preprocess,
    row_inputs,
)
from ropod_sysid.simulate import Sensors, sensed  # noqa: E402
from ropod_sysid.solve import kind_rows  # noqa: E402
from tests.conftest import shipped  # noqa: E402

COUNTS = 2**14


def odometry_motion(model: PlatformModel, q: np.ndarray, angles: np.ndarray, rates: np.ndarray,
                    accels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-frame q̇, q̈ (N, D) of the odometry twist ν = N(α) α̇ at the rows: q̈ from
    ν̇ = N α̈ + (∂ν/∂α) α̇ (the steering angles' rates turn the wheels' rolling rows) and the
    frame's rotation ω × ν; the own coordinates' rates and accelerations as measured."""
    nu = base_twist(model, angles, rates)
    eps = 1e-6
    nud = base_twist(model, angles, accels) + (
        base_twist(model, angles + eps * rates, rates)
        - base_twist(model, angles - eps * rates, rates)) / (2 * eps)
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    own = np.asarray(model.coordinate_channels, int)
    ax, ay = nud[:, 0] - nu[:, 2] * nu[:, 1], nud[:, 1] + nu[:, 2] * nu[:, 0]
    qd = np.column_stack([c * nu[:, 0] - s * nu[:, 1], s * nu[:, 0] + c * nu[:, 1], nu[:, 2],
                          rates[:, own]])
    qdd = np.column_stack([c * ax - s * ay, s * ax + c * ay, nud[:, 2], accels[:, own]])
    return qd, qdd


def chain_gram(model: PlatformModel, pre: Preprocessed, index: np.ndarray, counts: int,
               friction: str = "per-wheel") -> np.ndarray:
    """E[δAᵀδA] (3, p, p) of the rows at ``index``: each encoder channel's rate and
    acceleration errors (uncorrelated: odd and even kernels) carried through the fit's recipe by
    central differences (module docstring)."""
    rows = row_inputs(pre, index)
    noise = SensorNoise(0.0, counts, 1.0 / pre.dt, span=pre.span_samples * pre.dt,
                        row_step=pre.grid.step, degree=pre.degree)
    n, j = rows.angles.shape
    held = (held_joints(model, rows.angle_rates[:, model.coordinate_channels])
            if model.n_dof > 3 else None)
    rest = at_rest(rows)
    zero = np.zeros((n, j))
    qd0, qdd0 = odometry_motion(model, rows.q, rows.angles, rows.angle_rates, zero)
    qd_meas = qd0.copy()
    qd_meas[:, :3] = rows.qd

    def a_at(rates: np.ndarray, accels: np.ndarray) -> np.ndarray:
        qd, qdd = odometry_motion(model, rows.q, rows.angles, rates, accels)
        st = model.state(rows.q, (qd_meas + qd - qd0)[:, :3], rows.angles, rates)
        st, qdd_c = model.consistent_motion(st, rows.qdd + qdd - qdd0)
        st.held = held
        a = model.a_id_ext(st, qdd_c, friction)  # type: ignore[arg-type]
        a[rest] = 0.0
        return a

    cps = rows.angle_rates * pre.dt / (2.0 * math.pi / counts)
    a_k, var = [], []
    for order, kernel in ((1, velocity_kernel(noise.k, noise.dt, noise.degree)),
                          (2, acceleration_kernel(noise.k, noise.dt, noise.degree))):
        full = row_kernel(noise.grid, kernel)
        s2 = encoder_variance(counts) * np.sum(full**2) * sawtooth_share(full, cps)
        for ch in np.flatnonzero(_encoders(model, j)):
            h = np.zeros((n, j))
            h[:, ch] = 1e-6 if order == 1 else 1e-4
            if order == 1:
                d = a_at(rows.angle_rates + h, zero) - a_at(rows.angle_rates - h, zero)
            else:
                d = a_at(rows.angle_rates, h) - a_at(rows.angle_rates, -h)
            a_k.append(d / (2 * h[0, ch]))
            var.append(s2[:, ch])
    w = np.stack(a_k, axis=1) * np.sqrt(np.stack(var, axis=1))[:, :, None, None]
    per_dof = np.einsum("nkdp,nkdq->dpq", w, w)
    return kind_grams(per_dof)


def quantised(log: Log, platform: object, rng: np.random.Generator | None,
              jitter: float = 0.0) -> Log:
    """The log's angles as 2¹⁴-count encoders record them (``jitter``: at instants jittered
    by ±jitter s, as :func:`sensed`, seed 2021); with ``rng`` their zeros at random."""
    if jitter > 0:
        return sensed(log, platform, Sensors(encoder_counts=COUNTS, jitter=jitter),  # type: ignore[arg-type]
                      np.random.default_rng(2021))
    if rng is None:
        return sensed(log, platform, Sensors(encoder_counts=COUNTS), np.random.default_rng(0))  # type: ignore[arg-type]
    step = 2 * np.pi / COUNTS
    enc = np.asarray(platform.layout.encoders, bool)  # type: ignore[attr-defined]
    off = rng.uniform(0.0, step, log.angles.shape[1])
    a = log.angles.copy()
    a[:, enc] = np.round((a[:, enc] + off[enc]) / step) * step - off[enc]
    return Log(log.t, log.layout, a, log.currents, None, log.source, [])


def simulated(name: str, duration: float, rate: float, seed: int
              ) -> tuple[object, object, list[Log]]:
    """The exact logs of the four variants of a typical run of the ropod (``ropod``: the
    shipped sample's; ``ropod-off``: attachment points off the square)."""
    from ropod_sysid.params import thesis_fixed_masses
    from ropod_sysid.platform import ropod_platform
    from ropod_sysid.simulate import simulate
    from ropod_sysid.trajectory import typical, variants
    from tests.conftest import OFF_SQUARE

    platform = ropod_platform()
    if name == "ropod-off":
        platform = platform.with_positions(OFF_SQUARE)
    truth = thesis_fixed_masses(platform.unit_names)
    runs = variants(typical(duration=duration, platform=platform, seed=seed))
    res = simulate(platform, truth, [tr.to_setpoints() for tr in runs.values()], rate=rate)
    return platform, truth, [r.log for r in res]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("--logs", type=int, default=99, help="at most this many logs")
    ap.add_argument("--first", type=int, default=0, help="from this log on (name order)")
    ap.add_argument("--offsets", action="store_true", help="the encoders' zeros at random")
    ap.add_argument("--prototype", action="store_true", help="predict by chain_gram")
    ap.add_argument("--duration", type=float, default=60.0, help="ropod*: the run [s]")
    ap.add_argument("--rate", type=float, default=100.0, help="ropod*: the log rate [Hz]")
    ap.add_argument("--seed", type=int, default=0, help="ropod*: the typical run's seed")
    ap.add_argument("--jitter", type=float, default=0.0,
                    help="sample instants jittered by ± this [s] (the shipped ropod: 0.0005)")
    args = ap.parse_args()
    if args.dataset.startswith("ropod"):
        platform, truth, logs = simulated(args.dataset, args.duration, args.rate, args.seed)
    else:
        platform, truth, logs = shipped(args.dataset)
    logs = logs[args.first: args.first + args.logs]
    model = PlatformModel(platform)
    names = model.parameter_names()
    m = truth.vector(names)
    p = len(names)
    emp, cross, pred = np.zeros((3, p, p)), np.zeros((3, p)), np.zeros((3, p, p))
    ata, per_row = np.zeros((3, p, p)), np.zeros(3)
    rng = np.random.default_rng(1) if args.offsets else None
    start = time.perf_counter()
    for log in logs:
        pre_e = preprocess(log, platform)
        a_e, _ = filtered_system(model, pre_e)
        pre = preprocess(quantised(log, platform, rng, args.jitter), platform)
        a_q, _ = filtered_system(model, pre)
        for d in range(3):
            x = kind_rows(a_q - a_e, d)
            emp[d] += x.T @ x
            cross[d] += x.T @ (x @ m)
            y = kind_rows(a_e, d)
            ata[d] += y.T @ y
            per_row[d] = (kind_rows(np.zeros((1,) + a_e.shape[1:]), d)).shape[0]
        gram = chain_gram if args.prototype else fit_error_gram
        pred += gram(model, pre, pre.row_samples(), COUNTS)
    print(f"{args.dataset}: {len(logs)} logs, {'prototype' if args.prototype else 'library'} "
          f"gram, zeros {'at random' if args.offsets else 'at 0'}, "
          f"{f'jitter ±{args.jitter * 1e3:g} ms, ' if args.jitter else ''}"
          f"{time.perf_counter() - start:.0f} s; predicted / empirical: diagonal, (E m)_j")
    inertial = [j for j, n in enumerate(names) if n.startswith(("m_", "J"))]
    for d, kind in enumerate(("x", "y", "θ+own")):
        cells = [f"{names[j]} {pred[d, j, j] / emp[d, j, j]:.2f}, "
                 f"{(pred[d, j] @ m) / cross[d, j]:.2f}"
                 for j in inertial if emp[d, j, j] > 0]
        print(f"  {kind:6s} " + "; ".join(cells))
    if args.dataset.startswith("ropod"):
        print("  bias −(ÃᵀÃ)⁻¹ Ẽ m / value, empirical → predicted (θ rows weighted as the fit):")
        print("  " + "; ".join(f"{names[j]} {e:+.2%} → {q:+.2%}" for j, e, q in
                               zip(inertial, *(bias(ata, g, m, per_row)[inertial]
                                               for g in (emp, pred)), strict=True)))


def bias(ata: np.ndarray, gram: np.ndarray, m: np.ndarray, per_row: np.ndarray) -> np.ndarray:
    """−(ÃᵀÃ)⁻¹ Ẽ m (p,) over the value (as the fit keeps it: on a rank-deficient problem the
    last column of each dependent set dropped, and each kept value the combination
    (Ã_bᵀÃ_b)⁻¹ Ã_bᵀ Ã m), the kinds' grams (3, p, p) summed with the θ kind weighted by
    Sec. VI-A's w (of the exact rows' b = A m: w² = ½ (mean b_x² + mean b_y²) / mean b_θ², the
    kinds having ``per_row`` rows per sample); nan for a dropped column."""
    bx, by, bt = (float(m @ ata[d] @ m) / per_row[d] for d in range(3))
    w2 = 0.5 * (bx + by) / bt
    a = ata[0] + ata[1] + w2 * ata[2]
    e = gram[0] + gram[1] + w2 * gram[2]
    scale = 1.0 / np.sqrt(np.maximum(np.diag(a), 1e-300))

    def rank(cols: list[int]) -> int:
        sub = a[np.ix_(cols, cols)] * np.outer(scale[cols], scale[cols])
        ev = np.linalg.eigvalsh(sub)
        return int(np.sum(ev > 1e-9 * ev.max()))

    keep = list(range(len(m)))
    while rank(keep) < len(keep):
        keep.remove(next(c for c in reversed(keep) if rank([k for k in keep if k != c])
                         == rank(keep)))
    out = np.full(len(m), np.nan)
    ab = a[np.ix_(keep, keep)]
    value = np.linalg.solve(ab, (a @ m)[keep])
    out[keep] = -np.linalg.solve(ab, (e @ m)[keep]) / value
    return out


if __name__ == "__main__":
    main()
