"""Fusion of placed depth maps, one map tile at a time: DEM, orthophoto, TSDF mesh and revisits.

The region is cut into square tiles of the map grid (UTM of the dive's origin, :mod:`auvnav.raster`),
``tile_m`` on a side; a tile reads only the pairs whose footprint meets it, so memory is bounded by the
tile, never by the survey. Within a tile the map and the local NED frame are related by an affine map
(fitted to the exact conversion at the tile's corners: the UTM scale and meridian convergence do not
change over a few metres).

- **DEM**: each valid pixel's point (rectified left camera -> local NED by the pair's placed pose) falls
  in a DEM cell; a cell's elevation (metres, up, ``-down``) is the inverse-variance weighted mean of its
  points (weights ``1 / sigma_Z^2``, :mod:`auvnav.recon.dense`), its 1-sigma that mean's formal sigma
  inflated by the points' reduced chi-square when above one. Cells with fewer than ``min_points``
  points, or a 1-sigma over ``max_sigma_m``, have no data.
- **Orthophoto**: every mosaic cell's point on the DEM (bilinear, small holes filled) is projected into
  each pair's rectified, illumination-corrected left image and sampled (bilinear); the images are
  blended with feathered weights, the square of the distance to the image's border over half its
  height, so seams fade over the whole overlap (a weighted average, Szeliski 2006, "Image alignment
  and stitching: a tutorial", section 6.2, feathering).
- **Mesh**: the tile's depth maps (each cut to the tile and a margin, the rims of their matched
  regions left out) are integrated into a truncated
  signed distance volume (Curless and Levoy 1996, "A volumetric method for building complex models
  from range images", SIGGRAPH) with Open3D, the tensor ``VoxelBlockGrid`` or the legacy
  ``ScalableTSDFVolume``; marching cubes gives the coloured mesh, cut to the triangles whose centroid
  lies in the tile (the voxel grid is aligned across tiles, so neighbouring tiles meet).
- **Revisits** (the paper's Fig. 11): the tile's pairs are split into visits (runs of pairs with no
  gap over ``visit_gap_s``); for two visits more than ``far_apart_s`` apart, each visit's own DEM is
  made over the tile and their difference over the cells both see is the step a reconstruction would
  show there: its median, with and without the tide correction (the tide at each pair is known, so
  both come from the same points). A step over ``relief_step_m`` and three sigma is false relief.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray
from auvnav.recon.dense import DenseGeometry, DenseSettings, pair_dense
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import Rectification

log = logging.getLogger(__name__)

Tsdf = Literal["blockgrid", "scalable"]


@dataclass(frozen=True)
class FusionSettings:
    """How depth maps are fused (module docstring).

    Parameters
    ----------
    tile_m : float
        Side of a tile, metres; a whole number of DEM and mosaic cells.
    dem_cell_m, mosaic_cell_m : float
        Cells of the DEM and of the orthophoto, metres.
    voxel_m : float
        TSDF voxel, metres (0: no mesh).
    tsdf : {"blockgrid", "scalable"}
        Open3D's tensor ``VoxelBlockGrid`` or legacy ``ScalableTSDFVolume``.
    truncation_voxels : float
        TSDF truncation, voxels.
    edge_px : int
        Matched pixels this close to the rim of a matched region are not integrated into the TSDF
        (they make skirts of triangles off the floor: the 95th percentile of the mesh's error on the
        test dive falls from 10 to 8 cm with 3 pixels).
    min_points : int
        Points a DEM cell needs.
    max_sigma_m : float
        DEM cells whose 1-sigma (inflated by their points' scatter) exceeds this have no data: the
        flanks of steep relief and occlusions, where the views disagree (0: keep every cell).
    fill_px : int
        DEM holes up to about this many cells across are filled for the orthophoto.
    visit_gap_s, far_apart_s : float
        Visits of a tile are split by gaps over ``visit_gap_s``; two visits more than ``far_apart_s``
        apart are compared (the depth stage's 20 minutes).
    relief_step_m : float
        A step between visits over this (and three sigma) is false relief (the depth stage's 10 cm).
    min_relief_cells : int
        DEM cells two visits must share to be compared.
    """

    tile_m: float = 5.12
    dem_cell_m: float = 0.01
    mosaic_cell_m: float = 0.002
    voxel_m: float = 0.02
    tsdf: Tsdf = "blockgrid"
    truncation_voxels: float = 4.0
    edge_px: int = 3
    min_points: int = 3
    max_sigma_m: float = 0.01
    fill_px: int = 8
    visit_gap_s: float = 60.0
    far_apart_s: float = 1200.0
    relief_step_m: float = 0.1
    min_relief_cells: int = 400

    def __post_init__(self) -> None:
        for name in ("tile_m", "dem_cell_m", "mosaic_cell_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive; found {getattr(self, name)}")
        for name in ("dem_cell_m", "mosaic_cell_m"):
            n = self.tile_m / getattr(self, name)
            if abs(n - round(n)) > 1e-6 or round(n) < 1:
                raise ValueError(
                    f"tile_m ({self.tile_m:g} m) must be a whole number of {name} ({getattr(self, name):g} m)"
                )
        if self.voxel_m < 0 or self.edge_px < 0:
            raise ValueError(f"voxel_m and edge_px must be >= 0; found {self.voxel_m}, {self.edge_px}")

    @property
    def dem_cells(self) -> int:
        return round(self.tile_m / self.dem_cell_m)

    @property
    def mosaic_cells(self) -> int:
        return round(self.tile_m / self.mosaic_cell_m)


@dataclass(frozen=True)
class TileJob:
    """One tile's work: where it is, and the pairs that see it (in time order).

    Parameters
    ----------
    row, col : int
        The tile's place in the tile grid (rows from north to south).
    A_ne_xy : ndarray, shape (2, 2)
        Map metres (x east, y north) relative to the tile's north-west corner -> local (north, east),
        relative to ``ne0_m``.
    ne0_m : ndarray, shape (2,)
        Local (north, east) of the tile's north-west corner, metres.
    pairs : ndarray of int, shape (n,)
        Indices of the pairs (rows of the image index).
    t_s : ndarray, shape (n,)
    T_ned_rect : ndarray, shape (n, 4, 4)
        Placed pose of each pair's rectified left camera (tide-corrected when a tide is known).
    relief_before_m, relief_after_m : ndarray, shape (n,)
        Added to a pair's elevations as placed, they give its elevations from pressure depth without
        and with the tide correction (:class:`~auvnav.recon.placement.Placement`).
    left, right : tuple of str
        Image file names relative to ``images/``.
    """

    row: int
    col: int
    A_ne_xy: FloatArray
    ne0_m: FloatArray
    pairs: NDArray[np.int64]
    t_s: FloatArray
    T_ned_rect: FloatArray
    relief_before_m: FloatArray
    relief_after_m: FloatArray
    left: tuple[str, ...]
    right: tuple[str, ...]


@dataclass(frozen=True)
class FusionContext:
    """What every tile task shares (picklable)."""

    images_dir: Path
    cache_dir: Path | None
    rig: StereoRig
    rect: Rectification
    geom: DenseGeometry
    dense: DenseSettings
    settings: FusionSettings
    tide_known: bool


@dataclass
class TileResult:
    """A tile's products.

    ``dem`` (2, n, n) float32 elevation and 1-sigma, metres (NaN: no data); ``mosaic`` (m, m) uint8
    (0: no data); the mesh as ``vertices_enu_m`` (k, 3) float64 (east, north, up about the dive's
    origin), ``colours`` (k, 3) uint8 and ``faces`` (f, 3) int32; ``relief`` rows; ``points`` used.
    """

    row: int
    col: int
    dem: NDArray[np.float32]
    mosaic: NDArray[np.uint8]
    vertices_enu_m: FloatArray
    colours: NDArray[np.uint8]
    faces: NDArray[np.int32]
    relief: list[dict[str, Any]]
    points: int
    pairs: int


def visits(t_s: FloatArray, gap_s: float) -> NDArray[np.intp]:
    """Visit number of each time (sorted): a new visit after every gap over ``gap_s``."""
    t = np.asarray(t_s, dtype=float)
    if t.size == 0:
        return np.zeros(0, dtype=np.intp)
    return np.concatenate([[0], np.cumsum(np.diff(t) > gap_s)]).astype(np.intp)


def _fill(values: NDArray[np.float32], valid: NDArray[np.bool_], radius: int) -> NDArray[np.float32]:
    """Holes filled by normalised convolution (Knutsson and Westin 1993) over about ``radius`` cells."""
    if valid.all() or not valid.any():
        return values
    k = 2 * radius + 1
    w = cv2.blur(valid.astype(np.float32), (k, k))
    s = cv2.blur(np.where(valid, values, 0).astype(np.float32), (k, k))
    out = values.copy()
    hole = ~valid & (w > 0)
    out[hole] = s[hole] / w[hole]
    out[~valid & (w <= 0)] = np.nan
    return out


def fuse_tile(ctx: FusionContext, job: TileJob) -> TileResult:
    """Fuse the pairs of one tile (module docstring)."""
    s = ctx.settings
    n_dem = s.dem_cells
    A = np.asarray(job.A_ne_xy, dtype=float)
    A_inv = np.linalg.inv(A)
    A_inv32 = A_inv.astype(np.float32)
    inv_cell = np.float32(1.0 / s.dem_cell_m)
    ne0 = np.asarray(job.ne0_m, dtype=float)
    visit = visits(job.t_s, s.visit_gap_s)
    cells = n_dem * n_dem
    W, WZ, WZ2, N = (np.zeros(cells) for _ in range(4))
    visit_sums = _VisitSums(cells)  # one visit's sums at a time; finished visits kept sparse
    margin_m = s.voxel_m * (s.truncation_voxels + 2) if s.voxel_m > 0 else 0.0
    geom = ctx.geom
    used: list[tuple[int, NDArray[np.uint8], tuple[float, float, float, float]]] = []
    tsdf: _Tsdf | None = None
    points = 0
    for k in range(len(job.pairs)):
        try:
            dense = pair_dense(
                ctx.images_dir / job.left[k],
                ctx.images_dir / job.right[k],
                ctx.rig,
                ctx.rect,
                geom,
                ctx.dense,
                ctx.cache_dir,
            )
        except ValueError:  # DenseFailed: said when the pair was matched
            dense = None
        if dense is None:
            continue
        T = job.T_ned_rect[k]
        # Points relative to the tile's north-west corner (north, east) and the camera's depth.
        local = T[:3, 3] - np.array([ne0[0], ne0[1], 0.0])
        p, z, idx = dense.points_local(geom, T[:3, :3], local)
        x = A_inv32[0, 0] * p[:, 0] + A_inv32[0, 1] * p[:, 1]  # map metres east of the corner
        y = -(A_inv32[1, 0] * p[:, 0] + A_inv32[1, 1] * p[:, 1])  # map metres south of it, as rows go
        inside = (x >= 0) & (x < s.tile_m) & (y >= 0) & (y < s.tile_m)
        if not inside.any():
            continue
        zi = z[inside]
        sigma = zi * zi * np.float32(ctx.dense.sigma_disparity_px / (geom.f_px * geom.baseline_m))
        wi = (1.0 / (sigma * sigma)).astype(np.float64)
        ei = -p[inside, 2].astype(np.float64)  # elevation: up
        cell = (np.floor(y[inside] * inv_cell).astype(np.intp) * n_dem
                + np.floor(x[inside] * inv_cell).astype(np.intp))  # fmt: skip
        np.minimum(cell, cells - 1, out=cell)
        W += np.bincount(cell, wi, cells)
        WZ += np.bincount(cell, wi * ei, cells)
        WZ2 += np.bincount(cell, wi * ei * ei, cells)
        N += np.bincount(cell, None, cells)
        visit_sums.add(int(visit[k]), cell, wi, ei, job.relief_before_m[k], job.relief_after_m[k])
        points += int(inside.sum())
        xi, yi = x[inside], y[inside]
        box = (float(xi.min()), float(xi.max()), float(yi.min()), float(yi.max()))
        used.append((k, dense.image, box))
        if s.voxel_m > 0:
            near = (x >= -margin_m) & (x < s.tile_m + margin_m) & (y >= -margin_m) & (y < s.tile_m + margin_m)
            depth = np.zeros(geom.width * geom.height, dtype=np.float32)
            depth[idx[near]] = z[near].astype(np.float32)
            if tsdf is None:
                tsdf = _Tsdf(s, geom, ne0, float(T[2, 3]), ctx.dense.max_range_m)
            depth_map = depth.reshape(geom.height, geom.width)
            if s.edge_px > 0:  # no surface from the rims of the matched regions (skirts in the mesh)
                k = 2 * s.edge_px + 1
                keep = cv2.erode((depth_map > 0).astype(np.uint8), np.ones((k, k), np.uint8))
                depth_map[keep == 0] = 0.0
            tsdf.integrate(depth_map, dense.image, T)
    ok = N >= s.min_points
    mean = np.full(cells, np.nan)
    mean[ok] = WZ[ok] / W[ok]
    chi2 = np.zeros(cells)
    chi2[ok] = np.maximum(WZ2[ok] - W[ok] * mean[ok] ** 2, 0.0)
    dof = np.maximum(N - 1, 1)
    sig = np.full(cells, np.nan)
    sig[ok] = np.sqrt(np.maximum(1.0, chi2[ok] / dof[ok]) / W[ok])
    if s.max_sigma_m > 0:
        mean[sig > s.max_sigma_m] = np.nan
        sig[sig > s.max_sigma_m] = np.nan
    dem = np.stack([mean, sig]).reshape(2, n_dem, n_dem).astype(np.float32)
    relief = _relief(job, visit, visit_sums.done(), ok, ctx.tide_known, s)
    mosaic = _orthophoto(job, used, dem[0], A, ne0, geom, s)
    if tsdf is not None:
        vertices, colours, faces = tsdf.mesh(A_inv, ne0)
    else:
        vertices, colours, faces = np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3), np.int32)
    return TileResult(job.row, job.col, dem, mosaic, vertices, colours, faces, relief, points, len(used))


@dataclass(frozen=True)
class _Visit:
    """One visit's DEM over a tile, sparse: its cells, and per cell the weighted mean elevation as
    placed and the mean offsets to pressure depth without and with the tide."""

    cells: NDArray[np.intp]
    elevation_m: FloatArray
    before_m: FloatArray
    after_m: FloatArray


class _VisitSums:
    """Sums of the current visit over every cell; a finished visit is kept as a sparse :class:`_Visit`
    (visits arrive in time order), so memory holds one dense set whatever the number of visits."""

    def __init__(self, cells: int) -> None:
        self.current = -1
        self.sums = np.zeros((4, cells))
        self.visits: dict[int, _Visit] = {}

    def add(
        self, v: int, cell: NDArray[np.intp], w: FloatArray, elev: FloatArray, before: float, after: float
    ) -> None:
        if v != self.current:
            self._flush()
            self.current = v
        n = self.sums.shape[1]
        self.sums[0] += np.bincount(cell, w, n)
        self.sums[1] += np.bincount(cell, w * elev, n)
        self.sums[2] += np.bincount(cell, w * before, n)
        self.sums[3] += np.bincount(cell, w * after, n)

    def _flush(self) -> None:
        if self.current < 0:
            return
        idx = np.flatnonzero(self.sums[0])
        w = self.sums[0, idx]
        self.visits[self.current] = _Visit(
            idx, self.sums[1, idx] / w, self.sums[2, idx] / w, self.sums[3, idx] / w
        )
        self.sums[:, idx] = 0.0

    def done(self) -> dict[int, _Visit]:
        self._flush()
        self.current = -1
        return self.visits


def _relief(
    job: TileJob,
    visit: NDArray[np.intp],
    sums: dict[int, _Visit],
    ok: NDArray[np.bool_],
    tide_known: bool,
    s: FusionSettings,
) -> list[dict[str, Any]]:
    """Steps between the tile's visits more than ``far_apart_s`` apart (module docstring)."""
    rows: list[dict[str, Any]] = []
    ids = sorted(sums)
    spans = {v: (float(job.t_s[visit == v].min()), float(job.t_s[visit == v].max())) for v in ids}
    for ia, a in enumerate(ids):
        for b in ids[ia + 1 :]:
            if spans[b][0] - spans[a][1] <= s.far_apart_s:
                continue
            va, vb = sums[a], sums[b]
            cells, ja, jb = np.intersect1d(va.cells, vb.cells, assume_unique=True, return_indices=True)
            good = ok[cells]
            cells, ja, jb = cells[good], ja[good], jb[good]
            n = len(cells)
            if n < s.min_relief_cells:
                continue
            za, zb = va.elevation_m[ja], vb.elevation_m[jb]
            placed = zb - za
            before = (zb + vb.before_m[jb]) - (za + va.before_m[ja])
            after = (zb + vb.after_m[jb]) - (za + va.after_m[ja])
            tide_change = (vb.after_m[jb] - vb.before_m[jb]) - (va.after_m[ja] - va.before_m[ja])
            r, c = np.divmod(cells, s.dem_cells)
            centre_xy = np.array([c.mean() + 0.5, -(r.mean() + 0.5)]) * s.dem_cell_m
            ne = job.ne0_m + job.A_ne_xy @ centre_xy

            def step(d: FloatArray) -> tuple[float, float]:
                med = float(np.median(d))
                return med, 1.4826 * float(np.median(np.abs(d - med))) / math.sqrt(len(d))

            placed_m, placed_sigma = step(placed)
            before_m, before_sigma = step(before)
            after_m, after_sigma = step(after)
            rows.append(
                {
                    "tile_row": job.row,
                    "tile_col": job.col,
                    "north_m": float(ne[0]),
                    "east_m": float(ne[1]),
                    "t_a_start": spans[a][0],
                    "t_a_end": spans[a][1],
                    "t_b_start": spans[b][0],
                    "t_b_end": spans[b][1],
                    "dt_s": spans[b][0] - spans[a][1],
                    "cells": n,
                    "area_m2": n * s.dem_cell_m**2,
                    "tide_change_m": float(np.median(tide_change)) if tide_known else math.nan,
                    "step_placed_m": placed_m,
                    "step_placed_sigma_m": placed_sigma,
                    "step_before_m": before_m,
                    "step_before_sigma_m": before_sigma,
                    "step_after_m": after_m if tide_known else math.nan,
                    "step_after_sigma_m": after_sigma if tide_known else math.nan,
                    "false_relief_before": bool(abs(before_m) > max(s.relief_step_m, 3 * before_sigma)),
                    "false_relief_after": bool(abs(after_m) > max(s.relief_step_m, 3 * after_sigma))
                    if tide_known
                    else False,
                }
            )
    return rows


def _orthophoto(
    job: TileJob,
    used: list[tuple[int, NDArray[np.uint8], tuple[float, float, float, float]]],
    elevation: NDArray[np.float32],
    A: FloatArray,
    ne0: FloatArray,
    geom: DenseGeometry,
    s: FusionSettings,
) -> NDArray[np.uint8]:
    """The tile's orthophoto from the DEM and the pairs' corrected left images (module docstring)."""
    m = s.mosaic_cells
    out = np.zeros((m, m), dtype=np.uint8)
    valid = np.isfinite(elevation)
    if not used or not valid.any():
        return out
    filled = _fill(elevation, valid, s.fill_px)
    has_dem = np.isfinite(filled)
    # Mosaic cell centres sample the DEM bilinearly (a cell-centre aligned resize).
    up = cv2.resize(np.where(has_dem, filled, 0).astype(np.float32), (m, m), interpolation=cv2.INTER_LINEAR)
    has = cv2.resize(has_dem.astype(np.float32), (m, m), interpolation=cv2.INTER_LINEAR) > 0.999
    # Cell centres relative to the tile centre, map metres (float32 is exact to a micrometre here).
    half_m = s.tile_m / 2
    coords = (np.arange(m, dtype=np.float64) + 0.5) * s.mosaic_cell_m
    xs = (coords - half_m).astype(np.float32)
    ys = (half_m - coords).astype(np.float32)
    ne_c = ne0 + A @ np.array([half_m, -half_m])  # local north, east of the tile centre
    acc = np.zeros((m, m), dtype=np.float32)
    wsum = np.zeros((m, m), dtype=np.float32)
    half_px = np.float32(0.5 * min(geom.width, geom.height))
    A32 = A.astype(np.float32)
    for k, image, (x0, x1, y0, y1) in used:
        c0, c1 = max(0, int(x0 / s.mosaic_cell_m) - 2), min(m, int(np.ceil(x1 / s.mosaic_cell_m)) + 2)
        r0, r1 = max(0, int(y0 / s.mosaic_cell_m) - 2), min(m, int(np.ceil(y1 / s.mosaic_cell_m)) + 2)
        if c1 <= c0 or r1 <= r0:
            continue
        T = job.T_ned_rect[k]
        R, c = T[:3, :3], T[:3, 3]
        X, Y = np.meshgrid(xs[c0:c1], ys[r0:r1])
        dn = A32[0, 0] * X + A32[0, 1] * Y + np.float32(ne_c[0] - c[0])
        de = A32[1, 0] * X + A32[1, 1] * Y + np.float32(ne_c[1] - c[1])
        dd = -up[r0:r1, c0:c1] - np.float32(c[2])
        Rt = R.T.astype(np.float32)
        px = Rt[0, 0] * dn + Rt[0, 1] * de + Rt[0, 2] * dd
        py = Rt[1, 0] * dn + Rt[1, 1] * de + Rt[1, 2] * dd
        pz = Rt[2, 0] * dn + Rt[2, 1] * de + Rt[2, 2] * dd
        pz = np.where(pz > 0.05, pz, np.float32(np.nan))
        u = np.float32(geom.f_px) * px / pz + np.float32(geom.cx_px)
        v = np.float32(geom.f_px) * py / pz + np.float32(geom.cy_px)
        border = np.minimum(np.minimum(u, geom.width - 1 - u), np.minimum(v, geom.height - 1 - v))
        w = np.clip(np.nan_to_num(border, nan=-1.0) / half_px, 0.0, 1.0) ** 2
        w[~has[r0:r1, c0:c1]] = 0
        sample = cv2.remap(
            image, np.nan_to_num(u, nan=-1e4), np.nan_to_num(v, nan=-1e4), cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT, borderValue=0,
        )  # fmt: skip
        acc[r0:r1, c0:c1] += w * sample
        wsum[r0:r1, c0:c1] += w
    good = wsum > 1e-6
    out[good] = np.clip(np.rint(acc[good] / wsum[good]), 1, 255).astype(np.uint8)
    return out


class _Tsdf:
    """A tile's TSDF volume (Open3D), integrated frame by frame, then its cropped mesh."""

    def __init__(
        self, s: FusionSettings, geom: DenseGeometry, ne0: FloatArray, down_m: float, max_range_m: float
    ) -> None:
        from auvnav.recon.o3d import open3d

        self.o3d = o3d = open3d()
        self.s = s
        v = s.voxel_m
        # A tile-local origin on the voxel lattice: float32 stays exact and neighbouring tiles share voxels.
        self.origin = np.array([*(np.round(np.asarray(ne0) / v) * v), round(down_m / v) * v])
        self.trunc = s.truncation_voxels * v
        self.max_depth = max_range_m + self.trunc
        self.geom = geom
        self.frames = 0  # depth maps integrated
        if s.tsdf == "blockgrid":
            o3c = o3d.core
            block_res = 16
            across = s.tile_m / (block_res * v) + 4
            self.grid = o3d.t.geometry.VoxelBlockGrid(
                attr_names=("tsdf", "weight", "color"),
                attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
                attr_channels=((1), (1), (3)),
                voxel_size=v,
                block_resolution=block_res,
                block_count=int(across * across * 6),
                device=o3c.Device("CPU:0"),
            )
            self.intrinsic = o3c.Tensor(geom.K, o3c.float64)
        else:
            self.volume = o3d.pipelines.integration.ScalableTSDFVolume(
                voxel_length=v,
                sdf_trunc=self.trunc,
                color_type=o3d.pipelines.integration.TSDFVolumeColorType.RGB8,
            )
            self.intrinsic = o3d.camera.PinholeCameraIntrinsic(
                geom.width, geom.height, geom.f_px, geom.f_px, geom.cx_px, geom.cy_px
            )

    def integrate(self, depth: NDArray[np.float32], image: NDArray[np.uint8], T_ned_rect: FloatArray) -> None:
        """One depth map (rectified left camera, metres, 0: none) with its image, placed at ``T_ned_rect``;
        nothing when no pixel has a depth within range, or when those that have touch no block of the
        grid (a sliver of a pair in the tile, eroded away: Open3D refuses such a frame)."""
        if not np.any((depth > 0) & (depth <= self.max_depth)):
            return
        self.frames += 1
        o3d = self.o3d
        R, t = T_ned_rect[:3, :3], T_ned_rect[:3, 3] - self.origin
        E = np.eye(4)
        E[:3, :3] = R.T
        E[:3, 3] = -R.T @ t
        rgb = np.ascontiguousarray(np.repeat(image[:, :, None], 3, axis=2))
        if self.s.tsdf == "blockgrid":
            o3c = o3d.core
            d = o3d.t.geometry.Image(o3c.Tensor(depth))
            colour = o3d.t.geometry.Image(o3c.Tensor(rgb.astype(np.float32) / 255.0))
            extrinsic = o3c.Tensor(E, o3c.float64)
            mult = float(self.s.truncation_voxels)
            try:
                coords = self.grid.compute_unique_block_coordinates(
                    d, self.intrinsic, extrinsic, 1.0, self.max_depth, mult
                )
            except RuntimeError as err:
                # Open3D samples the depth map on a stride: a few pixels in range between its samples
                # touch no block, and it refuses the frame
                if "No block is touched" not in str(err):
                    raise
                self.frames -= 1
                return
            self.grid.integrate(
                coords, d, colour, self.intrinsic, self.intrinsic, extrinsic, 1.0, self.max_depth, mult
            )
        else:
            rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
                o3d.geometry.Image(rgb),
                o3d.geometry.Image(depth),
                depth_scale=1.0,
                depth_trunc=self.max_depth,
                convert_rgb_to_intensity=False,
            )
            self.volume.integrate(rgbd, self.intrinsic, E)

    def mesh(
        self, A_inv: FloatArray, ne0: FloatArray
    ) -> tuple[FloatArray, NDArray[np.uint8], NDArray[np.int32]]:
        """The mesh cut to the tile (triangles whose centroid lies in it), vertices in ENU (east, north,
        up) about the dive's origin, metres; colours (k, 3) uint8; faces (f, 3) int32."""
        empty = (np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3), np.int32))
        if self.frames == 0:
            return empty
        if self.s.tsdf == "blockgrid":
            mesh = self.grid.extract_triangle_mesh(weight_threshold=0.5).to_legacy()  # one view has weight 1
        else:
            mesh = self.volume.extract_triangle_mesh()
        vertices = np.asarray(mesh.vertices, dtype=float)
        faces = np.asarray(mesh.triangles, dtype=np.int64)
        colours = np.asarray(mesh.vertex_colors, dtype=float)
        if len(faces) == 0:
            return empty
        ned = vertices + self.origin
        centroid = ned[faces].mean(axis=1)
        xy = (centroid[:, :2] - ne0) @ A_inv.T
        tile = self.s.tile_m
        keep = (xy[:, 0] >= 0) & (xy[:, 0] < tile) & (-xy[:, 1] >= 0) & (-xy[:, 1] < tile)
        if not keep.any():
            return empty
        kept, inverse = np.unique(faces[keep].ravel(), return_inverse=True)
        ned = ned[kept]
        enu = np.stack([ned[:, 1], ned[:, 0], -ned[:, 2]], axis=1)
        if len(colours) == len(vertices):
            rgb = np.clip(np.rint(colours[kept] * 255), 0, 255).astype(np.uint8)
        else:
            rgb = np.full((len(kept), 3), 128, np.uint8)
        return enu, rgb, inverse.reshape(-1, 3).astype(np.int32)
