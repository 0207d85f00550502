"""The simulator's compiled path: the whole RK4 loop of :func:`ropod_sysid.simulate.simulate`
in numba, for a platform whose unit groups all have a compiled kernel.

Each unit type may offer a kernel of one sample (``UnitType.compiled(params, variant)``: the
kernel module, e.g. :mod:`ropod_sysid.model.units.swivel_jit`, and its geometry and parameter
arrays). The groups of a platform are passed as flat arrays with offsets (a kernel id per group),
so one compiled loop serves every list of groups; the kernels are dispatched by id
(:data:`KERNELS`). The state is x = (q_b, q̇, unit angles) with q̇ (D,) the generalized velocity:
the base twist, then the rates of the units' own coordinates (the steered wheels' β̇; D = 3
without them). Per RK4 stage it sums the base's M_b (eq. 2) and every group's M_add, b_dir, B_τ,
friction torques τ_f and generalized friction force f_f into eq. 65 (D × D) and solves eq. 33;
body-axis friction (004 eqs. 6–8) and the external force B_Fb F_b (eq. 3) are added on the
base. Constraint rows G the units do not eliminate (the steered wheels' lateral no-slip) are
taken at their consistent rank and enforced with Baumgarte's term as
:meth:`ropod_sysid.model.PlatformModel.forward_dynamics` does (Udwadia and Kalaba):
q̈ = a + M⁻¹Gᵀ (G M⁻¹ Gᵀ)⁺ (c − G a), the symmetric eigen-decompositions by cyclic Jacobi
rotations (:func:`_eigh`) instead of LAPACK's. The controller (per actuator: PI on the rate, or
PD on the planned angle for the position-controlled steering, 001 eqs. 24–25; anti-windup,
torque limit), the setpoints on the step grid, the recording every ``stride`` steps and the
kinetic energy are the same as the numpy path's, which stays the reference (results equal to
round-off, ``tests/test_simulate_jit.py``).

:func:`run` alone is called from Python and cached on disk (``cache=True``): the first call in
a fresh environment compiles (about 11 s, numba's typing and lowering more than LLVM), later
processes load the cache (about 1 s). Platforms with constraint rows pass their scratch
(``cons``, :func:`constraint_scratch`), the others None, and numba prunes every branch under
``cons is None`` to the one it takes: the loop without constraint rows compiles neither the
steered kernel nor the constrained solve, and platforms with steered units compile a second
specialization of run on their first call (about 18 s; 1 s to load). The functions it calls are
compiled into it: they have no Python wrapper and no cache of their own
(``no_cpython_wrapper=True``; each wrapper and cache cost the first compile a fraction of a
second); the kind dispatchers (``_unit_*``) and the functions run calls from one place
(:func:`_eom`, :func:`_control`, :func:`_accel` with :func:`_constrained`, :func:`_rates`,
:func:`_energy`) are inlined into their callers (``inline="always"``), so no separately
optimised library sits between the loop and the kernels (each library is optimised again with
all it links in: inlining them cut the steered specialization's compile from 23.0 to 18.5 s of
CPU, one measurement each); the kernels themselves are not (inlined too, they cost the ropod's
compile 5–11 s more in two measurements). Arrays are copied element by element, not by slice
assignment, which would compile numba's shape-mismatch message (3 s of string formatting).
numba checks a cached function only against its own source file, not those of the functions
it calls, so :func:`run`'s cache is flushed when a kernel module's source changes
(:func:`_refresh_caches`).
"""

from __future__ import annotations

import hashlib
import inspect
import math
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

try:
    import fcntl
except ImportError:  # not on Windows: there every process compiles for itself
    fcntl = None  # type: ignore[assignment]

import numpy as np
from numba import njit, types

from ropod_sysid.model import PlatformModel, base
from ropod_sysid.model.units import omni_jit, steered_jit, swivel_jit

