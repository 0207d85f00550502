"""``ropod-sysid trajectory``: plan identification runs (typical, optimised) and check them."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from ropod_sysid.cli.common import (
    INPUT,
    POSITIVE_INT,
    SEED,
    Number,
    given,
    json_text,
    positive,
    quiet_option,
    reports_errors,
    writes,
)
from ropod_sysid.errors import InputError
from ropod_sysid.forked import PROCESSES_ENV
from ropod_sysid.platform import Platform, load_platform
from ropod_sysid.trajectory import MAX_HARMONICS, OPTIMIZE_DURATION, TYPICAL_MAX_DURATION
from ropod_sysid.trajectory.excitation import OBJECTIVES
from ropod_sysid.trajectory.limits import CURVATURE_REACH_FACTOR, STEER_RATE_MAX

OUT_FILES = {"original": "original.csv", "mirrored": "mirrored.csv",
             "negated": "negated.csv", "mirrored_negated": "mirrored_negated.csv"}


def limit_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """--v-max, --a-max, --w-max, --alpha-max, --pivot-rate-max/--no-pivot-limit,
    --steer-rate-max, --wheel-rate-max, --curvature-radius-min, --floor."""
    options = [
        click.option("--v-max", default=1.0, show_default=True, type=positive(),
                     help="Speed limit |v| [m/s]."),
        click.option("--a-max", default=1.0, show_default=True, type=positive(),
                     help="Acceleration limit |a| of the base origin [m/s²]."),
        click.option("--w-max", default=1.0, show_default=True, type=positive(),
                     help="Rotation rate limit |ω| [rad/s]."),
        click.option("--alpha-max", default=1.0, show_default=True, type=positive(),
                     help="Rotational acceleration limit |ω̇| [rad/s²]."),
        click.option("--pivot-rate-max", default=1.5, show_default=True, type=positive(),
                     help="Pivot rate limit |δ̇| [rad/s] of units with a pivot (swivel; keeps "
                          "wheel flips out)."),
        click.option("--no-pivot-limit", is_flag=True,
                     help="Do not limit the pivot rates."),
        click.option("--steer-rate-max", default=STEER_RATE_MAX, show_default=True,
                     type=positive("rad/s"),
                     help="Steering rate limit |β̇| [rad/s] of units with an actuated steering "
                          "(steered; default 195.95 °/s, Stöger et al. (001)'s vehicle)."),
        click.option("--wheel-rate-max", default=None, type=positive("rad/s"),
                     help="Rate limit |φ̇| of every driven wheel [rad/s] (any unit type; not "
                          "the steering motors) [default: none]."),
        click.option("--curvature-radius-min", default=None, type=Number(0, 1000, unit="m"),
                     help="Least curvature radius R = |v|/|ω| of the base wherever it rotates "
                          "while moving [m] (Robuffo Giordano et al. (002) eq. 26: the centre "
                          "of rotation stays outside the footprint, so no wheel on a held leg "
                          "comes to rest, a type-A singularity; a rotation in place has R = 0 "
                          "and is not allowed); 0: no limit [default: for a platform with legs "
                          f"{CURVATURE_REACH_FACTOR:g} × the farthest reach of a leg's "
                          "attachment point, rounded up to the cm (0.81 m for "
                          "datasets/legs; 002: 0.82 m), none without legs]."),
        click.option("--floor", nargs=4, type=float, default=None,
                     metavar="XMIN XMAX YMIN YMAX",
                     help="Floor rectangle for the base origin [m], start at (0, 0) "
                          "[default: -3 3 -2 2]."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def _limits(v_max: float, a_max: float, w_max: float, alpha_max: float,
            pivot_rate_max: float, no_pivot_limit: bool, wheel_rate_max: float | None,
            steer_rate_max: float = STEER_RATE_MAX, curvature_radius_min: float | None = None,
            platform: Platform | None = None) -> Any:
    """The limits of the options; ``--curvature-radius-min`` not given: the platform's default
    (:func:`~ropod_sysid.trajectory.limits.default_curvature_radius`), 0: none."""
    from ropod_sysid.trajectory import Limits
    from ropod_sysid.trajectory.limits import default_curvature_radius

    if no_pivot_limit and given("pivot_rate_max"):
        raise InputError(f"--pivot-rate-max {pivot_rate_max:g} and --no-pivot-limit: give one "
                         "of them")
    if curvature_radius_min is None:
        r_min = None if platform is None else default_curvature_radius(platform)
    else:
        r_min = curvature_radius_min or None
    return Limits(v_max, a_max, w_max, alpha_max, None if no_pivot_limit else pivot_rate_max,
                  wheel_rate_max, steer_rate_max, r_min)


def _singular_note(traj: Any, platform: Platform | None) -> str | None:
    """One line on the time the run spends near singular configurations (platforms with
    constraint rows), else None."""
    if platform is None:
        return None
    from ropod_sysid.trajectory import run_singular_report

    rep = run_singular_report(traj, platform)
    if rep is None:
        return None
    return (f"near singular configurations (the fit leaves out the base rows): "
            f"{100 * rep.moving_fraction.max():.1f} % of the moving time, longest "
            f"{rep.longest.max():.2f} s (see trajectory check)")


def _curvature_note(traj: Any, platform: Platform | None, limits: Any) -> str | None:
    """One line on the run's least curvature radius against the limit, None without one."""
    if limits.curvature_radius_min is None:
        return None
    from ropod_sysid.platform import ropod_platform
    from ropod_sysid.trajectory.curvature import curvature_report

    rep = curvature_report(traj.t, traj.twist(), (platform or ropod_platform()).positions,
                           limits.curvature_radius_min)
    least = f"{rep.min_radius:.3g} m" if rep.min_radius < float("inf") else "inf"
    return (f"curvature radius while moving: least {least} (R_min "
            f"{limits.curvature_radius_min:g} m, 002 eq. 26: no rotation in place)")


