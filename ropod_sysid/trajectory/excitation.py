"""Optimal excitation: a finite Fourier series run searched for identifiability (Swevers et al.).

:func:`optimize` searches the coefficients of a run of
:class:`~ropod_sysid.trajectory.fourier.FourierFamily` with scipy's differential evolution for
the best condition number (or log-determinant) of the stacked regressor A_ID,ext of the four
variants (Sec. VI-A, VI-C), unit angles in each type's quasi-steady closed form
(:meth:`UnitType.quasi_steady_angles`: swivel units trailing their pivots, eq. 8a; omni wheels
integrating their rates), within the limits [m/s, m/s², rad/s, rad/s², and optionally the wheel
rates] and the floor [m]. Any mix of unit types.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.platform import Platform
from ropod_sysid.trajectory.fourier import FourierFamily, _scaled_twist
from ropod_sysid.trajectory.identifiability import _world_motion, conditioning
from ropod_sysid.trajectory.limits import (
    DEFAULT_FLOOR,
    PIVOT_DESIGN_MARGIN,
    Floor,
    Limits,
    PlanningError,
    _check_floor,
)
from ropod_sysid.trajectory.precheck import stacked_regressor
from ropod_sysid.trajectory.prediction import _variant_prediction, predict_angles
from ropod_sysid.trajectory.run_variants import VARIANT_SIGNS, VARIANTS, _off_floor, variants
from ropod_sysid.trajectory.setpoints import Trajectory

OPTIMIZE_DURATION = (5.0, 600.0)  # optimize(): shortest and longest run [s]
MAX_HARMONICS = 20  # optimize(): most harmonics of each Fourier series
SPEED_WEIGHT = 0.5  # optimize(): weight of −log(mean speed / v_max) in the objective
MAX_LAG = 0.35  # optimize(): sin of the largest quasi-steady lag of a unit behind its pivot


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


class _Objective:
    """Vectorised objective of :func:`optimize` over a population of coefficient vectors."""

    def __init__(self, platform: Platform, duration: float, harmonics: int, limits: Limits,
                 floor: Floor, objective: str, friction: str, grid_rate: float,
                 eval_rate: float) -> None:
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
        r_max = float(np.linalg.norm(self.positions, axis=1).max())
        self.family = FourierFamily(duration, harmonics, self.t, r_max,
                                    limits.pivot_rate_max or 1.5)
        step = max(int(round(grid_rate / eval_rate)), 1)
        self.eval_idx = np.arange(step // 2 + 1, n, step)  # interior samples (not at rest)
        self.rank: int | None = None
        self.evaluations = 0

    def twist(self, coef: np.ndarray, margin: float = 0.95,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Twist and its rate (S, N, 3) at the largest speed scale s_v within the limits and the
        floor (all four variants) times ``margin``, and s_v (S,)."""
        return _scaled_twist(self.family, coef, self.limits, self.floor, self.t, margin)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Objective values (S,) for coefficients x (D, S) (scipy's vectorised layout)."""
        coef = np.atleast_2d(np.asarray(x, float).T)
        out = np.empty(coef.shape[0])
        for k in range(0, coef.shape[0], 64):
            out[k:k + 64] = self._batch(coef[k:k + 64])
        self.evaluations += coef.shape[0]
        return out

    def _batch(self, coef: np.ndarray) -> np.ndarray:
        tw, twd, _ = self.twist(coef)
        signs = np.array([VARIANT_SIGNS[v] for v in VARIANTS])  # (4, 3)
        tw_v = tw[:, None] * signs[None, :, None, :]
        twd_v = twd[:, None] * signs[None, :, None, :]
        pred = predict_angles(self.t, tw_v, self.model, twist_rates=twd_v)
        assert pred.lag is not None
        lag = np.abs(pred.lag[:, :2]).max(axis=(1, 2, 3))  # negated variants: the same
        penalty = np.maximum(lag / MAX_LAG - 1.0, 0.0)
        if self.limits.pivot_rate_max is not None:
            peak = np.abs(pred.turning[:, :2]).max(axis=(1, 2, 3))
            penalty += np.maximum(peak / (PIVOT_DESIGN_MARGIN * self.limits.pivot_rate_max)
                                  - 1.0, 0.0)
        if self.limits.wheel_rate_max is not None:
            wheel = np.abs(pred.actuator_rates).max(axis=(1, 2, 3))
            penalty += np.maximum(wheel / (PIVOT_DESIGN_MARGIN * self.limits.wheel_rate_max)
                                  - 1.0, 0.0)
        idx = self.eval_idx
        q, qd, qdd = _world_motion(self.t, tw_v, twd_v)
        n_s = coef.shape[0]
        # angle rates from the constraints (the swivel's eq. 8a) at the quasi-steady angles:
        # consistent kinematics, so the structural rank deficiency shows exactly
        st = self.model.state(q[:, :, idx].reshape(-1, 3), qd[:, :, idx].reshape(-1, 3),
                              pred.angles[:, :, idx].reshape(n_s * 4 * idx.size, -1))
        a = self.model.a_id_ext(st, qdd[:, :, idx].reshape(-1, 3),
                                self.friction)  # type: ignore[arg-type]
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
        return value + 10.0 * penalty + 100.0 * penalty**2


def optimize(platform: Platform, duration: float = 30.0, harmonics: int = 5,
             objective: str = "cond", seed: int = 0, maxiter: int = 25,
             limits: Limits | None = None, floor: Sequence[float] = DEFAULT_FLOOR,
             progress: bool = False, dt: float = 0.005, popsize: int = 4,
             friction: str = "per-wheel") -> OptimizeResult:
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
      subspace, maximised.

    Pivot rates (units with a turning joint) and, with a wheel-rate limit, wheel rates above
    80 % of their limit, and quasi-steady lags of a unit behind its pivot with
    sin > 0.35 (a unit cannot follow a pivot that barely moves), are penalised; −0.5 log(mean
    speed / v_max) is added as a tie-breaker towards brisk runs, which the column-scaled
    regressor cannot see. scipy's differential evolution searches
    the coefficients (seeded, vectorised over the population); the best candidate whose limits,
    floor and pivot rates integrated on the fine grid all hold is returned.

    Parameters
    ----------
    platform : unit types and geometry for the regressor and the predicted angles
    duration : length of the run [s]; harmonics : H, harmonics per DOF (base period = duration)
    objective : ``"cond"`` or ``"logdet"``; seed : random seed (repeatable)
    maxiter : generations of the search; popsize : population = popsize × 3(2H+1) candidates
    limits, floor : as for :func:`typical`; progress : progress bar on stderr (terminal only)
    dt : sample interval of the returned setpoints [s]; friction : friction model of A_ID,ext

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
    if objective not in ("cond", "logdet"):
        raise InputError(f"unknown objective {objective!r}; use cond or logdet")
    if isinstance(harmonics, bool) or not isinstance(harmonics, int) \
            or not 1 <= harmonics <= MAX_HARMONICS:
        raise InputError(f"harmonics must be an integer from 1 to {MAX_HARMONICS}, got "
                         f"{harmonics!r}")
    lo, hi = OPTIMIZE_DURATION
    if not (isinstance(duration, int | float) and lo <= duration <= hi):
        raise InputError(f"duration must be between {lo:g} and {hi:g} s, got {duration!r}")
    if isinstance(maxiter, bool) or not isinstance(maxiter, int) or maxiter < 1:
        raise InputError(f"maxiter must be a positive integer, got {maxiter!r}")
    check_variant(friction)
    t_start = time.monotonic()
    obj = _Objective(platform, float(duration), harmonics, limits, floor, objective, friction,
                     grid_rate=10.0, eval_rate=2.0)
    dim = obj.family.n_coefficients
    generations = 0
    with Progress(maxiter, "optimize", quiet=not progress) as bar:
        def callback(*_args: object, **_kw: object) -> None:
            nonlocal generations
            generations += 1
            bar.update(1)

        res = scipy.optimize.differential_evolution(
            obj, [(-1.0, 1.0)] * dim, seed=seed, maxiter=maxiter, popsize=popsize, tol=0.0,
            polish=False, vectorized=True, updating="deferred", init="latinhypercube",
            callback=callback)
    fine_t = np.linspace(0.0, duration, int(round(duration / dt)) + 1)
    fam = FourierFamily(duration, harmonics, fine_t,
                        float(np.linalg.norm(platform.positions, axis=1).max()),
                        limits.pivot_rate_max or 1.5)
    notes: list[str] = []
    why_first = ""
    chosen = None
    for rank_k, k in enumerate(np.argsort(res.population_energies)[:12]):
        coef = res.population[k]
        _, _, s_v = obj.twist(coef[None])
        tw, _, _ = _scaled_twist(fam, coef[None], limits, floor, fine_t, 0.95, s_v)
        traj = Trajectory.from_twist(fine_t, tw[0, :, 0], tw[0, :, 1], tw[0, :, 2])
        ok, why = _verify(traj, platform, limits, floor)
        if ok:
            chosen = (coef, traj, float(s_v[0]), float(res.population_energies[k]))
            if rank_k:
                notes.append(f"{rank_k} better candidate(s) broke a limit on the fine grid "
                             f"({why_first}); took the next")
            break
        why_first = why_first or why
    if chosen is None:
        raise PlanningError(f"no optimised run within the limits ({why_first}); try another "
                            "seed, more maxiter or a longer duration")
    coef, traj, s_v, value = chosen
    model = PlatformModel(platform)
    cond = conditioning(stacked_regressor(*_variant_prediction(traj, model), model,
                                          friction)[0])
    return OptimizeResult(traj, objective, value, cond.condition_number, cond.rank,
                          obj.rank or 0, coef.reshape(3, -1), s_v, obj.evaluations,
                          generations, time.monotonic() - t_start, notes)


def _verify(traj: Trajectory, platform: Platform, limits: Limits,
            floor: Floor) -> tuple[bool, str]:
    """Limits, floor (four variants) and the integrated turning rates, flags and wheel rates
    of a run on its own grid."""
    rates = traj.twist_rates()
    if traj.speed().max() > limits.v_max:
        return False, "speed"
    if traj.acceleration().max() > limits.a_max:
        return False, "acceleration"
    if np.abs(traj.omega).max() > limits.w_max or np.abs(rates[:, 2]).max() > limits.alpha_max:
        return False, "rotation"
    var = variants(traj)
    off = _off_floor(var, floor)
    if off is not None:
        return False, f"floor ({off})"
    if limits.pivot_rate_max is not None or limits.wheel_rate_max is not None:
        pred = predict_angles(traj.t, np.stack([vt.twist() for vt in var.values()]), platform)
        peak = pred.turning_peak
        if limits.pivot_rate_max is not None and (peak > limits.pivot_rate_max
                                                  or pred.flagged):
            return False, f"pivot rate {peak:.2f} rad/s"
        wheel = float(np.abs(pred.actuator_rates).max())
        if limits.wheel_rate_max is not None and wheel > limits.wheel_rate_max:
            return False, f"wheel rate {wheel:.3g} rad/s"
    return True, ""
