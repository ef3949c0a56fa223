"""Coverage of a dive's images: footprints on a map grid, the planned area's coverage and gaps, overlap,
and the spacing of adjacent lines (the paper's 'accordion' and 'figure 8', Fig. 2).

:func:`analyse_coverage` is the one computation, used alike on a dive's navigation (the coverage
stage) and on a simulated dive's truth (``auvnav evaluate``):

1. **Footprints.** Each stereo pair's footprint is where both cameras see the floor
   (:func:`auvnav.footprint.stereo_footprints`), or the left camera's alone, on a horizontal floor at
   the depth the caller gives for each image (the DVL's altitude below the DVL, or the true seafloor).
2. **Images per cell** on a map grid in the UTM zone of the dive's origin (:mod:`auvnav.raster`), a
   cell counting an image when its centre lies in the footprint (:mod:`auvnav.coverage.grid`).
3. **The region**: the mission's planned area (:mod:`auvnav.coverage.plan`), or without a mission the
   area between the adjacent lines the track flew. Its **coverage** is the percentage of its cells
   seen by at least ``min_images`` images. Its **gaps** are the holes *between the flown lines*
   (the paper's 'accordion'): connected regions of cells no image saw, inside both the region and
   the area between adjacent flown lines (each pair's quadrilateral where both lines were flown,
   ``line_end_m`` in from their ends, where the vehicle turns: :func:`~auvnav.coverage.lines.
   pair_quad`), at least ``min_gap_area_m2`` in area, each with its width (largest inscribed disc)
   and place. The region's other unseen cells lie outside the flown lines or at their ends (a survey
   that fell short of or beside its planned area: a 'figure 8' compresses the lines, a heading
   offset moves them; the turns): they count against the coverage as **not surveyed**, and are not
   gaps.
4. **Overlap**: the histogram of images per cell (area per count, in the region and everywhere
   imaged) and the along-track overlap of consecutive images (their intersection over the smaller,
   :func:`auvnav.footprint.polygon_overlaps`).
5. **Lines**: the flown lines matched to the planned ones and each adjacent pair's spacing profile,
   classified on plan, accordion or figure 8 (:mod:`auvnav.coverage.lines`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from auvnav.coverage.grid import Gaps, count_polygons, find_gaps, ground_cell_area_m2, polygon_mask
from auvnav.coverage.lines import (
    LINE_END_M,
    FlownLine,
    PairSpacing,
    match_lines,
    pair_quad,
    pair_spacing,
    runs_as_plan,
)
from auvnav.coverage.plan import MIN_LINE_M, SurveyPlan
from auvnav.dive import Dive
from auvnav.errors import InsufficientDataError
from auvnav.footprint import footprints_on_plane, polygon_overlaps, stereo_footprints
from auvnav.frames import FloatArray, GeodeticOrigin, se3
from auvnav.raster import MapGrid
from auvnav.trajectory import Trajectory
from auvnav.vehicle import StereoRig

log = logging.getLogger(__name__)

FootprintKind = Literal["stereo", "left"]
#: Images whose camera is less than this above the floor, or more than :data:`MAX_CAMERA_HEIGHT_M`,
#: are left out (a floor estimate gone wrong, the vehicle at the surface), metres.
MIN_CAMERA_HEIGHT_M = 0.2
MAX_CAMERA_HEIGHT_M = 15.0
#: The largest grid made, cells (about 1.6 GB of counts and masks): a track far off its survey.
MAX_CELLS = 200_000_000
#: Histogram bins of images per cell: 0, 1, ..., the last one counting that many or more.
HISTOGRAM_BINS = 11
#: Consecutive images further apart in time than this many median intervals are not compared.
BREAK_INTERVALS = 1.5


@dataclass(frozen=True)
class CoverageOptions:
    """How coverage is measured (the coverage stage's settings, in SI units).

    Parameters
    ----------
    cell_m : float
        Side of a grid cell, metres.
    footprint : {"stereo", "left"}
        Where both cameras see, or the left camera's footprint.
    min_images : int
        A cell is covered when at least this many images see it.
    min_gap_area_m2 : float
        Smaller uncovered regions are not gaps, m^2.
    gap_width_m : float
        Gaps at least this wide are counted apart (``count_wider``), metres.
    station_m, margin_m : float
        Spacing stations along the lines, and the ends left out, metres.
    tolerance_m : float
        A pair is on plan while its spacing stays within this of the plan, metres.
    min_line_m : float
        Shortest survey line, metres.
    line_end_m : float
        Gaps between two lines are looked for this far in from their ends (the vehicle turns there).
    """

    cell_m: float = 0.05
    footprint: FootprintKind = "stereo"
    min_images: int = 1
    min_gap_area_m2: float = 0.01
    gap_width_m: float = 0.5
    station_m: float = 1.0
    margin_m: float = 10.0
    tolerance_m: float = 0.1
    min_line_m: float = MIN_LINE_M
    line_end_m: float = LINE_END_M

    @classmethod
    def from_settings(cls, settings: dict[str, Any]) -> CoverageOptions:
        """The options of the coverage stage's settings (as ``summary.json`` records them)."""
        return cls(
            cell_m=float(settings["cell_m"]),
            footprint=settings["footprint"],
            min_images=int(settings["min_images"]),
            min_gap_area_m2=float(settings["min_gap_area_m2"]),
            gap_width_m=float(settings["gap_width_m"]),
            station_m=float(settings["station_m"]),
            margin_m=float(settings["line_margin_m"]),
            tolerance_m=float(settings["tolerance_m"]),
            min_line_m=float(settings["min_line_m"]),
            line_end_m=float(settings.get("line_end_m", LINE_END_M)),
        )

    def __post_init__(self) -> None:
        positive = ("cell_m", "station_m", "min_line_m")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive; found {getattr(self, name)}")
        if self.min_images < 1:
            raise ValueError(f"min_images must be at least 1; found {self.min_images}")


@dataclass(frozen=True)
class Coverage:
    """What :func:`analyse_coverage` measured (module docstring).

    Parameters
    ----------
    grid : MapGrid
    counts : ndarray of uint16, shape (H, W)
        Images per cell.
    region : ndarray of bool, shape (H, W)
        The planned area (or the flown lines' area); all False when there is none.
    region_kind : {"planned", "flown lines", "none"}
    between : ndarray of bool, shape (H, W)
        The region's cells between adjacent flown lines, where gaps are looked for.
    gaps : Gaps
    cell_area_m2 : float
        Ground area of a cell.
    t_s : ndarray, shape (P,)
        Times of the images used.
    footprints_ne_m : ndarray, shape (P, K, 2)
    along_overlap : ndarray, shape (P - 1,)
        Overlap of each image with the next (NaN across a break in the images).
    plan : SurveyPlan or None
        The lines and pairs used (the mission's, or the track's runs).
    flown : list of FlownLine
    pairs : list of PairSpacing
    options : CoverageOptions
    dropped : int
        Images left out (camera height out of range, or outside the trajectory).
    """

    grid: MapGrid
    counts: NDArray[np.uint16]
    region: NDArray[np.bool_]
    region_kind: Literal["planned", "flown lines", "none"]
    between: NDArray[np.bool_]
    gaps: Gaps
    cell_area_m2: float
    t_s: FloatArray
    footprints_ne_m: FloatArray
    along_overlap: FloatArray
    plan: SurveyPlan | None
    flown: list[FlownLine]
    pairs: list[PairSpacing]
    options: CoverageOptions
    dropped: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def covered(self) -> NDArray[np.bool_]:
        return self.counts >= self.options.min_images

    def coverage_pct(self) -> float | None:
        """Percentage of the region's cells that are covered; None without a region."""
        n = int(np.count_nonzero(self.region))
        if n == 0:
            return None
        return 100.0 * int(np.count_nonzero(self.region & self.covered)) / n

    def summary(self) -> dict[str, Any]:
        """The figures of ``summary.json`` (module docstring)."""
        a = self.cell_area_m2
        gaps = self.gaps
        region_cells = int(np.count_nonzero(self.region))
        clipped = np.minimum(self.counts, HISTOGRAM_BINS - 1)
        hist_all = np.bincount(clipped.ravel(), minlength=HISTOGRAM_BINS)
        hist_region = np.bincount(clipped[self.region], minlength=HISTOGRAM_BINS)
        ov = self.along_overlap[np.isfinite(self.along_overlap)]
        classes = [p.classification for p in self.pairs]
        spacing = np.concatenate([p.spacing_m[p.valid] for p in self.pairs]) if self.pairs else np.zeros(0)
        planned = [p.planned_m for p in self.pairs if p.planned_m is not None]
        wider = gaps.width_m >= self.options.gap_width_m
        largest = None
        if len(gaps):
            largest = {
                "area_m2": float(gaps.area_m2[0]),
                "width_m": float(gaps.width_m[0]),
                "north_m": float(gaps.centroid_ne_m[0, 0]),
                "east_m": float(gaps.centroid_ne_m[0, 1]),
            }
        return {
            "images": len(self.t_s),
            "images_dropped": self.dropped,
            "footprint": "stereo overlap" if self.options.footprint == "stereo" else "left camera",
            "cell_m": self.grid.cell_m,
            "cell_area_m2": a,
            "grid": {
                "width": self.grid.width,
                "height": self.grid.height,
                "x0_m": self.grid.x0_m,
                "y0_m": self.grid.y0_m,
            },
            "imaged_area_m2": float(np.count_nonzero(self.covered)) * a,
            "region": self.region_kind,
            "region_area_m2": region_cells * a,
            "coverage_pct": self.coverage_pct(),
            "gaps": {
                "count": len(gaps),
                "area_m2": float(gaps.area_m2.sum()),
                "uncovered_area_m2": float(np.count_nonzero(self.region & ~self.covered)) * a,
                "not_surveyed_m2": float(np.count_nonzero(self.region & ~self.covered & ~self.between)) * a,
                "min_area_m2": self.options.min_gap_area_m2,
                "wider_than_m": self.options.gap_width_m,
                "count_wider": int(np.count_nonzero(wider)),
                "widest_m": float(gaps.width_m.max()) if len(gaps) else 0.0,
                "largest": largest,
            },
            "overlap_histogram": {
                "images": [*range(HISTOGRAM_BINS - 1), f"{HISTOGRAM_BINS - 1}+"],
                "area_m2": (hist_all * a).tolist(),
                "region_area_m2": (hist_region * a).tolist(),
            },
            "along_track_overlap": {
                "pairs": int(ov.size),
                "median": float(np.median(ov)) if ov.size else None,
                "p05": float(np.percentile(ov, 5)) if ov.size else None,
                "min": float(ov.min()) if ov.size else None,
            },
            "lines": {
                "planned": 0 if self.plan is None else len(self.plan.lines),
                "flown": len(self.flown),
                "pairs": len(self.pairs),
                "planned_spacing_m": float(np.median(planned)) if planned else None,
                "spacing_mean_m": float(spacing.mean()) if spacing.size else None,
                "spacing_min_m": float(spacing.min()) if spacing.size else None,
                "spacing_max_m": float(spacing.max()) if spacing.size else None,
                "on_plan": classes.count("on plan"),
                "accordion": classes.count("accordion"),
                "figure_8": classes.count("figure 8"),
                "tolerance_m": self.options.tolerance_m,
            },
            **self.extra,
        }


def image_poses(dive: Dive, trajectory: Trajectory) -> tuple[Trajectory, int]:
    """The trajectory at the dive's image times that lie inside it, and how many lie outside."""
    if dive.images is None:
        raise InsufficientDataError("the dive has no images (images/index.csv)")
    t = dive.images.t_s
    inside = (t >= trajectory.t_s[0]) & (t <= trajectory.t_s[-1])
    return trajectory.interpolate(t[inside]), int(np.count_nonzero(~inside))


def image_altitude_m(dive: Dive, t_s: FloatArray, fallback_m: float | None = None) -> FloatArray:
    """The DVL's altitude at times ``t_s`` (its valid samples interpolated), or ``fallback_m``.

    Raises
    ------
    InsufficientDataError
        The DVL gives fewer than two altitudes and there is no fallback.
    """
    dvl = dive.dvl
    ok = (
        np.zeros(len(dvl.t_s), bool)
        if dvl.altitude_m is None
        else dvl.valid & np.isfinite(dvl.altitude_m) & (dvl.altitude_m > 0)
    )
    if np.count_nonzero(ok) >= 2:
        return np.interp(t_s, dvl.t_s[ok], dvl.altitude_m[ok])
    if fallback_m is not None:
        log.warning("nav/dvl: no altitude; the footprints use an altitude of %.2f m", fallback_m)
        return np.full(len(t_s), float(fallback_m))
    raise InsufficientDataError(
        "nav/dvl has no altitude (altitude_m): give --altitude-m to place the footprints"
    )


def floor_below_dvl(poses: Trajectory, altitude_m: FloatArray, dvl_lever_body_m: FloatArray) -> FloatArray:
    """Depth of the floor under each pose: the DVL's depth plus its altitude, metres, positive down."""
    dvl_down = poses.p_ned_m[:, 2] + (poses.R_ned_body @ np.asarray(dvl_lever_body_m, dtype=float))[:, 2]
    return dvl_down + np.asarray(altitude_m, dtype=float)


#: The floor under a camera is looked for in the DVL's altitudes within this time of the image, s.
FLOOR_WINDOW_S = 6.0
#: ... where the DVL passed within this of the camera's nadir, metres (else: the floor under the DVL).
FLOOR_REACH_M = 0.25


def floor_under_cameras(
    poses: Trajectory, trajectory: Trajectory, dive: Dive, rig: StereoRig, fallback_m: float | None = None
) -> FloatArray:
    """Depth of the floor under each image's camera, from the DVL's altitude where the DVL passed over it.

    The camera looks at the floor ahead of the DVL (the rig sits forward of it): the floor there is
    the depth the DVL measured (its depth on ``trajectory`` plus its altitude) when it passed closest
    to the camera's nadir, within :data:`FLOOR_WINDOW_S` of the image and :data:`FLOOR_REACH_M` of the
    nadir; elsewhere (turns, gaps in bottom lock) the floor under the DVL at the image's time
    (:func:`floor_below_dvl`).

    Parameters
    ----------
    poses : Trajectory
        The body pose at each image.
    trajectory : Trajectory
        The trajectory the poses come from (the DVL's samples are placed on it).
    dive : Dive
    rig : StereoRig
    fallback_m : float, optional
        Altitude where the DVL gives none (:func:`image_altitude_m`).

    Returns
    -------
    ndarray, shape (P,)
        Metres, positive down, local NED.
    """
    lever = dive.vehicle.dvl.lever_arm_body_m
    under = floor_below_dvl(poses, image_altitude_m(dive, poses.t_s, fallback_m), lever)
    dvl = dive.dvl
    if dvl.altitude_m is None:
        return under
    ok = dvl.valid & np.isfinite(dvl.altitude_m) & (dvl.altitude_m > 0)
    ok &= (dvl.t_s >= trajectory.t_s[0]) & (dvl.t_s <= trajectory.t_s[-1])
    if np.count_nonzero(ok) < 2:
        return under
    at = trajectory.interpolate(dvl.t_s[ok])
    q = at.p_ned_m + at.R_ned_body @ np.asarray(lever, dtype=float)  # the DVL, local NED
    floor = q[:, 2] + dvl.altitude_m[ok]
    t = dvl.t_s[ok]
    nadir = (poses.p_ned_m + poses.R_ned_body @ rig.mount.lever_arm_body_m)[:, :2]
    lo = np.searchsorted(t, poses.t_s - FLOOR_WINDOW_S)
    hi = np.searchsorted(t, poses.t_s + FLOOR_WINDOW_S)
    width = int(max(np.max(hi - lo), 1))
    idx = lo[:, None] + np.arange(width)[None, :]
    inside = idx < hi[:, None]
    idx = np.minimum(idx, len(t) - 1)
    dist = np.hypot(q[idx, 0] - nadir[:, None, 0], q[idx, 1] - nadir[:, None, 1])
    dist = np.where(inside, dist, np.inf)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(poses.t_s))
    near = dist[rows, best] <= FLOOR_REACH_M
    return np.where(near, floor[idx[rows, best]], under)


