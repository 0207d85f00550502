"""The report's figures: small functions from arrays to PNG bytes (matplotlib, Agg).

Every figure is drawn on its own :class:`matplotlib.figure.Figure` with the Agg canvas (no
pyplot, no global state, no display needed). What is *plotted* is decimated to at most
``MAX_POINTS`` points per line; what is *computed* (RMS values, histograms, binned means) always
uses every sample. Line data are decimated by keeping the minimum and maximum of each bucket, so
that a single spike in a long log still shows.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, cast

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, MaxNLocator, NullLocator
from matplotlib.transforms import Bbox

if TYPE_CHECKING:
    from ropod_sysid.platform import Layout
    from ropod_sysid.plotdata import LogPlot

MAX_POINTS = 2000
DPI = 96
DOF_LABELS = ("x", "y", "θ")
DOF_UNITS = ("N", "N", "N m")
VEL_LABELS = ("ẋ [m/s]", "ẏ [m/s]", "θ̇ [rad/s]")
BLUE, ORANGE, GREY, RED, GREEN = "#1f5fa8", "#e07b00", "#7f8790", "#c0392b", "#2e8b57"
PALETTE = ("#1f5fa8", "#e07b00", "#2e8b57", "#c0392b", "#7b4fa0", "#8c564b", "#d6619e",
           "#5a6b7b", "#b5a000", "#17a2b8")

_STYLE = {
    "font.size": 8.5,
    "axes.titlesize": 9.5,
    "axes.labelsize": 8.5,
    "axes.grid": True,
    "grid.color": "#dde1e6",
    "grid.linewidth": 0.6,
    "axes.edgecolor": "#9aa3ad",
    "axes.spines.top": False,
    "axes.spines.right": False,
    "legend.fontsize": 7.5,
    "legend.frameon": False,
    "lines.linewidth": 1.0,
    "xtick.labelsize": 7.5,
    "ytick.labelsize": 7.5,
    "path.simplify": True,
    "agg.path.chunksize": 10000,
}


# ---------------------------------------------------------------------------------------------
# decimation (plotting only)


def decimate(x: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS,
             ) -> tuple[np.ndarray, np.ndarray]:
    """At most ~``max_points`` points of the line (x, y): the min and max of each bucket, in
    order, so that peaks survive. ``y`` may be (n,) or (n, k); returns one line's x and y when
    1-D, else x (m, k) and y (m, k) with each column decimated on its own."""
    x = np.asarray(x)
    y = np.asarray(y)
    n = len(x)
    if n <= max_points:
        return x, y
    buckets = max(max_points // 2, 1)
    edges = np.linspace(0, n, buckets + 1).astype(int)
    size = int(np.max(np.diff(edges)))
    # pad each bucket to the same size with its own last sample, then argmin/argmax row-wise
    starts = edges[:-1]
    idx = np.minimum(starts[:, None] + np.arange(size)[None, :], (edges[1:] - 1)[:, None])
    cols = y[:, None] if y.ndim == 1 else y
    xs, ys = [], []
    for j in range(cols.shape[1]):
        v = cols[idx, j]  # (buckets, size)
        with np.errstate(invalid="ignore"):
            lo = idx[np.arange(buckets), np.nanargmin(np.where(np.isnan(v), np.inf, v), axis=1)]
            hi = idx[np.arange(buckets), np.nanargmax(np.where(np.isnan(v), -np.inf, v), axis=1)]
        keep = np.sort(np.stack([lo, hi], axis=1), axis=1).ravel()
        xs.append(x[keep])
        ys.append(cols[keep, j])
    if y.ndim == 1:
        return xs[0], ys[0]
    return np.stack(xs, axis=1), np.stack(ys, axis=1)


def subsample(n: int, max_points: int = MAX_POINTS, seed: int = 0) -> np.ndarray:
    """Sorted random indices of at most ``max_points`` of ``n`` samples (for scatter plots)."""
    if n <= max_points:
        return np.arange(n)
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(n, size=max_points, replace=False))


# ---------------------------------------------------------------------------------------------
# plumbing


def _figure(width: float, height: float, **margins: float) -> Figure:
    """A figure with fixed margins (fractions of the figure; a layout engine would cost more
    time than the drawing itself)."""
    fig = Figure(figsize=(width, height), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(**{"left": 0.07, "right": 0.985, "top": 0.94, "bottom": 0.12, **margins})
    return fig


def _png(fig: Figure) -> bytes:
    """The figure drawn by Agg as a PNG of at most 256 colours (white background).

    Measured on the report's figures: a third of the bytes of matplotlib's RGBA PNG and half
    its encoding time; the figures are flat colours and antialiased edges.
    """
    fig.patch.set_facecolor("white")
    fig.canvas.draw()
    return _encode(cast(FigureCanvasAgg, fig.canvas))  # every figure's (:func:`_figure`)


def _encode(canvas: FigureCanvasAgg) -> bytes:
    """What ``canvas`` holds now as a PNG of at most 256 colours (:func:`_png`)."""
    from PIL import Image  # matplotlib's own dependency

    width, height = canvas.get_width_height(physical=True)
    # read in place and converted by PIL (a strided numpy view costs a copy twice as slow)
    rgba = Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    image = rgba.convert("RGB").quantize(256, method=Image.Quantize.FASTOCTREE)
    buf = io.BytesIO()
    image.save(buf, format="png", compress_level=6)
    return buf.getvalue()


def _redraw(fig: Figure, axes: Sequence) -> bytes:
    """Rescale ``axes`` to their lines' new data and draw ``fig`` (in the report's style)."""
    with _style():
        for ax in axes:
            ax.relim()
            ax.autoscale_view()
        return _png(fig)


def _line(ax, x: np.ndarray, y: np.ndarray, **kw) -> None:
    xd, yd = decimate(x, y)
    ax.plot(xd, yd, **kw)


def _title(ax, text: str) -> None:
    """Left-aligned axes title at a fixed height (matplotlib's automatic title placement
    measures the tick labels and costs more than drawing the axes)."""
    ax.set_title(text, loc="left", y=1.0, pad=4.0)


def _legend_above(ax, **kw) -> None:
    """Legend right-aligned above the axes (next to a left-aligned title), off the data."""
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), borderaxespad=0.1,
              handlelength=1.6, columnspacing=1.0, **kw)


def _style():
    return matplotlib.rc_context(_STYLE)


# ---------------------------------------------------------------------------------------------
# figures


class FitFigure:
    """The thesis's Fig. 13 for one log: per DOF the fit A_ID,ext m* against the filtered b_ID
    (upper panel) and the error b_ID − A_ID,ext m* (lower panel), over time.

    The axes, lines and legend are built once and only their data change from log to log:
    building the axes and their ticks costs more than drawing them.
    """

    def __init__(self) -> None:
        with _style():
            fig = _figure(10.0, 8.4, top=0.97, bottom=0.055)
            gs = fig.add_gridspec(6, 1, height_ratios=[3, 1.3] * 3, hspace=0.32)
            axes = [fig.add_subplot(gs[k]) for k in range(6)]
            for k in range(1, 6):
                axes[k].sharex(axes[0])
            self.lines: list[tuple[Line2D, Line2D, Line2D]] = []
            self.texts = []
            for d in range(3):
                top, bot = axes[2 * d], axes[2 * d + 1]
                # b wide and light, the fit thin on top: both stay visible where they agree
                (b_line,) = top.plot([], [], color="#aeb8c3", lw=3.0, label="b_ID (filtered)")
                (fit_line,) = top.plot([], [], color=BLUE, lw=0.9, label="A_ID,ext m*")
                top.set_ylabel(f"{DOF_LABELS[d]} [{DOF_UNITS[d]}]")
                _title(top, f"{DOF_LABELS[d]} row of the direct EOM")
                self.texts.append(top.text(
                    0.995, 0.96, "", transform=top.transAxes, ha="right", va="top", fontsize=8,
                    color=RED, bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1.5}))
                (err_line,) = bot.plot([], [], color=RED, lw=0.8)
                bot.axhline(0.0, color="#444", lw=0.6)
                bot.set_ylabel(f"error [{DOF_UNITS[d]}]")
                bot.yaxis.set_major_locator(MaxNLocator(3))
                top.yaxis.set_major_locator(MaxNLocator(5))
                top.tick_params(labelbottom=False)
                if d < 2:
                    bot.tick_params(labelbottom=False)
                self.lines.append((b_line, fit_line, err_line))
            axes[0].xaxis.set_major_locator(MaxNLocator(8))
            _legend_above(axes[0], ncols=2)
            axes[-1].set_xlabel("t [s]")
        self.fig, self.axes = fig, axes

    def render(self, t: np.ndarray, b: np.ndarray, fit: np.ndarray,
               rms: Sequence[float] | None = None) -> bytes:
        """The figure of one log's rows: times t (r,), b_ID and A_ID,ext m* (r, 3). ``rms``:
        the RMS error per DOF over all rows (default: over the rows given)."""
        self.set_log(t, b, fit, rms)
        return _redraw(self.fig, self.axes)

    @property
    def changing(self) -> list[Any]:
        """The artists that change from log to log (:func:`_render_shared`)."""
        return [line for lines in self.lines for line in lines] + list(self.texts)

    def set_log(self, t: np.ndarray, b: np.ndarray, fit: np.ndarray,
                rms: Sequence[float] | None = None) -> None:
        """One log's data in the lines and texts (:meth:`render`), nothing drawn."""
        err = b - fit
        for d, (b_line, fit_line, err_line) in enumerate(self.lines):
            b_line.set_data(*decimate(t, b[:, d]))
            fit_line.set_data(*decimate(t, fit[:, d]))
            err_line.set_data(*decimate(t, err[:, d]))
            if rms is not None:
                r = float(rms[d])
            else:
                r = float(np.sqrt(np.mean(err[:, d] ** 2))) if len(err) else float("nan")
            self.texts[d].set_text(f"RMS error {r:.3g} {DOF_UNITS[d]}")


