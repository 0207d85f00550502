"""The omni-wheel unit type (004, 5DPO): closed forms and independent re-derivations.

Each check derives the quantity a second way (the paper's matrices written out by hand, finite
differences of wheel-centre positions, Kane's method with numerical partial velocities, the
robot-frame Newton equations, energy along an RK4 integration) instead of repeating the module.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.model import base
from ropod_sysid.model.base import (
    BODY_FRICTION,
    body_friction_columns,
    body_friction_force,
    body_velocity,
)
from ropod_sysid.model.units import UNIT_TYPES
from ropod_sysid.model.units.omni import OmniSpec, OmniUnits

PLATFORM = Path(__file__).resolve().parents[1] / "datasets" / "omni" / "platform.yaml"
D, R, M, J = 0.089, 0.0325, 2.34, 0.0228  # 004 Table III
# 004 Table III friction, in the contract's sign (added, so negative when dissipative)
PAPER_BODY = {"fbv_x": -0.4978, "fbv_y": -0.6763, "fbv_w": -0.0141,
              "fbc_x": -1.8738, "fbc_y": -2.2198, "fbc_w": -0.1385}


def five_dpo() -> OmniUnits:
    return OmniUnits.from_platform_dict(yaml.safe_load(PLATFORM.read_text()), str(PLATFORM))


def three_wheel() -> OmniUnits:
    """A three-wheeled robot, wheels at 30°, 150°, 270°, one of them clockwise and larger."""
    ang = np.radians([30.0, 150.0, 270.0])
    specs = [OmniSpec(f"w{i}", (0.12 * np.cos(a), 0.12 * np.sin(a)), a + np.pi / 2, 0.03, 0.2)
             for i, a in enumerate(ang)]
    specs[2] = OmniSpec("w2", specs[2].position, specs[2].heading - np.pi, 0.04, 0.2)
    return OmniUnits(specs, 10.0)


PLATFORMS = {"5dpo": five_dpo, "three": three_wheel}


def states(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 3)) * [1.0, 1.0, 3.0]
    qd = rng.normal(size=(n, 3)) * [0.5, 0.5, 2.0]
    qdd = rng.normal(size=(n, 3))
    return q, qd, qdd


def rot(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (N, 2, 2)


def rim_rate(units: OmniUnits, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """φ̇ from first principles: the velocity of each wheel centre x_b + R(θ) p_i along q̇
    (a complex-step derivative, exact to rounding), projected on the rolling direction
    R(θ) h_i, over r_i."""
    def centres(qq: np.ndarray) -> np.ndarray:
        return qq[:, None, :2] + np.einsum("nab,kb->nka", rot(qq[:, 2]), units.positions)

    h = 1e-30
    vel = centres(q + 1j * h * qd).imag / h
    hdg = np.stack([np.cos(units.headings), np.sin(units.headings)], -1)
    hw = np.einsum("nab,kb->nka", rot(q[:, 2]), hdg)
    return (vel * hw).sum(-1) / units.r


def m_dir(units: OmniUnits, data, params: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    m_add, b_dir = units.mass_terms(data, params)
    return base.m_b(params["m_b"], params["Jzz_b"], m_add.shape[0]) + m_add, b_dir


def forward(units: OmniUnits, q: np.ndarray, qd: np.ndarray, params: dict[str, float],
            tau: np.ndarray, variant: str = "per-wheel") -> np.ndarray:
    """q̈_b of eq. 65 for the omni group: M_dir⁻¹ (B_τ (τ + τ_f) + B_Fb F_f + b_dir)."""
    data = units.kinematics(q, qd)
    mm, b_dir = m_dir(units, data, params)
    rhs = np.einsum("nck,nk->nc", data.b_tau, tau + units.friction_torques(data, params,
                                                                          variant)) + b_dir
    if variant == "body":
        rhs += body_friction_force(q[:, 2], qd, params, units.alpha)
    return np.linalg.solve(mm, rhs[..., None])[..., 0]


# ------------------------------------------------------------------ kinematics
def test_jacobian_is_paper_eq2_and_its_pseudo_inverse_eqs3_5() -> None:
    units = five_dpo()
    assert units.n_units == 4 and UNIT_TYPES["omni"] is OmniUnits
    # 004 eq. 2: (v0, v1, v2, v3) = H (v, vn, w); eq. 1 maps the world twist to (v, vn, w)
    h = np.array([[0, 1, D], [-1, 0, D], [0, -1, D], [1, 0, D]], float)
    q, qd, _ = states(50)
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    eq1 = np.zeros((50, 3, 3))
    eq1[:, 0, 0], eq1[:, 0, 1], eq1[:, 1, 0], eq1[:, 1, 1] = c, s, -s, c
    eq1[:, 2, 2] = 1.0
    data = units.kinematics(q, qd)
    np.testing.assert_allclose(R * data.jac, h @ eq1, atol=1e-15)
    np.testing.assert_allclose(R * units.actuator_rates(q, qd),
                               np.einsum("kc,ncd,nd->nk", h, eq1, qd), atol=1e-14)
    # 004 eqs. 3–5: v = (v3 − v1)/2, vn = (v0 − v2)/2, w = Σ v_i / (4 d)
    eqs3_5 = np.array([[0, -0.5, 0, 0.5], [0.5, 0, -0.5, 0], [1 / (4 * D)] * 4])
    np.testing.assert_allclose(np.linalg.pinv(R * data.jac[0] @ eq1[0].T), eqs3_5, atol=1e-12)


@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_jacobian_against_the_differentiated_wheel_centres(make) -> None:
    units = make()
    q, qd, _ = states(40, seed=1)
    fd = rim_rate(units, q, qd)
    np.testing.assert_allclose(units.actuator_rates(q, qd), fd, rtol=1e-12, atol=1e-12)
    data = units.kinematics(q, qd)
    np.testing.assert_allclose(data.wheel_rate, fd, rtol=1e-12, atol=1e-12)
    # J̇ q̇ (O2) is the rate of change of J along the motion, at fixed q̇
    h = 1e-6
    j_plus = units.kinematics(q + h * qd, qd).jac
    j_minus = units.kinematics(q - h * qd, qd).jac
    np.testing.assert_allclose(data.jac_dot_qd,
                               np.einsum("nkc,nc->nk", (j_plus - j_minus) / (2 * h), qd),
                               rtol=1e-7, atol=1e-7)


@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_constraint_rows_give_odometry_by_least_squares(make) -> None:
    units = make()
    q, qd, _ = states(30, seed=2)
    a, b = units.constraint_rows(None, units.actuator_rates(q, qd))
    assert a.shape == (30, units.n_units, 3) and b.shape == (30, units.n_units)
    nu = body_velocity(q[:, 2], qd)  # the rows are in the base-frame twist
    twist = np.linalg.lstsq(a[0], b[0], rcond=None)[0]
    np.testing.assert_allclose(twist, nu[0], atol=1e-12)
    solved = np.linalg.solve(np.einsum("nkc,nkd->ncd", a, a),
                             np.einsum("nkc,nk->nc", a, b)[..., None])[..., 0]
    np.testing.assert_allclose(solved, nu, atol=1e-11)
    ata, atb = units.normal_equations(None, units.actuator_rates(q, qd))
    np.testing.assert_allclose(np.linalg.solve(ata, atb[..., None])[..., 0], nu, atol=1e-11)
    # rows are rim speeds [m/s]: a wheel rate error δφ̇ shows as r δφ̇ in the slip quantity
    phid = units.actuator_rates(q, qd)
    phid[:, 0] += 0.5
    slip = units.quantities(units.kinematics(q, qd, None, phid), qd)["slip"]
    assert slip[0] == "m/s"
    np.testing.assert_allclose(slip[1][:, 0], 0.5 * units.r[0], atol=1e-12)
    np.testing.assert_allclose(slip[1][:, 1:], 0.0, atol=1e-12)


# ------------------------------------------------------------------ dynamics
def test_mdir_with_zero_rotor_inertia_is_the_rigid_body() -> None:
    units = five_dpo()
    q, qd, _ = states(10)
    mm, b_dir = m_dir(units, units.kinematics(q, qd), {"m_b": M, "Jzz_b": J, "Jrot_o": 0.0})
    np.testing.assert_array_equal(mm, np.broadcast_to(np.diag([M, M, J]), (10, 3, 3)))
    np.testing.assert_array_equal(b_dir, 0.0)


@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_energy_conserved_without_torque_and_friction(make) -> None:
    units = make()
    params = {"m_b": M, "Jzz_b": J, "Jrot_o": 2e-4}  # J_rot/r² ≈ 0.2 kg: a visible coupling
    q = np.zeros((6, 3))
    _, qd, _ = states(6, seed=3)
    qd[:, 2] = np.linspace(-6.0, 6.0, 6)  # combined translation and rotation
    zero = np.zeros((6, units.n_units))

    def energy(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        mm, _ = m_dir(units, units.kinematics(q, qd), params)
        return 0.5 * np.einsum("nc,ncd,nd->n", qd, mm, qd)

    def f(q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return qd, forward(units, q, qd, params, zero)

    e0 = energy(q, qd)
    v0 = np.hypot(qd[:, 0], qd[:, 1])
    dt = 1e-3
    for _ in range(2000):  # RK4 over 2 s
        k1 = f(q, qd)
        k2 = f(q + dt / 2 * k1[0], qd + dt / 2 * k1[1])
        k3 = f(q + dt / 2 * k2[0], qd + dt / 2 * k2[1])
        k4 = f(q + dt * k3[0], qd + dt * k3[1])
        q = q + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        qd = qd + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    np.testing.assert_allclose(energy(q, qd), e0, rtol=1e-10)  # measured: 5e-14
    # the wheels' spin energy is the group's kinetic energy, ½ q̇ᵀ M_add q̇
    data = units.kinematics(q, qd)
    m_add, _ = units.mass_terms(data, params)
    np.testing.assert_allclose(units.kinetic_energy(data, params),
                               0.5 * np.einsum("nc,ncd,nd->n", qd, m_add, qd), rtol=1e-12)
    # the symmetric 5DPO has an isotropic M_add and b_dir ⟂ ṙ (the spinning wheels turn the
    # velocity with the base but keep the speed); the three-wheel robot moves energy between
    # translation and the wheels, so its coupling is not trivial
    change = np.max(np.abs(np.hypot(qd[:, 0], qd[:, 1]) - v0))
    assert change < 1e-12 if units.n_units == 4 else change > 1e-3


@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_mass_terms_against_kane_with_finite_differences(make) -> None:
    """Second derivation: M from the Hessian of T(q̇) = ½ J_rot Σ φ̇_i² and the velocity terms
    from Kane's method, Σ_i (∂φ̇_i/∂q̇)ᵀ J_rot φ̈_i, with φ̇ from wheel-centre differences."""
    units = make()
    jrot = 3e-4
    q, qd, qdd = states(8, seed=4)
    data = units.kinematics(q, qd)
    m_add, b_dir = units.mass_terms(data, {"Jrot_o": jrot})
    h, ht = 0.5, 1e-5  # T is quadratic and φ̇ linear in q̇: central differences are exact
    eye = np.eye(3)

    def t_kin(qq: np.ndarray, vv: np.ndarray) -> np.ndarray:
        return 0.5 * jrot * (rim_rate(units, qq, vv) ** 2).sum(-1)

    hess = np.empty((8, 3, 3))
    for a in range(3):
        for b in range(3):
            ea, eb = h * eye[a], h * eye[b]
            hess[:, a, b] = (t_kin(q, qd + ea + eb) - t_kin(q, qd + ea - eb)
                             - t_kin(q, qd - ea + eb) + t_kin(q, qd - ea - eb)) / (4 * h * h)
    np.testing.assert_allclose(hess, m_add, rtol=1e-6, atol=1e-6 * np.abs(m_add).max())

    # partial velocities ∂φ̇/∂q̇ (φ̇ is linear in q̇) and φ̈ along the motion (q, q̇, q̈)
    partial = np.stack([(rim_rate(units, q, qd + h * eye[c]) - rim_rate(units, q, qd - h * eye[c]))
                        / (2 * h) for c in range(3)], axis=-1)  # (N, k, 3)
    for acc in (np.zeros_like(qdd), qdd):
        phidd = (rim_rate(units, q + ht * qd, qd + ht * acc)
                 - rim_rate(units, q - ht * qd, qd - ht * acc)) / (2 * ht)
        kane = jrot * np.einsum("nkc,nk->nc", partial, phidd)
        ours = np.einsum("ncd,nd->nc", m_add, acc) - b_dir
        np.testing.assert_allclose(ours, kane, rtol=1e-8, atol=1e-8 * np.abs(kane).max())
        # the A_ID column of J_rot,o is the same share divided by J_rot,o
        np.testing.assert_allclose(jrot * units.a_id(data, acc)[..., 0], ours, rtol=1e-12,
                                   atol=1e-15)


