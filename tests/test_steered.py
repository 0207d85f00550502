"""The steered-wheel unit type (001), checked independently of its derivation: the
wheel-centre velocity by finite differences of its position, Kane's method with finite-difference
partial velocities, virtual power, energy through a singular configuration, the projector
against scipy's null space, the torque distribution, and the fit's recovery of the
combinations the module docstring predicts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import yaml

from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_logs
from ropod_sysid.io import read_log
from ropod_sysid.model import PlatformModel
from ropod_sysid.model.assembly import null_projector
from ropod_sysid.params import Parameters, typical_parameters
from ropod_sysid.platform import platform_from_dict
from ropod_sysid.regressor import Span
from ropod_sysid.simulate import Controller, Sensors, Setpoints, sensed, simulate
from tests.conftest import shipped

R = 0.1
ENTRY = {"name": "jku", "wheel_radius": R, "torque_constant": 2.0,
         "steer_torque_constant": 10.0, "friction_tanh_gain": 100.0,
         "units": [{"name": "1", "type": "steered", "position": [0.3, 0.0]},
                   {"name": "2", "type": "steered", "position": [-0.3, 0.0]}]}
# a mixed platform: a steered wheel off the axis and two omni wheels
MIXED = {"name": "mixed", "wheel_radius": R, "torque_constant": 2.0,
         "steer_torque_constant": 10.0, "friction_tanh_gain": 100.0,
         "units": [{"name": "s", "type": "steered", "position": [0.25, 0.1]},
                   {"name": "a", "type": "omni", "position": [-0.2, 0.2], "heading": 0.3},
                   {"name": "b", "type": "omni", "position": [-0.2, -0.2], "heading": 2.0}]}
# four steered wheels at the corners (over-constrained: the axles must meet at one point)
FOUR = {"name": "four", "wheel_radius": R, "torque_constant": 2.0,
        "steer_torque_constant": 10.0, "friction_tanh_gain": 100.0,
        "units": [{"name": n, "type": "steered", "position": p} for n, p in
                  (("1", [0.35, 0.25]), ("2", [-0.35, 0.25]), ("3", [-0.35, -0.25]),
                   ("4", [0.35, -0.25]))]}
TRUTH = {"m_b": 93.0, "Jzz_b": 4.51, "Jst": 0.2234, "Jrot_s": 0.0205}
FRICTIONLESS = {f"{f}_{u}": 0.0 for f in ("fdv", "fdc", "fsv", "fsc") for u in ("1", "2")}


def steered() -> PlatformModel:
    return PlatformModel(platform_from_dict(ENTRY, "<test>"))


def random_state(model: PlatformModel, rng: np.random.Generator, n: int = 5
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pose (n, 3), generalized velocity (n, D) (not constrained) and unit angles (n, J)."""
    q = rng.normal(size=(n, 3))
    qd = rng.normal(size=(n, model.n_dof))
    angles = rng.uniform(-np.pi, np.pi, size=(n, model.layout.n_angles))
    return q, qd, angles


