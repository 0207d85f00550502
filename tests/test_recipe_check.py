"""The recipe check (fit's default on logs of up to 1,000,000 samples, --recipe-check): the shift
to a second recipe folded into σ (ropod_sysid.crosscheck)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from ropod_sysid import crosscheck
from ropod_sysid.cli.main import main
from ropod_sysid.crosscheck import reference_options
from ropod_sysid.errors import InputError
from ropod_sysid.fit import FitOptions, fit_files, fit_logs
from ropod_sysid.io.csvlog import write_csv_log
from ropod_sysid.platform import save_platform
from ropod_sysid.recipe import Span
from ropod_sysid.reference import ReferenceBudget
from ropod_sysid.simulate import Setpoints, simulate
from ropod_sysid.summary import identifiability_verdict


def smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


@pytest.fixture(scope="module")
def varied_run(off_square, truth):
    """benchmarks/varied.py's run 6: 60 s, its sinusoids' periods and phases drawn (seed 7),
    logged at 200 Hz, exact. Its default fit keeps 45 % of the 29 values within 2σ."""
    duration = 60.0
    t = np.arange(0.0, duration + 0.005, 0.01)
    fwd = smoothstep(t / 2.0) * smoothstep((duration - 0.5 - t) / 2.0)
    mix = smoothstep((t - 4.0) / 3.0) * smoothstep((duration - 8.0 - t) / 3.0)
    period = np.array([5.7520525, 5.62091176, 6.40516705])
    phase = np.array([0.9705076, 1.68137602, 5.53129006])
    wave = np.sin(2.0 * np.pi * t[:, None] / period + phase)
    sp = Setpoints(t, 0.5 * fwd + 0.3 * mix * wave[:, 0], 0.3 * mix * wave[:, 1],
                   0.8 * mix * wave[:, 2])
    (run,) = simulate(off_square, truth, [sp], rate=200.0)
    return run.log


def test_reference_recipe():
    """The other smoother, the lag searched unless the hold or a delay is given; the quartic's
    span widened to its 17 samples of the slowest log."""
    ref = reference_options(FitOptions(), 0.005)
    assert (ref.span, ref.input_delay, ref.recipe_check) == (
        Span(0.1, True, 4), "auto", False)
    assert reference_options(FitOptions(), 0.01).span == Span(0.17, True, 4)
    assert reference_options(FitOptions(span=Span.parse("11")), 0.01).span == Span(17, False, 4)
    quartic = FitOptions(span=Span.parse("0.2s").with_smoother("quartic"), input_delay="auto")
    assert reference_options(quartic, 0.01).span == Span(0.2, True, 2)
    held = reference_options(FitOptions(control_period=0.001, encoder_counts=2**14), 0.005)
    assert (held.input_delay, held.control_period, held.encoder_counts) == (0.0, 0.001, 2**14)
    assert reference_options(FitOptions(input_delay=0.002), 0.005).input_delay == 0.002


def test_recipe_check_folds_the_shift_into_sigma(off_square, truth, varied_run):
    """σ² becomes σ² + Δ², Δ the shift to the reference fit; on the varied run, whose LOESS
    fit is biased beyond its σ (m_b +6.2 %), every value is then within 2σ of the truth."""
    from ropod_sysid.params import parameter_names

    ref = truth.vector(parameter_names(off_square))
    plain = fit_logs([varied_run], off_square, FitOptions(recipe_check=False))
    checked = fit_logs([varied_run], off_square, FitOptions(recipe_check=True))
    other = fit_logs([varied_run], off_square, reference_options(FitOptions(), 0.005))
    shift = plain.solution.values - other.solution.values
    np.testing.assert_array_equal(checked.solution.values, plain.solution.values)
    np.testing.assert_allclose(checked.solution.std,
                               np.sqrt(plain.solution.std**2 + shift**2), rtol=1e-12)
    assert checked.recipe_shift == dict(zip(plain.names, shift.tolist(), strict=True))

    def inside(fit) -> float:
        return float(np.mean(np.abs(fit.solution.values - ref) < 2 * fit.solution.std))

    assert inside(plain) < 0.5 and inside(checked) == 1.0
    assert abs(plain.solution.values[0] / ref[0] - 1) > 0.05  # m_b +6.2 %
    assert "(the recipe check: the recipe's bias" in checked.solution.std_basis
    extras = checked.parameter_file().extras["recipe_check"]
    assert extras["reference"] == "--smoother quartic --span 0.1s --input-delay auto"
    assert extras["shift"]["m_b"] == pytest.approx(shift[0])
    # σ wide enough for the bias: the weak combination (J_rot,w) is then weakly determined
    assert identifiability_verdict(checked).startswith("full rank but weakly determined")


def test_recipe_check_of_files_as_of_logs(tmp_path, off_square, varied_run):
    """The streamed fit (the command's) folds the same shift as the in-memory one, and the
    parameter file records it."""
    log = tmp_path / "run.csv"
    platform = tmp_path / "platform.yaml"
    write_csv_log(varied_run, log)
    save_platform(off_square, platform)
    files = fit_files([log], off_square, FitOptions(recipe_check=True))
    memory = fit_logs([varied_run], off_square, FitOptions(recipe_check=True))
    np.testing.assert_allclose(files.solution.std, memory.solution.std, rtol=1e-6)
    out = tmp_path / "params.json"
    res = CliRunner().invoke(main, ["fit", str(log), "--platform", str(platform), "--out",
                                   str(out), "--recipe-check", "--quiet"])
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert data["recipe_check"]["reference"].startswith("--smoother quartic")
    assert data["parameters"]["m_b"]["std"] == pytest.approx(files.solution.std[0], rel=1e-9)
    # the default on a log of 12,001 samples: the same check; --no-recipe-check: none
    default = tmp_path / "default.json"
    res = CliRunner().invoke(main, ["fit", str(log), "--platform", str(platform), "--out",
                                    str(default), "--quiet"])
    assert res.exit_code == 0, res.output
    assert json.loads(default.read_text()) == data
    plain = tmp_path / "plain.json"
    res = CliRunner().invoke(main, ["fit", str(log), "--platform", str(platform), "--out",
                                    str(plain), "--no-recipe-check", "--quiet"])
    assert res.exit_code == 0, res.output
    unchecked = json.loads(plain.read_text())
    assert "recipe_check" not in unchecked
    assert unchecked["parameters"]["m_b"]["std"] < data["parameters"]["m_b"]["std"]


def test_automatic_check_of_long_logs_on_windows_spread_over_them(monkeypatch, off_square,
                                                                  varied_run):
    """"auto" (the default) checks logs of up to AUTO_MAX_SAMPLES samples whole; on longer
    ones it measures the shift between the two recipes on windows spread over the logs, each
    fitted as a log of its own, and folds it into the whole fit's σ, with a note; where that
    cannot be fitted σ stays the jackknife's and the note says so and how to include the
    bias."""
    assert FitOptions().recipe_check == "auto"
    with pytest.raises(InputError, match=r"^recipe_check 'yes': use True \(--recipe-check\), "
                       r"False \(--no-recipe-check\) or 'auto' \(the default\)$"):
        FitOptions(recipe_check="yes")  # type: ignore[arg-type]
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", 10_000)  # the run: 12,001 samples
    assert crosscheck.reference_budget("auto", varied_run.n_samples) == 10_000
    assert crosscheck.reference_budget(True, varied_run.n_samples) is None
    # four windows of 2,500 samples centred at about 1/8, 3/8, 5/8 and 7/8 of the logs'
    # samples, starting on multiples of 60 samples (the rows' phase: every row step up to 10)
    assert crosscheck.reference_windows([12_001], 10_000) == [
        [(240, 2740), (3240, 5740), (6240, 8740), (9240, 11740)]]
    # across two logs a window is split; a part under a quarter of a window is left out
    assert crosscheck.reference_windows([7_000, 5_001], 10_000) == [
        [(240, 2740), (3240, 5740), (6240, 7000)], [(0, 1740), (2240, 4740)]]
    # 60 minutes at 1 kHz: 50,000 samples every 15 minutes, on multiples of 2,520
    assert crosscheck.reference_windows([3_600_060], 200_000) == [
        [(423_360, 473_360), (1_323_000, 1_373_000), (2_222_640, 2_272_640),
         (3_124_800, 3_174_800)]]
    assert crosscheck.reference_windows([3_000, 100], 10_000) == [[(0, 3000)], [(0, 100)]]
    # --split-gaps: a piece from any sample on gets its windows on multiples of the alignment
    # counted from its own start (the piece's row grid), those it reaches at all
    assert ReferenceBudget.for_logs("auto", ["log"], [12_001], lambda _: 12_001).align == 60
    budget = ReferenceBudget(200_000, {"log": crosscheck.reference_windows([3_600_060],
                                                                          200_000)[0]},
                             crosscheck.window_align(200_000))
    assert (budget.align, budget.of_piece("log", 0)) == (2520, budget.windows["log"])
    assert budget.of_piece("log", 1_000_003) == [(325_080, 372_997), (1_224_720, 1_272_637),
                                                 (2_126_880, 2_174_797)]
    assert budget.of_piece("log", 1_372_000) == [(0, 1_000), (851_760, 900_640),
                                                 (1_753_920, 1_802_800)]
    long = fit_logs([varied_run], off_square)
    plain = fit_logs([varied_run], off_square, FitOptions(recipe_check=False))
    windows = [varied_run.slice(a, b) for a, b in
               crosscheck.reference_windows([varied_run.n_samples], 10_000)[0]]
    base = fit_logs(windows, off_square, FitOptions(recipe_check=False))
    ref = fit_logs(windows, off_square, crosscheck.reference_options(FitOptions(), 0.005))
    shift = base.solution.values - ref.solution.values
    np.testing.assert_array_equal(long.solution.values, plain.solution.values)
    np.testing.assert_allclose(long.solution.std, np.hypot(plain.solution.std, shift),
                               rtol=1e-12)
    assert list(long.recipe_shift.values()) == pytest.approx(shift, rel=1e-12, abs=0)
    assert long.recipe_reference == ("--smoother quartic --span 0.1s --input-delay auto on "
                                     f"{base.samples:,} samples in 4 windows spread over the "
                                     "logs")
    assert long.logs[0].notes[-1] == (
        f"recipe check on {base.samples:,} of the logs' {long.samples:,} samples, in 4 windows "
        "spread over them (fit checks all of them by default up to 10,000): σ includes the "
        "shift between the two recipes measured there, the recipe's bias, which more data do "
        "not shrink; add --recipe-check to measure it on all of them (1.4-1.8 times the fit's "
        "time)")
    assert not any("recipe check" in note for note in plain.logs[0].notes)
    forced = fit_logs([varied_run], off_square, FitOptions(recipe_check=True))
    assert forced.recipe_shift is not None and "first" not in forced.recipe_reference
    # windows too short for the quartic's span: σ the jackknife's, and the note
    monkeypatch.setattr(crosscheck, "PREFIX_SAMPLES", 60)
    short = fit_logs([varied_run], off_square)
    np.testing.assert_array_equal(short.solution.std, plain.solution.std)
    assert short.recipe_shift is None
    assert short.logs[0].notes[-1].startswith(
        "recipe check left out: its fits of part of the logs (--smoother quartic "
        "--span 0.1s --input-delay auto) failed: ")
    left_out = crosscheck.checked(
        dataclasses.replace(plain, options=FitOptions(),
                            logs=[dataclasses.replace(lf, notes=[]) for lf in plain.logs]),
        lambda _: plain, lambda _: None, lambda _: None)
    assert left_out.logs[0].notes == [
        f"recipe check left out: the logs have {plain.samples:,} samples, more than the "
        "10,000 up to which fit runs it by default; σ is the jackknife's alone and does "
        "not include the recipe's bias (docs/accuracy.md); add --recipe-check to include it "
        "(1.4-1.8 times the fit's time)"]


def test_automatic_check_whose_reference_fails_keeps_sigma(off_square, varied_run):
    """A reference fit that cannot be made (an InputError) leaves an automatic check's σ as it
    was, with a note naming the reference; asked for with --recipe-check it is the error."""
    plain = fit_logs([varied_run], off_square, FitOptions(recipe_check=False))

    def refit(options: FitOptions):
        raise InputError("run.csv: too short for the span")

    fresh = [dataclasses.replace(lf, notes=[]) for lf in plain.logs]
    auto = crosscheck.checked(dataclasses.replace(plain, options=FitOptions(), logs=fresh),
                              refit, lambda _: None)
    np.testing.assert_array_equal(auto.solution.std, plain.solution.std)
    assert auto.logs[0].notes == [
        "recipe check left out: its reference fit (--smoother quartic --span 0.1s "
        "--input-delay auto) failed: run.csv: too short for the span"]
    with pytest.raises(InputError, match="too short for the span"):
        crosscheck.checked(dataclasses.replace(plain, options=FitOptions(recipe_check=True)),
                           refit, lambda _: None)


def test_report_of_a_checked_parameter_file(off_square, varied_run):
    """A report from the parameter file (no refit) shows its σ as what they are: the basis and
    the shift come from the file, and the verdict does not ask for --recipe-check again."""
    from ropod_sysid.report.html import result_from_parameter_file

    checked = fit_logs([varied_run], off_square, FitOptions(recipe_check=True))
    pfile = checked.parameter_file()
    result, _ = result_from_parameter_file(off_square, [varied_run], pfile)
    assert result.shown.std_basis == checked.solution.std_basis
    assert result.recipe_shift == pytest.approx(checked.recipe_shift)
    assert "--recipe-check folds" not in identifiability_verdict(result)


def test_recipe_limited_values_are_flagged(off_square, varied_run):
    """A value whose shift exceeds the jackknife's σ (2Δ² > σ², σ² = σ_j² + Δ²) is flagged
    recipe-limited in the printed table and the report, which shows each value's shift."""
    from ropod_sysid.crosscheck import recipe_limited
    from ropod_sysid.report.html import render_fit_report
    from ropod_sysid.summary import format_fit

    assert recipe_limited(1.0, 0.71) and not recipe_limited(1.0, 0.70)
    assert not recipe_limited(float("nan"), 1.0)
    checked = fit_logs([varied_run], off_square, FitOptions(recipe_check=True))
    sol = checked.solution
    limited = [n for j, n in enumerate(sol.names)
               if 2 * checked.recipe_shift[n] ** 2 > sol.std[j] ** 2]
    assert "m_b" in limited and len(limited) < len(sol.names)  # the bias of the weak combination
    table = format_fit(checked)
    flagged = [line.split()[0] for line in table.splitlines() if "recipe-limited (shift " in line]
    assert flagged == limited
    assert f"recipe-limited (shift {checked.recipe_shift['m_b']:+.3g})" in table
    html = render_fit_report(checked, [varied_run])
    assert ">recipe shift</th>" in html
    assert html.count('<span class="flag recipe-limited"') == len(limited)
    plain = fit_logs([varied_run], off_square, FitOptions(recipe_check=False))
    assert "recipe-limited" not in format_fit(plain)
    assert ">recipe shift</th>" not in render_fit_report(plain, [varied_run])


def _counting(monkeypatch, module, name: str) -> list[int]:
    """Count the calls of ``module.name`` (patched in place)."""
    calls: list[int] = []
    real = getattr(module, name)

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls


def test_reference_formed_in_the_fits_own_pass(tmp_path, monkeypatch, off_square, varied_run):
    """fit_files forms the reference beside its own triangles, reading each log once, and
    gives the same values, σ and shifts as a reference fit that reads the logs again."""
    from ropod_sysid import stream

    log = tmp_path / "run.csv"
    write_csv_log(varied_run, log)
    reads = _counting(monkeypatch, stream, "iter_chunks")
    once = fit_files([log], off_square, FitOptions(recipe_check=True))
    assert len(reads) == 1 and once.recipe_shift is not None
    real = stream.piece_triangles_checked
    monkeypatch.setattr(stream, "piece_triangles_checked",
                        lambda *a, **k: (real(*a, **k)[0], None))  # no reference: read again
    twice = fit_files([log], off_square, FitOptions(recipe_check=True))
    assert len(reads) == 3
    np.testing.assert_array_equal(once.solution.values, twice.solution.values)
    np.testing.assert_allclose(once.solution.std, twice.solution.std, rtol=1e-12, atol=0)
    assert once.recipe_shift == pytest.approx(twice.recipe_shift, rel=1e-12, abs=1e-15)
    assert once.recipe_reference == twice.recipe_reference


def test_reference_of_pieces_between_gaps(tmp_path, monkeypatch, off_square, varied_run):
    """With --split-gaps each piece gets its reference in the same pass, as read again."""
    from ropod_sysid import stream

    t = varied_run.t.copy()
    t[6000:] += 1.0  # a gap of a second at 30 s
    gapped = dataclasses.replace(varied_run, t=t)
    log = tmp_path / "gapped.csv"
    write_csv_log(gapped, log)
    options = FitOptions(recipe_check=True, split_gaps=True)
    reads = _counting(monkeypatch, stream, "iter_chunks")
    once = fit_files([log], off_square, options)
    assert len(reads) == 1 and [lf.source for lf in once.logs] == [f"{log}[1]", f"{log}[2]"]
    real = stream.piece_triangles_checked
    monkeypatch.setattr(stream, "piece_triangles_checked",
                        lambda *a, **k: (real(*a, **k)[0], None))
    twice = fit_files([log], off_square, options)
    np.testing.assert_allclose(once.solution.std, twice.solution.std, rtol=1e-12, atol=0)


def test_reference_of_long_logs_formed_in_the_pass(tmp_path, monkeypatch, off_square,
                                                   varied_run):
    """A log longer than the automatic check's limit gets its reference on part of its
    samples in the fit's own pass: a CSV log surely longer (its bytes over the longest rows)
    on PREFIX_SAMPLES in windows spread over its estimated length, one whose length is not
    known beforehand on its first AUTO_MAX_SAMPLES, cut there; each with the fit's rows over
    the same samples kept apart: one reading, the fit's values unchanged, σ widened by the
    shift measured there (as the in-memory fit of those samples gives it, to the rows at the
    windows' edges), and the note."""
    from ropod_sysid import stream
    from ropod_sysid.chunks import estimated_samples, fewest_samples

    log = tmp_path / "run.csv"
    write_csv_log(varied_run, log)
    gz = tmp_path / "run.csv.gz"
    write_csv_log(varied_run, gz)
    assert 0 < fewest_samples(log) == fewest_samples(gz) <= varied_run.n_samples
    assert fewest_samples(varied_run) == estimated_samples(varied_run) == varied_run.n_samples
    for path in (log, gz):  # (the rows' mean length: within 5 %)
        assert estimated_samples(path) == pytest.approx(varied_run.n_samples, rel=0.05)
    assert estimated_samples(tmp_path / "run.mcap") == 0
    plain = fit_files([log], off_square, FitOptions(recipe_check=False))
    reads = _counting(monkeypatch, stream, "iter_chunks")
    monkeypatch.setattr(crosscheck, "PREFIX_SAMPLES", 9_000)
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", fewest_samples(log) - 1)
    surely = fit_files([log], off_square, chunk=1000)
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", fewest_samples(log))
    found = fit_files([log], off_square, chunk=1000)
    assert len(reads) == 2
    budget = min(9_000, fewest_samples(log) - 1)
    spread = crosscheck.reference_windows([estimated_samples(log)], budget)[0]
    for fit, windows in ((surely, spread), (found, [(0, fewest_samples(log))])):
        np.testing.assert_allclose(fit.solution.values, plain.solution.values, rtol=1e-9)
        part = [varied_run.slice(a, b) for a, b in windows]
        base = fit_logs(part, off_square, FitOptions(recipe_check=False))
        ref = fit_logs(part, off_square, crosscheck.reference_options(FitOptions(), 0.005))
        shift = base.solution.values - ref.solution.values
        # (the rows at the windows' edges: the pass smooths them with the samples beyond)
        np.testing.assert_allclose(list(fit.recipe_shift.values()), shift, rtol=2e-3,
                                   atol=2e-3 * np.abs(shift).max())
        np.testing.assert_allclose(fit.solution.std, np.hypot(plain.solution.std, shift),
                                   rtol=1e-2)
    assert len(spread) == 4 and spread[0][0] > 0
    # (the fit's rows over a window: inside the reference recipe's trimmed ends)
    assert any(surely.logs[0].notes[-1].startswith(
        f"recipe check on {n:,} of the logs' {plain.samples:,} samples, in 4 windows spread "
        "over them (fit checks") for n in range(base.samples - 200, base.samples + 1))
    assert any(found.logs[0].notes[-1].startswith(
        f"recipe check on the logs' first {n:,} of {plain.samples:,} samples (fit checks")
        for n in (base.samples - 1, base.samples))  # (the rows' grid at the cut)


def test_windows_too_short_for_the_reference_in_the_pass(tmp_path, monkeypatch, off_square,
                                                         varied_run):
    """Streamed windows too short for the reference recipe's span are each left out at their
    end (their last samples reduced, :meth:`ropod_sysid.stream._Blocks.flush`), the fit's rows
    over them not kept: σ stays the jackknife's, with the note that the check was left out and
    why, as the in-memory fit of the same windows says it."""
    from ropod_sysid import reference
    from ropod_sysid.chunks import fewest_samples

    log = tmp_path / "run.csv"
    write_csv_log(varied_run, log)
    plain = fit_files([log], off_square, FitOptions(recipe_check=False))
    left_out = _counting(monkeypatch, reference.ReferenceTee, "_left_out")
    monkeypatch.setattr(crosscheck, "PREFIX_SAMPLES", 60)  # four windows of 15 samples
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", fewest_samples(log) - 1)
    short = fit_files([log], off_square, chunk=1000)
    assert len(left_out) == 4
    assert short.recipe_shift is None
    np.testing.assert_allclose(short.solution.std, plain.solution.std, rtol=1e-9)
    np.testing.assert_allclose(short.solution.values, plain.solution.values, rtol=1e-9)
    memory = fit_logs([varied_run], off_square)
    assert short.logs[0].notes[-1] == memory.logs[0].notes[-1].replace(
        varied_run.source, str(log)) == (
        "recipe check left out: its fits of part of the logs (--smoother quartic --span 0.1s "
        f"--input-delay auto) failed: {log}: 15 samples are too few for a smoother span of 21 "
        "samples (0.105 s); record a longer run or use a shorter --span")


def test_logs_of_one_fit_share_the_references_budget(tmp_path, monkeypatch, off_square,
                                                     varied_run):
    """Serially the logs of one fit draw on one budget of AUTO_MAX_SAMPLES: two logs each
    under it but together over it form the first's reference whole and the second's cut
    where the budget ends (compared with the fit's rows up to there), and the fit's σ holds
    the shift measured on those samples, with the note; each log read once."""
    from ropod_sysid import stream

    paths = [tmp_path / "a.csv", tmp_path / "b.csv"]
    write_csv_log(varied_run, paths[0])
    write_csv_log(dataclasses.replace(varied_run, currents=1.001 * varied_run.currents),
                  paths[1])  # (not a copy of the first)
    real = stream.piece_triangles_checked
    formed: list[tuple[bool, bool]] = []

    def spy(*args, **kwargs):
        out = real(*args, **kwargs)
        formed.append((out[1].partial, out[1].main[0][1] is not out[0][0][1]))
        return out

    monkeypatch.setattr(stream, "piece_triangles_checked", spy)
    reads = _counting(monkeypatch, stream, "iter_chunks")
    monkeypatch.setattr(crosscheck, "AUTO_MAX_SAMPLES", 3 * varied_run.n_samples // 2)
    fit = fit_files(paths, off_square)
    assert formed == [(False, False), (True, True)] and len(reads) == 2
    plain = fit_files(paths, off_square, FitOptions(recipe_check=False))
    assert np.all(fit.solution.std > plain.solution.std)
    assert fit.logs[0].notes[-1].startswith("recipe check on the logs' first ")
