"""Missions: what the vehicle is told to do, as generated geometry and as a YAML file.

Four generators give the paper's dive types (section III-A and IV-A):

- :func:`navcheck`: reciprocal legs on a star of evenly spaced headings through a common centre,
  then a regular grid over the centre (lines north-south, then east-west) that ties the arms
  together (the navigation check dive, paper section III-A and Fig. 4);
- :func:`survey`: a lead-in leg, then a full-coverage lawnmower of parallel reciprocal lines
  (the 75 m x 50 m, 1 m spacing survey after a 100 m leg of paper section IV-A, Fig. 8);
- :func:`transit`: long straight sub-sea legs at evenly spaced headings, each between GPS fixes at
  the surface (the transits that fix the compass correction's constant, paper section III-B);
- :func:`spin`: full turns on the spot at constant depth, for magnetometer calibration.

The mission file (format ``auvnav-mission/1``)
----------------------------------------------
::

    format: auvnav-mission/1
    name: survey
    speed_mps: 0.5          # nominal speed through the water on legs
    altitude_m: 2.0         # altitude above the seafloor while under way
    geometry: {width_m: 75.0, ...}     # optional: the generator's options, for the record
    segments:
      - {type: surface, duration_s: 120}         # at the surface; GPS fixes; the onboard
                                                 # navigation resets to them at the end
      - {type: descend}                          # straight down to altitude_m
      - {type: line, waypoints: [[0, 0], [100, 0], [175, 0], [175, 1]]}
                                                 # legs between waypoints [north_m, east_m],
                                                 # local NED about the dive's origin
      - {type: spin, turns: 3, rate_deg_s: 5, direction: cw}   # turns on the spot
      - {type: ascend}                           # straight up to the surface
      - {type: surface, duration_s: 120}

Keys are checked strictly: an unknown key, a wrong type or a negative length is an error naming the
file and the key. A ``line`` segment may override ``speed_mps`` and ``altitude_m``; ``descend`` and
``ascend`` may give ``rate_mps`` (default: the vehicle's vertical rate limit). When the vehicle is
more than a few metres from a ``line`` segment's first waypoint it first steers to it.

The survey's ``width_m`` is the length of each line (along the survey heading) and ``height_m`` the
extent across the lines: the paper's "75 m x 50 m with 1 m spacing" is 51 lines of 75 m.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from auvnav.config import dump_yaml, load_yaml, pydantic_problems, quote
from auvnav.errors import ConfigError
from auvnav.streams import atomic_write

FORMAT = "auvnav-mission/1"
MissionKind = Literal["navcheck", "survey", "transit", "spin"]
KINDS: tuple[str, ...] = ("navcheck", "survey", "transit", "spin")

# Vehicle defaults of the paper's class (ACFR's Sirius: about 0.5 m/s at 2 m altitude for stereo
# imaging; Williams et al. 2012, "Monitoring of benthic reference sites", IEEE RAM 19(1)).
DEFAULT_SPEED_MPS = 0.5
DEFAULT_ALTITUDE_M = 2.0
DEFAULT_SURFACE_S = 120.0  # time at the surface for GPS fixes before and after each dive
DEFAULT_SPIN_RATE_DEG_S = 5.0

# Bounds of a mission a vehicle could fly (the simulator allocates by duration and extent).
#: Farthest waypoint from the origin, metres (the longest AUV transits are tens of kilometres).
MAX_EXTENT_M = 100e3
#: Longest planned mission, seconds (the longest AUV dives last about a day).
MAX_DURATION_S = 48 * 3600.0
#: Most waypoints in a mission (a 75 m x 50 m survey at 1 m spacing has about 100).
MAX_WAYPOINTS = 100_000
#: Fastest and slowest speed, m/s; highest altitude, metres; fastest spin, deg/s.
SPEED_RANGE_MPS = (0.01, 10.0)
MAX_ALTITUDE_M = 1000.0
MAX_SPIN_RATE_DEG_S = 90.0
#: Vertical rate and water depth assumed when the duration of a mission is bounded (the simulator's
#: defaults are of this order).
_BOUND_VERTICAL_RATE_MPS = 0.5
_BOUND_WATER_DEPTH_M = 0.0


# ---------------------------------------------------------------------------------------------
# Segments and missions (SI units, radians)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Surface:
    """Wait at the surface for ``duration_s``; GPS fixes; the onboard navigation resets to them."""

    duration_s: float = DEFAULT_SURFACE_S


@dataclass(frozen=True)
class Descend:
    """Descend straight down to the mission altitude; ``rate_mps`` None = the vehicle's limit."""

    rate_mps: float | None = None


