"""Shared, session-scoped simulations: simulated once, used by every test that needs a run."""

# ruff: noqa: E402 (the settings below must come before numpy and the package load)
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

# cache the rewritten test modules and the package's bytecode (in the git-ignored __pycache__)
# even where PYTHONDONTWRITEBYTECODE is set: every test worker collects every file, which
# took 8.3 s compiling them anew against 4.6 s cached (measured on this suite)
sys.dont_write_bytecode = False

if os.environ.get("PYTEST_XDIST_WORKER"):  # every CPU has a test worker already: one BLAS
    # thread each, set before numpy loads (two spinning pools per core made the leg fits three
    # times slower), and reports draw and optimize evaluates in-process (Painter(2) and
    # ForkedMap(…, 2) are tested)
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")
    os.environ.setdefault("ROPOD_SYSID_DRAWERS", "1")
    os.environ.setdefault("ROPOD_SYSID_PROCESSES", "1")

import numpy as np
import pytest

from ropod_sysid.io import Log, read_log
from ropod_sysid.params import Parameters, thesis_fixed_masses
from ropod_sysid.platform import Platform, load_platform, ropod_platform
from ropod_sysid.simulate import Setpoints, SimResult, record, simulate

DATASETS = Path(__file__).resolve().parent.parent / "datasets"

# the first calls of the compiled simulator's loop: compile it on an empty numba cache, without
# constraint rows (the ropod) and with (steered wheels: a specialization of its own)
WARM_UP = """
import numpy as np
from ropod_sysid.params import thesis_fixed_masses, typical_parameters
from ropod_sysid.platform import load_platform, ropod_platform
from ropod_sysid.simulate import Setpoints, simulate
pf = ropod_platform()
t = np.array([0.0, 0.05])
sp = Setpoints(t, 0.1 + 0 * t, 0 * t, 0 * t)
simulate(pf, thesis_fixed_masses(pf.unit_names), sp, engine="numba")
pf = load_platform("datasets/steered/platform.yaml")
simulate(pf, typical_parameters(pf, 93.0, 4.51), sp, engine="numba")
"""
_WARM_UP = pytest.StashKey[subprocess.Popen]()  # the process running WARM_UP


_CONFIG: pytest.Config | None = None


def pytest_configure(config: pytest.Config) -> None:
    """With test workers, the controller (idle while they test) starts a process that compiles
    the simulator's loop at once: on a clean clone (no numba cache yet) the workers would each
    compile it, at the same time, about 11 s each (and its specialization for steered wheels,
    with constraint rows, after it). A worker that needs the loop before the cache is written
    waits for it (:func:`ropod_sysid.simulate_jit.first_compile`), then loads it; until then
    the workers collect and run other tests. On a warm cache it only loads it."""
    global _CONFIG
    _CONFIG = config
    if os.environ.get("PYTEST_XDIST_WORKER") or not getattr(config.option, "numprocesses", 0):
        return
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    config.stash[_WARM_UP] = subprocess.Popen(
        [sys.executable, "-c", WARM_UP], cwd=Path(__file__).resolve().parent.parent, env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def pytest_unconfigure(config: pytest.Config) -> None:
    """Stop the compile of :func:`pytest_configure` if the tests ended before it."""
    proc = config.stash.get(_WARM_UP, None)
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.wait()


# Test files in the order the workers take them: longest first (the files' seconds in
# tests/durations.json), so that no long file is left for one worker at the end while the other
# idles. `ROPOD_TEST_DURATIONS=write python -m pytest` measures and rewrites the table.
DURATIONS = Path(__file__).resolve().parent / "durations.json"
_SPENT = pytest.StashKey[dict[str, float]]()  # seconds per test file, summed on the controller


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0].rsplit("/", 1)[-1]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Order the files longest first (stable: the tests of a file keep their order). A file
    missing from the table (new) goes first: it may be long, and a short one first costs
    nothing. Used with ``--no-loadscope-reorder``, which keeps this order."""
    try:
        seconds = json.loads(DURATIONS.read_text())
    except (OSError, ValueError):
        return
    items.sort(key=lambda item: -seconds.get(_file_of(item.nodeid), float("inf")))


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Sum each file's setup, call and teardown seconds (for ``ROPOD_TEST_DURATIONS=write``)."""
    if os.environ.get("ROPOD_TEST_DURATIONS") != "write" or _CONFIG is None:
        return
    spent = _CONFIG.stash.setdefault(_SPENT, {})
    name = _file_of(report.nodeid)
    spent[name] = spent.get(name, 0.0) + report.duration


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Write the files' seconds to :data:`DURATIONS` (on the controller, after a whole run)."""
    spent = session.config.stash.get(_SPENT, None)
    if spent and not os.environ.get("PYTEST_XDIST_WORKER"):
        table = {k: round(v, 1) for k, v in sorted(spent.items(), key=lambda kv: -kv[1])}
        DURATIONS.write_text(json.dumps(table, indent=1) + "\n")


