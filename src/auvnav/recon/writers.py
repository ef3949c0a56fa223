"""Writers whose memory is bounded by a tile: a GeoTIFF written window by window, a PLY mesh assembled
from per-tile parts.

:class:`TiledGeoTiff` has the profile of :func:`auvnav.raster.write_geotiff` (UTM of the dive's origin,
256 x 256 tiles, deflate, averaged overviews) but takes the raster one window at a time, so a survey's
orthophoto never has to be held whole; blocks never written stay empty (``SPARSE_OK``) and read as
no data. :class:`PlyWriter` appends each tile's vertices and faces to two scratch files and writes the
binary PLY (Open3D, trimesh and MeshLab read it) when closed.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from auvnav.raster import MapGrid, utm_crs


class TiledGeoTiff:
    """A GeoTIFF on ``grid`` written window by window (module docstring); renamed into place on close.

    Parameters
    ----------
    path : Path
    grid : MapGrid
    count : int
        Bands.
    dtype : str
        numpy dtype name (``uint8``, ``float32``).
    nodata : float
    description : tuple of str
        A name per band.
    """

    def __init__(
        self, path: Path, grid: MapGrid, count: int, dtype: str, nodata: float, description: tuple[str, ...]
    ) -> None:
        import rasterio

        self.path = Path(path)
        self.grid = grid
        self.tmp = self.path.with_name(f".{self.path.name}.tmp")
        tiled = grid.width >= 256 and grid.height >= 256
        profile: dict[str, Any] = {
            "driver": "GTiff",
            "width": grid.width,
            "height": grid.height,
            "count": count,
            "dtype": dtype,
            "crs": utm_crs(grid.origin).to_wkt(),
            "transform": grid.transform,
            "nodata": nodata,
            "compress": "deflate",
            "tiled": tiled,
            "sparse_ok": True,
            "bigtiff": "IF_SAFER",
        }
        if tiled:
            profile.update(blockxsize=256, blockysize=256)
        self.dataset = rasterio.open(self.tmp, "w", **profile)
        for k, name in enumerate(description, start=1):
            self.dataset.set_band_description(k, name)

    def write(self, row: int, col: int, data: NDArray[Any]) -> None:
        """Write ``data`` (bands, h, w) or (h, w) with its top-left cell at (row, col) of the grid."""
        from rasterio.windows import Window

        array = np.asarray(data)
        if array.ndim == 2:
            array = array[None]
        h = min(array.shape[1], self.grid.height - row)
        w = min(array.shape[2], self.grid.width - col)
        if h <= 0 or w <= 0:
            return
        self.dataset.write(array[:, :h, :w], window=Window(col, row, w, h))

    def close(self, *, overviews: bool = True) -> None:
        """Build the averaged overviews (2x, 4x, ... down to about 256 cells), close, rename into place."""
        from rasterio.enums import Resampling

        if overviews:
            size = max(self.grid.width, self.grid.height)
            factors = [2**k for k in range(1, 24) if size / 2**k >= 256]
            if factors:
                self.dataset.build_overviews(factors, Resampling.average)
        self.dataset.close()
        os.replace(self.tmp, self.path)

    def abort(self) -> None:
        """Close and remove the unfinished file."""
        if not self.dataset.closed:
            self.dataset.close()
        self.tmp.unlink(missing_ok=True)


_VERTEX = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
_FACE = np.dtype([("n", "u1"), ("v", "<i4", (3,))])


class PlyWriter:
    """A binary little-endian PLY mesh with vertex colours, written from parts (module docstring).

    Parameters
    ----------
    path : Path
    comments : tuple of str
        PLY comment lines (the frame, the origin).
    """

    def __init__(self, path: Path, comments: tuple[str, ...] = ()) -> None:
        self.path = Path(path)
        self.comments = comments
        self._vertex_path = self.path.with_name(f".{self.path.name}.vertices.tmp")
        self._face_path = self.path.with_name(f".{self.path.name}.faces.tmp")
        self._vertices = open(self._vertex_path, "wb")
        self._faces = open(self._face_path, "wb")
        self.n_vertices = 0
        self.n_faces = 0

    def add(
        self, vertices: NDArray[np.floating], colours: NDArray[np.uint8], faces: NDArray[np.integer]
    ) -> None:
        """Append a part: vertices (k, 3) metres, colours (k, 3) uint8, faces (f, 3) into this part's vertices."""
        if len(vertices) == 0:
            return
        v = np.empty(len(vertices), dtype=_VERTEX)
        v["x"], v["y"], v["z"] = (vertices[:, i] for i in range(3))
        v["red"], v["green"], v["blue"] = (colours[:, i] for i in range(3))
        f = np.empty(len(faces), dtype=_FACE)
        f["n"] = 3
        f["v"] = np.asarray(faces, dtype=np.int64) + self.n_vertices
        self._vertices.write(v.tobytes())
        self._faces.write(f.tobytes())
        self.n_vertices += len(v)
        self.n_faces += len(f)

    def close(self) -> None:
        """Write the PLY (header, vertices, faces) through a temporary file renamed into place."""
        self._vertices.close()
        self._faces.close()
        header = ["ply", "format binary_little_endian 1.0"]
        header += [f"comment {c}" for c in self.comments]
        header += [
            f"element vertex {self.n_vertices}",
            "property float x",
            "property float y",
            "property float z",
            "property uchar red",
            "property uchar green",
            "property uchar blue",
            f"element face {self.n_faces}",
            "property list uchar int vertex_indices",
            "end_header",
        ]
        tmp = self.path.with_name(f".{self.path.name}.tmp")
        try:
            with open(tmp, "wb") as out:
                out.write(("\n".join(header) + "\n").encode("ascii"))
                for part in (self._vertex_path, self._face_path):
                    with open(part, "rb") as src:
                        shutil.copyfileobj(src, out, 1 << 22)
            os.replace(tmp, self.path)
        finally:
            tmp.unlink(missing_ok=True)
            self._vertex_path.unlink(missing_ok=True)
            self._face_path.unlink(missing_ok=True)

    def abort(self) -> None:
        """Remove the scratch files."""
        for fh in (self._vertices, self._faces):
            fh.close()
        self._vertex_path.unlink(missing_ok=True)
        self._face_path.unlink(missing_ok=True)
