"""The smart-wheel data layout: what a ropod (or KELO) drive records, turned into a contract log.

The EtherCAT process data of one drive unit is ``sens_ROPOD_SmartWheel_t`` (public
``ropod_global_libraries``, ``ec_structdata.h``; the same fields in KELO's ``KeloDriveAPI.h``),
logged on ``/sw_ethercat_parser/data`` as ``sensors[n]``, one entry per unit. The fields used here:

==================  =====  ==========================================================
``sensor_ts``       ns     EtherCAT clock at acquisition (uint64, arbitrary epoch)
``encoder_1/_2``    rad    motor (wheel) encoders
``encoder_pivot``   rad    pivot encoder (the drive wraps it to [−π, π))
``current_1_q/_2_q`` A     torque-producing motor currents
``voltage_bus``     V      bus voltage (a plausibility check)
==================  =====  ==========================================================

plus ``status1``, ``status2``, ``setpoint_ts``, ``velocity_1/_2/_pivot``, ``current_1_d/_2_d``,
which are carried but not used. Containers:

* MCAP, JSON encoding: ``{"sensors": [{"sensor_ts": 1700000000000000000, "encoder_1": ...}, ...]}``
  (schema ``ropod_sysid/SmartWheelData``, jsonschema);
* MCAP (or a ROS bag), the KELO driver's ``kelo_tulip/msg/KeloDrivesInput``: the same fields
  per wheel in ``wheels[]``, after a ``std_msgs/Header``;
* MCAP, ROS 2 encoding: schema ``ropod_sysid_msgs/msg/SmartWheelData`` (:data:`SW_MSGDEF`, a
  ``SmartWheelSensors[] sensors`` array; floats as float64 so that the drive's float32 values and
  simulated float64 ones both pass exactly);
* CSV: one row per frame, columns ``sensors.<k>.<field>`` (``sensors.0.sensor_ts``, …).

The layout is recognised by the topic ``/sw_ethercat_parser/data`` or a schema name containing
``SmartWheel`` (MCAP), or ``sensors.0.`` columns (CSV).

Conversion (:func:`frames_to_log`), for sensor ``k`` = unit ``k`` of the platform file, with the
unit's settings ``left_motor``, ``sign_left``, ``sign_right``, ``pivot_offset``:

* left wheel = motor ``left_motor``, right wheel = the other motor; encoder and current of each
  wheel are multiplied by that wheel's sign;
* encoders are unwrapped (those that arrive wrapped to [0, 2π) or [−π, π)); the pivot angle is the
  unwrapped pivot encoder minus ``pivot_offset``, on the branch where its first sample lies in
  [−π, π);
* ``sensor_ts`` stays integer until it becomes seconds from the first kept frame (subtracted as
  integers, then converted): t is unit 0's clock;
* corrupt frames are dropped, in this order: malformed (missing fields, too few sensors), zeroed
  (a unit with ``sensor_ts`` 0 or all values 0), non-finite values, ``voltage_bus`` outside
  ``voltage_range`` (default [10, 60] V), and non-monotonic ``sensor_ts`` (a frame not after the
  last kept one, or a forward spike that the next frame falls back from). How many were dropped,
  why and where (frame numbers and times) goes into ``Log.notes`` and a warning.

The checks and the conversion run piece by piece (:class:`ropod_sysid.io.swframes.FrameChecks`),
so an MCAP recording streams in chunks with the same samples and note as one piece.
"""

from __future__ import annotations

import csv
import json
import math
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from ropod_sysid.errors import InputError
from ropod_sysid.io.atomic import atomic_path
from ropod_sysid.io.log import Log, join_logs
from ropod_sysid.io.timebase import Gaps, check_times
from ropod_sysid.model.units import swivel
from ropod_sysid.platform import Platform

SW_TOPIC = "/sw_ethercat_parser/data"
SW_JSON_SCHEMA = "ropod_sysid/SmartWheelData"
SW_ROS2_SCHEMA = "ropod_sysid_msgs/msg/SmartWheelData"
INT_FIELDS = ("status1", "status2", "sensor_ts", "setpoint_ts")
FLOAT_FIELDS = ("encoder_1", "velocity_1", "current_1_d", "current_1_q",
                "encoder_2", "velocity_2", "current_2_d", "current_2_q",
                "encoder_pivot", "velocity_pivot", "voltage_bus")