def shipped(name: str) -> tuple[Platform, Parameters, list[Log]]:
    """A shipped dataset ``datasets/<name>``: its platform, truth and logs (in name order)."""
    folder = DATASETS / name
    platform = load_platform(folder / "platform.yaml")
    truth = Parameters(json.loads((folder / "truth.json").read_text()))
    return platform, truth, [read_log(p, platform) for p in sorted(folder.glob("*.csv.gz"))]


# attachment points moved off the symmetric square by 1–3 cm (thesis Sec. VI-C)
OFF_SQUARE = np.array([[0.23, 0.20], [-0.19, 0.22], [-0.21, -0.18], [0.20, -0.23]])


def smooth_setpoints(duration: float, sx: float, sw: float, dt: float = 0.01,
                     ramp: float = 1.5, rest: float = 0.5) -> Setpoints:
    """A smooth, rest-to-rest run: sinusoids under a C² smoothstep envelope.

    ``sx`` = ±1 negates the translations, ``sw`` = ±1 mirrors (the four variants of Sec. VI-A);
    the envelope rises over ``ramp`` [s], falls over ``ramp`` and rests for the last ``rest``.
    """
    t = np.arange(0.0, duration + dt / 2, dt)

    def smoothstep(u: np.ndarray) -> np.ndarray:
        u = np.clip(u, 0.0, 1.0)
        return u**3 * (10 - 15 * u + 6 * u**2)

    end = duration - rest
    env = smoothstep(t / ramp) * smoothstep((end - t) / ramp)
    vx = sx * env * (0.6 + 0.4 * np.sin(2 * np.pi * t / 6))
    vy = sx * sw * 0.3 * np.sin(2 * np.pi * t / 8) * env
    om = sw * 0.8 * np.sin(2 * np.pi * t / 5) * env
    return Setpoints(t, vx, vy, om)


def four_variants(duration: float, ramp: float = 1.5, rest: float = 0.5) -> list[Setpoints]:
    return [smooth_setpoints(duration, sx, sw, ramp=ramp, rest=rest)
            for sx, sw in ((1, 1), (1, -1), (-1, 1), (-1, -1))]


@pytest.fixture(scope="session")
def off_square() -> Platform:
    return ropod_platform().with_positions(OFF_SQUARE)


@pytest.fixture(scope="session")
def truth(off_square: Platform):
    return thesis_fixed_masses(off_square.unit_names)


def subsampled(platform: Platform, res: SimResult, rate: float, sensors=None,
               rng: np.random.Generator | None = None, source: str = "<simulation>",
               ) -> SimResult:
    """A simulated run logged at a lower ``rate`` (every k-th sample), recorded again with
    ``sensors``: the same states as simulating at that rate (the integration step does not
    depend on the log rate)."""
    from ropod_sysid.simulate import Sensors

    step = int(round(1.0 / (rate * (res.log.t[1] - res.log.t[0]))))
    out = SimResult(None, res.q[::step], res.qd[::step], res.qdd[::step],  # type: ignore[arg-type]
                    res.angles[::step], res.tau[::step], res.f_b[::step], res.energy[::step])
    t = res.log.t[0] + np.arange(len(out.q)) / rate
    out.log = record(platform, out, t, sensors or Sensors(), rng or np.random.default_rng(0),
                     source)
    return out


@pytest.fixture(scope="session")
def runs_off_square_1k(off_square: Platform, truth) -> list[SimResult]:
    """Four exact 8 s variants on the off-square platform (1 kHz logs)."""
    return simulate(off_square, truth, four_variants(8.0), rate=1000.0)


@pytest.fixture(scope="session")
def runs_off_square(off_square: Platform, runs_off_square_1k: list[SimResult],
                    ) -> list[SimResult]:
    """The same runs logged at 200 Hz (equal to simulating them at rate=200)."""
    return [subsampled(off_square, r, 200.0) for r in runs_off_square_1k]


@pytest.fixture(scope="session")
def runs_off_square_noisy(off_square: Platform, runs_off_square: list[SimResult]):
    """The same runs recorded with 2¹⁴-count encoders and 30 mA current noise."""
    from ropod_sysid.simulate import Sensors

    rng = np.random.default_rng(7)
    sensors = Sensors(encoder_counts=2**14, current_noise=0.03)
    return [record(off_square, r, r.log.t, sensors, rng, f"noisy{k}")
            for k, r in enumerate(runs_off_square)]


@pytest.fixture(scope="session")
def runs_square_1k() -> list[SimResult]:
    """Four exact 6 s variants on the symmetric ropod (structurally rank deficient), 1 kHz."""
    pf = ropod_platform()
    return simulate(pf, thesis_fixed_masses(pf.unit_names), four_variants(6.0), rate=1000.0)


@pytest.fixture(scope="session")
def runs_square(runs_square_1k: list[SimResult]) -> list[SimResult]:
    """The same runs logged at 200 Hz (equal to simulating them at rate=200)."""
    return [subsampled(ropod_platform(), r, 200.0) for r in runs_square_1k]
