"""Least squares on QR triangles: stacking, weighting, fixing, rank, null space and σ.

The stacked system A_ID,ext,tot m_ext = b_ID,tot (eq. 37) is never formed. Each block of rows
[A | b] is reduced at once to the upper triangle R of its QR factorisation, (p+1)×(p+1), with
RᵀR = [A b]ᵀ[A b]; so ‖[A b] z‖ = ‖R z‖ for every z, and triangles of different blocks combine by
stacking them and reducing again (TSQR). Memory does not grow with the data, and the normal
equations are never formed.

Rows are kept apart per degree of freedom of the direct EOM (x, y, θ), so that the rotational
weight of Sec. VI-A and the unweighted RMS per translation and rotation can be computed from the
triangles after the fact.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from ropod_sysid.errors import IdentifiabilityError, InputError

DOF = ("x", "y", "theta")
NULL_TOL = 1e-3  # relative size below which a null-space entry is treated as zero
RCOND = 1e-4  # default: relative singular value below which a direction is unidentifiable


def qr_triangle(a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
    """Upper triangle R ((p+1)×(p+1), or p×p without b) of the QR factorisation of [A | b].

    Fewer rows than columns are padded with zero rows, so R is always square.
    """
    m = a if b is None else np.column_stack([a, b])
    p = m.shape[1]
    if m.shape[0] == 0:
        return np.zeros((p, p))
    r = scipy.linalg.qr(m, mode="r", check_finite=False)[0]
    out = np.zeros((p, p))
    out[: min(r.shape[0], p)] = r[:p]
    return out


def stack_triangles(triangles: Sequence[np.ndarray]) -> np.ndarray:
    """Combine triangles of row blocks into the triangle of all rows (TSQR step)."""
    return qr_triangle(np.vstack(list(triangles)))


@dataclass
class Triangles:
    """QR triangles of one stacked system (a log), one per DOF row of the direct EOM.

    r : (3, p+1, p+1) triangles of [A_dof | b_dof] for dof = x, y, θ
    rows : equation rows per DOF
    samples : log samples those rows cover (after trimming; ``rows`` × the row step)
    correlation : rows per independent row: the LOESS over the rows makes neighbours share
        their noise (1/Σh² of its kernel h, for a residual white before that filter)
    duration : length of the log the rows come from [s]
    """

    r: np.ndarray
    rows: int
    label: str = ""
    samples: int = 0
    correlation: float = 1.0
    duration: float = 0.0

    @classmethod
    def from_rows(cls, a: np.ndarray, b: np.ndarray, label: str = "") -> Triangles:
        """From A (N, 3, p) and b (N, 3): one triangle per DOF."""
        r = np.stack([qr_triangle(a[:, d, :], b[:, d]) for d in range(3)])
        return cls(r, a.shape[0], label)

    def merge(self, other: Triangles) -> Triangles:
        """Append another block of rows of the same system (streaming)."""
        r = np.stack([stack_triangles([self.r[d], other.r[d]]) for d in range(3)])
        return Triangles(r, self.rows + other.rows, self.label, self.samples + other.samples,
                         self.correlation, self.duration + other.duration)

    def torque_free(self) -> bool:
        """Whether the rows move the platform (A ≠ 0) with no torque at all (b = 0): the motor
        currents of the log are all zero."""
        return bool(np.any(self.r[:, :, :-1]) and not np.any(self.r[:, :, -1]))

    def mean_square_b(self) -> np.ndarray:
        """Mean square of b_ID per DOF (3,): ‖b‖² = ‖R e_b‖² (column norms are kept)."""
        return (self.r[:, :, -1] ** 2).sum(axis=1) / max(self.rows, 1)

    def rotation_weight(self) -> float:
        """Sec. VI-A: the weight w of the θ rows making mean(w² b_θ²) = mean(b_x², b_y²)."""
        ms = self.mean_square_b()
        trans = 0.5 * (ms[0] + ms[1])
        return float(np.sqrt(trans / ms[2])) if ms[2] > 0 else 1.0

    def weighted(self, w_rot: float) -> np.ndarray:
        """Triangle of the system with the θ rows scaled by ``w_rot``."""
        return stack_triangles([self.r[0], self.r[1], w_rot * self.r[2]])

    def residual_ss(self, m: np.ndarray) -> np.ndarray:
        """Unweighted residual sums of squares ‖A_dof m − b_dof‖² per DOF (3,)."""
        z = np.append(m, -1.0)
        return ((self.r @ z) ** 2).sum(axis=1)

    def rms(self, m: np.ndarray) -> dict[str, float]:
        """RMS residual of the direct EOM: translation rows [N] and rotation rows [N m]."""
        ss = self.residual_ss(m)
        n = max(self.rows, 1)
        return {"translation": float(np.sqrt((ss[0] + ss[1]) / (2 * n))),
                "rotation": float(np.sqrt(ss[2] / n)),
                "x": float(np.sqrt(ss[0] / n)), "y": float(np.sqrt(ss[1] / n)),
                "theta": float(np.sqrt(ss[2] / n))}


def combined_rms(systems: Sequence[Triangles], m: np.ndarray) -> dict[str, float]:
    """RMS over all stacked samples (translation, rotation), unweighted."""
    ss = sum(s.residual_ss(m) for s in systems)
    n = max(sum(s.rows for s in systems), 1)
    return {"translation": float(np.sqrt((ss[0] + ss[1]) / (2 * n))),
            "rotation": float(np.sqrt(ss[2] / n))}


@dataclass
class Solution:
    """A least-squares fit and how well the data determine it.

    values : (p,) parameter values (fixed ones included, as given)
    std : (p,) standard deviations σ̂ √(c diag((AᵀA)⁻¹)) of the weighted system, c the rows'
        ``correlation`` (:class:`Triangles`); NaN when fixed or determined only in combination
    singular_values : of the column-scaled free regressor (descending)
    rank : numerical rank of the column-scaled free regressor
    condition_number : σ_max/σ_min of the column-scaled free regressor; when it is rank
        deficient, of its identifiable part (σ_max over the smallest σ counted in the rank)
    null_space : (p, k) basis of the combinations the data cannot separate (in parameters)
    combination : (p,) True where the value is determined only in combination with others
    combinations : name → readable identifiable combination the value stands for
    """

    names: list[str]
    values: np.ndarray
    std: np.ndarray
    singular_values: np.ndarray
    rank: int
    condition_number: float
    null_space: np.ndarray
    combination: np.ndarray
    combinations: dict[str, str]
    fixed: dict[str, float]
    sigma2: float
    rows: int
    covariance: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 0)))

    def null_space_text(self, tol: float = 1e-3) -> list[str]:
        """Each null-space vector as 'a·name + b·name …' (largest coefficient 1)."""
        out = []
        for v in self.null_space.T:
            v = v / v[np.argmax(np.abs(v))]
            terms = [f"{c:+.4g}·{n}" for c, n in zip(v, self.names, strict=True)
                     if abs(c) > tol]
            out.append(" ".join(terms).lstrip("+"))
        return out


def numerical_rank(sv: np.ndarray, rcond: float = RCOND) -> int:
    """The rank rule of the fit and of ``trajectory check``: the singular values ``sv``
    (descending) of a column-scaled regressor above ``rcond`` · σ_max."""
    sv = np.asarray(sv, float)
    return int(np.sum(sv > rcond * sv[0])) if sv.size and sv[0] > 0 else 0


def check_rcond(rcond: float) -> None:
    """``rcond`` is a finite number in (0, 1): 0 counts noise as identifiable, 1 nothing."""
    if not (np.isfinite(rcond) and 0 < rcond < 1):
        raise InputError(f"--rcond {rcond:g}: must be a finite number in (0, 1), e.g. {RCOND:g}")


def check_fixed(fixed: Mapping[str, float], names: Sequence[str]) -> None:
    """Fixed parameters are parameters of the model (``names``) with finite values."""
    for k, v in fixed.items():
        if k not in names:
            raise InputError(f"--fix {k}: unknown parameter; known: {', '.join(names)}")
        if not np.isfinite(v):
            raise InputError(f"--fix {k}={v:g}: the value must be a finite number")


def solve(r: np.ndarray, rows: int, names: Sequence[str],
          fixed: Mapping[str, float] | None = None, rcond: float = RCOND,
          bounds: tuple[np.ndarray, np.ndarray] | None = None,
          correlation: float = 1.0) -> Solution:
    """Solve min ‖A m − b‖ from the triangle ``r`` of [A | b] (weighted, stacked).

    Parameters
    ----------
    r : (p+1, p+1) triangle; ``rows`` : number of rows it summarises (for σ̂²)
    correlation : rows per independent row (:attr:`Triangles.correlation`): the covariance of
        the values is σ̂² (AᵀA)⁻¹ times it
    fixed : name → value held fixed (moved to the right-hand side)
    rcond : singular values of the column-scaled regressor below ``rcond·σ_max`` count as zero;
        those directions are reported in the null space and their dependent parameters are
        set to zero, the independent ones then stand for identifiable combinations.
    bounds : (lower, upper) arrays over all parameters for a bounded (physical) fit.
    """
    names = list(names)
    p = len(names)
    fixed = dict(fixed or {})
    check_rcond(rcond)
    check_fixed(fixed, names)
    fix_idx = [names.index(k) for k in fixed]
    free = [j for j in range(p) if j not in fix_idx]
    m_fix = np.array([fixed[names[j]] for j in fix_idx])
    c = r[:, free]
    d = r[:, -1] - (r[:, fix_idx] @ m_fix if fix_idx else 0.0)
    norms = np.linalg.norm(c, axis=0)
    if not free or not np.any(norms > 0):
        raise IdentifiabilityError(
            "the regressor has rank 0: the logs do not excite any parameter; use logs in which "
            "the platform moves")
    scale = np.where(norms > 0, norms, 1.0)
    cs = c / scale
    sv = np.linalg.svd(cs, compute_uv=False)
    rank = numerical_rank(sv, rcond)
    q_free = len(free)
    values = np.zeros(p)
    values[fix_idx] = m_fix
    std = np.full(p, np.nan)
    combination = np.zeros(p, dtype=bool)
    combinations: dict[str, str] = {}
    null = np.zeros((p, 0))
    cov = np.full((p, p), np.nan)

    if rank < q_free:
        # Null space of the column-scaled regressor; entries below NULL_TOL of a vector's
        # largest are noise of a numerically (not exactly) singular system.
        _, _, vt = np.linalg.svd(cs)
        ns = vt[rank:].T  # (q, q - rank), scaled coordinates
        ns = np.where(np.abs(ns) >= NULL_TOL * np.abs(ns).max(axis=0), ns, 0.0)
        # dependent parameters: the most involved ones (pivoted QR of the null space rows)
        _, _, piv = scipy.linalg.qr(ns.T, mode="economic", pivoting=True)
        dep = np.sort(piv[: q_free - rank])
        base = np.setdiff1d(np.arange(q_free), dep)
        n_free = ns / scale[:, None]
        null = np.zeros((p, ns.shape[1]))
        null[free] = n_free / np.linalg.norm(n_free, axis=0)
        # any solution ± null space: setting x_D = 0 leaves x_B = true_B + K true_D
        k_scaled = -ns[base] @ np.linalg.inv(ns[dep])
        k_scaled[np.abs(k_scaled) < NULL_TOL] = 0.0
        k_mat = k_scaled * scale[dep][None, :] / scale[base][:, None]
        for bi, jb in enumerate(base):
            terms = [f"{k_mat[bi, di]:+.4g}·{names[free[jd]]}"
                     for di, jd in enumerate(dep) if k_scaled[bi, di] != 0.0]
            if terms:
                combination[free[jb]] = True
                combinations[names[free[jb]]] = f"{names[free[jb]]} " + " ".join(terms)
        for jd in dep:
            combination[free[jd]] = True
            combinations[names[free[jd]]] = (
                f"not identifiable from these logs; set to 0 (fix it, e.g. --fix "
                f"{names[free[jd]]}=VALUE, to separate the combination)")
        cols = base
    else:
        cols = np.arange(q_free)

    cb = cs[:, cols]
    qb, rb = np.linalg.qr(cb)
    y = scipy.linalg.solve_triangular(rb, qb.T @ d)
    resid_ss = float(np.sum(d**2) - np.sum((qb.T @ d) ** 2))
    resid_ss = max(resid_ss, 0.0)
    dof = max(rows - len(cols), 1)
    sigma2 = resid_ss / dof
    rinv = scipy.linalg.solve_triangular(rb, np.eye(len(cols)))
    cov_s = correlation * sigma2 * rinv @ rinv.T
    idx = [free[j] for j in cols]
    values[idx] = y / scale[cols]
    cov_b = cov_s / np.outer(scale[cols], scale[cols])
    std[idx] = np.sqrt(np.diag(cov_b))
    cov[np.ix_(idx, idx)] = cov_b

    if bounds is not None:
        lo, hi = (np.asarray(v, float) for v in bounds)
        from scipy.optimize import lsq_linear  # imported here: only bounded fits need it

        res = lsq_linear(cs, d, bounds=(lo[free] * scale, hi[free] * scale),
                                        method="bvls", lsmr_tol="auto")
        values[free] = res.x / scale

    if not np.any(values[free]):
        raise IdentifiabilityError(
            "the solution is all zeros: nothing in the logs' torques needs the parameters "
            "(are the motor currents all zero?); check the current columns of the logs")
    # of the identifiable part: σ_max over the smallest singular value kept
    cond = float(sv[0] / sv[rank - 1])
    return Solution(names, values, std, sv, rank, cond, null, combination, combinations, fixed,
                    sigma2, rows, cov)

