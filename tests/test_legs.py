"""Wheels on movable legs (002), checked independently of their derivation (L1–L6 of
:mod:`ropod_sysid.model.units.legs`): 002's constraint rows (17) by hand, its eq. (18) corrected,
the constant-leg reduction to the fixed-attachment model, Kane's method with finite-difference
partial velocities, virtual power, energy while the legs slide, and the platform entry."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.io import read_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.params import Parameters, parameter_names
from ropod_sysid.platform import load_platform, platform_from_dict
from ropod_sysid.regressor import Span
from ropod_sysid.simulate import Sensors, derivatives, rk4_step, sensed
from ropod_sysid.trajectory import Trajectory, check, read_trajectory_csv, typical
from ropod_sysid.trajectory.limits import Limits, default_curvature_radius
from ropod_sysid.trajectory.prediction import predict_angles
from tests.conftest import shipped
from tests.test_steered import advanced

R = 0.1
SETTINGS = {"name": "justin", "wheel_radius": R, "torque_constant": 2.0,
            "steer_torque_constant": 10.0, "friction_tanh_gain": 100.0}
CORNERS = (("1", 1, 1), ("2", -1, 1), ("3", -1, -1), ("4", 1, -1))
S2 = float(np.sqrt(0.5))


def justin(hip: float = 0.1, wheel: str = "steered", **extra: object) -> dict:
    """Four wheels of type ``wheel`` on legs along the diagonals from hips at (±hip, ±hip)."""
    units = []
    for n, sx, sy in CORNERS:
        u = {"name": n, "type": wheel, "leg": {"hip": [sx * hip, sy * hip],
                                               "axis": [sx * S2, sy * S2],
                                               "range": [0.37, 0.56]}}
        units.append(u | extra)
    return SETTINGS | {"units": units}


TRUTH = {"m_b": 120.0, "Jzz_b": 9.0, "Jst": 0.12, "Jrot_s": 0.02, "m_leg": 6.0}
LEG_COLS = np.array([2, 5, 8, 11])  # the leg_u channels among the angles
LEG_ROWS = np.array([4, 6, 8, 10])  # λ_u among the generalized coordinates


def random_state(model: PlatformModel, rng: np.random.Generator, n: int = 4
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = rng.normal(size=(n, 3))
    qd = rng.normal(size=(n, model.n_dof))
    angles = rng.uniform(-np.pi, np.pi, size=(n, model.layout.n_angles))
    legs = np.array([g.angles[-1] for g, _ in model.groups])
    angles[:, legs] = rng.uniform(0.37, 0.56, size=(n, legs.size))
    return q, qd, angles


def test_platform_entry_round_trip_and_errors() -> None:
    plat = platform_from_dict(justin(), "<p>")
    assert plat.types == ["steered+leg"]
    assert plat.layout.angle_names[:3] == ("steer_1", "phi_1", "leg_1")
    names = parameter_names(plat)
    assert names[:5] == ["m_b", "Jzz_b", "m_leg", "Jst", "Jrot_s"]
    assert names[-2:] == ["flv_4", "flc_4"]
    d = plat.to_dict()
    assert d["units"][0]["type"] == "steered" and "position" not in d["units"][0]
    assert platform_from_dict(d, "<again>") == plat
    bad = justin()
    bad["units"][0]["position"] = [0.1, 0.1]
    with pytest.raises(InputError, match=r"^<p>: 'units\[0\]' \(unit '1'\): key 'position' "
                       r"with 'leg': the attachment point is hip \+ lambda \* axis; leave out "
                       r"'position'$"):
        platform_from_dict(bad, "<p>")
    bad = justin()
    bad["units"][1]["leg"]["axis"] = [1.0, 1.0]
    with pytest.raises(InputError, match=r"'leg.axis' has length 1.414; give a unit vector "
                       r"\(e.g. \[0.7071, 0.7071\]\)$"):
        platform_from_dict(bad, "<p>")
    bad = justin()
    bad["units"][2]["leg"]["range"] = [0.5, 0.4]
    with pytest.raises(InputError, match=r"'leg.range' is \[0.5, 0.4\]; give \[lmin, lmax\]"):
        platform_from_dict(bad, "<p>")


def test_constraint_rows_are_002_eq_17_and_eq_18_needs_its_factors() -> None:
    """At hip 0 and axis (cos α, sin α) each lateral row is 002 (17): [−sin(θ+β), cos(θ+β),
    Δ, Γ] on (x, y, θ, λ) with Δ = λ cos(α − β), Γ = sin(α − β), and nothing on β. The
    steering angle of (18) with the cos α / sin α factors of (12) satisfies it; as printed
    (λθ̇ without them) it does not."""
    model = PlatformModel(platform_from_dict(justin(hip=0.0), "<p>"))
    rng = np.random.default_rng(17)
    q, qd, angles = random_state(model, rng)
    st = model.state(q, qd, angles)
    g, _ = model.constraints(st, exact=True)
    alpha = np.array([np.pi / 4, 3 * np.pi / 4, -3 * np.pi / 4, -np.pi / 4])
    beta, lam = angles[:, [0, 3, 6, 9]], angles[:, LEG_COLS]
    th = q[:, 2:3]
    assert np.allclose(g[:, :, 0], -np.sin(th + beta), atol=1e-14)
    assert np.allclose(g[:, :, 1], np.cos(th + beta), atol=1e-14)
    assert np.allclose(g[:, :, 2], lam * np.cos(alpha - beta), atol=1e-14)
    for i, row in enumerate(LEG_ROWS):
        assert np.allclose(g[:, i, row], np.sin(alpha[i] - beta[:, i]), atol=1e-14)
        others = np.setdiff1d(np.arange(3, model.n_dof), [row])
        assert np.abs(g[:, i, others]).max() < 1e-14
    # (18): world twist and leg rates → steering angle
    xd, yd, w = qd[:, 0:1], qd[:, 1:2], qd[:, 2:3]
    lam_d = qd[:, LEG_ROWS]
    vx = np.cos(th) * xd + np.sin(th) * yd
    vy = -np.sin(th) * xd + np.cos(th) * yd
    fixed = np.arctan2(vy + lam * np.cos(alpha) * w + np.sin(alpha) * lam_d,
                       vx - lam * np.sin(alpha) * w + np.cos(alpha) * lam_d)
    printed = np.arctan2(vy + lam * w + np.sin(alpha) * lam_d,
                         vx - lam * w + np.cos(alpha) * lam_d)

    def lateral(b: np.ndarray) -> np.ndarray:
        return (-np.sin(th + b) * xd + np.cos(th + b) * yd + lam * np.cos(alpha - b) * w
                + np.sin(alpha - b) * lam_d)

    assert np.abs(lateral(fixed)).max() < 1e-12
    assert np.abs(lateral(printed)).min() > 1e-3


def test_a_constant_leg_is_the_fixed_attachment_model() -> None:
    """With every leg held (λ̇ = 0) at one extension the legged model restricted to (q_b, β)
    is the fixed steered platform at P = hip + λ a whose base carries the four leg masses
    (m_b + 4 m_leg, J_zz,b + m_leg Σ|P|²: the points are symmetric), to 1e-12: M_dir, b_dir,
    B_τ, the friction torques, the constraints, M_dir q̈ − b_dir and the kinetic energy (the
    identification columns are those equations' coefficients:
    :func:`test_regressor_is_linear_in_the_parameters`)."""
    lam = 0.43
    legged = PlatformModel(platform_from_dict(justin(), "<legs>"))
    pts = [[sx * (0.1 + lam * S2), sy * (0.1 + lam * S2)] for _, sx, sy in CORNERS]
    fixed = PlatformModel(platform_from_dict(SETTINGS | {"units": [
        {"name": n, "type": "steered", "position": p}
        for (n, _, _), p in zip(CORNERS, pts, strict=True)]}, "<fixed>"))
    rng = np.random.default_rng(5)
    q, qd, angles = random_state(legged, rng)
    angles[:, LEG_COLS] = lam
    qd[:, LEG_ROWS] = 0.0
    keep_rows = np.array([0, 1, 2, 3, 5, 7, 9])
    keep_ang = np.setdiff1d(np.arange(12), LEG_COLS)
    friction = {f"{f}_{u}": -0.3 * (i + 1) for i, f in enumerate(("fdv", "fdc", "fsv", "fsc"))
                for u in "1234"}
    sum_p2 = float(np.sum(np.square(pts)))
    p_legs = Parameters(TRUTH | friction)
    p_fixed = Parameters({**TRUTH, "m_b": TRUTH["m_b"] + 4 * TRUTH["m_leg"],
                          "Jzz_b": TRUTH["Jzz_b"] + TRUTH["m_leg"] * sum_p2} | friction)
    st_l = legged.state(q, qd, angles)
    st_f = fixed.state(q, qd[:, keep_rows], angles[:, keep_ang])
    e_l, e_f = legged.direct_eom(st_l, p_legs), fixed.direct_eom(st_f, p_fixed)
    ix = np.ix_(np.arange(4), keep_rows, keep_rows)
    assert np.abs(e_l.m_dir[ix] - e_f.m_dir).max() < 1e-12
    assert np.abs(e_l.b_dir[:, keep_rows] - e_f.b_dir).max() < 1e-12
    assert np.abs(e_l.b_tau[:, keep_rows] - e_f.b_tau).max() < 1e-12
    assert np.abs(e_l.tau_f - e_f.tau_f).max() < 1e-12
    g_l, c_l = legged.constraints(st_l, exact=True)
    g_f, c_f = fixed.constraints(st_f, exact=True)
    assert np.abs(g_l[:, :, keep_rows] - g_f).max() < 1e-12
    assert np.abs(c_l - c_f).max() < 1e-12
    assert np.allclose(legged.kinetic_energy(st_l, p_legs), fixed.kinetic_energy(st_f, p_fixed),
                       rtol=1e-13)
    qdd = rng.normal(size=qd.shape)
    qdd[:, LEG_ROWS] = 0.0
    lhs_l = np.einsum("nij,nj->ni", e_l.m_dir, qdd) - e_l.b_dir
    lhs_f = np.einsum("nij,nj->ni", e_f.m_dir, qdd[:, keep_rows]) - e_f.b_dir
    assert np.abs(lhs_l[:, keep_rows] - lhs_f).max() < 1e-12


@pytest.mark.parametrize("wheel", ["steered", "swivel", "omni"])
def test_regressor_is_linear_in_the_parameters(wheel: str) -> None:
    """A_ID,ext m = P (M_dir q̈ − b_dir − f_f − B_τ τ_f) at random states, for every wheel
    type on legs: the identification columns (Tᵀ A_ID,L, the leg's mass and friction) are
    those of the equations of motion."""
    extra = {"heading": 0.4} if wheel == "omni" else {}
    settings = {"wheel_distance": 0.08, "caster_offset": 0.02, "hub_com_offset": -0.005}
    model = PlatformModel(platform_from_dict(justin(wheel=wheel, **extra) | settings, "<p>"))
    rng = np.random.default_rng(7)
    n = 5
    q = rng.normal(size=(n, 3))
    qd = rng.normal(size=(n, model.n_dof))
    angles = rng.uniform(-np.pi, np.pi, size=(n, model.layout.n_angles))
    leg = np.array([g.angles[-1] for g, _ in model.groups])
    angles[:, leg] = rng.uniform(0.37, 0.56, size=(n, 4))
    rates = rng.normal(size=angles.shape)
    names = model.parameter_names()
    values = {nm: rng.uniform(0.05, 2.0) * (-1 if nm[0] == "f" else 1) for nm in names}
    params = Parameters(values)
    st = model.state(q, qd[:, :3], angles, rates)
    qdd = rng.normal(size=(n, model.n_dof))
    eom = model.direct_eom(st, params)
    need = (np.einsum("nij,nj->ni", eom.m_dir, qdd) - eom.b_dir
            - np.einsum("nca,na->nc", eom.b_tau, eom.tau_f))
    if eom.f_f is not None:
        need = need - eom.f_f
    proj = model.identification_projector(st)
    if proj is not None:
        need = np.einsum("nij,nj->ni", proj, need)
    a = model.a_id_ext(st, qdd)
    assert np.allclose(np.einsum("ndp,p->nd", a, params.vector(names)), need, atol=1e-10)


@pytest.mark.parametrize("wheel", ["steered", "omni"])
def test_kane_equations_and_virtual_power_equal_the_model(wheel: str) -> None:
    """Kane's method from the bodies' speeds alone: the base (ṙ, θ̇), each leg's point mass at
    r + R(hip + λ a) (its velocity ṙ + θ̇ S R P + λ̇ R a), each unit's turn θ̇ + β̇ and its
    wheel's spin t·v_P / r. Partial velocities by finite differences in q̇, accelerations by central
    differences in time: the generalized inertia forces equal M_dir q̈ − b_dir (L3, L6);
    virtual power gives B_τ."""
    extra = {"heading": 0.4} if wheel == "omni" else {}
    model = PlatformModel(platform_from_dict(justin(wheel=wheel, **extra), "<p>"))
    rng, h = np.random.default_rng(11), 1e-5
    params = TRUTH | {"Jrot_o": 0.004}
    q, qd, angles = random_state(model, rng, 3)
    qdd = rng.normal(size=qd.shape)

    def speeds(q: np.ndarray, qd: np.ndarray, ang: np.ndarray) -> tuple[np.ndarray, ...]:
        out = [qd[:, 0], qd[:, 1], qd[:, 2]]
        inertia = [params["m_b"], params["m_b"], params["Jzz_b"]]
        for (g, unit), rows in zip(model.groups, model.rows, strict=True):
            lam = ang[:, g.angles[-1]]  # ṙ + θ̇ S R P + λ̇ R a of the point r + R P
            lam_rate = qd[:, rows[-1]]
            p = unit.leg.point(lam)  # type: ignore[attr-defined]
            a = np.broadcast_to(unit.leg.axis, p.shape)  # type: ignore[attr-defined]
            c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
            rp = np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]], axis=-1)
            ra = np.stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1]], axis=-1)
            vel = (qd[:, :2] + qd[:, 2:3] * np.stack([-rp[:, 1], rp[:, 0]], axis=-1)
                   + lam_rate[:, None] * ra)
            out += [vel[:, 0], vel[:, 1]]
            inertia += [params["m_leg"]] * 2
            a = ang[:, g.angles]
            if wheel == "steered":
                psi = q[:, 2] + a[:, 0]
                out.append(qd[:, 2] + qd[:, rows[3]])
                inertia.append(params["Jst"])
                jr = params["Jrot_s"]
            else:
                psi = q[:, 2] + 0.4
                jr = params["Jrot_o"]
            out.append((np.cos(psi) * vel[:, 0] + np.sin(psi) * vel[:, 1]) / R)
            inertia.append(jr)
        return np.stack(out, axis=-1), np.array(inertia)

    sp, inertia = speeds(q, qd, angles)
    partial = np.stack([speeds(q, qd + 1e-3 * np.eye(model.n_dof)[r], angles)[0] - sp
                        for r in range(model.n_dof)], axis=1) / 1e-3
    q_f, ang_f = advanced(model, q, qd, angles, h)
    q_b, ang_b = advanced(model, q, qd, angles, -h)
    acc = (speeds(q_f, qd + h * qdd, ang_f)[0] - speeds(q_b, qd - h * qdd, ang_b)[0]) / (2 * h)
    kane = np.einsum("nrs,s,ns->nr", partial, inertia, acc)
    st = model.state(q, qd, angles)
    eom = model.direct_eom(st, params, "per-wheel")
    model_side = np.einsum("nij,nj->ni", eom.m_dir, qdd) - eom.b_dir
    assert np.allclose(kane, model_side, rtol=1e-6, atol=1e-6), wheel
    tau = rng.normal(size=(3, model.layout.n_currents))
    power = (tau * st.actuator_rate).sum(axis=1)
    assert np.allclose(np.einsum("nda,na,nd->n", st.b_tau, tau, qd), power)


def test_energy_is_conserved_while_the_legs_slide() -> None:
    """No torque, no friction: the platform coasting with its legs sliding (q̇ in the null
    space of the constraints, every λ̇ ≠ 0) keeps its kinetic energy (RK4, 1 ms, 0.3 s) and
    its constraints, and the legs do move."""
    model = PlatformModel(platform_from_dict(justin(), "<p>"))
    params = Parameters(TRUTH)
    rng = np.random.default_rng(2)
    q = np.zeros((1, 3))
    angles = np.array([[0.3, 0.0, 0.45, 2.0, 0.0, 0.5, -2.2, 0.0, 0.4, -0.6, 0.0, 0.5]])
    st = model.state(q, np.zeros((1, model.n_dof)), angles)
    g, _ = model.constraints(st, exact=True)
    _, _, vt = np.linalg.svd(g[0])
    null = vt[g.shape[1]:]
    qd = (null.T @ rng.normal(size=null.shape[0]))[None]
    qd *= 0.3 / np.abs(qd[:, LEG_ROWS]).min()  # legs at 0.3 m/s or faster
    tau = np.zeros((1, model.layout.n_currents))
    e0 = model.kinetic_energy(model.state(q, qd, angles), params)[0]
    lam0 = angles[0, LEG_COLS].copy()
    worst, moved = 0.0, np.zeros(4)
    for _ in range(300):
        q, qd, angles = rk4_step(
            lambda *y: derivatives(model, params, "per-wheel", *y[:3], y[3]),
            (q, qd, angles), 1e-3, (tau,) * 4)
        g, _ = model.constraints(model.state(q, qd, angles), exact=True)
        worst = max(worst, float(np.abs(np.einsum("ncd,nd->nc", g, qd)).max()))
        moved = np.maximum(moved, np.abs(angles[0, LEG_COLS] - lam0))
    e1 = model.kinetic_energy(model.state(q, qd, angles), params)[0]
    assert abs(e1 - e0) < 1e-7 * e0
    assert worst < 1e-7
    assert moved.min() > 0.01  # every leg slid by a centimetre or more


LEGS_DATA = Path(__file__).resolve().parent.parent / "datasets" / "legs"
LIMITS = Limits(v_max=0.4, w_max=0.5)
FLOOR = (-5.0, 5.0, -4.0, 4.0)


def test_typical_plans_the_legs_and_check_names_what_they_determine(tmp_path: Path) -> None:
    """``trajectory typical`` plans every leg's extension within its range (the setpoint CSV's
    ``leg_u`` columns, read back exactly); ``check`` then finds m_leg only with the wheels'
    spin inertia (m_leg + Jrot_s/r², as the fit names it) and the legs' friction determined.
    Without the legs' plan (they hold) m_leg is not determined apart from the base, nor is the
    leg friction."""
    platform = load_platform(LEGS_DATA / "platform.yaml")
    traj = typical(duration=20.0, v_max=0.4, w_max=0.5, pivot_rate_max=None, floor=FLOOR,
                   platform=platform)
    assert sorted(traj.planned) == ["leg_1", "leg_2", "leg_3", "leg_4"]
    for lam in traj.planned.values():
        assert lam.min() >= 0.37 and lam.max() <= 0.56
        assert np.ptp(lam) > 0.05  # the legs do move
    path = tmp_path / "run.csv"
    traj.write_csv(path)
    back = read_trajectory_csv(path, PlatformModel(platform).planned_columns)
    for c, v in traj.planned.items():
        assert np.array_equal(back.planned[c], v)
    params = {"m_b": 126.0, "Jzz_b": 8.0}
    moving = check(traj, platform, LIMITS, FLOOR, params=params)
    assert moving.combinations["m_leg"] == "m_leg +100·Jrot_s"
    assert not any(n.startswith("fl") for n in moving.combinations)
    held = check(dataclasses.replace(traj, planned={}), platform, LIMITS, FLOOR, params=params)
    assert "m_leg" in held.combinations and held.combinations["m_leg"] != "m_leg +100·Jrot_s"
    assert all(f"flv_{u}" in held.combinations or not np.isfinite(
        held.std[held.names.index(f"flv_{u}")]) for u in "1234")


def test_the_shipped_leg_sample_is_fitted_within_its_sigma() -> None:
    """The shipped Justin-like sample (legs moving, 250 Hz, 2¹⁴ counts, 30 mA): the rank
    analysis names m_leg + 100·J_rot,s (the wheels' spin inertia moves with the legs) and
    nothing else; every value it determines lies within 3σ of the truth's, but for J_st: its
    rows see the steering loops' fast torques, point-sampled, and it comes out 1.9 % high
    (3.6σ, a discretisation bias the σ does not include; as on the steered sample), asserted
    within 3 %."""
    platform = load_platform(LEGS_DATA / "platform.yaml")
    logs = [read_log(p, platform) for p in sorted(LEGS_DATA.glob("*.csv.gz"))]
    truth = json.loads((LEGS_DATA / "truth.json").read_text())
    sol = fit_logs(logs, platform).solution
    assert sol.combinations["m_leg"] == "m_leg +100·Jrot_s"
    assert sorted(sol.combinations) == ["Jrot_s", "m_leg"]
    value = dict(zip(sol.names, sol.values, strict=True))
    expect = dict(zip(sol.names, sol.combination_of(Parameters(truth).vector(sol.names)),
                      strict=True))
    for name, std in zip(sol.names, sol.std, strict=True):
        if name == "Jst":
            assert value[name] == pytest.approx(expect[name], rel=0.03)
        elif np.isfinite(std) and std > 0:
            assert abs(value[name] - expect[name]) < 3 * std, name
    assert value["m_leg"] == pytest.approx(truth["m_leg"] + 100 * truth["Jrot_s"], rel=0.03)


def test_a_leg_that_cancels_the_base_at_its_wheel_is_flagged() -> None:
    """002 §III-C's leg case of a type-A singularity: the base translating along a leg's axis
    while that leg retracts at the same speed leaves its wheel at rest (its steering angle
    undefined): the prediction flags that unit there and nowhere else; a held leg is not."""
    platform = load_platform(LEGS_DATA / "platform.yaml")
    model = PlatformModel(platform)
    t = np.linspace(0.0, 2.0, 201)
    speed = 0.1
    axis = np.array([S2, S2])  # unit 1's leg
    twist = np.zeros((1, t.size, 3))
    twist[0, :, :2] = speed * axis
    legs = np.full((1, t.size, 4), 0.465)
    legs[0, :, 0] = 0.465 - speed * (t - 1.0)  # retracting as fast as the base moves
    pred = predict_angles(t, twist, model, planned=legs)
    flag = pred.flags["wheel at rest (type A)"][0]
    assert flag[5:-5, 0].all() and not flag[:, 1:].any()
    held = predict_angles(t, twist, model)
    assert not held.flags["wheel at rest (type A)"].any()


def test_cli_simulates_the_planned_legs_and_converts_their_logs(tmp_path: Path) -> None:
    """``simulate`` reads a setpoint CSV's ``leg_u`` columns and drives the legs to them
    through the wheels (each within 1 cm of its plan over a short, quick run); ``convert`` carries
    the extensions through a JSON MCAP and back exactly; ``inspect`` shows their range."""
    from click.testing import CliRunner

    from ropod_sysid.cli.main import main

    t = np.linspace(0.0, 0.3, 16)
    x = np.clip(t / 0.25, 0.0, 1.0)
    ramp = x**3 * (10 - 15 * x + 6 * x * x)
    rows = ["t,vx,vy,omega,leg_1,leg_2,leg_3,leg_4"]
    plan = 0.465 + 0.012 * ramp
    rows += [f"{a},{0.2 * r},0,{0.1 * r},{p},{p},0.465,{2 * 0.465 - p}"
             for a, r, p in zip(t, ramp, plan, strict=True)]
    traj = tmp_path / "run.csv"
    traj.write_text("\n".join(rows) + "\n")
    run = CliRunner()
    out = tmp_path / "log.csv"
    res = run.invoke(main, ["simulate", "--platform", str(LEGS_DATA / "platform.yaml"),
                            "--params", str(LEGS_DATA / "truth.json"), "--trajectory",
                            str(traj), "--out", str(out), "--rate", "250",
                            "--torque-limit", "30", "--steer-kp", "10", "--steer-ki", "200",
                            "--steer-torque-limit", "28", "--quiet"])
    assert res.exit_code == 0, res.output
    platform = load_platform(LEGS_DATA / "platform.yaml")
    log = read_log(out, platform)
    legs = log.angles[:, [platform.layout.angle_names.index(f"leg_{u}") for u in "1234"]]
    want = np.stack([np.interp(log.t, t, c) for c in (plan, plan, np.full(t.size, 0.465),
                                                      2 * 0.465 - plan)], axis=1)
    assert np.abs(legs - want).max() < 0.01  # 8.6 mm: passive legs, pushed by the base's
    # acceleration and held only through the wheels' loops
    assert np.ptp(legs[:, 0]) > 0.008  # the legs did move
    mcap = tmp_path / "log.mcap"
    back = tmp_path / "back.csv"
    for src, dst in ((out, mcap), (mcap, back)):
        res = run.invoke(main, ["convert", str(src), str(dst), "--platform",
                                str(LEGS_DATA / "platform.yaml"), "--quiet"])
        assert res.exit_code == 0, res.output
    again = read_log(back, platform)
    assert np.array_equal(again.angles, log.angles) and np.array_equal(again.t, log.t)
    res = run.invoke(main, ["inspect", str(out), "--platform", str(LEGS_DATA / "platform.yaml")])
    assert res.exit_code == 0 and "leg_1" in res.output, res.output


def circle_run(radius: float, speed: float = 0.2, duration: float = 4.0) -> Trajectory:
    """From rest along a circle of ``radius`` [m] (0: a rotation in place at 0.3 rad/s) at
    ``speed`` [m/s] and back to rest, minimum-jerk ramps of 1 s."""
    t = np.linspace(0.0, duration, int(duration / 0.01) + 1)
    x = np.clip(np.minimum(t, duration - t), 0.0, 1.0)
    ramp = x**3 * (10 - 15 * x + 6 * x * x)
    vx = speed * ramp if radius else 0.0 * ramp
    omega = speed * ramp / radius if radius else 0.3 * ramp
    return Trajectory.from_twist(t, vx, 0.0 * t, omega)


def test_check_flags_a_curvature_radius_below_its_limit() -> None:
    """002 eq. 26: R = |v|/|ω| ≥ R_min while the base moves. ``check`` reports the least R
    over the moving time and the fraction below R_min, and flags each stretch below it (the
    least R in it, all variants); a rotation in place (R = 0) and a circle of 0.5 m break
    0.81 m, a circle of 1 m does not, and without the limit nothing is flagged."""
    platform = load_platform(LEGS_DATA / "platform.yaml")
    params = {"m_b": 126.0, "Jzz_b": 8.0}
    limits = Limits(v_max=0.4, w_max=0.5, pivot_rate_max=None, curvature_radius_min=0.81)
    tight = check(circle_run(0.5), platform, limits, FLOOR, params=params)
    assert not tight.ok
    (finding,) = [f for f in tight.findings if f.what == "curvature radius R [m] (moving)"]
    assert finding.below and finding.peak == pytest.approx(0.5) and finding.limit == 0.81
    # the moving time: some attachment point at 1 cm/s or faster (0.16 s into the ramp)
    assert finding.variant == "all" and (finding.t_start, finding.t_end) == (0.16, 3.84)
    assert finding.text().startswith("curvature radius R [m] (moving): 0.5 < 0.81 from t=")
    assert tight.curvature is not None and tight.curvature.moving_fraction == 1.0
    assert tight.to_dict()["curvature"]["min_radius"] == pytest.approx(0.5)
    spin = check(circle_run(0.0), platform, limits, FLOOR, params=params)
    assert spin.curvature is not None and spin.curvature.min_radius == 0.0
    assert not spin.ok and spin.to_dict()["ok"] is False
    wide = check(circle_run(1.0), platform, limits, FLOOR, params=params)
    assert wide.ok, [f.text() for f in wide.findings]
    assert wide.curvature is not None and wide.curvature.min_radius == pytest.approx(1.0)
    assert wide.curvature.moving_fraction == 0.0
    free = check(circle_run(0.5), platform, dataclasses.replace(limits,
                                                                curvature_radius_min=None),
                 FLOOR, params=params)
    assert free.ok and free.to_dict()["limits"]["curvature_radius_min"] is None


def test_typical_keeps_the_curvature_radius() -> None:
    """With R_min (002 eq. 26; the platform's default: 1.3 × the legs' reach, 0.81 m here)
    ``typical`` rotates only about points at least R_min away — no rotation in place — and
    its legs' plan brings no wheel to rest (type A): ``check`` finds nothing, and the base
    still turns (the least R is finite)."""
    platform = load_platform(LEGS_DATA / "platform.yaml")
    r_min = default_curvature_radius(platform)
    assert r_min == 0.81
    assert default_curvature_radius(load_platform(LEGS_DATA.parent / "steered"
                                                  / "platform.yaml")) is None
    traj = typical(duration=20.0, v_max=0.4, w_max=0.5, pivot_rate_max=None, floor=FLOOR,
                   platform=platform, curvature_radius_min=r_min)
    rep = check(traj, platform, dataclasses.replace(LIMITS, pivot_rate_max=None,
                                                    curvature_radius_min=r_min),
                FLOOR, params={"m_b": 126.0, "Jzz_b": 8.0})
    assert rep.ok, [f.text() for f in rep.findings]
    assert rep.curvature is not None and r_min <= rep.curvature.min_radius < 1.5
    assert np.abs(traj.omega).max() > 0.2 and np.ptp(traj.planned["leg_1"]) > 0.05


def test_cli_curvature_radius_default_and_errors(tmp_path: Path) -> None:
    """The CLI's R_min defaults to the platform's (0.81 m with legs): the shipped legs run,
    planned before the limit, starts with a rotation in place and is flagged (exit 0, ``ok``
    false, the finding in the JSON); ``--curvature-radius-min 0`` lifts the limit; a bad value
    is a one-line error that writes nothing."""
    from click.testing import CliRunner

    from ropod_sysid.cli.main import main

    run = CliRunner()
    args = ["trajectory", "check", str(LEGS_DATA / "trajectory" / "original.csv.gz"),
            "--platform", str(LEGS_DATA / "platform.yaml"), "--params",
            str(LEGS_DATA / "truth.json"), "--v-max", "0.4", "--w-max", "0.5", "--floor",
            "-5", "5", "-4", "4", "--json"]
    res = run.invoke(main, args)
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["ok"] is False and data["limits"]["curvature_radius_min"] == 0.81
    assert data["curvature"]["min_radius"] == 0.0 and data["curvature"]["ok"] is False
    assert 0.5 < data["curvature"]["moving_fraction"] < 1.0
    assert [f["what"] for f in data["findings"]] == ["curvature radius R [m] (moving)"]
    res = run.invoke(main, [*args, "--curvature-radius-min", "0"])
    data = json.loads(res.output)
    assert data["ok"] is True and data["curvature"]["limit"] is None
    # with a sensor model: the recipe check's shift is not predicted by default (no compiled
    # simulator for legs), and the text says so
    res = run.invoke(main, [*args[:-1], "--current-noise", "0.03"])
    assert res.exit_code == 0, res.output
    assert res.output.rstrip().endswith(
        "note: the recipe check's shift, which fit folds into σ by default, is not predicted: "
        f"the simulator has no compiled kernel for {LEGS_DATA / 'platform.yaml'}'s units; "
        "--recipe-check simulates the run in numpy (minutes)")
    out = tmp_path / "x"
    for value in ("-1", "nan"):
        res = run.invoke(main, ["trajectory", "typical", "--platform",
                                str(LEGS_DATA / "platform.yaml"), "--out", str(out),
                                "--curvature-radius-min", value])
        lines = [x for x in res.output.splitlines() if x.strip()]
        assert res.exit_code == 2 and len(lines) == 1, res.output
        assert lines[0] == (f"error: --curvature-radius-min {value}: must be a finite number "
                            "in [0, 1000] m")
    assert not out.exists()


def test_optimize_plans_the_legs_within_every_limit(tmp_path: Path) -> None:
    """``trajectory optimize`` searches the legs' extensions with the base motion: the
    written CSVs carry every leg's plan, within its range and below the legs' rate limit,
    moving, and not typical's plan on the same base motion; ``check`` on the written run (all
    four variants) finds no limit broken — R_min (the platform's default) and the steering
    rate among them — and no wheel at rest (type A), and the legs determine m_leg (with the
    wheels' spin inertia) and their friction."""
    from click.testing import CliRunner

    from ropod_sysid.cli.main import main
    from ropod_sysid.model.units.legs import LEG_RATE_MAX
    from ropod_sysid.trajectory.setpoints import with_planned

    out = tmp_path / "opt"
    res = CliRunner().invoke(main, ["trajectory", "optimize", "--platform",
                                    str(LEGS_DATA / "platform.yaml"), "--duration", "6",
                                    "--harmonics", "1", "--maxiter", "1", "--objective", "cond",
                                    "--v-max", "0.4", "--w-max", "0.5", "--floor", "-5", "5",
                                    "-4", "4", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "note: planned with the base motion (on its progress while the base moves): leg 1 ±" \
        in res.output
    platform = load_platform(LEGS_DATA / "platform.yaml")
    columns = PlatformModel(platform).planned_columns
    back = {p.stem: read_trajectory_csv(p, columns) for p in out.glob("*.csv")}
    assert sorted(back) == ["mirrored", "mirrored_negated", "negated", "original"]
    run = back["original"]
    typical_plan = with_planned(dataclasses.replace(run, planned={}), platform)
    for c in columns:
        lam = run.planned[c]
        assert lam.min() >= 0.37 and lam.max() <= 0.56 and np.ptp(lam) > 0.01, c
        assert np.abs(np.gradient(lam, run.t)).max() <= LEG_RATE_MAX
        assert not np.allclose(lam, typical_plan.planned[c])
        for vt in back.values():  # the variants share the plan
            assert np.array_equal(vt.planned[c], lam)
    limits = Limits(v_max=0.4, w_max=0.5, curvature_radius_min=0.81)
    rep = check(run, platform, limits, FLOOR, params=json.loads((LEGS_DATA / "truth.json")
                                                                .read_text()))
    assert rep.ok, [f.text() for f in rep.findings]
    assert rep.curvature is not None and rep.curvature.min_radius >= 0.81
    assert rep.combinations["m_leg"] == "m_leg +100·Jrot_s"
    legs = [rep.names.index(f"{f}_{u}") for f in ("flv", "flc") for u in "1234"]
    assert np.isfinite(rep.relative_std[legs]).all() and rep.relative_std[legs].max() < 1.0


def test_the_sigma_objective_weighs_the_legs_motion() -> None:
    """``optimize``'s σ objective sees the legs' plan: on the same base motion, legs that
    sweep more of their range at their fastest determine m_leg and the leg friction better
    (a lower objective) than legs that barely move; with a target that names no leg
    parameter the legs' plan still changes the run but hardly the objective's value."""
    from ropod_sysid.noise import SensorNoise
    from ropod_sysid.trajectory.excitation import _Objective, sigma_target

    platform = load_platform(LEGS_DATA / "platform.yaml")
    truth = json.loads((LEGS_DATA / "truth.json").read_text())
    limits = Limits(v_max=0.4, w_max=0.5, pivot_rate_max=None, curvature_radius_min=0.81)
    leg_names = ["m_leg", *(f"{f}_{u}" for f in ("flv", "flc") for u in "1234")]
    values = {}
    for target in (leg_names, ["m_b"]):
        sig = sigma_target(platform, target, "per-wheel", SensorNoise(), truth)
        obj = _Objective(platform, 10.0, 2, limits, FLOOR, "sigma", "per-wheel", 10.0, 2.0,
                         sig)
        base = np.random.default_rng(1).uniform(-1, 1, obj.n_base)
        wide = np.concatenate([base, np.tile([1.0, 1.0, 0.0], 4)])
        small = np.concatenate([base, np.tile([0.0, 0.0, 0.0], 4)])
        values[target[0]] = obj(np.stack([wide, small], axis=1))
    wide_v, small_v = values["m_leg"]
    assert wide_v < small_v - 2.0  # σ smaller by more than a factor e² (geometric mean)
    assert abs(values["m_b"][0] - values["m_b"][1]) < 0.2


@pytest.fixture(scope="module")
def legs_exact() -> tuple:
    """The shipped exact logs of the Justin-like base (legs moving): platform, truth, logs."""
    return shipped("legs-exact")


def truth_of(sol, truth: Parameters) -> dict[str, float]:
    """The truth of each value the fit reports (combinations as the fit forms them)."""
    return dict(zip(sol.names, sol.combination_of(truth.vector(sol.names)), strict=True))


@pytest.mark.parametrize("smoother", ["loess", "quartic"])
def test_exact_leg_logs_determine_every_value_within_one_percent(legs_exact,
                                                                 smoother: str) -> None:
    """Exact 250 Hz logs of the Justin-like base with its legs moving (1 ms control step, each
    current the mean over its log interval): the rank analysis names m_leg + 100·J_rot,s and
    nothing else, and every value it determines lies within 1 % of the truth's — the legs'
    viscous and Coulomb friction, m_leg's lump, the base's mass and inertia, the drives' and
    steerings' friction (measured within 0.1 %) — but J_st in the default fit: +1.3 % (9σ),
    the three-point differences' attenuation of β̈ (asserted within 2 %); with ``--smoother
    quartic`` (five-point differences) J_st +0.5 %, every value within 1 %."""
    platform, truth, logs = legs_exact
    span = Span.parse(None).with_smoother(smoother)
    sol = fit_logs(logs, platform, FitOptions(span=span)).solution
    assert sol.combinations["m_leg"] == "m_leg +100·Jrot_s"
    assert sorted(sol.combinations) == ["Jrot_s", "m_leg"]
    expect = truth_of(sol, truth)
    for name, value, std in zip(sol.names, sol.values, sol.std, strict=True):
        if np.isfinite(std):
            rel = 0.02 if name == "Jst" and smoother == "loess" else 0.01
            assert value == pytest.approx(expect[name], rel=rel), name


def test_noisy_leg_logs_are_covered_by_sigma(legs_exact) -> None:
    """The same logs as 2¹⁴-count angle encoders (the legs' extensions exact) and 30 mA current
    noise record them: every value the plain fit determines within 3σ of the truth's (seeds
    1–4: within 1.65σ; with ``--encoder-counts`` J_st comes to 2.6–3.0σ)."""
    platform, truth, logs = legs_exact
    rng = np.random.default_rng(1)
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03)
    sol = fit_logs([sensed(log, platform, sensors, rng) for log in logs], platform).solution
    expect = truth_of(sol, truth)
    for name, value, std in zip(sol.names, sol.values, sol.std, strict=True):
        if np.isfinite(std):
            assert abs(value - expect[name]) < 3 * std, (name, value, expect[name], std)
