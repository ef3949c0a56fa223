"""Rasters of a dive on a projected map grid, written as tiled, compressed GeoTIFFs (rasterio, pyproj).

A dive's products live in its local NED frame; a map product is a grid of square cells in the UTM
zone of the dive's origin (:func:`utm_crs`), rows from north to south. :func:`ned2map` and
:func:`map2ned` convert between the two exactly (through WGS84, pymap3d and pyproj), so a raster lines
up with the same place in any GIS whatever the meridian convergence and UTM scale at the site.
:class:`MapGrid` is such a grid; :func:`write_geotiff` writes bands on it, tiled and compressed with
overviews; :func:`read_geotiff` reads one back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from auvnav.errors import AuvnavError
from auvnav.frames import FloatArray, GeodeticOrigin, geodetic2ned, ned2geodetic
from auvnav.streams import atomic_write


def utm_crs(origin: GeodeticOrigin) -> Any:
    """The ``pyproj.CRS`` of the UTM zone (WGS84) that holds ``origin``."""
    from pyproj import CRS

    lat, lon = math.degrees(origin.latitude_rad), (math.degrees(origin.longitude_rad) + 180.0) % 360.0 - 180.0
    zone = int((lon + 180.0) // 6.0) + 1
    return CRS.from_epsg((32600 if lat >= 0 else 32700) + zone)


def _transformer(origin: GeodeticOrigin, inverse: bool = False) -> Any:
    from pyproj import Transformer

    crs = utm_crs(origin)
    return (
        Transformer.from_crs(crs.geodetic_crs, crs, always_xy=True)
        if not inverse
        else Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True)
    )


def ned2map(p_ne_m: ArrayLike, origin: GeodeticOrigin) -> FloatArray:
    """Local north and east (..., 2), metres, to UTM easting and northing (..., 2), metres."""
    p = np.asarray(p_ne_m, dtype=float)
    ned = np.concatenate([p, np.zeros((*p.shape[:-1], 1))], axis=-1)
    lat, lon, _ = ned2geodetic(ned, origin)
    x, y = _transformer(origin).transform(np.degrees(lon), np.degrees(lat))
    return np.stack([np.asarray(x, dtype=float), np.asarray(y, dtype=float)], axis=-1)


def map2ned(xy_m: ArrayLike, origin: GeodeticOrigin) -> FloatArray:
    """UTM easting and northing (..., 2), metres, to local north and east (..., 2), metres."""
    xy = np.asarray(xy_m, dtype=float)
    lon, lat = _transformer(origin, inverse=True).transform(xy[..., 0], xy[..., 1])
    ned = geodetic2ned(np.radians(lat), np.radians(lon), np.full(np.shape(lat), origin.height_m), origin)
    return np.asarray(ned, dtype=float)[..., :2]


@dataclass(frozen=True)
class MapGrid:
    """A grid of square cells on the map (UTM of the dive's origin), rows from north to south.

    Parameters
    ----------
    x0_m, y0_m : float
        Easting and northing of the grid's north-west corner (the outer corner of cell (0, 0)), metres.
    cell_m : float
        Side of a cell, metres.
    width, height : int
        Columns and rows.
    origin : GeodeticOrigin
        The dive's origin (it fixes the UTM zone).
    """

    x0_m: float
    y0_m: float
    cell_m: float
    width: int
    height: int
    origin: GeodeticOrigin

    def __post_init__(self) -> None:
        if not (self.cell_m > 0 and self.width > 0 and self.height > 0):
            raise ValueError(f"a grid needs cells and a positive cell size; found {self.width}x{self.height}")

    @classmethod
    def covering(
        cls, p_ne_m: ArrayLike, origin: GeodeticOrigin, cell_m: float, *, margin_m: float = 0.0
    ) -> MapGrid:
        """The smallest grid, aligned to whole cells of the map, holding every point (N, 2) in local NED."""
        xy = ned2map(np.reshape(np.asarray(p_ne_m, dtype=float), (-1, 2)), origin)
        lo = np.floor((xy.min(axis=0) - margin_m) / cell_m) * cell_m
        hi = np.ceil((xy.max(axis=0) + margin_m) / cell_m) * cell_m
        width, height = (round(v) for v in (hi - lo) / cell_m)
        return cls(float(lo[0]), float(hi[1]), cell_m, max(width, 1), max(height, 1), origin)

    @property
    def transform(self) -> Any:
        """The rasterio affine transform of the grid."""
        from rasterio.transform import from_origin

        return from_origin(self.x0_m, self.y0_m, self.cell_m, self.cell_m)

    def cell_centres_map(self) -> tuple[FloatArray, FloatArray]:
        """Easting (width,) and northing (height,) of the cell centres, metres."""
        x = self.x0_m + (np.arange(self.width) + 0.5) * self.cell_m
        y = self.y0_m - (np.arange(self.height) + 0.5) * self.cell_m
        return x, y

    def cell_centres_ned(self) -> FloatArray:
        """Local north and east of every cell centre, shape (height, width, 2), metres."""
        x, y = self.cell_centres_map()
        xx, yy = np.meshgrid(x, y)
        return map2ned(np.stack([xx, yy], axis=-1), self.origin)

    def cells_of_map(self, xy_m: ArrayLike) -> NDArray[np.intp]:
        """Row and column (..., 2) of the cells holding map points (..., 2) (outside: out of range)."""
        xy = np.asarray(xy_m, dtype=float)
        col = np.floor((xy[..., 0] - self.x0_m) / self.cell_m).astype(np.intp)
        row = np.floor((self.y0_m - xy[..., 1]) / self.cell_m).astype(np.intp)
        return np.stack([row, col], axis=-1)


def write_geotiff(
    path: Path,
    bands: ArrayLike,
    grid: MapGrid,
    *,
    nodata: float | None = None,
    description: tuple[str, ...] = (),
    overviews: bool = True,
) -> None:
    """Write bands on a grid as a tiled, deflate-compressed GeoTIFF with overviews, atomically.

    Parameters
    ----------
    path : Path
    bands : array, shape (height, width) or (bands, height, width)
        Any dtype rasterio writes (uint8, uint16, float32, ...).
    grid : MapGrid
    nodata : float, optional
        The value of cells without data.
    description : tuple of str
        A name per band (GDAL band description).
    overviews : bool
        Add 2x, 4x, ... overviews (averaged) down to about 256 cells.
    """
    import rasterio
    from rasterio.enums import Resampling

    data = np.asarray(bands)
    if data.ndim == 2:
        data = data[None]
    if data.shape[1:] != (grid.height, grid.width):
        raise ValueError(
            f"bands must be (height, width) = {(grid.height, grid.width)}; found {data.shape[1:]}"
        )
    profile = {
        "driver": "GTiff",
        "width": grid.width,
        "height": grid.height,
        "count": data.shape[0],
        "dtype": data.dtype.name,
        "crs": utm_crs(grid.origin).to_wkt(),
        "transform": grid.transform,
        "nodata": nodata,
        "compress": "deflate",
        "tiled": grid.width >= 256 and grid.height >= 256,
        "blockxsize": 256,
        "blockysize": 256,
    }
    if not profile["tiled"]:
        profile.pop("blockxsize")
        profile.pop("blockysize")

    def write(tmp: Path) -> None:
        with rasterio.open(tmp, "w", **profile) as out:
            out.write(data)
            for k, name in enumerate(description, start=1):
                out.set_band_description(k, name)
            if overviews:
                factors = [2**k for k in range(1, 16) if max(grid.width, grid.height) / 2**k >= 256]
                if factors:
                    out.build_overviews(factors, Resampling.average)

    atomic_write(Path(path), write)


def read_geotiff(path: Path) -> tuple[FloatArray, dict[str, Any]]:
    """Bands (bands, height, width) and the profile of a GeoTIFF; a one-line error when unreadable."""
    import rasterio
    from rasterio.errors import RasterioIOError

    try:
        with rasterio.open(path) as src:
            return src.read(), dict(src.profile)
    except RasterioIOError as err:
        raise AuvnavError(f"{path}: not a readable GeoTIFF ({str(err).splitlines()[0][:80]})") from None
