"""``fit --input-delay auto``: the delay of the logged torques behind the motion, from the logs.

One pass over the logs forms b_ID at the node delays of a bracket
(:class:`ropod_sysid.regressor.DelayBracket`); the criterion at each node is the weighted
residual variance of the fit at that delay, and the delay the vertex of the parabola through
the least nodes (:func:`parabola_vertex`). With the encoders' error gram (``--encoder-counts``,
or counts detected in the logs) the criterion is the corrected fit's, and where that is a
small difference of large numbers the fixed point of :func:`corrected_delay`
(docs/method.md, step 1).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ropod_sysid.fit import FitOptions, Reduce, fit_systems
from ropod_sysid.regressor import DelayBracket
from ropod_sysid.solve import Solution, Triangles, node_weights

if TYPE_CHECKING:
    from ropod_sysid.plotdata import LogPlot

__all__ = ["between_nodes", "corrected_delay", "delay_search", "parabola_vertex",
           "search_counts_note"]

NODE_FIT = 3  # node delays the delay search fits its parabola to (parabola_vertex)


def search_counts_note(systems: Sequence[Triangles]) -> str | None:
    """The delay search's note on the encoder counts detected in the logs (``--input-delay
    auto`` without ``--encoder-counts``; :func:`_delay_search`): that its criterion was
    corrected for them, or, when only some logs' angles move by whole counts, that it was
    not. None when no log's do."""
    counts = [s.error_counts for s in systems]
    if not any(counts):
        return None
    known = [c for c in counts if c]
    if len(known) == len(counts):
        shown = sorted(set(known))
        n = "/".join(map(str, shown))
        return (f"--input-delay auto: the search corrected its criterion for the quantisation "
                f"of the {n}-count encoders the angles move by, as --encoder-counts {n} does "
                "(uncorrected, their errors in the accelerations move the delay found later); "
                "the fit at that delay is not corrected: give --encoder-counts "
                f"{shown[0] if len(shown) == 1 else 'N'} for that too")
    return ("--input-delay auto: the angles of only some logs move by whole counts, so the "
            "search's criterion is not corrected for the encoders' quantisation, whose errors "
            "in the accelerations can move the delay found later; give --encoder-counts to "
            "correct it")


def delay_search(reduce: Reduce, names: Sequence[str], options: FitOptions,
                  ) -> tuple[list[tuple[str, Triangles, list[str], LogPlot | None]], float,
                             tuple[int, ...]]:
    """``--input-delay auto``: one pass forms b_ID at the node delays of the bracket ±top
    (:class:`ropod_sysid.regressor.DelayBracket`, top = ``max_delay``, at most one span);
    the weighted residual variance at the nodes gives the delay by a parabola through the
    smallest (:func:`parabola_vertex`), and the triangles of that delay follow from the
    nodes' (:meth:`Triangles.at_delay`): no further pass over the logs. An optimum at the
    bracket's end gets a note. Returns the logs' pieces at that delay, the delay and the
    detected counts its criterion was corrected for (() for none).

    The criterion is the residual variance of the fit the logs get: corrected for the
    encoders' errors in A with ``--encoder-counts`` (:func:`corrected_triangle`, its ρ²:
    :func:`corrected_factor`). Without it, when every log's angles move by whole counts of
    2π/N (:func:`ropod_sysid.quantisation.detect_encoder_counts`, on each log's first chunk), the
    pass formed the gram of the detected N (that of ``--encoder-counts N``, on the search's
    sparser rows: :func:`ropod_sysid.noise.search_gram_stride`) and the criterion is corrected
    all the same, so that the delay found is the one ``--encoder-counts N`` finds (within
    0.02 ms where measured): the plain fit's residual is least where b_ID lines up with the
    columns the encoders' errors blur, later than the true lag (docs/method.md). The fit at
    that delay stays as asked, uncorrected; a note says what the search did
    (:func:`search_counts_note`). When only some logs' angles move by whole counts the
    criterion stays uncorrected (a note says so)."""
    bracket = options.reduce_delay()
    assert isinstance(bracket, DelayBracket)  # (input_delay "auto")
    top = bracket.top
    wide = reduce(bracket, True)
    systems = [tri for _, tri, _, _ in wide]
    detecting = options.encoder_counts is None  # then a gram is of counts detected in a log
    note = search_counts_note(systems) if detecting else None
    if detecting and not all(s.error_counts for s in systems):
        systems = [replace(s, error_gram=None, error_counts=None) for s in systems]
    detected = tuple(sorted({s.error_counts for s in systems if s.error_counts})) \
        if detecting else ()

    def cost(d: float) -> float:
        sol, _ = fit_systems([s.at_delay(d, stretches=False) for s in systems], names,
                             options, calibrate=False)
        return sol.sigma2

    # the logs' nodes (their sample times may differ by rounding: merged within 1 µs)
    nodes = np.unique(np.round(np.concatenate([s.delays for s in systems]), 6))
    if any(s.error_gram is not None for s in systems):
        delay = corrected_delay(systems, nodes, names, options)
    else:
        costs = np.array([cost(float(d)) for d in nodes])
        delay = parabola_vertex(nodes, costs)
        if options.span.degree > 2:  # derivatives without the LOESS's bias: between_nodes
            delay = between_nodes(nodes, costs, cost, delay,
                                  max(s.delay_order for s in systems))
    out = []
    for (source, _, notes, plot), s in zip(wide, systems, strict=True):
        at = s.at_delay(delay)
        if detecting:  # the fit itself as asked: uncorrected
            at = replace(at, error_gram=None, error_counts=None)
        if plot is not None and plot.b_rows.ndim == 3:
            assert s.delays is not None  # (a 3-D b_rows: the search's nodes)
            w = node_weights(s.delays, delay, s.delay_order)
            plot = replace(plot, b_rows=plot.b_rows @ w)
        out.append((source, at, notes, plot))
    if note:
        out[0][2].append(note)
    if abs(delay) >= top - 2e-4:
        out[0][2].append(f"--input-delay auto: the best delay, {1000 * delay:+.2f} ms, is at "
                         f"the end of the bracket ±{1000 * top:.0f} ms searched: the lag may be "
                         "longer, or the residual hardly depends on it; give a delay in seconds "
                         "to check")
    return out, delay, detected


