"""Stops and restarts (issue 14 item 3): a log in which the robot stops, holds and starts again
fits as its moving pieces fitted as separate logs (benchmarks/stops.py on a 30 s run)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ropod_sysid.fit import fit_logs
from ropod_sysid.io import Log
from ropod_sysid.platform import Platform
from ropod_sysid.simulate import Setpoints, simulate


def smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def forward_ends(duration: float) -> Setpoints:
    """A rest-to-rest run that drives forward at both ends (the pivots trail alike where two
    copies meet) and in all three directions between."""
    t = np.arange(0.0, duration + 0.005, 0.01)
    fwd = smoothstep(t) * smoothstep(duration - 0.5 - t)
    mix = smoothstep(t - 1.5) * smoothstep(duration - 2.0 - t)
    return Setpoints(t, 0.5 * fwd + 0.3 * mix * np.sin(2 * np.pi * t / 3),
                     0.3 * mix * np.sin(2 * np.pi * t / 2),
                     0.8 * mix * np.sin(2 * np.pi * t / 2.5))


def tile(log: Log, copies: int) -> Log:
    """``copies`` repetitions of ``log`` as one log: t and the wheel angles continued, the pivot
    angles by whole turns (benchmarks/stops.py)."""
    dt = float(np.median(np.diff(log.t)))
    period = log.t[-1] - log.t[0] + dt
    shift = log.angles[-1] - log.angles[0]
    w = log.layout.wrapped
    shift[w] = 2 * np.pi * np.round(shift[w] / (2 * np.pi))
    return dataclasses.replace(
        log, t=np.concatenate([log.t + k * period for k in range(copies)]),
        angles=np.concatenate([log.angles + k * shift for k in range(copies)]),
        currents=np.concatenate([log.currents] * copies))


def cut(log: Log, start: int, stop: int | None = None) -> Log:
    return dataclasses.replace(log, t=log.t[start:stop], angles=log.angles[start:stop],
                               currents=log.currents[start:stop])


@pytest.fixture(scope="module")
def run_log(off_square: Platform, truth) -> Log:
    (run,) = simulate(off_square, truth, forward_ends(8.0), rate=200.0)
    return run.log


def test_joined_log_fits_as_its_pieces(off_square: Platform, run_log: Log) -> None:
    """Two copies of an 8 s run joined at a stop (the speed loops holding opposing currents,
    then a controller reset) give the values of the same log cut in the rest stretch and
    fitted as two logs: measured within 0.001σ of every parameter (with REST_* thresholds a
    third of the shipped ones, 7.8σ). The cut is at an even sample, so that both keep their
    rows (every 2nd sample) at the same samples: cut at the seam itself, the second piece's
    rows move by one sample, and the values by the rows' phase (up to 2.0σ of the pieces' σ
    here; docs/method.md, "The rows' torque average"). The joined log also equals its run
    fitted at both phases (the run and it without its first sample, two logs; 0.001σ)."""
    n = len(run_log.t)
    assert n % 2 == 1  # the seam is at an odd sample: the cut below is before it, in the rest
    joined = tile(run_log, 2)
    whole = fit_logs([joined], off_square).solution
    parts = fit_logs([cut(joined, 0, n - 1), cut(joined, n - 1)], off_square).solution
    np.testing.assert_array_less(np.abs(whole.values - parts.values), 0.01 * parts.std)
    # the second copy's rows are at its odd samples: the joined log is the run at both phases
    phases = fit_logs([run_log, cut(run_log, 1)], off_square).solution
    np.testing.assert_array_less(np.abs(whole.values - phases.values), 0.01 * phases.std)