_BUILT: dict[Any, Any] = {}  # this process's figures built once and redrawn (FitFigure, …)


def _fit_figure() -> FitFigure:
    """This process's :class:`FitFigure`, built on first use."""
    if FitFigure not in _BUILT:
        _BUILT[FitFigure] = FitFigure()
    return _BUILT[FitFigure]


def _inputs_figure(layout: Layout) -> InputsFigure:
    """This process's :class:`InputsFigure` of ``layout``, built on first use."""
    key = (InputsFigure, tuple(layout.columns()))
    if key not in _BUILT:
        _BUILT[key] = InputsFigure(layout)
    return _BUILT[key]


def fit_vs_measured(t: np.ndarray, b: np.ndarray, fit: np.ndarray,
                    rms: Sequence[float] | None = None) -> bytes:
    """:class:`FitFigure` of one log (the figure built once per process)."""
    fig = _fit_figure()
    return fig.render(t, b, fit, rms)


class InputsFigure:
    """The inputs of one log: base path (x–y), base velocities, the units' turning angles
    (swivel pivots: the wrapped angle channels), actuator torques, from their min/max envelopes
    (:class:`ropod_sysid.plotdata.LogPlot`); built once for the platform's layout and redrawn
    per log (see :class:`FitFigure`)."""

    def __init__(self, layout: Layout) -> None:
        units = list(layout.units)
        turning = [(int(i), name) for name, i, w in zip(layout.angle_names, layout.angle_unit,
                                                       layout.wrapped, strict=True) if w]
        actuators = list(zip(layout.current_unit, layout.current_channels, strict=True))
        with _style():
            fig = _figure(10.0, 6.4, top=0.95, bottom=0.08, left=0.065, right=0.99)
            gs = fig.add_gridspec(2, 2, wspace=0.2, hspace=0.32)
            ax_path = fig.add_subplot(gs[0, 0])
            ax_vel = fig.add_subplot(gs[0, 1])
            ax_piv = fig.add_subplot(gs[1, 0])
            ax_tau = fig.add_subplot(gs[1, 1], sharex=ax_piv)
            # y's bucket extremes, x at the same (sorted) indices: the path stays in order
            (self.path,) = ax_path.plot([], [], color=BLUE, lw=1.1)
            (self.start,) = ax_path.plot([], [], "o", color=GREEN, ms=5, label="start")
            (self.end,) = ax_path.plot([], [], "s", color=RED, ms=5, label="end")
            ax_path.set_aspect("equal", adjustable="datalim")
            ax_path.set_xlabel("x_b [m]")
            ax_path.set_ylabel("y_b [m]")
            _title(ax_path, "base path")
            _legend_above(ax_path, ncols=2)
            self.vel = [ax_vel.plot([], [], color=col, label=lab)[0]
                        for lab, col in zip(VEL_LABELS, (BLUE, ORANGE, GREEN), strict=True)]
            ax_vel.set_xlabel("t [s]")
            _title(ax_vel, "base velocities")
            _legend_above(ax_vel, ncols=3)
            self.piv = [ax_piv.plot([], [], color=PALETTE[i % len(PALETTE)], label=name)[0]
                        for i, name in turning]
            ax_piv.set_xlabel("t [s]")
            ax_piv.set_ylabel("[deg]")
            _title(ax_piv, "turning angles" if turning else "turning angles (none: fixed "
                   "wheels)")
            if turning:
                _legend_above(ax_piv, ncols=min(len(turning), 8))
            handles, self.tau = [], []
            styles = ("-", "--", ":", "-.")
            seen: dict[int, int] = {}
            kinds: dict[int, str] = {}
            for i, ch in actuators:
                j = seen.get(int(i), 0)
                seen[int(i)] = j + 1
                kinds.setdefault(j, ch.field)
                self.tau.append(ax_tau.plot([], [], color=PALETTE[int(i) % len(PALETTE)],
                                            lw=0.8, ls=styles[j % len(styles)])[0])
            handles = [Line2D([], [], color=PALETTE[i % len(PALETTE)], label=str(u))
                       for i, u in enumerate(units)]
            if len(kinds) > 1:
                handles += [Line2D([], [], color="#333", ls=styles[j % len(styles)],
                                   label=f.removeprefix("cur_").removeprefix("cur"))
                            for j, f in kinds.items()]
            ax_tau.set_xlabel("t [s]")
            ax_tau.set_ylabel("[N m]")
            _title(ax_tau, "actuator torques")
            _legend_above(ax_tau, handles=handles, ncols=min(len(handles), 8))
            for ax in (ax_vel, ax_piv, ax_tau):
                ax.xaxis.set_major_locator(MaxNLocator(6))
                ax.yaxis.set_major_locator(MaxNLocator(5))
        self.fig, self.axes = fig, [ax_path, ax_vel, ax_piv, ax_tau]

    def render(self, plot: LogPlot) -> bytes:
        self.set_log(plot)
        return _redraw(self.fig, self.axes)

    @property
    def changing(self) -> list[Any]:
        """The artists that change from log to log (:func:`_render_shared`)."""
        return [self.path, self.start, self.end, *self.vel, *self.piv, *self.tau]

    def set_log(self, plot: LogPlot) -> None:
        """One log's data in the lines (:meth:`render`), nothing drawn."""
        self.path.set_data(*decimate(plot.path[0][:, 0], plot.path[1][:, 0]))
        self.start.set_data([plot.start[0]], [plot.start[1]])
        self.end.set_data([plot.end[0]], [plot.end[1]])
        for d, line in enumerate(self.vel):
            line.set_data(*decimate(plot.velocity[0][:, d], plot.velocity[1][:, d]))
        for i, line in enumerate(self.piv):
            line.set_data(*decimate(plot.turning[0][:, i], np.degrees(plot.turning[1][:, i])))
        tt, tau = plot.torque
        for j, line in enumerate(self.tau):  # every actuator
            line.set_data(*decimate(tt[:, j], tau[:, j]))