KERNELS: tuple[Any, ...] = (swivel_jit, omni_jit, steered_jit)  # a kernel's id: its index here
CHUNK = 2000  # steps per compiled call (between progress-bar updates)
NO_TORQUES = np.zeros((1, 1, 1))  # run's tau_given when its controller acts
# :func:`_eigh` turns a pair while its off-diagonal entry exceeds this × the geometric mean of
# their diagonal entries (round-off: the eigenvalues to relative precision), in at most
# JACOBI_SWEEPS sweeps (G Gᵀ of 4–8 wheels, rank 3, took 5–10 in a test of random rows)
JACOBI_TOL = 2.2e-16
JACOBI_SWEEPS = 50


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _unit_dynamics(head: np.ndarray, geo: np.ndarray, par: np.ndarray, ia: np.ndarray,
                   ic: np.ndarray, q: np.ndarray, qd: np.ndarray, ang: np.ndarray,
                   m: np.ndarray, b: np.ndarray, btau: np.ndarray, tauf: np.ndarray,
                   ff: np.ndarray, arate: np.ndarray, crate: np.ndarray,
                   cons: tuple | None) -> None:
    kind = head[0]
    if cons is None:  # no constraint rows, no steered units: numba compiles only this branch
        if kind == 0:
            swivel_jit.dynamics(geo, par, ia, ic, q, qd, ang, m, b, btau, tauf, ff, arate,
                                crate)
        else:
            omni_jit.dynamics(geo, par, ia, ic, q, qd, ang, m, b, btau, tauf, ff, arate, crate)
    elif kind == 0:
        swivel_jit.dynamics(geo, par, ia, ic, q, qd, ang, m, b, btau, tauf, ff, arate, crate)
    elif kind == 1:
        omni_jit.dynamics(geo, par, ia, ic, q, qd, ang, m, b, btau, tauf, ff, arate, crate)
    else:
        steered_jit.dynamics(geo, par, ia, ic, head[1], head[2], q, qd, ang, m, b, btau, tauf,
                             arate, crate, cons[0], cons[1])


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _unit_setpoints(head: np.ndarray, geo: np.ndarray, ia: np.ndarray, ic: np.ndarray,
                    plan: np.ndarray, q: np.ndarray, qd: np.ndarray, twist: np.ndarray,
                    ang: np.ndarray, want: np.ndarray, err: np.ndarray,
                    cons: tuple | None) -> None:
    kind = head[0]
    if cons is None:  # as :func:`_unit_dynamics`
        if kind == 0:
            swivel_jit.actuator_rates(geo, ia, ic, q, qd, ang, want)
        else:
            omni_jit.actuator_rates(geo, ia, ic, q, qd, ang, want)
    elif kind == 0:
        swivel_jit.actuator_rates(geo, ia, ic, q, qd, ang, want)
    elif kind == 1:
        omni_jit.actuator_rates(geo, ia, ic, q, qd, ang, want)
    else:
        steered_jit.setpoints(geo, ia, ic, plan[head[3]:], twist, ang, want, err)


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _unit_energy(head: np.ndarray, geo: np.ndarray, par: np.ndarray, ia: np.ndarray,
                 q: np.ndarray, qd: np.ndarray, ang: np.ndarray, cons: tuple | None) -> float:
    kind = head[0]
    if cons is None:  # as :func:`_unit_dynamics`
        if kind == 0:
            return swivel_jit.kinetic_energy(geo, par, ia, q, qd, ang)
        return omni_jit.kinetic_energy(geo, par, ia, q, qd, ang)
    if kind == 0:
        return swivel_jit.kinetic_energy(geo, par, ia, q, qd, ang)
    if kind == 1:
        return omni_jit.kinetic_energy(geo, par, ia, q, qd, ang)
    return steered_jit.kinetic_energy(geo, par, ia, head[1], q, qd, ang)


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _eom(groups: tuple, cons: tuple | None, bp: np.ndarray, x: np.ndarray, m: np.ndarray,
         b: np.ndarray, btau: np.ndarray, tauf: np.ndarray, ff: np.ndarray, arate: np.ndarray,
         crate: np.ndarray) -> None:
    """The terms of eq. 65 at the state x = (q_b, q̇, unit angles): M_dir = M_b + Σ M_add
    (eqs. 2, 49), Σ b_dir, B_τ, τ_f and f_f (with body-axis friction) (D × D, D, …), the unit
    rates and the constraint rows G, Ġ q̇ into ``cons`` (:func:`constraint_scratch`)."""
    heads, geo, goff, par, poff, ia, iaoff, ic, icoff, dims = groups
    n_dof = dims[0]
    q, qd, ang = x[0:3], x[3:3 + n_dof], x[3 + n_dof:]
    m[:, :] = 0.0
    m[0, 0] = bp[0]
    m[1, 1] = bp[0]
    m[2, 2] = bp[1]
    b[:] = 0.0
    ff[:] = 0.0
    for k in range(heads.shape[0]):
        _unit_dynamics(heads[k], geo[goff[k]:goff[k + 1]], par[poff[k]:poff[k + 1]],
                       ia[iaoff[k]:iaoff[k + 1]], ic[icoff[k]:icoff[k + 1]], q, qd, ang, m, b,
                       btau, tauf, ff, arate, crate, cons)
    if bp[3] != 0.0:
        # body-axis friction F_f = f_bv ⊙ ν + f_bc ⊙ tanh(α ν), ν the twist in the base frame
        # (004 eqs. 1, 6–8), on the base through B_Fb (eq. 3)
        c, s = math.cos(q[2]), math.sin(q[2])
        nu0 = c * qd[0] + s * qd[1]
        nu1 = -s * qd[0] + c * qd[1]
        nu2 = qd[2]
        alpha = bp[2]
        f0 = bp[4] * nu0 + bp[7] * math.tanh(alpha * nu0)
        f1 = bp[5] * nu1 + bp[8] * math.tanh(alpha * nu1)
        f2 = bp[6] * nu2 + bp[9] * math.tanh(alpha * nu2)
        ff[0] += c * f0 - s * f1
        ff[1] += s * f0 + c * f1
        ff[2] += f2


