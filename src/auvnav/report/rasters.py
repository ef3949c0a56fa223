"""Small previews of the reconstruction's GeoTIFFs (DEM, orthophoto) for the report's figures and map.

A preview is read at a reduced resolution straight from the file (rasterio reads its overviews), so
a 10,000 x 10,000 orthophoto costs what a 1,000 x 1,000 one does. Its extent is given in the dive's
local east and north (metres about the origin): the UTM corners converted with
:func:`auvnav.raster.map2ned` (over a patch of tens of metres the grid's rotation against true north,
the meridian convergence, is below a thousandth of a degree per metre of easting and is not drawn).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvnav.errors import AuvnavError
from auvnav.frames import FloatArray, GeodeticOrigin
from auvnav.raster import map2ned


@dataclass(frozen=True)
class RasterPreview:
    """A band read at reduced resolution.

    Parameters
    ----------
    band : ndarray, shape (H, W) or (3, H, W) for the orthophoto's colours
        Values, NaN where the file has no data; rows from north to south.
    bounds_m : (left, bottom, right, top)
        Map coordinates of the raster's edges, metres (UTM).
    cell_m : float
        The preview's cell size, metres.
    full_shape : (rows, cols)
        The file's size.
    full_cell_m : float
        The file's cell size, metres.
    corners_ne_m : ndarray, shape (2, 2)
        Local (north, east) of the top-left and bottom-right corners, metres.
    """

    band: FloatArray
    bounds_m: tuple[float, float, float, float]
    cell_m: float
    full_shape: tuple[int, int]
    full_cell_m: float
    corners_ne_m: FloatArray

    def extent_local_en(self) -> tuple[float, float, float, float]:
        """(west, east, south, north) in local metres, as matplotlib's ``imshow(extent=...)`` wants."""
        (n_top, e_left), (n_bottom, e_right) = self.corners_ne_m
        return float(e_left), float(e_right), float(n_bottom), float(n_top)


def read_raster_preview(
    path: Path, origin: GeodeticOrigin, max_px: int, *, bands: tuple[int, ...] = (1,)
) -> RasterPreview:
    """A GeoTIFF's bands at most ``max_px`` cells on the longer side (never upsampled).

    Parameters
    ----------
    path : Path
    origin : GeodeticOrigin
        The dive's origin, for the local extent.
    max_px : int
    bands : tuple of int
        1-based band numbers; one band gives shape (H, W), several (B, H, W).
    """
    import rasterio
    from rasterio.enums import Resampling
    from rasterio.errors import RasterioIOError

    try:
        with rasterio.open(path) as src:
            scale = max(1.0, max(src.width, src.height) / max_px)
            shape = (max(1, round(src.height / scale)), max(1, round(src.width / scale)))
            data = src.read(
                list(bands), out_shape=(len(bands), *shape), resampling=Resampling.average, masked=True
            )
            b = src.bounds
            full_shape = (src.height, src.width)
            full_cell = float(abs(src.transform.a))
    except RasterioIOError as err:
        raise AuvnavError(f"{path}: not a readable GeoTIFF ({str(err).splitlines()[0][:80]})") from None
    values = np.ma.filled(data.astype(float), np.nan)
    corners = map2ned(np.array([[b.left, b.top], [b.right, b.bottom]]), origin)
    return RasterPreview(
        band=values[0] if len(bands) == 1 else values,
        bounds_m=(b.left, b.bottom, b.right, b.top),
        cell_m=(b.right - b.left) / shape[1],
        full_shape=full_shape,
        full_cell_m=full_cell,
        corners_ne_m=corners,
    )