@dataclass(frozen=True)
class Ascend:
    """Ascend straight up to the surface; ``rate_mps`` None = the vehicle's limit."""

    rate_mps: float | None = None


@dataclass(frozen=True)
class Line:
    """Follow the legs between waypoints.

    Parameters
    ----------
    waypoints_ne_m : tuple of (north_m, east_m)
        At least one point, metres, local NED about the dive's origin.
    speed_mps, altitude_m : float or None
        Overrides of the mission's nominal values.
    """

    waypoints_ne_m: tuple[tuple[float, float], ...]
    speed_mps: float | None = None
    altitude_m: float | None = None

    def length_m(self) -> float:
        """Length of the legs between the waypoints, metres."""
        w = self.waypoints_ne_m
        return sum(math.dist(a, b) for a, b in itertools.pairwise(w))


@dataclass(frozen=True)
class Spin:
    """Turn on the spot through ``turns`` full turns at ``rate_rad_s``, clockwise seen from above
    when ``direction`` is +1, at constant depth."""

    turns: float
    rate_rad_s: float = math.radians(DEFAULT_SPIN_RATE_DEG_S)
    direction: Literal[1, -1] = 1


Segment = Surface | Descend | Ascend | Line | Spin


@dataclass(frozen=True)
class Mission:
    """A mission: nominal speed and altitude and a sequence of segments.

    Parameters
    ----------
    name : str
    segments : tuple of Segment
    speed_mps : float
        Nominal speed on legs, m/s.
    altitude_m : float
        Nominal altitude above the seafloor, metres.
    geometry : dict
        The generator's options (file units), kept for the record.
    """

    name: str
    segments: tuple[Segment, ...]
    speed_mps: float = DEFAULT_SPEED_MPS
    altitude_m: float = DEFAULT_ALTITUDE_M
    geometry: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.segments:
            raise ValueError("a mission needs at least one segment")
        if not (self.speed_mps > 0 and self.altitude_m > 0):
            raise ValueError(
                f"speed_mps and altitude_m must be positive; found {self.speed_mps}, {self.altitude_m}"
            )
        object.__setattr__(self, "segments", tuple(self.segments))

    def line_length_m(self) -> float:
        """Total length of the planned legs, metres."""
        return sum(s.length_m() for s in self.segments if isinstance(s, Line))

    def planned_duration_s(self, vertical_rate_mps: float, water_depth_m: float) -> float:
        """A rough duration, seconds: legs at nominal speed, vertical moves, spins, surface waits."""
        total = 0.0
        for s in self.segments:
            if isinstance(s, Surface):
                total += s.duration_s
            elif isinstance(s, Line):
                total += s.length_m() / (s.speed_mps or self.speed_mps)
            elif isinstance(s, Spin):
                total += s.turns * 2 * math.pi / s.rate_rad_s
            else:
                total += water_depth_m / (s.rate_mps or vertical_rate_mps)
        return total

    def summary(self) -> dict[str, Any]:
        """Counts and lengths, for reports and truth.yaml."""
        counts: dict[str, int] = {}
        for s in self.segments:
            counts[type(s).__name__.lower()] = counts.get(type(s).__name__.lower(), 0) + 1
        legs = sum(max(len(s.waypoints_ne_m) - 1, 0) for s in self.segments if isinstance(s, Line))
        return {
            "name": self.name,
            "speed_mps": self.speed_mps,
            "altitude_m": self.altitude_m,
            "segments": counts,
            "legs": legs,
            "line_length_m": self.line_length_m(),
            "geometry": dict(self.geometry),
        }


