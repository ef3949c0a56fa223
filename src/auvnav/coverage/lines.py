"""The lines a vehicle flew, and the spacing of each pair of adjacent lines along them.

**Flown lines.** A track (positions at the image times, or any trajectory's) is cut into *straight
runs*: stretches where the course over the ground, measured over :data:`COURSE_WINDOW_M` of path,
stays within :data:`RUN_TOLERANCE_RAD` of the course where the run began. The planned runs of the
mission (:class:`~auvnav.coverage.plan.SurveyPlan`) are matched to them in order: the next flown run
whose course is within :data:`MATCH_TOLERANCE_RAD` of the planned direction and whose length is
between half and one and a half times the planned run's; a planned run made of several legs (a
lead-in continued by the first line) is shared among its legs in proportion to their lengths. The
matching never uses positions: a track that drifted tens of metres off the plan (the paper's
'accordion') is matched as well as one on it. Without a mission, the runs themselves are the lines
and pairs are formed from consecutive ones as a mission's are.

**Spacing.** For a pair of adjacent lines ``a`` then ``b`` (planned spacing ``S``), both flown
tracks are expressed in line ``a``'s planned frame (along its direction from its planned start,
across towards line ``b``), their across-track positions interpolated at stations every
``station_m`` along it, ``margin_m`` in from each end; the spacing is the difference at each station
where both lines are. A pair is **on plan** when the spacing stays within ``tolerance_m`` of ``S``
everywhere; otherwise an **accordion** when its largest departure opens the pair (wider than
planned) and a **figure 8** when it closes it (narrower, or the lines cross: negative spacing). A
heading error that differs between the two directions of reciprocal lines turns each pair into a
wedge hinged at its turn end, where the planned step between lines fixes the spacing (paper Fig. 2):
the far end opens (accordion) or closes (figure 8) by line length x the difference of the heading
errors. Without a planned spacing the spacing at the turn end stands for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from auvnav.coverage.plan import Leg, Pair, SurveyPlan, _pair
from auvnav.frames import FloatArray, wrap_angle

#: Course over the ground measured over this much path, metres (smooths a track's noise).
COURSE_WINDOW_M = 2.0
#: A straight run ends where the course departs this much from where the run began.
RUN_TOLERANCE_RAD = math.radians(20.0)
#: A flown run matches a planned one whose direction is within this.
MATCH_TOLERANCE_RAD = math.radians(25.0)
#: Flown runs looked at past the last matched one before a planned run is declared not flown.
MATCH_LOOKAHEAD = 6

PairClass = Literal["on plan", "accordion", "figure 8"]


@dataclass(frozen=True)
class FlownLine:
    """The part of a track that flew one planned leg.

    Parameters
    ----------
    leg : int
        Index of the planned leg (:attr:`SurveyPlan.legs`), or of the run when there is no plan.
    first, last : int
        First and last sample of the track on it (inclusive).
    t_start_s, t_end_s : float
        Their times, POSIX seconds.
    """

    leg: int
    first: int
    last: int
    t_start_s: float
    t_end_s: float


@dataclass(frozen=True)
class PairSpacing:
    """The spacing of a pair of adjacent lines along them (see the module docstring).

    Parameters
    ----------
    pair : Pair
        The pair (legs of the plan, or runs of the track without a plan).
    line_a, line_b : int
        Their numbers among the survey lines (0-based).
    along_m : ndarray, shape (S,)
        Stations along line ``a``'s planned direction from its planned start, metres.
    spacing_m : ndarray, shape (S,)
        Across-track distance from line ``a`` to line ``b`` at each station, metres (towards the planned
        side: negative where the lines crossed); NaN where either line is missing.
    planned_m : float or None
        The planned spacing (None: no plan).
    reference_m : float
        What the spacing is compared with: the planned spacing, or the spacing at the turn end.
    tolerance_m : float
    """

    pair: Pair
    line_a: int
    line_b: int
    along_m: FloatArray
    spacing_m: FloatArray
    planned_m: float | None
    reference_m: float
    tolerance_m: float

    @property
    def valid(self) -> NDArray[np.bool_]:
        return np.isfinite(self.spacing_m)

    @property
    def n(self) -> int:
        return int(np.count_nonzero(self.valid))

    def _ends(self) -> tuple[float, float]:
        """Spacing at the turn end and at the far end (mean of the three stations nearest each)."""
        s = self.spacing_m[self.valid]
        if s.size == 0:
            return math.nan, math.nan
        head, tail = float(np.mean(s[:3])), float(np.mean(s[-3:]))
        return (tail, head) if self.pair.turn_end_at_end else (head, tail)

    @property
    def classification(self) -> PairClass | None:
        if self.n == 0:
            return None
        dev = self.spacing_m[self.valid] - self.reference_m
        if float(np.max(np.abs(dev))) <= self.tolerance_m:
            return "on plan"
        return "accordion" if float(np.max(dev)) >= -float(np.min(dev)) else "figure 8"

    def row(self) -> dict[str, object]:
        """A row of ``lines.csv``."""
        s = self.spacing_m[self.valid]
        turn, far = self._ends()
        nan = math.nan
        return {
            "pair": None,
            "line_a": self.line_a,
            "line_b": self.line_b,
            "planned_m": nan if self.planned_m is None else self.planned_m,
            "stations": self.n,
            "min_m": float(s.min()) if s.size else nan,
            "mean_m": float(s.mean()) if s.size else nan,
            "max_m": float(s.max()) if s.size else nan,
            "turn_end_m": turn,
            "far_end_m": far,
            "class": self.classification or "not flown",
        }


def course_over_ground(p_ne_m: FloatArray, window_m: float = COURSE_WINDOW_M) -> FloatArray:
    """Course at each sample over ``window_m`` of path centred on it, radians; NaN where the track
    moved less than a quarter of the window over it (hovering, descending)."""
    p = np.asarray(p_ne_m, dtype=float)
    if len(p) < 2:
        return np.full(len(p), np.nan)
    d = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
    a = np.clip(np.searchsorted(d, d - window_m / 2, side="left"), 0, len(p) - 1)
    b = np.clip(np.searchsorted(d, d + window_m / 2, side="right") - 1, 0, len(p) - 1)
    delta = p[b] - p[a]
    course = np.arctan2(delta[:, 1], delta[:, 0])
    course[np.hypot(delta[:, 0], delta[:, 1]) < window_m / 4] = np.nan
    return course


def straight_runs(
    p_ne_m: FloatArray, *, min_length_m: float, tolerance_rad: float = RUN_TOLERANCE_RAD
) -> list[tuple[int, int]]:
    """Straight runs of a track (first and last sample, inclusive) at least ``min_length_m`` long."""
    p = np.asarray(p_ne_m, dtype=float)
    course = course_over_ground(p)
    d = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))]) if len(p) else np.zeros(0)
    runs: list[tuple[int, int]] = []
    start, ref = -1, 0.0
    for k, c in enumerate(course):
        ok = math.isfinite(c) and start >= 0 and abs(float(wrap_angle(c - ref))) <= tolerance_rad
        if ok:
            continue
        if start >= 0 and d[k - 1] - d[start] >= min_length_m:
            runs.append((start, k - 1))
        start, ref = (k, float(c)) if math.isfinite(c) else (-1, 0.0)
    if start >= 0 and len(p) and d[-1] - d[start] >= min_length_m:
        runs.append((start, len(p) - 1))
    return runs


def _run_course(p: FloatArray, first: int, last: int) -> float:
    delta = p[last] - p[first]
    return math.atan2(float(delta[1]), float(delta[0]))


def match_lines(
    plan: SurveyPlan, t_s: FloatArray, p_ne_m: FloatArray, *, min_line_m: float
) -> list[FlownLine]:
    """The part of a track that flew each planned survey line (module docstring), in flight order.

    Parameters
    ----------
    plan : SurveyPlan
    t_s : ndarray, shape (N,)
        Sample times, POSIX seconds.
    p_ne_m : ndarray, shape (N, 2)
        North and east of the track, metres, local NED.
    min_line_m : float
        Shortest straight run looked at, metres.

    Returns
    -------
    list of FlownLine
        One per survey line that was flown (lines not found are left out).
    """
    p = np.asarray(p_ne_m, dtype=float)
    d = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))]) if len(p) else np.zeros(0)
    flown = straight_runs(p, min_length_m=0.5 * min_line_m)
    lines = set(plan.lines)
    out: list[FlownLine] = []
    nxt = 0
    for run in plan.runs:
        legs = [plan.legs[k] for k in run]
        planned_len = sum(leg.length_m for leg in legs)
        bearing = legs[0].bearing_rad
        found = None
        for m in range(nxt, min(nxt + MATCH_LOOKAHEAD, len(flown))):
            first, last = flown[m]
            length = d[last] - d[first]
            course = _run_course(p, first, last)
            if (
                abs(float(wrap_angle(course - bearing))) <= MATCH_TOLERANCE_RAD
                and 0.5 * planned_len <= length <= 1.5 * planned_len + min_line_m
            ):
                found = m
                break
        if found is None:
            continue
        nxt = found + 1
        first, last = flown[found]
        fraction = (d[first : last + 1] - d[first]) / max(d[last] - d[first], 1e-9)
        bounds = np.concatenate([[0.0], np.cumsum([leg.length_m for leg in legs])]) / planned_len
        for k, leg_index in enumerate(run):
            if leg_index not in lines:
                continue
            inside = np.flatnonzero((fraction >= bounds[k]) & (fraction <= bounds[k + 1]))
            if inside.size < 2:
                continue
            a, b = first + int(inside[0]), first + int(inside[-1])
            out.append(FlownLine(leg_index, a, b, float(t_s[a]), float(t_s[b])))
    return out


def runs_as_plan(
    t_s: FloatArray, p_ne_m: FloatArray, *, min_line_m: float
) -> tuple[SurveyPlan, list[FlownLine]]:
    """Without a mission: the straight runs of a track as its lines, paired as a plan's would be.

    Returns
    -------
    plan : SurveyPlan
        Legs fitted to the runs (first to last sample), their pairs and the area between them.
    flown : list of FlownLine
    """
    from auvnav.coverage.plan import _convex_hull

    p = np.asarray(p_ne_m, dtype=float)
    runs = straight_runs(p, min_length_m=min_line_m)
    legs = [Leg(p[a].copy(), p[b].copy(), 0) for a, b in runs]
    pairs = [q for q in (_pair(legs, k, k + 1) for k in range(len(legs) - 1)) if q is not None]
    lines = tuple(sorted({q.a for q in pairs} | {q.b for q in pairs}))
    area = tuple(
        _convex_hull(
            np.stack([legs[q.a].start_ne_m, legs[q.a].end_ne_m, legs[q.b].start_ne_m, legs[q.b].end_ne_m])
        )
        for q in pairs
    )
    plan = SurveyPlan(
        tuple(legs), lines, tuple(pairs), tuple((k,) for k in range(len(legs))), area, 0.0, 0.0, "track"
    )
    flown = [FlownLine(k, a, b, float(t_s[a]), float(t_s[b])) for k, (a, b) in enumerate(runs) if k in lines]
    return plan, flown


def across_profile(
    p_ne_m: FloatArray,
    origin_ne_m: FloatArray,
    along_ne: FloatArray,
    across_ne: FloatArray,
    stations_m: FloatArray,
) -> FloatArray:
    """Across-track position of a line's track at stations along a direction, metres (NaN off its ends).

    Parameters
    ----------
    p_ne_m : ndarray, shape (N, 2)
        The line's samples, metres, local NED.
    origin_ne_m, along_ne, across_ne : ndarray, shape (2,)
        The frame: origin, unit vector along, unit vector across.
    stations_m : ndarray, shape (S,)
    """
    rel = np.asarray(p_ne_m, dtype=float) - origin_ne_m
    along, across = rel @ along_ne, rel @ across_ne
    order = np.argsort(along, kind="stable")
    if order.size < 2:
        return np.full(len(stations_m), np.nan)
    return np.interp(stations_m, along[order], across[order], left=np.nan, right=np.nan)


def pair_spacing(
    plan: SurveyPlan,
    flown: list[FlownLine],
    p_ne_m: FloatArray,
    *,
    station_m: float,
    margin_m: float,
    tolerance_m: float,
    planned: bool = True,
) -> list[PairSpacing]:
    """The spacing profile of every adjacent pair of the plan whose two lines were flown.

    Parameters
    ----------
    plan : SurveyPlan
    flown : list of FlownLine
        From :func:`match_lines` (or :func:`runs_as_plan`).
    p_ne_m : ndarray, shape (N, 2)
        The track the lines index, metres, local NED.
    station_m, margin_m, tolerance_m : float
        Station step, ends left out, and the on-plan tolerance, metres.
    planned : bool
        The plan is a mission's (False: runs of the track; the turn end's spacing is the reference).
    """
    p = np.asarray(p_ne_m, dtype=float)
    by_leg = {f.leg: f for f in flown}
    number = {leg: k for k, leg in enumerate(plan.lines)}
    out = []
    for pair in plan.pairs:
        fa, fb = by_leg.get(pair.a), by_leg.get(pair.b)
        if fa is None or fb is None:
            continue
        leg = plan.legs[pair.a]
        length = leg.length_m
        stations = np.arange(margin_m, length - margin_m + 1e-9, station_m)
        if stations.size == 0:
            stations = np.array([0.5 * length])
        xa = across_profile(p[fa.first : fa.last + 1], leg.start_ne_m, leg.unit, pair.across_ne, stations)
        xb = across_profile(p[fb.first : fb.last + 1], leg.start_ne_m, leg.unit, pair.across_ne, stations)
        spacing = xb - xa
        reference = pair.spacing_m
        if not planned:
            valid = np.flatnonzero(np.isfinite(spacing))
            ends = valid[-3:] if pair.turn_end_at_end else valid[:3]
            reference = float(np.mean(spacing[ends])) if ends.size else pair.spacing_m
        out.append(
            PairSpacing(
                pair=pair,
                line_a=number[pair.a],
                line_b=number[pair.b],
                along_m=stations,
                spacing_m=spacing,
                planned_m=pair.spacing_m if planned else None,
                reference_m=reference,
                tolerance_m=tolerance_m,
            )
        )
    return out


#: Gaps between two lines are looked for this far in from the lines' planned ends by default, metres:
#: there the vehicle turns onto and off the line (1.5 m of turn anticipation in the simulator's
#: guidance, a footprint's length, the overshoot), which leaves holes no heading error made.
LINE_END_M = 3.0


def pair_quad(
    pair: Pair, leg: Leg, a_ne_m: FloatArray, b_ne_m: FloatArray, *, end_m: float = LINE_END_M
) -> FloatArray | None:
    """The area between two flown lines: the quadrilateral of their across-track positions where both
    were flown, ``end_m`` in from line ``a``'s planned ends (north-east, metres), or None.

    Parameters
    ----------
    pair : Pair
    leg : Leg
        Line ``a``'s planned leg (the frame: along it from its start, across towards line ``b``).
    a_ne_m, b_ne_m : ndarray, shape (N, 2)
        The two lines' samples (two suffice for a straight line), local NED.
    end_m : float
    """
    u, v = leg.unit, pair.across_ne
    lo, hi = end_m, leg.length_m - end_m
    for pts in (a_ne_m, b_ne_m):
        along = (np.asarray(pts, dtype=float) - leg.start_ne_m) @ u
        lo, hi = max(lo, float(along.min())), min(hi, float(along.max()))
    if not hi > lo:
        return None
    stations = np.array([lo, hi])
    xa = across_profile(a_ne_m, leg.start_ne_m, u, v, stations)
    xb = across_profile(b_ne_m, leg.start_ne_m, u, v, stations)
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(xb))):
        return None
    at = [(stations[0], xa[0]), (stations[1], xa[1]), (stations[1], xb[1]), (stations[0], xb[0])]
    return np.array([leg.start_ne_m + s * u + x * v for s, x in at])