def inputs(plot: LogPlot, layout: Layout) -> bytes:
    """:class:`InputsFigure` of one log (the figure built once per process and layout)."""
    fig = _inputs_figure(layout)
    return fig.render(plot)


# logs whose time spans differ by at most this share of the longest are drawn on the same axes
# limits (:func:`_render_shared`); others each on its own
SHARED_SPAN = 0.1  # (the report says "within 10 %": templates/report.html)


def fit_vs_measured_logs(logs: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray,
                                              Sequence[float] | None]]) -> list[bytes]:
    """:func:`fit_vs_measured` of each of ``logs`` ((t, b, fit, rms) each): on the same axes
    limits when their time spans agree (:data:`SHARED_SPAN`), which are then drawn once
    (:func:`_render_shared`)."""
    fig = _fit_figure()
    return _render_shared(fig, [tuple(item) for item in logs], [item[0] for item in logs])


def inputs_logs(plots: Sequence[LogPlot], layout: Layout) -> list[bytes]:
    """:func:`inputs` of each of ``plots``, as :func:`fit_vs_measured_logs` draws them."""
    fig = _inputs_figure(layout)
    return _render_shared(fig, [(plot,) for plot in plots], [plot.torque[0] for plot in plots])


def _render_shared(figure: FitFigure | InputsFigure, args: list[tuple[Any, ...]],
                   times: list[np.ndarray]) -> list[bytes]:
    """``figure`` with each log's ``args`` (of its ``set_log``). Where the logs' ``times``
    span about as long (:data:`SHARED_SPAN`), every axes gets the limits of all the logs'
    data together, the axes, ticks, grid and legends are drawn once, and each log's lines
    and texts (``figure.changing``) are drawn over a copy of that (matplotlib's blitting):
    0.03 s instead of 0.09 s a figure of the fit per DOF. Otherwise each is drawn whole
    (:func:`_redraw`), on its own data's limits."""
    spans = [float(np.ptp(t)) if np.size(t) else 0.0 for t in times]
    if len(args) < 2 or min(spans) < (1.0 - SHARED_SPAN) * max(spans):
        return [figure.render(*a) for a in args]
    fig, axes, changing = figure.fig, figure.axes, figure.changing
    with _style():
        limits = []
        for a in args:
            figure.set_log(*a)
            for ax in axes:
                ax.relim()
            limits.append([ax.dataLim.frozen() for ax in axes])
        for k, ax in enumerate(axes):
            ax.dataLim.set(Bbox.union([box[k] for box in limits]))
            ax.autoscale_view()
        fig.patch.set_facecolor("white")
        canvas = cast(FigureCanvasAgg, fig.canvas)  # every figure's (:func:`_figure`)
        for artist in changing:
            artist.set_animated(True)
        try:
            canvas.draw()  # everything but the animated artists
            background = canvas.copy_from_bbox(fig.bbox)
            out = []
            for a in args:
                figure.set_log(*a)
                canvas.restore_region(background)
                for artist in changing:
                    artist.axes.draw_artist(artist)
                out.append(_encode(canvas))
        finally:
            for artist in changing:
                artist.set_animated(False)
    return out


