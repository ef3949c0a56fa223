"""Map grids of a dive: local NED to UTM and back, grids that cover, GeoTIFFs with their CRS and bounds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auvnav.frames import GeodeticOrigin
from auvnav.raster import MapGrid, map2ned, ned2map, read_geotiff, utm_crs, write_geotiff

SCOTT_REEF = GeodeticOrigin.from_degrees(-14.05, 121.78)


@settings(max_examples=50, deadline=None)
@given(st.floats(-2000, 2000), st.floats(-2000, 2000))
def test_ned_to_map_and_back_is_exact_to_a_micrometre(north: float, east: float) -> None:
    p = np.array([[north, east]])
    np.testing.assert_allclose(map2ned(ned2map(p, SCOTT_REEF), SCOTT_REEF), p, atol=1e-6)


def test_the_zone_holds_the_origin_and_distances_are_kept() -> None:
    assert utm_crs(SCOTT_REEF).to_epsg() == 32751  # zone 51 south
    assert utm_crs(GeodeticOrigin.from_degrees(41.5, -70.7)).to_epsg() == 32619  # Woods Hole, 19 north
    xy = ned2map(np.array([[0.0, 0.0], [100.0, 0.0]]), SCOTT_REEF)
    # UTM's scale at 121.78 E in zone 51 (central meridian 123 E) is within 0.04% of 1.
    assert np.linalg.norm(xy[1] - xy[0]) == pytest.approx(100.0, rel=4e-4)


def test_a_grid_covers_its_points_on_whole_cells() -> None:
    p = np.array([[0.0, 0.0], [10.0, 20.0], [-5.0, 3.0]])
    grid = MapGrid.covering(p, SCOTT_REEF, 0.05, margin_m=1.0)
    rc = grid.cells_of_map(ned2map(p, SCOTT_REEF))
    assert np.all((rc >= 0) & (rc < [grid.height, grid.width]))
    assert grid.x0_m / 0.05 == pytest.approx(round(grid.x0_m / 0.05))
    centres = grid.cell_centres_ned()
    assert centres.shape == (grid.height, grid.width, 2)
    assert centres[0, 0, 0] > centres[-1, 0, 0]  # row 0 is the north


def test_geotiff_opens_with_its_crs_and_bounds(tmp_path: Path) -> None:
    import rasterio

    grid = MapGrid.covering(np.array([[0.0, 0.0], [30.0, 40.0]]), SCOTT_REEF, 0.05)
    data = np.arange(grid.height * grid.width, dtype=np.float32).reshape(grid.height, grid.width)
    path = tmp_path / "dem.tif"
    write_geotiff(path, data, grid, nodata=-9999.0, description=("depth_m",))
    bands, profile = read_geotiff(path)
    np.testing.assert_array_equal(bands[0], data)
    with rasterio.open(path) as src:
        assert src.crs.to_epsg() == 32751 and src.nodata == -9999.0
        assert src.bounds.left == pytest.approx(grid.x0_m) and src.bounds.top == pytest.approx(grid.y0_m)
        assert src.descriptions == ("depth_m",) and src.overviews(1)  # tiled with overviews
        assert profile["compress"] == "deflate"
    assert not list(tmp_path.glob(".*"))  # written through a temporary file, renamed


def test_an_unreadable_geotiff_is_one_line(tmp_path: Path) -> None:
    from auvnav.errors import AuvnavError

    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"II*\x00garbage")
    with pytest.raises(AuvnavError, match=r"bad\.tif: not a readable GeoTIFF"):
        read_geotiff(bad)