def image_footprints(
    poses: Trajectory, floor_down_m: FloatArray, rig: StereoRig, kind: FootprintKind
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Footprints (P, K, 2) of the images at ``poses``, and which are usable (camera height in range)."""
    T = se3(poses.R_ned_body, poses.p_ned_m)
    cam_down = poses.p_ned_m[:, 2] + (poses.R_ned_body @ rig.mount.lever_arm_body_m)[:, 2]
    height = np.asarray(floor_down_m, dtype=float) - cam_down
    ok = np.isfinite(height) & (height >= MIN_CAMERA_HEIGHT_M) & (height <= MAX_CAMERA_HEIGHT_M)
    floor = np.where(ok, floor_down_m, cam_down + 1.0)
    if kind == "stereo":
        return stereo_footprints(T, rig, floor), ok
    return footprints_on_plane(T, rig, floor), ok


def along_track_overlap(t_s: FloatArray, footprints_ne_m: FloatArray) -> FloatArray:
    """Overlap of each footprint with the next (intersection over the smaller); NaN across a break
    (consecutive images more than :data:`BREAK_INTERVALS` median intervals apart)."""
    n = len(t_s)
    out = np.full(max(n - 1, 0), np.nan)
    if n < 2:
        return out
    dt = np.diff(t_s)
    limit = BREAK_INTERVALS * float(np.median(dt))
    k = np.flatnonzero(dt <= limit)
    out[k] = polygon_overlaps(footprints_ne_m[k], footprints_ne_m[k + 1])
    return out


def flown_area(
    plan: SurveyPlan, pairs: list[PairSpacing], flown: list[FlownLine], p_ne_m: FloatArray, end_m: float
) -> list[FloatArray]:
    """The area between adjacent flown lines, ``end_m`` in from their ends
    (:func:`auvnav.coverage.lines.pair_quad`): north-east polygons, metres."""
    by_leg = {f.leg: f for f in flown}
    out = []
    for pair in pairs:
        fa, fb = by_leg[pair.pair.a], by_leg[pair.pair.b]
        quad = pair_quad(
            pair.pair,
            plan.legs[pair.pair.a],
            p_ne_m[fa.first : fa.last + 1],
            p_ne_m[fb.first : fb.last + 1],
            end_m=end_m,
        )
        if quad is not None:
            out.append(quad)
    return out


def make_grid(
    footprints_ne_m: FloatArray, region_ne_m: list[FloatArray], origin: GeodeticOrigin, cell_m: float
) -> MapGrid:
    """The grid holding every footprint and the region, a cell of margin around; an error when it
    would exceed :data:`MAX_CELLS`."""
    points = [np.reshape(footprints_ne_m, (-1, 2)), *[np.asarray(p) for p in region_ne_m]]
    grid = MapGrid.covering(np.concatenate(points), origin, cell_m, margin_m=cell_m)
    if grid.width * grid.height > MAX_CELLS:
        raise InsufficientDataError(
            f"the images and the planned area span {grid.width * cell_m:.0f} m x {grid.height * cell_m:.0f} m: "
            f"{grid.width * grid.height / 1e6:.0f} million cells of {cell_m:g} m (limit "
            f"{MAX_CELLS / 1e6:.0f} million); use larger cells"
        )
    return grid


def lines_of(
    poses: Trajectory, plan: SurveyPlan | None, options: CoverageOptions
) -> tuple[SurveyPlan, list[FlownLine], bool]:
    """The lines flown at ``poses``: matched to the mission's plan, or without one (or a plan with no
    pairs) the track's own runs. Returns the plan used, the flown lines and whether the plan is a
    mission's."""
    t, p_ne = poses.t_s, poses.p_ned_m[:, :2]
    if plan is not None and len(plan.pairs) > 0:
        return plan, match_lines(plan, t, p_ne, min_line_m=options.min_line_m), True
    runs_plan, flown = runs_as_plan(t, p_ne, min_line_m=options.min_line_m)
    return runs_plan, flown, False


