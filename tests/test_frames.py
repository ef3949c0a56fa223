"""Property tests for auvnav.frames (DESIGN section 4 conventions)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auvnav import frames as F

ATOL_ROT = 1e-12  # rotation entries, dimensionless
ATOL_ANGLE_RAD = 1e-9
ATOL_GEO_M = 1e-3  # 1 mm, the bound within 10 km of the origin

angle = st.floats(-np.pi, np.pi, allow_nan=False)
any_angle = st.floats(-100.0, 100.0, allow_nan=False)
pitch = st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3, allow_nan=False)  # away from gimbal lock
vec = st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3, max_size=3).map(np.array)


@st.composite
def transforms(draw: st.DrawFn) -> np.ndarray:
    return F.se3(F.euler2rot(draw(angle), draw(pitch), draw(angle)), draw(vec))


@given(angle, pitch, angle)
def test_rotation_is_orthonormal_with_det_one(yaw: float, p: float, roll: float) -> None:
    R = F.euler2rot(yaw, p, roll)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=ATOL_ROT)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=ATOL_ROT)
    assert F.is_rotation(R)


@given(angle, pitch, angle)
def test_euler_matrix_round_trip(yaw: float, p: float, roll: float) -> None:
    y2, p2, r2 = F.rot2euler(F.euler2rot(yaw, p, roll))
    assert abs(F.angle_diff(y2, yaw)) < ATOL_ANGLE_RAD
    assert p2 == pytest.approx(p, abs=ATOL_ANGLE_RAD)
    assert abs(F.angle_diff(r2, roll)) < ATOL_ANGLE_RAD


@given(angle, pitch, angle)
def test_euler_quaternion_round_trip(yaw: float, p: float, roll: float) -> None:
    q = F.euler2quat_wxyz(yaw, p, roll)
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert q[0] >= 0
    np.testing.assert_allclose(F.quat_wxyz2rot(q), F.euler2rot(yaw, p, roll), atol=1e-12)
    y2, p2, r2 = F.quat_wxyz2euler(q)
    assert abs(F.angle_diff(y2, yaw)) < 1e-8 and abs(F.angle_diff(r2, roll)) < 1e-8
    assert p2 == pytest.approx(p, abs=1e-8)


def test_quaternion_names_scalar_first() -> None:
    # 90 degrees of yaw about down: q = (cos 45, 0, 0, sin 45), scalar first.
    np.testing.assert_allclose(
        F.euler2quat_wxyz(np.pi / 2, 0, 0), [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-15
    )


def test_yaw_is_clockwise_from_north() -> None:
    # Heading 90 deg (east): the body's forward axis points east in NED.
    np.testing.assert_allclose(F.euler2rot(np.pi / 2, 0, 0) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    # Positive pitch raises the nose: forward gains a negative down component.
    assert (F.euler2rot(0, 0.1, 0) @ [1, 0, 0])[2] < 0


@given(any_angle)
def test_wrap_is_idempotent_and_in_range(a: float) -> None:
    w = F.wrap_angle(a)
    assert -np.pi < w <= np.pi
    assert F.wrap_angle(w) == w
    assert np.cos(w) == pytest.approx(np.cos(a), abs=1e-9)


def test_wrap_boundaries() -> None:
    assert F.wrap_angle(np.pi) == np.pi
    assert F.wrap_angle(-np.pi) == np.pi
    assert F.angle_diff(np.radians(-179), np.radians(179)) == pytest.approx(np.radians(2))


@given(transforms())
def test_se3_inverse(T: np.ndarray) -> None:
    np.testing.assert_allclose(F.se3_compose(T, F.se3_inverse(T)), np.eye(4), atol=1e-9)


@given(transforms())
def test_pose6_round_trip(T: np.ndarray) -> None:
    """A loop's six numbers (x, y, z, roll, pitch, yaw) and back, also for a stack of transforms."""
    p6 = F.pose6(T)
    np.testing.assert_allclose(p6[:3], T[:3, 3])
    np.testing.assert_allclose(F.from_pose6(p6), T, atol=1e-9)
    stack = np.stack([T, F.se3_inverse(T)])
    np.testing.assert_allclose(F.from_pose6(F.pose6(stack)), stack, atol=1e-6)


@given(transforms(), transforms(), transforms())
def test_se3_associative(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> None:
    np.testing.assert_allclose(
        F.se3_compose(F.se3_compose(A, B), C), F.se3_compose(A, F.se3_compose(B, C)), rtol=1e-9, atol=1e-6
    )


@given(transforms(), vec)
def test_se3_apply_matches_matrix(T: np.ndarray, p: np.ndarray) -> None:
    np.testing.assert_allclose(F.se3_apply(T, p), (T @ np.append(p, 1.0))[:3], atol=1e-9)


@given(transforms(), vec, vec)
def test_se3_apply_to_a_grid_of_points_matches_each_point(
    T: np.ndarray, p: np.ndarray, q: np.ndarray
) -> None:
    """One transform over a (2, 3, 3) stack of points (OpenCV's path) is each point's transform."""
    grid = np.stack([np.stack([p, q, p - q]), np.stack([q, p + q, 2 * p])])
    out = F.se3_apply(T, grid)
    assert out.shape == grid.shape
    for k in np.ndindex(grid.shape[:2]):
        np.testing.assert_allclose(out[k], (T @ np.append(grid[k], 1.0))[:3], rtol=1e-9, atol=1e-6)


@settings(max_examples=50)
@given(
    st.floats(-80, 80),
    st.floats(-180, 180),
    st.floats(-10_000, 10_000),
    st.floats(-10_000, 10_000),
    st.floats(-10, 5_000),
)
def test_geodetic_ned_round_trip_within_10_km(lat0: float, lon0: float, n: float, e: float, d: float) -> None:
    origin = F.GeodeticOrigin.from_degrees(lat0, lon0)
    p = np.array([n, e, d])
    lat, lon, h = F.ned2geodetic(p, origin)
    np.testing.assert_allclose(F.geodetic2ned(lat, lon, h, origin), p, atol=ATOL_GEO_M)


def test_geodetic_ned_known_offset() -> None:
    # One arc-minute of latitude north at the equator is 1842.9 m on WGS84 (meridian arc, Bowring).
    origin = F.GeodeticOrigin.from_degrees(0.0, 0.0)
    p = F.geodetic2ned(np.radians(1 / 60), 0.0, 0.0, origin)
    assert p[0] == pytest.approx(1842.9, abs=0.1)
    assert abs(p[1]) < 1e-9


def test_is_rotation_rejects_reflections_and_scales() -> None:
    assert not F.is_rotation(np.diag([1.0, 1.0, -1.0]))
    assert not F.is_rotation(2 * np.eye(3))
    assert not F.is_rotation(np.eye(2))


def test_stacks_broadcast() -> None:
    yaw = np.linspace(-3, 3, 7)
    R = F.euler2rot(yaw, 0.1, -0.2)
    assert R.shape == (7, 3, 3)
    y2, _, _ = F.rot2euler(R)
    np.testing.assert_allclose(y2, yaw, atol=1e-12)


def test_ned2geodetic_shapes_agree() -> None:
    origin = F.GeodeticOrigin.from_degrees(-14.05, 121.78)
    for p in (np.zeros(3), np.zeros((1, 3)), np.zeros((4, 3))):
        lat, lon, h = F.ned2geodetic(p, origin)
        assert lat.shape == lon.shape == h.shape == p.shape[:-1]
