"""Rest-to-rest finite Fourier series for the base motion (Swevers et al.): :class:`FourierFamily`.

The family of the optimal excitation search (:mod:`ropod_sysid.trajectory.excitation`): speed
[m/s], direction of travel [rad] and curvature [rad/m] of the base, each a finite Fourier series,
rest to rest, no pivot velocity ever reversing (eq. 8a); :func:`_scaled_twist` runs every
candidate at the largest speed scale within the limits and the floor.
"""

from __future__ import annotations

import math

import numpy as np

from ropod_sysid.trajectory.blends import _quintic
from ropod_sysid.trajectory.limits import Floor, Limits
from ropod_sysid.trajectory.run_variants import _variant_paths

KAPPA_FRACTION = 0.9  # FourierFamily: κ_max · max pivot radius (ICR outside the units)
RHO_BETA, RHO_KAPPA = 0.5, 0.1  # FourierFamily: rate scales of direction and curvature
NU_MIN = 0.25  # FourierFamily: least speed between the ramps, as a fraction of s_v


class FourierFamily:
    """Rest-to-rest finite Fourier series for the base motion, in polar form (base frame).

    Each of the three base DOFs of the twist gets a finite Fourier series with base period T
    and H harmonics (Swevers et al.; ω_f = 2π / T, coefficients c, a_l, b_l):

        speed      ν(t) = s_v w(t) (ν_0 + (1 − ν_0)(1 + tanh g(t)) / 2),   ν_0 = 0.25
                   g(t) = c_v + Σ a_l sin(lω_f t) + b_l cos(lω_f t)
        direction  β(t) = π c_β + ρ_β w(t)² h_β(t)                 [rad, of travel, base frame]
        curvature  κ(t) = κ_max tanh(c_κ + ρ_κ w(t)² h_κ(t))         [rad/m]
        h(t) = Σ (a_l sin(lω_f t) − b_l cos(lω_f t)) / (l ω_f)        (so ḣ = Σ a_l cos + b_l sin)
        (vx, vy) = ν (cos β, sin β),   ω = ν κ,

    with w(t) a window rising from 0 to 1 over the first ``ramp`` seconds and falling back over
    the last (minimum-jerk profile): rest to rest, acceleration continuous. Why polar rather than
    a series per Cartesian component: pivot i moves with P_i = ν (e(β) + κ S r_i) (eq. 8a);
    with |κ| < κ_max = 0.6 / max|r_i| the bracket never vanishes — the instantaneous centre of
    rotation stays outside the units — so no pivot velocity ever reverses (no wheel flip, Sec.
    VI-A) whatever the coefficients, where Cartesian series reverse them all the time; between
    the ramps the speed stays above ν_0 s_v, for a unit cannot turn while its pivot stands. The
    direction of P_i, hence the pivot rate, depends on β and κ only, not on the speed scale s_v;
    ρ_β and ρ_κ size the rates of β and of κ's argument to the pivot-rate budget, and β, κ vary
    only where w is near 1 (w² factor), so the units need not turn while the base barely moves.
    The curvature radius is R = |v|/|ω| = 1/|κ| > 1/κ_max wherever the base moves: with
    ``radius_min`` (002 eq. 26's R_min) κ_max ≤ 1/R_min, so every member keeps it.
    """

    def __init__(self, duration: float, harmonics: int, t: np.ndarray, r_max: float,
                 rate_budget: float = 1.5, ramp: float | None = None,
                 radius_min: float | None = None) -> None:
        self.duration = float(duration)
        self.harmonics = int(harmonics)
        self.t = np.asarray(t, float)
        self.ramp = float(ramp if ramp is not None else min(0.15 * duration, 4.0))
        self.kappa_max = KAPPA_FRACTION / max(float(r_max), 1e-6)
        if radius_min is not None:  # R = |v|/|ω| = 1/|κ| ≥ radius_min (002 eq. 26)
            self.kappa_max = min(self.kappa_max, 1.0 / radius_min)
        self.rho_beta = RHO_BETA * rate_budget / math.sqrt(2 * self.harmonics)
        self.rho_kappa = RHO_KAPPA * rate_budget / math.sqrt(2 * self.harmonics)
        wf = 2 * math.pi / self.duration
        lw = wf * np.arange(1, self.harmonics + 1)
        arg = np.outer(self.t, lw)
        sn, cs = np.sin(arg), np.cos(arg)
        one, zero = np.ones((len(self.t), 1)), np.zeros((len(self.t), 1))
        # bases (N, 2H+1); coefficient order [c, a_1..a_H, b_1..b_H]
        self.g0 = np.hstack([one, sn, cs])  # g and ġ (speed)
        self.g1 = np.hstack([zero, cs * lw, -sn * lw])
        self.h0 = np.hstack([zero, sn / lw, -cs / lw])  # h and ḣ (direction, curvature)
        self.h1 = np.hstack([zero, cs, sn])
        up, dup, _ = _quintic(self.t / self.ramp)
        dn, ddn, _ = _quintic((self.duration - self.t) / self.ramp)
        self.w = up * dn
        self.dw = dup / self.ramp * dn - up * ddn / self.ramp

    @property
    def n_coefficients(self) -> int:
        return 3 * (2 * self.harmonics + 1)

    def shape(self, coef: np.ndarray) -> tuple[np.ndarray, ...]:
        """(ν, ν̇, β, β̇, κ, κ̇) (S, N) at unit speed scale for coefficients (S, 3(2H+1))."""
        c = np.asarray(coef, float).reshape(-1, 3, 2 * self.harmonics + 1)
        g = c[:, 0] @ self.g0.T
        gd = c[:, 0] @ self.g1.T
        w, dw = self.w, self.dw
        th = np.tanh(g)
        base = NU_MIN + (1 - NU_MIN) * (1 + th) / 2
        nu = w * base
        nud = dw * base + w * (1 - NU_MIN) * (1 - th**2) * gd / 2
        w2, dw2 = w**2, 2 * w * dw
        hb, hbd = c[:, 1] @ self.h0.T, c[:, 1] @ self.h1.T
        beta = math.pi * c[:, 1, :1] + self.rho_beta * w2 * hb
        betad = self.rho_beta * (dw2 * hb + w2 * hbd)
        hk, hkd = c[:, 2] @ self.h0.T, c[:, 2] @ self.h1.T
        tk = np.tanh(c[:, 2, :1] + self.rho_kappa * w2 * hk)
        kappa = self.kappa_max * tk
        kappad = self.kappa_max * (1 - tk**2) * self.rho_kappa * (dw2 * hk + w2 * hkd)
        return nu, nud, beta, betad, kappa, kappad


