"""A reconstruction against a simulated truth: DEM error, orthophoto misregistration, false relief.

The seafloor and its albedo are functions of world coordinates (the simulator's, handed in by
:mod:`auvnav.evaluate`: nothing here imports the simulator). A reconstruction lives in the frame of the
trajectory that placed it, which differs from the world by what no relative measurement sees (the
starting fix, the compass's constant term); as for ``ate_aligned_rmse_m``, the placed poses of the pairs
it used are aligned to the true poses at the same times (the best rotation about the vertical and
translation, ``align``), and the products are scored through that alignment:

- ``dem_rmse_m``: every DEM cell's point (its centre, minus its elevation as depth), aligned, against
  the true depth at the aligned place; ``dem_rmse_unaligned_m`` without the alignment;
- ``mosaic_misregistration_*``: the orthophoto cut into blocks of 256 x 256 cells (those at least
  99% covered), each phase-correlated (``cv2.phaseCorrelate``, Hanning window) with the true albedo
  rendered at the aligned centres of its cells; the shift's length, in cells (pixels) and millimetres;
- ``relief_step_before_m``, ``relief_step_after_m``: RMS over ``relief.csv`` of the steps between
  visits more than 20 minutes apart, without and with the tide correction (no truth needed);
  ``relief_step_*_median_abs_m`` the median of their sizes (one bad comparison does not sway it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pandas as pd

from auvnav import products as P
from auvnav.footprint import SeafloorLike
from auvnav.frames import FloatArray, rot_z
from auvnav.raster import MapGrid, map2ned
from auvnav.trajectory import Trajectory

BLOCK = 256
MIN_COVERED = 0.99
MAX_BLOCKS = 400


class AlbedoLike(Protocol):
    """Anything with a vectorised albedo of world points (the simulator's texture)."""

    def albedo(self, north_m: FloatArray, east_m: FloatArray, *, footprint_m: float = 0.0) -> FloatArray: ...


Align = Callable[[FloatArray, FloatArray], "tuple[float, FloatArray]"]


def _grid(profile: dict[str, Any], origin: Any) -> MapGrid:
    t = profile["transform"]
    return MapGrid(float(t.c), float(t.f), float(t.a), int(profile["width"]), int(profile["height"]), origin)


def _aligned_ne(grid: MapGrid, r0: int, c0: int, h: int, w: int, yaw: float, t: FloatArray) -> FloatArray:
    """Local (north, east) of the cells (h, w, 2) of a window, moved by the alignment (rotation about
    the vertical and horizontal translation)."""
    x = grid.x0_m + (c0 + np.arange(w) + 0.5) * grid.cell_m
    y = grid.y0_m - (r0 + np.arange(h) + 0.5) * grid.cell_m
    xx, yy = np.meshgrid(x, y)
    ne = map2ned(np.stack([xx, yy], axis=-1), grid.origin)
    R = rot_z(yaw)[:2, :2]
    return ne @ R.T + t[:2]


def recon_section(
    dive_path: Path,
    truth: Trajectory,
    floor: SeafloorLike,
    texture: AlbedoLike | None,
    align: Align,
    *,
    folder: Path | None = None,
) -> dict[str, Any] | None:
    """Score a reconstruction (module docstring); None when it has no products.

    Parameters
    ----------
    dive_path : Path
    truth : Trajectory
        The true trajectory.
    floor : object with ``depth_m(north_m, east_m)``
        The true seafloor, depth below the datum.
    texture : object with ``albedo(north_m, east_m, footprint_m=)``, optional
        The true albedo (no mosaic score without it).
    align : callable(p_est, p_ref) -> (yaw_rad, t_ned_m)
        The best rigid alignment about the vertical (:func:`auvnav.evaluate.align_yaw_translation`).
    folder : Path, optional
        The products' folder (default ``DIVE/products/recon``).
    """
    import rasterio

    from auvnav.dive import read_dive_info

    folder = Path(folder) if folder is not None else P.stage_dir(dive_path, "recon")
    pairs_file, dem_file = folder / P.RECON_PAIRS.name, folder / P.RECON_DEM.name
    if not pairs_file.is_file() or not dem_file.is_file():
        return None
    origin = read_dive_info(dive_path).origin
    pairs = pd.read_csv(pairs_file)
    pairs = pairs[(pairs["status"] == "ok") & (pairs["t"] >= truth.t_s[0]) & (pairs["t"] <= truth.t_s[-1])]
    est = pairs[["north_m", "east_m", "down_m"]].to_numpy(dtype=float)
    ref = truth.interpolate(pairs["t"].to_numpy(dtype=float)).p_ned_m
    yaw, t = align(est, ref)
    aligned = est @ rot_z(yaw).T + t
    out: dict[str, Any] = {
        "pairs": len(pairs),
        "alignment_yaw_deg": math.degrees(yaw),
        "alignment_m": [float(v) for v in t],
        "placement_aligned_rmse_m": float(np.sqrt(np.mean(np.sum((aligned - ref) ** 2, axis=1)))),
    }

    # DEM against the true depth, aligned and not.
    errors, raw_sq = [], []
    with rasterio.open(dem_file) as src:
        grid = _grid(dict(src.profile), origin)
        for _, window in src.block_windows(1):
            elev = src.read(1, window=window)
            have = np.isfinite(elev)
            if not have.any():
                continue
            r0, c0, h, w = int(window.row_off), int(window.col_off), int(window.height), int(window.width)
            ne = _aligned_ne(grid, r0, c0, h, w, 0.0, np.zeros(3))
            p = np.concatenate([ne[have], -elev[have, None].astype(float)], axis=1)
            raw_sq.append((p[:, 2] - floor.depth_m(p[:, 0], p[:, 1])) ** 2)
            q = p @ rot_z(yaw).T + t
            errors.append(q[:, 2] - floor.depth_m(q[:, 0], q[:, 1]))
    if errors:
        err = np.concatenate(errors)
        out.update(
            dem_rmse_m=float(np.sqrt(np.mean(err**2))),
            dem_rmse_unaligned_m=float(np.sqrt(np.mean(np.concatenate(raw_sq)))),
            dem_error_median_m=float(np.median(err)),
            dem_error_abs_p95_m=float(np.percentile(np.abs(err), 95)),
            dem_cells=len(err),
        )
    else:
        out.update(dem_rmse_m=None, dem_rmse_unaligned_m=None, dem_cells=0)

    # Orthophoto against the true albedo, block by block.
    mosaic_file = folder / P.RECON_MOSAIC.name
    shifts: list[float] = []
    cell_m = None
    if texture is not None and mosaic_file.is_file():
        import cv2

        with rasterio.open(mosaic_file) as src:
            grid = _grid(dict(src.profile), origin)
            cell_m = grid.cell_m
            windows = []
            for _, window in src.block_windows(1):
                if window.width == BLOCK and window.height == BLOCK:
                    windows.append(window)
            full = []
            for window in windows:
                block = src.read(1, window=window)
                if np.mean(block > 0) >= MIN_COVERED:
                    full.append((window, block))
            step = max(1, math.ceil(len(full) / MAX_BLOCKS))
            hann = cv2.createHanningWindow((BLOCK, BLOCK), cv2.CV_32F)
            for window, block in full[::step]:
                r0, c0 = int(window.row_off), int(window.col_off)
                ne = _aligned_ne(grid, r0, c0, BLOCK, BLOCK, yaw, t)
                true = texture.albedo(ne[..., 0], ne[..., 1], footprint_m=grid.cell_m).astype(np.float32)
                seen = block.astype(np.float32)
                (dx, dy), _ = cv2.phaseCorrelate(true, seen, hann)
                shifts.append(math.hypot(dx, dy))
    if shifts:
        s = np.asarray(shifts)
        out.update(
            mosaic_misregistration_median_px=float(np.median(s)),
            mosaic_misregistration_p95_px=float(np.percentile(s, 95)),
            mosaic_misregistration_median_mm=float(np.median(s)) * 1000 * cell_m,
            mosaic_misregistration_p95_mm=float(np.percentile(s, 95)) * 1000 * cell_m,
            mosaic_blocks=len(s),
            mosaic_cell_mm=1000 * cell_m,
        )
    else:
        out.update(mosaic_misregistration_median_px=None, mosaic_misregistration_p95_px=None, mosaic_blocks=0)

    # The Fig. 11 check, as the stage measured it.
    relief_file = folder / P.RECON_RELIEF.name
    before = after = None
    if relief_file.is_file():
        relief = pd.read_csv(relief_file)

        def rms(column: str) -> float | None:
            x = relief[column].dropna().to_numpy(dtype=float) if column in relief else np.zeros(0)
            return float(np.sqrt(np.mean(x**2))) if x.size else None

        def median_abs(column: str) -> float | None:
            x = relief[column].dropna().to_numpy(dtype=float) if column in relief else np.zeros(0)
            return float(np.median(np.abs(x))) if x.size else None

        before, after = rms("step_before_m"), rms("step_after_m")
        out["relief_comparisons"] = len(relief)
        out["relief_step_before_median_abs_m"] = median_abs("step_before_m")
        out["relief_step_after_median_abs_m"] = median_abs("step_after_m")
    out.update(
        relief_step_before_m=before,
        relief_step_after_m=after,
        relief_removed_pct=None
        if before is None or after is None or before == 0
        else 100 * (1 - after / before),
    )
    return out