def _floor(floor: tuple[float, ...] | None) -> tuple[float, float, float, float]:
    from ropod_sysid.trajectory import DEFAULT_FLOOR, _check_floor

    if not floor:
        return DEFAULT_FLOOR
    try:
        return _check_floor(floor)
    except InputError as exc:
        raise InputError(f"--floor: {exc}") from None


def _write_variants(traj: Any, out: str) -> list[Path]:
    """Write the run and its variants into ``out`` (made and checked by ``writes``)."""
    from ropod_sysid.trajectory import variants

    written = []
    for name, vt in variants(traj).items():
        target = Path(out) / OUT_FILES[name]
        try:
            vt.write_csv(target)
        except OSError as exc:
            raise InputError(f"{target}: cannot write ({exc.strerror or exc})") from None
        written.append(target)
    return written


def sensor_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """The sensor model of the logs a run will give (:class:`ropod_sysid.noise.
    SensorNoise`)."""
    for option in reversed([
        click.option("--current-noise", type=Number(0, 100, unit="A"), default=None,
                     help="σ of each motor-current sample [A] [default with a sensor model: "
                          "0.03]."),
        click.option("--encoder-counts", type=Number(16, 2**40, integer=True), default=None,
                     help="Counts per revolution of the wheel and pivot encoders [default "
                          "with a sensor model: 16384]."),
        click.option("--exact-encoders", is_flag=True,
                     help="Encoders without quantisation (only current noise)."),
        click.option("--log-rate", default=100.0, show_default=True, type=positive("Hz"),
                     help="Sample rate of the logs the fit will use [Hz]."),
    ]):
        func = option(func)
    return func


def _sensors(current_noise: float | None, encoder_counts: int | None, exact: bool,
             log_rate: float, default: bool) -> Any:
    """The sensor model of the options; None (white noise on b_ID) when none is given and
    ``default`` is False."""
    from ropod_sysid.noise import SensorNoise

    if exact and encoder_counts is not None:
        raise InputError("--exact-encoders and --encoder-counts: give one of them")
    if not default and current_noise is None and encoder_counts is None and not exact:
        return None
    return SensorNoise(0.03 if current_noise is None else current_noise,
                       None if exact else (encoder_counts or 2**14), log_rate)


