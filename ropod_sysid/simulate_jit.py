"""The simulator's compiled path: the whole RK4 loop of :func:`ropod_sysid.simulate.simulate`
in numba, for a platform whose unit groups all have a compiled kernel.

Each unit type may offer a kernel of one sample (``UnitType.compiled(params, variant)``: the
kernel module, e.g. :mod:`ropod_sysid.model.units.swivel_jit`, and its geometry and parameter
arrays). The groups of a platform are passed as flat arrays with offsets (a kernel id per group),
so one compiled loop serves every list of groups; the kernels are dispatched by id
(:data:`KERNELS`). Per RK4 stage it sums the base's M_b (eq. 2) and every group's M_add, b_dir,
B_τ, friction torques τ_f and generalized friction force f_f into eq. 65 and solves eq. 33;
body-axis friction (004 eqs. 6–8) and the external force B_Fb F_b (eq. 3) are added on the
base. The controller (PI per actuator, anti-windup, torque limit), the setpoints on the step
grid, the recording every ``stride`` steps and the kinetic energy are the same as the numpy
path's, which stays the reference (results equal to round-off, ``tests/test_simulate_jit.py``).

:func:`run` alone is called from Python and cached on disk (``cache=True``): the first call in
a fresh environment compiles (about 11 s, numba's typing and lowering more than LLVM), later
processes load the cache (about 1 s). The functions it calls are compiled into it: they have no
Python wrapper and no cache of their own (``no_cpython_wrapper=True``; each wrapper and cache
cost the first compile a fraction of a second), and the kind dispatchers (``_unit_*``) are
inlined into their callers (``inline="always"``), so no separately optimised library sits
between the loop and the kernels. Arrays are copied element by element, not by slice
assignment, which would compile numba's shape-mismatch message (3 s of string formatting).
numba checks a cached function only against its own source file, not those of the functions
it calls, so :func:`run`'s cache is flushed when a kernel module's source changes
(:func:`_refresh_caches`).
"""

from __future__ import annotations

import hashlib
import inspect
import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

try:
    import fcntl
except ImportError:  # not on Windows: there every process compiles for itself
    fcntl = None  # type: ignore[assignment]

import numpy as np
from numba import njit

from ropod_sysid.model import PlatformModel, base
from ropod_sysid.model.units import omni_jit, swivel_jit

KERNELS: tuple[Any, ...] = (swivel_jit, omni_jit)  # a kernel's id is its index here
CHUNK = 2000  # steps per compiled call (between progress-bar updates)
NO_TORQUES = np.zeros((1, 1, 1))  # run's tau_given when its controller acts


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _unit_dynamics(kind: int, geo: np.ndarray, par: np.ndarray, ia: np.ndarray,
                   ic: np.ndarray, q: np.ndarray, qd: np.ndarray, ang: np.ndarray,
                   m: np.ndarray, b: np.ndarray, btau: np.ndarray, tauf: np.ndarray,
                   ff: np.ndarray, arate: np.ndarray, crate: np.ndarray) -> None:
    if kind == 0:
        swivel_jit.dynamics(geo, par, ia, ic, q, qd, ang, m, b, btau, tauf, ff, arate, crate)
    else:
        omni_jit.dynamics(geo, par, ia, ic, q, qd, ang, m, b, btau, tauf, ff, arate, crate)


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _unit_actuator_rates(kind: int, geo: np.ndarray, ia: np.ndarray, ic: np.ndarray,
                         q: np.ndarray, qd: np.ndarray, ang: np.ndarray,
                         crate: np.ndarray) -> None:
    if kind == 0:
        swivel_jit.actuator_rates(geo, ia, ic, q, qd, ang, crate)
    else:
        omni_jit.actuator_rates(geo, ia, ic, q, qd, ang, crate)


@njit(inline="always", no_cpython_wrapper=True, error_model="numpy")
def _unit_energy(kind: int, geo: np.ndarray, par: np.ndarray, ia: np.ndarray, q: np.ndarray,
                 qd: np.ndarray, ang: np.ndarray) -> float:
    if kind == 0:
        return swivel_jit.kinetic_energy(geo, par, ia, q, qd, ang)
    return omni_jit.kinetic_energy(geo, par, ia, q, qd, ang)