@njit(no_cpython_wrapper=True, error_model="numpy")
def _factor(a: np.ndarray, piv: np.ndarray) -> None:
    """LU factors of a square matrix in place (Gaussian elimination with partial pivoting, as
    LAPACK's getrf): U on and above the diagonal, L's multipliers below, ``piv[col]`` the row
    swapped with ``col``."""
    n = a.shape[0]
    for col in range(n):
        p = col
        for r in range(col + 1, n):
            if abs(a[r, col]) > abs(a[p, col]):
                p = r
        piv[col] = p
        if p != col:
            for c in range(n):
                a[col, c], a[p, c] = a[p, c], a[col, c]
        for r in range(col + 1, n):
            f = a[r, col] / a[col, col]
            a[r, col] = f
            for c in range(col + 1, n):
                a[r, c] -= f * a[col, c]


@njit(no_cpython_wrapper=True, error_model="numpy")
def _solve(a: np.ndarray, piv: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out = A⁻¹ y from the factors of :func:`_factor` (as getrs); ``y`` is overwritten."""
    n = a.shape[0]
    for col in range(n):
        p = piv[col]
        if p != col:
            y[col], y[p] = y[p], y[col]
        for r in range(col + 1, n):
            y[r] -= a[r, col] * y[col]
    for r in range(n - 1, -1, -1):
        acc = y[r]
        for c in range(r + 1, n):
            acc -= a[r, c] * out[c]
        out[r] = acc / a[r, r]


@njit(no_cpython_wrapper=True, error_model="numpy")
def _eigh(a: np.ndarray, vec: np.ndarray, lam: np.ndarray, n: int) -> None:
    """Eigenvalues ``lam`` (n,) and eigenvectors (the columns of ``vec``, n × n) of the
    symmetric matrix whose lower triangle the leading n × n block of ``a`` holds (as LAPACK's
    syevd reads it), by cyclic Jacobi rotations until a sweep turns no pair
    (:data:`JACOBI_TOL`); ``a`` is overwritten."""
    for i in range(n):
        for j in range(n):
            if j > i:
                a[i, j] = a[j, i]
            vec[i, j] = 1.0 if i == j else 0.0
    for _ in range(JACOBI_SWEEPS):
        turned = False
        for p in range(n - 1):
            for r in range(p + 1, n):
                apr = a[p, r]
                if abs(apr) <= JACOBI_TOL * math.sqrt(abs(a[p, p] * a[r, r])):
                    continue  # below round-off of the diagonal (and 0): no turn
                turned = True
                # the rotation that zeros a[p, r]: t = tan φ, the smaller root of
                # t² + 2 ϑ t − 1 = 0, ϑ = (a_rr − a_pp) / (2 a_pr) (t = 0 where ϑ² overflows)
                theta = (a[r, r] - a[p, p]) / (2.0 * apr)
                t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):
                    akp, akr = a[k, p], a[k, r]
                    a[k, p] = c * akp - s * akr
                    a[k, r] = s * akp + c * akr
                for k in range(n):
                    apk, ark = a[p, k], a[r, k]
                    a[p, k] = c * apk - s * ark
                    a[r, k] = s * apk + c * ark
                for k in range(n):
                    vkp, vkr = vec[k, p], vec[k, r]
                    vec[k, p] = c * vkp - s * vkr
                    vec[k, r] = s * vkp + c * vkr
                a[p, r] = 0.0
                a[r, p] = 0.0
        if not turned:
            break
    for i in range(n):
        lam[i] = a[i, i]


@njit(no_cpython_wrapper=True, error_model="numpy")
def _gram(g: np.ndarray, h: np.ndarray, n: int, s: np.ndarray) -> None:
    """The lower triangle of G H (H = ``h`` (D, C)) over G's first n rows into ``s``."""
    for i in range(n):
        for j in range(i + 1):
            acc = 0.0
            for d in range(g.shape[1]):
                acc += g[i, d] * h[d, j]
            s[i, j] = acc


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _constrained(cons: tuple, bp: np.ndarray, x: np.ndarray, m: np.ndarray, piv: np.ndarray,
                 rhs: np.ndarray, qdd: np.ndarray) -> None:
    """q̈ = a + M⁻¹Gᵀ (G M⁻¹ Gᵀ)⁺ (c − G a) for the unconstrained q̈ = a (in ``qdd``, M's
    factors in ``m``, ``piv``), c = −Ġ q̇ − β G q̇ (Baumgarte's β = bp[10]; eigenvalues of
    G M⁻¹ Gᵀ below bp[11] × the largest left free: slip), as
    :meth:`PlatformModel.forward_dynamics`. More rows than their consistent rank r are taken
    as that nearest set (:func:`ropod_sysid.model.assembly.consistent_constraints`, U_r U_rᵀ G
    with U_r G's r leading left singular vectors, the leading eigenvectors of G Gᵀ), here as
    the r rows U_rᵀ G and U_rᵀ Ġ q̇: the same q̈, since the dropped directions carry
    eigenvalues of G M⁻¹ Gᵀ at round-off, which the pseudo-inverse leaves out. ``cons``'s G
    and Ġ q̇ are overwritten."""
    g, gdot, rank, col, v, mg, s, vec, lam = cons
    n_con, n_dof = g.shape
    n = n_con
    if n_con > rank[0]:  # U_rᵀ G and U_rᵀ Ġ q̇ in G's first r rows, U_r from G Gᵀ
        n = rank[0]
        for j in range(n_con):
            for d in range(n_dof):
                mg[d, j] = g[j, d]
        _gram(g, mg, n_con, s)  # G Gᵀ
        _eigh(s, vec, lam, n_con)
        for t in range(n):  # the largest eigenvalues, one at a time
            top = 0
            for j in range(1, n_con):
                if lam[j] > lam[top]:
                    top = j
            lam[top] = -np.inf
            for d in range(n_dof):
                acc = 0.0
                for j in range(n_con):
                    acc += vec[j, top] * g[j, d]
                mg[d, t] = acc
            acc = 0.0
            for j in range(n_con):
                acc += vec[j, top] * gdot[j]
            col[t] = acc
        for t in range(n):
            for d in range(n_dof):
                g[t, d] = mg[d, t]
            gdot[t] = col[t]
    # M⁻¹Gᵀ (D × n) and the residual c − G a into col
    for j in range(n):
        for d in range(n_dof):
            rhs[d] = g[j, d]
        _solve(m, piv, rhs, v)
        acc = 0.0
        for d in range(n_dof):
            mg[d, j] = v[d]
            acc += g[j, d] * (bp[10] * x[3 + d] + qdd[d])
        col[j] = -gdot[j] - acc
    _gram(g, mg, n, s)  # S = G M⁻¹ Gᵀ
    _eigh(s, vec, lam, n)
    top = lam[0]
    for j in range(1, n):
        top = max(top, lam[j])
    for j in range(n):  # λ = S⁺ (c − G a) by the eigenvectors
        acc = 0.0
        for i in range(n):
            acc += vec[i, j] * col[i]
        v[j] = acc / lam[j] if lam[j] > bp[11] * top else 0.0
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += vec[i, j] * v[j]
        col[i] = acc
    for d in range(n_dof):
        acc = 0.0
        for j in range(n):
            acc += mg[d, j] * col[j]
        qdd[d] += acc


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _accel(cons: tuple | None, bp: np.ndarray, x: np.ndarray, m: np.ndarray, b: np.ndarray,
           btau: np.ndarray, tauf: np.ndarray, ff: np.ndarray, tau: np.ndarray,
           fb: np.ndarray, has_fb: bool, rhs: np.ndarray, piv: np.ndarray,
           qdd: np.ndarray) -> None:
    """q̈ = M_dir⁻¹ (B_Fb F_b + B_τ (τ + τ_f) + f_f + b_dir) (eqs. 33, 65), with constraint
    rows projected out (:func:`_constrained`); ``m`` is overwritten."""
    for c in range(m.shape[0]):
        acc = 0.0
        for a in range(tau.shape[0]):
            acc += btau[c, a] * (tau[a] + tauf[a])
        rhs[c] = acc + ff[c] + b[c]
    if has_fb:
        ct, st = math.cos(x[2]), math.sin(x[2])
        rhs[0] += ct * fb[0] - st * fb[1]
        rhs[1] += st * fb[0] + ct * fb[1]
        rhs[2] += fb[2]
    _factor(m, piv)
    _solve(m, piv, rhs, qdd)
    if cons is not None:
        _constrained(cons, bp, x, m, piv, rhs, qdd)


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _rates(x: np.ndarray, n_dof: int, arate: np.ndarray, k: np.ndarray) -> None:
    """The rates of the state besides q̈ into ``k``: q̇_b and the unit rates (element by
    element, see the module's docstring)."""
    for c in range(3):
        k[c] = x[3 + c]
    for j in range(arate.shape[0]):
        k[3 + n_dof + j] = arate[j]


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _energy(groups: tuple, cons: tuple | None, bp: np.ndarray, x: np.ndarray) -> float:
    """Kinetic energy of base and units [J] (App. C)."""
    heads, geo, goff, par, poff, ia, iaoff, ic, icoff, dims = groups
    n_dof = dims[0]
    qd = x[3:3 + n_dof]
    t = 0.5 * bp[0] * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * bp[1] * qd[2] ** 2
    for k in range(heads.shape[0]):
        t += _unit_energy(heads[k], geo[goff[k]:goff[k + 1]], par[poff[k]:poff[k + 1]],
                          ia[iaoff[k]:iaoff[k + 1]], x[0:3], qd, x[3 + n_dof:], cons)
    return t


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _control(groups: tuple, cons: tuple | None, x: np.ndarray, sp: np.ndarray,
             plan: np.ndarray, qd_set: np.ndarray, want: np.ndarray, err: np.ndarray,
             crate: np.ndarray, integ: np.ndarray, tau: np.ndarray, gains: np.ndarray,
             dt: float) -> None:
    """The controller (zero-order hold over the step): the setpoints for the current unit
    angles (IK of the base twist; the steering along its ``plan``), one loop per actuator —
    PI on the rate, or for a position-controlled actuator (``gains[3]`` > 0) PD on its angle
    error — with anti-windup and the torque limit, on the actuator rates ``crate`` at x
    (:func:`_eom`). ``gains`` (4, A): kp, ki, limit, position-controlled."""
    heads, geo, goff, par, poff, ia, iaoff, ic, icoff, dims = groups
    n_dof = dims[0]
    c, s = math.cos(x[2]), math.sin(x[2])
    qd_set[0] = c * sp[0] - s * sp[1]
    qd_set[1] = s * sp[0] + c * sp[1]
    qd_set[2] = sp[2]
    for k in range(heads.shape[0]):
        _unit_setpoints(heads[k], geo[goff[k]:goff[k + 1]], ia[iaoff[k]:iaoff[k + 1]],
                        ic[icoff[k]:icoff[k + 1]], plan, x[0:3], qd_set, sp, x[3 + n_dof:],
                        want, err, cons)
    for a in range(tau.shape[0]):
        e = want[a] - crate[a]
        # PI on the rate (the integral), or PD on the angle (its error given)
        held = err[a] if gains[3, a] > 0 else integ[a] + e * dt
        raw = gains[0, a] * e + gains[1, a] * held
        tau[a] = min(max(raw, -gains[2, a]), gains[2, a])
        if tau[a] == raw:  # anti-windup
            integ[a] = integ[a] + e * dt


@njit(cache=True, error_model="numpy")
def run(groups: tuple, cons: tuple | None, bp: np.ndarray, ctrl: np.ndarray,
        gains: np.ndarray, stride: int, first: int, end: int, last: np.ndarray,
        sp_all: np.ndarray, plan_all: np.ndarray, f_all: np.ndarray, has_fb: bool,
        x_all: np.ndarray, integ_all: np.ndarray, rec_q: np.ndarray, rec_qd: np.ndarray,
        rec_qdd: np.ndarray, rec_ang: np.ndarray, rec_tau: np.ndarray, rec_fb: np.ndarray,
        rec_e: np.ndarray, rec_tau_sum: np.ndarray, tau_given: np.ndarray) -> None:
    """Steps ``first`` … ``end`` (at most ``last[r]`` for run r) of every run: the controller,
    the records and RK4 with τ held over the step; the states ``x_all`` (R, 3 + D + J) and PI
    integrators ``integ_all`` (R, A) are updated in place. ``cons`` the constraint rows' scratch
    (:func:`constraint_scratch`; None without: then numba compiles neither the steered kernel
    nor the constrained solve into this specialization of run). ``ctrl`` = [dt, given];
    ``gains`` (4, A) the controller's (:func:`_control`); ``plan_all`` (steps + 1, R, P) the
    planned steering on the step grid (:func:`planned`). With ``given`` > 0 there is no
    controller: each step holds the torques ``tau_given[step, r]`` (a free-running simulation
    under given torques, :func:`ropod_sysid.validate.free_run`). ``rec_tau_sum`` sums each
    step's torques into the record nearest it (the steps ``k·stride − stride//2`` …
    ``k·stride − stride//2 + stride − 1`` into record k): the interval means of
    :attr:`ropod_sysid.simulate.SimResult.tau_mean`. ``rec_qd`` records the first
    ``rec_qd.shape[2]`` entries of q̇ (3: the base twist)."""
    n_dof = groups[9][0]
    dt = ctrl[0]
    given = ctrl[1] > 0
    n_runs, n_x = x_all.shape
    n_act = integ_all.shape[1]
    m = np.empty((n_dof, n_dof))
    b, ff, rhs = np.empty(n_dof), np.empty(n_dof), np.empty(n_dof)
    piv = np.zeros(n_dof, np.int64)
    qd_set = np.empty(3)
    btau = np.zeros((n_dof, n_act))
    tauf, crate, want, err, tau = (np.zeros(n_act), np.zeros(n_act), np.zeros(n_act),
                                   np.zeros(n_act), np.zeros(n_act))
    arate = np.zeros(n_x - 3 - n_dof)
    ks = np.empty((4, n_x))
    y = np.empty(n_x)
    for r in range(n_runs):
        x = x_all[r]
        integ = integ_all[r]
        for step in range(first, min(end, last[r]) + 1):
            fb = f_all[step if has_fb else 0, r]
            # RK4 with τ held over the step; the first stage (at x) sets τ by the controller
            # and records (one call site per function: each is compiled into run once)
            for stage in range(4):
                h = 0.0 if stage == 0 else (dt if stage == 3 else 0.5 * dt)
                for j in range(n_x):
                    y[j] = x[j] + h * ks[stage - 1, j] if stage > 0 else x[j]
                _eom(groups, cons, bp, y, m, b, btau, tauf, ff, arate, crate)
                if stage == 0:
                    if given:
                        for a in range(n_act):
                            tau[a] = tau_given[step, r, a]
                    else:
                        _control(groups, cons, y, sp_all[step, r], plan_all[step, r], qd_set,
                                 want, err, crate, integ, tau, gains, dt)
                    near = (step + stride // 2) // stride
                    if near < rec_tau_sum.shape[0]:
                        for a in range(n_act):
                            rec_tau_sum[near, r, a] += tau[a]
                kn = ks[stage]
                _accel(cons, bp, y, m, b, btau, tauf, ff, tau, fb, has_fb, rhs, piv,
                       kn[3:3 + n_dof])
                _rates(y, n_dof, arate, kn)
                if stage == 0 and step % stride == 0:
                    k = step // stride
                    for c in range(3):
                        rec_q[k, r, c] = x[c]
                        rec_qdd[k, r, c] = kn[3 + c]
                        if has_fb:
                            rec_fb[k, r, c] = fb[c]
                    for c in range(rec_qd.shape[2]):  # the base twist, or all of q̇ (free run)
                        rec_qd[k, r, c] = x[3 + c]
                    for j in range(n_x - 3 - n_dof):
                        rec_ang[k, r, j] = x[3 + n_dof + j]
                    for a in range(n_act):
                        rec_tau[k, r, a] = tau[a]
                    rec_e[k, r] = _energy(groups, cons, bp, x)
                if step == last[r]:
                    break
            if step == last[r]:
                break
            for j in range(n_x):
                x[j] = x[j] + dt / 6 * (ks[0, j] + 2 * ks[1, j] + 2 * ks[2, j] + ks[3, j])


def groups_of(model: PlatformModel, params: Mapping[str, float], friction: str
              ) -> tuple[np.ndarray, ...] | None:
    """The groups of the model as the flat arrays :func:`run` takes, or None when a group's
    type has no compiled kernel or declines these parameters (the numpy path then simulates).
    Per group its head (kernel id, its first own coordinate's row among the D, its first
    constraint row, its first entry of the plan); last ``dims`` = [D, C constraint rows, their
    consistent rank, P planned entries]."""
    heads, geo, par, ia, ic = [], [], [], [], []
    con, plan = 0, 0
    for (g, unit), rows in zip(model.groups, model.rows, strict=True):
        compiled = getattr(unit, "compiled", None)
        kernel = None if compiled is None else compiled(params, friction)
        if kernel is None or kernel[0] not in KERNELS:
            return None
        module, g_geo, g_par = kernel
        k = len(g.specs)
        heads.append([KERNELS.index(module), rows[3] if rows.size > 3 else 0, con, plan])
        con += getattr(module, "CONSTRAINTS", 0) * k
        plan += getattr(module, "PLANNED", 0) * k
        geo.append(g_geo)
        par.append(g_par)
        ia.append(np.asarray(g.angles, np.int64))
        ic.append(np.asarray(g.currents, np.int64))

    def flat(parts: list[np.ndarray], dtype: type) -> tuple[np.ndarray, np.ndarray]:
        off = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
        return np.concatenate(parts).astype(dtype), off

    dims = np.array([model.n_dof, con, model.motion_rank or 0, plan], np.int64)
    return (np.array(heads, np.int64).reshape(-1, 4), *flat(geo, float), *flat(par, float),
            *flat(ia, np.int64), *flat(ic, np.int64), dims)


def planned(plans: Sequence[tuple[np.ndarray, ...] | None], n_steps: int, n_runs: int
            ) -> np.ndarray:
    """The groups' plans (:meth:`PlatformModel.plans`: per group None or arrays (N, R, k))
    as :func:`run`'s ``plan_all`` (N, R, P): each group's arrays side by side, in group order
    (the steered wheels': β_d of its k units, then β̇_d)."""
    parts = [a for p in plans if p is not None for a in p]
    if not parts:
        return np.zeros((n_steps, n_runs, 0))
    return np.ascontiguousarray(np.concatenate(parts, axis=-1))


def constraint_scratch(groups: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...] | None:
    """:func:`run`'s ``cons`` for the groups: None without constraint rows, else G (C, D),
    Ġ q̇ (C,), their consistent rank (1,) and the scratch of :func:`_constrained` (a C- and a
    (D + C)-vector, M⁻¹Gᵀ (D, C), two C × C, the eigenvalues (C,))."""
    n_dof, n_con, rank = (int(v) for v in groups[9][:3])
    if n_con == 0:
        return None
    return (np.zeros((n_con, n_dof)), np.zeros(n_con), np.array([rank], np.int64),
            np.zeros(n_con), np.zeros(n_dof + n_con), np.zeros((n_dof, n_con)),
            np.zeros((n_con, n_con)), np.zeros((n_con, n_con)), np.zeros(n_con))


def base_parameters(model: PlatformModel, params: Mapping[str, float],
                    friction: str) -> np.ndarray:
    """[m_b, J_zz,b, α, body, f_bv (3), f_bc (3), β, slip] for :func:`run` (body = 1 with
    body-axis friction, its coefficients as :func:`ropod_sysid.model.base.body_friction_force`
    reads them; β the simulator's Baumgarte term [1/s], slip the eigenvalue ratio below which
    constraint directions are left free, :data:`ropod_sysid.model.assembly.SLIP_RANK` ²)."""
    from ropod_sysid.model.assembly import SLIP_RANK
    from ropod_sysid.simulate import BAUMGARTE

    body = friction == "body"
    coeff = [float(params.get(n, 0.0)) if body else 0.0 for n in base.BODY_FRICTION]
    return np.array([params["m_b"], params["Jzz_b"], model.alpha, float(body), *coeff,
                     BAUMGARTE, SLIP_RANK**2], float)


def integrate(groups: tuple[np.ndarray, ...], bp: np.ndarray, ctrl: np.ndarray,
              gains: np.ndarray, stride: int, steps: int, last: np.ndarray, sp_all: np.ndarray,
              plan_all: np.ndarray, f_all: np.ndarray | None, angles0: np.ndarray, n_act: int,
              records: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             np.ndarray, np.ndarray, np.ndarray], bar: Any) -> None:
    """Every run from rest at the unit angles ``angles0`` (R, J) through step ``last[r]``, in
    chunks of :data:`CHUNK` steps (the progress bar moves between them); writes ``records``
    (q, q̇, q̈, angles, τ, F_b, energy, the sums of τ near each record; (n_rec, R, …) each)."""
    n_runs, n_ang = angles0.shape
    n_dof = int(groups[9][0])
    x = np.zeros((n_runs, 3 + n_dof + n_ang))
    x[:, 3 + n_dof:] = angles0
    integ = np.zeros((n_runs, n_act))
    has_fb = f_all is not None
    forces = np.ascontiguousarray(f_all) if f_all is not None else np.zeros((1, n_runs, 3))
    sp = np.ascontiguousarray(sp_all)
    plan = np.ascontiguousarray(plan_all)
    cons = constraint_scratch(groups)
    bar.set(0.0, force=True)  # drawn while a first call compiles or loads the cache
    for first in range(0, steps + 1, CHUNK):
        end = min(first + CHUNK - 1, steps)
        with first_compile(cons):
            run(groups, cons, bp, ctrl, gains, stride, first, end, last, sp, plan, forces,
                has_fb, x, integ, *records, NO_TORQUES)
        bar.set(min(end, steps))


@contextmanager
def first_compile(cons: tuple[np.ndarray, ...] | None = None) -> Iterator[None]:
    """Around a call of :func:`run` with the constraint scratch ``cons``: this process's first
    call of that specialization (without constraint rows, or with: ``cons`` None or not) holds
    a lock that every process on the same cache takes, so that of processes starting on an
    empty cache at once (the test suite's workers, a dask cluster's) one compiles and writes
    the cache while the others wait and then load it, instead of each compiling for itself.
    Later calls take no lock."""
    plain = cons is None
    if fcntl is None or any((sig[1] == types.none) == plain for sig in run.signatures):
        yield
        return
    name = "simulate_jit.lock" if plain else "simulate_jit.constrained.lock"
    try:
        # numba's private cache: not in its stubs
        lock = open(Path(run._cache.cache_path) / name, "a")  # type: ignore[attr-defined]  # noqa: SIM115
    except (AttributeError, OSError):  # numba's cache internals differ, or a read-only cache
        yield
        return
    with lock:  # closing the file releases the lock
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def _refresh_caches() -> None:
    """Flush the on-disk caches of this module's compiled functions when the source of a
    kernel module changed since they were written: they hold the kernels compiled in."""
    try:
        digest = hashlib.sha256()
        for module in KERNELS:
            digest.update(Path(inspect.getfile(module)).read_bytes())
        # numba's private cache: not in its stubs
        stamp = Path(run._cache.cache_path) / "simulate_jit.kernels.sha256"  # type: ignore[attr-defined]
        if stamp.exists() and stamp.read_text() == digest.hexdigest():
            return
        for value in list(globals().values()):
            cache: Any = getattr(value, "_cache", None)
            if getattr(value, "py_func", None) is not None and hasattr(cache, "flush"):
                cache.flush()
        stamp.write_text(digest.hexdigest())
    except (AttributeError, OSError):  # numba's cache internals differ, or a read-only cache
        pass


_refresh_caches()
