"""The HTML fit report: sections, figures, escaping, no network, the report command, Chromium."""

from __future__ import annotations

import base64
import dataclasses
import multiprocessing
import os
import shutil
import subprocess
from html.parser import HTMLParser

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid.cli.main import main
from ropod_sysid.errors import InputError
from ropod_sysid.fit import fit_logs
from ropod_sysid.io import write_log
from ropod_sysid.io.paramfile import ParameterFile, read_parameter_file, write_parameter_file
from ropod_sysid.params import thesis_fixed_masses
from ropod_sysid.platform import ropod_platform, save_platform
from ropod_sysid.report import render_fit_report, result_from_parameter_file, write_fit_report
from ropod_sysid.report.figures import MAX_POINTS, decimate
from ropod_sysid.simulate import Setpoints, simulate

PIVOTS = np.array([[0.23, 0.20], [-0.19, 0.22], [-0.21, -0.18], [0.20, -0.23]])
SECTIONS = ("summary", "fit", "parameters", "singular-values", "residuals", "inputs")
EVIL = "<script>alert(1)</script>"


def setpoints(duration: float, sx: float, sw: float, phase: float) -> Setpoints:
    """Rest to rest: smooth sinusoids under a smoothstep envelope."""
    t = np.arange(0.0, duration + 0.005, 0.01)
    u0, u1 = np.clip(t / 1.2, 0, 1), np.clip((duration - 0.3 - t) / 1.2, 0, 1)
    env = u0**2 * (3 - 2 * u0) * u1**2 * (3 - 2 * u1)
    vx = sx * env * (0.5 + 0.3 * np.sin(2 * np.pi * t / 3 + phase))
    vy = sx * sw * env * 0.3 * np.sin(2 * np.pi * t / 4 + phase)
    om = sw * env * 0.8 * np.sin(2 * np.pi * t / 2.5 + phase)
    return Setpoints(t, vx, vy, om)


@pytest.fixture(scope="module")
def sim():
    """Three 6 s runs simulated together: two to fit, one to validate on."""
    platform = ropod_platform().with_positions(PIVOTS)
    params = thesis_fixed_masses(platform.unit_names)
    # 2.5 ms RK4 steps (stride 2 to the 200 Hz log): the report needs plausible runs, not
    # the 1 ms fidelity of the identification tests
    runs = simulate(platform, params, [setpoints(6.0, 1, 1, 0.0), setpoints(6.0, -1, -1, 1.0),
                                       setpoints(6.0, 1, -1, 2.0)], rate=200.0, dt=2.5e-3)
    logs = [dataclasses.replace(r.log, source=f"run{k}.csv") for k, r in enumerate(runs)]
    result = fit_logs(logs[:2], platform)
    return platform, params, logs, result


@pytest.fixture(scope="module")
def truth_file(sim) -> ParameterFile:
    platform, params, _, result = sim
    values = params.to_mapping()
    return ParameterFile(platform.name, {k: {"value": v, "std": None} for k, v in values.items()},
                         {"translation": 0.0, "rotation": 0.0}, 1.0, len(values), 0)


@pytest.fixture(scope="module")
def full_html(sim, truth_file) -> str:
    platform, _, logs, result = sim
    return render_fit_report(result, logs[:2], compare=truth_file, compare_label="truth.json",
                             validation_logs=[logs[2]])


@pytest.fixture(scope="module")
def files(tmp_path_factory, sim, truth_file):
    """Platform, logs (one with markup in its file name), parameter files on disk."""
    platform, _, logs, result = sim
    d = tmp_path_factory.mktemp("report")
    save_platform(platform, d / "platform.yaml")
    names = ["run0.csv", f"run1{EVIL.replace('/', '')}.csv", "val.csv"]
    paths = []
    for log, name in zip(logs, names, strict=True):
        write_log(log, d / name)
        paths.append(d / name)
    write_parameter_file(result.parameter_file(), d / "params.json")
    write_parameter_file(truth_file, d / "truth.json")
    return d, paths


class Page(HTMLParser):
    """Tags, attributes, ids, images and inline text of a page."""

    def __init__(self, html: str) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.ids: set[str] = set()
        self.styles: list[str] = []
        self.text: list[str] = []
        self._in_style = False
        self.feed(html)
        self.close()

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        if a.get("id"):
            self.ids.add(a["id"])
        self._in_style = tag == "style"

    def handle_endtag(self, tag):
        if tag == "style":
            self._in_style = False

    def handle_data(self, data):
        (self.styles if self._in_style else self.text).append(data)

    def all(self, tag: str) -> list[dict[str, str | None]]:
        return [a for t, a in self.tags if t == tag]