def _params(path: str | None, platform: Platform) -> Any:
    if path is None:
        return None
    from ropod_sysid.io.paramfile import read_truth_parameters

    return read_truth_parameters(path, platform)


def _platform(path: str | None) -> Platform | None:
    return None if path is None else load_platform(path)


@click.group("trajectory", short_help="Plan identification runs and check them.")
def command() -> None:
    """Plan identification runs (thesis Sec. VI-A) and check them before the robot drives.

    Setpoint CSVs: t, vx, vy, omega (base frame) and the planned pose x, y, theta (world frame,
    start at 0); ``simulate --trajectory`` and the robot's velocity controller take them.
    """


def output_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """--dt and --out of the commands that write a run and its variants."""
    func = click.option("--out", "out", required=True, type=click.Path(file_okay=False),
                        help="Directory for original.csv, mirrored.csv, negated.csv, "
                             "mirrored_negated.csv.")(func)
    return click.option("--dt", default=0.005, show_default=True,
                        type=Number(0, 0.1, low_open=True, unit="s"),
                        help="Setpoint sample interval [s].")(func)


@command.command("typical", short_help="A typical run (corners, rotations, lateral moves).")
@limit_options
@click.option("--duration", default=60.0, show_default=True,
              type=Number(0, TYPICAL_MAX_DURATION, low_open=True, unit="s"),
              help="Length of the run [s].")
@click.option("--platform", "platform_path", type=INPUT, default=None,
              help="Platform YAML (unit types and geometry: pivots to plan for, wheel rates) "
                   "[default: the ropod].")
@click.option("--seed", default=0, show_default=True, type=SEED,
              help="0: the reference run; other seeds vary speeds and lobe order.")
@output_options
@quiet_option
@reports_errors
@writes(inputs={"platform_path": "--platform"}, folders={"out": "--out"},
        folder_files=OUT_FILES.values())
def typical_command(v_max: float, a_max: float, w_max: float, alpha_max: float,
                    pivot_rate_max: float, no_pivot_limit: bool, steer_rate_max: float,
                    wheel_rate_max: float | None, curvature_radius_min: float | None,
                    floor: tuple[float, ...], duration: float,
                    platform_path: str | None, seed: int, dt: float, out: str,
                    quiet: bool) -> None:
    """Write a typical run and its three variants (mirrored, negated, mirrored-negated)."""
    from ropod_sysid.trajectory import typical

    platform = _platform(platform_path)
    limits = _limits(v_max, a_max, w_max, alpha_max, pivot_rate_max, no_pivot_limit,
                     wheel_rate_max, steer_rate_max, curvature_radius_min, platform)
    traj = typical(duration, limits.v_max, limits.a_max, limits.w_max, limits.alpha_max,
                   _floor(floor), dt, seed, limits.pivot_rate_max, platform,
                   limits.wheel_rate_max, limits.steer_rate_max,
                   limits.curvature_radius_min)
    written = _write_variants(traj, out)
    if not quiet:
        click.echo(f"typical run: {traj.duration:g} s, {traj.n_samples} setpoints; wrote "
                   + ", ".join(str(p) for p in written))
        note = _singular_note(traj, platform)
        if note:
            click.echo(note)
        note = _curvature_note(traj, platform, limits)
        if note:
            click.echo(note)


@command.command("optimize", short_help="An optimised run (Fourier series, least predicted σ).")
@limit_options
@click.option("--platform", "platform_path", required=True, type=INPUT,
              help="Platform YAML (unit types and geometry for the regressor and the "
                   "predicted pivot and wheel rates).")
@click.option("--duration", default=30.0, show_default=True,
              type=Number(OPTIMIZE_DURATION[0], OPTIMIZE_DURATION[1], unit="s"),
              help="Length of the run [s].")
@click.option("--harmonics", default=5, show_default=True,
              type=Number(1, MAX_HARMONICS, integer=True),
              help="Harmonics of each Fourier series.")
