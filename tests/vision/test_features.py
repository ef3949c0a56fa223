"""Front end: SIFT keypoints where their features are, stereo matches at the right disparity,
descriptors companded to 4 bits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from auvnav.frames import euler2rot, se3
from auvnav.sim.camera import camera_poses, default_stereo_rig, scale_camera_rig, to_grey
from auvnav.sim.camera import render_stereo_pair as render_colour
from auvnav.sim.texture import SeafloorTexture
from auvnav.vision.camera import rectification
from auvnav.vision.features import (
    SIFT_COMPONENT_MAX,
    FeatureSettings,
    compand_descriptors,
    correct_illumination,
    detect,
)
from auvnav.vision.stereo import stereo_features


def render_stereo_pair(*args, **kwargs):
    """The colour camera's pair as grey images, as the front end reads them."""
    return tuple(to_grey(image) for image in render_colour(*args, **kwargs))


# A location bias b shows as 2 b between the keypoints of an image and of the image turned by 180 degrees
# (0.5 px with OpenCV's fast upscale uncorrected); the turn is exact, so a tolerance well below that.
BIAS_TOL_PX = 0.03


@pytest.mark.parametrize("scale", [None, 0.5])
def test_keypoints_have_no_location_bias(flat_floor, scale: float | None) -> None:
    """An unbiased detector finds the keypoints of an image turned by 180 degrees at the turned positions."""
    rig = scale_camera_rig(default_stereo_rig(), 0.5)
    T = se3(euler2rot(0.3, 0.0, 0.0), np.array([0.0, 0.0, flat_floor.base_m - 2.0]))
    image = correct_illumination(render_stereo_pair(flat_floor, SeafloorTexture(seed=2), rig, T)[0])
    settings = FeatureSettings(scale=scale)
    h, w = image.shape
    uv = detect(image, settings).uv_px
    turned = detect(np.ascontiguousarray(image[::-1, ::-1]), settings).uv_px
    back = np.column_stack([w - 1 - turned[:, 0], h - 1 - turned[:, 1]])
    dist, k = cKDTree(uv).query(back)
    same = dist < 0.5
    assert same.sum() > 0.5 * len(uv)
    bias = np.median(back[same] - uv[k[same]], axis=0)
    np.testing.assert_allclose(bias, 0.0, atol=BIAS_TOL_PX)


@pytest.mark.parametrize("image_scale", [1.0, 0.5])
def test_stereo_matches_lie_on_the_floor(flat_floor, image_scale: float) -> None:
    """A level view of a flat floor: almost every keypoint is matched, at the floor's range.

    This view (texture seed 2) once lost every match at full size and nine in ten at half size: the
    disparity search started from zero and its first pass locked on to the wrong place.
    """
    rig = scale_camera_rig(default_stereo_rig(), image_scale)
    T = se3(euler2rot(0.3, 0.0, 0.0), np.array([0.0, 0.0, flat_floor.base_m - 1.7]))
    left, right = render_stereo_pair(flat_floor, SeafloorTexture(seed=2), rig, T)
    settings = FeatureSettings()
    feats = stereo_features(left, right, rig, rectification(rig), settings)
    assert len(feats) > 0.8 * settings.max_features
    range_m = flat_floor.base_m - camera_poses(rig, T)[0][2, 3]
    assert np.median(feats.p_cam_m[:, 2]) == pytest.approx(range_m, rel=0.002)


@given(
    st.integers(1, 64),
    st.one_of(st.none(), st.floats(0.05, 1.0)),
    st.sampled_from([340, 680, 1360, 2464]),
)
def test_the_stereo_window_is_the_odd_side_nearest_the_setting(
    side: int, scale: float | None, width: int
) -> None:
    settings = FeatureSettings(lk_window_px=side, scale=scale)
    window = settings.lk_window_for(width)
    assert window % 2 == 1
    assert abs(window - side / settings.scale_for(width)) <= 1.0


def test_the_default_stereo_window_is_the_one_the_benchmarks_measured() -> None:
    # 17 px on the half-scale images, where SIFT runs at their own size; twice as wide on full-size ones
    assert FeatureSettings().lk_window_for(680) == 17
    assert FeatureSettings().lk_window_for(1360) == 35


@given(st.lists(st.integers(0, 255), min_size=2, max_size=128))
def test_companding_is_monotonic_and_spans_4_bits(values: list[int]) -> None:
    d = np.array(sorted(values), dtype=np.uint8)[None, :]
    q = compand_descriptors(d)[0]
    assert q.dtype == np.uint8 and q.min() >= 0 and q.max() <= 15
    assert np.all(np.diff(q.astype(int)) >= 0)
    assert compand_descriptors(np.array([[0, int(SIFT_COMPONENT_MAX)]], dtype=np.uint8)).tolist() == [[0, 15]]