# ---------------------------------------------------------------------------------------------
# Generators
# ---------------------------------------------------------------------------------------------


def _positive(**values: float) -> None:
    for name, v in values.items():
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ConfigError(f"mission option {name} must be a positive number; found {quote(v)}")
        if v > MAX_EXTENT_M:
            raise ConfigError(f"mission option {name} must be at most {MAX_EXTENT_M:g} m; found {v:g}")


def _count(name: str, n: int) -> None:
    """Refuse options that would make more than :data:`MAX_WAYPOINTS` waypoints (before making them)."""
    if n > MAX_WAYPOINTS // 2:
        raise ConfigError(f"mission options give {n:.3g} {name}; at most {MAX_WAYPOINTS // 2}")


def _unit(heading_rad: float) -> tuple[float, float]:
    return math.cos(heading_rad), math.sin(heading_rad)


def _dive(name: str, lines: list[Line], geometry: dict[str, Any], **nominal: float) -> Mission:
    """Surface, descend, the lines, ascend, surface."""
    segments: list[Segment] = [Surface(), Descend(), *lines, Ascend(), Surface()]
    return Mission(name=name, segments=tuple(segments), geometry=geometry, **nominal)


def navcheck(
    *, headings: int = 12, leg_m: float = 50.0, grid_m: float = 10.0, grid_spacing_m: float = 1.0
) -> Mission:
    """The navigation check dive (paper section III-A): a star of reciprocal legs plus a grid.

    Parameters
    ----------
    headings : int
        Number of arms, evenly spaced from north (12: every 30 degrees).
    leg_m : float
        Length of each arm, metres; the vehicle flies out from the centre and back.
    grid_m : float
        Side of the square grid centred on the star, metres.
    grid_spacing_m : float
        Spacing of the grid's lines, metres; north-south lines, then east-west lines.

    Returns
    -------
    Mission
        Centred on the dive's origin, where the vehicle descends.
    """
    if not isinstance(headings, int) or headings < 1:
        raise ConfigError(f"mission option headings must be a positive integer; found {quote(headings)}")
    _positive(leg_m=leg_m, grid_m=grid_m, grid_spacing_m=grid_spacing_m)
    _count("headings", headings)
    _count("grid lines (grid_m / grid_spacing_m + 1)", math.floor(grid_m / grid_spacing_m + 1e-9) + 1)
    points: list[tuple[float, float]] = [(0.0, 0.0)]
    for k in range(headings):
        un, ue = _unit(2 * math.pi * k / headings)
        points += [(leg_m * un, leg_m * ue), (0.0, 0.0)]
    n_lines = math.floor(grid_m / grid_spacing_m + 1e-9) + 1
    half = grid_m / 2
    offsets = [-half + i * grid_spacing_m for i in range(n_lines)]
    for i, x in enumerate(offsets):  # north-south lines at east = x, alternating direction
        n0 = -half if i % 2 == 0 else half
        points += [(n0, x), (-n0, x)]
    last_n, last_e = points[-1]
    rows = offsets[::-1] if last_n > 0 else offsets  # east-west lines from the corner reached
    for i, y in enumerate(rows):  # east-west lines at north = y, alternating direction
        e0 = math.copysign(half, last_e) * (1 if i % 2 == 0 else -1)
        points += [(y, e0), (y, -e0)]
    geometry = {"headings": headings, "leg_m": leg_m, "grid_m": grid_m, "grid_spacing_m": grid_spacing_m}
    return _dive("navcheck", [Line(tuple(points))], geometry)


