"""Excitation trajectories: plan, check and optimise identification runs (thesis Sec. VI-A).

A run is a series of base-twist setpoints in the *base* frame — t [s], vx, vy [m/s], ω [rad/s] —
that the robot's velocity controller tracks; its planned pose x, y [m], θ [rad] in the world
frame follows by integration from zero. The thesis identifies on a "typical" run (straights,
corners, rotations, constant velocity and acceleration) repeated in four variants — original,
mirrored (left and right corners swapped), negated (every translation and rotation with a minus
sign) and mirrored-negated — whose stacked regressors are solved together (Sec. VI-A). It keeps
out the transition of a wheel unit from its unstable "pulling" to its stable "pushing"
configuration, which shakes the platform and fits badly; the disturbance observer ignores the
data when a pivot rate exceeds 1.5 rad/s for the same reason (Sec. VII-C).

The unit angles along a planned motion are each unit type's business
(:meth:`UnitType.predict_angles`): the trajectory code asks every group of any mix of types and
names no joint. For smart-wheel (swivel) units the kinematics is (thesis eq. 8a, written in the
base frame): pivot i at r_i = (x_i, y_i)
moves with P_i = (vx − ω y_i, vy + ω x_i); its unit turns towards P_i,

    δ̇_i = |P_i| sin(ψ_i − δ_i) / s_w − ω,        ψ_i = atan2(P_iy, P_ix),

so with the small caster offset s_w the unit trails its pivot (δ_i ≈ ψ_i, stable) and turns as
fast as the direction ψ_i does. A unit flips (δ_i − ψ_i passes ±π/2 on its way to the stable
side) when P_i reverses or passes near zero while turning. Limits, as in the thesis's
experiments: |v| = |(vx, vy)| ≤ v_max, |a| ≤ a_max (the world acceleration of the base origin,
centripetal part included), |ω| ≤ ω_max, |ω̇| ≤ α_max, |δ̇_i| ≤ pivot_rate_max (units with a
turning joint), |β̇_i| ≤ steer_rate_max (units with an actuated steering: the steered wheel, whose
planned steering follows its wheel-centre velocity), optionally |φ̇| ≤ wheel_rate_max for
every driven wheel and the base's curvature radius R = |v|/|ω| ≥ curvature_radius_min wherever
it rotates (002 eq. 26: the centre of rotation outside the footprint, so no wheel on a held leg
comes to rest; by default for platforms with legs). Omni wheels have no turning joint: there
are no wheel flips to plan for.
Steered wheels add constraint rows, which lose rank where all wheel axles lie on one line; the
fit leaves out the base rows near there, and ``check`` reports the time a run spends there.

Modules (every public name is re-exported here):

* :mod:`~ropod_sysid.trajectory.limits` — :class:`Limits`, the floor, :class:`PlanningError`,
  :func:`default_curvature_radius`;
* :mod:`~ropod_sysid.trajectory.setpoints` — :class:`Trajectory`, :func:`integrate_pose` and the
  setpoint CSV (:func:`read_trajectory_csv`, :func:`write_trajectory_csv`);
* :mod:`~ropod_sysid.trajectory.run_variants` — :func:`variant`, :func:`variants`;
* :mod:`~ropod_sysid.trajectory.prediction` — :func:`predict_angles` (every unit type);
* :mod:`~ropod_sysid.trajectory.pivots` — :func:`predict_pivots` (eq. 8a, all-swivel platforms);
* :mod:`~ropod_sysid.trajectory.blends` — minimum-jerk twist programs;
* :mod:`~ropod_sysid.trajectory.typical_run` — :func:`typical`;
* :mod:`~ropod_sysid.trajectory.identifiability` — :func:`conditioning`, :func:`predicted_std`;
* :mod:`~ropod_sysid.trajectory.precheck` — :func:`check` (limits, floor, pivot, steering and
  wheel rates, the curvature radius (:func:`curvature_report`), the time near singular
  configurations (:func:`singular_report`), the predicted
  stacked regressor's condition number and rank and each parameter's predicted standard
  deviation);
* :mod:`~ropod_sysid.trajectory.plotting` — :func:`plot`;
* :mod:`~ropod_sysid.trajectory.fourier` and :mod:`~ropod_sysid.trajectory.excitation` —
  :func:`optimize` (finite Fourier series, Swevers et al.).
"""

