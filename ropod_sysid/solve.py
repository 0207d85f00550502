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
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np

from ropod_sysid.errors import IdentifiabilityError, InputError

DOF = ("x", "y", "theta")
STRETCH_S = 2.0  # length of the stretches of a log the jackknife leaves out one at a time [s]
MIN_STRETCHES = 4  # fewer stretches in all logs: no jackknife, the white-noise σ alone
NULL_TOL = 1e-3  # relative size below which a null-space entry is treated as zero
TIE_BREAK = 1e-6  # relative preference for the later parameter among near-tied dependents
RCOND = 1e-4  # default: relative singular value below which a direction is unidentifiable


def qr_triangle(a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
    """Upper triangle R ((p+1)×(p+1), or p×p without b) of the QR factorisation of [A | b].

    Fewer rows than columns are padded with zero rows, so R is always square.
    """
    m = a if b is None else np.column_stack([a, b])
    p = m.shape[1]
    if m.shape[0] == 0:
        return np.zeros((p, p))
    # imported where used: at a fit's start it delayed the reading of the logs by 0.2 s, and
    # here it loads in the rows' thread beside the first block's smoothing
    import scipy.linalg

    r = scipy.linalg.qr(m, mode="r", check_finite=False)[0]
    out = np.zeros((p, p))
    out[: min(r.shape[0], p)] = r[:p]
    return out


def node_weights(nodes: np.ndarray, delay: float, order: int = 1) -> np.ndarray:
    """(n,) weights of the node delays' b_ID columns that give ``delay``'s
    (:meth:`Triangles.at_delay`): ``order`` 1, linear interpolation between the two nearest
    nodes (exact for nodes one sample apart); 3, the cubic through the four nearest (nodes
    several samples apart)."""
    n = len(nodes)
    delay = float(np.clip(delay, nodes[0], nodes[-1]))
    k = int(np.clip(np.searchsorted(nodes, delay) - 1, 0, n - 2))
    w = np.zeros(n)
    if order == 1 or n < 4:
        f = (delay - nodes[k]) / (nodes[k + 1] - nodes[k])
        w[k], w[k + 1] = 1.0 - f, f
        return w
    k0 = int(np.clip(k - 1, 0, n - 4))
    x = nodes[k0: k0 + 4]
    diff = x[:, None] - x[None, :] + np.eye(4)  # Lagrange: Π_{j≠i} (d − x_j) / (x_i − x_j)
    num = np.where(np.eye(4, dtype=bool), 1.0, delay - x[None, :])
    w[k0: k0 + 4] = np.prod(num / diff, axis=1)
    return w


def row_kinds(n_dof: int) -> np.ndarray:
    """The triangle (0: x, 1: y, 2: θ) of each of the D rows of a sample: the units' own
    coordinates (the steered wheels' β, torques in N m) join the θ rows."""
    return np.minimum(np.arange(n_dof), 2)


def kind_rows(rows: np.ndarray, kind: int) -> np.ndarray:
    """The rows (m, D, w) of one kind as (m·n_kind, w), sample by sample."""
    sel = row_kinds(rows.shape[1]) == kind
    picked = rows[:, sel]
    return picked.reshape(-1, rows.shape[2])


def stretch_grams(a: np.ndarray, b: np.ndarray, first_row: int, stretch_rows: int,
                  ) -> np.ndarray:
    """(K, 2, p+1, p+1): [A b]ᵀ[A b] of the x and y rows together and of the θ rows of A
    (m, 3, p) and b (m, 3), per stretch of ``stretch_rows`` rows counted from row 0 of the log,
    the block's first row being row ``first_row`` (the first and last stretch of the block may
    be partial; :meth:`Triangles.merge` joins them with the neighbouring blocks')."""
    m, d, p = a.shape
    b = b.reshape(m, d, -1)  # (m, D, n): b at n node delays (Triangles.delays)
    w = p + b.shape[2]
    cuts = np.arange(stretch_rows - first_row % stretch_rows, m, stretch_rows)
    edges = np.concatenate([[0], cuts, [m]])
    out = np.empty((len(edges) - 1, 2, w, w))
    for i, (s, e) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        ab = np.concatenate([a[s:e], b[s:e]], axis=2)
        xy = ab[:, :2].reshape(-1, w)
        rot = ab[:, 2:].reshape(-1, w)
        out[i, 0] = xy.T @ xy
        out[i, 1] = rot.T @ rot
    return out


def per_row(n_dof: int) -> tuple[int, int, int]:
    """Rows of each kind per sample for D generalized coordinates."""
    return (1, 1, n_dof - 2)


def stack_triangles(triangles: Sequence[np.ndarray]) -> np.ndarray:
    """Combine triangles of row blocks into the triangle of all rows (TSQR step)."""
    return qr_triangle(np.vstack(list(triangles)))


@dataclass
class Triangles:
    """QR triangles of one stacked system (a log), one per DOF row of the direct EOM.

    r : (3, p+1, p+1) triangles of [A_dof | b_dof] for dof = x, y, θ (the θ triangle also
        holds the rows of the units' own coordinates, :func:`row_kinds`)
    rows : equation rows per DOF (samples of rows; ``per_row`` rows of each kind per sample)
    samples : log samples those rows cover (after trimming; ``rows`` × the row step)
    correlation : rows per independent row: the LOESS over the rows makes neighbours share
        their noise (1/Σh² of its kernel h, for a residual white before that filter)
    duration : length of the log the rows come from [s]
    stretches : per stretch of ``stretch_rows`` rows (:data:`STRETCH_S` seconds, counted from
        the log's first row; the last one may be shorter), the normal-equation pieces
        [A b]ᵀ[A b] of its x and y rows together and of its θ rows: a list of blocks of
        (K, 2, p+1, p+1) arrays, in row order. O(duration) small matrices, from which the
        jackknife σ (:func:`jackknife_covariance`) is formed after the solve, without a second
        pass over the logs.
    delays : None, or the node delays [s] (n,) whose b_ID columns the triangles hold in place
        of one ((3, p+n, p+n); ``--input-delay auto``): :meth:`at_delay` gives the triangles of
        any delay between them, interpolating with ``delay_order`` (:func:`node_weights`).
    """

    r: np.ndarray
    rows: int
    label: str = ""
    samples: int = 0
    correlation: float = 1.0
    duration: float = 0.0
    stretches: list[np.ndarray] = field(default_factory=list, repr=False)
    stretch_rows: int = 0
    delays: np.ndarray | None = field(default=None, repr=False)
    delay_order: int = 1
    idle: int = 0  # rows at rest: zero rows, no equation (ropod_sysid.regressor.at_rest)
    # E[δA_dᵀ δA_d] (3, p, p) of the encoders' errors in A (fit --encoder-counts), or None
    error_gram: np.ndarray | None = field(default=None, repr=False)
    per_row: tuple[int, int, int] = (1, 1, 1)  # rows of each kind per sample (row_kinds)
    # the encoders' counts per revolution error_gram is for: given (--encoder-counts) or, for
    # the delay search alone, detected in the log (ropod_sysid.quantisation.detect_encoder_counts)
    error_counts: int | None = None

    @property
    def equations(self) -> int:
        """Rows per DOF that carry an equation (:attr:`rows` less the idle ones)."""
        return self.rows - self.idle

    @classmethod
    def from_rows(cls, a: np.ndarray, b: np.ndarray, label: str = "") -> Triangles:
        """From A (N, D, p) and b (N, D): one triangle per kind of row (:func:`row_kinds`)."""
        ab = np.concatenate([a, b.reshape(*b.shape[:2], -1)], axis=2)
        r = np.stack([qr_triangle(kind_rows(ab, d)) for d in range(3)])
        return cls(r, a.shape[0], label, per_row=per_row(a.shape[1]))

    def merge(self, other: Triangles) -> Triangles:
        """Append another block of rows of the same system (streaming)."""
        r = np.stack([stack_triangles([self.r[d], other.r[d]]) for d in range(3)])
        return Triangles(r, self.rows + other.rows, self.label, self.samples + other.samples,
                         self.correlation, self.duration + other.duration,
                         self._joined_stretches(other), self.stretch_rows or other.stretch_rows,
                         self.delays, self.delay_order, self.idle + other.idle,
                         _sum_grams(self.error_gram, other.error_gram), self.per_row,
                         self.error_counts or other.error_counts)

    def at_delay(self, delay: float, stretches: bool = True) -> Triangles:
        """The triangles of one delay [s] from those of the node delays (:attr:`delays`): b_ID
        of a delay is the linear interpolation of the two nearest nodes' columns (exact for
        nodes a sample apart: :class:`ropod_sysid.regressor.DelayBracket`), and [A | b_d] =
        [A | B] T, T = diag(I, w), so its triangle is that of R T and its stretches Tᵀ G T.
        ``stretches=False`` leaves them out (a cheap cost function)."""
        assert self.delays is not None
        n = len(self.delays)
        p = self.r.shape[-1] - n
        t = np.zeros((p + n, p + 1))
        t[:p, :p] = np.eye(p)
        t[p:, p] = node_weights(self.delays, delay, self.delay_order)
        r = np.stack([qr_triangle(rd @ t) for rd in self.r])
        st = [t.T @ s @ t for s in self.stretches] if stretches else []
        return Triangles(r, self.rows, self.label, self.samples, self.correlation,
                         self.duration, st, self.stretch_rows, idle=self.idle,
                         error_gram=self.error_gram, per_row=self.per_row,
                         error_counts=self.error_counts)

    def _joined_stretches(self, other: Triangles) -> list[np.ndarray]:
        """The stretches of ``other`` (the rows after this block's) after this block's: when
        this block ends inside a stretch, the other's first stretch completes it."""
        if not self.stretches or not other.stretches:
            return self.stretches + other.stretches
        if self.stretch_rows and self.rows % self.stretch_rows:
            last, first = self.stretches[-1].copy(), other.stretches[0]
            last[-1] += first[0]
            rest = [first[1:]] if len(first) > 1 else []
            return self.stretches[:-1] + [last] + rest + other.stretches[1:]
        return self.stretches + other.stretches

    def weighted_stretches(self, w_rot: float) -> np.ndarray:
        """(K, p+1, p+1): each stretch's [A b]ᵀ[A b] with the θ rows scaled by ``w_rot``."""
        if not self.stretches:
            p1 = self.r.shape[-1]
            return np.zeros((0, p1, p1))
        st = np.concatenate(self.stretches)
        return st[:, 0] + w_rot**2 * st[:, 1]

    def torque_free(self) -> bool:
        """Whether the rows move the platform (A ≠ 0) with no torque at all (b = 0): the motor
        currents of the log are all zero."""
        return bool(np.any(self.r[:, :, :-1]) and not np.any(self.r[:, :, -1]))

    def mean_square_b(self) -> np.ndarray:
        """Mean square of b_ID per DOF (3,): ‖b‖² = ‖R e_b‖² (column norms are kept)."""
        return (self.r[:, :, -1] ** 2).sum(axis=1) / (max(self.equations, 1)
                                                        * np.array(self.per_row))

    def rotation_weight(self) -> float:
        """Sec. VI-A: the weight w of the θ rows making mean(w² b_θ²) = mean(b_x², b_y²)."""
        ms = self.mean_square_b()
        trans = 0.5 * (ms[0] + ms[1])
        return float(np.sqrt(trans / ms[2])) if ms[2] > 0 else 1.0

    def weighted_error_gram(self, w_rot: float) -> np.ndarray | None:
        """E[δÃᵀδÃ] (p, p) of the system with the θ rows scaled by ``w_rot``, or None."""
        e = self.error_gram
        return None if e is None else e[0] + e[1] + w_rot**2 * e[2]

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
        n = max(self.equations, 1)
        rot = n * self.per_row[2]
        return {"translation": float(np.sqrt((ss[0] + ss[1]) / (2 * n))),
                "rotation": float(np.sqrt(ss[2] / rot)),
                "x": float(np.sqrt(ss[0] / n)), "y": float(np.sqrt(ss[1] / n)),
                "theta": float(np.sqrt(ss[2] / rot))}


def combined_rms(systems: Sequence[Triangles], m: np.ndarray) -> dict[str, float]:
    """RMS over all stacked samples (translation, rotation), unweighted."""
    ss = cast(np.ndarray, sum(s.residual_ss(m) for s in systems))  # systems: never empty
    n = max(sum(s.equations for s in systems), 1)
    rot = max(sum(s.equations * s.per_row[2] for s in systems), 1)
    return {"translation": float(np.sqrt((ss[0] + ss[1]) / (2 * n))),
            "rotation": float(np.sqrt(ss[2] / rot))}


@dataclass
class Solution:
    """A least-squares fit and how well the data determine it.

    values : (p,) parameter values (fixed ones included, as given)
    std : (p,) calibrated standard deviations: the larger of the delete-one-stretch jackknife's
        (:func:`jackknife_covariance`; it sees residuals correlated over seconds and slowly
        varying model and discretisation error) and ``std_white``; NaN when fixed or not
        identifiable
    std_white : (p,) the white-noise standard deviations σ̂ √(c diag((AᵀA)⁻¹)) of the weighted
        system, c the rows' ``correlation`` (:class:`Triangles`): right only when sensor noise
        dominates the residual (kept for comparison)
    std_basis : what ``std`` is, in words (for the parameter file and the report)
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
    std_white: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    std_basis: str = "white noise"
    stretch_weights: np.ndarray | None = field(default=None, repr=False)  # --robust huber
    at_bound: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, dtype=bool))
    note: str = ""  # e.g. a bounded fit of a rank-deficient system chose one point of a set

    def combination_of(self, m: np.ndarray) -> np.ndarray:
        """``m`` (p,) moved along the null space to where the solution's dependent parameters
        (those set to 0) are 0: the identifiable combinations of ``m`` in the solution's terms,
        e.g. a truth to compare the values with."""
        m = np.asarray(m, float)
        if not self.null_space.shape[1]:
            return m.copy()
        dep = np.flatnonzero(self.combination & ~np.isfinite(self.std)
                             & ~np.isin(self.names, list(self.fixed)))
        c = np.linalg.lstsq(self.null_space[dep], -m[dep], rcond=None)[0]
        return m + self.null_space @ c

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


def _sum_grams(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """The sum of two blocks' error grams (None when neither has one)."""
    if a is None:
        return b
    return a if b is None else a + b


def jackknife_covariance(stretches: np.ndarray, idx: np.ndarray, values: np.ndarray,
                         scale: np.ndarray) -> np.ndarray:
    """Delete-one-stretch jackknife covariance of the parameters ``idx`` of the least-squares
    solution ``values`` (p,), from the stretches' normal-equation pieces G_k = [A_k b_k]ᵀ[A_k
    b_k] ((K, p+1, p+1), weighted; :class:`Triangles`): leaving stretch k out moves the
    solution by d_k = (H − H_k)⁻¹ g_k, with H = Σ H_k the normal matrix of ``idx`` and
    g_k = A_kᵀ(A_k m − b_k) the stretch's score at the solution; cov = (K−1)/K Σ (d_k − d̄)
    (d_k − d̄)ᵀ. Residuals correlated within a stretch (the rows' LOESS, slowly varying model
    and discretisation error) enter through the scores, and each stretch's own leverage through
    (H − H_k)⁻¹. ``scale``: column scales of ``idx`` (for the conditioning of the solves)."""
    z = np.append(values, -1.0)
    hk = stretches[:, idx][:, :, idx] / np.outer(scale, scale)
    g = (stretches[:, idx, :] @ z) / scale
    h = hk.sum(axis=0)
    try:
        d = np.linalg.solve(h[None] - hk, g[..., None])[..., 0]
    except np.linalg.LinAlgError:  # a stretch alone excites a parameter
        d = (np.linalg.pinv(h[None] - hk, rcond=1e-12) @ g[..., None])[..., 0]
    k = len(d)
    dev = (d - d.mean(axis=0)) / scale
    return (k - 1) / k * dev.T @ dev


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


def _check_nonzero(values: np.ndarray) -> None:
    """A solution of all zeros is no fit: the torques need no parameter."""
    if not np.any(values):
        raise IdentifiabilityError(
            "the solution is all zeros: nothing in the logs' torques needs the parameters "
            "(are the motor currents all zero?); check the current columns of the logs")


def _free_system(r: np.ndarray, names: list[str], fixed: Mapping[str, float],
                 ) -> tuple[list[int], list[int], np.ndarray, np.ndarray, np.ndarray,
                            np.ndarray]:
    """The fixed and free columns of the triangle ``r``, the fixed values, the free columns,
    the right-hand side with the fixed ones moved to it, and the free columns' scales
    (norms; 1 for a zero column). No free column with a nonzero norm: rank 0, an error."""
    fix_idx = [names.index(k) for k in fixed]
    free = [j for j in range(len(names)) if j not in fix_idx]
    m_fix = np.array([fixed[names[j]] for j in fix_idx])
    c = r[:, free]
    d = r[:, -1] - (r[:, fix_idx] @ m_fix if fix_idx else 0.0)
    norms = np.linalg.norm(c, axis=0)
    if not free or not np.any(norms > 0):
        raise IdentifiabilityError(
            "the regressor has rank 0: the logs do not excite any parameter; use logs in which "
            "the platform moves")
    return fix_idx, free, m_fix, c, d, np.where(norms > 0, norms, 1.0)


def solve(r: np.ndarray, rows: int, names: Sequence[str],
          fixed: Mapping[str, float] | None = None, rcond: float = RCOND,
          bounds: tuple[np.ndarray, np.ndarray] | None = None,
          correlation: float = 1.0, stretches: np.ndarray | None = None) -> Solution:
    """Solve min ‖A m − b‖ from the triangle ``r`` of [A | b] (weighted, stacked).

    Parameters
    ----------
    r : (p+1, p+1) triangle; ``rows`` : number of rows it summarises (for σ̂²)
    correlation : rows per independent row (:attr:`Triangles.correlation`): the white-noise
        covariance of the values is σ̂² (AᵀA)⁻¹ times it
    stretches : (K, p+1, p+1) the weighted stretches of all logs
        (:meth:`Triangles.weighted_stretches`): with at least :data:`MIN_STRETCHES` the
        standard deviations are the larger of the jackknife's (:func:`jackknife_covariance`)
        and the white-noise ones
    fixed : name → value held fixed (moved to the right-hand side)
    rcond : singular values of the column-scaled regressor below ``rcond·σ_max`` count as zero;
        those directions are reported in the null space and their dependent parameters are
        set to zero, the independent ones then stand for identifiable combinations.
    bounds : (lower, upper) arrays over all parameters for a bounded (physical) fit
        (:func:`_bounded`).
    """
    import scipy.linalg  # (see qr_triangle)

    names = list(names)
    p = len(names)
    fixed = dict(fixed or {})
    check_rcond(rcond)
    check_fixed(fixed, names)
    if bounds is not None:
        return _bounded(r, rows, names, fixed, rcond, bounds, correlation, stretches)
    fix_idx, free, m_fix, c, d, scale = _free_system(r, names, fixed)
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
        # dependent parameters: the most involved ones (pivoted QR of the null space rows);
        # near-ties (two columns alike once scaled: a lump) go to the later parameter, so
        # that the same one stands for the combination from run to run, not the rounding's
        tilt = 1.0 + TIE_BREAK * np.arange(q_free) / max(q_free, 1)
        _, _, piv = scipy.linalg.qr((ns * tilt[:, None]).T, mode="economic", pivoting=True)
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
    std_white = std.copy()
    std_white[idx] = np.sqrt(np.diag(cov_b))
    basis = (f"white noise: σ̂ √(c diag((AᵀA)⁻¹)), c = {correlation:.3g} rows per independent "
             "row")
    if stretches is not None and len(stretches) >= MIN_STRETCHES:
        y_full = values.copy()
        y_full[idx] = y / scale[cols]
        jack = jackknife_covariance(stretches, np.asarray(idx), y_full, scale[cols])
        # the larger of the two per parameter, correlations from the jackknife
        sd = np.sqrt(np.maximum(np.diag(jack), np.diag(cov_b)))
        jd = np.sqrt(np.diag(jack))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(jd > 0, sd / jd, 0.0)
        cov_b = np.where(np.outer(jd, jd) > 0, jack * np.outer(ratio, ratio), cov_b)
        basis = (f"jackknife over {len(stretches)} stretches of {STRETCH_S:g} s (residuals "
                 "correlated in time and slowly varying model error), at least the white-noise "
                 "σ")
    std[idx] = np.sqrt(np.diag(cov_b))
    cov[np.ix_(idx, idx)] = cov_b

    _check_nonzero(values[free])
    # of the identifiable part: σ_max over the smallest singular value kept
    cond = float(sv[0] / sv[rank - 1])
    return Solution(names, values, std, sv, rank, cond, null, combination, combinations, fixed,
                    sigma2, rows, cov, std_white, basis)



def _bounded(r: np.ndarray, rows: int, names: list[str], fixed: dict[str, float],
             rcond: float, bounds: tuple[np.ndarray, np.ndarray], correlation: float,
             stretches: np.ndarray | None) -> Solution:
    """The bounded least-squares solution (BVLS) with its own account: the parameters it leaves
    at a bound are held there (:attr:`Solution.at_bound`), and the free fit of the others at
    that point — whose values are the bounded ones (the optimality conditions of a bounded
    least-squares problem) — gives their σ, rank and combinations. When that fit is still rank
    deficient the bounded solution is one point of a set of equally good ones: the parameters
    of the combinations get no σ of their own, their ``combinations`` text gives the
    identifiable combination with its value and σ, and :attr:`Solution.note` says so."""
    from scipy.optimize import lsq_linear  # imported here: only bounded fits need it

    p = len(names)
    lo, hi = (np.asarray(v, float) for v in bounds)
    fix_idx, free_list, m_fix, c, d, scale = _free_system(r, names, fixed)
    free = np.array(free_list, dtype=int)
    lo_s, hi_s = lo[free] * scale, hi[free] * scale
    x = lsq_linear(c / scale, d, bounds=(lo_s, hi_s), method="bvls", lsmr_tol="auto").x
    tol = 1e-9 * (1.0 + np.abs(x).max())
    at = (np.isfinite(lo_s) & (x - lo_s <= tol)) | (np.isfinite(hi_s) & (hi_s - x <= tol))
    x = np.where(at & (x - lo_s <= tol), lo_s, np.where(at, hi_s, x))
    values = np.zeros(p)
    values[fix_idx] = m_fix
    values[free] = x / scale
    _check_nonzero(values[free])
    at_bound = np.zeros(p, dtype=bool)
    at_bound[free[at]] = True
    if at.all():  # every free parameter on a bound: nothing left to fit
        none = np.full(p, np.nan)
        return Solution(names, values, none, np.zeros(0), 0, np.nan, np.zeros((p, 0)),
                        np.zeros(p, dtype=bool), {}, fixed, np.nan, rows,
                        np.full((p, p), np.nan), none.copy(), "none: every free parameter is "
                        "at a bound", at_bound)
    held = {**fixed, **{names[j]: float(values[j]) for j in free[at]}}
    inner = solve(r, rows, names, held, rcond, correlation=correlation, stretches=stretches)
    std, white = inner.std.copy(), inner.std_white.copy()
    combination = inner.combination.copy()
    combinations = dict(inner.combinations)
    note = ""
    unbounded = solve(r, rows, names, fixed, rcond, correlation=correlation,
                      stretches=stretches)
    lower = np.zeros(p, dtype=bool)
    lower[free[at & (x == lo_s)]] = True
    if _slides(unbounded.null_space, lower, at_bound & ~lower):
        tied = np.flatnonzero(np.any(unbounded.null_space != 0, axis=1))
        note = ("the bounded fit chose one point of a set of equally good solutions: these "
                f"logs cannot separate {', '.join(names[j] for j in tied)}; hold one of them "
                "with --fix NAME=VALUE to choose the point")
        comb = unbounded.combination_of(values)
        for j in tied:
            name = names[j]
            sd = inner.std[j] if np.isfinite(inner.std[j]) else unbounded.std[j]
            if np.isfinite(unbounded.std[j]):
                combinations[name] = (f"one point of a set; identifiable: "
                                      f"{unbounded.combinations.get(name, name)} = "
                                      f"{comb[j]:.5g} ± {sd:.2g}")
            else:
                combinations[name] = ("one point of a set; not identifiable alone (hold it "
                                      f"with --fix {name}=VALUE)")
            std[j] = white[j] = np.nan
            combination[j] = True
    return replace(inner, values=values, std=std, std_white=white, combination=combination,
                   combinations=combinations, fixed=fixed, at_bound=at_bound, note=note)


def _slides(null: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> bool:
    """Whether a point can move along a null-space direction (p, k) without leaving the
    bounds it is on (``lower``, ``upper`` masks): then it is one point of a set of equally good
    bounded solutions."""
    for v in null.T:
        for d in (v, -v):
            if np.all(d[lower] >= 0) and np.all(d[upper] <= 0):
                return True
    return False


def gram_triangle(gram: np.ndarray) -> np.ndarray:
    """An upper triangle R with RᵀR = ``gram`` (p+1, p+1), from its eigen-decomposition so that
    a semi-definite Gram matrix (a rank-deficient problem) keeps its null space."""
    lam, vec = np.linalg.eigh(0.5 * (gram + gram.T))
    # numpy's stubs type qr as returning a QRResult for every mode; mode="r" returns R alone
    return np.linalg.qr(np.sqrt(np.maximum(lam, 0.0))[:, None] * vec.T, mode="r")  # type: ignore[return-value]