def check_self_contained(page: Page) -> None:
    """Nothing on the page loads anything over the network, and there is no script."""
    assert not page.all("script"), "the report needs no JavaScript"
    assert not page.all("link"), "no external stylesheets"
    for tag in ("iframe", "object", "embed", "base"):
        assert not page.all(tag)
    for tag, attrs in page.tags:
        for name, value in attrs.items():
            assert not name.startswith("on"), (tag, name)  # no event handlers
            if name in ("src", "href", "srcset", "action", "poster", "data", "xlink:href"):
                v = (value or "").strip().lower()
                assert not v.startswith(("http:", "https:", "//", "ftp:")), (tag, name, v)
                if name == "src":
                    assert v.startswith("data:image/"), (tag, v[:40])
                if name == "href":
                    assert v.startswith("#"), (tag, v)  # in-page anchors only
            if name == "style":
                assert "url(" not in (value or "").lower()
    css = "".join(page.styles).lower()
    assert "@import" not in css and "url(" not in css and "@font-face" not in css


def check_images(page: Page, expected: int) -> None:
    imgs = page.all("img")
    assert len(imgs) + len(page.all("svg")) == expected
    for img in imgs:
        src = img["src"] or ""
        assert src.startswith("data:image/png;base64,")
        png = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
        assert img.get("alt")


# ---------------------------------------------------------------------------------------------
# the page


def test_every_section_and_figure(full_html):
    page = Page(full_html)
    for sid in (*SECTIONS, "validation", "null-space", "parameter-table"):
        assert sid in page.ids, sid
    # per fit log: Fig. 13 and inputs; the first log's predicted velocity, singular values,
    # histograms, residual vs velocity, residual autocorrelation (issue 14); one observer view
    # per validation log; the parameter correlation (issue 17) is a table
    check_images(page, 2 * 2 + 5 + 1)
    assert len(page.all("figcaption")) == 11
    text = " ".join(page.text)
    for phrase in ("RMS translation", "RMS rotation", "Condition number", "Input delay",
                   "Friction model", "per-wheel", "Smoother span", "Rank",
                   "Residual autocorrelation", "jackknife over 6 stretches of 2 s"):
        assert phrase in text, phrase


def test_correlation_table_is_the_fits_covariance(sim, full_html):
    """One row and column per parameter; each determined cell's r is cov_ij / √(cov_ii cov_jj)
    of the fit, coloured on the blue–white–red scale; |r| ≥ 0.9 off the diagonal written."""
    _, _, _, result = sim
    sol = result.solution
    table = full_html.split('id="correlation"', 1)[1].split("</table>", 1)[0]
    rows = table.split("<tbody>", 1)[1].split("<tr>")[1:]
    assert len(rows) == len(sol.names)
    cov = sol.covariance
    sd = np.sqrt(np.where(np.diag(cov) > 0, np.diag(cov), np.nan))
    expect = cov / np.outer(sd, sd)
    for i, row in enumerate(rows):
        cells = row.split("<td ")[1:]
        assert len(cells) == len(sol.names)
        for j, cell in enumerate(cells):
            if np.isnan(expect[i, j]):
                assert "data-r" not in cell and "background:#dddddd" in cell
                continue
            r = float(cell.split('data-r="', 1)[1].split('"', 1)[0])
            assert r == pytest.approx(expect[i, j], abs=6e-5)
            written = cell.split(">", 1)[1].split("</td>", 1)[0]
            assert bool(written) == (i != j and abs(expect[i, j]) >= 0.9), (i, j, written)
    assert any("data-r" in c for c in rows[0].split("<td ")[1:])


