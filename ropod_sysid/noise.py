"""What sensor noise does to a fit: predicted before a run, and corrected in the fit.

A fit's white-noise standard deviations (:func:`ropod_sysid.solve.solve`) are
σ̂ √(c diag((ÃᵀÃ)⁻¹)): Ã the equation rows with the θ rows weighted by w (Sec. VI-A), σ̂² their
residual variance and c the rows per independent row after the rows' LOESS
(:attr:`ropod_sysid.regressor.RowGrid.correlation`). Along a planned run the rows follow from the
planned motion (:func:`ropod_sysid.trajectory.precheck.stacked_regressor`) and w from the
predicted b_ID = A_ID,ext m; σ̂² follows from the sensors, traced through the same recipe
(Sec. VI-B) the fit applies to a log:

* **current noise** σ_i [A], white per sample: the torque of actuator a is k_t,a i_a, so b_ID
  of a row carries B_τ diag(k_t² σ_i²) B_τᵀ, through the torque average over the row step and the
  rows' LOESS (kernel g_τ: :func:`row_kernel`);
* **encoder quantisation**, 2π/counts per count, uniform: σ_φ² = (2π/counts)² / 12 per angle and
  sample while the angle moves a count per sample or more (a slower angle steps rarely: its
  error is a sampled sawtooth, :func:`sawtooth_share`; in a fit, every angle's error is the
  sawtooth of its motion through the row's window, :func:`tone_share`; both in
  :mod:`ropod_sysid.quantisation`). The angles are smoothed
  (LOESS of k samples) and differenced (odd kernel to φ̇, even to φ̈: uncorrelated), the pose
  follows by odometry (the base displacement is G Δφ, G = (CᵀC)⁻¹ Cᵀ D from the units'
  constraint rows C ν = D φ̇), and each channel's rate and acceleration errors reach the rows
  through the fit's own recipe (:func:`recipe_sensitivities`: odometry's q̇ and q̈ including the
  steering rates' term, the projection onto the allowed motions, the held joints, the
  identification projector, the rows at rest), then pass the rows' LOESS with them. A row's
  error is δA m; its variance Σ_s (W_s m)² over the sources s.

Both are white per sample before the filters, so a row carries σ² ‖g‖² of each, g the whole
kernel from the samples to the row. σ̂² is the mean over rows and DOFs of the weighted
variances; the fit's c is 1/Σh_r² of the rows' kernel h_r.

The errors of q̈ and of the measured rates also sit in A_ID,ext itself (errors in the
variables), and a least-squares fit shrinks the columns they blur:
E[m̂ − m] ≈ −(ÃᵀÃ + E[δÃᵀδÃ])⁻¹ E[δÃᵀδÃ] m. E[δAᵀδA] = Σ_s W_sᵀ W_s is formed once, by
:func:`recipe_error_gram`, for both sides: what ``fit --encoder-counts`` subtracts from a log's
normal equations (:func:`fit_error_gram`) and what ``trajectory check`` and ``optimize`` predict
for a planned run (:func:`planned_rows`: the same recipe at the planned states; on the same rows
and given the same motion through the rows' windows, :func:`window_motion`, whose
:func:`tone_share` the fit takes for each channel, the two grams are equal; a planned run
without it takes each channel's share from its rows' rates, :func:`sawtooth_share`). Measured
against the quantised − exact rows of steered-swivel and legs-exact, its inertial columns'
diagonals agree within 0.8–1.1 (the legs' J_st 0.5–0.65, cause not found); the base rows'
variance of δA m on steered-swivel within 0.77–0.84 (the steering rows' 0.12–0.24, cause not
found). Through the swivel's caster offset the pivots' acceleration carries q̈ / d, so the
unit-inertia columns carry q̈'s errors a hundredfold: this bias, not σ, limits a run that a
white-noise criterion calls excellent. It does not shrink with the run's length. (Measured,
20 seeds: on the 37 s typical and optimised runs of the off-square ropod the predicted and the
fits' mean errors agree within 1–7 %; on the 30 s typical run they do not — −1.8 kg predicted
for m_b, +0.7 ± 0.3 kg fitted — for a reason not found.) The errors of A's angle-dependent
columns are second order and left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

import numpy as np

from ropod_sysid import signals
from ropod_sysid.errors import InputError
from ropod_sysid.quantisation import encoder_variance, sawtooth_share, tone_share, window_motion
from ropod_sysid.recipe import DEFAULT_SPAN_S, RowGrid

if TYPE_CHECKING:
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.params import Friction
    from ropod_sysid.regressor import Preprocessed
    from ropod_sysid.solve import Solution

__all__ = ["MotionRows", "SensorNoise", "encoder_variance", "fit_error_gram", "planned_rows",
           "predicted_fit_std", "recipe_error_gram", "row_kernel", "row_variances",
           "search_gram_stride", "sigma_hat"]


@dataclass(frozen=True)
class SensorNoise:
    """The sensors of the logs a planned run will give, and how the fit will treat them.

    current_noise : σ of each motor-current sample [A]
    encoder_counts : counts per revolution of wheel and turning-joint encoders (None: exact)
    log_rate : sample rate of the logs [Hz]
    span : the fit's LOESS span [s] (``--span``; 0.1 s by default)
    row_step : samples between equation rows (``--row-step``; None: the fit's default)
    degree : the fit's smoother (``--smoother``): 2 LOESS and three-point differences, 4 the
        local quartic and five-point differences
    jitter : half-width of a uniform jitter of the sample instants [samples]
        (:func:`ropod_sysid.io.timebase.grid_jitter`; for :func:`tone_share`)
    tone_nodes : :func:`tone_share`'s nodes per lag (None: :func:`tone_nodes` of the kernel)
    """

    current_noise: float = 0.03
    encoder_counts: int | None = 2**14
    log_rate: float = 100.0
    span: float = DEFAULT_SPAN_S
    row_step: int | None = None
    degree: int = 2
    jitter: float = 0.0
    tone_nodes: int | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.current_noise) and self.current_noise >= 0):
            raise InputError(f"--current-noise {self.current_noise:g}: give σ in A, ≥ 0")
        if self.encoder_counts is not None and (int(self.encoder_counts) != self.encoder_counts
                                                or self.encoder_counts < 16):
            raise InputError(f"--encoder-counts {self.encoder_counts!r}: give a whole number "
                             "of counts per revolution, at least 16")
        if not (math.isfinite(self.log_rate) and self.log_rate > 0):
            raise InputError(f"--log-rate {self.log_rate:g}: give the logs' rate in Hz, > 0")
        if not (math.isfinite(self.span) and self.span > 0):
            raise InputError(f"span {self.span!r}: give the fit's LOESS span in s, > 0")
        if self.current_noise == 0 and self.encoder_counts is None:
            raise InputError("no sensor noise (current noise 0 A, exact encoders): the "
                             "predicted standard deviations would all be 0; give "
                             "--current-noise or --encoder-counts")

    @property
    def dt(self) -> float:
        return 1.0 / self.log_rate

    @property
    def k(self) -> int:
        """The LOESS span in samples at the log rate (as ``Span.samples``)."""
        k = max(int(round(self.span / self.dt)), 3)
        return k if k % 2 else k + 1

    @property
    def grid(self) -> RowGrid:
        return RowGrid.for_span(self.k, self.row_step, self.degree)

    @property
    def rows_per_second(self) -> float:
        """Equation rows per second of log."""
        return self.log_rate / self.grid.step

    def describe(self) -> str:
        enc = (f"{self.encoder_counts}-count encoders" if self.encoder_counts is not None
               else "exact encoders")
        return (f"{self.current_noise:g} A current noise, {enc}, {self.log_rate:g} Hz logs, "
                f"span {self.span:g} s, a row every {self.grid.step} sample(s)")


def row_kernel(grid: RowGrid, sample_kernel: np.ndarray) -> np.ndarray:
    """The kernel from white per-sample noise to one equation row: ``sample_kernel`` (what the
    recipe does per sample), sampled at the row step and then filtered by the rows' LOESS
    (the rows' kernel h_r spread over ``step`` samples)."""
    h_r = signals.loess_kernel(grid.span) if grid.span > 3 else np.array([1.0])
    spread = np.zeros((h_r.size - 1) * grid.step + 1)
    spread[::grid.step] = h_r
    return np.convolve(spread, sample_kernel)


def current_kernel(grid: RowGrid) -> np.ndarray:
    """Per-sample kernel of a row's torque: :attr:`RowGrid.torque_kernel` (the mean over
    2⌊step/2⌋ + 1 samples; after the quartic smoother least-norm weights over 2·step + 1
    samples)."""
    return grid.torque_kernel


def difference_kernel(dt: float, degree: int = 2) -> np.ndarray:
    """Convolution kernel [1/s] of the first differences after the smoother of ``degree``:
    three-point central (2), five-point (4) (:func:`ropod_sysid.regressor.difference`)."""
    if degree == 2:
        return np.array([0.5, 0.0, -0.5]) / dt
    return np.array([-1.0, 8.0, 0.0, -8.0, 1.0]) / (12.0 * dt)


def acceleration_kernel(k: int, dt: float, degree: int = 2) -> np.ndarray:
    """Per-sample kernel from an angle's error to its contribution to q̈ [1/s²]: the LOESS of
    ``k`` samples (of ``degree``) and two differences."""
    cd = difference_kernel(dt, degree)
    return np.convolve(np.convolve(signals.loess_kernel(k, degree), cd), cd)


def channel_variances(noise: SensorNoise, rates: np.ndarray, order: int,
                      window_motion: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Variance (N, J) of each angle channel's rate (``order`` 1) or acceleration (2) error at
    the rows from quantisation: σ_φ² ‖g‖² of the whole kernel g to a row
    (:func:`velocity_kernel` or :func:`acceleration_kernel` and the rows' LOESS) times the
    :func:`sawtooth_share` of a channel moving |φ̇| dt / step counts per sample; or, with
    ``window_motion`` (rates [rad/s], accelerations [rad/s²], each (N, J): the channels'
    motion through the row's window, :func:`window_motion`), the :func:`tone_share` of that
    motion."""
    kernel = (velocity_kernel if order == 1 else acceleration_kernel)(noise.k, noise.dt,
                                                                     noise.degree)
    full = row_kernel(noise.grid, kernel)
    assert noise.encoder_counts is not None  # (the callers' encoder channels)
    counts = int(noise.encoder_counts)
    step = 2.0 * math.pi / counts
    white = encoder_variance(counts) * float(np.sum(full**2))
    if window_motion is not None:
        rate, accel = window_motion
        return white * tone_share(full, rate * noise.dt / step, accel * noise.dt**2 / step,
                                  noise.jitter, noise.tone_nodes)
    cps = np.abs(rates) * noise.dt / step
    return white * sawtooth_share(full, cps)


def velocity_kernel(k: int, dt: float, degree: int = 2) -> np.ndarray:
    """Per-sample kernel from an angle's error to its contribution to q̇ [1/s]: the LOESS of
    ``k`` samples (of ``degree``) and one difference. (It is odd where
    :func:`acceleration_kernel` is even: the errors of q̇ and q̈ of a row are uncorrelated.)"""
    return np.convolve(signals.loess_kernel(k, degree), difference_kernel(dt, degree))


def _encoders(model: PlatformModel, n_angles: int) -> np.ndarray:
    """(J,) bool: the platform's rotary-encoder channels (:attr:`Layout.encoders`)."""
    layout = getattr(model, "layout", None)
    return np.ones(n_angles, bool) if layout is None else np.asarray(layout.encoders, bool)


def measured_rate_channels(model: PlatformModel, st: object, qdd: np.ndarray,
                           friction: Friction) -> list[int]:
    """The angle channels whose measured rate A_ID,ext depends on (the unit types that use
    measured rates: the swivel's pivots), found on a few rows."""
    few = min(8, st.q.shape[0])  # type: ignore[attr-defined]
    q, qd, ang = st.q[:few], st.qd[:few], st.angles[:few]  # type: ignore[attr-defined]
    rates = st.angle_rate[:few]  # type: ignore[attr-defined]
    base = model.a_id_ext(model.state(q, qd, ang, rates), qdd[:few], friction)
    j = rates.shape[1]
    moved = np.tile(rates, (j, 1)).reshape(j, few, j)  # each channel's rate moved, stacked
    moved[np.arange(j), :, np.arange(j)] += 1.0
    a = model.a_id_ext(model.state(np.tile(q, (j, 1)), np.tile(qd, (j, 1)),
                                   np.tile(ang, (j, 1)), moved.reshape(j * few, j)),
                       np.tile(qdd[:few], (j, 1)), friction)
    changed = (a.reshape(j, few, -1) != base.reshape(1, few, -1)).any(axis=(1, 2))
    return np.flatnonzero(changed).tolist()


def row_variances(model: PlatformModel, rows: Preprocessed | MotionRows, params: object,
                  noise: SensorNoise, friction: Friction = "per-wheel",
                  encoder: np.ndarray | None = None) -> np.ndarray:
    """Variance (N, D) [N², N², (N m)², …] of each DOF of the equation rows ``rows``
    (:class:`MotionRows`, e.g. :func:`planned_rows`) under ``noise``: current noise through
    B_τ, the torque average and the rows' LOESS (module docstring; zero on the own rows of a
    held joint, which the fit locks), and the encoders' share, the variance of the rows' error
    δA m through the fit's recipe (:func:`recipe_error_gram`; ``encoder`` (N, D) when already
    formed). ``params`` the true values (:class:`~ropod_sysid.params.DynamicParameters`)."""
    from ropod_sysid.regressor import held_joints

    st = model.state(rows.q, rows.qd, rows.angles, rows.angle_rates)
    b_tau = st.b_tau
    out: np.ndarray = np.zeros(b_tau.shape[:2])  # (N, D)
    if noise.current_noise > 0:
        grid = noise.grid
        k_t = model.platform.torque_constants()
        power = float(np.sum(row_kernel(grid, current_kernel(grid)) ** 2))
        out += np.einsum("nda,a->nd", b_tau**2, (k_t * noise.current_noise) ** 2) * power
        if out.shape[1] > 3:  # the fit locks a held joint: its own rows are zero
            own = model.coordinate_channels
            out[:, 3:][held_joints(model, rows.angle_rates[:, own])] = 0.0
    if noise.encoder_counts is not None:
        if encoder is None:
            truth = params.vector(model.parameter_names(friction))  # type: ignore[attr-defined]
            encoder = recipe_error_gram(model, rows, noise, friction, truth)[1]
        assert encoder is not None  # recipe_error_gram gives the variances with truth
        out += encoder
    return out


def sigma_hat(variances: np.ndarray, w_rot: float) -> float:
    """σ̂ of the fit's weighted rows: √ of the mean over rows and DOFs of the variances
    (N, D), the θ rows and the units' own rows weighted by ``w_rot``."""
    v = variances.mean(axis=0)
    return float(np.sqrt((v[0] + v[1] + w_rot**2 * v[2:].sum()) / v.size))


def rotation_weight(b: np.ndarray) -> float:
    """Sec. VI-A's weight of the θ rows for rows b_ID (N, 3) (as
    :meth:`ropod_sysid.solve.Triangles.rotation_weight`)."""
    ms = np.mean(b**2, axis=0)
    rot = float(ms[2:].mean())  # the θ rows with the units' own rows (one kind)
    return float(np.sqrt(0.5 * (ms[0] + ms[1]) / rot)) if rot > 0 else 1.0


def predicted_solution(a: np.ndarray, truth: np.ndarray, names: list[str] | None = None
                       ) -> Solution:
    """The fit's solution (:func:`ropod_sysid.solve.solve`) of noise-free rows ``a`` (M, D, p)
    whose b_ID is A m for the values ``truth`` (p,): its rank, the columns it keeps and the
    combinations it names (``names``, default p0, p1, …)."""
    from ropod_sysid.solve import gram_triangle, solve

    rows = a.reshape(-1, a.shape[-1])
    ab = np.column_stack([rows, rows @ truth])
    return solve(gram_triangle(ab.T @ ab), rows.shape[0],
                 names or [f"p{j}" for j in range(rows.shape[1])])


def base_columns(a: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The columns of rows ``a`` (M, D, p) a fit keeps (:func:`ropod_sysid.solve.solve`): all
    of them, or on a rank-deficient problem the base of each identifiable combination."""
    sol = predicted_solution(a, truth)
    return np.flatnonzero(np.isfinite(sol.std_white))


def predicted_fit_std(a: np.ndarray, variances: np.ndarray, truth: np.ndarray,
                      noise: SensorNoise, rows_per_eval: float,
                      error_gram: np.ndarray | None = None,
                      ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """The white-noise standard deviations (p,) a fit of the rows will report, as the fit forms
    them: σ̂ √(c diag((ÃᵀÃ)⁻¹)) on the fit's columns (:func:`base_columns`: on a rank-deficient
    problem a combination's σ for its base parameter, inf for the dependent ones); and the bias
    (p,) the errors of q̈ in A_ID,ext give the fit, −(ÃᵀÃ + E[δÃᵀδÃ])⁻¹ E[δÃᵀδÃ] m
    (:func:`recipe_error_gram`; zero without it, nan outside the identifiable subspace).

    a : (M, 3, p) rows at the evaluation samples, each standing for ``rows_per_eval`` of the
    fit's rows; variances : (M, 3) their variances (:func:`row_variances`); truth : (p,) the
    values that give the predicted b_ID = A m (for the rotation weight); error_gram : (3, p, p)
    over the M rows. Returns the standard deviations, the bias, σ̂ and the rotation weight.
    """
    from ropod_sysid.trajectory.identifiability import predicted_std

    w_rot = rotation_weight(np.einsum("mdp,p->md", a, truth))
    moving = np.abs(a).sum(axis=(1, 2)) > 0  # the fit leaves out the rows at rest
    s = sigma_hat(variances[moving] if moving.any() else variances, w_rot)
    std = predicted_std(a, (s, s / w_rot), rows_per_second=rows_per_eval)
    if not np.isfinite(std).all():
        # as the fit: the dependent parameters of a combination set to 0, the others (its
        # base) standing for the identifiable combinations, with their σ
        cols = base_columns(a, truth)
        std = np.full_like(truth, np.inf)
        std[cols] = predicted_std(a[..., cols], (s, s / w_rot), rows_per_second=rows_per_eval)
    bias = np.zeros_like(truth)
    if error_gram is not None:
        inside = np.isfinite(std)
        aw = a.copy()
        aw[:, 2:] *= w_rot
        flat = aw.reshape(-1, a.shape[-1])[:, inside]
        err = (error_gram[0] + error_gram[1] + w_rot**2 * error_gram[2])
        e_in = err[np.ix_(inside, inside)]
        bias = np.full_like(truth, np.nan)
        bias[inside] = -np.linalg.solve(flat.T @ flat + e_in, (err @ truth)[inside])
    return std * math.sqrt(noise.grid.correlation), bias, s, w_rot


GRAM_ROWS_PER_SPAN = 3  # rows per smoother span at which fit_error_gram evaluates the gram


def gram_stride(span_rows: int) -> int:
    """Every how many equation rows :func:`fit_error_gram` evaluates the error gram: about
    :data:`GRAM_ROWS_PER_SPAN` rows per smoother span of ``span_rows`` rows (1 below 6 rows).

    A row's share of the gram varies with the smoothed motion, slowly on the scale of a span,
    so every third row of an 11-row span, weighted three times, gives the same corrected fit:
    on the shipped ropod, omni, steered, steered-four and legs samples every value moved by at
    most 0.031σ (median 0.002σ) at strides 3 and 4 whichever row they started at, against up
    to 1.07σ at stride 6 (a Coulomb column's tanh is steep where a rate crosses zero, and a
    row there can carry 60 % of its gram)."""
    return max(1, int(span_rows) // GRAM_ROWS_PER_SPAN)


# fit --encoder-counts: the gram on every gram_stride-th row for a log's first this-many gram
# rows (a minute at 100 Hz or at 1 kHz), then on every SEARCH_GRAM_LATER-th of those, each
# weighted so (fit_error_gram's sparse_after). A long log's gram is a sum over many rows of a
# function of the motion; its later rows sampled 4x sparser moved every value of a 10-minute
# 1 kHz log's corrected fit (ten recordings of one 60 s run, benchmarks/longlog.py's) by at most
# 0.11σ (median 0.04σ) and took the fit from 4.1 to 1.9 s in process (the command 4.25 to
# 2.1–2.2 s; plain 1.1 s); logs of up to 2,000 gram rows, the
# shipped samples', are untouched
FIT_GRAM_DENSE = 2000
# the delay search's gram of counts detected in a log (not given): on every this-many-th of the
# rows the fit's gram uses (search_gram_stride) ...
SEARCH_GRAM_SPARSER = 4
# ... for a log's first this-many gram rows, then on every SEARCH_GRAM_LATER-th of those
SEARCH_GRAM_DENSE = 2000
SEARCH_GRAM_LATER = 4
# ... and with tone_share's nodes per lag this many (the fit's: tone_nodes of the kernel)
SEARCH_TONE_NODES = 1


def search_gram_stride(span_rows: int) -> int:
    """Every how many equation rows the delay search (``--input-delay auto`` without
    ``--encoder-counts``) evaluates the error gram of the counts it detected in a log
    (:func:`detect_encoder_counts`): :data:`SEARCH_GRAM_SPARSER` × :func:`gram_stride`, about
    one row per smoother span, for the first :data:`SEARCH_GRAM_DENSE` gram rows of a log (4
    minutes at 1 kHz or at the shipped sample's 100 Hz), then :data:`SEARCH_GRAM_LATER` times
    sparser (:func:`fit_error_gram`'s ``sparse_after``), each with :data:`SEARCH_TONE_NODES`
    node per lag in :func:`tone_share`. The search's criterion needs E only where it moves the
    residual with the delay, and the fit at the delay found is not corrected.

    Measured against ``--encoder-counts 16384`` (the fit's stride and nodes): the delay found
    within 0.02 ms on the shipped ropod, omni, steered and legs samples and on
    ``benchmarks/bias.py``'s off-square runs at 100 / 200 / 1000 Hz, unshifted and shifted
    5 ms (``--part delay``: +0.38 / +0.49 / +0.46 and +5.26 / +5.49 / +5.46 ms against +0.39 /
    +0.50 / +0.47 and +5.27 / +5.50 / +5.47 ms; with the fit's nodes here +0.40 / +0.50 /
    +0.46 and +5.28 / +5.50 / +5.46 ms); on ``benchmarks/run.py``'s 10-minute 1 kHz log
    +0.330 ms with one node (+0.340 ms with the kernel's three), +0.322 and +0.345 ms with
    every row 2× and 4× sparser. One node per lag took the search's gram on that log from
    0.84 to 0.50 CPU-s (at 1 kHz :func:`tone_share` was 62 % of it), the later rows' sparser
    stride 0.50 to about 0.3. Where the corrected residual is nearly all the encoders' share
    (``benchmarks/delay.py``'s 1 kHz runs: ρ² at the best node 1/1.9 and 1/23 of its
    neighbours') the criterion hangs on E's last percent, and the delay found moves by tenths
    of a millisecond and more with the stride and nodes: there +1.60 ms with the kernel's
    nodes, +1.75 ms with one."""
    return SEARCH_GRAM_SPARSER * gram_stride(span_rows)


def fit_error_gram(model: PlatformModel, pre: Preprocessed, index: np.ndarray, encoder_counts: int,
                   friction: Friction = "per-wheel", first_row: int = 0,
                   stride: int | None = None, tone_nodes: int | None = None,
                   sparse_after: int | None = None) -> np.ndarray:
    """E[δAᵀδA] (3, p, p) of the equation rows at samples ``index`` of a preprocessed block
    ``pre`` (:class:`ropod_sysid.regressor.Preprocessed`) for encoders of ``encoder_counts``
    per revolution: what ``fit --encoder-counts`` subtracts from the normal equations
    (corrected least squares). The errors are carried through the fit's own recipe
    (:func:`recipe_error_gram`) at every ``stride``-th row of the log (default
    :func:`gram_stride` of the rows' span; ``first_row``: the log's row number of
    ``index[0]``, so that blocks streamed in chunks pick the rows of the whole log), each
    weighted ``stride``; from the log's row ``sparse_after`` on (None: never) at every
    :data:`SEARCH_GRAM_LATER` × ``stride``-th row, each weighted so; each channel's
    quantisation error as the sawtooth of its motion through the row's window
    (:func:`tone_share`, :func:`window_motion`); ``tone_nodes``: :class:`SensorNoise`'s."""
    noise = SensorNoise(0.0, encoder_counts, 1.0 / pre.dt, span=pre.span_samples * pre.dt,
                        row_step=pre.grid.step, degree=pre.degree,
                        jitter=float(getattr(pre, "jitter", 0.0)), tone_nodes=tone_nodes)
    index = np.asarray(index)
    stride = gram_stride(pre.grid.span) if stride is None else max(1, int(stride))
    row = first_row + np.arange(index.size)
    later = np.zeros(index.size, bool) if sparse_after is None else row >= sparse_after
    sparse = SEARCH_GRAM_LATER * stride
    p = len(model.parameter_names(friction))
    out = np.zeros((3, p, p))
    for rows, every, shift in ((~later, stride, 0), (later, sparse, sparse_after or 0)):
        at = index[rows & ((row - shift) % every == every // 2)]
        if at.size:
            gram, _ = recipe_error_gram(model, pre.take(at), noise, friction,
                                        motion=window_motion(pre, at))
            out += kind_grams(gram) * float(every)
    return out


def _turning_channels(model: PlatformModel, angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """The angle channels the units' constraint rows (odometry) depend on, found on a few
    rows (the steering angles and pivots; not the wheels')."""
    from ropod_sysid.odometry import constraint_system

    few = min(8, angles.shape[0])
    j = angles.shape[1]
    base = constraint_system(model, angles[:few], rates[:few])
    moved = np.tile(angles[:few], (j, 1)).reshape(j, few, j)  # each channel moved, stacked
    moved[np.arange(j), :, np.arange(j)] += 0.1
    new = constraint_system(model, moved.reshape(j * few, j), np.tile(rates[:few], (j, 1)))
    changed = np.zeros(j, bool)
    for x, y in zip(base, new, strict=True):
        changed |= (y.reshape(j, few, -1) != x.reshape(1, few, -1)).any(axis=(1, 2))
    return np.flatnonzero(changed)


def odometry_maps(model: PlatformModel, q: np.ndarray, angles: np.ndarray, rates: np.ndarray,
                  eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """How the angle channels' errors reach the world-frame q̇ and q̈ (N, D) of the rows
    through odometry: M (N, D, J), δq̇ = M δφ̇ and δq̈ = M δφ̈ + K δφ̇, with K (N, D, J).
    M = [R(θ) G; E] (G = (CᵀC)⁻¹ Cᵀ D the odometry gain from the units' constraint rows
    C ν = D φ̇, E the selection of the units' own coordinates); K from q̈ = R (ν̇ + ω × ν)
    with ν = G(φ) φ̇: ν̇ = G φ̈ + Ġ φ̇, so a rate error δφ̇_j moves q̈ by
    R (Ġ e_j + ∂(G φ̇)/∂φ_j + δω × ν + ω × G e_j) — the wheels' rolling rows turn with the
    steering angles, so a steering angle's rate error reaches q̈ with about the wheel speed as
    gain (Ġ by differences along φ̇, ∂/∂φ_j by differences)."""
    from ropod_sysid.odometry import constraint_system, solve_symmetric3

    n, j = angles.shape
    d = int(getattr(model, "n_dof", 3))

    def gain(ang: np.ndarray) -> np.ndarray:  # G (J, N, 3) at the angles (N, J)
        c, _ = constraint_system(model, ang, np.zeros((n, j)))
        _, b = constraint_system(model, np.tile(ang, (j, 1)),
                                 np.repeat(np.eye(j), n, axis=0))
        ct = np.swapaxes(c, 1, 2)
        rhs = ct @ np.moveaxis(b.reshape(j, n, -1), 0, 2)  # (N, 3, J): Cᵀ D
        return np.moveaxis(np.linalg.solve(ct @ c, rhs), 2, 0)

    g = gain(angles)
    g_dot = (gain(angles + eps * rates) - g) / eps  # Ġ: along the angles' motion
    nu = np.einsum("cni,nc->ni", g, rates)
    body = g_dot.copy()  # (J, N, 3): ∂ν̇/∂φ̇_c
    turning = _turning_channels(model, angles, rates)
    if turning.size:  # ∂(G φ̇)/∂φ_c of the channels the constraint rows turn with
        t = turning.size
        ang = np.tile(angles, (t, 1)).reshape(t, n, j)
        ang[np.arange(t), :, turning] += eps
        c, b = constraint_system(model, ang.reshape(t * n, j), np.tile(rates, (t, 1)))
        ct = np.swapaxes(c, 1, 2)
        moved = solve_symmetric3(ct @ c, (ct @ b[..., None])[..., 0]).reshape(t, n, 3)
        body[turning] += (moved - nu) / eps
    w, gw = nu[:, 2], g[:, :, 2]  # ω and δω per channel
    body[:, :, 0] -= gw * nu[:, 1] + w * g[:, :, 1]
    body[:, :, 1] += gw * nu[:, 0] + w * g[:, :, 0]
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    m, k = np.zeros((n, d, j)), np.zeros((n, d, j))
    for out, v in ((m, g), (k, body)):
        out[:, 0] = (c * v[:, :, 0] - s * v[:, :, 1]).T
        out[:, 1] = (s * v[:, :, 0] + c * v[:, :, 1]).T
        out[:, 2] = v[:, :, 2].T
    own = np.asarray(getattr(model, "coordinate_channels", np.zeros(0, int)), int)
    m[:, 3 + np.arange(own.size), own] = 1.0
    return m, k


@dataclass
class MotionRows:
    """The motion at equation rows as the fit's recipe reads it: the fields of a
    :class:`ropod_sysid.regressor.Preprocessed` that :func:`recipe_sensitivities` reads, for
    rows that come from no log (a planned run's: :func:`planned_rows`).

    q : (N, 3) pose; qd : (N, 3) the base's rates; qdd : (N, D) the accelerations of every
    DOF (the base's, then the units' own coordinates'); angles, angle_rates : (N, J) the unit
    angles and their rates as the encoders give them.
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    angles: np.ndarray
    angle_rates: np.ndarray

    def take(self, index: slice | np.ndarray) -> MotionRows:
        """The rows at ``index`` (as :meth:`Preprocessed.take`)."""
        return MotionRows(self.q[index], self.qd[index], self.qdd[index], self.angles[index],
                          self.angle_rates[index])


def planned_rows(model: PlatformModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                 angles: np.ndarray, angle_rates: np.ndarray | None = None) -> MotionRows:
    """The :class:`MotionRows` of a planned motion: q (N, 3), q̇ and q̈ (N, D) (the units' own
    coordinates' rates after the base's), the predicted angles (N, J); ``angle_rates`` (N, J)
    the encoders' rates (None: the rates the base motion implies at the angles, the units' own
    coordinates' from q̇ — what the planned A_ID,ext reads, :meth:`PlatformModel.state`)."""
    if angle_rates is None:
        angle_rates = model.state(q, qd, angles).angle_rate
    return MotionRows(q, qd[:, :3], qdd, angles, angle_rates)


def recipe_sensitivities(model: PlatformModel, rows: Preprocessed | MotionRows, noise: SensorNoise,
                         friction: Friction = "per-wheel", h: float = 1e-6,
                         used: list[int] | None = None,
                         motion: tuple[np.ndarray, np.ndarray] | None = None,
                         ) -> tuple[np.ndarray, list[int]]:
    """W (N, 2J, D, p): the first-order change of each row's A_ID,ext per standard deviation
    of each encoder channel's rate error (the first J sources) and acceleration error (the
    last J) at the rows ``rows`` (a :class:`Preprocessed` of the row samples, or
    :class:`MotionRows`). The sources are independent (odd and even kernels: uncorrelated;
    :func:`channel_variances`), so E[δA_dᵀ δA_d] = Σ_s W_sdᵀ W_sd and the row's error δA_d m
    has the variance Σ_s (W_sd m)² (:func:`recipe_error_gram`). The errors are carried
    through the fit's recipe (:func:`ropod_sysid.regressor.raw_system`):

    * odometry (:func:`odometry_maps`): δq̇ = M δφ̇, δq̈ = M δφ̈ + K δφ̇;
    * :meth:`~ropod_sysid.model.PlatformModel.consistent_motion`: δq̇ ← P_v δq̇ (its own
      coordinates' rates with it) and δq̈ ← P_a δq̈ − G⁺ δ(Ġ q̇), P = I − G⁺G, where the rows are
      regular (elsewhere unchanged);
    * A_ID,ext, linear in q̈ (A = A₀ + Σ_k A_k q̈_k: D + 1 evaluations) and through the state
      along the base twist and the rate channels A or Ġ q̇ use (the units' own coordinates,
      the swivel's pivots; differences of step ``h``);
    * the held joints locked, the identification projector (the base rows left out near
      singular configurations) and the rows at rest zero, as the fit forms them.

    Without constraints the projections are the identity. ``used``: the rate channels A or
    Ġ q̇ reads (None: found on a few rows); returned with W, for the next rows. ``motion``:
    the channels' motion through the rows' windows (:func:`window_motion`), whose
    :func:`tone_share` the sources' variances take (None: :func:`sawtooth_share` of the rows'
    rates). (Second-order terms — the angles' own errors in A's angle-dependent columns — are left
    out.)"""
    from ropod_sysid.model.assembly import SINGULAR_MARGIN, base_singular_ratio
    from ropod_sysid.regressor import at_rest, held_joints

    n, j = rows.angles.shape
    d = int(getattr(model, "n_dof", 3))
    enc = _encoders(model, j)
    own = np.asarray(getattr(model, "coordinate_channels", np.zeros(0, int)), int)
    rates = rows.angle_rates
    st_m = model.state(rows.q, rows.qd, rows.angles, rates)
    st, qdd = model.consistent_motion(st_m, rows.qdd)
    if d > 3:
        st.held = held_joints(model, rates[:, own])
    eye = np.broadcast_to(np.eye(d), (n, d, d))
    con = model.constraints(st_m)
    if con is not None:
        regular = base_singular_ratio(con[0], model.motion_rank) >= SINGULAR_MARGIN
        p_v = eye - np.linalg.pinv(con[0], rcond=1e-9) @ con[0]
        # not None: the model is constrained (con above)
        g_c, c_c = cast(tuple[np.ndarray, np.ndarray], model.constraints(st))
        g_pinv = np.linalg.pinv(g_c, rcond=1e-9)
        p_a = eye - g_pinv @ g_c
        p_v[~regular], p_a[~regular], g_pinv[~regular] = np.eye(d), np.eye(d), 0.0
    else:
        p_v = p_a = eye
    m, k = odometry_maps(model, rows.q, rows.angles, rates)

    # A's linear parts in q̈ (before the identification projector, applied once at the end)
    a0 = model.a_id_ext(st, np.zeros((n, d)), friction, projected=False)
    a_k = np.stack([model.a_id_ext(st, np.broadcast_to(np.eye(d)[i], (n, d)), friction,
                                   projected=False) - a0 for i in range(d)], axis=1)
    a_c = a0 + (qdd[:, None, :] @ a_k.reshape(n, d, -1)).reshape(a0.shape)

    # the state's directions: the base twist and the rate channels A or Ġ q̇ reads
    if used is None:
        used = sorted(set(own.tolist()) | set(measured_rate_channels(model, st, qdd, friction)))
    qd_m = p_v @ m  # (N, D, J): δq̇ after the consistent motion's projection
    t_map = np.zeros((n, 3 + len(used), j))  # the rate errors' moves along the directions
    t_map[:, :3] = qd_m[:, :3]
    # every direction's state at once: the model evaluated on (3 + I)·N stacked rows
    n_dir = 3 + len(used)
    qd_s = np.tile(st.qd, (n_dir, 1))
    rates_s = np.tile(st.angle_rate, (n_dir, 1))
    for i in range(n_dir):
        rows_i = slice(i * n, (i + 1) * n)
        if i < 3:
            qd_s[rows_i, i] += h
        else:
            ch = used[i - 3]
            rates_s[rows_i, ch] += h
            where = np.flatnonzero(own == ch)
            if where.size:
                t_map[:, i] = qd_m[:, 3 + where[0]]
            else:
                t_map[:, i, ch] = 1.0
    st_s = model.state(np.tile(st.q, (n_dir, 1)), qd_s, np.tile(st.angles, (n_dir, 1)),
                       rates_s)
    a_s = model.a_id_ext(st_s, np.tile(qdd, (n_dir, 1)), friction, projected=False)
    da = np.moveaxis((a_s.reshape(n_dir, *a_c.shape) - a_c) / h, 0, 1)  # (N, I, D, p)
    if con is not None:
        c_s = cast(tuple[np.ndarray, np.ndarray], model.constraints(st_s))[1]  # as con
        dc = np.moveaxis((c_s.reshape(n_dir, *c_c.shape) - c_c) / h, 0, -1)  # (N, C, I)
    proj = model.identification_projector(st)
    da_all = np.concatenate([a_k, da], axis=1)  # (N, D + I, D, p)
    if proj is not None:
        da_all = proj[:, None] @ da_all
    dqdd_v = p_a @ k
    if con is not None:
        dqdd_v = dqdd_v - g_pinv @ (dc @ t_map)
    # the sources' coefficients on A's terms: (N, D + I, 2J), rate errors then acceleration
    coef = np.concatenate([np.concatenate([dqdd_v, p_a @ m], axis=2),
                           np.concatenate([t_map, np.zeros_like(t_map)], axis=2)], axis=1)
    sd = np.concatenate([np.sqrt(channel_variances(noise, rates, 1, motion)),
                         np.sqrt(channel_variances(noise, rates, 2, motion))], axis=1)
    sd[:, np.concatenate([~enc, ~enc])] = 0.0  # a leg's extension is no rotary encoder
    sd[at_rest(rows)] = 0.0
    coef = coef * sd[:, None, :]
    p = da_all.shape[-1]
    w = np.swapaxes(coef, 1, 2) @ da_all.reshape(n, -1, d * p)  # (N, 2J, D·p)
    return w.reshape(n, -1, d, p), used




def recipe_error_gram(model: PlatformModel, rows: Preprocessed | MotionRows, noise: SensorNoise,
                      friction: Friction = "per-wheel", truth: np.ndarray | None = None,
                      motion: tuple[np.ndarray, np.ndarray] | None = None,
                      ) -> tuple[np.ndarray, np.ndarray | None]:
    """E[δA_dᵀ δA_d] (D, p, p) summed over the rows ``rows`` (a :class:`Preprocessed` of the
    row samples, or :class:`MotionRows`), per row d, from the encoders' quantisation carried
    through the fit's recipe (:func:`recipe_sensitivities`), in chunks of rows that bound its
    memory (about 64 MB); and with ``truth`` m (p,) the variance (N, D) of each row's error
    δA_d m = Σ_s (W_sd m)², the encoders' share of the rows' noise (None without ``truth``).
    ``motion``: as :func:`recipe_sensitivities`'s, (N, J) each. Zero with exact encoders."""
    n, j = rows.angles.shape
    d, p = int(getattr(model, "n_dof", 3)), len(model.parameter_names(friction))
    gram = np.zeros((d, p, p))
    var = None if truth is None else np.zeros((n, d))
    if noise.encoder_counts is None:
        return gram, var
    chunk = max(256, int(8e6 // (2 * j * d * p)))
    used = None
    for k in range(0, n, chunk):
        part = None if motion is None else (motion[0][k:k + chunk], motion[1][k:k + chunk])
        w, used = recipe_sensitivities(model, rows.take(slice(k, k + chunk)), noise,
                                       friction, used=used, motion=part)
        x = np.moveaxis(w, 2, 0).reshape(d, -1, p)  # (D, N·2J, p)
        gram += np.swapaxes(x, 1, 2) @ x
        if var is not None:
            assert truth is not None  # var is None without truth
            var[k:k + chunk] = (np.einsum("nsdp,p->nsd", w, truth) ** 2).sum(axis=1)
    return gram, var


def kind_grams(per_dof: np.ndarray) -> np.ndarray:
    """Error grams (…, D, p, p) per row summed into the fit's three row kinds (…, 3, p, p):
    x, y, and θ with the units' own coordinates (:func:`ropod_sysid.solve.row_kinds`)."""
    from ropod_sysid.solve import row_kinds

    kinds = row_kinds(per_dof.shape[-3])
    return np.stack([per_dof[..., kinds == k, :, :].sum(axis=-3) for k in range(3)], axis=-3)