def test_substituting_the_constraint_into_lagrange_would_be_wrong() -> None:
    """The wheel constraint is nonholonomic: Lagrange's equations of T(q, q̇) with φ̇ = J q̇
    substituted add a gyroscopic term that spins up a base whose only wheel is at its centre —
    impossible, as the floor force on that wheel passes through the centre. O3 has none."""
    units = OmniUnits([OmniSpec("c", (0.0, 0.0), 0.3, R, 0.1)])
    jrot = 1e-3
    q = np.array([[0.0, 0.0, 0.4]])
    qd = np.array([[0.3, -0.5, 2.0]])
    params = {"m_b": M, "Jzz_b": J, "Jrot_o": jrot}
    qdd = forward(units, q, qd, params, np.zeros((1, 1)))
    assert qdd[0, 2] == 0.0
    # naive Lagrange at q̈ = 0: d/dt ∂T/∂q̇ − ∂T/∂q (finite differences of T(q, q̇))
    h = 1e-5
    eye = np.eye(3)

    def t_kin(qq: np.ndarray, vv: np.ndarray) -> float:
        return float(0.5 * jrot * (rim_rate(units, qq, vv) ** 2).sum())

    def dt_dqd(qq: np.ndarray) -> np.ndarray:
        return np.array([(t_kin(qq, qd + h * eye[c]) - t_kin(qq, qd - h * eye[c])) / (2 * h)
                         for c in range(3)])

    ddt = (dt_dqd(q + h * qd) - dt_dqd(q - h * qd)) / (2 * h)
    dt_dq = np.array([(t_kin(q + h * eye[c], qd) - t_kin(q - h * eye[c], qd)) / (2 * h)
                      for c in range(3)])
    naive_b_dir = -(ddt - dt_dq)
    _, b_dir = units.mass_terms(units.kinematics(q, qd), params)
    phid = units.actuator_rates(q, qd)[0, 0]
    jth = np.array([-np.sin(0.7), np.cos(0.7), 0.0]) / R  # ∂J/∂θ for θ + a = 0.7
    gyro = jrot * phid * (qd[0, 2] * jth - np.array([0, 0, 1.0]) * (jth @ qd[0]))
    np.testing.assert_allclose(naive_b_dir, b_dir[0] - gyro, rtol=1e-5, atol=1e-9)
    assert abs(naive_b_dir[2]) > 0.01 * J  # the naive model would turn the base at > 0.01 rad/s²
    assert abs(gyro @ qd[0]) < 1e-15  # ... while doing no work, so energy cannot tell them apart