def _scaled_twist(family: FourierFamily, coef: np.ndarray, limits: Limits, floor: Floor,
                  t: np.ndarray, margin: float, s_v: np.ndarray | None = None,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Twist, twist rate (S, N, 3) and speed scale s_v (S,) of a family's candidates.

    s_v is the largest scale (times ``margin``) with |v| ≤ v_max, |ω| ≤ ω_max, |ω̇| ≤ α_max,
    |a| ≤ a_max (a = s_v sqrt(ν̇² + ν² (β̇ + s_v ν κ)²) grows monotonically with s_v) and the
    four variants inside the floor (bisection: the path grows with s_v); given s_v is used as is.
    """
    nu, nud, beta, betad, kappa, kappad = family.shape(coef)
    tiny = 1e-12
    if s_v is None:
        hi = np.minimum.reduce([
            limits.v_max / (nu.max(1) + tiny),
            limits.w_max / (np.abs(nu * kappa).max(1) + tiny),
            limits.alpha_max / (np.abs(nud * kappa + nu * kappad).max(1) + tiny)])
        hi = np.minimum(hi * margin, 20.0)

        sub = slice(None, None, max(len(t) // 150, 1))  # floor on a coarse grid
        t_sub = t[sub]

        def feasible(s: np.ndarray) -> np.ndarray:
            sc = s[:, None]
            acc = sc * np.sqrt(nud**2 + nu**2 * (betad + sc * nu * kappa) ** 2)
            ok = acc.max(1) <= limits.a_max * margin
            tw = _twist_of(sc, nu[:, sub], beta[:, sub], kappa[:, sub])
            paths = _variant_paths(t_sub, tw)
            x0, x1, y0, y1 = (margin * f for f in floor)
            inside = ((paths[..., 0] >= x0) & (paths[..., 0] <= x1) & (paths[..., 1] >= y0)
                      & (paths[..., 1] <= y1)).all(axis=(1, 2))
            return ok & inside

        lo = np.zeros_like(hi)
        top = feasible(hi)
        for _ in range(8):
            mid = 0.5 * (lo + hi)
            good = feasible(mid)
            lo = np.where(good, mid, lo)
            hi = np.where(good, hi, mid)
        s_v = np.where(top, hi, lo)
    sc = np.asarray(s_v, float)[:, None]
    tw = _twist_of(sc, nu, beta, kappa)
    cb, sb = np.cos(beta), np.sin(beta)
    twd = np.stack([sc * (nud * cb - nu * betad * sb), sc * (nud * sb + nu * betad * cb),
                    sc * (nud * kappa + nu * kappad)], axis=-1)
    return tw, twd, np.asarray(s_v, float)


def _twist_of(sc: np.ndarray, nu: np.ndarray, beta: np.ndarray, kappa: np.ndarray) -> np.ndarray:
    return np.stack([sc * nu * np.cos(beta), sc * nu * np.sin(beta), sc * nu * kappa], axis=-1)
