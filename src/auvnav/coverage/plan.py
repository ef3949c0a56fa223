"""The survey a mission plans: its legs, its lines, the pairs of adjacent lines and the area they cover.

A mission (:mod:`auvnav.plan.missions`) is a sequence of segments; its ``line`` segments are legs
between waypoints, flown from wherever the vehicle is (a leg to the first waypoint is added when the
vehicle starts more than :data:`CAPTURE_M` from it, as the vehicle's guidance does). From the legs:

- **lines**: legs at least ``min_line_m`` long that have an adjacent partner;
- **adjacent pairs**: two such legs flown one after the other (short legs such as the step between
  lawnmower lines may come between them), parallel or reciprocal within :data:`PARALLEL_TOL_RAD`,
  side by side (their along-track extents overlap by at least half the shorter one) and apart
  (across-track offset over :data:`MIN_SPACING_M`). The planned spacing is the across-track offset
  of the second line's middle from the first line; the pair's *turn end* is the end of the first
  line nearer the start of the second (where the vehicle turned from one to the other);
- **the planned area**: the union of each pair's quadrilateral (the convex hull of its two lines);
  for the paper's 75 m x 50 m lawnmower it is that rectangle;
- **runs**: consecutive legs in the same direction flown without a turn (the survey's lead-in and its
  first line are one run), which a flown track is matched against (:mod:`auvnav.coverage.lines`).

Everything is in the mission's frame: local NED about the dive's origin, north and east in metres.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from auvnav.frames import FloatArray
from auvnav.plan.missions import Ascend, Line, Mission, Surface

#: A line segment starts with a leg to its first waypoint when the vehicle is further than this, metres
#: (the simulator's guidance: ``VehicleDynamics.waypoint_capture_m``).
CAPTURE_M = 3.0
#: Two legs are parallel (or reciprocal) within this angle.
PARALLEL_TOL_RAD = math.radians(5.0)
#: Two parallel legs closer than this across track are one line continued, not a pair, metres.
MIN_SPACING_M = 0.05
#: Legs shorter than this are not survey lines by default, metres.
MIN_LINE_M = 10.0


@dataclass(frozen=True)
class Leg:
    """One planned leg.

    Parameters
    ----------
    start_ne_m, end_ne_m : ndarray, shape (2,)
        North and east, metres, local NED.
    epoch : int
        Surfacings before the leg (the vehicle's navigation is reset to GPS at each).
    """

    start_ne_m: FloatArray
    end_ne_m: FloatArray
    epoch: int

    @property
    def length_m(self) -> float:
        return float(np.hypot(*(self.end_ne_m - self.start_ne_m)))

    @property
    def bearing_rad(self) -> float:
        """Direction, radians clockwise from north."""
        d = self.end_ne_m - self.start_ne_m
        return math.atan2(float(d[1]), float(d[0]))

    @property
    def unit(self) -> FloatArray:
        d = self.end_ne_m - self.start_ne_m
        return d / max(float(np.hypot(*d)), 1e-12)


@dataclass(frozen=True)
class Pair:
    """Two adjacent planned lines.

    Parameters
    ----------
    a, b : int
        Indices into :attr:`SurveyPlan.legs` (``a`` flown first).
    spacing_m : float
        Planned across-track distance from line ``a`` to the middle of line ``b``, metres (> 0).
    across_ne : ndarray, shape (2,)
        Unit vector perpendicular to line ``a``, pointing to line ``b``.
    turn_end_at_end : bool
        The vehicle turned from ``a`` to ``b`` at the end of ``a`` (True) or at its start.
    """

    a: int
    b: int
    spacing_m: float
    across_ne: FloatArray
    turn_end_at_end: bool


@dataclass(frozen=True)
class SurveyPlan:
    """The legs, lines, adjacent pairs, runs and area of a mission (see the module docstring).

    Parameters
    ----------
    legs : tuple of Leg
        Every leg, in flight order.
    lines : tuple of int
        Indices of the legs that are survey lines, in flight order.
    pairs : tuple of Pair
        Adjacent lines, in flight order.
    runs : tuple of tuple of int
        Consecutive legs in one direction (indices), each at least ``min_line_m`` long in total.
    area_ne_m : tuple of ndarray, each (K, 2)
        Convex polygons whose union is the planned area (north, east), metres.
    altitude_m, speed_mps : float
        The mission's nominal altitude and speed.
    name : str
    """

    legs: tuple[Leg, ...]
    lines: tuple[int, ...]
    pairs: tuple[Pair, ...]
    runs: tuple[tuple[int, ...], ...]
    area_ne_m: tuple[FloatArray, ...]
    altitude_m: float
    speed_mps: float
    name: str = "mission"

    def area_m2(self) -> float:
        """Area of the planned area (its polygons are adjacent quadrilaterals: summed), m^2."""
        from auvnav.footprint import polygon_area

        return float(sum(polygon_area(p) for p in self.area_ne_m))

    def summary(self) -> dict[str, object]:
        spacing = [p.spacing_m for p in self.pairs]
        return {
            "name": self.name,
            "legs": len(self.legs),
            "lines": len(self.lines),
            "pairs": len(self.pairs),
            "planned_spacing_m": None if not spacing else float(np.median(spacing)),
            "area_m2": self.area_m2(),
            "altitude_m": self.altitude_m,
        }


def mission_legs(mission: Mission) -> list[Leg]:
    """Every leg the vehicle flies, in order, from the dive's start at the origin (see module docstring)."""
    here = np.zeros(2)
    epoch = 0
    legs: list[Leg] = []
    ascended = False
    for segment in mission.segments:
        if isinstance(segment, Ascend):
            ascended = True
        elif isinstance(segment, Surface) and ascended:
            epoch += 1
            ascended = False
        elif isinstance(segment, Line):
            points = [np.asarray(w, dtype=float) for w in segment.waypoints_ne_m]
            if float(np.hypot(*(points[0] - here))) > CAPTURE_M or len(points) == 1:
                points.insert(0, here.copy())
            for a, b in itertools.pairwise(points):
                if float(np.hypot(*(b - a))) > 1e-9:
                    legs.append(Leg(a, b, epoch))
            here = points[-1]
    return legs


def _pair(legs: list[Leg], i: int, j: int) -> Pair | None:
    """The pair (i, j) when the two legs are adjacent lines, else None."""
    a, b = legs[i], legs[j]
    if a.epoch != b.epoch:
        return None
    cos = float(a.unit @ b.unit)
    if abs(cos) < math.cos(PARALLEL_TOL_RAD):
        return None
    u = a.unit
    v = np.array([-u[1], u[0]])
    along_b = sorted(float((p - a.start_ne_m) @ u) for p in (b.start_ne_m, b.end_ne_m))
    common = min(a.length_m, along_b[1]) - max(0.0, along_b[0])
    if common < 0.5 * min(a.length_m, b.length_m):
        return None
    across = float((0.5 * (b.start_ne_m + b.end_ne_m) - a.start_ne_m) @ v)
    if abs(across) < MIN_SPACING_M:
        return None
    v = v if across > 0 else -v
    turn_at_end = float(np.hypot(*(a.end_ne_m - b.start_ne_m))) <= float(
        np.hypot(*(a.start_ne_m - b.start_ne_m))
    )
    return Pair(i, j, abs(across), v, turn_at_end)


def _convex_hull(points: FloatArray) -> FloatArray:
    """Convex hull (Andrew's monotone chain), counter-clockwise in (north, east)."""
    pts = sorted({(float(p[0]), float(p[1])) for p in points})
    if len(pts) < 3:
        return np.array(pts, dtype=float)

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1], dtype=float)