@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_input_matrix_by_virtual_power(make) -> None:
    units = make()
    q, qd, _ = states(25, seed=5)
    tau = np.random.default_rng(6).normal(size=(25, units.n_units))
    data = units.kinematics(q, qd)
    power = np.einsum("nck,nk,nc->n", data.b_tau, tau, qd)
    np.testing.assert_allclose(power, (tau * rim_rate(units, q, qd)).sum(-1), rtol=1e-7)
    # 004 eqs. 9–12 for the 5DPO: ΣF_v = f3 − f1, ΣF_vn = f0 − f2, ΣT = d Σ f_i, f_i = τ_i / r
    if units.n_units == 4:
        f = tau / R
        world = np.einsum("nck,nk->nc", data.b_tau, tau)
        body = np.einsum("nba,nb->na", rot(q[:, 2]), world[:, :2])
        np.testing.assert_allclose(body[:, 0], f[:, 3] - f[:, 1], rtol=1e-12)
        np.testing.assert_allclose(body[:, 1], f[:, 0] - f[:, 2], rtol=1e-12)
        np.testing.assert_allclose(world[:, 2], D * f.sum(-1), rtol=1e-12)


def test_rotating_frame_coupling_that_eqs6_8_omit() -> None:
    """004 eqs. 6–8 in the robot frame drop M ω v_n and −M ω v; with them the robot-frame
    Newton equations agree with the world-frame model, without them they do not."""
    units = five_dpo()
    params = {"m_b": M, "Jzz_b": J, "Jrot_o": 0.0} | PAPER_BODY  # the paper has no J_rot
    q, _, _ = states(20, seed=7)
    nu = np.column_stack([np.full(20, 0.5), np.full(20, -0.2), np.linspace(-4, 4, 20)])
    qd = np.column_stack([np.einsum("nab,nb->na", rot(q[:, 2]), nu[:, :2]), nu[:, 2]])
    tau = np.random.default_rng(8).normal(size=(20, 4)) * 0.05
    qdd = forward(units, q, qd, params, tau, "body")
    # robot-frame acceleration of (v, v_n): d/dt (R(θ)ᵀ ṙ) = R(θ)ᵀ r̈ − ω S (v, v_n)
    w = nu[:, 2]
    nud = np.einsum("nba,nb->na", rot(q[:, 2]), qdd[:, :2])
    nud[:, 0] += w * nu[:, 1]
    nud[:, 1] -= w * nu[:, 0]
    # 004 eqs. 6–13 (Coulomb sign(·) as tanh(α ·), the contract's signs)
    f = tau / R
    a = units.alpha
    fv = f[:, 3] - f[:, 1] + PAPER_BODY["fbv_x"] * nu[:, 0] + PAPER_BODY["fbc_x"] * np.tanh(
        a * nu[:, 0])
    fvn = f[:, 0] - f[:, 2] + PAPER_BODY["fbv_y"] * nu[:, 1] + PAPER_BODY["fbc_y"] * np.tanh(
        a * nu[:, 1])
    tq = D * f.sum(-1) + PAPER_BODY["fbv_w"] * w + PAPER_BODY["fbc_w"] * np.tanh(a * w)
    paper = np.column_stack([fv / M, fvn / M, tq / J])
    full = paper + np.column_stack([w * nu[:, 1], -w * nu[:, 0], np.zeros(20)])
    np.testing.assert_allclose(nud, full[:, :2], atol=1e-12)
    np.testing.assert_allclose(qdd[:, 2], paper[:, 2], rtol=1e-12)
    miss = np.linalg.norm(nud[:, :2] - paper[:, :2], axis=1)
    np.testing.assert_allclose(miss, np.abs(w) * np.hypot(0.5, 0.2), rtol=1e-12)
    assert miss.max() > 2.0  # m/s² at ω = 4 rad/s, |v| = 0.54 m/s: as large as the drive itself
    assert np.abs(paper[:, :2]).max() < 2 * miss.max()