def test_correlation_colours_and_undetermined_cells():
    from ropod_sysid.report.correlation import colours, correlation, correlation_table

    assert list(colours(np.array([-1.0, 0.0, 1.0, np.nan]))) == [
        "#2166ac", "#f7f7f7", "#b2182b", "#dddddd"]
    cov = np.array([[4.0, -3.8, 0.0], [-3.8, 4.0, 0.0], [0.0, 0.0, 0.0]])
    r = correlation(cov, 3)
    assert r[0, 1] == pytest.approx(-0.95) and np.isnan(r[2]).all()
    assert np.isnan(correlation(np.zeros((0, 0)), 2)).all()  # no covariance: nothing shown
    table = correlation_table(["a", "b", "<c>"], cov)
    assert [c["text"] for c in table["rows"][0]["cells"]] == ["", "-.95", ""]
    assert table["rows"][2]["cells"][2]["title"] == "<c> – <c>: not determined"


def test_self_contained(full_html):
    check_self_contained(Page(full_html))
    assert "<script" not in full_html.lower()


def test_summary_numbers_are_the_fit(sim, full_html):
    _, _, _, result = sim
    text = " ".join(Page(full_html).text)
    assert f"{result.rms['translation']:.4g}" in text
    assert f"{result.rms['rotation']:.4g}" in text
    assert f"{result.solution.rank} of {len(result.solution.names)} free" in text


def test_compare_table_side_by_side(sim, full_html):
    _, params, _, result = sim
    page = Page(full_html)
    # the table's rows: one per parameter, with the comparison's value and the difference
    body = full_html.split('id="parameter-table"', 1)[1].split("</table>", 1)[0]
    rows = body.split("<tr>")[2:]  # header row first
    assert len(rows) == len(result.names)
    assert "truth.json" in " ".join(page.text)
    m_b = next(r for r in rows if ">m_b<" in r)
    assert ">35.1<" in m_b  # the truth's value
    cells = Page(m_b).text
    diff = result.solution.values[0] - 35.1
    assert any(c.replace("−", "-") == f"{diff:.3g}" for c in cells), cells


def test_log_text_is_escaped_and_null_space_shown(sim):
    platform, _, logs, _ = sim
    evil = [dataclasses.replace(logs[0], source=EVIL,
                                notes=['<img src="http://x/y.png" onerror="alert(2)">'])]
    result = fit_logs(evil, platform)
    # as if the logs could not separate m_b from m_wh (a rank-deficient fit)
    sol = result.solution
    null = np.zeros((len(sol.names), 1))
    null[[0, 2], 0] = [0.8, -0.6]
    combination = np.zeros(len(sol.names), dtype=bool)
    combination[[0, 2]] = True
    result.solution = dataclasses.replace(
        sol, rank=len(sol.names) - 1, null_space=null, combination=combination,
        condition_number=float("inf"),
        combinations={"m_b": "m_b +0.75·m_wh", "m_wh": "not identifiable alone: set to 0"})
    html = render_fit_report(result, evil, validation_logs=[
        dataclasses.replace(logs[2], source="<b onmouseover=alert(3)>v</b>")])
    assert "<script" not in html.lower()
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert '<img src="http' not in html and "<b onmouseover" not in html
    page = Page(html)
    check_self_contained(page)
    assert EVIL in " ".join(page.text)  # shown to the reader as text
    assert "rank deficient" in html
    null_items = html.split('id="null-space"', 1)[1].split("</ul>", 1)[0]
    assert null_items.count("<li") == 1 and "m_b" in null_items and "m_wh" in null_items
    assert html.count('<span class="flag combination"') == 2


def test_rebuilt_from_the_parameter_file_equals_the_fit(sim, files):
    platform, _, logs, result = sim
    d, _ = files
    pfile = read_parameter_file(d / "params.json")
    rebuilt, notes = result_from_parameter_file(platform, logs[:2], pfile)
    assert notes == []
    np.testing.assert_allclose(rebuilt.solution.values, result.solution.values, rtol=1e-12)
    np.testing.assert_allclose(rebuilt.solution.std, result.solution.std, rtol=1e-12)
    for k in ("translation", "rotation"):
        assert rebuilt.rms[k] == pytest.approx(result.rms[k], rel=1e-9)
    assert rebuilt.solution.rank == result.solution.rank
    assert rebuilt.solution.condition_number == pytest.approx(result.solution.condition_number)
    np.testing.assert_allclose(rebuilt.solution.singular_values,
                               result.solution.singular_values, rtol=1e-9)
    # on other logs: the file's values, the residual of those logs, and a note saying so
    other, notes = result_from_parameter_file(platform, logs[2:], pfile)
    np.testing.assert_allclose(other.solution.values, result.solution.values, rtol=1e-12)
    assert any("on these logs" in n for n in notes), notes


