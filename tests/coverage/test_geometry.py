"""Coverage geometry: stereo footprints, polygons counted on a grid, gaps, the plan of a mission."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auvnav.coverage.grid import count_cells, find_gaps, ground_cell_area_m2, polygon_mask
from auvnav.coverage.plan import survey_plan
from auvnav.footprint import (
    convex_intersection,
    convex_intersections,
    footprints_on_plane,
    polygon_area,
    polygon_overlap,
    polygon_overlaps,
    stereo_footprints,
)
from auvnav.frames import GeodeticOrigin, euler2rot, se3
from auvnav.plan.missions import navcheck, survey, transit
from auvnav.raster import MapGrid
from auvnav.sim.camera import default_stereo_rig

ORIGIN = GeodeticOrigin.from_degrees(-14.05, 121.78)


def _level_pose(north: float = 0.0, east: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    return se3(euler2rot(yaw, 0.0, 0.0)[None], np.array([[north, east, 10.0]]))


def test_right_footprint_is_the_left_shifted_by_the_baseline() -> None:
    """A level rig heading north over a flat floor: the right camera looks from 7 cm to starboard (east)."""
    rig = default_stereo_rig()
    floor = np.array([12.0])
    left = footprints_on_plane(_level_pose(), rig, floor, camera="left")[0]
    right = footprints_on_plane(_level_pose(), rig, floor, camera="right")[0]
    shift = right.mean(axis=0) - left.mean(axis=0)
    assert shift[1] == pytest.approx(rig.baseline_m, abs=0.01)  # principal points differ by a few px
    assert abs(shift[0]) < 0.01


def test_stereo_footprint_is_the_intersection_and_narrower_than_either() -> None:
    rig = default_stereo_rig()
    T, floor = _level_pose(3.0, 4.0, math.radians(30)), np.array([12.0])
    left = footprints_on_plane(T, rig, floor)[0]
    right = footprints_on_plane(T, rig, floor, camera="right")[0]
    both = stereo_footprints(T, rig, floor)[0]
    assert polygon_area(both) == pytest.approx(polygon_area(convex_intersection(left, right)), rel=1e-12)
    assert polygon_area(both) < min(polygon_area(left), polygon_area(right))
    assert polygon_overlap(both, left) == pytest.approx(1.0, abs=1e-9)  # contained in the left one


def test_footprints_that_do_not_meet_have_no_area() -> None:
    a = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert convex_intersection(a, a + 2.0).shape == (0, 2)


def _random_convex(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """``n`` convex polygons of ``k`` corners on circles, half of them clockwise."""
    angle = np.sort(rng.uniform(0.0, 2.0 * math.pi, (n, k)), axis=1)
    radius = rng.uniform(0.5, 1.5, (n, 1, 1))
    polys = rng.normal(0.0, 0.8, (n, 1, 2)) + radius * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    polys[::2] = polys[::2, ::-1]
    return polys


def test_batched_clipping_is_the_polygon_by_polygon_one() -> None:
    """The vectorised Sutherland-Hodgman (coverage's speed) gives the same corners, in the same order,
    and the same overlaps as the one polygon at a time; pairs that do not meet give no corners."""
    rng = np.random.default_rng(7)
    a, b = _random_convex(rng, 400, 4), _random_convex(rng, 400, 6)
    b[:5] += 10.0  # far apart
    inter, count = convex_intersections(a, b)
    for k in range(len(a)):
        ref = convex_intersection(a[k], b[k])
        assert count[k] == len(ref)
        np.testing.assert_allclose(inter[k, : len(ref)], ref, atol=1e-12)
    scalar = np.array([polygon_overlap(x, y) for x, y in zip(a, b, strict=True)])
    np.testing.assert_allclose(polygon_overlaps(a, b), scalar, atol=1e-12)
    assert np.all(count[:5] == 0) and np.count_nonzero(scalar) > 100


def _inside_convex(poly: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Brute force: cell centres on the inner side of every edge of a counter-clockwise polygon, and
    those on an edge (within 1e-6 cell), which may go either way."""
    inside = np.ones(x.shape, bool)
    near = np.zeros(x.shape, bool)
    for k in range(len(poly)):
        (x0, y0), (x1, y1) = poly[k - 1], poly[k]
        length = math.hypot(x1 - x0, y1 - y0)
        side = ((x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)) / length
        inside &= side >= 0
        near |= np.abs(side) < 1e-6
    return inside, near


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-2.0, 42.0), st.floats(-2.0, 32.0)), min_size=3, max_size=8, unique=True))
def test_count_cells_holds_exactly_the_cell_centres_inside(points: list[tuple[float, float]]) -> None:
    from scipy.spatial import ConvexHull, QhullError

    pts = np.array(points)
    try:
        hull = pts[ConvexHull(pts).vertices]  # counter-clockwise in (x, y)
    except QhullError:
        return  # degenerate (collinear) input
    counts = count_cells(hull[None], 30, 40)
    rows, cols = np.mgrid[0:30, 0:40]
    expected, on_edge = _inside_convex(hull, cols.astype(float), rows.astype(float))
    assert np.array_equal((counts > 0)[~on_edge], expected[~on_edge])


