"""The modular model against the thesis's closed forms and an independent route (energy)."""

from __future__ import annotations

import numpy as np
import pytest

from ropod_sysid.model import PlatformModel
from ropod_sysid.params import DynamicParameters, parameter_names, thesis_fixed_masses
from ropod_sysid.platform import platform_from_dict, ropod_platform
from tests.swivel_arrays import angles_of


@pytest.fixture(scope="module")
def ropod():
    pf = ropod_platform()
    return pf, PlatformModel(pf), thesis_fixed_masses(pf.unit_names)


def random_state(model: PlatformModel, n: int = 50, seed: int = 0):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 3)) * [2.0, 2.0, 3.0]
    qd = rng.normal(size=(n, 3))
    delta = rng.uniform(-np.pi, np.pi, size=(n, model.n_units))
    return q, qd, delta, model.state(q, qd, angles_of(delta))


def test_det_a_iwh_is_minus_caster_offset(ropod):
    pf, model, _ = ropod
    *_, st = random_state(model)
    det = np.linalg.det(st.units[0].a_iwh)
    np.testing.assert_allclose(det, -pf.units[0].caster_offset, rtol=1e-12)


def test_m_add_minors_match_eqs_50_51(ropod):
    pf, model, p = ropod
    q, _, delta, st = random_state(model)
    m_add = model.groups[0][1].m_add(st.units[0], p)  # (N, k, 3, 3)
    u = pf.units[0]
    r_w, d_w, s_w, dx = u.wheel_radius, u.wheel_distance, u.caster_offset, u.hub_com_offset
    m_wh, jzz_wh, jrot_w = p["m_wh"], p["Jzz_wh"], p["Jrot_w"]
    th_i = q[:, 2:3] + delta
    # eq. 50 as corrected in docs/method.md
    m11 = (np.cos(th_i) ** 2 * (m_wh + 2 * jrot_w / r_w**2)
           + np.sin(th_i) ** 2 * (2 * jzz_wh * r_w**2 + jrot_w * d_w**2
                                  + 2 * dx**2 * r_w**2 * m_wh) / (2 * r_w**2 * s_w**2))
    np.testing.assert_allclose(m_add[..., 0, 0], m11, rtol=1e-10)
    # eq. 51: the second leading minor does not depend on the state
    minor2 = ((m_wh * r_w**2 + 2 * jrot_w) / (2 * r_w**4 * s_w**2)
              * (jrot_w * d_w**2 + 2 * m_wh * dx**2 * r_w**2 + 2 * jzz_wh * r_w**2))
    np.testing.assert_allclose(np.linalg.det(m_add[..., :2, :2]), minor2, rtol=1e-9)
    # rank 2: the third minor vanishes, two singular values do not
    sv = np.linalg.svd(m_add, compute_uv=False)
    assert np.all(sv[..., 2] < 1e-9 * sv[..., 0])
    assert np.all(sv[..., 1] > 1e-6 * sv[..., 0])


def test_printed_eq_50_is_wrong_for_a_unit_along_x(ropod):
    """Driving along the unit axis must accelerate m_wh + 2 J_rot/R_w²: not zero as printed."""
    pf, model, p = ropod
    st = model.state(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 12)))
    m_add = model.groups[0][1].m_add(st.units[0], p)
    np.testing.assert_allclose(m_add[0, :, 0, 0],
                               p["m_wh"] + 2 * p["Jrot_w"] / pf.units[0].wheel_radius**2)


def test_m_dir_symmetric_positive_definite(ropod):
    _, model, p = ropod
    *_, st = random_state(model, 200, seed=3)
    m_dir = model.direct_eom(st, p).m_dir
    np.testing.assert_allclose(m_dir, np.swapaxes(m_dir, 1, 2), atol=1e-9)
    assert np.all(np.linalg.eigvalsh(m_dir)[:, 0] > 0)