def test_written_atomically_without_compare_or_validation(sim, tmp_path):
    platform, _, logs, result = sim
    out = tmp_path / "r.html"
    with pytest.raises(InputError, match="no such parameter file"):
        write_fit_report(result, logs[:2], out, compare=tmp_path / "missing.json")
    assert list(tmp_path.iterdir()) == []  # not even a temporary file
    write_fit_report(result, logs[:2], out)
    assert out.stat().st_mode & 0o044  # a document to share, not a 0600 temporary file
    assert [p.name for p in tmp_path.iterdir()] == ["r.html"]
    html = out.read_text(encoding="utf-8")
    page = Page(html)
    assert "validation" not in page.ids
    assert all(s in page.ids for s in SECTIONS)
    check_self_contained(page)
    check_images(page, 2 * 2 + 5)  # + autocorrelation, prediction
    assert "Δ/σ" not in html


def test_decimation_keeps_peaks_and_bounds_points():
    t = np.linspace(0.0, 100.0, 50_001)
    y = np.sin(t)
    y[12_345] = 50.0  # one spike in a long log
    xd, yd = decimate(t, y)
    assert len(xd) <= MAX_POINTS and np.all(np.diff(xd) >= 0)
    assert yd.max() == 50.0 and yd.min() == pytest.approx(-1.0, abs=1e-3)
    xs, ys = decimate(t, np.column_stack([y, -y]))
    assert xs.shape == ys.shape and ys.shape[1] == 2 and ys[:, 1].min() == -50.0
    short = np.arange(10.0)
    assert decimate(short, short)[0] is short


# ---------------------------------------------------------------------------------------------
# the commands


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_report_command(files):
    d, (log0, log1, val) = files
    out = d / "out" / "report.html"
    r = run("report", log0, log1, "--platform", d / "platform.yaml", "--params",
            d / "params.json", "--out", out, "--compare", d / "truth.json", "--validate", val,
            "--quiet")
    assert r.exit_code == 0, r.output
    html = out.read_text(encoding="utf-8")
    page = Page(html)
    check_self_contained(page)
    check_images(page, 2 * 2 + 5 + 1)  # + autocorrelation, prediction, observer
    assert {*SECTIONS, "validation"} <= page.ids
    assert "<script" not in html.lower()  # the log's file name holds <script>
    assert "&lt;script&gt;alert(1)&lt;script&gt;" in html
    assert "truth.json" in html and "params.json" in html


def test_fit_with_report(files):
    d, (log0, log1, val) = files
    out = d / "fit-report.html"
    r = run("fit", log0, log1, "--platform", d / "platform.yaml", "--out", d / "p2.json",
            "--report", out, "--compare", d / "truth.json", "--validate", val, "--quiet")
    assert r.exit_code == 0, r.output
    page = Page(out.read_text(encoding="utf-8"))
    assert {*SECTIONS, "validation"} <= page.ids
    check_images(page, 2 * 2 + 5 + 1)  # two logs fitted (a 6 s log alone is too short)
    assert "truth.json" in " ".join(page.text)


@pytest.mark.parametrize("case", ["missing-params", "foreign-params", "bad-log", "bad-compare",
                                  "bad-span", "out-is-dir"])
def test_report_bad_input(files, tmp_path, case):
    d, (log0, log1, _) = files
    out = tmp_path / "report.html"
    args = [log0, "--platform", d / "platform.yaml", "--params", d / "params.json"]
    if case == "missing-params":
        args[-1] = tmp_path / "nope.json"
    elif case == "foreign-params":
        p = tmp_path / "foreign.json"
        p.write_text('{"platform": "x", "parameters": {"m_b": {"value": 1, "std": null}, '
                     '"warp_drive": {"value": 2, "std": null}}, "rms": {"translation": 1, '
                     '"rotation": 1}, "condition_number": 1, "rank": 1, "samples": 1}')
        args[-1] = p
    elif case == "bad-log":
        bad = tmp_path / "bad.csv"
        bad.write_text("t,delta_1\n0,0\n")
        args[0] = bad
    elif case == "bad-compare":
        args += ["--compare", tmp_path / "nope.json"]
    elif case == "bad-span":
        args += ["--span", "-3"]
    elif case == "out-is-dir":
        out = tmp_path
    r = run("report", *args, "--out", out)
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), r.output
    if case != "out-is-dir":
        assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".report.html")]