def survey(
    *,
    width_m: float = 75.0,
    height_m: float = 50.0,
    spacing_m: float = 1.0,
    lead_in_m: float = 100.0,
    heading_deg: float = 0.0,
) -> Mission:
    """A full-coverage lawnmower after a lead-in leg (paper section IV-A).

    Parameters
    ----------
    width_m : float
        Length of each line, metres (along ``heading_deg``).
    height_m : float
        Extent across the lines, metres; ``floor(height_m / spacing_m) + 1`` lines, stepping to the
        right of the survey heading.
    spacing_m : float
        Distance between adjacent lines, metres.
    lead_in_m : float
        Length of the leg from the origin to the first line, metres, along ``heading_deg``
        (0 for none).
    heading_deg : float
        Direction of the first line, degrees clockwise from true north.

    Returns
    -------
    Mission
    """
    _positive(width_m=width_m, height_m=height_m, spacing_m=spacing_m)
    if not (math.isfinite(lead_in_m) and 0 <= lead_in_m <= MAX_EXTENT_M):
        raise ConfigError(f"mission option lead_in_m must be in [0, {MAX_EXTENT_M:g}] m; found {lead_in_m!r}")
    if not math.isfinite(heading_deg):
        raise ConfigError(f"mission option heading_deg must be finite; found {heading_deg!r}")
    _count("lines (height_m / spacing_m + 1)", math.floor(height_m / spacing_m + 1e-9) + 1)
    heading = math.radians(heading_deg)
    un, ue = _unit(heading)
    rn, re = _unit(heading + math.pi / 2)
    n_lines = math.floor(height_m / spacing_m + 1e-9) + 1
    start = (lead_in_m * un, lead_in_m * ue)
    points: list[tuple[float, float]] = [(0.0, 0.0)] if lead_in_m > 0 else []
    for i in range(n_lines):
        across = (start[0] + i * spacing_m * rn, start[1] + i * spacing_m * re)
        far = (across[0] + width_m * un, across[1] + width_m * ue)
        points += [across, far] if i % 2 == 0 else [far, across]
    geometry = {
        "width_m": width_m,
        "height_m": height_m,
        "spacing_m": spacing_m,
        "lead_in_m": lead_in_m,
        "heading_deg": heading_deg,
        "lines": n_lines,
    }
    return _dive("survey", [Line(tuple(points))], geometry)


def transit(*, legs: int = 4, leg_m: float = 2000.0, heading_deg: float = 0.0) -> Mission:
    """Straight sub-sea legs at evenly spaced headings, each between GPS fixes at the surface.

    Leg ``k`` heads ``heading_deg + k * 360 / legs`` and starts where the previous one ended, so
    four legs make a closed square. The vehicle surfaces after each leg.

    Parameters
    ----------
    legs : int
    leg_m : float
        Length of each leg, metres.
    heading_deg : float
        Heading of the first leg, degrees clockwise from true north.
    """
    if not isinstance(legs, int) or legs < 1:
        raise ConfigError(f"mission option legs must be a positive integer; found {quote(legs)}")
    _positive(leg_m=leg_m)
    _count("legs", legs)
    if not math.isfinite(heading_deg):
        raise ConfigError(f"mission option heading_deg must be finite; found {heading_deg!r}")
    segments: list[Segment] = [Surface()]
    here = (0.0, 0.0)
    for k in range(legs):
        un, ue = _unit(math.radians(heading_deg) + 2 * math.pi * k / legs)
        there = (here[0] + leg_m * un, here[1] + leg_m * ue)
        segments += [Descend(), Line((here, there)), Ascend(), Surface()]
        here = there
    geometry = {"legs": legs, "leg_m": leg_m, "heading_deg": heading_deg}
    return Mission(name="transit", segments=tuple(segments), geometry=geometry)


