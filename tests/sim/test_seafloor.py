"""The procedural seafloor: seeded, vectorised, gradient consistent, reef-scale relief."""

from __future__ import annotations

import numpy as np
import pytest

from auvnav.sim.seafloor import Seafloor, SeafloorParams

GRID = np.meshgrid(np.arange(-50.0, 50.0, 0.5), np.arange(-50.0, 50.0, 0.5), indexing="ij")


def test_seeded() -> None:
    n, e = GRID
    a, b = Seafloor(7).depth_m(n, e), Seafloor(7).depth_m(n, e)
    np.testing.assert_array_equal(a, b)
    assert np.abs(Seafloor(8).depth_m(n, e) - a).max() > 0.5


def test_vectorised_shapes_and_single_points() -> None:
    floor = Seafloor(3)
    n, e = GRID
    d = floor.depth_m(n, e)
    assert d.shape == n.shape
    assert floor.depth_m(n[:3, :4], 1.0).shape == (3, 4)  # broadcasting
    gn, ge = floor.gradient(n, e)
    for i, j in [(0, 0), (123, 45), (199, 199), (100, 17)]:
        single = floor.depth_and_gradient(float(n[i, j]), float(e[i, j]))
        assert single == pytest.approx((d[i, j], gn[i, j], ge[i, j]), abs=1e-12)


def test_gradient_matches_finite_differences() -> None:
    floor = Seafloor(5)
    n, e = GRID
    h = 1e-5
    gn, ge = floor.gradient(n, e)
    dn = (floor.depth_m(n + h, e) - floor.depth_m(n - h, e)) / (2 * h)
    de = (floor.depth_m(n, e + h) - floor.depth_m(n, e - h)) / (2 * h)
    np.testing.assert_allclose(gn, dn, atol=1e-5)
    np.testing.assert_allclose(ge, de, atol=1e-5)


def test_relief() -> None:
    """Reef mounds of 0.5-2 m on a gently sloping floor around the mean depth."""
    n, e = GRID
    flat = SeafloorParams(slope=0.0, undulation_m=0.0, rugosity_m=0.0)
    reefs = 45.0 - Seafloor(11, flat).depth_m(n, e)  # mound height above the floor
    assert reefs.min() == pytest.approx(0.0, abs=1e-12)
    assert 1.2 < reefs.max() < 2.0 * 1.6  # mounds up to 2 m (overlaps add a little)
    assert 0.2 < np.mean(reefs > 0.05) < 0.8
    d = Seafloor(11).depth_m(n, e)
    assert 40.0 < d.min() < d.max() < 50.0
    rugosity = SeafloorParams(slope=0.0, undulation_m=0.0, reef_probability=0.0)
    small = Seafloor(11, rugosity).depth_m(n, e) - 45.0
    assert 0.01 < small.std() < 0.05


def test_bad_params() -> None:
    with pytest.raises(ValueError, match="half-length"):
        SeafloorParams(reef_cell_m=2.0)
    with pytest.raises(ValueError, match="reef_probability"):
        SeafloorParams(reef_probability=1.5)