def analyse_coverage(
    poses: Trajectory,
    floor_down_m: FloatArray,
    rig: StereoRig,
    origin: GeodeticOrigin,
    plan: SurveyPlan | None,
    options: CoverageOptions,
    *,
    flown: list[FlownLine] | None = None,
    planned_lines: bool = True,
) -> Coverage:
    """Coverage of the images taken at ``poses`` (module docstring).

    Parameters
    ----------
    poses : Trajectory
        The body pose at each image, local NED (a trajectory interpolated at the image times).
    floor_down_m : ndarray, shape (P,)
        Depth of the floor under each image, metres, positive down.
    rig : StereoRig
    origin : GeodeticOrigin
        The dive's origin (the grid's UTM zone).
    plan : SurveyPlan or None
        The mission's lines and planned area; None: the track's own runs and the area between them.
    options : CoverageOptions
    flown : list of FlownLine, optional
        The lines as matched on another track of the same images (to measure the truth over the same
        stretches as an estimate, :func:`lines_of`), with the plan they were matched to; default:
        matched on ``poses``.
    planned_lines : bool
        With ``flown``: the plan is a mission's (False: the runs of a track, :func:`lines_of`).

    Returns
    -------
    Coverage

    Raises
    ------
    InsufficientDataError
        No image with a usable footprint.
    """
    polygons, ok = image_footprints(poses, floor_down_m, rig, options.footprint)
    dropped = int(np.count_nonzero(~ok))
    if dropped:
        log.warning(
            "%d of %d images left out: the camera is less than %.1f m or more than %.0f m above the floor",
            dropped,
            len(ok),
            MIN_CAMERA_HEIGHT_M,
            MAX_CAMERA_HEIGHT_M,
        )
    if not np.any(ok):
        raise InsufficientDataError("no image has a usable footprint (camera height out of range)")
    t = poses.t_s
    p_ne = poses.p_ned_m[:, :2]
    if flown is None:
        plan, flown, planned = lines_of(poses, plan, options)
    else:
        planned = plan is not None and planned_lines
        if plan is None:
            raise ValueError("flown lines need the plan they were matched to")
    pairs = pair_spacing(
        plan,
        flown,
        p_ne,
        station_m=options.station_m,
        margin_m=options.margin_m,
        tolerance_m=options.tolerance_m,
        planned=planned,
    )
    area = list(plan.area_ne_m)
    kind: Literal["planned", "flown lines", "none"] = (
        "planned" if planned else ("flown lines" if area else "none")
    )
    used = polygons[ok]
    grid = make_grid(used, area, origin, options.cell_m)
    counts = np.minimum(count_polygons(used, grid), np.iinfo(np.uint16).max).astype(np.uint16)
    region = polygon_mask(area, grid)
    between = region & polygon_mask(flown_area(plan, pairs, flown, p_ne, options.line_end_m), grid)
    cell_area = ground_cell_area_m2(grid)
    gaps = find_gaps(
        between & (counts < options.min_images),
        grid,
        min_area_m2=options.min_gap_area_m2,
        cell_area_m2=cell_area,
    )
    return Coverage(
        grid=grid,
        counts=counts,
        region=region,
        region_kind=kind,
        between=between,
        gaps=gaps,
        cell_area_m2=cell_area,
        t_s=t[ok],
        footprints_ne_m=used,
        along_overlap=along_track_overlap(t[ok], used),
        plan=plan,
        flown=flown,
        pairs=pairs,
        options=options,
        dropped=dropped,
    )