def warm(layout: Layout | None = None) -> None:
    """Build and draw once the figures a report redraws per log (fonts loaded, ticks laid
    out), e.g. in a drawing process while the logs are still being read."""
    fig = _fit_figure()
    with _style():
        _png(fig.fig)
    if layout is not None:
        _inputs_figure(layout)


def singular_values(sv: np.ndarray, rank: int, rcond: float) -> bytes:
    """Singular values of the column-scaled weighted stacked regressor (log scale), with the
    threshold rcond·σ_max below which a direction counts as not identifiable."""
    with _style():
        fig = _figure(10.0, 3.0, bottom=0.16, top=0.9)
        ax = fig.add_subplot()
        k = np.arange(1, len(sv) + 1)
        colors = [BLUE if j < rank else RED for j in range(len(sv))]
        positive = sv[sv > 0]
        floor = float(positive.min()) * 1e-2 if positive.size else 1e-16
        ax.bar(k, np.maximum(sv, floor), color=colors, width=0.7, alpha=0.85)
        ax.plot(k, sv, "o-", color="#333", ms=2.5, lw=0.7)
        if len(sv):
            ax.axhline(rcond * sv[0], color=RED, ls="--", lw=0.9,
                       label=f"threshold rcond·σ₁ = {rcond * sv[0]:.2g}")
            _legend_above(ax)
        ax.set_yscale("log")
        ax.yaxis.set_minor_locator(NullLocator())
        ax.yaxis.set_major_formatter(FuncFormatter(_power_of_ten))
        ax.set_xlabel("index")
        ax.set_ylabel("singular value")
        ax.set_xticks(k if len(k) <= 40 else k[:: int(np.ceil(len(k) / 40))])
        ax.set_xlim(0.3, len(sv) + 0.7)
        _title(ax, "column-scaled, weighted, stacked regressor")
        return _png(fig)


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _power_of_ten(value: float, _pos: int | None = None) -> str:
    """A log axis' tick label as plain text, 10⁻³ (matplotlib's own, $10^{-3}$, goes through
    mathtext's parser: a fifth of the figure's time)."""
    if not value > 0:
        return ""
    k = round(float(np.log10(value)))
    if abs(value / 10.0**k - 1.0) > 1e-9:
        return f"{value:.2g}"
    return "1" if k == 0 else "10" if k == 1 else f"10{str(k).translate(_SUPERSCRIPT)}"