# ---------------------------------------------------------------------------------------------
# a real browser


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None


@pytest.mark.skipif(chromium() is None,
                    reason="chromium is not installed (CI installs it: apt-get install chromium)")
def test_chromium_renders_the_report(full_html, tmp_path):
    import matplotlib.image

    page = tmp_path / "report.html"
    page.write_text(full_html, encoding="utf-8")
    shot = tmp_path / "shot.png"
    cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", "--hide-scrollbars", f"--user-data-dir={tmp_path / 'profile'}",
           f"--screenshot={shot}", "--window-size=1200,2000", page.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert shot.exists(), proc.stderr[-2000:]
    img = matplotlib.image.imread(shot)
    assert img.shape[:2] == (2000, 1200)
    rgb = np.round(img[..., :3] * 255).astype(np.uint8).reshape(-1, 3)
    colours = np.unique(rgb[:, 0].astype(np.uint32) << 16 | rgb[:, 1].astype(np.uint32) << 8
                        | rgb[:, 2])
    assert len(colours) > 200, len(colours)  # text, tables and plotted figures, not a blank page
    assert img[..., :3].std() > 0.05
    # the dark header band and a figure below it: the page is laid out, not a plain text dump
    assert img[30, :, :3].mean() < 0.4
    assert img[1000:2000, :, :3].std() > 0.05


def test_compare_accepts_a_flat_truth_mapping(sim, tmp_path):
    """A simulation's truth (name: value) is shown beside the fit like a parameter file."""
    import json

    platform, params, logs, result = sim
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps(params.to_mapping()))
    html = render_fit_report(result, logs[:2], compare=truth)
    body = html.split('id="parameter-table"', 1)[1].split("</table>", 1)[0]
    m_b = next(r for r in body.split("<tr>")[2:] if ">m_b<" in r)
    assert ">35.1<" in m_b and "truth.json" in html


def test_report_command_compares_with_a_flat_truth_mapping(files, tmp_path):
    """``report --compare`` takes a simulation's flat truth (name: value), as ``fit`` does."""
    import json

    d, (log0, log1, _) = files
    values = {k: v["value"] for k, v in
              json.loads((d / "params.json").read_text())["parameters"].items()}
    flat = tmp_path / "flat_truth.json"
    flat.write_text(json.dumps(values))
    out = tmp_path / "r.html"
    r = run("report", log0, log1, "--platform", d / "platform.yaml", "--params",
            d / "params.json", "--out", out, "--compare", flat, "--quiet")
    assert r.exit_code == 0, r.output
    assert "flat_truth.json" in out.read_text(encoding="utf-8")


def test_figures_drawn_by_workers_are_those_drawn_here(sim):
    """A figure drawn by two forked workers (the default on two CPUs) and in this process is
    the same bytes (so is the report); a figure that fails in a worker fails with the
    worker's error, and the workers end."""
    from ropod_sysid.report import painter

    platform = sim[0]
    t = np.linspace(0.0, 5.0, 500)
    b = np.column_stack([np.sin(t), np.cos(t), 0.1 * t])
    logs = [(t, b, 0.9 * b, None), (t, -b, -0.8 * b, None)]
    with painter.Painter(1) as one:
        here = one.draw("fit_vs_measured", t, b, 0.9 * b).uri()
        hist = one.draw("residual_histograms", b).uri()
        each = [d.uri() for d in one.draw_each("fit_vs_measured_logs", 2, logs)]
    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork here: every figure is drawn in this process")
    with painter.Painter(2, platform.layout) as p:
        assert p.draw("fit_vs_measured", t, b, 0.9 * b).uri() == here
        assert p.draw("residual_histograms", b).uri() == hist
        assert [d.uri() for d in p.draw_each("fit_vs_measured_logs", 2, logs)] == each
        drawn = p.draw("residual_histograms", "not an array")
        with pytest.raises(Exception, match="not an array|index|dimension|shape|str"):
            drawn.uri()
        pool = p.pool
    assert p.pool is None and pool is not None
    with pytest.raises(ValueError, match="workers 0: at least 1"):
        painter.Painter(0)