from ropod_sysid.trajectory.curvature import (
    MOVING_SPEED,
    CurvatureReport,
    curvature_radius,
    curvature_report,
)
from ropod_sysid.trajectory.excitation import (
    MAX_HARMONICS,
    MAX_LAG,
    OPTIMIZE_DURATION,
    SPEED_WEIGHT,
    OptimizeResult,
    optimize,
)
from ropod_sysid.trajectory.fourier import (
    KAPPA_FRACTION,
    NU_MIN,
    RHO_BETA,
    RHO_KAPPA,
    FourierFamily,
)
from ropod_sysid.trajectory.identifiability import (
    RANK_TOL,
    Conditioning,
    conditioning,
    predicted_std,
)
from ropod_sysid.trajectory.limits import (
    CURVATURE_REACH_FACTOR,
    DEFAULT_FLOOR,
    PIVOT_DESIGN_MARGIN,
    STEER_RATE_MAX,
    Floor,
    Limits,
    PlanningError,
    default_curvature_radius,
)
from ropod_sysid.trajectory.limits import _check_floor as _check_floor
from ropod_sysid.trajectory.pivots import PivotPrediction, predict_pivots, trailing_pivots
from ropod_sysid.trajectory.plotting import plot
from ropod_sysid.trajectory.precheck import (
    CheckReport,
    Finding,
    SingularReport,
    check,
    run_singular_report,
    singular_report,
    true_parameters,
)
from ropod_sysid.trajectory.prediction import (
    Prediction,
    predict_angles,
    steering_points,
    trailing_points,
)
from ropod_sysid.trajectory.run_variants import VARIANT_SIGNS, VARIANTS, variant, variants
from ropod_sysid.trajectory.setpoints import (
    COLUMNS,
    POSE_COLUMNS,
    TWIST_COLUMNS,
    Trajectory,
    integrate_pose,
    read_trajectory_csv,
    trajectory_csv_text,
    write_trajectory_csv,
)
from ropod_sysid.trajectory.typical_run import (
    DESIGN_MARGIN,
    LOBES,
    SIDE_DIRECTIONS,
    SPIN_OFFSETS,
    SPIN_START_MIN,
    TYPICAL_MAX_DURATION,
    typical,
)

__all__ = [
    "COLUMNS", "CURVATURE_REACH_FACTOR", "DEFAULT_FLOOR", "DESIGN_MARGIN", "KAPPA_FRACTION",
    "LOBES", "MAX_HARMONICS",
    "MAX_LAG", "MOVING_SPEED", "NU_MIN", "OPTIMIZE_DURATION", "PIVOT_DESIGN_MARGIN",
    "POSE_COLUMNS", "RANK_TOL", "RHO_BETA", "RHO_KAPPA", "SIDE_DIRECTIONS", "SPEED_WEIGHT",
    "SPIN_OFFSETS", "SPIN_START_MIN", "STEER_RATE_MAX", "TWIST_COLUMNS", "TYPICAL_MAX_DURATION",
    "VARIANTS", "VARIANT_SIGNS",
    "CheckReport", "Conditioning", "CurvatureReport", "Finding", "Floor", "FourierFamily", "Limits",
    "OptimizeResult", "PivotPrediction", "PlanningError", "Prediction", "SingularReport",
    "Trajectory",
    "check", "conditioning", "curvature_radius", "curvature_report",
    "default_curvature_radius", "integrate_pose", "optimize", "plot", "predict_angles",
    "predict_pivots", "predicted_std", "read_trajectory_csv", "run_singular_report",
    "singular_report", "steering_points", "trailing_pivots",
    "trailing_points", "trajectory_csv_text", "true_parameters", "typical",
    "variant", "variants", "write_trajectory_csv",
]