@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_world_model_equals_robot_frame_newton_euler_with_spinning_wheels(make) -> None:
    """A third derivation of M_add and b_dir: in the robot frame ν = (v, v_n, ω) the wheel rates
    φ̇ = J_b ν have constant coefficients J_b = [h_i, c_i]/r_i, so the wheels add J_rot J_bᵀ J_b ν̇
    and nothing else; only the base carries the rotating-frame term M ω S (v, v_n)."""
    units = make()
    params = {"m_b": M, "Jzz_b": J, "Jrot_o": 4e-4} | PAPER_BODY
    q, qd, _ = states(15, seed=12)
    tau = np.random.default_rng(13).normal(size=(15, units.n_units)) * 0.05
    qdd = forward(units, q, qd, params, tau, "body")
    nu = np.column_stack([np.einsum("nba,nb->na", rot(q[:, 2]), qd[:, :2]), qd[:, 2]])
    j_b = units.kinematics(np.zeros_like(q), nu).jac[0]  # (k, 3), θ = 0: the robot frame
    phid = np.einsum("kc,nc->nk", j_b, nu)
    tau_f = units.friction_torques(units.kinematics(q, qd), params, "body")  # none: body axis
    a = units.alpha
    f_body = (np.array([params[n] for n in BODY_FRICTION[:3]]) * nu
              + np.array([params[n] for n in BODY_FRICTION[3:]]) * np.tanh(a * nu))
    coupling = np.column_stack([-M * nu[:, 2] * nu[:, 1], M * nu[:, 2] * nu[:, 0], np.zeros(15)])
    lhs = np.diag([M, M, J]) + params["Jrot_o"] * j_b.T @ j_b
    rhs = np.einsum("kc,nk->nc", j_b, tau + tau_f) + f_body - coupling
    nud = np.linalg.solve(lhs, rhs.T).T
    expect_xy = np.einsum("nab,nb->na", rot(q[:, 2]), nud[:, :2] + nu[:, 2:3] * np.column_stack(
        [-nu[:, 1], nu[:, 0]]))  # r̈ = R(θ) (ν̇ + ω S ν)
    np.testing.assert_allclose(qdd[:, :2], expect_xy, atol=1e-11)
    np.testing.assert_allclose(qdd[:, 2], nud[:, 2], atol=1e-11)
    np.testing.assert_allclose(units.actuator_rates(q, qd), phid, atol=1e-12)