def spin(*, turns: float = 3.0, rate_deg_s: float = DEFAULT_SPIN_RATE_DEG_S) -> Mission:
    """Full turns on the spot at constant depth for magnetometer calibration.

    Parameters
    ----------
    turns : float
        Number of full clockwise turns.
    rate_deg_s : float
        Turn rate, degrees per second.
    """
    _positive(turns=turns, rate_deg_s=rate_deg_s)
    if rate_deg_s > MAX_SPIN_RATE_DEG_S:
        raise ConfigError(
            f"mission option rate_deg_s must be at most {MAX_SPIN_RATE_DEG_S:g}; found {rate_deg_s:g}"
        )
    segments: list[Segment] = [
        Surface(),
        Descend(),
        Spin(turns=float(turns), rate_rad_s=math.radians(rate_deg_s)),
        Ascend(),
        Surface(),
    ]
    return Mission(name="spin", segments=tuple(segments), geometry={"turns": turns, "rate_deg_s": rate_deg_s})


GENERATORS = {"navcheck": navcheck, "survey": survey, "transit": transit, "spin": spin}


def build_mission(kind: str, options: dict[str, Any]) -> Mission:
    """A generated mission from its kind and the options that were given (None = default).

    Raises
    ------
    ConfigError
        Unknown kind, or an option that this kind does not take.
    """
    if kind not in GENERATORS:
        raise ConfigError(f"unknown mission kind {kind!r}; expected one of {', '.join(KINDS)}")
    generator = GENERATORS[kind]
    given = {k: v for k, v in options.items() if v is not None}
    accepted = generator.__kwdefaults__ or {}
    foreign = sorted(k for k in given if k not in accepted)
    if foreign:
        names = ", ".join("--" + k.replace("_", "-") for k in foreign)
        raise ConfigError(f"{names}: not an option of the {kind} mission")
    mission = generator(**given)
    check_bounds(mission, f"the {kind} mission's options")
    return mission


def survey_line_spacing(
    p_ne_m: NDArray[np.float64],
    onboard_ne_m: NDArray[np.float64],
    mission: Mission,
    *,
    margin_m: float = 10.0,
    station_m: float = 1.0,
) -> NDArray[np.float64]:
    """Spacing between adjacent lines of a flown :func:`survey`, at stations along the lines.

    Each line's samples are those whose *onboard* position lies on it (within half a spacing of the
    planned line, at least ``margin_m`` from its ends: the straight part the vehicle believed it
    flew); their *true* across-track positions are interpolated at stations every ``station_m``
    along the line (in true along-track coordinates). With onboard positions for ``p_ne_m`` too
    this measures the spacing the vehicle believed.

    Parameters
    ----------
    p_ne_m : ndarray, shape (N, 2), metres, local NED (north, east)
        The track to measure (e.g. the truth).
    onboard_ne_m : ndarray, shape (N, 2), metres, local NED
        The vehicle's onboard track at the same times (to tell the lines apart).
    mission : Mission
        Made by :func:`survey` (its geometry is read).
    margin_m, station_m : float
        Metres left out at each end of a line; station spacing.

    Returns
    -------
    ndarray, shape (lines - 1, stations), metres
        Across-track distance from line i to line i + 1 (positive: in the planned direction, to the
        right of the survey heading); NaN where a line does not reach a station.
    """
    g = mission.geometry
    if not {"width_m", "spacing_m", "lead_in_m", "heading_deg", "lines"} <= set(g):
        raise ValueError("survey_line_spacing needs a mission made by survey() (its geometry keys)")
    heading = math.radians(g["heading_deg"])
    u = np.array([math.cos(heading), math.sin(heading)])
    v = np.array([-u[1], u[0]])
    start = g["lead_in_m"] * u
    along_ob, across_ob = (onboard_ne_m - start) @ u, (onboard_ne_m - start) @ v
    along, across = (p_ne_m - start) @ u, (p_ne_m - start) @ v
    width, spacing = float(g["width_m"]), float(g["spacing_m"])
    stations = np.arange(margin_m, width - margin_m + 1e-9, station_m)
    middle = (along_ob >= margin_m - station_m) & (along_ob <= width - margin_m + station_m)
    positions = np.full((int(g["lines"]), stations.size), np.nan)
    for i in range(int(g["lines"])):
        on_line = middle & (np.abs(across_ob - i * spacing) < spacing / 2)
        if np.count_nonzero(on_line) < 2:
            continue
        order = np.argsort(along[on_line])
        positions[i] = np.interp(
            stations, along[on_line][order], across[on_line][order], left=np.nan, right=np.nan
        )
    return np.diff(positions, axis=0)