def test_the_drawers_follow_the_environment(monkeypatch):
    """``ROPOD_SYSID_DRAWERS`` sets how many processes draw (1: in-process); nonsense is
    ignored."""
    from ropod_sysid.report import painter

    monkeypatch.setenv(painter.DRAWERS_ENV, "1")
    assert painter.default_workers() == 1
    monkeypatch.setenv(painter.DRAWERS_ENV, "3")
    assert painter.default_workers() == 3
    monkeypatch.setenv(painter.DRAWERS_ENV, "many")
    assert painter.default_workers() in (1, 2)


def test_logs_streamed_side_by_side_give_the_same_result(off_square, runs_off_square, tmp_path):
    """result_from_parameter_file with two threads equals one thread's, log for log."""
    logs = [r.log for r in runs_off_square]
    path = tmp_path / "params.json"
    write_parameter_file(fit_logs(logs, off_square).parameter_file(), path)
    pfile = read_parameter_file(path)
    one, _ = result_from_parameter_file(off_square, logs, pfile, threads=1)
    two, _ = result_from_parameter_file(off_square, logs, pfile, threads=2)
    assert [lf.source for lf in two.logs] == [lf.source for lf in one.logs]
    np.testing.assert_array_equal(two.solution.singular_values, one.solution.singular_values)
    for a, b in zip(one.logs, two.logs, strict=True):
        assert a.rms == b.rms
        np.testing.assert_array_equal(a.plot.b_rows, b.plot.b_rows)


def test_logs_of_one_length_share_their_axes_and_are_drawn_once():
    """The per-log figures of logs about as long are drawn on the limits of all their data,
    the axes once and each log's lines over them (blitting): each log's image is the full
    drawing of that log on those limits but where its lines cross the axes' own lines (0.01 %
    of the pixels); logs of very different lengths are each drawn on their own."""
    import io

    from PIL import Image

    from ropod_sysid.report import figures

    def pixels(png: bytes) -> np.ndarray:
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    t = np.linspace(0.0, 20.0, 3000)
    b = np.column_stack([40 * np.sin(t), 30 * np.cos(0.7 * t), 5 * np.sin(0.3 * t)])
    logs = [(t, b, 0.95 * b, None), (t * 1.05, -2 * b, -1.9 * b, None)]
    shared = figures.fit_vs_measured_logs(logs)
    assert len(shared) == 2 and shared[0] != shared[1]
    fig = figures._BUILT[figures.FitFigure]
    limits = [(ax.get_xlim(), ax.get_ylim()) for ax in fig.axes]
    assert limits[0][1][1] > 2 * 40 * 0.99  # the second log's range, in the first's image
    for log, png in zip(logs, shared, strict=True):
        fig.set_log(*log)
        with figures._style():
            for ax, (x, y) in zip(fig.axes, limits, strict=True):
                ax.set_xlim(x)
                ax.set_ylim(y)
            whole = pixels(figures._png(fig.fig))
        differ = np.any(whole != pixels(png), axis=-1).mean()
        assert differ < 0.002, differ  # (without the lines: 2.3 %)
    # a 2 s log beside the 20 s one: each on its own, as fit_vs_measured draws it
    short = (t[:300], b[:300], 0.95 * b[:300], None)
    alone = figures.fit_vs_measured_logs([logs[0], short])
    assert alone == [figures.fit_vs_measured(*logs[0]), figures.fit_vs_measured(*short)]


def test_a_bad_log_stops_the_logs_streamed_side_by_side(off_square, runs_off_square,
                                                        monkeypatch, tmp_path):
    """With logs streamed two at a time, a log's error is raised as soon as it comes: the
    logs not yet begun are not read (the one beside it may be, and ends)."""
    import time

    from ropod_sysid.report import html

    logs = [dataclasses.replace(r.log, source=f"log{k}") for k, r in enumerate(runs_off_square)]
    path = tmp_path / "params.json"
    write_parameter_file(fit_logs(logs, off_square).parameter_file(), path)
    started = []

    def pieces(log, *args, **kwargs):
        started.append(log.source)
        if log.source == "log0":
            raise InputError("log0: bad")
        time.sleep(0.3)
        return []

    monkeypatch.setattr(html, "stream_pieces", pieces)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="log0: bad"):
        result_from_parameter_file(off_square, logs, read_parameter_file(path), threads=2)
    assert time.perf_counter() - t0 < 0.25
    time.sleep(0.4)  # a log begun beside the bad one ends; no other begins
    assert started[0] == "log0" and set(started) <= {"log0", "log1"}, started