# ------------------------------------------------------------------ identification
@pytest.mark.parametrize("variant", ["per-wheel", "shared", "body"])
@pytest.mark.parametrize("make", PLATFORMS.values(), ids=PLATFORMS.keys())
def test_regressor_columns_reproduce_the_equations_of_motion(make, variant: str) -> None:
    """[A_base | A_Jrot | A_friction] m_ext = M_dir q̈ − b_dir − (friction force) (eq. 66)."""
    units = make()
    names = units.friction_names(units.names, variant)
    rng = np.random.default_rng(9)
    values = dict(zip(names, -rng.uniform(0.01, 0.5, len(names)), strict=True))
    params = {"m_b": M, "Jzz_b": J, "Jrot_o": 2e-4} | values
    q, qd, qdd = states(12, seed=10)
    phid = units.actuator_rates(q, qd) + rng.normal(size=(12, units.n_units)) * 0.1
    data = units.kinematics(q, qd, None, phid)
    a_ext = np.concatenate([base.a_id_base(qdd), units.a_id(data, qdd),
                            units.friction_columns(data, variant)], axis=2)
    m_ext = np.array([M, J, 2e-4] + [values[n] for n in names])
    mm, b_dir = m_dir(units, data, params)
    friction = np.einsum("nck,nk->nc", data.b_tau,
                         units.friction_torques(data, params, variant))
    if variant == "body":
        friction += body_friction_force(q[:, 2], qd, params, units.alpha)
        np.testing.assert_array_equal(units.friction_torques(data, params, variant), 0.0)
    np.testing.assert_allclose(a_ext @ m_ext,
                               np.einsum("ncd,nd->nc", mm, qdd) - b_dir - friction, atol=1e-12)