SW_FIELDS = INT_FIELDS + FLOAT_FIELDS
REQUIRED_FLOATS = ("encoder_1", "encoder_2", "encoder_pivot", "current_1_q", "current_2_q",
                   "voltage_bus")
REQUIRED = ("sensor_ts",) + REQUIRED_FLOATS
VOLTAGE_RANGE = (10.0, 60.0)
DEFAULT_EPOCH_NS = 1_700_000_000_123_456_789
STATUS1_OK = 0x001F   # enabled 1 and 2, encoder 1, 2 and pivot OK
MIN_SAMPLES = 3
_TWO_PI = 2.0 * math.pi
_CSV_COLUMN = re.compile(r"^sensors\.(\d+)\.(\w+)$")
_UINT64_MAX = (1 << 64) - 1

SW_MSGDEF = """\
# ropod / KELO smart-wheel EtherCAT process data (sens_ROPOD_SmartWheel_t), one entry per unit.
SmartWheelSensors[] sensors
================================================================================
MSG: ropod_sysid_msgs/SmartWheelSensors
uint16 status1          # status bits (STAT1_)
uint16 status2
uint64 sensor_ts        # EtherCAT clock at sensor acquisition [ns], arbitrary epoch
uint64 setpoint_ts      # EtherCAT clock of the last setpoint [ns]
float64 encoder_1       # motor 1 encoder [rad]
float64 velocity_1      # motor 1 velocity [rad/s]
float64 current_1_d     # motor 1 direct current [A]
float64 current_1_q     # motor 1 quadrature (torque) current [A]
float64 encoder_2       # motor 2 encoder [rad]
float64 velocity_2      # motor 2 velocity [rad/s]
float64 current_2_d     # motor 2 direct current [A]
float64 current_2_q     # motor 2 quadrature (torque) current [A]
float64 encoder_pivot   # pivot encoder [rad]
float64 velocity_pivot  # pivot velocity [rad/s]
float64 voltage_bus     # bus voltage [V]
"""


KELO_SCHEMA = "kelo_tulip/msg/KeloDrivesInput"  # the KELO driver's per-wheel drive inputs


def is_smartwheel_schema(name: str) -> bool:
    """True for a schema name of the smart-wheel layout: ours, the ropod's, or the KELO
    driver's ``KeloDrivesInput`` (its ``wheels[]`` carry the same fields as ``sensors[]``)."""
    plain = name.lower().replace("_", "")
    return "smartwheel" in plain or "kelodrivesinput" in plain


def smartwheel_json_schema() -> dict[str, Any]:
    """The JSON schema of one smart-wheel message (for viewers)."""
    props: dict[str, Any] = {f: {"type": "integer", "minimum": 0} for f in INT_FIELDS}
    props |= {f: {"type": "number"} for f in FLOAT_FIELDS}
    props["sensor_ts"]["description"] = "EtherCAT clock at sensor acquisition [ns]"
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": SW_JSON_SCHEMA,
        "description": "ropod/KELO smart-wheel process data (sens_ROPOD_SmartWheel_t) per unit",
        "type": "object",
        "properties": {"sensors": {"type": "array", "items": {
            "type": "object", "properties": props, "required": list(REQUIRED)}}},
        "required": ["sensors"],
    }


# ---------------------------------------------------------------------------------------------
# raw frames → contract log


@dataclass
class SmartWheelFrames:
    """The raw frames of a smart-wheel log, as recorded (before any check).

    sensor_ts : (N, n) uint64 [ns]; values : field → (N, n) float64 for
    :data:`REQUIRED_FLOATS`; malformed : (N,) bool, frames that lacked fields or sensors.
    """

    sensor_ts: np.ndarray
    values: dict[str, np.ndarray]
    malformed: np.ndarray
    source: str = "<memory>"
    notes: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return int(self.sensor_ts.shape[0])