def test_kinetic_energy_equals_quadratic_form(ropod):
    """Independent route: ½ q̇ᵀ M_dir q̇ equals the bodies' kinetic energies summed."""
    _, model, p = ropod
    _, qd, _, st = random_state(model, seed=5)
    m_dir = model.direct_eom(st, p).m_dir
    quad = 0.5 * np.einsum("ni,nij,nj->n", qd, m_dir, qd)
    np.testing.assert_allclose(model.kinetic_energy(st, p), quad, rtol=1e-12)


def test_b_tau_fp_equals_eq_64_and_virtual_work(ropod):
    """B_τfp of eq. 64 equals the virtual-work route (e3 − a^θ̈_i)ᵀ."""
    _, model, _ = ropod
    *_, st = random_state(model, seed=7)
    u = st.units[0]
    expect = -u.a_theta.copy()
    expect[..., 2] += 1.0
    np.testing.assert_allclose(u.b_tau_fp, np.moveaxis(expect, 1, 2), atol=1e-9)


def test_b_tau_equals_wheel_jacobian(ropod):
    """Virtual work: B_τ,iw = (∂φ̇_iw/∂q̇_b)ᵀ, the wheel rate Jacobian (eqs. 11, 32)."""
    _, model, _ = ropod
    q, qd, delta, st = random_state(model, 20, seed=11)
    angles = angles_of(delta)
    jac = np.stack([model.actuator_rates(q, np.broadcast_to(e, qd.shape), angles)
                    for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(st.b_tau, jac, atol=1e-9)
    np.testing.assert_allclose(model.actuator_rates(q, qd, angles), st.actuator_rate,
                               atol=1e-12)


def test_regressor_reproduces_eom(ropod):
    """A_ID,ext m_ext = M_dir q̈ − b_dir − B_τ τ_fw − B_τfp τ_fp for any q̈ (eqs. 35, 66)."""
    pf, model, p = ropod
    rng = np.random.default_rng(2)
    q, qd, delta, st = random_state(model, 30, seed=2)
    qdd = rng.normal(size=(30, 3))
    for friction in ("per-wheel", "shared"):
        names = parameter_names(pf, friction)
        pp = p if friction == "per-wheel" else DynamicParameters.from_vector(
            p.vector(names), names)
        eom2 = model.direct_eom(st, pp, friction)
        assert eom2.f_f is not None  # pivot friction, B_τfp τ_fp (eq. 64)
        lhs2 = (np.einsum("ncd,nd->nc", eom2.m_dir, qdd) - eom2.b_dir
                - np.einsum("nca,na->nc", eom2.b_tau, eom2.tau_f) - eom2.f_f)
        a = model.a_id_ext(st, qdd, friction)
        assert a.shape == (30, 3, len(model.parameter_names(friction)))
        np.testing.assert_allclose(a @ pp.vector(names), lhs2, atol=1e-8)
    assert model.a_id_ext(st, qdd).shape[2] == 29


def test_forward_and_inverse_dynamics_agree(ropod):
    _, model, p = ropod
    rng = np.random.default_rng(4)
    *_, st = random_state(model, 25, seed=4)
    qdd = rng.normal(size=(25, 3))
    tau = model.inverse_dynamics(st, p, qdd)
    np.testing.assert_allclose(model.forward_dynamics(st, p, tau), qdd, atol=1e-9)
    # minimum norm: any other solution differs by a null-space vector of B_τ
    f_b = model.disturbance(st, p, qdd, tau)
    np.testing.assert_allclose(f_b, 0.0, atol=1e-8)


def test_disturbance_recovers_applied_force(ropod):
    _, model, p = ropod
    rng = np.random.default_rng(9)
    *_, st = random_state(model, 25, seed=9)
    tau = rng.normal(size=(25, 4, 2)).reshape(25, 8)
    f_b = rng.normal(size=(25, 3)) * [40, 40, 10]
    qdd = model.forward_dynamics(st, p, tau, f_b)
    np.testing.assert_allclose(model.disturbance(st, p, qdd, tau), f_b, atol=1e-8)


def test_static_magnification_is_four(ropod):
    """Sec. VIII-A: wheel friction torques weigh d_w/(2 s_w) = 4 times more on the platform when
    a unit stands across the force than when it is aligned with it.

    Aligned, equal roll friction torques τ_f on both wheels give a force 2 τ_f/R_w at the pivot;
    turned 90°, the wheels counter-rotate, the torques are opposite, and the pivot force is
    (τ_f/R_w) d_w/s_w (lever d_w over lever s_w).
    """
    pf, model, _ = ropod
    delta = np.array([[np.pi / 2, 0.0, 0.0, 0.0]])
    st = model.state(np.zeros((1, 3)), np.zeros((1, 3)), angles_of(delta))
    tau_f = 0.3
    u = pf.units[0]
    across = st.b_tau[0, :2, 0:2] @ np.array([-tau_f, tau_f])  # unit 1 (L, R), δ = 90°
    aligned = st.b_tau[0, :2, 2:4] @ np.array([tau_f, tau_f])  # unit 2, δ = 0
    np.testing.assert_allclose(np.linalg.norm(aligned), 2 * tau_f / u.wheel_radius)
    ratio = np.linalg.norm(across) / np.linalg.norm(aligned)
    assert ratio == pytest.approx(u.wheel_distance / (2 * u.caster_offset), rel=1e-12)
    assert ratio == pytest.approx(4.0, rel=1e-12)
    # the across force pushes along the base x axis, the unit's lateral direction
    assert abs(across[1]) < 1e-9 * abs(across[0])


def test_eight_unit_platform_needs_no_code_change():
    """Two ropods bolted together: the model is modular in the number of units."""
    base = ropod_platform().to_dict()
    units = [{"name": f"{k + 1}", "pivot": [x + dx, y]}
             for k, (dx, (x, y)) in enumerate(
                 [(dx, u["pivot"]) for dx in (-0.33, 0.33) for u in base["units"]])]
    pf = platform_from_dict(base | {"units": units}, "<8 units>")
    model = PlatformModel(pf)
    p = thesis_fixed_masses(pf.unit_names)
    q, qd, delta, st = random_state(model, 10, seed=1)
    eom = model.direct_eom(st, p)
    assert eom.b_tau.shape == (10, 3, 8 * 2)
    assert np.all(np.linalg.eigvalsh(eom.m_dir)[:, 0] > 0)
    assert model.a_id_ext(st, np.ones((10, 3))).shape == (10, 3, 5 + 6 * 8)
    np.testing.assert_allclose(model.kinetic_energy(st, p),
                               0.5 * np.einsum("ni,nij,nj->n", qd, eom.m_dir, qd), rtol=1e-12)


def test_groups_and_platform_order_are_invisible():
    """Units of different geometry form separate groups; per-channel arrays (B_τ, τ_f, rates)
    still follow the platform file's order. Every term is the sum of its groups' terms — two
    half platforms added, the base counted once — and listing the units in another order only
    reorders the channels."""
    from ropod_sysid.model import base

    data = ropod_platform().to_dict()
    for k in (0, 2):
        data["units"][k] |= {"wheel_radius": 0.06, "caster_offset": 0.015}
    mixed = platform_from_dict(data, "<mixed>")

    def sub(idx: list[int]):
        return platform_from_dict(data | {"units": [data["units"][k] for k in idx]}, "<sub>")

    order = [0, 2, 1, 3]  # units 1, 3, 2, 4: one group after the other
    reordered = sub(order)
    halves = [sub([0, 2]), sub([1, 3])]
    m_mixed, m_reord = PlatformModel(mixed), PlatformModel(reordered)
    m_halves = [PlatformModel(h) for h in halves]
    assert [len(g.units) for g, _ in m_mixed.groups] == [2, 2]
    assert [list(g.units) for g, _ in m_mixed.groups] == [[0, 2], [1, 3]]
    assert len(m_reord.groups) == 2 and all(len(m.groups) == 1 for m in m_halves)
    p = thesis_fixed_masses(mixed.unit_names)
    rng = np.random.default_rng(12)
    q, qd, qdd = rng.normal(size=(3, 7, 3))
    angles = rng.uniform(-3, 3, size=(7, 12))  # δ, φ_L, φ_R per unit
    rates = rng.normal(size=(7, 12))
    tau = rng.normal(size=(7, 8))

    def channels(x: np.ndarray, per_unit: int, units: list[int]) -> np.ndarray:
        """The channels of these units (platform order of ``mixed``), last axis."""
        return x.reshape(*x.shape[:-1], 4, per_unit)[..., units, :].reshape(
            *x.shape[:-1], per_unit * len(units))

    groups = [[0, 2], [1, 3]]
    s_mixed = m_mixed.state(q, qd, angles, rates)
    s_reord = m_reord.state(q, qd, channels(angles, 3, order), channels(rates, 3, order))
    s_halves = [m.state(q, qd, channels(angles, 3, g), channels(rates, 3, g))
                for m, g in zip(m_halves, groups, strict=True)]
    e1, e2 = m_mixed.direct_eom(s_mixed, p), m_reord.direct_eom(s_reord, p)
    eh = [m.direct_eom(s, p) for m, s in zip(m_halves, s_halves, strict=True)]
    m_b = base.m_b(p["m_b"], p["Jzz_b"], 7)
    np.testing.assert_allclose(e1.m_dir, e2.m_dir, atol=1e-12)
    np.testing.assert_allclose(e1.m_dir, eh[0].m_dir + eh[1].m_dir - m_b, atol=1e-12)
    for name in ("b_dir", "f_f"):
        np.testing.assert_allclose(getattr(e1, name), getattr(e2, name), atol=1e-12)
        np.testing.assert_allclose(getattr(e1, name), getattr(eh[0], name)
                                   + getattr(eh[1], name), atol=1e-12)
    for name in ("b_tau", "tau_f"):
        np.testing.assert_allclose(channels(getattr(e1, name), 2, order), getattr(e2, name),
                                   atol=1e-12)
        for g, e in zip(groups, eh, strict=True):
            np.testing.assert_allclose(channels(getattr(e1, name), 2, g), getattr(e, name),
                                       atol=1e-12)
    ke_base = base.kinetic_energy_base(p["m_b"], p["Jzz_b"], qd)
    np.testing.assert_allclose(m_mixed.kinetic_energy(s_mixed, p),
                               sum(m.kinetic_energy(s, p) for m, s in zip(m_halves, s_halves,
                                                                          strict=True))
                               - ke_base, rtol=1e-12)
    np.testing.assert_allclose(m_mixed.forward_dynamics(s_mixed, p, tau),
                               m_reord.forward_dynamics(s_reord, p, channels(tau, 2, order)),
                               atol=1e-12)
    for friction in ("per-wheel", "shared"):
        names = m_mixed.parameter_names(friction)
        a1 = m_mixed.a_id_ext(s_mixed, qdd, friction)
        a2 = m_reord.a_id_ext(s_reord, qdd, friction)
        col2 = {n: k for k, n in enumerate(m_reord.parameter_names(friction))}
        assert sorted(col2) == sorted(names)
        np.testing.assert_allclose(a1, a2[..., [col2[n] for n in names]], atol=1e-12)
        a_h = [(m.a_id_ext(s, qdd, friction), m.parameter_names(friction))
               for m, s in zip(m_halves, s_halves, strict=True)]
        for k, n in enumerate(names):
            want = sum(a[..., h.index(n)] for a, h in a_h if n in h)
            if n in ("m_b", "Jzz_b"):
                want = want - a_h[0][0][..., a_h[0][1].index(n)]  # the base, once
            np.testing.assert_allclose(a1[..., k], want, atol=1e-12, err_msg=n)
    np.testing.assert_allclose(channels(m_mixed.angle_rates(q, qd, angles), 3, order),
                               m_reord.angle_rates(q, qd, channels(angles, 3, order)),
                               atol=1e-12)
    np.testing.assert_allclose(channels(m_mixed.actuator_rates(q, qd, angles), 2, [1, 3]),
                               m_halves[1].actuator_rates(q, qd, channels(angles, 3, [1, 3])),
                               atol=1e-12)