def test_counts_add_up_over_overlapping_polygons() -> None:
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]) - 0.5  # cells 0..9
    counts = count_cells(np.stack([square, square + np.array([5.0, 0.0])]), 12, 20)
    assert counts[:10, :5].min() == 1 and counts[:10, 5:10].min() == 2 and counts[:10, 10:15].min() == 1
    assert counts.sum() == 200


def test_a_strip_gap_has_its_width_and_area() -> None:
    grid = MapGrid(500000.0, 8400000.0, 0.05, 200, 100, ORIGIN)
    uncovered = np.zeros((100, 200), bool)
    uncovered[20:80, 50:56] = True  # 6 cells = 0.30 m wide, 3 m long
    uncovered[5, 5] = True  # one cell: under the minimum area
    gaps = find_gaps(uncovered, grid, min_area_m2=0.01, cell_area_m2=0.0025)
    assert len(gaps) == 1
    assert gaps.area_m2[0] == pytest.approx(60 * 6 * 0.0025)
    assert gaps.width_m[0] == pytest.approx(0.30, abs=0.05)
    assert (gaps.labels > 0).sum() == 360


def test_ground_area_of_a_cell_removes_the_utm_scale() -> None:
    grid = MapGrid(500000.0, 8400000.0, 0.05, 10, 10, ORIGIN)
    # Transverse Mercator point scale to second order, k = k0 (1 + (dlon cos lat)^2 / 2) (Snyder 1987,
    # "Map Projections: A Working Manual", USGS PP 1395, eq. 8-11): 121.78 E is 1.22 degrees west of
    # zone 51's central meridian (123 E); the areal scale is k^2
    k = 0.9996 * (1 + (math.radians(123.0 - 121.78) * math.cos(math.radians(14.05))) ** 2 / 2)
    assert ground_cell_area_m2(grid) == pytest.approx(0.0025 / k**2, rel=1e-5)


def test_polygon_mask_of_the_planned_area_has_its_area() -> None:
    plan = survey_plan(survey(width_m=20.0, height_m=5.0, spacing_m=1.0, lead_in_m=10.0))
    area = np.concatenate(plan.area_ne_m)
    grid = MapGrid.covering(area, ORIGIN, 0.05, margin_m=0.5)
    mask = polygon_mask(list(plan.area_ne_m), grid)
    assert mask.sum() * ground_cell_area_m2(grid) == pytest.approx(100.0, rel=0.02)


def test_survey_plan_of_the_paper_lawnmower() -> None:
    """75 m x 50 m at 1 m after a 100 m lead-in: 51 lines, 50 pairs 1 m apart, a 3,750 m^2 area; the
    lead-in (collinear with the first line) is no line; turns alternate between the lines' ends."""
    plan = survey_plan(survey())
    assert len(plan.lines) == 51 and len(plan.pairs) == 50
    assert all(p.spacing_m == pytest.approx(1.0) for p in plan.pairs)
    assert plan.area_m2() == pytest.approx(3750.0)
    assert plan.legs[0].length_m == pytest.approx(100.0) and 0 not in plan.lines
    assert plan.runs[0] == (0, 1)  # the lead-in continued by the first line: one run
    assert [p.turn_end_at_end for p in plan.pairs[:4]] == [True, True, True, True]
    assert np.allclose(plan.pairs[0].across_ne, [0.0, 1.0])  # the lines step east


def test_missions_without_adjacent_lines_have_no_pairs() -> None:
    assert survey_plan(transit()).pairs == ()
    nc = survey_plan(navcheck(headings=4, leg_m=20.0, grid_m=4.0), min_line_m=3.0)
    assert len(nc.pairs) > 0  # the grid's lines
    assert all(p.spacing_m == pytest.approx(1.0) for p in nc.pairs)