# corrected_delay(): below this ratio of the corrected to the plain residual at the best node
# the corrected cost is taken as noise (measured: 0.12–0.29 on the off-square runs at 100–1000 Hz
# and the shipped sample, under 0.001 on benchmarks/delay.py's 1 kHz runs)
FRAGILE_SHARE = 0.02
# the fixed point d = g(d) is sought by secant steps on g(d) − d from the plain search's delay;
# they stop when a step is below DELAY_TOL [s] or after DELAY_STEPS
DELAY_TOL = 1e-5
DELAY_STEPS = 12


def corrected_delay(systems: Sequence[Triangles], nodes: np.ndarray, names: Sequence[str],
                    options: FitOptions) -> float:
    """The input delay [s] of logs whose triangles carry the encoders' error gram.

    The criterion is the corrected fit's own cost, ρ² = ‖b − A m‖² − mᵀE m, at the nodes,
    and the vertex of the parabola through the least (:func:`parabola_vertex`) — unless ρ² at
    its least node is under :data:`FRAGILE_SHARE` of the plain residual there: then the
    encoders' errors are nearly all the residual and ρ² a small difference of large numbers
    (2¹⁴ counts, four 20 s typical runs at 1 kHz: ρ² clipped near 0, the nodes 5 ms either
    side 1.9× and 23× it, the vertex 2.8 ms off). There, for values m held fixed, the residual
    ‖b(d) − A m‖² is a smooth quadratic in the torques' delay d whose expectation at the true
    m is least at the true delay (the encoders' errors in A do not depend on b's delay). So
    g(d): the corrected m fitted at d, then the vertex of that residual over the nodes; the
    delay is the fixed point d = g(d), by secant steps from the plain residual's vertex (the
    plain fit's values, shrunk by the encoders' errors, are best matched later). It is not the
    rule everywhere: on the off-square 8 s runs (2¹⁴ counts, 30 mA, 8 noise draws) it finds
    0.35–0.4 ms less than ρ² and the exact logs at 100 and 200 Hz (docs/method.md)."""
    plain = [replace(s, error_gram=None) for s in systems]

    def solved(ss: Sequence[Triangles], d: float) -> tuple[Solution, list[float]]:
        return fit_systems([s.at_delay(d, stretches=False) for s in ss], names, options,
                           calibrate=False)

    rho2 = np.array([solved(systems, float(d))[0].sigma2 for d in nodes])
    k = int(np.argmin(rho2))
    if rho2[k] >= FRAGILE_SHARE * solved(plain, float(nodes[k]))[0].sigma2:
        return parabola_vertex(nodes, rho2)
    plain_costs = np.array([solved(plain, float(d))[0].sigma2 for d in nodes])

    def g(d: float) -> float:
        sol, weights = solved(systems, d)
        costs = np.zeros(len(nodes))
        for s, w in zip(systems, weights, strict=True):
            scale = np.array([1.0, 1.0, w * w])
            assert s.delays is not None  # the search's systems hold b_ID at its nodes
            for j, x in enumerate(nodes):
                z = np.append(sol.values, -node_weights(s.delays, float(x), s.delay_order))
                costs[j] += float(scale @ ((s.r @ z) ** 2).sum(axis=1))
        return parabola_vertex(nodes, costs)

    d0 = parabola_vertex(nodes, plain_costs)
    d1 = g(d0)
    h0 = d1 - d0
    for _ in range(DELAY_STEPS):
        if abs(h0) < DELAY_TOL:
            break
        g1 = g(d1)
        h1 = g1 - d1
        # secant on h(d) = g(d) − d; a plain step where the secant is flat or points away
        slope = (h1 - h0) / (d1 - d0) if d1 != d0 else 0.0
        d_next = d1 - h1 / slope if slope < -1e-3 else g1
        d0, h0, d1 = d1, h1, float(np.clip(d_next, nodes[0], nodes[-1]))
    return d1