def _ts_value(v: Any) -> int:
    if isinstance(v, bool):
        raise TypeError("boolean timestamp")
    if isinstance(v, int):
        out = v
    elif (isinstance(v, float) and v.is_integer()) or (isinstance(v, str)
                                                         and v.strip().isdigit()):
        out = int(v)
    else:
        raise TypeError(f"sensor_ts {v!r} is not a whole number of nanoseconds")
    if not 0 <= out <= _UINT64_MAX:
        raise ValueError("sensor_ts out of range")
    return out


def frames_from_messages(decoded: Sequence[Any], platform: Platform, where: str,
                         encoding: str = "json", offset: int = 0) -> SmartWheelFrames:
    """Raw frames from decoded smart-wheel messages (JSON dicts or ROS 2 objects);
    ``offset``: the number of the first of them in the file (message 0 is checked whole)."""
    n = platform.n_units
    n_frames = len(decoded)
    ts = np.zeros((n_frames, n), dtype=np.uint64)
    vals = np.zeros((len(REQUIRED_FLOATS), n_frames, n))
    malformed = np.zeros(n_frames, dtype=bool)
    if encoding == "json":
        def sensors_of(m: Any) -> Any:
            return m["sensors"] if "sensors" in m or "wheels" not in m else m["wheels"]

        def get(s: Any, name: str) -> Any:
            return s[name]
    else:
        def sensors_of(m: Any) -> Any:  # (a KELO message holds them in ``wheels``)
            return m.sensors if hasattr(m, "sensors") or not hasattr(m, "wheels") else m.wheels

        def get(s: Any, name: str) -> Any:
            return getattr(s, name)

    notes: list[str] = []
    for k, m in enumerate(decoded):
        try:
            sensors = sensors_of(m)
            if len(sensors) < n:
                raise IndexError(f"{len(sensors)} sensors")
            for i in range(n):
                s = sensors[i]
                ts[k, i] = _ts_value(get(s, "sensor_ts"))
                for j, name in enumerate(REQUIRED_FLOATS):
                    vals[j, k, i] = float(get(s, name))
        except (KeyError, AttributeError, IndexError, TypeError, ValueError,
                OverflowError) as exc:
            if offset + k == 0:
                raise InputError(_first_frame_problem(exc, m, n, platform, where, sensors_of,
                                                      get)) from None
            malformed[k] = True
            ts[k] = 0
            vals[:, k] = 0.0
        if offset + k == 0 and len(sensors) > n:
            notes.append(extra_sensors_note(where, len(sensors), platform))
    return SmartWheelFrames(ts, dict(zip(REQUIRED_FLOATS, vals, strict=True)), malformed, where,
                            notes)


def extra_sensors_note(where: str, count: int, platform: Platform) -> str:
    return (f"{where}: the smart-wheel data has {count} sensors; the first "
            f"{platform.n_units} are read as units {', '.join(platform.unit_names)}")


def _first_frame_problem(exc: BaseException, m: Any, n: int, platform: Platform, where: str,
                         sensors_of: Any, get: Any) -> str:
    try:
        sensors = sensors_of(m)
        count = len(sensors)
    except (KeyError, AttributeError, TypeError):
        return (f"{where}: message 0 has no 'sensors' array; not the smart-wheel layout "
                "(sensors[n] with sensor_ts, encoder_1, ...)")
    if count < n:
        return (f"{where}: the smart-wheel data has {count} sensor{'s' if count != 1 else ''} "
                f"but the platform '{platform.name}' has {n} units; use the platform file that "
                "matches the robot")
    for i in range(n):
        for name in REQUIRED:
            try:
                get(sensors[i], name)
            except (KeyError, AttributeError, TypeError):
                return (f"{where}: message 0, sensors[{i}] has no field '{name}'; the "
                        f"smart-wheel layout needs {', '.join(REQUIRED)}")
    return (f"{where}: message 0 of the smart-wheel data has a bad value "
            f"({' '.join(str(exc).split())[:80]}); fix the recording")