def wheel_centre(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """World position (n, 2) of a point p (2,) fixed in the base."""
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    return q[:, :2] + np.stack([c * p[0] - s * p[1], s * p[0] + c * p[1]], axis=-1)


def advanced(model: PlatformModel, q: np.ndarray, qd: np.ndarray, angles: np.ndarray,
             h: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose and angles moved along q̇ for a time h (the own coordinates move with their rates)."""
    ang = angles.copy()
    ang[:, model.coordinate_channels] += h * qd[:, 3:]
    return q + h * qd[:, :3], ang


def test_rows_are_the_wheel_centre_velocity() -> None:
    """S1, S2: r J q̇ and G q̇ are the wheel centre's velocity along and across the wheel,
    the velocity found by differentiating the centre's position numerically."""
    model, rng, h = steered(), np.random.default_rng(1), 1e-6
    q, qd, angles = random_state(model, rng)
    st = model.state(q, qd, angles)
    g, _ = model.constraints(st)
    unit, data = model.groups[0][1], st.units[0]
    for k in range(unit.n_units):
        p = unit.positions[k]
        vel = (wheel_centre(q + h * qd[:, :3], p)
               - wheel_centre(q - h * qd[:, :3], p)) / (2 * h)
        psi = q[:, 2] + angles[:, 2 * k]
        along = np.cos(psi) * vel[:, 0] + np.sin(psi) * vel[:, 1]
        across = -np.sin(psi) * vel[:, 0] + np.cos(psi) * vel[:, 1]
        assert np.allclose(R * np.einsum("nc,nc->n", data.jac[:, k], qd[:, :3]), along,
                           atol=1e-8)
        assert np.allclose(np.einsum("nd,nd->n", g[:, k], qd), across, atol=1e-8)


def test_time_derivatives_by_finite_differences() -> None:
    """S3 and S4: J̇ q̇ and Ġ q̇ equal central differences of J q̇ and G q̇ along the motion."""
    model, rng, h = steered(), np.random.default_rng(2), 1e-6
    q, qd, angles = random_state(model, rng)
    st = model.state(q, qd, angles)
    g, g_dot = model.constraints(st)
    q_f, ang_f = advanced(model, q, qd, angles, h)
    q_b, ang_b = advanced(model, q, qd, angles, -h)
    ahead, back = model.state(q_f, qd, ang_f), model.state(q_b, qd, ang_b)
    jq = [np.einsum("nkc,nc->nk", s.units[0].jac, qd[:, :3]) for s in (ahead, back)]
    assert np.allclose((jq[0] - jq[1]) / (2 * h), st.units[0].jac_dot_qd, atol=1e-7)
    gq = [np.einsum("nkd,nd->nk", model.constraints(s)[0], qd) for s in (ahead, back)]
    assert np.allclose((gq[0] - gq[1]) / (2 * h), g_dot, atol=1e-7)


@pytest.mark.parametrize("layout", [ENTRY, MIXED], ids=["steered", "mixed"])
def test_kane_equations_equal_the_model(layout: dict) -> None:
    """Kane's method from the bodies' speeds alone (base translation and rotation, each unit's
    turn θ̇ + β̇, each wheel's spin t·Ṗ/r with Ṗ the rigid base's point velocity): partial
    velocities by finite differences in q̇, accelerations by central differences in time; the
    generalized inertia forces equal M_dir q̈ − b_dir (S5, S6); virtual power gives B_τ (S7)."""
    model = PlatformModel(platform_from_dict(layout, "<test>"))
    rng, h = np.random.default_rng(3), 1e-5
    params = dict(TRUTH, Jrot_o=0.003)
    q, qd, angles = random_state(model, rng, 3)
    qdd = rng.normal(size=qd.shape)

    def speeds(q: np.ndarray, qd: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, ...]:
        """(mass-weighted body speeds (n, s), their inertias (s,)) from positions only."""
        out, inertia = [qd[:, 0], qd[:, 1], qd[:, 2]], [params["m_b"], params["m_b"],
                                                        params["Jzz_b"]]
        for (g, unit), rows in zip(model.groups, model.rows, strict=True):
            ang = angles[:, g.angles]
            for k in range(unit.n_units):
                p = unit.positions[k]
                c, s = np.cos(q[:, 2]), np.sin(q[:, 2])  # ṙ + θ̇ × R p, a rigid body's point
                vel = qd[:, :2] + qd[:, 2:3] * np.stack([-(s * p[0] + c * p[1]),
                                                         c * p[0] - s * p[1]], axis=-1)
                if rows.size > 3:  # steered: its turn and its wheel's spin
                    psi = q[:, 2] + ang[:, 2 * k]
                    out.append(qd[:, 2] + qd[:, rows[3 + k]])
                    inertia.append(params["Jst"])
                    jr = params["Jrot_s"]
                else:  # omni: the wheel's spin along its heading
                    psi = q[:, 2] + unit.headings[k]
                    jr = params["Jrot_o"]
                out.append((np.cos(psi) * vel[:, 0] + np.sin(psi) * vel[:, 1]) / unit.r[k])
                inertia.append(jr)
        return np.stack(out, axis=-1), np.array(inertia)

    sp, inertia = speeds(q, qd, angles)
    # partial velocities: the speeds are linear in q̇
    partial = np.stack([speeds(q, qd + 1e-3 * np.eye(model.n_dof)[r], angles)[0] - sp
                        for r in range(model.n_dof)], axis=1) / 1e-3  # (n, D, s)
    q_f, ang_f = advanced(model, q, qd, angles, h)
    q_b, ang_b = advanced(model, q, qd, angles, -h)
    fwd = speeds(q_f, qd + h * qdd, ang_f)[0]
    bwd = speeds(q_b, qd - h * qdd, ang_b)[0]
    acc = (fwd - bwd) / (2 * h)
    kane = np.einsum("nrs,s,ns->nr", partial, inertia, acc)
    eom = model.direct_eom(model.state(q, qd, angles), params, "per-wheel")
    model_side = np.einsum("nij,nj->ni", eom.m_dir, qdd) - eom.b_dir
    assert np.allclose(kane, model_side, rtol=1e-7, atol=1e-7)
    # virtual power: Σ τ_a (rate of actuator a) = (B_τ τ)·q̇
    st = model.state(q, qd, angles)
    tau = rng.normal(size=(3, model.layout.n_currents))
    power = (tau * st.actuator_rate).sum(axis=1)
    assert np.allclose(np.einsum("nda,na,nd->n", st.b_tau, tau, qd), power)


def test_projector_regular_and_singular() -> None:
    """P = I − G⁺G equals N Nᵀ for scipy's null space of G; P Gᵀ = 0, P² = P, and its rank is
    D − rank G: 3 when the axles cross, 4 when both lie on the line through the wheels
    (001's singular configuration), and a configuration a hair from it is still regular."""
    model = steered()
    cases = {"regular": ([0.5, -0.9], 3), "singular": ([np.pi / 2, np.pi / 2], 4),
             "flipped": ([np.pi / 2, -np.pi / 2], 4), "near": ([np.pi / 2, np.pi / 2 + 1e-6], 3)}
    for name, (beta, rank) in cases.items():
        angles = np.array([[beta[0], 0.0, beta[1], 0.0]])
        st = model.state(np.array([[0.1, 0.2, 0.7]]), np.zeros((1, 5)), angles)
        g, _ = model.constraints(st)
        p = null_projector(g, 5)[0]
        n = scipy.linalg.null_space(g[0], rcond=1e-9)
        assert n.shape[1] == rank, name
        assert np.allclose(n.T @ n, np.eye(rank))
        assert np.allclose(g[0] @ n, 0.0, atol=1e-12)
        assert np.allclose(p, n @ n.T, atol=1e-9), name
        assert np.allclose(p @ g[0].T, 0.0, atol=1e-12) and np.allclose(p @ p, p)
        assert round(float(np.trace(p))) == rank


def lateral_base_block(model: PlatformModel, angles: np.ndarray) -> np.ndarray:
    """The steered units' lateral rows on the base twist (N, k, 3) at unit angles (N, J), as
    the module docstring writes them (S2: n = (−sin β, cos β), e = p · h) in the base frame."""
    (_, unit), = model.groups
    beta = angles[:, ::2]
    p = unit.positions
    return np.stack([-np.sin(beta), np.cos(beta),
                     p[:, 0] * np.cos(beta) + p[:, 1] * np.sin(beta)], axis=-1)


def test_planned_steering_keeps_four_wheels_on_one_centre() -> None:
    """Four wheels planned along twists that stop, hold and restart in new directions: at every
    sample the axles meet at one point (the lateral rows have rank 2: σ₃ = 0), and the
    steering turns only while the base is slow (its angle changes by the plan's smooth step,
    never jumps)."""
    model = PlatformModel(platform_from_dict(FOUR, "<test>"))
    t = np.linspace(0.0, 6.0, 1201)
    env = np.clip(np.sin(np.pi * t / 2.0), 0.0, None) ** 2  # moves, stops, moves again
    first = t < 2
    tw = env[:, None] * np.where(first[:, None], [0.3, 0.02, 0.12], [-0.06, 0.2, -0.2])
    (_, unit), = model.groups
    pred = unit.predict_angles(t, tw[None])
    sv = np.linalg.svd(lateral_base_block(model, pred.angles[0]), compute_uv=False)
    assert sv[:, 2].max() < 1e-9 * sv[:, 0].min()
    beta = pred.angles[0][:, ::2]
    assert np.abs(np.diff(beta, axis=0)).max() < 0.05  # 10 ms steps: no jump
    stopped = (t > 2.0) & (t < 4.0)
    assert np.ptp(beta[stopped], axis=0).max() > 0.5  # it turned while stopped


def test_nearly_consistent_wheels_leave_the_base_free_and_slip_is_left_out() -> None:
    """Four wheels whose angles miss a common centre by ε: taken exactly the base would be
    locked (rank 3); the model takes the nearest consistent constraints (rank 2), whose
    projector is within O(ε) of the consistent one, and identification leaves out the base rows
    once ε exceeds the slip margin (0.01)."""
    model = PlatformModel(platform_from_dict(FOUR, "<test>"))
    (_, unit), = model.groups
    twist = np.array([0.2, 0.1, 0.3])
    u_x, u_y = unit.centre_velocity(twist)
    beta = np.arctan2(u_y, u_x)
    projectors = []
    for eps in (0.0, 1e-3, 3e-2):
        angles = np.zeros((1, 8))
        angles[0, ::2] = beta + eps * np.array([1.0, -1.0, 0.5, 0.0])
        st = model.state(np.zeros((1, 3)), np.zeros((1, model.n_dof)), angles)
        exact, _ = model.constraints(st, exact=True)
        assert np.linalg.matrix_rank(exact[0], tol=1e-12) == (2 if eps == 0 else 3)
        p = model.projector(st)[0]
        assert round(float(np.trace(p[:3, :3]))) == 1  # the base keeps one freedom
        projectors.append(p)
        base_rows = model.identification_projector(st)[0][:3, :3]
        assert np.allclose(base_rows, 0.0) == (eps > 0.01)
    assert np.abs(projectors[1] - projectors[0]).max() < 5e-3


def test_forward_dynamics_keeps_the_constraints_and_the_projected_equations() -> None:
    """q̈ satisfies G q̈ = −Ġ q̇ and P (M q̈ − Q) = 0 in regular and singular configurations.

    In the singular one (both axles along the base x axis, θ = 0) the two lateral rows are
    equal, and their accelerations agree only if the wheel centres' lateral accelerations do:
    β̇₁ v₁ = β̇₂ v₂ for the centres' speeds v_i = ẏ ± 0.3 θ̇; other steering rates would make
    the wheels slip."""
    model, rng = steered(), np.random.default_rng(5)
    params = Parameters(TRUTH | FRICTIONLESS)
    angles = np.array([[0.5, 0.0, -0.9, 0.0], [np.pi / 2, 1.0, np.pi / 2, 2.0]])
    q = np.array([[0.0, 0.0, 0.3], [1.0, 2.0, 0.0]])
    # regular: any velocity the constraints allow (the null space of G); singular: as above
    st0 = model.state(q, np.zeros((2, 5)), angles)
    g0, _ = model.constraints(st0)
    qd = np.einsum("nij,nj->ni", null_projector(g0, 5), rng.normal(size=(2, 5)))
    qd[1] = [0.0, 0.2, 1.0, 0.2, -1.0]  # v₁ = 0.5, v₂ = −0.1
    st = model.state(q, qd, angles)
    tau = rng.normal(size=(2, 4))
    qdd = model.forward_dynamics(st, params, tau)
    g, g_dot = model.constraints(st)
    assert np.allclose(np.einsum("ncd,nd->nc", g, qdd), -g_dot, atol=1e-10)
    eom = model.direct_eom(st, params)
    resid = np.einsum("nij,nj->ni", eom.m_dir, qdd) - eom.generalized_force(tau)
    assert np.allclose(np.einsum("nij,nj->ni", model.projector(st), resid), 0.0, atol=1e-10)


@pytest.mark.parametrize("layout", [ENTRY, FOUR, MIXED], ids=["two", "four", "mixed"])
def test_projection_equals_the_minimal_model(layout: dict) -> None:
    """Where the constraints are regular, the projected forward dynamics equal the minimal
    model in independent velocities ν (q̇ = N ν, N an orthonormal basis of G's null space from
    scipy): q̈ = ζ + N ν̇ with ζ = −G⁺ Ġq̇ and (NᵀMN) ν̇ = Nᵀ(Q − M ζ) (001 eqs. 12–15), for
    consistent random configurations (the axles on one centre) and random torques."""
    model = PlatformModel(platform_from_dict(layout, "<test>"))
    rng = np.random.default_rng(11)
    params = Parameters(typical_parameters(model.platform, 93.0, 4.51).to_mapping()
                        | {"Jrot_o": 0.003})
    n = 4
    twist = rng.normal(size=(n, 3))
    angles = np.stack([model.initial_angles(tw) for tw in twist])
    q = rng.normal(size=(n, 3))
    st0 = model.state(q, np.zeros((n, model.n_dof)), angles)
    g0, _ = model.constraints(st0)
    qd = np.stack([scipy.linalg.null_space(g0[i]) @ rng.normal(
        size=scipy.linalg.null_space(g0[i]).shape[1]) for i in range(n)])
    st = model.state(q, qd, angles)
    tau = rng.normal(size=(n, model.layout.n_currents))
    qdd = model.forward_dynamics(st, params, tau)
    eom = model.direct_eom(st, params, "per-wheel")
    rhs = eom.generalized_force(tau)
    g, g_dot = model.constraints(st)
    for i in range(n):
        null = scipy.linalg.null_space(g[i])
        zeta = -np.linalg.pinv(g[i]) @ g_dot[i]
        nu_dot = np.linalg.solve(null.T @ eom.m_dir[i] @ null,
                                 null.T @ (rhs[i] - eom.m_dir[i] @ zeta))
        assert np.allclose(qdd[i], zeta + null @ nu_dot, rtol=1e-8, atol=1e-9)


def test_energy_is_conserved_through_a_singular_configuration() -> None:
    """No torque, no friction: starting with both axles on the line through the wheels and the
    units turning (at rates consistent there: β̇₁ v₁ = β̇₂ v₂, see above), the platform leaves
    the singular configuration and its kinetic energy stays constant (RK4, 1 ms); the
    constraints stay satisfied."""
    model = steered()
    params = Parameters(TRUTH | FRICTIONLESS)
    q = np.zeros((1, 3))
    angles = np.array([[np.pi / 2, 0.0, np.pi / 2, 0.0]])
    qd = np.array([[0.0, 0.2, 1.0, 0.2, -1.0]])  # G q̇ = 0: no velocity along the base x
    tau = np.zeros((1, 4))
    dt, seen_rank = 1e-3, set()

    def deriv(q: np.ndarray, qd: np.ndarray, ang: np.ndarray) -> tuple[np.ndarray, ...]:
        st = model.state(q, qd, ang)
        return qd[:, :3], model.forward_dynamics(st, params, tau), st.angle_rate

    e0 = model.kinetic_energy(model.state(q, qd, angles), params)[0]
    worst = 0.0
    for _ in range(600):
        y = (q, qd, angles)
        k1 = deriv(*y)
        k2 = deriv(*(a + 0.5 * dt * b for a, b in zip(y, k1, strict=True)))
        k3 = deriv(*(a + 0.5 * dt * b for a, b in zip(y, k2, strict=True)))
        k4 = deriv(*(a + dt * b for a, b in zip(y, k3, strict=True)))
        q, qd, angles = (a + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
                         for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4, strict=True))
        st = model.state(q, qd, angles)
        g, _ = model.constraints(st)
        seen_rank.add(int(np.linalg.matrix_rank(g[0], tol=1e-6)))
        worst = max(worst, float(np.abs(np.einsum("ncd,nd->nc", g, qd)).max()))
    e1 = model.kinetic_energy(model.state(q, qd, angles), params)[0]
    assert seen_rank == {2}  # it left the singular start at once
    assert abs(e1 - e0) < 1e-8 * e0
    assert worst < 1e-8


def test_torque_distribution_is_the_weighted_right_inverse() -> None:
    """001 eqs. 17–23: the torques reproduce the projected generalized forces exactly, no other
    solution has a smaller uᵀ W u (W = diag(1/τ_max²)), and the steering torques are the
    steering rows alone (eq. 17's decoupling)."""
    model, rng = steered(), np.random.default_rng(7)
    params = Parameters(TRUTH | FRICTIONLESS)
    angles = np.array([[0.5, 0.0, -0.9, 0.0]])
    q = np.array([[0.0, 0.0, 0.3]])
    g0, _ = model.constraints(model.state(q, np.zeros((1, 5)), angles))
    proj = null_projector(g0, 5)
    qd = np.einsum("nij,nj->ni", proj, rng.normal(size=(1, 5)))
    st = model.state(q, qd, angles)
    qdd = model.forward_dynamics(st, params, rng.normal(size=(1, 4)))
    t_max = np.array([25.6, 129.0, 25.6, 129.0])
    u = model.inverse_dynamics(st, params, qdd, torque_max=t_max)
    eom = model.direct_eom(st, params)
    pb = np.einsum("nij,nja->nia", proj, eom.b_tau)[0]
    q_d = proj[0] @ (eom.m_dir[0] @ qdd[0] - eom.b_dir[0])
    assert np.allclose(pb @ u[0], q_d, atol=1e-10)
    w = np.diag(1 / t_max**2)
    null = scipy.linalg.null_space(pb)
    assert null.shape[1] == 1  # four torques, three independent equations
    for z in np.linspace(-5, 5, 11):
        other = u[0] + z * null[:, 0]
        assert other @ w @ other >= u[0] @ w @ u[0] - 1e-12
    turn = qdd[0, 2] + qdd[0, 3:]
    assert np.allclose(u[0, 1::2], TRUTH["Jst"] * turn)


def test_entry_errors_are_one_line() -> None:
    entry = dict(ENTRY)
    entry.pop("steer_torque_constant")
    with pytest.raises(InputError, match="missing key 'steer_torque_constant'"):
        platform_from_dict(entry, "p.yaml")
    bad = dict(ENTRY, units=[{"name": "1", "type": "steered", "position": [0.3, 0.0],
                              "pivot": [0, 0]}, ENTRY["units"][1]])
    with pytest.raises(InputError, match="unknown key 'pivot' for type steered"):
        platform_from_dict(bad, "p.yaml")


def test_sensor_noise_on_the_steered_sample_is_covered_and_predicted(
        tmp_path) -> None:
    """The shipped steered sample (2¹⁴ counts, 30 mA): every determined value within 3σ of the
    truth, plain and with ``--encoder-counts``, whose error gram of A includes the steering
    angles' second differences (β̈ rows) and takes the base's combinations to within 0.5 %
    (−0.6 % and −1.1 % uncorrected); ``trajectory check``'s sensor model predicts that
    uncorrected error."""
    from click.testing import CliRunner

    from ropod_sysid.cli.main import main

    here = Path(__file__).resolve().parent.parent / "datasets" / "steered"
    logs = sorted(str(p) for p in here.glob("*.csv.gz"))
    truth = json.loads((here / "truth.json").read_text())
    pf = platform_from_dict(yaml.safe_load((here / "platform.yaml").read_text()), "<sample>")
    plain = fit_logs([read_log(p, pf) for p in logs], pf)
    corrected = fit_logs([read_log(p, pf) for p in logs], pf, FitOptions(encoder_counts=2**14))
    for sol, worst in ((plain.solution, 0.015), (corrected.solution, 0.005)):
        value = dict(zip(sol.names, sol.values, strict=True))
        expect = dict(zip(sol.names, sol.combination_of(Parameters(truth).vector(sol.names)),
                          strict=True))
        err = max(abs(value[n] / expect[n] - 1) for n in ("m_b", "Jzz_b"))
        assert err < worst
        # every value and combination the logs determine lies within 3σ of the truth's (the
        # steering's own rows left out while it is held: its Coulomb term within 0.5 %)
        for name, std in zip(sol.names, sol.std, strict=True):
            if np.isfinite(std) and std > 0:
                assert abs(value[name] - expect[name]) < 3 * std, name
        for name in ("fsv_1", "fsc_1", "fsv_2", "fsc_2"):
            assert value[name] == pytest.approx(expect[name], rel=0.01), name
    # trajectory check's sensor model covers the steering too: the bias it predicts for the
    # base's values (the encoders' errors in q̈) is the plain fit's error within a factor 2
    result = CliRunner().invoke(main, ["trajectory", "check", "--platform",
                                       str(here / "platform.yaml"), "--encoder-counts", "16384",
                                       "--current-noise", "0.03", "--params",
                                       str(here / "truth.json"), "--json",
                                       str(here / "trajectory" / "original.csv.gz")])
    assert result.exit_code == 0, result.output
    predicted = json.loads(result.output)["predicted"]
    value = dict(zip(plain.solution.names, plain.solution.values, strict=True))
    for name, combined in (("m_b", 97.1), ("Jzz_b", 4.879)):
        fitted = value[name] - combined
        assert 0.5 < predicted[name]["bias"] / fitted < 2.0, (name, predicted[name], fitted)
        assert np.isfinite(predicted[name]["std"]) and predicted[name]["std"] > 0


def test_fit_names_the_combinations_and_recovers_them() -> None:
    """Noise-free simulated logs (001's vehicle under its decentralised controllers): the fit's
    rank analysis finds m_b + (n/r²) J_rot,s and J_zz,b + (Σ|p|²/r²) J_rot,s, and every
    identifiable value and combination is within 1 % of the truth's (drive Coulomb friction
    within 1.1 %: −1.03 % measured with the rates moved onto the allowed motions, −0.99 %
    without)."""
    pf = platform_from_dict(ENTRY, "<test>")
    truth = Parameters(TRUTH | {"fdv_1": -0.35, "fdc_1": -0.88, "fsv_1": -2.08, "fsc_1": -2.11,
                                "fdv_2": -0.32, "fdc_2": -0.95, "fsv_2": -1.9, "fsc_2": -2.3})
    t = np.linspace(0, 5, 501)
    vx, vy, om = (0.3 * np.sin(2 * np.pi * t / 5) ** 2, 0.12 * np.sin(2 * np.pi * t / 2.5),
                  0.5 * np.sin(2 * np.pi * t / 3.3))
    runs = [Setpoints(t, vx, vy, om), Setpoints(t, -vx, vy, -om)]
    res = simulate(pf, truth, runs, rate=250.0, dt=2e-3,
                   controller=Controller(kp=20.0, ki=200.0, torque_limit=25.6))
    fit = fit_logs([r.log for r in res], pf)
    sol = fit.solution
    assert sol.combinations["m_b"] == "m_b +200·Jrot_s"
    assert sol.combinations["Jzz_b"] == "Jzz_b +18·Jrot_s"
    value = dict(zip(sol.names, sol.values, strict=True))
    expect = dict(truth.to_mapping())
    expect["m_b"] += 200 * expect["Jrot_s"]
    expect["Jzz_b"] += 18 * expect["Jrot_s"]
    for name in sol.names:
        if name == "Jrot_s":
            continue
        rel = 0.011 if name.startswith("fdc") else 0.01
        assert value[name] == pytest.approx(expect[name], rel=rel), name


@pytest.fixture(scope="module")
def four_sample() -> tuple:
    """The shipped exact logs of four steered wheels at a rectangle's corners: platform, truth,
    logs."""
    return shipped("steered-four")


def four_wheel_null_space(names: list[str]) -> np.ndarray:
    """The combinations four steered wheels at (±0.35, ±0.25) m cannot separate, derived (not
    fitted): J_rot,s/r² as a point mass at each wheel centre (m_b + n/r² J_rot,s, J_zz,b +
    Σ|p|²/r² J_rot,s: n/r² = 400, Σ|p|²/r² = 74 m²·1/m²), and by the layout's symmetry the
    drives' viscous friction alternating round the corners (+1, −1, +1, −1), whose torques
    cancel in every rigid motion the axles allow. (p, 2)."""
    idx = {n: i for i, n in enumerate(names)}
    out = np.zeros((len(names), 2))
    for name, value in (("Jrot_s", 1.0), ("m_b", -400.0), ("Jzz_b", -74.0)):
        out[idx[name], 0] = value
    for u, sign in zip("1234", (1.0, -1.0, 1.0, -1.0), strict=True):
        out[idx[f"fdv_{u}"], 1] = sign
    return out


def in_null_space(sol, v: np.ndarray) -> bool:
    """Does the combination v (p,) lie in the fit's null space?"""
    basis = scipy.linalg.orth(sol.null_space)
    return bool(np.linalg.norm(basis @ (basis.T @ v)) > 0.999 * np.linalg.norm(v))


def compared(sol, truth: Parameters, null: np.ndarray
             ) -> tuple[dict[str, float], dict[str, float]]:
    """The truth moved along those derived combinations (columns of ``null``) that the fit
    found unseparable, to where the parameters the fit set to 0 are 0: the truth of each value
    the fit reports; and each one's scale, the sum of its parts' magnitudes (|m_b| + 400
    |J_rot,s|; |f_dv,2| + |f_dv,4| for the difference f_dv,2 − f_dv,4 of two nearly equal
    values)."""
    null = null[:, [in_null_space(sol, v) for v in null.T]]
    m = truth.vector(sol.names)
    dep = [i for i, s in enumerate(sol.std) if not np.isfinite(s)]
    c = np.linalg.lstsq(null[dep], -m[dep], rcond=None)[0]
    scale = np.abs(m) + np.abs(null * c).sum(axis=1)
    return (dict(zip(sol.names, m + null @ c, strict=True)),
            dict(zip(sol.names, scale, strict=True)))


def test_four_wheels_exact_logs_determine_every_combination_within_one_percent(
        four_sample) -> None:
    """Exact 100 Hz logs of four steered wheels (a typical and an optimised run, four variants
    each; each current the mean over its log interval): the fit's own rank analysis finds
    exactly the two combinations derived in :func:`four_wheel_null_space` (its null space spans
    them), and every value it determines lies within 1 % of the truth's combination (of its
    parts' magnitudes: the drives' f_dv,2 − f_dv,4 is 0.023 of 0.69 N m s/rad each; measured
    0.06 % of the parts, −1.8 % of the difference), J_st within 0.5 % (+0.27 %; +2.3 % when
    the currents are point samples: ``make_dataset.py``). (It and the mixed platform's test
    replace a live 4 s simulation's, whose assertions — the combinations' names, m_b and
    J_zz,b within 1 %, J_st within 10 % — these assert more tightly on longer runs.)"""
    pf, truth, logs = four_sample
    sol = fit_logs(logs, pf).solution
    null = four_wheel_null_space(list(sol.names))
    assert sol.null_space.shape[1] == 2
    assert all(in_null_space(sol, v) for v in null.T)
    assert sol.combinations["m_b"].startswith("m_b +400·Jrot_s")
    expect, scale = compared(sol, truth, null)
    for name, value, std in zip(sol.names, sol.values, sol.std, strict=True):
        if np.isfinite(std):
            tol = 0.005 if name == "Jst" else 0.01
            assert abs(value - expect[name]) < tol * scale[name], (name, value, expect[name])


def test_four_wheels_noisy_logs_are_covered_by_sigma(four_sample) -> None:
    """The same logs as 2¹⁴-count encoders and 30 mA current noise record them: every value
    the plain fit determines within 3σ of the truth's combination (over seeds 1–6 the largest
    is J_zz,b's, 2.2–2.9σ: the encoders' bias, −1.7 to −2.0 %; ``--encoder-counts``
    over-corrects m_b on these logs, +0.8 to +4.2σ off the truth's combination; +1.9 to +6.2σ
    with a white share per encoder); seed 2 here."""
    pf, truth, logs = four_sample
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03)
    rng = np.random.default_rng(2)
    noisy = [sensed(log, pf, sensors, rng) for log in logs]
    fit = fit_logs(noisy, pf)
    # the fit notes the encoders' counts and that their correction can over-correct here
    assert ("whole counts of 2π/16384" in fit.logs[0].notes[-1]
            and "can over-correct" in fit.logs[0].notes[-1])
    sol = fit.solution
    expect, _ = compared(sol, truth, four_wheel_null_space(list(sol.names)))
    for name, value, std in zip(sol.names, sol.values, sol.std, strict=True):
        if np.isfinite(std):
            assert abs(value - expect[name]) < 3 * std, (name, value, expect[name], std)