def parabola_vertex(x: np.ndarray, y: np.ndarray, width: int = NODE_FIT) -> float:
    """The minimum of the quadratic fitted to the ``width`` points of (``x``, ``y``) nearest
    the smallest ``y``, held within those points (at a node when too few or not convex).
    The delay search fits the costs at the node delays only: between nodes the interpolated
    torques average the current noise, which would pull the minimum to mid-sample delays."""
    i = int(np.argmin(y))
    lo = int(np.clip(i - width // 2, 0, max(len(x) - width, 0)))
    xs, ys = x[lo: lo + width], y[lo: lo + width]
    if len(xs) < 3:
        return float(x[i])
    c2, c1, _ = np.polyfit(xs - x[i], ys, 2)
    if c2 <= 0:
        return float(x[i])
    return float(np.clip(x[i] - c1 / (2 * c2), xs[0], xs[-1]))


def between_nodes(nodes: np.ndarray, costs: np.ndarray, cost: Callable[[float], float],
                  vertex: float, order: int = 1) -> float:
    """The least criterion between the node delays, for ``--smoother quartic``: the
    parabola through three nodes (``vertex``, :func:`parabola_vertex`) takes the criterion as
    quadratic over two node spacings, which put the delay of noise-free 200 Hz logs under a
    1 ms hold at 0.56 ms; between the nodes its least value is at 0.50 ms, the hold's half step
    (docs/method.md, "The delay search between its nodes").

    Nodes one sample apart (``order`` 1): b_ID between two nodes is their linear
    interpolation, so the refit's residual bᵀP⊥b is along each interval exactly the quadratic
    (1 − f) c_a + f c_b − f (1 − f) q in the fraction f (for the fixed rotation weight), q from
    one ``cost`` at the interval's middle: q = 2 (c_a + c_b − 2 c_½); its least value on the two
    intervals beside the least node. Nodes several samples apart (``order`` 3, cubic
    interpolation): the vertex of the parabola through ``cost`` at ``vertex`` and a quarter
    node spacing either side, held within them.

    Only for the quartic: the LOESS's accelerations carry a bias that the delay trades
    against, and its residual is least 0.1–0.3 ms before the delay that fits best (on those
    logs 0.90 → 1.35 %). Between the nodes the current noise partly averages out, which pulls
    the minimum towards an interval's middle; with 30 mA at 200 Hz by up to 0.06 ms with the
    quartic (the rows' filters make neighbouring nodes' noise nearly the same). ``vertex`` is
    kept where the criterion is not convex."""
    if order != 1:
        h = 0.25 * float(np.min(np.diff(nodes))) if len(nodes) > 1 else 0.0
        if h <= 0:
            return vertex
        xs = vertex + h * np.array([-1.0, 0.0, 1.0])
        ys = np.array([cost(float(x)) for x in xs])
        c2, c1, _ = np.polyfit(xs - vertex, ys, 2)
        return vertex if c2 <= 0 else float(vertex + np.clip(-c1 / (2 * c2), -h, h))
    i = int(np.argmin(costs))
    best, at = np.inf, vertex
    for a in (i - 1, i):
        b = a + 1
        if a < 0 or b >= len(nodes):
            continue
        c_a, c_b = float(costs[a]), float(costs[b])
        q = 2.0 * (c_a + c_b - 2.0 * cost(0.5 * float(nodes[a] + nodes[b])))
        if not q > 0:
            continue
        f = float(np.clip(0.5 - (c_b - c_a) / (2.0 * q), 0.0, 1.0))
        value = (1.0 - f) * c_a + f * c_b - f * (1.0 - f) * q
        if value < best:
            best, at = value, float(nodes[a] + f * (nodes[b] - nodes[a]))
    return at