def predicted_velocity(t: np.ndarray, measured: np.ndarray, predicted: np.ndarray,
                       fit_pct: dict[str, float] | None) -> bytes:
    """Measured base twist (grey) against the fitted model simulated forward from the first
    row under the measured torques (blue; NaN where not simulated), in the base frame."""
    labels = ("v_x [m/s]", "v_y [m/s]", "ω [rad/s]")  # base frame
    keys = ("x", "y", "theta")
    with _style():
        fig = _figure(10.0, 5.2, top=0.94, bottom=0.09, left=0.08, hspace=0.35)
        axes = [fig.add_subplot(3, 1, d + 1) for d in range(3)]
        for d, ax in enumerate(axes):
            _line(ax, t, measured[:, d], color=GREY, lw=1.2, label="measured")
            _line(ax, t, predicted[:, d], color=BLUE, lw=0.8, label="model")
            ax.set_ylabel(labels[d])
            pct = "" if fit_pct is None else f"  fit {fit_pct[keys[d]]:.1f} %"
            _title(ax, f"{keys[d]}{pct}")
        axes[0].legend(loc="upper right", fontsize=8, ncols=2)
        axes[-1].set_xlabel("t [s]")
        return _png(fig)


def residual_histograms(residuals: np.ndarray) -> bytes:
    """Histogram of the error b − A m* per DOF over all samples of all logs, with the normal
    density of the same mean and standard deviation."""
    with _style():
        fig = _figure(10.0, 2.8, left=0.02, bottom=0.17, top=0.9)
        axes = fig.subplots(1, 3, gridspec_kw={"wspace": 0.08})
        for d, ax in enumerate(axes):
            r = residuals[:, d]
            r = r[np.isfinite(r)]
            if r.size == 0:
                continue
            mu, sd = float(np.mean(r)), float(np.std(r))
            # the bulk with a margin (robust scale); outliers pile up in the end bins
            mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
            lim = max(6.0 * mad, float(np.quantile(np.abs(r - mu), 0.95)), 1e-12)
            bins = np.linspace(mu - lim, mu + lim, 81)
            counts, _ = np.histogram(np.clip(r, bins[0], bins[-1]), bins=bins, density=True)
            ax.stairs(counts, bins, fill=True, color=BLUE, alpha=0.75)  # one patch, not 80
            if sd > 0:
                x = np.linspace(bins[0], bins[-1], 200)
                ax.plot(x, np.exp(-0.5 * ((x - mu) / sd) ** 2) / (sd * np.sqrt(2 * np.pi)),
                        color=ORANGE, lw=1.2, label="normal, same σ")
            ax.set_xlabel(f"error {DOF_LABELS[d]} [{DOF_UNITS[d]}]")
            _title(ax, f"{DOF_LABELS[d]}: mean {mu:.3g}, σ {sd:.3g}")
            ax.set_yticks([])
            if d == 0:
                ax.legend(loc="upper left")
        return _png(fig)


