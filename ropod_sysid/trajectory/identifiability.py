"""The predicted regressor along planned motions and what it says (thesis eqs. 35, 36, 66).

The stacked regressor A_ID,ext of the four variants, evaluated along the planned motion (q, q̇, q̈
in the world frame), tells before a run whether its data identify the parameters: the condition
number and rank of the column-scaled regressor (:func:`conditioning`) and the predicted standard
deviation of every parameter of a least-squares fit under white noise on b_ID [N, N m]
(:func:`predicted_std`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.solve import RCOND, numerical_rank
from ropod_sysid.trajectory.setpoints import integrate_pose

if TYPE_CHECKING:
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.params import Friction


def _world_motion(t: np.ndarray, twist: np.ndarray, rates: np.ndarray | None = None,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-frame q, q̇, q̈ (..., N, 3) of base-frame twists (..., N, 3) starting at zero.

    ``rates`` are the twist derivatives (second-order differences if not given).
    """
    if rates is None:
        rates = np.gradient(twist, t, axis=-2, edge_order=2)
    x, y, th = integrate_pose(t, twist[..., 0], twist[..., 1], twist[..., 2])
    c, s = np.cos(th), np.sin(th)
    vx, vy, w = twist[..., 0], twist[..., 1], twist[..., 2]
    ax = rates[..., 0] - w * vy
    ay = rates[..., 1] + w * vx
    q = np.stack([x, y, th], axis=-1)
    qd = np.stack([c * vx - s * vy, s * vx + c * vy, w], axis=-1)
    qdd = np.stack([c * ax - s * ay, s * ax + c * ay, rates[..., 2]], axis=-1)
    return q, qd, qdd


