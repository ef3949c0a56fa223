"""A dive's reconstruction, start to end: dense stereo per pair, placement, fusion per tile, products.

1. Every stereo pair whose camera lies in the region (grown by ``margin_m``) and inside the
   trajectory's time span is matched (:mod:`auvnav.recon.dense`), per pair through the executor, its
   dense map cached; failed pairs are skipped with a warning naming their images.
2. Each matched pair is placed by the trajectory (:mod:`auvnav.recon.placement`), with the tide.
3. Its footprint (the image rectangle at 1.25 times its median range: relief) says which map tiles it
   meets; each tile is fused through the executor (:mod:`auvnav.recon.fusion`), a few at a time, and
   written as it comes back: DEM and orthophoto windows, mesh part, revisit rows.

Products (in ``out``): ``dem.tif`` (float32, bands elevation and 1-sigma, metres, up, NaN no data),
``mosaic.tif`` (uint8 orthophoto, 0 no data), ``mesh.ply`` (binary PLY with vertex colours, east,
north, up about the dive's origin), ``relief.csv`` (the Fig. 11 check: one row per pair of visits to a
tile more than ``far_apart_s`` apart), ``pairs.csv`` (every pair considered: placed position, status,
matched fraction, median range) and the summary (returned; the stage writes ``summary.json``).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from auvnav import products as P
from auvnav.dive import Dive
from auvnav.errors import InsufficientDataError
from auvnav.executor import Executor, chunks
from auvnav.frames import FloatArray
from auvnav.raster import MapGrid, map2ned, ned2map, utm_crs
from auvnav.recon.dense import DenseFailed, DenseGeometry, DenseSettings, pair_dense
from auvnav.recon.fusion import FusionContext, FusionSettings, TileJob, TileResult, fuse_tile
from auvnav.recon.placement import Placement, place_pairs
from auvnav.recon.writers import PlyWriter, TiledGeoTiff
from auvnav.streams import write_table
from auvnav.trajectory import Trajectory
from auvnav.vision.camera import rectification

log = logging.getLogger(__name__)

Progress = Callable[[str, int, int], None]

#: Failed pairs named one by one in the log; beyond this many, a count.
NAMED_FAILURES = 20
RELIEF_COLUMNS = [
    "tile_row", "tile_col", "north_m", "east_m", "t_a_start", "t_a_end", "t_b_start", "t_b_end", "dt_s",
    "cells", "area_m2", "tide_change_m", "step_placed_m", "step_placed_sigma_m", "step_before_m", "step_before_sigma_m", "step_after_m",
    "step_after_sigma_m", "false_relief_before", "false_relief_after",
]  # fmt: skip


@dataclass(frozen=True)
class Region:
    """A box of local north and east (metres; None: unbounded) the reconstruction is limited to."""

    north_min_m: float | None = None
    north_max_m: float | None = None
    east_min_m: float | None = None
    east_max_m: float | None = None

    def __post_init__(self) -> None:
        for lo, hi in ((self.north_min_m, self.north_max_m), (self.east_min_m, self.east_max_m)):
            if lo is not None and hi is not None and not lo < hi:
                raise ValueError(f"an empty region: {lo} to {hi} m")

    def contains(self, ne_m: FloatArray, margin_m: float = 0.0) -> NDArray[np.bool_]:
        """Which points (n, 2) of local (north, east) lie in the region grown by ``margin_m``."""
        n, e = ne_m[:, 0], ne_m[:, 1]
        ok = np.ones(len(ne_m), dtype=bool)
        if self.north_min_m is not None:
            ok &= n >= self.north_min_m - margin_m
        if self.north_max_m is not None:
            ok &= n <= self.north_max_m + margin_m
        if self.east_min_m is not None:
            ok &= e >= self.east_min_m - margin_m
        if self.east_max_m is not None:
            ok &= e <= self.east_max_m + margin_m
        return ok

    def box(self) -> FloatArray | None:
        """The corners (4, 2) of the region as local (north, east), or None unless all four are bounded."""
        n0, n1, e0, e1 = self.north_min_m, self.north_max_m, self.east_min_m, self.east_max_m
        if n0 is None or n1 is None or e0 is None or e1 is None:
            return None
        return np.array([[n0, e0], [n0, e1], [n1, e1], [n1, e0]], dtype=float)


@dataclass(frozen=True)
class ReconInputs:
    """What a reconstruction places its depth maps with.

    Parameters
    ----------
    trajectory : Trajectory
    trajectory_name : str
        ``slam``, ``filter`` or ``dr`` (for the summary).
    tide : TideModel or None
        The tide (:class:`auvnav.depth.tide.TideModel`); None: depth as the trajectory gives it.
    tide_source : str or None
    tide_in_trajectory : bool
        The trajectory's depth is already below the datum.
    apply_tide : bool
        Lower the trajectory by the tide (:func:`~auvnav.recon.placement.place_pairs`).
    pressure_track : Trajectory, optional
        A track whose depth is the pressure depth (the navigation's): the vertical of the Fig. 11 check.
    """

    trajectory: Trajectory
    trajectory_name: str
    tide: Any = None
    tide_source: str | None = None
    tide_in_trajectory: bool = False
    apply_tide: bool = True
    pressure_track: Trajectory | None = None


@dataclass(frozen=True)
class _DenseContext:
    images_dir: Path
    cache_dir: Path | None
    rig: Any
    rect: Any
    geom: DenseGeometry
    settings: DenseSettings


def _dense_task(ctx: _DenseContext, items: list[tuple[int, str, str]]) -> list[tuple[int, str, float, float]]:
    """Match pairs; (index, status, matched fraction, median range) each; status ``ok``, ``missing``
    (an image missing or unreadable: already said) or the failure's reason."""
    out = []
    for k, left, right in items:
        try:
            dense = pair_dense(
                ctx.images_dir / left, ctx.images_dir / right, ctx.rig, ctx.rect, ctx.geom, ctx.settings,
                ctx.cache_dir,
            )  # fmt: skip
        except DenseFailed as err:
            out.append((k, str(err), math.nan, math.nan))
            continue
        if dense is None:
            out.append((k, "missing", math.nan, math.nan))
            continue
        frac, z = dense.summary(ctx.geom)
        out.append((k, "ok", frac, z))
    return out


def _tile_task(ctx: FusionContext, jobs: list[TileJob]) -> list[TileResult]:
    return [fuse_tile(ctx, job) for job in jobs]


def _footprints_map(
    placement: Placement, ranges_m: FloatArray, geom: DenseGeometry, origin: Any
) -> FloatArray:
    """Map corners (n, 4, 2) of each pair's image rectangle at 1.25 times its median range."""
    u = np.array([0.0, geom.width, geom.width, 0.0])
    v = np.array([0.0, 0.0, geom.height, geom.height])
    rays = np.stack([(u - geom.cx_px) / geom.f_px, (v - geom.cy_px) / geom.f_px, np.ones(4)])  # (3, 4)
    z = 1.25 * np.asarray(ranges_m, dtype=float)
    p_rect = rays[None, :, :] * z[:, None, None]  # (n, 3, 4)
    R, c = placement.T_ned_rect[:, :3, :3], placement.T_ned_rect[:, :3, 3]
    ned = np.swapaxes(R @ p_rect, 1, 2) + c[:, None, :]  # (n, 4, 3)
    return ned2map(ned[..., :2], origin)


def _tile_affines(
    grid: MapGrid, rows: NDArray, cols: NDArray, tile_m: float
) -> tuple[FloatArray, FloatArray]:
    """Per tile: local (north, east) of its north-west corner (k, 2) and the affine (k, 2, 2) from map
    offsets (x east, y north) to local offsets (exact conversion at three corners)."""
    x = grid.x0_m + cols * tile_m
    y = grid.y0_m - rows * tile_m
    corners = np.stack(
        [np.stack([x, y], -1), np.stack([x + tile_m, y], -1), np.stack([x, y - tile_m], -1)], axis=1
    )
    ne = map2ned(corners, grid.origin)  # (k, 3, 2)
    A = np.stack([(ne[:, 1] - ne[:, 0]) / tile_m, -(ne[:, 2] - ne[:, 0]) / tile_m], axis=2)
    return ne[:, 0], A


def reconstruct(
    dive: Dive,
    inputs: ReconInputs,
    out: Path,
    *,
    region: Region | None = None,
    dense: DenseSettings | None = None,
    fusion: FusionSettings | None = None,
    margin_m: float = 2.0,
    pairs: NDArray[np.intp] | None = None,
    cache_dir: Path | None = None,
    executor: Executor,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Reconstruct a dive (module docstring) into the folder ``out``; the summary.

    ``pairs`` limits the pairs considered (rows of the image index; default all): a reconstruction of
    the same pairs with another trajectory.

    Raises
    ------
    InsufficientDataError
        No images, no stereo calibration, no pair in the region and the trajectory's span, or no pair
        whose dense stereo succeeded.
    """
    region = region or Region()
    dense = dense or DenseSettings()
    fusion = fusion or FusionSettings()
    tick = progress or (lambda what, done, total: None)
    if dive.images is None or len(dive.images) == 0:
        raise InsufficientDataError(f"{dive.path}: reconstruction needs stereo images (images/index.csv)")
    rig = dive.vehicle.stereo
    if rig is None:
        raise InsufficientDataError(
            f"{dive.path}: reconstruction needs the stereo calibration (vehicle.yaml, key stereo)"
        )
    started = time.perf_counter()
    rect = rectification(rig)
    geom = DenseGeometry.of(rig, rect, dense)
    images = dive.images
    traj = inputs.trajectory
    chosen = np.ones(len(images), dtype=bool)
    if pairs is not None:
        chosen[:] = False
        chosen[np.asarray(pairs, dtype=np.intp)] = True
    outside = chosen & ((images.t_s < traj.t_s[0]) | (images.t_s > traj.t_s[-1]))
    if outside.any():
        log.warning(
            "%d of %d stereo pairs lie outside the %s trajectory's time span: left out",
            int(outside.sum()), int(chosen.sum()), inputs.trajectory_name,
        )  # fmt: skip
    inside_span = chosen & ~outside
    index = np.flatnonzero(inside_span)
    if len(index) == 0:
        raise InsufficientDataError(f"{dive.path}: no stereo pair lies inside the trajectory's time span")
    t_pairs = images.t_s[index]
    eta_all = None if inputs.tide is None else np.asarray(inputs.tide.predict(t_pairs), dtype=float)
    pressure = None
    if inputs.pressure_track is not None:
        track = inputs.pressure_track
        pressure = np.interp(t_pairs, track.t_s, track.p_ned_m[:, 2])
    placed = place_pairs(
        traj, t_pairs, rig, geom, eta_m=eta_all, apply_tide=inputs.apply_tide,
        tide_in_trajectory=inputs.tide_in_trajectory, pressure_down_m=pressure,
    )  # fmt: skip
    in_region = region.contains(placed.T_ned_rect[:, :2, 3], margin_m)
    index = index[in_region]
    placed = placed.select(in_region)
    if len(index) == 0:
        raise InsufficientDataError(f"{dive.path}: no stereo pair sees the region {_region_text(region)}")

    # 1. Dense stereo, per pair.
    images_dir = dive.path / "images"
    dctx = _DenseContext(images_dir, cache_dir, rig, rect, geom, dense)
    items = [(int(k), str(images.left[k]), str(images.right[k])) for k in index]
    status: dict[int, tuple[str, float, float]] = {}
    tick("dense stereo", 0, len(items))
    for chunk in executor.map(_dense_task, dctx, chunks(items, 4)):
        for k, what, frac, z in chunk:
            status[k] = (what, frac, z)
        tick("dense stereo", len(status), len(items))
    dense_s = time.perf_counter() - started
    failed = [k for k in index if status[k][0] not in ("ok", "missing")]
    missing = [k for k in index if status[k][0] == "missing"]
    for k in failed[:NAMED_FAILURES]:
        log.warning(
            "images/%s, images/%s: dense stereo failed (%s): pair skipped",
            images.left[k], images.right[k], status[k][0],
        )  # fmt: skip
    if len(failed) > NAMED_FAILURES:
        log.warning("%d more pairs whose dense stereo failed were skipped (pairs.csv names them)",
                    len(failed) - NAMED_FAILURES)  # fmt: skip
    ok = np.array([status[k][0] == "ok" for k in index])
    if not ok.any():
        raise InsufficientDataError(
            f"{dive.path}: dense stereo failed on every one of the {len(index)} pairs in the region "
            f"({len(missing)} with an image missing)"
        )

    # 2. Tiles and their pairs.
    origin = dive.info.origin
    used = index[ok]
    ranges = np.array([status[k][2] for k in used])
    sub = placed.select(ok)
    corners = _footprints_map(sub, ranges, geom, origin)  # (n, 4, 2)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    box_lo, box_hi = lo.min(axis=0), hi.max(axis=0)
    box = region.box()
    if box is not None:  # the tile grid stops at the region (its tiles hold what lies in them)
        reg_xy = ned2map(box, origin)
        box_lo, box_hi = np.maximum(box_lo, reg_xy.min(axis=0)), np.minimum(box_hi, reg_xy.max(axis=0))
        if np.any(box_hi <= box_lo):
            raise InsufficientDataError(
                f"{dive.path}: no image footprint meets the region {_region_text(region)}"
            )
    t = fusion.tile_m
    x0 = math.floor(box_lo[0] / t) * t
    y0 = math.ceil(box_hi[1] / t) * t
    n_cols = max(1, math.ceil((box_hi[0] - x0) / t - 1e-9))
    n_rows = max(1, math.ceil((y0 - box_lo[1]) / t - 1e-9))
    dem_grid = MapGrid(
        x0, y0, fusion.dem_cell_m, n_cols * fusion.dem_cells, n_rows * fusion.dem_cells, origin
    )
    mosaic_grid = MapGrid(
        x0, y0, fusion.mosaic_cell_m, n_cols * fusion.mosaic_cells, n_rows * fusion.mosaic_cells, origin
    )
    c_lo = np.floor((lo[:, 0] - x0) / t).astype(int)
    c_hi = np.floor((hi[:, 0] - x0) / t).astype(int)
    r_lo = np.floor((y0 - hi[:, 1]) / t).astype(int)
    r_hi = np.floor((y0 - lo[:, 1]) / t).astype(int)
    tiles: dict[tuple[int, int], list[int]] = {}
    for j in range(len(used)):
        for r in range(max(0, r_lo[j]), min(n_rows - 1, r_hi[j]) + 1):
            for c in range(max(0, c_lo[j]), min(n_cols - 1, c_hi[j]) + 1):
                tiles.setdefault((r, c), []).append(j)
    keys = sorted(tiles)
    rows_a = np.array([k[0] for k in keys])
    cols_a = np.array([k[1] for k in keys])
    ne0, A = _tile_affines(dem_grid, rows_a, cols_a, t) if keys else (np.zeros((0, 2)), np.zeros((0, 2, 2)))
    jobs = []
    for m, key in enumerate(keys):
        js = np.array(sorted(tiles[key], key=lambda j: sub.t_s[j]))
        ks = used[js]
        jobs.append(
            TileJob(
                row=key[0], col=key[1], A_ne_xy=A[m], ne0_m=ne0[m], pairs=ks.astype(np.int64),
                t_s=sub.t_s[js], T_ned_rect=sub.T_ned_rect[js], relief_before_m=sub.relief_before_m[js], relief_after_m=sub.relief_after_m[js],
                left=tuple(str(images.left[k]) for k in ks), right=tuple(str(images.right[k]) for k in ks),
            )
        )  # fmt: skip

    # 3. Fusion, a few tiles at a time, written as they come.
    fctx = FusionContext(images_dir, cache_dir, rig, rect, geom, dense, fusion, inputs.tide is not None)
    out = Path(out)
    dem_tif = TiledGeoTiff(
        out / P.RECON_DEM.name, dem_grid, 2, "float32", float("nan"), ("elevation_m", "sigma_m")
    )
    mosaic_tif = TiledGeoTiff(out / P.RECON_MOSAIC.name, mosaic_grid, 1, "uint8", 0, ("orthophoto",))
    comments = (
        "auvnav reconstruction: x east, y north, z up, metres, about the dive's origin "
        f"(latitude {math.degrees(origin.latitude_rad):.8f}, longitude {math.degrees(origin.longitude_rad):.8f}, WGS84)",
        "z is elevation above the tide datum"
        if inputs.tide is not None
        else "z is minus the trajectory's depth",
        f"map grid: {utm_crs(origin).to_string()}",
    )
    ply = PlyWriter(out / P.RECON_MESH.name, comments) if fusion.voxel_m > 0 else None
    relief: list[dict[str, Any]] = []
    tile_pairs = {}
    points = 0
    dem_cells = mosaic_cells = 0
    elev_lo, elev_hi = math.inf, -math.inf
    fusion_started = time.perf_counter()
    batch = max(1, 2 * executor.workers)
    done = 0
    tick("fusion tiles", 0, len(jobs))
    try:
        for start in range(0, len(jobs), batch):
            for results in executor.map(_tile_task, fctx, [[j] for j in jobs[start : start + batch]]):
                for res in results:
                    dem_tif.write(res.row * fusion.dem_cells, res.col * fusion.dem_cells, res.dem)
                    mosaic_tif.write(res.row * fusion.mosaic_cells, res.col * fusion.mosaic_cells, res.mosaic)
                    if ply is not None:
                        ply.add(res.vertices_enu_m, res.colours, res.faces)
                    relief += res.relief
                    points += res.points
                    tile_pairs[(res.row, res.col)] = res.pairs
                    have = np.isfinite(res.dem[0])
                    dem_cells += int(have.sum())
                    mosaic_cells += int((res.mosaic > 0).sum())
                    if have.any():
                        elev_lo = min(elev_lo, float(np.nanmin(res.dem[0])))
                        elev_hi = max(elev_hi, float(np.nanmax(res.dem[0])))
                    done += 1
                    tick("fusion tiles", done, len(jobs))
        dem_tif.close()
        mosaic_tif.close()
        if ply is not None:
            ply.close()
    except BaseException:
        dem_tif.abort()
        mosaic_tif.abort()
        if ply is not None:
            ply.abort()
        raise
    fusion_s = time.perf_counter() - fusion_started
    if ply is not None and ply.n_faces == 0 and dem_cells > 0:
        log.warning(
            "the %s TSDF gave an empty mesh (Open3D's legacy ScalableTSDFVolume does with open3d 0.20: "
            "use --tsdf blockgrid)",
            fusion.tsdf,
        )

    relief_frame = pd.DataFrame(relief, columns=RELIEF_COLUMNS)
    write_table(relief_frame, out / P.RECON_RELIEF.name)
    pair_status = np.array([status[k][0] for k in index], dtype=object)
    pairs_frame = pd.DataFrame(
        {
            "i": index,
            "t": placed.t_s,
            "left": [str(images.left[k]) for k in index],
            "right": [str(images.right[k]) for k in index],
            "north_m": placed.p_body_ned_m[:, 0],
            "east_m": placed.p_body_ned_m[:, 1],
            "down_m": placed.p_body_ned_m[:, 2],
            "tide_m": placed.eta_m,
            "status": [
                "ok" if s == "ok" else ("missing image" if s == "missing" else "failed") for s in pair_status
            ],
            "matched_fraction": [status[k][1] for k in index],
            "range_median_m": [status[k][2] for k in index],
            "reason": ["" if s in ("ok", "missing") else s for s in pair_status],
        }
    )
    write_table(pairs_frame, out / P.RECON_PAIRS.name)
    elapsed = time.perf_counter() - started
    summary = {
        "dive": dive.info.name,
        "trajectory": inputs.trajectory_name,
        "tide": {
            "source": inputs.tide_source,
            "applied": None
            if inputs.tide is None
            else (
                "in the trajectory (SLAM solved with it)"
                if inputs.tide_in_trajectory
                else (
                    "here"
                    if inputs.apply_tide
                    else "not to the placement: the SLAM trajectory is kept as solved"
                )
            ),
        },
        "region": asdict(region),
        "pairs": {
            "considered": len(index),
            "used": int(ok.sum()),
            "failed": len(failed),
            "missing_image": len(missing),
            "outside_trajectory": int(outside.sum()),
            "matched_fraction_median": float(np.median([status[k][1] for k in used])),
            "range_median_m": float(np.median(ranges)),
        },
        "dense": {
            **asdict(dense),
            "width_px": geom.width,
            "height_px": geom.height,
            "scale": geom.scale,
            "disparities_px": [geom.min_disparity, geom.min_disparity + geom.num_disparities],
        },
        "fusion": asdict(fusion),
        "grid": {
            "crs": utm_crs(origin).to_string(),
            "x0_m": x0,
            "y0_m": y0,
            "tiles": n_rows * n_cols,
            "tiles_with_data": len(jobs),
            "pairs_per_tile_max": max((len(v) for v in tiles.values()), default=0),
            "pairs_per_tile_median": float(np.median([len(v) for v in tiles.values()])) if tiles else 0.0,
            "dem_size": [dem_grid.width, dem_grid.height],
            "mosaic_size": [mosaic_grid.width, mosaic_grid.height],
        },
        "dem": {
            "cells": dem_cells,
            "area_m2": dem_cells * fusion.dem_cell_m**2,
            "elevation_min_m": None if dem_cells == 0 else elev_lo,
            "elevation_max_m": None if dem_cells == 0 else elev_hi,
        },
        "mosaic": {"cells": mosaic_cells, "area_m2": mosaic_cells * fusion.mosaic_cell_m**2},
        "mesh": None if ply is None else {"vertices": ply.n_vertices, "faces": ply.n_faces},
        "points": points,
        "relief": relief_summary(relief_frame),
        "seconds": {"dense": dense_s, "fusion": fusion_s, "total": elapsed},
        "pairs_per_s": float(ok.sum()) / elapsed if elapsed > 0 else None,
        "executor": executor.name,
        "workers": executor.workers,
    }
    return summary


def relief_summary(frame: pd.DataFrame) -> dict[str, Any]:
    """The Fig. 11 check in figures: steps between far-apart visits before and after the tide."""

    def rms(x: pd.Series) -> float | None:
        x = x.dropna().to_numpy(dtype=float)
        return float(np.sqrt(np.mean(x**2))) if x.size else None

    before, after = rms(frame["step_before_m"]), rms(frame["step_after_m"])
    return {
        "comparisons": len(frame),
        "step_placed_rms_m": rms(frame["step_placed_m"]),
        "step_before_rms_m": before,
        "step_after_rms_m": after,
        "step_before_median_abs_m": _median_abs(frame["step_before_m"]),
        "step_after_median_abs_m": _median_abs(frame["step_after_m"]),
        "step_before_max_m": float(frame["step_before_m"].abs().max()) if len(frame) else None,
        "step_after_max_m": float(frame["step_after_m"].abs().max())
        if len(frame) and frame["step_after_m"].notna().any()
        else None,
        "false_relief_before": int(frame["false_relief_before"].sum()) if len(frame) else 0,
        "false_relief_after": int(frame["false_relief_after"].sum()) if len(frame) else 0,
        "removed_pct": None if before is None or after is None or before == 0 else 100 * (1 - after / before),
    }


def _median_abs(x: pd.Series) -> float | None:
    """The median of the absolute values (None when there are none)."""
    v = x.dropna().to_numpy(dtype=float)
    return float(np.median(np.abs(v))) if v.size else None


def _region_text(region: Region) -> str:
    def b(lo: float | None, hi: float | None) -> str:
        return f"{'-inf' if lo is None else f'{lo:g}'}..{'inf' if hi is None else f'{hi:g}'}"

    return f"north {b(region.north_min_m, region.north_max_m)} m, east {b(region.east_min_m, region.east_max_m)} m"