def frames_to_log(frames: SmartWheelFrames, platform: Platform, where: str | None = None, *,
                  voltage_range: tuple[float, float] = VOLTAGE_RANGE,
                  warn: bool = True, gaps: Gaps | None = None) -> Log:
    """The contract log of smart-wheel frames, with the platform's per-unit settings.

    Corrupt frames are dropped (see the module description) and reported in ``Log.notes`` (and
    as a warning when ``warn``). Raises :class:`InputError` when fewer than 3 frames remain;
    with ``gaps`` (the file readers give it) also for a bad time base of the kept frames
    (:mod:`ropod_sysid.io.timebase`): a dropped frame leaves a step of two frames, no gap.
    """
    from ropod_sysid.io.swframes import FrameChecks

    where = where or frames.source
    checks = FrameChecks(platform, where, REQUIRED_FLOATS, voltage_range, frames.notes)
    first = checks.push(frames.sensor_ts, frames.values, frames.malformed)
    last, notes = checks.finish()
    log = join_logs([p for p in (first, last) if p is not None], notes)
    if gaps is not None:
        check_times(log.t, where, checks.locate, gaps)
    if warn:
        for note in notes:
            warnings.warn(note, stacklevel=2)
    return log


# ---------------------------------------------------------------------------------------------
# CSV


def is_smartwheel_csv(path: str | Path) -> bool:
    """True when the first line of the file names ``sensors.0.`` columns."""
    try:
        with open(path, "rb") as f:
            first = f.readline(1 << 20)
    except OSError:
        return False
    return b"sensors.0." in first


def read_smartwheel_csv(path: str | Path, platform: Platform, gaps: Gaps = "error") -> Log:
    """Read a CSV in the smart-wheel layout (columns ``sensors.<k>.<field>``) as a contract log
    (``gaps``: see :func:`frames_to_log`)."""
    where = str(path)
    path = Path(path)
    try:
        with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
            header = next(csv.reader([f.readline()]), [])
    except FileNotFoundError:
        raise InputError(f"{where}: no such log file; check the path") from None
    except OSError as exc:
        raise InputError(f"{where}: cannot read the log file ({exc.strerror or exc})") from None
    names = [h.strip() for h in header]
    present: dict[tuple[int, str], int] = {}
    for j, name in enumerate(names):
        m = _CSV_COLUMN.match(name)
        if m:
            present[(int(m.group(1)), m.group(2))] = j
    n = platform.n_units
    count = 1 + max((k for k, _ in present), default=-1)
    if count < n:
        raise InputError(
            f"{where}: the smart-wheel columns cover {count} sensor{'s' if count != 1 else ''} "
            f"(sensors.0 … sensors.{count - 1}) but the platform '{platform.name}' has {n} "
            "units; use the platform file that matches the robot")
    for k in range(n):
        for name in REQUIRED:
            if (k, name) not in present:
                raise InputError(f"{where}: column 'sensors.{k}.{name}' is missing; the "
                                 f"smart-wheel layout needs sensors.<k>.{', '.join(REQUIRED)}")
    arrow_names = [f"c{j}" for j in range(len(names))]
    types: dict[str, pa.DataType] = {}
    for k in range(n):
        types[f"c{present[(k, 'sensor_ts')]}"] = pa.uint64()
        for name in REQUIRED_FLOATS:
            types[f"c{present[(k, name)]}"] = pa.float64()
    try:
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(column_names=arrow_names, skip_rows=1),
            convert_options=pacsv.ConvertOptions(column_types=types,
                                                 include_columns=list(types)),
        )
    except (pa.ArrowException, ValueError, OSError) as exc:
        from ropod_sysid.io.csvlog import check_csv_lines

        # name the line (field count, text, overflow) as the contract reader does
        check_csv_lines(path, len(names), {names[int(c[1:])]: int(c[1:]) for c in types})
        msg = " ".join(str(exc).split())
        bad_ts = re.search(r"column #(\d+): CSV conversion error to uint64: invalid value '(.*)'",
                           msg)
        if bad_ts and int(bad_ts.group(1)) < len(names):    # e.g. too many digits
            k, value = int(bad_ts.group(1)), bad_ts.group(2)
            line = _line_with(path, k, value)
            shown = value if len(value) <= 24 else f"{value[:12]}… ({len(value)} digits)"
            raise InputError(
                f"{where}: line {line}, column '{names[k]}' has {shown!r}, which is not a "
                f"whole number of nanoseconds from 0 to 2^64 − 1; fix the value or remove the "
                "line") from None
        msg = re.sub(r"column #(\d+)",
                     lambda mm: f"column '{names[int(mm.group(1))]}'"
                     if int(mm.group(1)) < len(names) else mm.group(0), msg)
        raise InputError(f"{where}: not a readable smart-wheel CSV ({msg[:160]}); fix the file")\
            from None
    for c in types:
        col = table.column(c)
        if col.null_count:
            row = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
            raise InputError(f"{where}: line {row + 2}, column '{names[int(c[1:])]}' is empty; "
                             "fill it in or remove the line")
    n_rows = table.num_rows
    ts = np.empty((n_rows, n), dtype=np.uint64)
    vals = {f: np.empty((n_rows, n)) for f in REQUIRED_FLOATS}
    for k in range(n):
        ts[:, k] = table.column(f"c{present[(k, 'sensor_ts')]}").to_numpy()
        for name in REQUIRED_FLOATS:
            vals[name][:, k] = table.column(f"c{present[(k, name)]}").to_numpy()
    nonfinite = ~np.isfinite(np.stack(list(vals.values()))).all(axis=(0, 2))
    if nonfinite.any():   # spelled-out NaN/inf frames are dropped below, damaged digits are not
        from ropod_sysid.io.csvlog import check_csv_overflow

        check_csv_overflow(path, {names[int(c[1:])]: int(c[1:]) for c in types},
                           np.flatnonzero(nonfinite))
    notes = []
    if count > n:
        notes.append(extra_sensors_note(where, count, platform))
    frames = SmartWheelFrames(ts, vals, np.zeros(n_rows, dtype=bool), where, notes)
    return frames_to_log(frames, platform, where, gaps=gaps)


