"""Camera footprints on the seafloor and their overlap (:mod:`auvnav.footprint`)."""

from __future__ import annotations

import numpy as np
import pytest

from auvnav.footprint import footprints, polygon_overlap
from auvnav.frames import euler2rot, se3
from auvnav.sim.camera import default_stereo_rig

UNIT = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


# Overlap of the unit square with shifted or scaled copies: intersection over the smaller area.
OVERLAPS = [
    (UNIT + np.array([0.5, 0.0]), 0.5),
    (UNIT + np.array([0.5, 0.5]), 0.25),
    (UNIT + np.array([1.5, 0.0]), 0.0),
    (0.5 * UNIT + 0.25, 1.0),  # contained
    (2.0 * UNIT - 0.5, 1.0),  # contains
    (UNIT[::-1] + np.array([0.0, 0.75]), 0.25),  # clockwise order
]


@pytest.mark.parametrize(("other", "expected"), OVERLAPS)
def test_polygon_overlap(other: np.ndarray, expected: float) -> None:
    assert polygon_overlap(UNIT, other) == pytest.approx(expected, abs=1e-12)
    assert polygon_overlap(other, UNIT) == pytest.approx(expected, abs=1e-12)


def test_footprint_of_a_level_camera_is_its_image_rectangle(level_floor) -> None:
    """Level vehicle heading north, camera 1.7 m above a flat floor: the footprint is the image's
    rectangle scaled by height / focal length, across track along image x (body right)."""
    rig = default_stereo_rig()
    T = se3(euler2rot(0.0, 0.0, 0.0)[None], np.array([[10.0, 20.0, 8.0]]))
    height = 10.0 - 8.0 - rig.mount.lever_arm_body_m[2]
    poly = footprints(T, rig, level_floor(10.0))[0]
    K = rig.left.K
    across = height * rig.left.width / K[0, 0]
    along = height * rig.left.height / K[1, 1]
    assert np.ptp(poly[:, 1]) == pytest.approx(across, rel=1e-9)
    assert np.ptp(poly[:, 0]) == pytest.approx(along, rel=1e-9)
    # The optical centre's ground point is the camera's position plus the principal point's offset.
    centre = np.array([10.0, 20.0]) + rig.mount.lever_arm_body_m[:2]
    offset = height * np.array(
        [-(K[1, 2] - rig.left.height / 2) / K[1, 1], (K[0, 2] - rig.left.width / 2) / K[0, 0]]
    )
    np.testing.assert_allclose(poly.mean(axis=0), centre - offset, atol=1e-9)