# ---------------------------------------------------------------------------------------------
# The file
# ---------------------------------------------------------------------------------------------


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


_Speed = Annotated[float, Field(ge=SPEED_RANGE_MPS[0], le=SPEED_RANGE_MPS[1])]
_Altitude = Annotated[float, Field(gt=0, le=MAX_ALTITUDE_M)]
_Coordinate = Annotated[float, Field(ge=-MAX_EXTENT_M, le=MAX_EXTENT_M)]


class _SurfaceFile(_Strict):
    type: Literal["surface"]
    duration_s: float = Field(default=DEFAULT_SURFACE_S, gt=0, le=MAX_DURATION_S)


class _DescendFile(_Strict):
    type: Literal["descend"]
    rate_mps: _Speed | None = None


class _AscendFile(_Strict):
    type: Literal["ascend"]
    rate_mps: _Speed | None = None


class _LineFile(_Strict):
    type: Literal["line"]
    waypoints: list[Annotated[list[_Coordinate], Field(min_length=2, max_length=2)]] = Field(
        min_length=1, max_length=MAX_WAYPOINTS
    )
    speed_mps: _Speed | None = None
    altitude_m: _Altitude | None = None


class _SpinFile(_Strict):
    type: Literal["spin"]
    turns: float = Field(gt=0, le=1000)
    rate_deg_s: float = Field(default=DEFAULT_SPIN_RATE_DEG_S, gt=0, le=MAX_SPIN_RATE_DEG_S)
    direction: Literal["cw", "ccw"] = "cw"


_SegmentFile = Annotated[
    _SurfaceFile | _DescendFile | _AscendFile | _LineFile | _SpinFile, Field(discriminator="type")
]


class _MissionFile(_Strict):
    format: Literal["auvnav-mission/1"]
    name: str = "mission"
    speed_mps: _Speed = DEFAULT_SPEED_MPS
    altitude_m: _Altitude = DEFAULT_ALTITUDE_M
    geometry: dict[str, Any] = {}
    segments: list[_SegmentFile] = Field(min_length=1, max_length=MAX_WAYPOINTS)


def _segment(f: Any) -> Segment:
    if isinstance(f, _SurfaceFile):
        return Surface(f.duration_s)
    if isinstance(f, _DescendFile):
        return Descend(f.rate_mps)
    if isinstance(f, _AscendFile):
        return Ascend(f.rate_mps)
    if isinstance(f, _LineFile):
        return Line(tuple((float(n), float(e)) for n, e in f.waypoints), f.speed_mps, f.altitude_m)
    return Spin(f.turns, math.radians(f.rate_deg_s), 1 if f.direction == "cw" else -1)


def mission_from_mapping(data: Any, display: str = "mission") -> Mission:
    """A mission from the parsed YAML mapping; :class:`ConfigError` naming the key otherwise."""
    if not isinstance(data, dict):
        raise ConfigError(f"{display}: must be a mapping with format: {FORMAT}")
    try:
        f = _MissionFile.model_validate(data)
    except ValidationError as err:
        first = pydantic_problems(err, display)[0]
        more = f" (and {len(err.errors()) - 1} more problems)" if len(err.errors()) > 1 else ""
        raise ConfigError(f"{first}{more}") from None
    mission = Mission(
        name=f.name,
        segments=tuple(_segment(s) for s in f.segments),
        speed_mps=f.speed_mps,
        altitude_m=f.altitude_m,
        geometry=dict(f.geometry),
    )
    check_bounds(mission, display)
    return mission