def autocorrelation(t: np.ndarray, err: np.ndarray, max_lag: float) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """Lags [s] (L,) and the autocorrelation (L, 3) per DOF of one log's residual rows ``err``
    (r, 3) at the uniformly spaced times ``t`` (the kept rows), up to ``max_lag`` seconds
    (FFT of the zero-padded series; normalised by the overlap, 1 at lag 0)."""
    n = len(t)
    if n < 3:
        return np.zeros(0), np.zeros((0, 3))
    step = float(np.median(np.diff(t)))
    lags = min(n - 1, max(int(max_lag / step), 1)) + 1
    r = err - err.mean(axis=0)
    f = np.fft.rfft(r, 2 * n, axis=0)
    acf = np.fft.irfft(np.abs(f) ** 2, axis=0)[:lags] / (n - np.arange(lags))[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        acf = np.where(acf[:1] > 0, acf / acf[:1], 0.0)
    return step * np.arange(lags), acf


def residual_autocorrelation(series: Sequence[tuple[np.ndarray, np.ndarray]], stretch: float,
                             max_lag: float = 4.0) -> bytes:
    """The residual's autocorrelation per DOF against the lag, one line per log (``series``:
    its kept rows' times and errors), with the length of the jackknife's stretches: a residual
    correlated beyond the rows' LOESS span is model error, not sensor noise."""
    with _style():
        fig = _figure(10.0, 2.6, left=0.06, bottom=0.2, top=0.88)
        axes = fig.subplots(1, 3, sharey=True, gridspec_kw={"wspace": 0.06})
        for t, err in series:
            lags, acf = autocorrelation(t, err, max_lag)
            for d, ax in enumerate(axes):
                ax.plot(lags, acf[:, d], color=BLUE, lw=0.9, alpha=0.7)
        for d, ax in enumerate(axes):
            ax.axhline(0.0, color="0.6", lw=0.6)
            ax.axvline(stretch, color=ORANGE, lw=1.0, ls="--",
                       label=f"jackknife stretch {stretch:g} s")
            ax.set_xlabel("lag [s]")
            _title(ax, f"{DOF_LABELS[d]}")
            if d == 0:
                ax.set_ylabel("autocorrelation")
                ax.legend(loc="upper right")
        return _png(fig)


def residual_vs_velocity(velocity: np.ndarray, residuals: np.ndarray, bins: int = 41) -> bytes:
    """Per DOF the error against the corresponding base velocity: a thinned scatter of the
    samples and the mean error in velocity bins (over all samples). Unmodelled friction shows
    as a step or slope through zero velocity."""
    with _style():
        fig = _figure(10.0, 3.0, left=0.07, bottom=0.16, top=0.95)
        axes = fig.subplots(1, 3, gridspec_kw={"wspace": 0.32})
        for d, ax in enumerate(axes):
            v, r = velocity[:, d], residuals[:, d]
            ok = np.isfinite(v) & np.isfinite(r)
            v, r = v[ok], r[ok]
            if v.size == 0:
                continue
            pick = subsample(v.size, MAX_POINTS, seed=d)
            ax.plot(v[pick], r[pick], ".", ms=1.6, color=BLUE, alpha=0.35, rasterized=True)
            lo, hi = np.quantile(v, [0.002, 0.998])
            if hi > lo:
                edges = np.linspace(lo, hi, bins + 1)
                which = np.clip(np.digitize(v, edges) - 1, 0, bins - 1)
                inside = (v >= lo) & (v <= hi)
                count = np.bincount(which[inside], minlength=bins)
                total = np.bincount(which[inside], weights=r[inside], minlength=bins)
                with np.errstate(invalid="ignore", divide="ignore"):
                    mean = np.where(count >= 5, total / count, np.nan)
                centre = 0.5 * (edges[:-1] + edges[1:])
                ax.plot(centre, mean, "-", color=ORANGE, lw=1.6, label="binned mean")
            ax.axhline(0.0, color="#444", lw=0.6)
            ax.axvline(0.0, color="#444", lw=0.6)
            ylim = max(float(np.quantile(np.abs(r), 0.99)), 1e-12) * 1.5
            ax.set_ylim(-ylim, ylim)
            ax.set_xlabel(VEL_LABELS[d])
            ax.set_ylabel(f"error {DOF_LABELS[d]} [{DOF_UNITS[d]}]")
            if d == 0:
                ax.legend(loc="upper left")
        return _png(fig)


def observer(t: np.ndarray, f_hat: np.ndarray, force_threshold: float,
             torque_threshold: float) -> bytes:
    """The disturbance observer's view (thesis Fig. 16): low-passed F̂_bx, F̂_by and T̂_bz over
    time with the ±thresholds."""
    with _style():
        fig = _figure(10.0, 5.2, top=0.97, bottom=0.09)
        axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"hspace": 0.15})
        labels = ("F̂_bx [N]", "F̂_by [N]", "T̂_bz [N m]")
        for d, ax in enumerate(axes):
            thr = force_threshold if d < 2 else torque_threshold
            _line(ax, t, f_hat[:, d], color=(BLUE, ORANGE, GREEN)[d], lw=0.9)
            for s in (1, -1):
                ax.axhline(s * thr, color=RED, ls="--", lw=0.9)
            ax.set_ylabel(labels[d])
            peak = float(np.max(np.abs(f_hat[:, d]))) if len(f_hat) else 0.0
            ax.set_ylim(-1.15 * max(thr, peak), 1.15 * max(thr, peak))
            ax.text(0.995, 0.95, f"threshold ±{thr:g}", transform=ax.transAxes, ha="right",
                    va="top", fontsize=7.5, color=RED)
        axes[-1].set_xlabel("t [s]")
        return _png(fig)