def survey_plan(mission: Mission, *, min_line_m: float = MIN_LINE_M) -> SurveyPlan:
    """The legs, lines, adjacent pairs, runs and planned area of a mission (module docstring).

    Parameters
    ----------
    mission : Mission
    min_line_m : float
        Legs shorter than this are not lines (the steps between lawnmower lines), metres.

    Returns
    -------
    SurveyPlan
        Possibly without lines (a transit, a spin): then no pairs and no area.
    """
    legs = mission_legs(mission)
    long = [k for k, leg in enumerate(legs) if leg.length_m >= min_line_m]
    pairs = []
    for i, j in itertools.pairwise(long):
        pair = _pair(legs, i, j)
        if pair is not None:
            pairs.append(pair)
    lines = tuple(sorted({p.a for p in pairs} | {p.b for p in pairs}))
    area = tuple(
        _convex_hull(
            np.stack([legs[p.a].start_ne_m, legs[p.a].end_ne_m, legs[p.b].start_ne_m, legs[p.b].end_ne_m])
        )
        for p in pairs
    )
    runs: list[tuple[int, ...]] = []
    current: list[int] = []
    for k, leg in enumerate(legs):
        if current:
            prev = legs[current[-1]]
            joined = (
                prev.epoch == leg.epoch
                and float(np.hypot(*(prev.end_ne_m - leg.start_ne_m))) < 1e-6
                and float(prev.unit @ leg.unit) >= math.cos(PARALLEL_TOL_RAD)
            )
            if joined:
                current.append(k)
                continue
            runs.append(tuple(current))
        current = [k]
    if current:
        runs.append(tuple(current))
    runs = [r for r in runs if sum(legs[k].length_m for k in r) >= min_line_m]
    return SurveyPlan(
        legs=tuple(legs),
        lines=lines,
        pairs=tuple(pairs),
        runs=tuple(runs),
        area_ne_m=area,
        altitude_m=mission.altitude_m,
        speed_mps=mission.speed_mps,
        name=mission.name,
    )