def check_bounds(mission: Mission, display: str = "mission") -> None:
    """Raise :class:`ConfigError` for a mission no vehicle could fly: a waypoint farther than
    :data:`MAX_EXTENT_M` from the origin, more than :data:`MAX_WAYPOINTS` waypoints, or longer than
    :data:`MAX_DURATION_S` (legs at their speed, spins, surface waits; vertical moves not counted)."""
    n = sum(len(s.waypoints_ne_m) for s in mission.segments if isinstance(s, Line))
    if n > MAX_WAYPOINTS:
        raise ConfigError(f"{display}: {n} waypoints; a mission has at most {MAX_WAYPOINTS}")
    for s in mission.segments:
        if isinstance(s, Line):
            far = max(math.hypot(north, east) for north, east in s.waypoints_ne_m)
            if not far <= MAX_EXTENT_M:
                raise ConfigError(
                    f"{display}: a waypoint {far:.3g} m from the origin; a mission stays within "
                    f"{MAX_EXTENT_M / 1e3:g} km of it"
                )
    duration = mission.planned_duration_s(_BOUND_VERTICAL_RATE_MPS, _BOUND_WATER_DEPTH_M)
    if not duration <= MAX_DURATION_S:
        raise ConfigError(
            f"{display}: the mission would last {duration / 3600:.3g} h; at most {MAX_DURATION_S / 3600:g} h"
        )


def _segment_yaml(s: Segment) -> dict[str, Any]:
    if isinstance(s, Surface):
        return {"type": "surface", "duration_s": s.duration_s}
    if isinstance(s, Descend | Ascend):
        out: dict[str, Any] = {"type": type(s).__name__.lower()}
        if s.rate_mps is not None:
            out["rate_mps"] = s.rate_mps
        return out
    if isinstance(s, Line):
        out = {"type": "line", "waypoints": [[n, e] for n, e in s.waypoints_ne_m]}
        if s.speed_mps is not None:
            out["speed_mps"] = s.speed_mps
        if s.altitude_m is not None:
            out["altitude_m"] = s.altitude_m
        return out
    return {
        "type": "spin",
        "turns": s.turns,
        "rate_deg_s": math.degrees(s.rate_rad_s),
        "direction": "cw" if s.direction == 1 else "ccw",
    }


def mission_to_mapping(mission: Mission) -> dict[str, Any]:
    """The ``auvnav-mission/1`` mapping (file units)."""
    return {
        "format": FORMAT,
        "name": mission.name,
        "speed_mps": mission.speed_mps,
        "altitude_m": mission.altitude_m,
        "geometry": dict(mission.geometry),
        "segments": [_segment_yaml(s) for s in mission.segments],
    }


def read_mission(path: Path) -> Mission:
    """Read a mission file (strict YAML, :func:`auvnav.config.load_yaml`); :class:`ConfigError` with
    one line naming the file and problem."""
    path = Path(path)
    data, problems = load_yaml(path, str(path))
    if problems:
        raise ConfigError(str(problems[0]))
    return mission_from_mapping(data, str(path))


def write_mission(mission: Mission, path: Path) -> None:
    """Write a mission file (atomically); one flow-style line per segment."""
    head = {k: v for k, v in mission_to_mapping(mission).items() if k != "segments"}
    lines = [dump_yaml(head, default_flow_style=None, width=100).rstrip(), "segments:"]
    for s in mission.segments:
        text = dump_yaml(_segment_yaml(s), default_flow_style=True, width=10**9)
        lines.append(f"  - {text.strip()}")
    atomic_write(Path(path), lambda p: p.write_text("\n".join(lines) + "\n", encoding="utf-8"))


__all__ = [
    "FORMAT",
    "KINDS",
    "Ascend",
    "Descend",
    "Line",
    "Mission",
    "Segment",
    "Spin",
    "Surface",
    "build_mission",
    "mission_from_mapping",
    "mission_to_mapping",
    "navcheck",
    "read_mission",
    "spin",
    "survey",
    "survey_line_spacing",
    "transit",
    "write_mission",
]