@click.option("--objective", type=click.Choice(OBJECTIVES), default=OBJECTIVES[0],
              show_default=True,
              help="sigma: least predicted error of the --target parameters under the sensor "
                   "model (the fit's σ and the encoders' bias, as 'trajectory check' predicts "
                   "them); cond: least condition number of the column-scaled regressor; "
                   "logdet: its largest log-determinant.")
@click.option("--target", default="inertial", show_default=True,
              help="With --objective sigma: inertial (masses and inertias), all, or "
                   "comma-separated parameter names.")
@sensor_options
@click.option("--params", "params_path", type=INPUT, default=None,
              help="True parameter values for --objective sigma (relative errors); m_b and "
                   "Jzz_b alone: the rest each unit type's typical values [default: thesis "
                   "fixed masses, smart-wheel platforms only].")
@click.option("--seed", default=0, show_default=True, type=SEED, help="Random seed.")
@click.option("--maxiter", default=25, show_default=True, type=POSITIVE_INT,
              help="Generations of the search (differential evolution).")
@click.option("--processes", default=None, type=POSITIVE_INT,
              help="Processes that evaluate the candidates; the run found does not depend "
                   f"on it [default: 2 on two CPUs or more, else 1; or ${PROCESSES_ENV}].")
@output_options
@quiet_option
@reports_errors
@writes(inputs={"platform_path": "--platform", "params_path": "--params"},
        folders={"out": "--out"}, folder_files=OUT_FILES.values())
def optimize_command(v_max: float, a_max: float, w_max: float, alpha_max: float,
                     pivot_rate_max: float, no_pivot_limit: bool, steer_rate_max: float,
                     wheel_rate_max: float | None, curvature_radius_min: float | None,
                     floor: tuple[float, ...], platform_path: str, duration: float,
                     harmonics: int, objective: str, target: str, current_noise: float | None,
                     encoder_counts: int | None, exact_encoders: bool, log_rate: float,
                     params_path: str | None, seed: int, maxiter: int,
                     processes: int | None, dt: float, out: str, quiet: bool) -> None:
    """Search a run that determines the --target parameters best (or whose stacked regressor
    is best conditioned); write it and its variants."""
    from ropod_sysid.trajectory import optimize

    platform = load_platform(platform_path)
    limits = _limits(v_max, a_max, w_max, alpha_max, pivot_rate_max, no_pivot_limit,
                     wheel_rate_max, steer_rate_max, curvature_radius_min, platform)
    sensors = _sensors(current_noise, encoder_counts, exact_encoders, log_rate, default=True)
    params = _params(params_path, platform)
    targets: str | list[str] = (target if target in ("inertial", "all")
                                else [t.strip() for t in target.split(",") if t.strip()])
    result = optimize(platform, duration, harmonics, objective, seed, maxiter, limits,
                      _floor(floor), progress=not quiet, dt=dt, target=targets,
                      sensors=sensors, params=params, processes=processes)
    written = _write_variants(result.trajectory, out)
    if not quiet:
        click.echo(f"optimised run: {result.trajectory.duration:g} s, condition number "
                   f"{result.condition_number:.4g} (rank {result.rank}, identifiable "
                   f"subspace), {result.evaluations} candidates in {result.seconds:.1f} s")
        if result.targets:
            click.echo(f"predicted for {sensors.describe()} (trajectory check): "
                       + ", ".join(f"{n} σ {100 * r:.3g} %, bias "
                                   f"{100 * result.target_bias[n]:+.3g} %"
                                   for n, r in result.targets.items()))
        for note in result.notes:
            click.echo(f"note: {note}")
        singular = _singular_note(result.trajectory, platform)
        if singular:
            click.echo(singular)
        curvature = _curvature_note(result.trajectory, platform, limits)
        if curvature:
            click.echo(curvature)
        click.echo("wrote " + ", ".join(str(p) for p in written))


@command.command("check", short_help="Limits, floor, pivot, steering and wheel rates, "
                                     "singular time, predicted accuracy.")