@pytest.fixture(scope="module")
def mixed_sample() -> tuple:
    """The shipped exact logs of two steered wheels and two swivel casters: platform, truth,
    logs."""
    return shipped("steered-swivel")


def test_mixed_exact_logs_determine_every_combination_within_one_percent(mixed_sample) -> None:
    """Exact 100 Hz logs of steered wheels at (0.3, 0.2) and (−0.3, −0.2) m and swivel casters
    at the other corners (an optimised run, each current the mean over its log interval): the
    rank analysis names the lumps derived from the wheels that cannot slip sideways — each
    J_rot/r² a point mass at its wheel (steered: 2/r² = 200 and Σ|p|²/r² = 26; the casters'
    four wheels: 400 and 52, their hubs 2·m_wh and Σ|p|² = 0.26 m²) — and, fitted with
    five-point differences (``--smoother quartic``, 0.15 s), every value it determines lies
    within 1 % of the truth's (measured: the casters' J_zz,wh combination −0.9 %, the rest
    within 0.4 %; the default three-point differences attenuate the casters' fast pivot
    accelerations: J_zz,wh −3.6 %)."""
    pf, truth, logs = mixed_sample
    span = Span.parse("0.15s").with_smoother("quartic")
    sol = fit_logs(logs, pf, FitOptions(span=span)).solution
    assert sol.combinations["m_b"] == "m_b +200·Jrot_s +2·m_wh +400·Jrot_w"
    assert sol.combinations["Jzz_b"] == "Jzz_b +26·Jrot_s +0.26·m_wh +52·Jrot_w"
    expect = dict(zip(sol.names, sol.combination_of(truth.vector(sol.names)), strict=True))
    for name, value, std in zip(sol.names, sol.values, sol.std, strict=True):
        if np.isfinite(std):
            assert value == pytest.approx(expect[name], rel=0.01), name


def test_mixed_noisy_logs_are_covered_by_sigma(mixed_sample) -> None:
    """The same logs as 2¹⁴-count encoders and 30 mA current noise record them: every value
    the plain fit determines within 3σ of the truth's combination."""
    pf, truth, logs = mixed_sample
    rng = np.random.default_rng(1)
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03)
    sol = fit_logs([sensed(log, pf, sensors, rng) for log in logs], pf).solution
    expect = dict(zip(sol.names, sol.combination_of(truth.vector(sol.names)), strict=True))
    for name, value, std in zip(sol.names, sol.values, sol.std, strict=True):
        if np.isfinite(std):
            assert abs(value - expect[name]) < 3 * std, (name, value, expect[name], std)