def _line_with(path: Path, k: int, value: str) -> int:
    """The file line of the first record whose field ``k`` is ``value`` (error path only)."""
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        reader = csv.reader(f)
        for rec in reader:
            if len(rec) > k and rec[k].strip() == value:
                return reader.line_num
    return 0  # pragma: no cover - Arrow named a value that is in the file


def read_smartwheel(path: str | Path, platform: Platform) -> Log:
    """Read a smart-wheel log (.csv or .mcap) as a contract log."""
    if str(path).lower().endswith(".mcap"):
        from ropod_sysid.io.mcaplog import read_mcap_log

        return read_mcap_log(path, platform)
    return read_smartwheel_csv(path, platform)


# ---------------------------------------------------------------------------------------------
# writing


def _wrap(x: np.ndarray, how: str | None) -> np.ndarray:
    if how is None:
        return x
    if how == "2pi":
        return np.mod(x, _TWO_PI)
    if how == "pi":
        return np.mod(x + math.pi, _TWO_PI) - math.pi
    raise ValueError(f"wrap must be None, '2pi' or 'pi', got {how!r}")


CORRUPT_KINDS = ("zeroed", "voltage", "time")


def raw_frames(log: Log, platform: Platform, *, t0_ns: int = DEFAULT_EPOCH_NS,
               wrap: str | None = None, wrap_pivot: str | None = "pi",
               corrupt: int | Mapping[str, int] = 0, voltage: float = 24.0,
               seed: int = 0, decimals: int | None = None,
               ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The smart-wheel fields of ``log`` as the drives would send them: field → (N', n) arrays
    and the (N',) receive times [ns]; see :func:`write_smartwheel` for the options."""
    swivel.check_all_swivel(platform, "the smart-wheel layout")
    units = list(platform.unit_names)
    delta, phi, current = swivel.arrays(log)
    if list(log.units) != units:
        raise InputError(f"{log.source}: the log's units {', '.join(log.units)} differ from the "
                         f"platform's {', '.join(units)}")
    t = np.asarray(log.t, dtype=np.float64)
    n_s, n = t.size, len(units)
    rel = np.round((t - t[0]) * 1e9).astype(np.int64)
    ts = np.empty((n_s, n), dtype=np.uint64)
    for i in range(n):
        ts[:, i] = np.uint64(t0_ns + 250 * i) + rel.astype(np.uint64)
    f: dict[str, np.ndarray] = {
        "status1": np.full((n_s, n), STATUS1_OK, dtype=np.uint16),
        "status2": np.zeros((n_s, n), dtype=np.uint16),
        "sensor_ts": ts,
        "setpoint_ts": ts - np.uint64(500_000),
    }
    for name in FLOAT_FIELDS:
        f[name] = np.zeros((n_s, n))
    f["voltage_bus"][:] = voltage
    for i, u in enumerate(platform.units):
        lm, rm = u.left_motor, 3 - u.left_motor
        raw_l = u.sign_left * phi[:, i, 0]
        raw_r = u.sign_right * phi[:, i, 1]
        pivot = delta[:, i] + u.pivot_offset
        f[f"encoder_{lm}"][:, i] = _wrap(raw_l, wrap)
        f[f"encoder_{rm}"][:, i] = _wrap(raw_r, wrap)
        f["encoder_pivot"][:, i] = _wrap(pivot, wrap_pivot)
        if n_s > 1:
            f[f"velocity_{lm}"][:, i] = np.gradient(raw_l, t)
            f[f"velocity_{rm}"][:, i] = np.gradient(raw_r, t)
            f["velocity_pivot"][:, i] = np.gradient(pivot, t)
        f[f"current_{lm}_q"][:, i] = u.sign_left * current[:, i, 0]
        f[f"current_{rm}_q"][:, i] = u.sign_right * current[:, i, 1]
    if decimals is not None:
        for name in FLOAT_FIELDS:
            f[name] = np.round(f[name], decimals)
    recv = ts[:, 0].copy()

    counts = ({k: int(corrupt) for k in CORRUPT_KINDS} if isinstance(corrupt, int)
              else {k: int(corrupt.get(k, 0)) for k in CORRUPT_KINDS})
    unknown = set(corrupt) - set(CORRUPT_KINDS) if not isinstance(corrupt, int) else set()
    if unknown:
        raise ValueError(f"unknown corrupt frame kinds {sorted(unknown)}; use {CORRUPT_KINDS}")
    total = sum(counts.values())
    if total:
        if n_s < 2 * total + 20:
            raise ValueError("the log is too short for that many corrupt frames")
        rng = np.random.default_rng(seed)
        pos = np.sort(rng.choice(np.arange(10, n_s - 10), size=total, replace=False))
        kinds = [k for k in CORRUPT_KINDS for _ in range(counts[k])]
        rng.shuffle(kinds)
        rows: dict[str, list[np.ndarray]] = {name: [] for name in f}
        recv_rows = []
        for j, (p, kind) in enumerate(zip(pos.tolist(), kinds, strict=True)):
            row = {name: f[name][p - 1].copy() for name in f}
            if kind == "zeroed":
                for name in row:
                    row[name][:] = 0
            elif kind == "voltage":
                row["sensor_ts"] = ts[p - 1] + (ts[p] - ts[p - 1]) // np.uint64(2)
                row["voltage_bus"][j % n] = 3.0 if j % 2 == 0 else 250.0
            elif j % 2 == 0:        # a stale frame sent again: time goes back
                row = {name: f[name][p - 3].copy() for name in f}
            else:                   # a flipped high bit in the clock: a forward spike
                row["sensor_ts"] = row["sensor_ts"] + np.uint64(1 << 40)
            for name in f:
                rows[name].append(row[name])
            recv_rows.append(recv[p - 1])
        for name in f:
            f[name] = np.insert(f[name], pos, np.array(rows[name], dtype=f[name].dtype), axis=0)
        recv = np.insert(recv, pos, np.array(recv_rows, dtype=recv.dtype))
    return f, recv


def write_smartwheel(log: Log, path: str | Path, platform: Platform, *,
                     encoding: str = "json", topic: str = SW_TOPIC,
                     t0_ns: int = DEFAULT_EPOCH_NS, wrap: str | None = None,
                     wrap_pivot: str | None = "pi", corrupt: int | Mapping[str, int] = 0,
                     voltage: float = 24.0, seed: int = 0, decimals: int | None = None) -> int:
    """Write ``log`` in the smart-wheel layout (.mcap: ``encoding`` json or ros2; .csv), atomically.

    The inverse of reading: the per-unit settings of ``platform`` say which motor is the left
    wheel and the signs of the motors (so a platform with ``left_motor: 2`` gives swapped motors,
    ``sign_left: -1`` a flipped sign), and ``pivot_offset`` is added to the pivot encoder.
    ``sensor_ts`` counts from ``t0_ns`` (an arbitrary epoch; unit k's clock runs 250·k ns ahead).
    ``wrap`` wraps the wheel encoders to ``"2pi"`` [0, 2π) or ``"pi"`` [−π, π) (None: unwrapped,
    as the drive sends them); ``wrap_pivot`` the same for the pivot encoder (the drive wraps it to
    [−π, π)). ``corrupt`` inserts corrupt frames — an int for that many of each kind, or
    ``{"zeroed": k, "voltage": k, "time": k}`` — at random places (``seed``), which the reader
    drops, leaving the original log. ``decimals`` rounds the float fields (smaller files; None
    writes them exactly). Returns the number of frames written.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".csv", ".mcap"):
        raise InputError(f"{path}: unknown log format '{suffix}'; use .csv or .mcap")
    if suffix == ".mcap" and encoding not in ("json", "ros2"):
        raise InputError(f"{path}: unknown MCAP encoding {encoding!r}; use json or ros2")
    f, recv = raw_frames(log, platform, t0_ns=t0_ns, wrap=wrap, wrap_pivot=wrap_pivot,
                         corrupt=corrupt, voltage=voltage, seed=seed, decimals=decimals)
    n_frames = int(recv.size)
    with atomic_path(path) as tmp:
        if suffix == ".csv":
            _write_csv(f, tmp)
        else:
            with open(tmp, "wb") as out:
                _write_mcap(f, recv, out, encoding, topic)
    return n_frames


def _write_csv(f: dict[str, np.ndarray], path: Path) -> None:
    n = f["sensor_ts"].shape[1]
    cols = {f"sensors.{k}.{name}": f[name][:, k] for k in range(n) for name in SW_FIELDS}
    table = pa.table({k: pa.array(np.ascontiguousarray(v)) for k, v in cols.items()})
    with open(path, "wb") as out:
        out.write((",".join(cols) + "\n").encode())
        pacsv.write_csv(table, out, pacsv.WriteOptions(include_header=False,
                                                       quoting_style="needed"))


def _write_mcap(f: dict[str, np.ndarray], recv: np.ndarray, out: Any, encoding: str,
                topic: str) -> None:
    from ropod_sysid.io.mcapwrite import OFFERED_QOS, new_writer

    n_frames, n = f["sensor_ts"].shape
    lists = {name: f[name].tolist() for name in SW_FIELDS}
    recv_l = recv.tolist()
    payload: Callable[[dict[str, Any]], bytes]
    if encoding == "json":
        writer = new_writer(out)
        schema_id = writer.register_schema(SW_JSON_SCHEMA, "jsonschema",
                                           json.dumps(smartwheel_json_schema()).encode())
        encode = json.JSONEncoder(separators=(",", ":")).encode

        def payload(msg: dict[str, Any]) -> bytes:
            return encode(msg).encode()
        channel_id = writer.register_channel(topic, "json", schema_id)
    else:
        from mcap_ros2._dynamic import serialize_dynamic

        writer = new_writer(out, profile="ros2")
        schema_id = writer.register_schema(SW_ROS2_SCHEMA, "ros2msg", SW_MSGDEF.encode())
        payload = serialize_dynamic(SW_ROS2_SCHEMA, SW_MSGDEF)[SW_ROS2_SCHEMA]
        channel_id = writer.register_channel(topic, "cdr", schema_id,
                                             {"offered_qos_profiles": OFFERED_QOS})
    for k in range(n_frames):
        msg = {"sensors": [{name: lists[name][k][i] for name in SW_FIELDS} for i in range(n)]}
        writer.add_message(channel_id, recv_l[k], payload(msg), recv_l[k], k)
    writer.finish()
