"""The coverage stage (``auvnav coverage DIVE``): where the images fell, the gaps, and the lines' spacing.

Each stereo pair of ``images/index.csv`` (the camera's trigger log: the image files need not be
present) is placed with the best trajectory the dive has, SLAM, else the navigation filter, else
dead reckoning (``trajectory`` chooses one; the summary says which), its footprint on a level floor
at the depth the DVL measured where it passed under the camera
(:func:`~auvnav.coverage.analysis.floor_under_cameras`). With the mission the dive flew
(``mission``, an ``auvnav-mission/1`` file) the planned lines, their spacing and the planned area are
known; without it the track's own lines stand for them.

Products (DESIGN section 6), in ``DIVE/products/coverage/``:

- ``coverage.tif``: images per cell (uint16), a tiled GeoTIFF in the UTM zone of the dive's origin;
- ``coverage.png``: the same as a map, gaps in red, the planned area outlined, with a legend;
- ``lines.csv``: one row per pair of adjacent lines: ``pair, line_a, line_b, planned_m, stations,
  min_m, mean_m, max_m, turn_end_m, far_end_m, class`` (on plan, accordion, figure 8) and when each
  line was flown (``t_a_start, t_a_end, t_b_start, t_b_end``);
- ``spacing.csv``: each pair's spacing at its stations (``pair, line_a, line_b, along_m, spacing_m``);
- ``gaps.csv``: one row per gap, largest first (``gap, area_m2, width_m, north_m, east_m`` and its
  cells' bounding box ``row, col, rows, cols``);
- ``summary.json``: :meth:`~auvnav.coverage.analysis.Coverage.summary` with the trajectory, the
  mission and the settings used.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from auvnav import products as P
from auvnav.dive import ImageIndex, dive_files, find_stream_file, read_dive
from auvnav.errors import InsufficientDataError
from auvnav.stagekit import Stage, StageContext, StageSkipped, setting, settings_mapping

log = logging.getLogger(__name__)

TrajectoryName = Literal["best", "slam", "filter", "dr"]
#: The trajectories the footprints may be placed with, best first.
TRAJECTORIES: dict[str, P.Product] = {"slam": P.SLAM_TRAJECTORY, "filter": P.NAV_FILTER, "dr": P.NAV_DR}
TRAJECTORY_TITLES = {"slam": "SLAM", "filter": "navigation filter", "dr": "dead reckoning"}


@dataclass(frozen=True)
class CoverageSettings:
    """Settings of the coverage stage."""

    mission: Path | None = setting(
        None,
        "Mission file (auvnav-mission/1) the dive flew: planned lines, spacing and area "
        "[none: the track's own lines, and the area between them].",
    )
    trajectory: TrajectoryName = setting(
        "best", "Trajectory to place the images with: best = SLAM, else filter, else dead reckoning."
    )
    cell_m: float = setting(0.05, "Grid cell, metres.", minimum=0.005, maximum=10.0)
    footprint: Literal["stereo", "left"] = setting(
        "stereo", "Footprint: where both cameras see (stereo), or the left camera's."
    )
    min_images: int = setting(1, "A cell is covered when at least this many images see it.", minimum=1)
    min_gap_area_m2: float = setting(0.01, "Smaller uncovered regions are not gaps, m^2.", minimum=0.0)
    gap_width_m: float = setting(
        0.5, "Gaps at least this wide are counted apart (half the usual line spacing), metres.", minimum=0.0
    )
    station_m: float = setting(1.0, "Spacing stations along the lines, metres.", minimum=0.01)
    line_margin_m: float = setting(10.0, "Spacing left out at each end of a line, metres.", minimum=0.0)
    tolerance_m: float = setting(
        0.1, "A pair is on plan while its spacing stays within this of the plan, metres.", minimum=0.0
    )
    min_line_m: float = setting(10.0, "Shortest survey line, metres.", minimum=0.1)
    line_end_m: float = setting(
        3.0, "Gaps between lines are looked for this far in from their ends (turns), metres.", minimum=0.0
    )
    altitude_m: float | None = setting(
        None, "Altitude of the DVL above the floor where the DVL gives none, metres.", minimum=0.1
    )

    def options(self) -> Any:
        from auvnav.coverage.analysis import CoverageOptions

        return CoverageOptions.from_settings(settings_mapping(self))


def trajectory_file(dive: Path, name: str) -> tuple[str, Path] | None:
    """The trajectory the stage uses (its name and file), or None when the dive has none of it."""
    names = list(TRAJECTORIES) if name == "best" else [name]
    for n in names:
        path = TRAJECTORIES[n].path(dive)
        if path.is_file():
            return n, path
    return None


def _unavailable(dive: Path, settings: CoverageSettings) -> str | None:
    if find_stream_file(dive, ImageIndex.FILE) is None:
        return "no camera trigger log (images/index.csv): no images to place"
    if trajectory_file(dive, settings.trajectory) is None:
        if settings.trajectory == "best":
            return "no trajectory (products/slam or products/nav: run `auvnav navigate` first)"
        return f"no {TRAJECTORY_TITLES[settings.trajectory]} trajectory ({TRAJECTORIES[settings.trajectory].rel})"
    return None


def _inputs(dive: Path, settings: CoverageSettings) -> dict[str, Path]:
    files = dive_files(dive)
    index = find_stream_file(dive, ImageIndex.FILE)
    if index is not None:
        files[str(index.relative_to(dive))] = index
    chosen = trajectory_file(dive, settings.trajectory)
    if chosen is not None:
        files[str(chosen[1].relative_to(dive))] = chosen[1]
    if settings.mission is not None:
        files["mission"] = settings.mission
    return files


def _run(ctx: StageContext, settings: CoverageSettings, out: Path) -> dict[str, Any]:
    from auvnav.coverage.analysis import (
        analyse_coverage,
        floor_under_cameras,
        gap_rows,
        image_poses,
        line_rows,
        spacing_rows,
    )
    from auvnav.coverage.figure import write_coverage_png
    from auvnav.coverage.plan import survey_plan
    from auvnav.plan.missions import read_mission
    from auvnav.raster import utm_crs, write_geotiff
    from auvnav.streams import write_json
    from auvnav.trajectory import read_trajectory

    plan = (
        None
        if settings.mission is None
        else survey_plan(read_mission(settings.mission), min_line_m=settings.min_line_m)
    )
    dive = read_dive(ctx.dive, allow_outside=getattr(ctx, "allow_outside", False))
    if dive.images is None or len(dive.images) == 0:
        raise StageSkipped("no images in images/index.csv")
    rig = dive.vehicle.stereo
    if rig is None:
        raise StageSkipped("the vehicle has no stereo calibration (vehicle.yaml, key stereo): no footprints")
    chosen = trajectory_file(ctx.dive, settings.trajectory)
    if chosen is None:
        raise InsufficientDataError(f"{ctx.dive}: {_unavailable(ctx.dive, settings)}")
    name, path = chosen
    trajectory = read_trajectory(path)
    poses, outside = image_poses(dive, trajectory)
    if outside:
        log.warning(
            "%d of %d images lie outside the %s trajectory's time span: left out",
            outside,
            len(dive.images),
            name,
        )
    if len(poses) == 0:
        raise StageSkipped(f"no image lies inside the {TRAJECTORY_TITLES[name]} trajectory's time span")
    try:
        floor = floor_under_cameras(poses, trajectory, dive, rig, settings.altitude_m)
    except InsufficientDataError as err:
        raise StageSkipped(str(err)) from None
    if plan is not None and not plan.pairs:
        log.warning(
            "%s: the mission plans no adjacent lines; the track's own lines are used", settings.mission
        )
    ctx.tick("coverage", 0, 1)
    cov = analyse_coverage(poses, floor, rig, dive.info.origin, plan, settings.options())
    crs = utm_crs(dive.info.origin)
    write_geotiff(P.COVERAGE_TIF.inside(out), cov.counts, cov.grid, description=("images per cell",))
    source = f"{TRAJECTORY_TITLES[name]} ({path.relative_to(ctx.dive)})"
    pct = cov.coverage_pct()
    title = f"{dive.info.name}: images per {settings.cell_m:g} m cell from {TRAJECTORY_TITLES[name]}" + (
        "" if pct is None else f"; {cov.region_kind} area {pct:.1f}% covered, {len(cov.gaps)} gaps"
    )
    write_coverage_png(cov, P.COVERAGE_PNG.inside(out), title=title)
    import pandas as pd

    from auvnav.streams import write_table

    line_columns = [
        "pair", "line_a", "line_b", "planned_m", "stations", "min_m", "mean_m", "max_m",
        "turn_end_m", "far_end_m", "class", "t_a_start", "t_a_end", "t_b_start", "t_b_end",
    ]  # fmt: skip
    write_table(
        pd.DataFrame(line_rows(cov.pairs, cov.flown), columns=line_columns), P.COVERAGE_LINES.inside(out)
    )
    write_table(
        pd.DataFrame(spacing_rows(cov.pairs), columns=["pair", "line_a", "line_b", "along_m", "spacing_m"]),
        P.COVERAGE_SPACING.inside(out),
    )
    gap_columns = ["gap", "area_m2", "width_m", "north_m", "east_m", "row", "col", "rows", "cols"]
    write_table(pd.DataFrame(gap_rows(cov.gaps), columns=gap_columns), P.COVERAGE_GAPS.inside(out))
    summary = {
        "dive": dive.info.name,
        "trajectory": name,
        "trajectory_file": str(path.relative_to(ctx.dive)),
        "source": source,
        "images_outside_trajectory": outside,
        "crs": crs.to_string(),
        "mission": None if settings.mission is None else str(Path(settings.mission).resolve()),
        "plan": None if plan is None else plan.summary(),
        **cov.summary(),
        "settings": settings_mapping(settings),
    }
    write_json(summary, P.COVERAGE_SUMMARY.inside(out))
    ctx.tick("coverage", 1, 1)
    return summary


def format_summary(summary: dict[str, Any]) -> str:
    """The human account of the coverage stage's summary."""

    def m(x: float | None, unit: str = "m", fmt: str = ".2f") -> str:
        return "-" if x is None else f"{x:{fmt}} {unit}"

    g = summary["gaps"]
    lines = [
        f"{summary['images']} images placed with {summary['source']}; {summary['footprint']} footprints "
        f"on {summary['cell_m']:g} m cells ({summary['crs']}); {summary['imaged_area_m2']:.0f} m^2 imaged",
    ]
    if summary["coverage_pct"] is None:
        lines.append("no planned area and no adjacent lines: no coverage percentage, no gaps")
    else:
        where = "planned area" if summary["region"] == "planned" else "area between the flown lines"
        mission = f" (mission {summary['mission']})" if summary["mission"] else ""
        lines.append(
            f"{where}{mission}: {summary['region_area_m2']:.0f} m^2, {summary['coverage_pct']:.2f}% covered"
        )
        largest = g["largest"]
        lines.append(
            f"gaps between the flown lines: {g['count']} ({g['area_m2']:.2f} m^2)"
            + (
                ""
                if largest is None
                else f", the largest {largest['area_m2']:.2f} m^2 and {largest['width_m']:.2f} m wide at "
                f"north {largest['north_m']:.1f} m, east {largest['east_m']:.1f} m"
            )
            + f"; {g['count_wider']} at least {g['wider_than_m']:.2f} m wide"
        )
        lines.append(
            f"not covered: {g['uncovered_area_m2']:.2f} m^2, of which {g['not_surveyed_m2']:.2f} m^2 outside "
            "the flown lines (not surveyed)"
        )
        hist = summary["overlap_histogram"]
        cells = ", ".join(
            f"{k}: {a:.0f}" for k, a in zip(hist["images"], hist["region_area_m2"], strict=True) if a > 0
        )
        lines.append(f"images per cell in the {where} (m^2): {cells}")
    ov = summary["along_track_overlap"]
    if ov["median"] is not None:
        lines.append(
            f"along-track overlap of consecutive images: median {100 * ov['median']:.0f}%, "
            f"5th percentile {100 * ov['p05']:.0f}%, least {100 * ov['min']:.0f}%"
        )
    ln = summary["lines"]
    lines.append(
        f"lines: {ln['flown']} flown of {ln['planned']}; {ln['pairs']} adjacent pairs"
        + (
            f" (planned spacing {ln['planned_spacing_m']:.2f} m)"
            if ln["planned_spacing_m"] is not None
            else ""
        )
        + (
            ""
            if ln["spacing_mean_m"] is None
            else f": spacing {m(ln['spacing_min_m'])} to {m(ln['spacing_max_m'])}, mean {m(ln['spacing_mean_m'])}"
        )
    )
    lines.append(
        f"pairs on plan (within {ln['tolerance_m']:.2f} m): {ln['on_plan']}, accordion: {ln['accordion']}, "
        f"figure 8: {ln['figure_8']}"
    )
    return "\n".join(lines)


STAGE = Stage(
    name="coverage",
    title="image footprints on a map grid: coverage, gaps, overlap, line spacing ('accordion', 'figure 8')",
    after=("nav", "slam"),
    settings=CoverageSettings,
    inputs=_inputs,
    unavailable=_unavailable,
    run=_run,
    describe=format_summary,
)