def test_parameter_and_channel_names() -> None:
    units = five_dpo()
    assert units.inertial_names == ("Jrot_o",)
    assert units.friction_names(units.names) == ["fov_0", "foc_0", "fov_1", "foc_1", "fov_2",
                                                 "foc_2", "fov_3", "foc_3"]
    assert units.friction_names(units.names, "shared") == ["fov", "foc"]
    assert units.friction_names(units.names, "body") == []  # the base's: BODY_FRICTION
    assert [(c.column("3"), c.unit) for c in (*units.angles, *units.currents)] == [
        ("phi_3", "rad"), ("cur_3", "A")]
    with pytest.raises(InputError, match="^unknown friction model 'wheel'; use per-wheel, "
                                         "shared or body$"):
        units.friction_names(units.names, "wheel")  # type: ignore[arg-type]
    np.testing.assert_allclose(units.torques(np.ones((2, 4))), 0.1295)
    table = units.unit_table()
    assert table[1]["heading [deg]"] == pytest.approx(180.0)
    assert [row["moment arm c [m]"] for row in table] == pytest.approx([D] * 4)
    assert body_friction_columns(np.zeros(1), np.zeros((1, 3)), 10.0).shape == (1, 3, 6)


# ------------------------------------------------------------------ platform entries
def test_per_unit_overrides_of_radius_and_torque_constant() -> None:
    data = yaml.safe_load(PLATFORM.read_text())
    data["units"][2] |= {"wheel_radius": 0.05, "torque_constant": 0.3}
    units = OmniUnits.from_platform_dict(data)
    np.testing.assert_array_equal(units.r, [R, R, 0.05, R])
    np.testing.assert_array_equal(units.k_t, [0.1295, 0.1295, 0.3, 0.1295])
    q, qd, _ = states(5, seed=11)
    ref = five_dpo()
    np.testing.assert_allclose(units.actuator_rates(q, qd)[:, 2],
                               ref.actuator_rates(q, qd)[:, 2] * R / 0.05, rtol=1e-13)
    np.testing.assert_allclose(units.actuator_rates(q, qd), rim_rate(units, q, qd), rtol=1e-7,
                               atol=1e-8)
    np.testing.assert_allclose(units.torques(np.ones((1, 4)))[0], units.k_t)
    # same floor speed, so the rim-speed constraint rows are those of the reference
    a, b = units.constraint_rows(None, units.actuator_rates(q, qd))
    a_ref, b_ref = ref.constraint_rows(None, ref.actuator_rates(q, qd))
    np.testing.assert_allclose(a, a_ref)
    np.testing.assert_allclose(b, b_ref, rtol=1e-13)


