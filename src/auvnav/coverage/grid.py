"""Footprints on a map grid: images per cell, masks of polygons, gaps and their widths.

A cell counts as seen by an image when its centre lies inside the image's footprint (a convex
polygon): exact, with no outward bias of a line-drawing fill. :func:`count_polygons` does it for
all polygons at once, scanline by scanline: each polygon's rows give a column interval, and a
difference array summed along the rows turns the intervals into counts, so memory is one grid and
time is proportional to the cells covered.

Areas on the ground: a UTM grid's cell of side ``cell_m`` covers ``cell_m^2 / k^2`` of the ground,
``k^2`` the projection's areal scale at the site (:func:`ground_cell_area_m2`; 0.9992 near a
zone's central meridian, up to 1.002 at its edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray
from auvnav.raster import MapGrid, ned2map, utm_crs


def ground_cell_area_m2(grid: MapGrid) -> float:
    """Area of the ground one cell of ``grid`` covers, m^2 (the projection's areal scale removed)."""
    from pyproj import Proj

    crs = utm_crs(grid.origin)
    factors = Proj(crs).get_factors(
        math.degrees(grid.origin.longitude_rad), math.degrees(grid.origin.latitude_rad)
    )
    return grid.cell_m**2 / float(factors.areal_scale)


def polygons_to_cells(polygons_ne_m: FloatArray, grid: MapGrid) -> FloatArray:
    """Polygons (P, K, 2) in local north-east to the grid's cell coordinates (P, K, 2): (column, row)
    with cell centres at whole numbers."""
    xy = ned2map(np.asarray(polygons_ne_m, dtype=float), grid.origin)
    col = (xy[..., 0] - grid.x0_m) / grid.cell_m - 0.5
    row = (grid.y0_m - xy[..., 1]) / grid.cell_m - 0.5
    return np.stack([col, row], axis=-1)


def _row_intervals(
    cells: FloatArray, height: int, width: int
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
    """For convex polygons in cell coordinates (P, K, 2): every (polygon, row) with its first and last
    column of cell centres inside, clipped to the grid (empty intervals dropped)."""
    col, row = cells[..., 0], cells[..., 1]
    r0 = np.maximum(np.ceil(row.min(axis=1)), 0).astype(np.intp)
    r1 = np.minimum(np.floor(row.max(axis=1)), height - 1).astype(np.intp)
    n_rows = np.maximum(r1 - r0 + 1, 0)
    poly = np.repeat(np.arange(len(cells)), n_rows)
    offsets = np.concatenate([[0], np.cumsum(n_rows)[:-1]]) if len(cells) else np.zeros(0, np.intp)
    r = r0[poly] + (np.arange(poly.size) - np.repeat(offsets, n_rows))
    y0, y1 = row[poly], np.roll(row, -1, axis=1)[poly]
    x0, x1 = col[poly], np.roll(col, -1, axis=1)[poly]
    rr = r[:, None].astype(float)
    crosses = (np.minimum(y0, y1) <= rr) & (rr <= np.maximum(y0, y1)) & (y0 != y1)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # horizontal edges: not used
        x = x0 + (rr - y0) / (y1 - y0) * (x1 - x0)
    lo = np.where(crosses, x, np.inf).min(axis=1)
    hi = np.where(crosses, x, -np.inf).max(axis=1)
    c0 = np.maximum(np.ceil(lo - 1e-9), 0)
    c1 = np.minimum(np.floor(hi + 1e-9), width - 1)
    keep = np.isfinite(lo) & (c0 <= c1)
    return poly[keep], r[keep], c0[keep].astype(np.intp), c1[keep].astype(np.intp)


def count_cells(cells: FloatArray, height: int, width: int, *, chunk: int = 4096) -> NDArray[np.int32]:
    """How many convex polygons (P, K, 2), in cell coordinates, hold each cell's centre; (height, width)."""
    diff = np.zeros(height * (width + 1), dtype=np.int32)
    for start in range(0, len(cells), chunk):
        _, r, c0, c1 = _row_intervals(cells[start : start + chunk], height, width)
        np.add.at(diff, r * (width + 1) + c0, 1)
        np.add.at(diff, r * (width + 1) + c1 + 1, -1)
    return np.cumsum(diff.reshape(height, width + 1), axis=1, dtype=np.int32)[:, :width]


def count_polygons(polygons_ne_m: FloatArray, grid: MapGrid) -> NDArray[np.int32]:
    """Images per cell: how many footprints (P, K, 2), north-east in local NED, hold each cell's centre."""
    return count_cells(polygons_to_cells(polygons_ne_m, grid), grid.height, grid.width)


def polygon_mask(polygons_ne_m: FloatArray | list[FloatArray], grid: MapGrid) -> NDArray[np.bool_]:
    """Cells whose centre lies in any of the convex polygons (each (K, 2), north-east), shape (H, W)."""
    polys = list(polygons_ne_m)
    if not polys:
        return np.zeros((grid.height, grid.width), dtype=bool)
    k = max(len(p) for p in polys)
    padded = np.stack([np.concatenate([p, np.repeat(p[-1:], k - len(p), axis=0)]) for p in polys])
    return count_polygons(padded, grid) > 0


@dataclass(frozen=True)
class Gaps:
    """Connected regions of a region's cells not seen by any image (8-connected).

    Parameters
    ----------
    labels : ndarray of int32, shape (H, W)
        0 where there is no gap, else the gap's number (1-based, largest first).
    area_m2 : ndarray, shape (G,)
        Ground area of each gap, m^2.
    width_m : ndarray, shape (G,)
        Width of each gap, metres: the diameter of the largest disc centred on one of its cells that
        stays inside it, ``(2 d - 1)`` cells for ``d`` the largest distance (in cells, centre to centre)
        from one of its cells to a cell outside it: a strip ``n`` cells wide measures ``n`` cells when
        ``n`` is odd, ``n - 1`` when it is even.
    centroid_ne_m : ndarray, shape (G, 2)
        Centre of each gap, local north and east, metres.
    bbox_cells : ndarray of int, shape (G, 4)
        Row and column of its first cell, rows and columns it spans.
    """

    labels: NDArray[np.int32]
    area_m2: FloatArray
    width_m: FloatArray
    centroid_ne_m: FloatArray
    bbox_cells: NDArray[np.intp]

    def __len__(self) -> int:
        return len(self.area_m2)


def find_gaps(
    uncovered: NDArray[np.bool_], grid: MapGrid, *, min_area_m2: float, cell_area_m2: float
) -> Gaps:
    """The gaps of a region: connected uncovered cells (``uncovered``: inside the region and seen by
    no image) of at least ``min_area_m2``; the rest of the grid (covered or outside) bounds them."""
    import cv2
    from scipy import ndimage

    from auvnav.raster import map2ned

    mask = uncovered.astype(np.uint8)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8, ltype=cv2.CV_32S)
    area = stats[1:, cv2.CC_STAT_AREA].astype(float) * cell_area_m2
    keep = np.flatnonzero(area >= min_area_m2) + 1
    if keep.size == 0:
        return Gaps(
            np.zeros(uncovered.shape, np.int32),
            np.zeros(0),
            np.zeros(0),
            np.zeros((0, 2)),
            np.zeros((0, 4), np.intp),
        )
    dist = cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    radius = np.asarray(ndimage.maximum(dist, labels, keep), dtype=float)
    order = np.argsort(-area[keep - 1], kind="stable")
    keep, radius = keep[order], radius[order]
    relabel = np.zeros(n, dtype=np.int32)
    relabel[keep] = np.arange(1, keep.size + 1, dtype=np.int32)
    col, row = centroids[keep, 0], centroids[keep, 1]
    xy = np.stack([grid.x0_m + (col + 0.5) * grid.cell_m, grid.y0_m - (row + 0.5) * grid.cell_m], axis=-1)
    bbox = np.stack(
        [
            stats[keep, cv2.CC_STAT_TOP],
            stats[keep, cv2.CC_STAT_LEFT],
            stats[keep, cv2.CC_STAT_HEIGHT],
            stats[keep, cv2.CC_STAT_WIDTH],
        ],
        axis=-1,
    ).astype(np.intp)
    return Gaps(
        labels=relabel[labels],
        area_m2=area[keep - 1],
        width_m=np.maximum(2.0 * radius - 1.0, 1.0) * grid.cell_m,
        centroid_ne_m=map2ned(xy, grid.origin),
        bbox_cells=bbox,
    )
