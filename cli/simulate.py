"""``ropod-sysid simulate``: a log with known parameters from a setpoint trajectory."""

from __future__ import annotations

import click
import numpy as np

from ropod_sysid.cli.common import (
    INPUT,
    Number,
    given,
    platform_option,
    quiet_option,
    reports_errors,
    writes,
)
from ropod_sysid.control import KD, KI, ModelControl
from ropod_sysid.errors import InputError
from ropod_sysid.io import LOG_SUFFIXES, write_log
from ropod_sysid.io.csvlog import read_numeric_table
from ropod_sysid.io.paramfile import read_parameters, read_truth_parameters
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import DynamicParameters
from ropod_sysid.platform import Platform, load_platform
from ropod_sysid.simulate import (
    ENGINES,
    MAX_DT,
    MIN_COMPILED_STEPS,
    Controller,
    ForceSchedule,
    Sensors,
    check_run,
    simulate,
)
from ropod_sysid.trajectory import read_trajectory_csv

CONTROLS = ("pid", "model")
PID_GAINS = (("kp", "--kp"), ("ki", "--ki"), ("steer_kp", "--steer-kp"),
             ("steer_ki", "--steer-ki"))
MODEL_OPTIONS = (("control_params_path", "--control-params"), ("model_kd", "--model-kd"),
                 ("model_ki", "--model-ki"))


def check_control(control: str) -> None:
    """The options of the other control law are refused in one line, and the model-based
    law needs --control-params (before any work)."""
    if control == "pid":
        for name, option in MODEL_OPTIONS:
            if given(name):
                raise InputError(f"{option}: belongs to the model-based law; give --control "
                                 "model, or leave it out")
        return
    for name, option in PID_GAINS:
        if given(name):
            raise InputError(f"{option}: a gain of the decentralised loops (--control pid); "
                             "the model-based law's gains are --model-kd and --model-ki")
    if not given("control_params_path"):
        raise InputError("--control model: needs --control-params, the controller's "
                         "parameter file (a fit's output, or a flat name: value mapping)")


def control_parameters(path: str, platform: Platform) -> DynamicParameters:
    """The controller's parameters from ``path`` for ``platform``: one-line errors naming the
    file for another platform's file, unknown, missing or non-finite parameters."""
    from ropod_sysid.fitfile import parameters_of

    pfile = read_parameters(path, platform)  # a fit's file, or a flat truth.json
    _, values = parameters_of(pfile, platform, path)
    params = DynamicParameters.from_mapping(values, platform, path)
    params.check_physical(path)
    return params


@click.command("simulate", short_help="Simulate a run with known parameters; write its log.")
@platform_option
@click.option("--params", "params_path", required=True, type=INPUT,
              help="True parameters: a parameter file or a flat name: value mapping.")
@click.option("--trajectory", "traj_path", required=True, type=INPUT,
              help="Setpoint CSV with columns t, vx, vy, omega (base frame).")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Log to write (.csv or .mcap).")
@click.option("--rate", default=200.0, show_default=True,
              help="Log sample rate [Hz]; divides the integration rate 1/--dt.")
@click.option("--dt", default=MAX_DT, show_default=True,
              type=Number(0, MAX_DT, low_open=True, unit="s"),
              help="Integration and control step [s] (RK4, at most 1 ms).")
@click.option("--encoder-counts", type=int, default=None,
              help="Encoder counts per revolution, at least 16 (default: exact angles).")
@click.option("--current-noise", default=0.0, show_default=True,
              help="Current measurement noise, standard deviation [A].")
@click.option("--current-average", is_flag=True,
              help="Log each current as its mean over the log interval centred on the sample "
                   "(an averaging current measurement, or a 1 kHz bus decimated by "
                   "averaging); default: its value at the sample instant, which aliases the "
                   "control loops' fast torques when --rate is below the control rate.")
@click.option("--jitter", default=0.0, show_default=True,
              help="Timestamp jitter, half-width of a uniform distribution [s]; less than half "
                   "the sample step.")
@click.option("--seed", default=0, show_default=True, help="Random seed of the sensor effects.")
@click.option("--force", "force_path", type=INPUT, default=None,
              help="External force schedule CSV: t, F_bx, F_by, T_bz (base frame).")
@click.option("--kp", default=Controller.kp, show_default=True,
              help="Wheel speed loop proportional gain [N m s/rad].")
@click.option("--ki", default=Controller.ki, show_default=True,
              help="Wheel speed loop integral gain [N m/rad].")
@click.option("--torque-limit", default=Controller.torque_limit, show_default=True,
              help="Wheel torque limit [N m].")
@click.option("--steer-kp", default=Controller.steer_kp, show_default=True,
              help="Steering loop derivative gain D_s [N m s/rad] (steered units: PD on the "
                   "steering angle, Stöger et al. (001) eq. 25).")
@click.option("--steer-ki", default=Controller.steer_ki, show_default=True,
              help="Steering loop proportional gain P_s on the angle [N m/rad].")
@click.option("--steer-torque-limit", default=Controller.steer_torque_limit, show_default=True,
              help="Steering torque limit [N m].")
