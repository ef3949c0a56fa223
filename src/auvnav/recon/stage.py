"""The reconstruction stage (``auvnav recon DIVE``): dense stereo, mesh, DEM, orthophoto, Fig. 11 check.

Each stereo pair is matched densely (:mod:`auvnav.recon.dense`, per pair through the executor: Dask
spreads it with ``--scheduler``), placed with the best trajectory the dive has, SLAM, else the
navigation filter, else dead reckoning (``trajectory`` chooses; the summary says which), its depth
below the tide datum when a tide is known: the ``tide`` setting, else the depth stage's (the
``tide`` it was given), else none (the summary says so). A SLAM trajectory solved with a tide is
already below the datum. The region may be limited to a box of local north and east.

Products (DESIGN section 6), in ``DIVE/products/recon/``: ``mesh.ply``, ``dem.tif``, ``mosaic.tif``,
``relief.csv``, ``pairs.csv`` and ``summary.json`` (:mod:`auvnav.recon.reconstruct` says what each
holds). Dense maps are cached in ``DIVE/products/cache/recon/dense/``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from auvnav import products as P
from auvnav.dive import (
    ImageIndex,
    find_stream_file,
    image_files,
    image_inputs,
    read_dive,
    read_image_index,
    vehicle_file_name,
)
from auvnav.errors import AuvnavError, InsufficientDataError
from auvnav.stagekit import Stage, StageContext, StageSkipped, setting, settings_mapping
from auvnav.streams import write_json

log = logging.getLogger(__name__)

TrajectoryName = Literal["best", "slam", "filter", "dr"]
#: The trajectories depth maps may be placed with, best first.
TRAJECTORIES: dict[str, P.Product] = {"slam": P.SLAM_TRAJECTORY, "filter": P.NAV_FILTER, "dr": P.NAV_DR}
TRAJECTORY_TITLES = {"slam": "SLAM", "filter": "navigation filter", "dr": "dead reckoning"}


@dataclass(frozen=True)
class ReconSettings:
    """Settings of the reconstruction stage."""

    trajectory: TrajectoryName = setting(
        "best", "Trajectory to place the depth maps with: best = SLAM, else filter, else dead reckoning."
    )
    tide: Path | None = setting(
        None, "Tide constituent file (name, amplitude_m, phase_deg) [the depth stage's tide, if it had one]."
    )
    scale: float | None = setting(
        None, "Dense stereo scale (default: to 680 px wide, half of 1360).", minimum=1e-3, maximum=1.0
    )
    north_min_m: float | None = setting(None, "Reconstruct only north of this (local NED), metres.")
    north_max_m: float | None = setting(None, "Reconstruct only south of this (local NED), metres.")
    east_min_m: float | None = setting(None, "Reconstruct only east of this (local NED), metres.")
    east_max_m: float | None = setting(None, "Reconstruct only west of this (local NED), metres.")
    tile_m: float = setting(5.12, "Fusion tile side (memory is bounded by it), metres.", minimum=0.1)
    dem_cell_m: float = setting(0.01, "DEM cell, metres.", minimum=1e-4)
    mosaic_cell_m: float = setting(0.002, "Orthophoto cell, metres.", minimum=1e-4)
    dem_max_sigma_m: float = setting(
        0.01, "DEM cells less certain than this (1-sigma, metres) have no data (0: keep all).", minimum=0.0
    )
    voxel_m: float = setting(0.02, "TSDF voxel of the mesh, metres (0: no mesh).", minimum=0.0)
    tsdf: Literal["blockgrid", "scalable"] = setting(
        "blockgrid", "Open3D TSDF: tensor VoxelBlockGrid, or legacy ScalableTSDFVolume."
    )
    min_range_m: float = setting(
        1.0,
        "Nearest plausible seafloor from the camera, metres (a pair whose floor is nearer fails).",
        minimum=0.05,
    )
    max_range_m: float = setting(8.0, "Farthest plausible seafloor from the camera, metres.", minimum=0.1)

    def __post_init__(self) -> None:
        if not self.min_range_m < self.max_range_m:
            raise ValueError(
                f"min_range_m must be below max_range_m; found {self.min_range_m}, {self.max_range_m}"
            )
        for lo, hi in (("north_min_m", "north_max_m"), ("east_min_m", "east_max_m")):
            a, b = getattr(self, lo), getattr(self, hi)
            if a is not None and b is not None and not a < b:
                raise ValueError(f"{lo} must be below {hi}; found {a}, {b}")
        self.fusion()  # tile and cell sizes agree (a ValueError says how not)

    def dense(self) -> Any:
        from auvnav.recon.dense import DenseSettings

        return DenseSettings(scale=self.scale, min_range_m=self.min_range_m, max_range_m=self.max_range_m)

    def fusion(self) -> Any:
        from auvnav.recon.fusion import FusionSettings

        return FusionSettings(
            tile_m=self.tile_m,
            dem_cell_m=self.dem_cell_m,
            mosaic_cell_m=self.mosaic_cell_m,
            max_sigma_m=self.dem_max_sigma_m,
            voxel_m=self.voxel_m,
            tsdf=self.tsdf,
        )

    def region(self) -> Any:
        from auvnav.recon.reconstruct import Region

        return Region(self.north_min_m, self.north_max_m, self.east_min_m, self.east_max_m)


def trajectory_file(dive: Path, name: str) -> tuple[str, Path] | None:
    """The trajectory the stage uses (its name and file), or None when the dive has none of it."""
    for n in list(TRAJECTORIES) if name == "best" else [name]:
        path = TRAJECTORIES[n].path(dive)
        if path.is_file():
            return n, path
    return None


def pressure_file(dive: Path) -> Path | None:
    """A track whose depth is pressure depth (the navigation filter's, smoothed with the DVL's vertical
    velocity, else dead reckoning's): the Fig. 11 check's vertical, as a reconstruction placed with
    pressure depth would have it."""
    for product in (P.NAV_FILTER, P.NAV_DR):
        if product.path(dive).is_file():
            return product.path(dive)
    return None


def _depth_tide(dive: Path) -> Path | None:
    """The tide file the depth stage was given (its record), when it still exists."""
    record = P.read_record(dive, "depth")
    given = (record or {}).get("settings_given") or {}
    tide = given.get("tide")
    return Path(tide) if isinstance(tide, str) and Path(tide).is_file() else None


def _slam_tide(dive: Path) -> Path | None:
    """The tide file the SLAM trajectory was solved with (its summary), or None."""
    import json

    try:
        summary = json.loads(P.SLAM_SUMMARY.path(dive).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    tide = summary.get("tide") if isinstance(summary, dict) else None
    return Path(tide) if isinstance(tide, str) else None


def tide_file(dive: Path, settings: ReconSettings) -> tuple[Path | None, str]:
    """The tide the stage corrects with, and where it comes from (``setting``, ``depth stage``, ``slam``)."""
    if settings.tide is not None:
        return settings.tide, "setting"
    depth = _depth_tide(dive)
    if depth is not None:
        return depth, "depth stage"
    chosen = trajectory_file(dive, settings.trajectory)
    if chosen is not None and chosen[0] == "slam":
        slam = _slam_tide(dive)
        if slam is not None and slam.is_file():
            return slam, "slam"
    return None, ""


def _unavailable(dive: Path, settings: ReconSettings) -> str | None:
    if find_stream_file(dive, ImageIndex.FILE) is None:
        return "reconstruction needs stereo images: the dive has no images/index.csv"
    try:
        index = read_image_index(dive)
        name = vehicle_file_name(dive)
        vehicle = None
        if name is not None:
            from auvnav.vehicle import read_vehicle

            vehicle = read_vehicle(dive / name)
    except AuvnavError:
        return None  # the stage's run reports the problem with its file
    if vehicle is not None and vehicle.stereo is None:
        return "reconstruction needs the stereo calibration (vehicle.yaml, key stereo)"
    if index is not None and not image_files(dive, index):
        return f"reconstruction needs the images: none of the {2 * len(index)} that images/index.csv lists is in images/"
    if trajectory_file(dive, settings.trajectory) is None:
        if settings.trajectory == "best":
            return "no trajectory to place the depth maps with (products/slam or products/nav: run `auvnav navigate`)"
        return f"no {TRAJECTORY_TITLES[settings.trajectory]} trajectory ({TRAJECTORIES[settings.trajectory].rel})"
    return None


def _inputs(dive: Path, settings: ReconSettings) -> dict[str, Path]:
    files = image_inputs(dive)
    chosen = trajectory_file(dive, settings.trajectory)
    if chosen is not None:
        files[str(chosen[1].relative_to(dive))] = chosen[1]
        if chosen[0] == "slam" and P.SLAM_SUMMARY.path(dive).is_file():
            files[P.SLAM_SUMMARY.rel] = P.SLAM_SUMMARY.path(dive)
    tide, _ = tide_file(dive, settings)
    if tide is not None:
        files["tide"] = tide
    pressure = pressure_file(dive)
    if pressure is not None:
        files[str(pressure.relative_to(dive))] = pressure
    return files


def _run(ctx: StageContext, settings: ReconSettings, out: Path) -> dict[str, Any]:
    from auvnav.depth.tide import read_constituents
    from auvnav.recon.reconstruct import ReconInputs, reconstruct
    from auvnav.trajectory import read_trajectory

    dive = read_dive(ctx.dive, allow_outside=ctx.allow_outside)
    if dive.images is None or len(dive.images) == 0:
        raise StageSkipped("reconstruction needs stereo images: images/index.csv lists none")
    chosen = trajectory_file(ctx.dive, settings.trajectory)
    if chosen is None:
        raise InsufficientDataError(f"{ctx.dive}: {_unavailable(ctx.dive, settings)}")
    name, path = chosen
    tide_path, tide_from = tide_file(ctx.dive, settings)
    tide = None
    if tide_path is not None:
        tide = read_constituents(tide_path, latitude_rad=dive.info.origin.latitude_rad)
    in_trajectory = name == "slam" and _slam_tide(ctx.dive) is not None
    if in_trajectory and tide is None:
        log.warning("%s: the SLAM trajectory was solved with a tide this stage cannot read", ctx.dive)
    if name == "slam" and tide is not None and not in_trajectory:
        log.warning(
            "%s: the SLAM trajectory was solved without the tide; its loop closures already hold revisits "
            "together, so it is not lowered by the tide here (its depth is not below the datum: run "
            "`auvnav slam --tide FILE` for that); the tide serves the false-relief check",
            ctx.dive,
        )
    pressure = pressure_file(ctx.dive)
    inputs = ReconInputs(
        trajectory=read_trajectory(path),
        trajectory_name=name,
        tide=tide,
        tide_source=None if tide_path is None else f"{tide_path} ({tide_from})",
        tide_in_trajectory=in_trajectory,
        apply_tide=name != "slam",
        pressure_track=None if pressure is None else read_trajectory(pressure),
    )
    summary = reconstruct(
        dive,
        inputs,
        out,
        region=settings.region(),
        dense=settings.dense(),
        fusion=settings.fusion(),
        cache_dir=P.cache_dir(ctx.dive, "recon") / "dense",
        executor=ctx.executor(),
        progress=ctx.progress,
    )
    summary["trajectory_file"] = str(path.relative_to(ctx.dive))
    summary["settings"] = settings_mapping(settings)
    write_json(summary, P.RECON_SUMMARY.inside(out))
    return summary


def format_summary(summary: dict[str, Any]) -> str:
    """The human account of the reconstruction stage's summary."""
    pairs, grid, dem, relief, tide = (
        summary["pairs"],
        summary["grid"],
        summary["dem"],
        summary["relief"],
        summary["tide"],
    )
    lines = [
        f"{pairs['used']} stereo pairs reconstructed of {pairs['considered']} in the region "
        f"({pairs['failed']} failed dense stereo, {pairs['missing_image']} with an image missing), "
        f"placed with {TRAJECTORY_TITLES.get(summary['trajectory'], summary['trajectory'])} "
        f"({summary.get('trajectory_file', '')})",
        "tide: "
        + (
            "none (depth as the trajectory gives it; give --tide FILE to correct it)"
            if tide["source"] is None
            else f"{tide['source']}, applied {tide['applied']}"
        ),
        f"dense stereo at {summary['dense']['width_px']}x{summary['dense']['height_px']} px: median "
        f"{100 * pairs['matched_fraction_median']:.0f}% of pixels matched, median range {pairs['range_median_m']:.2f} m",
        f"grid {grid['crs']}: {grid['tiles_with_data']} tiles of {summary['fusion']['tile_m']:g} m with data; "
        f"DEM {dem['area_m2']:.1f} m^2 at {summary['fusion']['dem_cell_m']:g} m, orthophoto "
        f"{summary['mosaic']['area_m2']:.1f} m^2 at {summary['fusion']['mosaic_cell_m']:g} m",
    ]
    if summary["mesh"] is not None:
        lines.append(
            f"mesh: {summary['mesh']['vertices']} vertices, {summary['mesh']['faces']} faces "
            f"({summary['fusion']['tsdf']} TSDF, {summary['fusion']['voxel_m']:g} m voxels)"
        )

    def cm(x: float | None) -> str:
        return "-" if x is None else f"{100 * x:.1f} cm"

    lines.append(
        f"revisits over {summary['fusion']['far_apart_s'] / 60:.0f} min apart (Fig. 11): {relief['comparisons']} "
        f"compared; step RMS as placed {cm(relief['step_placed_rms_m'])}; with pressure depth "
        f"{cm(relief['step_before_rms_m'])} before the tide correction, {cm(relief['step_after_rms_m'])} "
        f"after; false relief {relief['false_relief_before']} before, {relief['false_relief_after']} after"
    )
    lines.append(
        f"{summary['seconds']['total']:.0f} s ({summary['seconds']['dense']:.0f} s dense stereo), "
        f"{summary['pairs_per_s']:.1f} pairs/s ({summary['executor']}, {summary['workers']} workers)"
    )
    return "\n".join(lines)


STAGE = Stage(
    name="recon",
    title="dense stereo, TSDF mesh, DEM and orthophoto (GeoTIFF), false relief on revisits (Fig. 11)",
    after=("nav", "slam", "depth"),
    settings=ReconSettings,
    inputs=_inputs,
    unavailable=_unavailable,
    run=_run,
    describe=format_summary,
    uses_executor=True,
)