@njit(no_cpython_wrapper=True, error_model="numpy")
def _eom(groups: tuple, bp: np.ndarray, x: np.ndarray, m: np.ndarray, b: np.ndarray,
         btau: np.ndarray, tauf: np.ndarray, ff: np.ndarray, arate: np.ndarray,
         crate: np.ndarray) -> None:
    """The terms of eq. 65 at the state x = (q_b, q̇_b, unit angles): M_dir = M_b + Σ M_add
    (eqs. 2, 49), Σ b_dir, B_τ, τ_f and f_f (with body-axis friction), and the unit rates."""
    kinds, geo, goff, par, poff, ia, iaoff, ic, icoff = groups
    q, qd, ang = x[0:3], x[3:6], x[6:]
    m[:, :] = 0.0
    m[0, 0] = bp[0]
    m[1, 1] = bp[0]
    m[2, 2] = bp[1]
    b[:] = 0.0
    ff[:] = 0.0
    for g in range(kinds.shape[0]):
        _unit_dynamics(kinds[g], geo[goff[g]:goff[g + 1]], par[poff[g]:poff[g + 1]],
                       ia[iaoff[g]:iaoff[g + 1]], ic[icoff[g]:icoff[g + 1]], q, qd, ang, m, b,
                       btau, tauf, ff, arate, crate)
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
def _solve3(a: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out = a⁻¹ y for a 3 × 3 matrix (Gaussian elimination with partial pivoting, as LAPACK's
    gesv); ``a`` and ``y`` are overwritten."""
    for col in range(3):
        piv = col
        for r in range(col + 1, 3):
            if abs(a[r, col]) > abs(a[piv, col]):
                piv = r
        if piv != col:
            for c in range(3):
                a[col, c], a[piv, c] = a[piv, c], a[col, c]
            y[col], y[piv] = y[piv], y[col]
        for r in range(col + 1, 3):
            f = a[r, col] / a[col, col]
            for c in range(col + 1, 3):
                a[r, c] -= f * a[col, c]
            y[r] -= f * y[col]
    for r in range(2, -1, -1):
        acc = y[r]
        for c in range(r + 1, 3):
            acc -= a[r, c] * out[c]
        out[r] = acc / a[r, r]


@njit(no_cpython_wrapper=True, error_model="numpy")
def _accel(x: np.ndarray, m: np.ndarray, b: np.ndarray, btau: np.ndarray, tauf: np.ndarray,
           ff: np.ndarray, tau: np.ndarray, fb: np.ndarray, has_fb: bool, rhs: np.ndarray,
           qdd: np.ndarray) -> None:
    """q̈_b = M_dir⁻¹ (B_Fb F_b + B_τ (τ + τ_f) + f_f + b_dir) (eqs. 33, 65); ``m`` is
    overwritten."""
    for c in range(3):
        acc = 0.0
        for a in range(tau.shape[0]):
            acc += btau[c, a] * (tau[a] + tauf[a])
        rhs[c] = acc + ff[c] + b[c]
    if has_fb:
        ct, st = math.cos(x[2]), math.sin(x[2])
        rhs[0] += ct * fb[0] - st * fb[1]
        rhs[1] += st * fb[0] + ct * fb[1]
        rhs[2] += fb[2]
    _solve3(m, rhs, qdd)


@njit(no_cpython_wrapper=True, error_model="numpy")
def _rates(x: np.ndarray, arate: np.ndarray, k: np.ndarray) -> None:
    """The rates of the state besides q̈_b into ``k``: q̇_b and the unit rates (element by
    element, see the module's docstring)."""
    for c in range(3):
        k[c] = x[3 + c]
    for j in range(arate.shape[0]):
        k[6 + j] = arate[j]


@njit(no_cpython_wrapper=True, error_model="numpy")
def _energy(groups: tuple, bp: np.ndarray, x: np.ndarray) -> float:
    """Kinetic energy of base and units [J] (App. C)."""
    kinds, geo, goff, par, poff, ia, iaoff, ic, icoff = groups
    qd = x[3:6]
    t = 0.5 * bp[0] * (qd[0] ** 2 + qd[1] ** 2) + 0.5 * bp[1] * qd[2] ** 2
    for g in range(kinds.shape[0]):
        t += _unit_energy(kinds[g], geo[goff[g]:goff[g + 1]], par[poff[g]:poff[g + 1]],
                          ia[iaoff[g]:iaoff[g + 1]], x[0:3], qd, x[6:])
    return t


@njit(no_cpython_wrapper=True, error_model="numpy")
def _control(groups: tuple, x: np.ndarray, sp: np.ndarray, qd_set: np.ndarray,
             want: np.ndarray, crate: np.ndarray, integ: np.ndarray, tau: np.ndarray, kp: float,
             ki: float, limit: float, dt: float) -> None:
    """The controller (zero-order hold over the step): IK for the current unit angles, one PI
    loop per actuator with anti-windup and the torque limit, on the actuator rates ``crate`` at
    x (:func:`_eom`)."""
    kinds, geo, goff, par, poff, ia, iaoff, ic, icoff = groups
    c, s = math.cos(x[2]), math.sin(x[2])
    qd_set[0] = c * sp[0] - s * sp[1]
    qd_set[1] = s * sp[0] + c * sp[1]
    qd_set[2] = sp[2]
    for g in range(kinds.shape[0]):
        _unit_actuator_rates(kinds[g], geo[goff[g]:goff[g + 1]],
                             ia[iaoff[g]:iaoff[g + 1]], ic[icoff[g]:icoff[g + 1]],
                             x[0:3], qd_set, x[6:], want)
    for a in range(tau.shape[0]):
        err = want[a] - crate[a]
        raw = kp * err + ki * (integ[a] + err * dt)
        tau[a] = min(max(raw, -limit), limit)
        if tau[a] == raw:  # anti-windup
            integ[a] = integ[a] + err * dt


@njit(cache=True, error_model="numpy")
def run(groups: tuple, bp: np.ndarray, ctrl: np.ndarray, stride: int, first: int, end: int,
        last: np.ndarray, sp_all: np.ndarray, f_all: np.ndarray, has_fb: bool, x_all: np.ndarray,
        integ_all: np.ndarray, rec_q: np.ndarray, rec_qd: np.ndarray, rec_qdd: np.ndarray,
        rec_ang: np.ndarray, rec_tau: np.ndarray, rec_fb: np.ndarray, rec_e: np.ndarray,
        rec_tau_sum: np.ndarray, tau_given: np.ndarray) -> None:
    """Steps ``first`` … ``end`` (at most ``last[r]`` for run r) of every run: the controller,
    the records and RK4 with τ held over the step; the states ``x_all`` (R, 6 + J) and PI
    integrators ``integ_all`` (R, A) are updated in place. With ``ctrl[4]`` > 0 there is no
    controller: each step holds the torques ``tau_given[step, r]`` (a free-running
    simulation under given torques, :func:`ropod_sysid.validate.free_run`). ``rec_tau_sum``
    sums each step's torques into the record nearest it (the steps ``k·stride − stride//2`` …
    ``k·stride − stride//2 + stride − 1`` into record k): the interval means of
    :attr:`ropod_sysid.simulate.SimResult.tau_mean`."""
    kinds, geo, goff, par, poff, ia, iaoff, ic, icoff = groups
    kp, ki, limit, dt = ctrl[0], ctrl[1], ctrl[2], ctrl[3]
    given = ctrl.shape[0] > 4 and ctrl[4] > 0
    n_runs, n_x = x_all.shape
    n_act = integ_all.shape[1]
    m = np.empty((3, 3))
    b, ff, rhs, qd_set = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    btau = np.zeros((3, n_act))
    tauf, crate, want, tau = (np.zeros(n_act), np.zeros(n_act), np.zeros(n_act),
                              np.zeros(n_act))
    arate = np.zeros(n_x - 6)
    ks = np.empty((4, n_x))
    y = np.empty(n_x)
    for r in range(n_runs):
        x = x_all[r]
        integ = integ_all[r]
        for step in range(first, min(end, last[r]) + 1):
            _eom(groups, bp, x, m, b, btau, tauf, ff, arate, crate)
            if given:
                for a in range(n_act):
                    tau[a] = tau_given[step, r, a]
            else:
                _control(groups, x, sp_all[step, r], qd_set, want, crate, integ, tau, kp, ki,
                         limit, dt)
            fb = f_all[step if has_fb else 0, r]
            near = (step + stride // 2) // stride
            if near < rec_tau_sum.shape[0]:
                for a in range(n_act):
                    rec_tau_sum[near, r, a] += tau[a]
            k1 = ks[0]
            _accel(x, m, b, btau, tauf, ff, tau, fb, has_fb, rhs, k1[3:6])
            _rates(x, arate, k1)
            if step % stride == 0:
                k = step // stride
                for c in range(3):
                    rec_q[k, r, c] = x[c]
                    rec_qd[k, r, c] = x[3 + c]
                    rec_qdd[k, r, c] = k1[3 + c]
                    if has_fb:
                        rec_fb[k, r, c] = fb[c]
                for j in range(n_x - 6):
                    rec_ang[k, r, j] = x[6 + j]
                for a in range(n_act):
                    rec_tau[k, r, a] = tau[a]
                rec_e[k, r] = _energy(groups, bp, x)
            if step == last[r]:
                break
            # RK4 with τ held over the step
            for stage in range(1, 4):
                h = dt if stage == 3 else 0.5 * dt
                prev = ks[stage - 1]
                for j in range(n_x):
                    y[j] = x[j] + h * prev[j]
                _eom(groups, bp, y, m, b, btau, tauf, ff, arate, crate)
                kn = ks[stage]
                _accel(y, m, b, btau, tauf, ff, tau, fb, has_fb, rhs, kn[3:6])
                _rates(y, arate, kn)
            for j in range(n_x):
                x[j] = x[j] + dt / 6 * (ks[0, j] + 2 * ks[1, j] + 2 * ks[2, j] + ks[3, j])


def groups_of(model: PlatformModel, params: Mapping[str, float], friction: str
              ) -> tuple[np.ndarray, ...] | None:
    """The groups of the model as the flat arrays :func:`run` takes, or None when a group's
    type has no compiled kernel (the numpy path then simulates)."""
    kinds, geo, par, ia, ic = [], [], [], [], []
    for g, unit in model.groups:
        compiled = getattr(unit, "compiled", None)
        if compiled is None:
            return None
        module, g_geo, g_par = compiled(params, friction)
        if module not in KERNELS:
            return None
        kinds.append(KERNELS.index(module))
        geo.append(g_geo)
        par.append(g_par)
        ia.append(np.asarray(g.angles, np.int64))
        ic.append(np.asarray(g.currents, np.int64))

    def flat(parts: list[np.ndarray], dtype: type) -> tuple[np.ndarray, np.ndarray]:
        off = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
        return np.concatenate(parts).astype(dtype), off

    return (np.array(kinds, np.int64), *flat(geo, float), *flat(par, float),
            *flat(ia, np.int64), *flat(ic, np.int64))


def base_parameters(model: PlatformModel, params: Mapping[str, float],
                    friction: str) -> np.ndarray:
    """[m_b, J_zz,b, α, body, f_bv (3), f_bc (3)] for :func:`run` (body = 1 with body-axis
    friction, its coefficients as :func:`ropod_sysid.model.base.body_friction_force` reads
    them)."""
    body = friction == "body"
    coeff = [float(params.get(n, 0.0)) if body else 0.0 for n in base.BODY_FRICTION]
    return np.array([params["m_b"], params["Jzz_b"], model.alpha, float(body), *coeff], float)


def integrate(groups: tuple[np.ndarray, ...], bp: np.ndarray, ctrl: np.ndarray, stride: int,
              steps: int, last: np.ndarray, sp_all: np.ndarray, f_all: np.ndarray | None,
              angles0: np.ndarray, n_act: int, records: tuple[np.ndarray, ...],
              bar: Any) -> None:
    """Every run from rest at the unit angles ``angles0`` (R, J) through step ``last[r]``, in
    chunks of :data:`CHUNK` steps (the progress bar moves between them); writes ``records``
    (q, q̇, q̈, angles, τ, F_b, energy, the sums of τ near each record; (n_rec, R, …) each)."""
    n_runs, n_ang = angles0.shape
    x = np.zeros((n_runs, 6 + n_ang))
    x[:, 6:] = angles0
    integ = np.zeros((n_runs, n_act))
    has_fb = f_all is not None
    forces = np.ascontiguousarray(f_all) if f_all is not None else np.zeros((1, n_runs, 3))
    sp = np.ascontiguousarray(sp_all)
    bar.set(0.0, force=True)  # drawn while a first call compiles or loads the cache
    for first in range(0, steps + 1, CHUNK):
        end = min(first + CHUNK - 1, steps)
        with first_compile():
            run(groups, bp, ctrl, stride, first, end, last, sp, forces, has_fb, x, integ,
                *records, NO_TORQUES)
        bar.set(min(end, steps))


@contextmanager
def first_compile() -> Iterator[None]:
    """Around a call of :func:`run`: this process's first call holds a lock that every process
    on the same cache takes, so that of processes starting on an empty cache at once (the test
    suite's workers, a dask cluster's) one compiles and writes the cache while the others wait
    and then load it, instead of each compiling for itself. Later calls take no lock."""
    if run.signatures or fcntl is None:
        yield
        return
    try:
        lock = open(Path(run._cache.cache_path) / "simulate_jit.lock", "a")  # noqa: SIM115
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
        stamp = Path(run._cache.cache_path) / "simulate_jit.kernels.sha256"
        if stamp.exists() and stamp.read_text() == digest.hexdigest():
            return
        for value in list(globals().values()):
            cache = getattr(value, "_cache", None)
            if getattr(value, "py_func", None) is not None and hasattr(cache, "flush"):
                cache.flush()
        stamp.write_text(digest.hexdigest())
    except (AttributeError, OSError):  # numba's cache internals differ, or a read-only cache
        pass


_refresh_caches()