@click.argument("traj_path", metavar="TRAJ.csv", type=INPUT)
@click.option("--platform", "platform_path", required=True, type=INPUT,
              help="Platform YAML (geometry).")
@limit_options
@click.option("--noise", default=1.0, show_default=True, type=positive(),
              help="White noise σ on b_ID for the predicted standard deviations [N, N m], "
                   "unless a sensor model is given (--current-noise, --encoder-counts).")
@sensor_options
@click.option("--friction", type=click.Choice(["per-wheel", "shared", "body"]),
              default="per-wheel", show_default=True,
              help="Friction coefficients per wheel, shared, or per body axis.")
@click.option("--params", "params_path", type=INPUT, default=None,
              help="True parameter values for relative stds; m_b and Jzz_b alone: the rest "
                   "each unit type's typical values [default: thesis fixed masses, smart-wheel "
                   "platforms only].")
@click.option("--recipe-check/--no-recipe-check", default=None,
              help="Also predict the shift that fit's recipe check folds into σ (its default "
                   "on logs of up to 1,000,000 samples): the four variants simulated without "
                   "sensor noise at --log-rate and fitted with the check, about 1-2 s (the "
                   "first run after installing compiles the simulator). Default: on with a "
                   "sensor model (--current-noise, --encoder-counts, --exact-encoders) where "
                   "fit would check the run's logs and the simulator is compiled.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Plot of the path and the setpoints (.png or .svg).")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@reports_errors
@writes(outputs={"plot_path": "--plot"},
        inputs={"traj_path": "TRAJ.csv", "platform_path": "--platform",
                "params_path": "--params"})
def check_command(traj_path: str, platform_path: str, v_max: float, a_max: float, w_max: float,
                  alpha_max: float, pivot_rate_max: float, no_pivot_limit: bool,
                  steer_rate_max: float, wheel_rate_max: float | None,
                  curvature_radius_min: float | None, floor: tuple[float, ...], noise: float,
                  current_noise: float | None, encoder_counts: int | None,
                  exact_encoders: bool, log_rate: float, friction: str,
                  params_path: str | None, recipe_check: bool | None, plot_path: str | None,
                  as_json: bool) -> None:
    """Check a setpoint CSV before a run: limits broken and where, pivot rates and wheel flips
    (units with a pivot), steering rates (steered units), wheel rates (every driven wheel), the
    least curvature radius while moving (with a limit: platforms with legs), the time near
    singular configurations (platforms with constraint rows: the fit leaves out the
    base rows there), the predicted condition number and rank of the four variants' stacked
    regressor, and the predicted standard deviation of every parameter. Findings are reported,
    not errors (exit 0)."""
    from ropod_sysid.trajectory import check, plot, read_trajectory_csv

    if plot_path is not None and Path(plot_path).suffix.lower() not in (".png", ".svg"):
        raise InputError(f"--plot {plot_path}: use a .png or .svg file name")
    from ropod_sysid.model import PlatformModel

    platform = load_platform(platform_path)
    limits = _limits(v_max, a_max, w_max, alpha_max, pivot_rate_max, no_pivot_limit,
                     wheel_rate_max, steer_rate_max, curvature_radius_min, platform)
    traj = read_trajectory_csv(traj_path, PlatformModel(platform).planned_columns)
    params = _params(params_path, platform)
    fl = _floor(floor)
    sensors = _sensors(current_noise, encoder_counts, exact_encoders, log_rate, default=False)
    from ropod_sysid.trajectory.recipe_shift import predicted_by_default

    recipe, why_not = (recipe_check, None) if recipe_check is not None else \
        predicted_by_default(traj, platform, params, friction, log_rate, sensors is not None)
    report = check(traj, platform, limits, fl, noise, params, friction, log_rate,
                   sensors=sensors, recipe=recipe, quiet=False)
    if plot_path is not None:
        plot(traj, plot_path, fl, limits, platform)
    if as_json:
        click.echo(json_text(report.to_dict()))
    else:
        click.echo(report.text())
        if why_not:
            click.echo(f"\n{why_not}")
        if plot_path is not None:
            click.echo(f"\nplot: {plot_path}")
