"""Optimal excitation: a finite Fourier series run searched for identifiability (Swevers et al.).

:func:`optimize` searches the coefficients of a run of
:class:`~ropod_sysid.trajectory.fourier.FourierFamily` with scipy's differential evolution for
the best condition number (or log-determinant) of the stacked regressor A_ID,ext of the four
variants (Sec. VI-A, VI-C), unit angles in each type's quasi-steady closed form
(:meth:`UnitType.quasi_steady_angles`: swivel units trailing their pivots, eq. 8a; omni wheels
integrating their rates; steered wheels along their planned steering), within the limits [m/s,
m/s², rad/s, rad/s², the pivot and steering rates, and optionally the wheel rates and the least
curvature radius, 002 eq. 26] and the floor [m]. Any mix of unit types. On platforms with
constraint rows (steered wheels) the samples near a singular configuration, whose base rows the
fit leaves out, are penalised as well. Units that plan coordinates of their own (a leg's
extension) add the numbers that choose their plan (:meth:`plan_search`) to the search.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.forked import ForkedMap, default_processes
from ropod_sysid.model.assembly import SINGULAR_MARGIN
from ropod_sysid.noise import SensorNoise
from ropod_sysid.params import Friction
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.fourier import FourierFamily, _scaled_twist
from ropod_sysid.trajectory.identifiability import (
    _world_motion,
    conditioning,
    with_own_coordinates,
)
from ropod_sysid.trajectory.limits import (
    DEFAULT_FLOOR,
    PIVOT_DESIGN_MARGIN,
    Floor,
    Limits,
    PlanningError,
    _check_floor,
)
from ropod_sysid.trajectory.precheck import CheckReport, stacked_regressor
from ropod_sysid.trajectory.prediction import _variant_prediction, predict_angles
from ropod_sysid.trajectory.run_variants import VARIANT_SIGNS, VARIANTS, _off_floor, variants
from ropod_sysid.trajectory.setpoints import Trajectory

OPTIMIZE_DURATION = (5.0, 600.0)  # optimize(): shortest and longest run [s]
MAX_HARMONICS = 20  # optimize(): most harmonics of each Fourier series
SPEED_WEIGHT = 0.5  # optimize(): weight of −log(mean speed / v_max) in the objective
SINGULAR_WEIGHT = 1.0  # optimize(): weight of the fraction of samples near singular
MAX_LAG = 0.35  # optimize(): sin of the largest quasi-steady lag of a unit behind its pivot
SIGMA_RERANK = 6  # optimize("sigma"): candidates within the limits weighed by check at the end
CURVATURE_MARGIN = 0.95  # optimize(): the least curvature radius is planned at R_min / this
BATCH = 64  # optimize(): most candidates evaluated at once (memory)
OBJECTIVES = ("sigma", "cond", "logdet")  # optimize(): what it minimises (the first: default)


@dataclass
class OptimizeResult:
    """An optimised excitation run and how it was found.

    Attributes
    ----------
    trajectory : the run (original variant), rest to rest, within the limits and the floor
    objective : ``"cond"`` or ``"logdet"``; value : its value (objective grid, penalties in)
    condition_number, rank : of the stacked regressor of the four variants (identifiable
        subspace, as :func:`check` evaluates it on the run's own grid)
    structural_rank : rank of the regressor the search found (identifiable subspace dimension)
    coefficients : (3, 2H+1) Fourier coefficients of speed, direction, curvature
    speed_scale : s_v [m/s]; evaluations, generations, seconds : the search's cost
    plan : the numbers in [0, 1] that chose the units' own plans (a leg's amplitude, frequency
        and phase: :meth:`plan_search`), per planning unit in the platform's group order
    """

    trajectory: Trajectory
    objective: str
    value: float
    condition_number: float
    rank: int
    structural_rank: int
    coefficients: np.ndarray
    speed_scale: float
    evaluations: int
    generations: int
    seconds: float
    notes: list[str] = field(default_factory=list)
    targets: dict[str, float] = field(default_factory=dict)  # "sigma": name → predicted rel. σ
    target_bias: dict[str, float] = field(default_factory=dict)  # name → predicted rel. bias
    plan: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _batches(n: int) -> list[np.ndarray]:
    """The candidates 0…n−1 in the fewest batches of at most :data:`BATCH`, of equal length
    (± 1, the longer first); whole batches of them, taken in order, are again such batches."""
    return np.array_split(np.arange(n), -(-n // BATCH))


class _Objective:
    """Vectorised objective of :func:`optimize` over a population of coefficient vectors."""

    def __init__(self, platform: Platform, duration: float, harmonics: int, limits: Limits,
                 floor: Floor, objective: str, friction: Friction, grid_rate: float,
                 eval_rate: float, sigma: SigmaTarget | None = None,
                 processes: int | None = None) -> None:
        from ropod_sysid.model import PlatformModel

        self.platform = platform
        self.model = PlatformModel(platform)
        self.positions = platform.positions
        self.limits = limits
        self.floor = floor
        self.objective = objective
        self.friction = friction
        n = int(math.ceil(duration * grid_rate))
        self.t = np.linspace(0.0, duration, n + 1)
        self.family = _family(platform, duration, harmonics, self.t, limits)
        self.n_base = self.family.n_coefficients
        # units that plan own coordinates (legs): their plan's numbers follow the base's
        self.planners = [(unit, int(unit.plan_dimensions)) for _, unit in self.model.groups
                         if hasattr(unit, "plan_search")]
        self.n_plan = sum(d for _, d in self.planners)
        step = max(int(round(grid_rate / eval_rate)), 1)
        self.eval_idx = np.arange(step // 2 + 1, n, step)  # interior samples (not at rest)
        self.rank: int | None = None
        self.evaluations = 0
        self.sigma = sigma
        self.rows_per_eval = (sigma.sensors.rows_per_second * step / grid_rate
                              if sigma is not None else 1.0)
        self.variances: np.ndarray | None = None  # mean row variances (D,), from the 1st batch
        self.columns: np.ndarray | None = None  # the fit's base columns (rank deficiency)
        self.processes = default_processes() if processes is None else processes
        self.split: ForkedMap | None = None

    def twist(self, coef: np.ndarray, margin: float = 0.95,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Twist and its rate (S, N, 3) at the largest speed scale s_v within the limits and the
        floor (all four variants) times ``margin``, and s_v (S,)."""
        return _scaled_twist(self.family, coef[:, :self.n_base], self.limits, self.floor,
                             self.t, margin)

    def planned(self, t: np.ndarray, tw: np.ndarray, coef: np.ndarray) -> np.ndarray | None:
        """The units' planned own coordinates (S, N, L) (:attr:`PlatformModel.planned_columns`
        order) along the candidates' twists (S, N, 3) at times t; None without any."""
        if not self.planners:
            return None
        out, k = [], self.n_base
        for unit, d in self.planners:
            out += list(unit.plan_search(t, tw, coef[:, k:k + d]).values())
            k += d
        return np.stack(out, axis=-1)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Objective values (S,) for coefficients x (D, S) (scipy's vectorised layout); after
        the first call (which fixes what the later ones share: the rank, the rows' variances)
        split over :attr:`processes` forked processes."""
        coef = np.atleast_2d(np.asarray(x, float).T)
        if self.evaluations and self.processes > 1 and self.split is None:
            self.split = ForkedMap(self.values, self.processes)
        if self.split is None:
            out = self.values(coef)
        else:  # each process whole batches: the same batches as in one process
            out = self.split(coef, [len(b) for b in _batches(coef.shape[0])])
        self.evaluations += coef.shape[0]
        return out

    def values(self, coef: np.ndarray) -> np.ndarray:
        """Objective values (S,) for coefficients (S, D), in the batches of
        :func:`_batches` (a value can differ in its last digits with its batch)."""
        out = np.empty(coef.shape[0])
        for idx in _batches(coef.shape[0]):
            out[idx] = self._batch(coef[idx])
        return out

    def close(self) -> None:
        """End the forked processes of :meth:`__call__`."""
        if self.split is not None:
            self.split.close()
            self.split = None

    def _batch(self, coef: np.ndarray) -> np.ndarray:
        tw, twd, _ = self.twist(coef)
        signs = np.array([VARIANT_SIGNS[v] for v in VARIANTS])  # (4, 3)
        tw_v = tw[:, None] * signs[None, :, None, :]
        twd_v = twd[:, None] * signs[None, :, None, :]
        legs = self.planned(self.t, tw, coef)  # the four variants share the plan
        planned = None if legs is None else np.broadcast_to(
            legs[:, None], (legs.shape[0], 4, *legs.shape[1:]))
        pred = predict_angles(self.t, tw_v, self.model, twist_rates=twd_v, planned=planned)
        assert pred.lag is not None
        lag = np.abs(pred.lag[:, :2]).max(axis=(1, 2, 3))  # negated variants: the same
        penalty = np.maximum(lag / MAX_LAG - 1.0, 0.0)
        if self.limits.pivot_rate_max is not None:
            peak = np.abs(pred.turning[:, :2]).max(axis=(1, 2, 3))
            penalty += np.maximum(peak / (PIVOT_DESIGN_MARGIN * self.limits.pivot_rate_max)
                                  - 1.0, 0.0)
        if self.limits.steer_rate_max is not None and pred.steering_units.any():
            steer = np.abs(pred.steering[..., pred.steering_units]).max(axis=(1, 2, 3))
            penalty += np.maximum(steer / (PIVOT_DESIGN_MARGIN * self.limits.steer_rate_max)
                                  - 1.0, 0.0)
        if self.limits.wheel_rate_max is not None:
            wheel = np.abs(pred.wheel_rates).max(axis=(1, 2, 3), initial=0.0)
            penalty += np.maximum(wheel / (PIVOT_DESIGN_MARGIN * self.limits.wheel_rate_max)
                                  - 1.0, 0.0)
        idx = self.eval_idx
        q, qd, qdd = _world_motion(self.t, tw_v, twd_v)
        qd, qdd = with_own_coordinates(self.model, self.t, qd, qdd, pred.rates)
        n_s, d = coef.shape[0], qd.shape[-1]
        # angle rates from the constraints (the swivel's eq. 8a) at the quasi-steady angles:
        # consistent kinematics, so the structural rank deficiency shows exactly
        st = self.model.state(q[:, :, idx].reshape(-1, 3), qd[:, :, idx].reshape(-1, d),
                              pred.angles[:, :, idx].reshape(n_s * 4 * idx.size, -1))
        qdd_rows = qdd[:, :, idx].reshape(-1, d)
        a = self.model.a_id_ext(st, qdd_rows, self.friction)
        # the fraction of samples near singular, whose base rows the fit leaves out
        ratio = self.model.singular_ratio(st)
        singular = (np.zeros(n_s) if ratio is None else
                    (ratio.reshape(n_s, -1) < SINGULAR_MARGIN).mean(axis=1))
        singular = SINGULAR_WEIGHT * singular
        if self.sigma is not None:
            value = self._sigma_value(a.reshape(n_s, -1, d, a.shape[-1]), st, qdd_rows)
            return value + 10.0 * penalty + 100.0 * penalty**2 + singular
        a = a.reshape(n_s, -1, a.shape[-1])
        norms = np.linalg.norm(a, axis=1)
        a = a / np.where(norms > 0, norms, 1.0)[:, None, :]
        # einsum, not BLAS: many small products, and threaded BLAS stalls on a busy machine
        gram = np.einsum("smi,smj->sij", a, a)
        lam = np.clip(np.linalg.eigvalsh(gram)[:, ::-1], 1e-300, None)
        if self.rank is None:
            self.rank = max(conditioning(a[k]).rank for k in range(min(6, n_s)))
        r = self.rank
        if self.objective == "cond":
            value = 0.5 * np.log(lam[:, 0] / lam[:, r - 1])
        else:
            value = -np.log(lam[:, :r]).sum(axis=1) / r
        # tie-breaker towards brisk runs: the scaled regressor does not see the signal level
        speed = np.linalg.norm(tw[..., :2], axis=-1).mean(axis=1) / self.limits.v_max
        value = value - SPEED_WEIGHT * np.log(np.maximum(speed, 1e-6))
        return value + 10.0 * penalty + 100.0 * penalty**2 + singular


    def _sigma_value(self, a: np.ndarray, st: object, qdd: np.ndarray) -> np.ndarray:
        """Mean log relative predicted σ of the target parameters (S,) from the candidates'
        rows a (S, R, D, p) at the states ``st`` and accelerations ``qdd`` (S·R, D): the fit's
        white-noise σ (:mod:`ropod_sysid.noise`), the θ rows weighted as the fit weighs them,
        σ̂ from the rows' mean variances (:func:`~ropod_sysid.noise.row_variances`, taken once:
        they hardly depend on the run), on the fit's base columns when the platform leaves
        combinations (:meth:`SigmaTarget.columns`). (The errors-in-variables bias needs the
        pivots' motion finer than this grid: :func:`optimize` weighs it in when it picks among
        the best candidates.)"""
        from ropod_sysid.noise import planned_rows, row_variances

        sig = self.sigma
        assert sig is not None
        if self.variances is None:
            rows = planned_rows(self.model, st.q, st.qd, qdd, st.angles,  # type: ignore[attr-defined]
                                st.angle_rate)  # type: ignore[attr-defined]
            self.variances = row_variances(self.model, rows, sig.truth_params, sig.sensors,
                                           self.friction).mean(axis=0)
            # the fit's columns of the candidate that excites the most of them (a leg that
            # hardly moves in one candidate leaves its columns out of that one's)
            excited = (np.linalg.norm(a, axis=(1, 2)) > 0).sum(axis=1)
            self.columns = sig.columns(a[int(np.argmax(excited))])
        cols = self.columns
        assert cols is not None
        b = np.einsum("srdp,p->srd", a, sig.truth)
        ms = np.mean(b**2, axis=1)  # (S, D): the θ rows and the units' own rows are one kind
        w = np.sqrt(0.5 * (ms[:, 0] + ms[:, 1]) / np.maximum(ms[:, 2:].mean(axis=1), 1e-300))
        v = self.variances
        s2 = (v[0] + v[1] + w**2 * v[2:].sum()) / v.size  # σ̂² of the weighted rows (S,)
        aw = a[..., cols].copy()
        aw[:, :, 2:, :] *= w[:, None, None, None]
        aw = aw.reshape(aw.shape[0], -1, len(cols))
        norms = np.linalg.norm(aw, axis=1)  # (S, q)
        norms = np.where(norms > 0, norms, 1.0)
        aw = aw / norms[:, None, :]
        gram = np.einsum("smi,smj->sij", aw, aw) * self.rows_per_eval
        lam, vec = np.linalg.eigh(gram)
        floor = np.maximum(1e-300 * lam[:, -1:], 1e-300)  # a candidate that excites nothing
        inv_diag = np.einsum("sjk,sk->sj", vec**2, 1.0 / np.maximum(lam, floor))
        var = inv_diag / norms**2 * (s2 * sig.correlation)[:, None]  # (S, q)
        tc = sig.target_cols(cols)
        return np.log(np.sqrt(var[:, tc]) / sig.scale[cols][tc]).mean(axis=1)


@dataclass
class SigmaTarget:
    """What ``objective="sigma"`` minimises: the predicted σ of ``names`` (of the fit's
    ``all_names``) relative to their true values, under the sensor model ``sensors``."""

    names: list[str]
    all_names: list[str]
    truth_params: object  # DynamicParameters
    truth: np.ndarray  # (p,)
    sensors: SensorNoise

    @property
    def correlation(self) -> float:
        return self.sensors.grid.correlation

    @property
    def scale(self) -> np.ndarray:
        """|true value| of every parameter (1 where it is 0)."""
        return np.where(np.abs(self.truth) > 0, np.abs(self.truth), 1.0)

    def columns(self, a: np.ndarray) -> np.ndarray:
        """The fit's base columns for rows like ``a`` (R, 3, p)
        (:func:`ropod_sysid.noise.base_columns`; on a platform with structural
        combinations a target then stands for its identifiable combination, as in the fit's
        output)."""
        from ropod_sysid.noise import base_columns

        return base_columns(a, self.truth)

    def target_cols(self, cols: np.ndarray) -> np.ndarray:
        """Positions within ``cols`` of the targets the fit determines (alone or as the base of a
        combination)."""
        idx = [self.all_names.index(n) for n in self.names]
        return np.flatnonzero(np.isin(cols, idx))


def sigma_target(platform: Platform, target: str | Sequence[str], friction: str,
                 sensors: SensorNoise, params: object = None) -> SigmaTarget:
    """The :class:`SigmaTarget` of ``target``: ``"inertial"`` (masses and inertias), ``"all"``
    or parameter names; ``params`` the true values (:func:`ropod_sysid.trajectory.precheck.
    true_parameters`: by default the thesis's fixed masses on smart-wheel platforms)."""
    from ropod_sysid.params import is_inertial, parameter_names
    from ropod_sysid.trajectory.precheck import true_parameters

    names = parameter_names(platform, friction)  # type: ignore[arg-type]
    if target == "inertial":
        chosen = [n for n in names if is_inertial(n)]
    elif target == "all":
        chosen = list(names)
    else:
        chosen = [target] if isinstance(target, str) else list(target)
        unknown = [n for n in chosen if n not in names]
        if unknown:
            raise InputError(f"--target {','.join(unknown)}: not a parameter of this platform "
                             f"with {friction} friction; use inertial, all or names of "
                             f"{', '.join(names[:8])}, …")
    truth = true_parameters(platform, params)  # type: ignore[arg-type]
    return SigmaTarget(chosen, names, truth, truth.vector(names), sensors)


def optimize(platform: Platform, duration: float = 30.0, harmonics: int = 5,
             objective: str = "sigma", seed: int = 0, maxiter: int = 25,
             limits: Limits | None = None, floor: Sequence[float] = DEFAULT_FLOOR,
             progress: bool = False, dt: float = 0.005, popsize: int = 4,
             friction: str = "per-wheel", target: str | Sequence[str] = "inertial",
             sensors: SensorNoise | None = None, params: object = None,
             processes: int | None = None) -> OptimizeResult:
    """An optimal excitation run: finite Fourier series per base DOF (Swevers et al.).

    The run is a member of :class:`FourierFamily` (speed, direction of travel and curvature of
    the base, each a finite Fourier series, rest to rest, no pivot velocity ever reversing);
    every candidate runs at the largest speed within the limits and the floor (all four
    variants) at 95 %. The objective is evaluated on the stacked regressor A_ID,ext of the four
    variants (Sec. VI-A) along the planned motion on a coarse grid, units trailing their pivot
    velocities (quasi-steady eq. 8a):

    * ``"cond"`` — the condition number of the column-scaled regressor on its identifiable
      subspace (σ_max / σ_r, r the structural rank: on the ropod's symmetric square the regressor
      is rank deficient for every run, thesis Sec. VI-C), minimised;
    * ``"logdet"`` — the log-determinant of the column-scaled information matrix on that
      subspace, maximised;
    * ``"sigma"`` — the mean log of the ``target`` parameters' predicted standard deviations
      relative to their true values, minimised: the σ the fit will report (its white-noise σ)
      under the sensor model ``sensors`` (:mod:`ropod_sysid.noise`; default 30 mA
      current noise, 2¹⁴-count encoders, 100 Hz). Unlike the column-scaled regressor this
      sees the signal level: a brisk run determines the parameters better than a slow one of
      the same shape. On a platform with structural combinations a target stands for its
      identifiable combination (as the fit reports it).

    Pivot rates (units with a turning joint) and, with a wheel-rate limit, wheel rates above
    80 % of their limit, and quasi-steady lags of a unit behind its pivot with
    sin > 0.35 (a unit cannot follow a pivot that barely moves), are penalised; −0.5 log(mean
    speed / v_max) is added as a tie-breaker towards brisk runs, which the column-scaled
    regressor cannot see. With a least curvature radius (002 eq. 26) the family's curvature is
    capped at 0.95 / R_min, so every candidate keeps it. scipy's differential evolution searches
    the coefficients (seeded, vectorised over the population); the best candidate whose limits,
    floor and pivot rates integrated on the fine grid all hold is returned.

    Units that plan coordinates of their own add them to the search: a leg's extension is
    :meth:`~ropod_sysid.model.units.legs.LeggedUnits.leg_profile` (a sinusoid on a progress
    gated on the base's speed at the leg, as ``typical`` plans it, so that no wheel comes to
    rest: 002 §III-C's type A) whose amplitude, frequency and phase are three more numbers
    of the search (:meth:`~ropod_sysid.model.units.legs.LeggedUnits.plan_search`), within the
    leg's range and rate. The regressor then has the legs' rows, so ``"sigma"`` weighs how
    well m_leg and the leg friction are determined when the targets name them (``"all"``,
    ``"inertial"`` for m_leg); a candidate whose integrated prediction flags a wheel at rest
    is refused.

    Parameters
    ----------
    platform : unit types and geometry for the regressor and the predicted angles
    duration : length of the run [s]; harmonics : H, harmonics per DOF (base period = duration)
    objective : ``"cond"``, ``"logdet"`` or ``"sigma"``; seed : random seed (repeatable)
    target : for ``"sigma"``: ``"inertial"``, ``"all"`` or parameter names
    sensors : for ``"sigma"``: the sensor model; params : true values (see :func:`sigma_target`)
    maxiter : generations of the search; popsize : population = popsize × 3(2H+1) candidates
    limits, floor : as for :func:`typical`; progress : progress bar on stderr (terminal only)
    dt : sample interval of the returned setpoints [s]; friction : friction model of A_ID,ext
    processes : processes that evaluate the candidates (default
        :func:`~ropod_sysid.forked.default_processes`); the result does not depend on it

    Returns
    -------
    OptimizeResult
    """
    import time

    import scipy.optimize

    from ropod_sysid.model import PlatformModel
    from ropod_sysid.model.units import check_variant
    from ropod_sysid.progress import Progress

    limits = limits or Limits()
    floor = _check_floor(floor)
    if objective not in OBJECTIVES:
        raise InputError(f"unknown objective {objective!r}; use {', '.join(OBJECTIVES)}")
    if isinstance(harmonics, bool) or not isinstance(harmonics, int) \
            or not 1 <= harmonics <= MAX_HARMONICS:
        raise InputError(f"harmonics must be an integer from 1 to {MAX_HARMONICS}, got "
                         f"{harmonics!r}")
    lo, hi = OPTIMIZE_DURATION
    if not (isinstance(duration, int | float) and lo <= duration <= hi):
        raise InputError(f"duration must be between {lo:g} and {hi:g} s, got {duration!r}")
    if isinstance(maxiter, bool) or not isinstance(maxiter, int) or maxiter < 1:
        raise InputError(f"maxiter must be a positive integer, got {maxiter!r}")
    friction = check_variant(friction)  # the same string, typed as a Friction
    t_start = time.monotonic()
    model = PlatformModel(platform)
    sigma = (sigma_target(platform, target, friction, sensors or SensorNoise(), params)
             if objective == "sigma" else None)
    obj = _Objective(platform, float(duration), harmonics, limits, floor, objective, friction,
                     grid_rate=10.0, eval_rate=2.0, sigma=sigma, processes=processes)
    bounds = [(-1.0, 1.0)] * obj.n_base + [(0.0, 1.0)] * obj.n_plan
    generations = 0
    with Progress(maxiter, "optimize", quiet=not progress) as bar:
        def callback(*_args: object, **_kw: object) -> None:
            nonlocal generations
            generations += 1
            bar.update(1)

        try:
            res = scipy.optimize.differential_evolution(
                obj, bounds, seed=seed, maxiter=maxiter, popsize=popsize, tol=0.0,
                polish=False, vectorized=True, updating="deferred", init="latinhypercube",
                callback=callback)
        finally:
            obj.close()
    fine_t = np.linspace(0.0, duration, int(round(duration / dt)) + 1)
    fam = _family(platform, duration, harmonics, fine_t, limits)

    def weigh(idx: np.ndarray) -> np.ndarray:
        """Candidates ``idx`` of the population on the fine grid: each one's (trajectory,
        s_v, the limit it breaks or "", its check report for ``sigma`` or None)."""
        out = np.empty(len(idx), dtype=object)
        for j, k in enumerate(idx):
            coef = res.population[k]
            _, _, s_v = obj.twist(coef[None])
            tw, _, _ = _scaled_twist(fam, coef[None, :obj.n_base], limits, floor, fine_t,
                                     0.95, s_v)
            legs = obj.planned(fine_t, tw, coef[None])
            traj = Trajectory.from_twist(fine_t, tw[0, :, 0], tw[0, :, 1], tw[0, :, 2],
                                         None if legs is None else dict(zip(
                                             model.planned_columns, legs[0].T, strict=True)))
            ok, why = _verify(traj, platform, limits, floor)
            rep = (_check(traj, platform, limits, floor, friction, sigma)
                   if ok and sigma is not None else None)
            out[j] = (traj, float(s_v[0]), why, rep)
        return out

    notes: list[str] = []
    why_first = ""
    good: list[tuple[np.ndarray, Trajectory, float, float, CheckReport | None]] = []
    broke = 0
    # the best candidates in order until enough hold every limit on the fine grid (with
    # "sigma", SIGMA_RERANK of them, weighed by check: a second each, split over processes)
    ranked, taken = np.argsort(res.population_energies)[:12], 0
    need = SIGMA_RERANK if sigma is not None else 1
    with ForkedMap(weigh, processes if sigma is not None else 1) as split:
        while len(good) < need and taken < len(ranked):
            batch = ranked[taken:taken + need - len(good)]
            taken += len(batch)
            for k, (traj, s_v, why, rep) in zip(batch, split(batch), strict=True):
                if why:
                    broke += 0 if good else 1
                    why_first = why_first or why
                else:
                    good.append((res.population[k], traj, s_v,
                                 float(res.population_energies[k]), rep))
    if not good:
        raise PlanningError(f"no optimised run within the limits ({why_first}); try another "
                            "seed, more maxiter or a longer duration")
    if broke:
        notes.append(f"{broke} better candidate(s) broke a limit on the fine grid "
                     f"({why_first}); took the next")
    chosen = good[0]
    if sigma is not None and len(good) > 1:
        # (with sigma every candidate within the limits has its check report)
        best = int(np.argmin([_total_error(g[4], sigma) for g in good]))  # type: ignore[arg-type]
        if best:
            notes.append(f"of the {len(good)} best candidates within the limits, number "
                         f"{best + 1} has the least predicted error once the encoders' bias "
                         "is counted (trajectory check)")
        chosen = good[best]
    coef, traj, s_v, value, rep = chosen
    if obj.planners:
        k, plans = obj.n_base, []
        for unit, d in obj.planners:
            plans.append(unit.describe_plan(coef[k:k + d]))
            k += d
        notes.append("planned with the base motion (on its progress while the base moves): "
                     + ", ".join(plans))
    cond = conditioning(stacked_regressor(*_variant_prediction(traj, model), model,
                                          friction)[0])
    out = OptimizeResult(traj, objective, value, cond.condition_number, cond.rank,
                         obj.rank or 0, coef[:obj.n_base].reshape(3, -1), s_v,
                         obj.evaluations, generations, time.monotonic() - t_start, notes,
                         plan=coef[obj.n_base:].copy())
    if rep is not None:
        assert sigma is not None
        out.targets = {n: float(rep.relative_std[rep.names.index(n)]) for n in sigma.names}
        out.target_bias = {n: float(rep.bias[j] / abs(rep.true_values[j]))
                           if rep.true_values[j] else math.nan
                           for n in sigma.names for j in [rep.names.index(n)]}
        out.seconds = time.monotonic() - t_start
    return out


def _check(traj: Trajectory, platform: Platform, limits: Limits, floor: Floor, friction: str,
           sigma: SigmaTarget) -> CheckReport:
    """:func:`~ropod_sysid.trajectory.precheck.check` of a run under ``sigma``'s sensor model
    and true values, on the run's own grid."""
    from ropod_sysid.trajectory.precheck import check

    return check(traj, platform, limits, floor, params=sigma.truth_params,  # type: ignore[arg-type]
                 friction=friction, sensors=sigma.sensors)


def _total_error(rep: CheckReport, sigma: SigmaTarget) -> float:
    """Mean log of the targets' predicted √(σ² + bias²) relative to their values, from a
    run's :func:`_check` report."""
    idx = [rep.names.index(n) for n in sigma.names]
    total = np.hypot(rep.std[idx], np.nan_to_num(rep.bias[idx]))
    ok = np.isfinite(total)
    return float(np.mean(np.log(total[ok] / sigma.scale[idx][ok]))) if ok.any() else math.inf


def _family(platform: Platform, duration: float, harmonics: int, t: np.ndarray,
            limits: Limits) -> FourierFamily:
    """The search's :class:`FourierFamily` on the grid t: curvature below the units' and
    1 / (R_min / :data:`CURVATURE_MARGIN`) (002 eq. 26)."""
    r_min = limits.curvature_radius_min
    return FourierFamily(duration, harmonics, t,
                         float(np.linalg.norm(platform.positions, axis=1).max()),
                         limits.pivot_rate_max or 1.5,
                         radius_min=None if r_min is None else r_min / CURVATURE_MARGIN)


def _verify(traj: Trajectory, platform: Platform, limits: Limits,
            floor: Floor) -> tuple[bool, str]:
    """Limits, floor (four variants), the curvature radius (002 eq. 26) and the integrated
    turning rates, flags (a wheel flip with a pivot-rate limit; a wheel at rest, type A,
    always) and wheel rates of a run on its own grid, with its planned own coordinates."""
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.trajectory.curvature import curvature_report

    rates = traj.twist_rates()
    if traj.speed().max() > limits.v_max:
        return False, "speed"
    if traj.acceleration().max() > limits.a_max:
        return False, "acceleration"
    if np.abs(traj.omega).max() > limits.w_max or np.abs(rates[:, 2]).max() > limits.alpha_max:
        return False, "rotation"
    if limits.curvature_radius_min is not None:
        curve = curvature_report(traj.t, traj.twist(), platform.positions,
                                 limits.curvature_radius_min)
        if not curve.ok:
            return False, f"curvature radius {curve.min_radius:.3g} m"
    var = variants(traj)
    off = _off_floor(var, floor)
    if off is not None:
        return False, f"floor ({off})"
    columns = PlatformModel(platform).planned_columns
    if (limits.pivot_rate_max is not None or limits.wheel_rate_max is not None
            or limits.steer_rate_max is not None or columns):
        planned = (np.stack([vt.planned_series(columns) for vt in var.values()])
                   if columns else None)
        pred = predict_angles(traj.t, np.stack([vt.twist() for vt in var.values()]), platform,
                              planned=planned)
        for what, mask in pred.flags.items():  # units without a turning joint: type A
            if mask[..., ~pred.turning_units].any():
                return False, what
        peak = pred.turning_peak
        if limits.pivot_rate_max is not None and (peak > limits.pivot_rate_max
                                                  or pred.flagged):
            return False, f"pivot rate {peak:.2f} rad/s"
        steer = pred.steering_peak
        if limits.steer_rate_max is not None and steer > limits.steer_rate_max:
            return False, f"steering rate {steer:.2f} rad/s"
        wheel = float(np.abs(pred.wheel_rates).max(initial=0.0))
        if limits.wheel_rate_max is not None and wheel > limits.wheel_rate_max:
            return False, f"wheel rate {wheel:.3g} rad/s"
    return True, ""