@click.option("--initial-angles", "initial_angles", type=click.Choice(["auto", "zero"]),
              default="auto", show_default=True,
              help="Unit angles at rest. auto: units that turn (swivel pivots) trail the "
                   "first motion; zero: all along the base x axis.")
@click.option("--initial-pivots", "initial_angles", type=click.Choice(["auto", "zero"]),
              hidden=True, help="Old name of --initial-angles.")
@click.option("--engine", type=click.Choice(ENGINES), default="auto", show_default=True,
              help="auto: the compiled loop (numba) when every unit type has a kernel and the "
                   f"run has at least {MIN_COMPILED_STEPS} steps, else numpy; numba: the "
                   "compiled loop; numpy: the vectorised reference (slower). --control model "
                   "runs with numpy.")
@click.option("--control", type=click.Choice(CONTROLS), default="pid", show_default=True,
              help="pid: decentralised loops per actuator (PI on the wheel speeds, PD on "
                   "steering angles; --kp … --steer-ki); model: the centralised model-based "
                   "law of Stöger et al. (001) eq. 26 with the model of --control-params "
                   "(inverse dynamics, feedback of the projected velocity error and its "
                   "integral, torques distributed by W = diag(1/τ_max²) over the limits "
                   "--torque-limit, --steer-torque-limit).")
@click.option("--control-params", "control_params_path", type=INPUT, default=None,
              help="--control model: the controller's parameters (a fit's parameter file or a "
                   "flat name: value mapping), which may differ from --params.")
@click.option("--model-kd", "model_kd", default=KD, show_default=True,
              type=Number(0, None, unit="1/s"),
              help="--control model: velocity gain k_d [1/s] (D = k_d × the projected mass "
                   "matrix).")
@click.option("--model-ki", "model_ki", default=KI, show_default=True,
              type=Number(0, None, unit="1/s²"),
              help="--control model: integral gain k_i [1/s²] (P = k_i × the projected mass "
                   "matrix).")
@quiet_option
@reports_errors
@writes(outputs={"out_path": "--out"},
        inputs={"platform_path": "--platform", "params_path": "--params",
                "traj_path": "--trajectory", "force_path": "--force",
                "control_params_path": "--control-params"})
def command(platform_path: str, params_path: str, traj_path: str, out_path: str, rate: float,
            dt: float, encoder_counts: int | None, current_noise: float,
            current_average: bool, jitter: float, seed: int, force_path: str | None,
            kp: float, ki: float, torque_limit: float,
            steer_kp: float, steer_ki: float, steer_torque_limit: float,
            initial_angles: str, engine: str, control: str, control_params_path: str | None,
            model_kd: float, model_ki: float, quiet: bool) -> None:
    """Simulate a run of the platform under a velocity controller and write its log."""
    if not out_path.lower().endswith(LOG_SUFFIXES):
        raise InputError(f"--out {out_path}: use a .csv or .mcap file name")
    check_control(control)
    if control == "model" and engine == "numba":
        raise InputError("--engine numba: the compiled loop has the decentralised controllers "
                         "only; use --engine numpy or auto with --control model")
    sensors = Sensors(encoder_counts, current_noise, jitter, seed, current_average)
    controller = Controller(kp, ki, torque_limit, steer_kp, steer_ki, steer_torque_limit)
    check_run(rate, dt, controller, sensors)  # before any work
    if given("seed") and not (current_noise > 0 or jitter > 0):
        raise InputError(f"--seed {seed}: seeds the current noise and timestamp jitter, and "
                         "neither is on; give --current-noise or --jitter, or leave out --seed")
    platform = load_platform(platform_path)
    values = read_truth_parameters(params_path, platform)
    params = DynamicParameters.from_mapping(values, platform, params_path)
    params.check_physical(params_path)
    model_control = None
    if control == "model" and control_params_path is not None:
        model_control = ModelControl(control_parameters(control_params_path, platform),
                                     model_kd, model_ki)
    setpoints = read_trajectory_csv(traj_path,
                                    PlatformModel(platform).planned_columns).to_setpoints()
    force = None
    if force_path is not None:
        fc = read_numeric_table(force_path, ["t", "F_bx", "F_by", "T_bz"])
        force = ForceSchedule(fc["t"], np.column_stack([fc["F_bx"], fc["F_by"], fc["T_bz"]]))
    try:
        (result,) = simulate(platform, params, setpoints, rate=rate, dt=dt,
                             controller=controller, sensors=sensors, force=force,
                             initial="auto" if initial_angles == "auto" else None, quiet=quiet,
                             source=out_path, engine=engine, control=model_control)
        finite = bool(np.all(np.isfinite(result.q)))
    except np.linalg.LinAlgError:  # an SVD or solve of the constrained model on inf/NaN
        finite = False
    if not finite:
        raise InputError(f"{traj_path}: the simulation diverged; lower the setpoints or raise "
                         "--torque-limit")
    write_log(result.log, out_path, platform)
    if not quiet:
        click.echo(f"wrote {out_path}: {result.log.n_samples} samples, "
                   f"{result.log.duration:.2f} s at {rate:g} Hz", err=True)