def with_own_coordinates(model: PlatformModel, t: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                         rates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The generalized velocity and acceleration (…, N, D) of planned motions: the base's
    (…, N, 3) followed by the units' own coordinates' (the steered wheels' β̇ from the
    predicted angle rates (…, N, J), β̈ by differences over t); unchanged without any."""
    if model.n_dof == 3:
        return qd, qdd
    own = rates[..., model.coordinate_channels]
    acc = np.gradient(own, t, axis=-2) if own.shape[-2] > 1 else np.zeros_like(own)
    return np.concatenate([qd, own], axis=-1), np.concatenate([qdd, acc], axis=-1)


def _regressor_rows(model: PlatformModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                    angles: np.ndarray, friction: Friction, chunk: int = 20000,
                    noise: tuple[object, object] | None = None,
                    angle_rates: np.ndarray | None = None,
                    motion: tuple[np.ndarray, np.ndarray] | None = None,
                    ) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray | float]:
    """A_ID,ext (M, D, p) at M samples with unit angles (M, J) (chunked to bound the memory);
    the angle rates follow from the base motion (for the swivel: δ̇ of eq. 8a) unless
    ``angle_rates`` (M, J) gives them (as a log's encoders would); a unit's own joint is
    locked while it is held, as the fit locks it. With ``noise`` = (true parameters,
    :class:`~ropod_sysid.noise.SensorNoise`) also the rows' variances (M, D)
    (:func:`~ropod_sysid.noise.row_variances`) and the encoders' error gram of A per row kind
    (3, p, p), both from the errors carried through the fit's own recipe
    (:func:`~ropod_sysid.noise.recipe_error_gram`, the one ``fit --encoder-counts``
    subtracts; :func:`~ropod_sysid.noise.kind_grams`). ``motion``: each channel's rate and
    acceleration through the rows' windows ((M, J) each;
    :func:`~ropod_sysid.quantisation.window_motion` of a log), whose
    :func:`~ropod_sysid.quantisation.tone_share` the encoders' errors then take, as the fit's
    do (None: the :func:`~ropod_sysid.quantisation.sawtooth_share` of the rows' rates)."""
    from ropod_sysid.noise import kind_grams, planned_rows, recipe_error_gram, row_variances

    out, var = [], []
    gram: np.ndarray | float = 0.0  # 0.0 without rows
    for k in range(0, q.shape[0], chunk):
        sl = slice(k, k + chunk)
        rates = None if angle_rates is None else angle_rates[sl]
        st = model.state(q[sl], qd[sl], angles[sl], rates)
        if qd.shape[1] > 3:  # the fit locks a unit's own joint while it is held
            from ropod_sysid.regressor import held_joints

            st.held = held_joints(model, qd[sl, 3:])
        a = model.a_id_ext(st, qdd[sl], friction)
        out.append(a)
        if noise is not None:
            params, sensors = noise
            rows = planned_rows(model, q[sl], qd[sl], qdd[sl], angles[sl], rates)
            truth = params.vector(model.parameter_names(friction))  # type: ignore[attr-defined]
            part = None if motion is None else (motion[0][sl], motion[1][sl])
            g, enc = recipe_error_gram(model, rows, sensors, friction, truth,  # type: ignore[arg-type]
                                       motion=part)
            var.append(row_variances(model, rows, params, sensors, friction, encoder=enc))  # type: ignore[arg-type]
            gram = gram + kind_grams(g)
    a = np.concatenate(out, axis=0)
    return a if noise is None else (a, np.concatenate(var, axis=0), gram)


@dataclass
class Conditioning:
    """Column-scaled singular values of a stacked regressor and what they say.

    singular_values : descending, of A with every column scaled to unit norm (as
        :func:`ropod_sysid.solve.solve` does)
    rank : number of singular values above ``1e-9 σ_max`` (the identifiable subspace)
    condition_number : σ_max / σ_rank — on the identifiable subspace
    condition_number_full : σ_max / σ_min over all columns (inf when rank deficient)
    """

    singular_values: np.ndarray
    rank: int
    condition_number: float
    condition_number_full: float


RANK_TOL = RCOND  # the fit's rank rule (:func:`ropod_sysid.solve.numerical_rank`)


def conditioning(a: np.ndarray) -> Conditioning:
    """:class:`Conditioning` of a stacked regressor (M, p) (or (…, 3, p) rows)."""
    a = a.reshape(-1, a.shape[-1])
    norms = np.linalg.norm(a, axis=0)
    sv = np.linalg.svd(a / np.where(norms > 0, norms, 1.0), compute_uv=False)
    if sv.size == 0 or sv[0] == 0:
        return Conditioning(sv, 0, math.inf, math.inf)
    rank = numerical_rank(sv, RANK_TOL)
    full = float(sv[0] / sv[-1]) if rank == sv.size else math.inf
    return Conditioning(sv, rank, float(sv[0] / sv[rank - 1]), full)


def predicted_std(a: np.ndarray, noise: float | tuple[float, float] = 1.0,
                  rows_per_second: float = 1.0, tol: float = RANK_TOL) -> np.ndarray:
    """Predicted standard deviation of each parameter (p,) of a least-squares fit.

    Parameters
    ----------
    a : (M, D, p) regressor rows sampled at ``rows_per_second`` samples per second of run
    noise : σ of b_ID, white: one value for every row, or (translation [N], rotation [N m])
    rows_per_second : the log samples each evaluated sample stands for: the information of a
        log at rate r_log evaluated at rate r_eval is r_log / r_eval times that of the rows

    Returns σ·sqrt(diag((AᵀWA)⁺)) with W = diag(1/σ²); parameters the data determine only in
    combination with others (outside the identifiable subspace) get inf.
    """
    sig = (noise, noise) if isinstance(noise, int | float) else noise
    w = np.where(np.arange(a.shape[1]) < 2, 1.0 / sig[0], 1.0 / sig[1])  # x, y; θ and own
    aw = (a * w[None, :, None]).reshape(-1, a.shape[-1]) * math.sqrt(rows_per_second)
    norms = np.linalg.norm(aw, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    _, sv, vt = np.linalg.svd(aw / scale, full_matrices=False)
    if sv.size == 0 or sv[0] == 0:
        return np.full(a.shape[-1], math.inf)
    r = numerical_rank(sv, tol)
    vr = vt[:r].T  # (p, r)
    cov_diag = ((vr / sv[:r]) ** 2).sum(axis=1) / scale**2
    # a unit vector e_j is identifiable when it lies in the row space span(vr)
    inside = np.linalg.norm(vr, axis=1) > 1 - 1e-6
    return np.where(inside & (norms > 0), np.sqrt(cov_diag), math.inf)
