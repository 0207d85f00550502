"""The "typical" identification run of the thesis (Sec. VI-A): :func:`typical`.

Straights, corners, rotations, constant velocity and acceleration, from rest to rest: a chain of
loops ("lobes") through the start, sized to the floor [m] and closed exactly, every twist change
a minimum-jerk blend within the limits (:mod:`ropod_sysid.trajectory.blends`). For the units
with a turning joint (the swivel's pivot) wheel flips are planned out and the turning rates
predicted by their type (eq. 8a) checked for all four variants; platforms without such units
(omni wheels) skip these steps. Units with an actuated steering (steered wheels) get blends slow
enough for the steering-rate limit, and on platforms whose constraint rows lose rank in some
manoeuvre (two steered wheels: a rotation in place, a sideways crab) that manoeuvre is left out
or turned. With a wheel-rate limit the driven wheels' rates are checked too. With a least
curvature radius (002 eq. 26; the default for platforms with legs) the corners are at least that
wide and the start's rotation is about a point that far beside the base (no rotation in place).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from ropod_sysid.errors import InputError
from ropod_sysid.model import PlatformModel
from ropod_sysid.model.assembly import SINGULAR_MARGIN
from ropod_sysid.platform import Platform, ropod_platform
from ropod_sysid.trajectory.blends import _path, _Plan, _sample
from ropod_sysid.trajectory.curvature import curvature_report
from ropod_sysid.trajectory.limits import (
    DEFAULT_FLOOR,
    PIVOT_DESIGN_MARGIN,
    STEER_RATE_MAX,
    Floor,
    Limits,
    PlanningError,
    _check_floor,
)
from ropod_sysid.trajectory.prediction import predict_angles, steering_points, trailing_points
from ropod_sysid.trajectory.run_variants import _off_floor, variants
from ropod_sysid.trajectory.setpoints import Trajectory, with_planned

TYPICAL_MAX_DURATION = 3600.0  # typical(): the longest run [s] (an hour of driving)
SPIN_START_MIN = 30.0  # typical(): runs this long [s] or longer start with a rotation in place
DESIGN_MARGIN = 0.9  # typical(): every limit is planned at 90 % of its value
ATTEMPTS = 16  # typical(): plans tried, each slower or with longer blends than the one before


@dataclass
class _Design:
    """Speeds and rates of a typical run."""

    v: float  # cruise speed on the long straights [m/s]
    v_corner: float  # speed in corners and on the short sides [m/s]
    v_spin: float  # speed at which a rotation in place is entered [m/s]
    w_corner: float  # corner rate [rad/s]
    w_spin: float  # rotation rate in place [rad/s]
    pause: float  # rest in a stop-and-go [s]
    spin: bool = True  # long runs start with a rotation in place
    spin_offset: float = 0.0  # … about a point this far to the right of the base origin [m]
    side: tuple[float, float] = (0.0, 1.0)  # crab lobes' short sides: direction (base frame)
    v_turn: float | None = None  # speed in the drive lobes' corners [m/s] (None: v_corner)


# lobe kinds of the typical run, in order: corners with a rotation in place, crab (lateral)
LOBES: tuple[tuple[str, bool], ...] = (("drive", False), ("crab", True), ("drive", True),
                                       ("crab", False))


def _lobe(plan: _Plan, kind: str, size: tuple[float, float], design: _Design, mirror: bool,
          first: bool) -> list[list[int]]:
    """One lobe of the run: a loop from the start back to it, at cruise speed along +x there.

    ``drive``: a rounded rectangle with four corners (left ones, right ones when mirrored), the
    first with a whole rotation in place. ``crab``: the same loop at constant heading — the
    short sides driven sideways (vy), the long side backwards with a stop-and-go — turning the
    direction of travel in the base frame instead of the heading. ``size`` = (e, c): length of
    the half straights through the start and of the second short side [m]. Returns groups of
    hold indices to solve for closure (x, then y).
    """
    sgn = -1.0 if mirror else 1.0
    cruise = np.array([design.v, 0.0, 0.0])
    v_slow = design.v_turn if kind == "drive" and design.v_turn else design.v_corner
    slow = np.array([v_slow, 0.0, 0.0])
    e, c = size
    if first:
        plan.to(cruise)
    plan.hold(e / design.v)
    plan.to(slow)
    if kind == "drive":
        plan.corner(sgn * math.pi / 2, design.w_corner)
        k_y = plan.hold(0.0)
        plan.corner(sgn * math.pi / 2, design.w_corner)
        plan.to(cruise)
        k_x = plan.hold(0.0)
        plan.to(slow)
        plan.corner(sgn * math.pi / 2, design.w_corner)
        plan.hold(c / v_slow)
        plan.corner(sgn * math.pi / 2, design.w_corner)
        groups = [[k_x], [k_y]]
    else:
        side = design.v_corner * np.array([design.side[0], sgn * design.side[1], 0.0])
        plan.to(side)
        k_y = plan.hold(0.0)
        plan.to(-slow)
        plan.to(-cruise)
        k_x1 = plan.hold(0.0)
        plan.stop_and_go(design.pause)
        k_x2 = plan.hold(0.0)
        plan.to(-slow)
        plan.to(-side)
        plan.hold(c / design.v_corner)
        plan.to(slow)
        groups = [[k_x1, k_x2], [k_y]]
    plan.to(cruise)
    plan.hold(e / design.v)
    return groups


def _close(plan: _Plan, first: int, groups: Sequence[Sequence[int]], theta0: float,
           p0: np.ndarray, target: np.ndarray) -> bool:
    """Lengthen the holds of ``groups`` so that the segments from ``first`` end at ``target``.

    A hold of a pure translation (ω = 0) at heading θ moves the base by h R(θ) u: the end point
    is affine in the hold times, so two groups of holds in independent directions close the
    loop exactly. Returns False if a hold would have to be negative.
    """
    _, pos, _ = _path(plan.segs[first:], theta0, p0, 0.005)
    heading = theta0
    dirs = {}
    for j, (a, b, dur) in enumerate(plan.segs[first:], start=first):
        c, s = math.cos(heading), math.sin(heading)
        dirs[j] = np.array([c * a[0] - s * a[1], s * a[0] + c * a[1]])
        heading += dur * (a[2] + b[2]) / 2
    mat = np.stack([sum(dirs[j] for j in g) for g in groups], axis=1)
    try:
        h = np.linalg.solve(mat, target - pos[-1])
    except np.linalg.LinAlgError:
        return False
    if np.any(h < -1e-9):
        return False
    for g, hj in zip(groups, h, strict=True):
        for j in g:
            plan.segs[j][2] += float(max(hj, 0.0))
    return True


def _lobe_plan(kind: str, size: tuple[float, float], design: _Design, caps: Limits,
               pivots: np.ndarray | None, mirror: bool = False,
               steering: np.ndarray | None = None) -> _Plan | None:
    plan = _Plan(caps, pivots, steering=steering)
    plan.level = np.array([design.v, 0.0, 0.0])
    groups = _lobe(plan, kind, size, design, mirror, first=False)
    if not _close(plan, 0, groups, 0.0, np.zeros(2), np.zeros(2)):
        return None
    return plan


def _fits(plan: _Plan | None, half: tuple[float, float]) -> bool:
    """Does a lobe stay within |x| ≤ W, |y| ≤ H? Its variants are reflections of it (a drive
    lobe has vy = 0, a crab lobe ω = 0), so they stay inside too."""
    if plan is None:
        return False
    _, pos, _ = _path(plan.segs, 0.0, np.zeros(2), 0.02)
    return bool(np.abs(pos[:, 0]).max() <= half[0] and np.abs(pos[:, 1]).max() <= half[1])


def _bisect(ok: Callable[[float], bool], lo: float, hi: float, steps: int = 10) -> float | None:
    """Largest value in [lo, hi] for which ``ok`` holds (assumed monotone), None if not at lo."""
    if not ok(lo):
        return None
    if ok(hi):
        return hi
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


def _fit_lobe(kind: str, design: _Design, caps: Limits, pivots: np.ndarray | None,
              half: tuple[float, float], steering: np.ndarray | None = None
              ) -> tuple[float, float] | None:
    """Sizes (e, c) [m] of the largest lobe of ``kind`` inside |x| ≤ W, |y| ≤ H."""
    def fits(e: float, c: float) -> bool:
        return _fits(_lobe_plan(kind, (e, c), design, caps, pivots, steering=steering), half)

    lo = None
    for e0 in np.arange(0.0, 2 * half[0], 0.25):
        if fits(float(e0), 0.0):
            lo = float(e0)
            break
    if lo is None:
        return None
    e = _bisect(lambda e: fits(e, 0.0), lo, 2 * half[0], steps=8)
    assert e is not None
    c = _bisect(lambda c: fits(e, c), 0.0, 2 * half[1], steps=8)
    return (e, c if c is not None else 0.0)


def _start_spin(plan: _Plan, design: _Design) -> None:
    """Start: a whole clockwise rotation in place from rest (units set tangentially, as they
    trail a rotation), then away along +x through a tight right arc, at cruise speed; heading
    back to 0 (mod 2π). Clockwise, so that the original run turns both ways early on. With a
    ``spin_offset`` d the rotation is about the point (0, −d) of the base frame instead (the
    base origin on a circle of radius d) and the arc no tighter than that."""
    w, d = design.w_spin, design.spin_offset
    rot = np.array([w * d, 0.0, -w])
    arc = np.array([max(design.v_spin, w * d), 0.0, -w])
    slow = np.array([arc[0], 0.0, 0.0])
    t_rot = plan.blend_time(np.zeros(3), rot)
    t_arc = plan.blend_time(rot, arc)
    t_slow = plan.blend_time(arc, slow)
    turned = design.w_spin * (t_rot / 2 + t_arc + t_slow / 2)
    target = 2 * math.pi
    while target < turned:
        target += 2 * math.pi
    plan.to(rot, t_rot)
    plan.hold((target - turned) / design.w_spin)
    plan.to(arc, t_arc)
    plan.to(slow, t_slow)
    plan.to(np.array([design.v, 0.0, 0.0]))
    plan.theta = 0.0  # a whole number of turns: the world heading is back to +x


def _typical_program(duration: float, caps: Limits, floor: Floor, pivots: np.ndarray | None,
                     design: _Design, order: Sequence[tuple[str, bool]],
                     shrink: float, steering: np.ndarray | None = None) -> list[list]:
    """The program of a typical run (see :func:`typical`), exactly ``duration`` long."""
    half = (shrink * min(floor[1], -floor[0]), shrink * min(floor[3], -floor[2]))
    sizes = {kind: _fit_lobe(kind, design, caps, pivots, half, steering)
             for kind in {k for k, _ in order}}
    if any(v is None for v in sizes.values()):
        raise PlanningError("the floor is too small for a typical run at these limits")

    plan = _Plan(caps, pivots, steering=steering)
    spin_start = duration >= SPIN_START_MIN and design.spin
    if spin_start:
        _start_spin(plan, design)
    lobe = 0
    while plan.duration < duration + 10.0:
        kind, mirror = order[lobe % len(order)]
        first = len(plan.segs)
        size = sizes[kind]
        assert size is not None  # (none is: checked above)
        if lobe == 0:  # the start moved the base along +x already: shorten the first straight
            if spin_start:
                p0 = _path(plan.segs, 0.0, np.zeros(2), 0.005)[1][-1]
                advance = float(p0[0])
            else:
                p0 = np.zeros(2)
                advance = 0.5 * design.v * plan.blend_time(np.zeros(3), np.array([design.v, 0, 0]))
            size = (max(size[0] - advance, 0.0), size[1])
        else:
            p0 = np.zeros(2)
        groups = _lobe(plan, kind, size, design, mirror, first=lobe == 0 and not spin_start)
        if not _close(plan, first, groups, 0.0, p0, np.zeros(2)):
            raise PlanningError("the floor is too small for a typical run at these limits")
        lobe += 1

    # stop on the last straight (a translation hold) that leaves time to decelerate
    starts = np.cumsum([0.0] + [s[2] for s in plan.segs])
    for j in range(len(plan.segs) - 1, -1, -1):
        a, b, dur = plan.segs[j]
        if not (np.array_equal(a, b) and a[2] == 0.0 and np.linalg.norm(a[:2]) > 0):
            continue
        t_stop = plan.blend_time(a, np.zeros(3))
        if starts[j] + t_stop <= duration and (dur > 0 or starts[j] + t_stop > duration - 1.0):
            break
    else:
        need = min(starts[j] + plan.blend_time(a, np.zeros(3))
                   for j, (a, b, _) in enumerate(plan.segs)
                   if np.array_equal(a, b) and a[2] == 0.0 and np.linalg.norm(a[:2]) > 0)
        raise PlanningError(f"duration {duration:g} s is too short for a typical run at these "
                            f"limits; give at least {math.ceil(need * 10) / 10:g} s")
    segs = [list(s) for s in plan.segs[:j + 1]]
    segs[j][2] = min(dur, duration - t_stop - starts[j])
    segs.append([a, np.zeros(3), t_stop])
    total = sum(s[2] for s in segs)
    k = duration / total  # ≥ 1: stretch time (speeds / k, accelerations / k²; same path)
    return [[sa / k, sb / k, sd * k] for sa, sb, sd in segs]


def typical(duration: float = 60.0, v_max: float = 1.0, a_max: float = 1.0,
            w_max: float = 1.0, alpha_max: float = 1.0, floor: Sequence[float] = DEFAULT_FLOOR,
            dt: float = 0.005, seed: int = 0, pivot_rate_max: float | None = 1.5,
            platform: Platform | None = None,
            wheel_rate_max: float | None = None,
            steer_rate_max: float | None = STEER_RATE_MAX,
            curvature_radius_min: float | None = None) -> Trajectory:
    """A "typical" identification run (thesis Sec. VI-A), from rest to rest.

    The run is a chain of loops ("lobes") through the start, each leaving and reaching it along
    +x at cruise speed: the lobes of the upper half of the floor turn left, the mirrored ones of
    the lower half turn right. Lobe kinds, in turn:

    * drive — straights at cruise speed (constant-velocity phases), slowing down into the four
      corners (acceleration phases); the first corner includes a whole rotation in place;
    * crab — the same loop at constant heading (the ropod is holonomic): the short sides driven
      sideways (vy), the long side backwards with a stop-and-go.

    Runs of 30 s or more start with a whole clockwise rotation in place and a right arc. A 60 s
    run holds the start, a left drive lobe and most of a crab lobe; the right corners of the
    drive lobes follow in longer runs — and in the mirrored variant, which swaps them.

    The order is drive-left, drive-right, crab, crab-mirrored, and again. Every change of the
    twist is a minimum-jerk blend (10τ³ − 15τ⁴ + 6τ⁵) between constant levels, so the
    acceleration is continuous (jumps in it bias the identification); each blend is as short as
    the limits allow at 90 % of their value (pivot rates: 80 %, quasi-steady). The lobes are
    sized to the floor and closed exactly by solving for the length of two straights.

    Wheel flips (Sec. VI-A) of the units that trail their pivot (the swivel type; on a mixed
    platform those units only, none on an omni platform) are planned out: no blend reverses the
    velocity of a pivot, a stop is followed by motion in the same direction, and the direction of
    every pivot velocity turns no faster than the pivot-rate limit. The angles predicted by every
    unit type (:func:`~ropod_sysid.trajectory.prediction.predict_angles`: pivot rates by
    integration of eq. 8a, wheel flips, wheel rates) are then checked for all four variants, and
    so is the floor. A wheel rate above ``wheel_rate_max`` makes the run slower (speeds and
    rotation rates scaled down) until it holds.

    Steered wheels (units with an actuated steering) are steered along their wheel-centre
    velocities, so while they move their steering rate is the rate at which the direction of
    that velocity turns: every blend is made long enough for it to stay within
    ``steer_rate_max`` (at 90 %), and the planned steering is checked for all four variants
    (a blend made longer still if it is not). At the stops (stop-and-go, start, end) a wheel
    resumes along the line it stopped on, so no turn on the spot is planned. Where the
    platform's constraint rows would come near losing rank (σ_r/σ_1 of their base block below
    :data:`~ropod_sysid.model.assembly.SINGULAR_MARGIN`, where the fit leaves out the base
    rows), a manoeuvre is changed (:func:`_regular_manoeuvres`): the start's rotation in place
    becomes a rotation about a point beside the base origin (:data:`SPIN_OFFSETS` × the
    largest unit distance, the first clear by twice the margin in all four variants), and the
    crab lobes' short sides turn from sideways (90°) towards the base x axis
    (:data:`SIDE_DIRECTIONS`) until that translation is clear of the margin. For 001's
    two wheels on the x axis both are singular as planned for the ropod (all axles on one
    line); four wheels at the corners of a rectangle are never near it. ``check`` reports the
    time that remains.

    Parameters
    ----------
    duration : length of the run [s] (≥ about 10 s); the program is cut on a straight, ends with
        a stop and is stretched in time (slower, same path) to last exactly this long.
    v_max, a_max, w_max, alpha_max : limits [m/s, m/s², rad/s, rad/s²] (see :class:`Limits`)
    floor : (x_min, x_max, y_min, y_max) [m], the rectangle the base origin must stay in, in
        the world frame of the planned pose (start at the origin, heading +x). Default: 6 m × 4 m
        centred on the start. The run uses the largest rectangle centred on the start inside it;
        shrink the floor by the robot's half size yourself.
    dt : sample interval of the setpoints [s]
    seed : 0 for the reference run; other seeds vary the speeds (±10 %) and the lobe order,
        repeatably.
    pivot_rate_max : pivot-rate limit [rad/s] (Sec. VII-C: 1.5); None to not plan for it
    platform : unit types and geometry for the predicted angles; default the ropod
        (:func:`ropod_platform`)
    wheel_rate_max : limit of every driven wheel's rate [rad/s]; None (default): none
    steer_rate_max : steering-rate limit of units with an actuated steering [rad/s] (default
        :data:`~ropod_sysid.trajectory.limits.STEER_RATE_MAX`, 001's 195.95 °/s); None to
        not plan for it
    curvature_radius_min : least curvature radius R = |v|/|ω| of the base wherever it rotates
        [m] (002 eq. 26; :func:`~ropod_sysid.trajectory.limits.default_curvature_radius`
        gives a platform's default); None (default): no limit. With it the start's whole
        rotation is a circle about a point at least R_min / 0.9 beside the base origin (no
        rotation in place, R = 0) and every corner is at least that wide.

    Returns
    -------
    Trajectory
        Setpoints at ``dt`` and the planned pose.
    """
    limits = Limits(v_max, a_max, w_max, alpha_max, pivot_rate_max, wheel_rate_max,
                    steer_rate_max, curvature_radius_min)
    floor = _check_floor(floor)
    if not (isinstance(duration, int | float) and 0 < duration <= TYPICAL_MAX_DURATION):
        raise InputError(f"duration must be a number of seconds in (0, "
                         f"{TYPICAL_MAX_DURATION:g}], got {duration!r}")
    if not (isinstance(dt, int | float) and 0 < dt <= 0.1):
        raise InputError(f"dt must be in (0, 0.1] s, got {dt!r}")
    if platform is None:
        platform = ropod_platform()
    pivots = trailing_points(platform) if pivot_rate_max is not None else None
    steering = steering_points(platform) if steer_rate_max is not None else None
    spin_offset, side = _regular_manoeuvres(platform)
    rng = np.random.default_rng(seed)
    jitter = 1.0 if seed == 0 else float(rng.uniform(0.9, 1.1))
    order = list(LOBES)
    if seed != 0:
        order = [order[i] for i in rng.permutation(len(order))]
        k = next(i for i, (kind, _) in enumerate(order) if kind == "drive")
        order = order[k:] + order[:k]  # a drive lobe first: it absorbs the start's offset
    pivot_margin = PIVOT_DESIGN_MARGIN
    steer_margin = DESIGN_MARGIN
    shrink = 0.97
    speed = 1.0
    slower = 1.0  # speeds and rotation rates scaled down for the wheel-rate limit
    wider = 1.0  # the least planned curvature radius scaled up for its limit
    turn = 1.0  # the speed in the corners scaled down for the floor (with R_min)
    last_error = ""
    for _attempt in range(ATTEMPTS):
        caps = limits.scaled(DESIGN_MARGIN, pivot_margin, steer_margin)
        if slower != 1.0:
            caps = Limits(caps.v_max * slower, caps.a_max, caps.w_max * slower, caps.alpha_max,
                          caps.pivot_rate_max, None, caps.steer_rate_max,
                          caps.curvature_radius_min)
        vm = v_max * slower
        v = min(0.8 * jitter, 0.85) * vm * speed
        v_corner = min(0.4 * vm * jitter, 0.9 * caps.a_max / (0.9 * caps.w_max)) * speed
        w_corner = min(0.9 * caps.w_max, 0.9 * caps.a_max / v_corner)
        w_spin, offset, v_turn = 0.9 * caps.w_max, spin_offset, None
        if caps.curvature_radius_min is not None:
            # 002 eq. 26: R = |v|/|ω| ≥ R_min in corners and in the start's rotation, which
            # turns about a point R_min / 0.9 (or farther) beside the base origin; corners of
            # radius R_min / 0.9 as fast as the corner rate allows, up to cruise speed
            r_plan = caps.curvature_radius_min * wider
            v_turn = max(v_corner, min(v, w_corner * r_plan)) * turn
            w_corner = min(w_corner, v_turn / r_plan, 0.9 * caps.a_max / v_turn)
            if offset is not None:
                offset = max(offset, r_plan)
                w_spin = min(w_spin, v / offset, math.sqrt(0.9 * caps.a_max / offset))
        design = _Design(
            v=v, v_corner=v_corner, v_spin=0.2 * vm * speed,
            w_corner=w_corner, w_spin=w_spin, pause=1.0, spin=offset is not None,
            spin_offset=offset or 0.0, side=side, v_turn=v_turn)
        try:
            segs = _typical_program(duration, caps, floor, pivots, design, order, shrink,
                                    steering)
        except PlanningError as exc:
            if "duration" in str(exc):
                raise
            if v_turn is not None and turn > 0.3:
                turn *= 0.8  # corners of R_min / 0.9 taken slower: shorter rate blends
            else:
                speed *= 0.85  # smaller corners
            last_error = str(exc)
            continue
        n = int(round(duration / dt))
        t = np.arange(n + 1) * dt
        if t[-1] < duration - 1e-9:
            t = np.append(t, duration)
        tw = _sample(segs, t)
        traj = with_planned(Trajectory.from_twist(t, tw[:, 0], tw[:, 1], tw[:, 2]), platform,
                            seed)  # legs: their extensions planned with the base motion
        var = variants(traj)
        if _off_floor(var, floor) is not None:
            shrink *= 0.93
            last_error = "the planned run leaves the floor"
            continue
        if curvature_radius_min is not None:
            curve = curvature_report(traj.t, traj.twist(), platform.positions,
                                     curvature_radius_min)
            if not curve.ok:
                wider *= 1.15
                last_error = (f"curvature radius {curve.min_radius:.3g} m below "
                              f"{curvature_radius_min:g} m")
                continue
        if pivots is not None or steering is not None or wheel_rate_max is not None:
            columns = PlatformModel(platform).planned_columns if platform else []
            pred = predict_angles(traj.t, np.stack([vt.twist() for vt in var.values()]),
                                  platform, planned=np.stack([vt.planned_series(columns)
                                                              for vt in var.values()]))
            peak = pred.turning_peak
            # (pivots only with a pivot-rate limit, as steering only with a steering-rate one)
            if pivots is not None and (peak > pivot_rate_max * 0.95 or pred.flagged):  # type: ignore[operator]
                pivot_margin *= 0.8
                last_error = f"predicted pivot rate {peak:.2f} rad/s exceeds the limit"
                continue
            steer = pred.steering_peak
            if steering is not None and steer > steer_rate_max * 0.95:  # type: ignore[operator]
                steer_margin *= 0.8
                last_error = f"predicted steering rate {steer:.2f} rad/s exceeds the limit"
                continue
            wheel = float(np.abs(pred.wheel_rates).max(initial=0.0))
            if wheel_rate_max is not None and wheel > wheel_rate_max * DESIGN_MARGIN:
                slower *= 0.97 * DESIGN_MARGIN * wheel_rate_max / wheel
                last_error = f"predicted wheel rate {wheel:.3g} rad/s exceeds the limit"
                continue
        return traj
    hint = ("" if curvature_radius_min is None else
            f" (--curvature-radius-min {curvature_radius_min:g} m makes every corner and the "
            f"start's rotation at least {curvature_radius_min / DESIGN_MARGIN:.3g} m wide)")
    raise PlanningError(f"cannot plan a typical run within the limits: {last_error}; relax "
                        f"the limits{hint}, enlarge the floor or use no pivot-rate limit")


SIDE_DIRECTIONS = (90.0, 75.0, 60.0, 45.0)  # typical(): crab sides tried [°], the first clear
# typical(): centres of the start's rotation tried, to the right of the base origin, in units of
# the largest distance of a unit from it (0: in place), the first clear of twice the margin
SPIN_OFFSETS = (0.0, 0.25, 0.5, 1.0)


def _regular_manoeuvres(platform: Platform) -> tuple[float | None, tuple[float, float]]:
    """(offset [m] of the start's rotation centre, None: no rotation at the start; crab side
    direction (cos, sin)) for a platform: the first of :data:`SPIN_OFFSETS` whose rotation
    (0 for a platform without constraint rows) and the first direction of
    :data:`SIDE_DIRECTIONS` whose translation stay clear of the singular margin in all four
    variants (90°, exactly (0, 1), if none does)."""
    from ropod_sysid.model import PlatformModel
    from ropod_sysid.trajectory.run_variants import VARIANT_SIGNS

    model = PlatformModel(platform)
    if not model.constrained:
        return 0.0, (0.0, 1.0)
    signs = np.array(list(VARIANT_SIGNS.values()))  # (4, 3)
    r_max = float(np.linalg.norm(platform.positions, axis=1).max())
    offsets = r_max * np.array(SPIN_OFFSETS)
    spins = np.stack([offsets, np.zeros(offsets.size), -np.ones(offsets.size)], axis=-1)
    sides = np.radians(SIDE_DIRECTIONS)
    dirs = np.stack([np.cos(sides), np.sin(sides)], axis=-1)
    dirs[sides == math.pi / 2] = (0.0, 1.0)
    crabs = np.column_stack([dirs, np.zeros(sides.size)])
    twists = np.vstack([spins, crabs])
    ratio = _singular_ratio_at(model, (twists[None] * signs[:, None]).reshape(-1, 3))
    worst = ratio.reshape(4, -1).min(axis=0)
    spin_ok = worst[:offsets.size] >= 2 * SINGULAR_MARGIN
    side_ok = worst[offsets.size:] >= SINGULAR_MARGIN
    offset = float(offsets[int(np.argmax(spin_ok))]) if spin_ok.any() else None
    k = int(np.argmax(side_ok)) if side_ok.any() else 0
    return offset, (float(dirs[k, 0]), float(dirs[k, 1]))


def _singular_ratio_at(model: PlatformModel, twists: np.ndarray) -> np.ndarray:
    """σ_r/σ_1 of the constraint rows' base block (:meth:`PlatformModel.singular_ratio`) for
    constant base-frame twists (m, 3) at heading 0, every unit at the angles it takes for
    that motion (:meth:`PlatformModel.initial_angles`)."""
    angles = np.stack([model.initial_angles(tw) for tw in twists])
    st = model.state(np.zeros_like(twists), twists, angles,
                     np.zeros_like(angles))
    # not None: the caller (_regular_manoeuvres) passes a constrained model only
    return cast(np.ndarray, model.singular_ratio(st))