def spacing_rows(pairs: list[PairSpacing]) -> list[dict[str, Any]]:
    """Rows of ``spacing.csv``: every station of every pair."""
    rows = []
    for k, p in enumerate(pairs):
        for s, d in zip(p.along_m, p.spacing_m, strict=True):
            rows.append(
                {
                    "pair": k,
                    "line_a": p.line_a,
                    "line_b": p.line_b,
                    "along_m": float(s),
                    "spacing_m": float(d),
                }
            )
    return rows


def line_rows(pairs: list[PairSpacing], flown: list[FlownLine]) -> list[dict[str, Any]]:
    """Rows of ``lines.csv``: one per adjacent pair, with when each of its lines was flown."""
    by_leg = {f.leg: f for f in flown}
    rows = []
    for k, p in enumerate(pairs):
        row = p.row()
        row["pair"] = k
        fa, fb = by_leg[p.pair.a], by_leg[p.pair.b]
        row.update(
            {
                "t_a_start": fa.t_start_s,
                "t_a_end": fa.t_end_s,
                "t_b_start": fb.t_start_s,
                "t_b_end": fb.t_end_s,
            }
        )
        rows.append(row)
    return rows


def gap_rows(gaps: Gaps) -> list[dict[str, Any]]:
    """Rows of ``gaps.csv``: one per gap, largest first."""
    return [
        {
            "gap": k + 1,
            "area_m2": float(gaps.area_m2[k]),
            "width_m": float(gaps.width_m[k]),
            "north_m": float(gaps.centroid_ne_m[k, 0]),
            "east_m": float(gaps.centroid_ne_m[k, 1]),
            "row": int(gaps.bbox_cells[k, 0]),
            "col": int(gaps.bbox_cells[k, 1]),
            "rows": int(gaps.bbox_cells[k, 2]),
            "cols": int(gaps.bbox_cells[k, 3]),
        }
        for k in range(len(gaps))
    ]


def mean_or_nan(x: FloatArray) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else math.nan