@pytest.mark.parametrize(("change", "message"), [
    ({"position": [0.1]}, "p.yaml: 'units[1]' (unit '1'): key 'position' must be two finite "
     "numbers [x, y] in metres (the wheel centre in the base frame)"),
    ({"position": [0.1, float("nan")]}, "p.yaml: 'units[1]' (unit '1'): key 'position' must be "
     "two finite numbers [x, y] in metres (the wheel centre in the base frame)"),
    ({"heading": None}, "p.yaml: 'units[1]' (unit '1'): missing key 'heading'; give the rolling "
     "direction in the base frame [rad]"),
    ({"heading": "north"}, "p.yaml: 'units[1]' (unit '1'): key 'heading' must be a number, got "
     "'north'; write a plain number in SI units (e.g. 0.05 or 5e-2)"),
    ({"heading": float("inf")}, "p.yaml: 'units[1]' (unit '1'): key 'heading' must be finite, "
     "got inf; give its value in SI units"),
    ({"wheel_radius": -0.03}, "p.yaml: 'units[1]' (unit '1'): 'wheel_radius' must be > 0, "
     "got -0.03; give the wheel radius in metres"),
    ({"torque_constant": True}, "p.yaml: 'units[1]' (unit '1'): key 'torque_constant' must be a "
     "number, got True; write a plain number in SI units (e.g. 0.05 or 5e-2)"),
    ({"pivot": [0, 0]}, "p.yaml: 'units[1]' (unit '1'): unknown key 'pivot' for type omni; "
     "known keys: name, type, position, heading, wheel_radius, torque_constant"),
])
def test_platform_entry_validation_messages(change: dict, message: str) -> None:
    data = yaml.safe_load(PLATFORM.read_text())
    entry = data["units"][1]
    for key, value in change.items():
        if value is None:
            entry.pop(key)
        else:
            entry[key] = value
    with pytest.raises(InputError) as err:
        OmniUnits.from_platform_dict(data, "p.yaml")
    assert str(err.value) == message
    assert "\n" not in str(err.value)


def test_platform_level_messages() -> None:
    data = yaml.safe_load(PLATFORM.read_text())
    del data["wheel_radius"]
    with pytest.raises(InputError, match=r"^p.yaml: missing key 'wheel_radius'; add it \(SI "
                                         r"units, see docs/file-formats.md\)$"):
        OmniUnits.from_platform_dict(data, "p.yaml")
    with pytest.raises(InputError, match="^p.yaml: no unit has 'type: omni'$"):
        OmniUnits.from_platform_dict({"units": [{"name": "1", "pivot": [0, 0]}]}, "p.yaml")
    with pytest.raises(InputError, match=r"^p.yaml: 'units\[0\]' must be a mapping"):
        OmniUnits.parse_entry(["x"], 0, "p.yaml", {})
    with pytest.raises(InputError, match=r"^p.yaml: 'units\[0\].name' is 'a b'; use letters, "
                                         "digits and underscores only$"):
        OmniUnits.parse_entry({"name": "a b"}, 0, "p.yaml", {})
    data = yaml.safe_load(PLATFORM.read_text())
    data["units"][3]["name"] = "1"
    with pytest.raises(InputError, match=r"^p.yaml: 'units\[3\].name' '1' is used twice; "
                                         "names must be unique$"):
        OmniUnits.from_platform_dict(data, "p.yaml")
