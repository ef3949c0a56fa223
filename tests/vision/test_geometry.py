"""Camera model, rectification, triangulation covariance, texture and renderer invariants."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from auvnav.errors import ConfigError
from auvnav.frames import euler2rot, se3, se3_apply
from auvnav.sim.camera import camera_poses, default_stereo_rig, scale_camera_rig, to_grey
from auvnav.sim.camera import render_stereo_pair as render_colour
from auvnav.sim.texture import SeafloorTexture
from auvnav.vision.camera import check_image_size, pixel_rays, rectification, rectify_points, triangulate


def render_stereo_pair(*args, **kwargs):
    """The colour camera's pair as grey images, as the front end reads them."""
    return tuple(to_grey(image) for image in render_colour(*args, **kwargs))


SUBPIXEL = 1e-6  # pixels: round trips through OpenCV's iterative undistortion
ALBEDO_ATOL = 1e-3  # world consistency up to cv2.remap's fixed-point interpolation weights


def test_default_rig_is_sirius_like() -> None:
    # Johnson-Roberson et al. 2010, J. Field Robotics 27(1): 1360 x 1024, ~42 deg horizontal FOV, ~7 cm
    rig = default_stereo_rig()
    assert (rig.left.width, rig.left.height) == (1360, 1024)
    assert np.degrees(rig.left.hfov_rad) == pytest.approx(42.0, abs=0.5)
    assert rig.baseline_m == pytest.approx(0.07, abs=0.002)
    # looking down: the optical axis is body down; image x is body right
    np.testing.assert_allclose(rig.mount.R_body_sensor[:, 2], [0, 0, 1])
    np.testing.assert_allclose(rig.mount.R_body_sensor[:, 0], [0, 1, 0])
    half = scale_camera_rig(rig, 0.5)
    assert (half.left.width, half.left.height) == (680, 512)
    assert half.left.hfov_rad == pytest.approx(rig.left.hfov_rad, rel=1e-3)


def test_pixel_rays_invert_projection_with_distortion() -> None:
    cam = default_stereo_rig().left
    u, v = np.meshgrid(np.linspace(0, cam.width - 1, 7), np.linspace(0, cam.height - 1, 5))
    rays = pixel_rays(cam, u, v)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-12)
    uv, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)
    np.testing.assert_allclose(uv.reshape(-1, 2), np.column_stack([u.ravel(), v.ravel()]), atol=SUBPIXEL)


def test_rectification_and_triangulation_recover_points() -> None:
    rig = default_stereo_rig()
    rect = rectification(rig)
    assert rect.baseline_m == pytest.approx(rig.baseline_m, rel=1e-9)
    rng = np.random.default_rng(0)
    p_left = np.column_stack(
        [rng.uniform(-0.6, 0.6, 50), rng.uniform(-0.4, 0.4, 50), rng.uniform(1.7, 2.4, 50)]
    )
    p_right = p_left @ rig.R_right_left.T + rig.t_right_left_m
    uvl, _ = cv2.projectPoints(p_left[:, None], np.zeros(3), np.zeros(3), rig.left.K, rig.left.D)
    uvr, _ = cv2.projectPoints(p_right[:, None], np.zeros(3), np.zeros(3), rig.right.K, rig.right.D)
    rl = rectify_points(uvl.reshape(-1, 2), rig.left, rect.R1, rect.P1)
    rr = rectify_points(uvr.reshape(-1, 2), rig.right, rect.R2, rect.P2)
    np.testing.assert_allclose(rl[:, 1], rr[:, 1], atol=1e-4)  # rows agree after rectification
    p, cov = triangulate(rl, rr, rect, 0.3, 0.1)
    np.testing.assert_allclose(p, p_left, atol=1e-6)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_triangulation_covariance_matches_monte_carlo() -> None:
    rect = rectification(default_stereo_rig())
    ul, ur, v = np.array([[900.0]]), np.array([[900.0 - 1200.0 * 0.07 / 2.0]]), np.array([[300.0]])
    sc, si = 0.5, 0.2
    rng = np.random.default_rng(1)
    n = 20000
    common = rng.normal(0, sc, (n, 2))
    left = np.column_stack(
        [ul[0, 0] + common[:, 0] + rng.normal(0, si, n), v[0, 0] + common[:, 1] + rng.normal(0, si, n)]
    )
    right = np.column_stack(
        [ur[0, 0] + common[:, 0] + rng.normal(0, si, n), v[0, 0] + common[:, 1] + rng.normal(0, si, n)]
    )
    samples, _ = triangulate(left, right, rect, sc, si)
    _, cov = triangulate(np.column_stack([ul[0], v[0]]), np.column_stack([ur[0], v[0]]), rect, sc, si)
    np.testing.assert_allclose(np.cov(samples.T), cov[0], rtol=0.08, atol=1e-9)


def test_image_size_mismatch_is_a_one_line_error() -> None:
    with pytest.raises(ConfigError) as err:
        check_image_size(default_stereo_rig().left, (512, 680), "images/left/000001.png")
    assert "images/left/000001.png" in str(err.value)
    assert "\n" not in str(err.value)


def test_texture_is_a_function_of_the_world_point() -> None:
    tex = SeafloorTexture(seed=4)
    rng = np.random.default_rng(2)
    n, e = rng.uniform(-3, 3, 500), rng.uniform(-3, 3, 500)
    alone = tex.albedo(n, e)
    # the same points inside a much larger set spread over several tiles, and as a 2-D grid
    n2, e2 = np.concatenate([n, rng.uniform(-40, 40, 3000)]), np.concatenate([e, rng.uniform(-40, 40, 3000)])
    np.testing.assert_allclose(tex.albedo(n2, e2)[:500], alone, atol=ALBEDO_ATOL)
    np.testing.assert_allclose(
        tex.albedo(n.reshape(20, 25), e.reshape(20, 25)).ravel(), alone, atol=ALBEDO_ATOL
    )
    assert 0.02 <= alone.min() and alone.max() <= 0.95
    assert not np.allclose(SeafloorTexture(seed=5).albedo(n, e), alone)
    with pytest.raises(ValueError, match="must match"):
        tex.albedo(n, e[:10])


def test_render_looks_like_a_strobe_image(flat_floor) -> None:
    rig = scale_camera_rig(default_stereo_rig(), 0.25)
    T = se3(euler2rot(0.4, 0.0, 0.0), np.array([1.0, 2.0, flat_floor.base_m - 2.0]))
    left, right = render_stereo_pair(flat_floor, SeafloorTexture(seed=1), rig, T)
    assert left.shape == (256, 340) and left.dtype == np.uint8
    assert right.shape == left.shape
    centre = left[96:160, 128:212].mean()
    corners = np.mean(
        [left[:32, :32].mean(), left[:32, -32:].mean(), left[-32:, :32].mean(), left[-32:, -32:].mean()]
    )
    assert 60 < centre < 200  # exposed for the survey altitude
    assert corners < 0.8 * centre  # strobe falloff and vignetting
    # a higher altitude is darker: inverse-square falloff and attenuation
    T_high = T.copy()
    T_high[2, 3] -= 2.0
    assert render_stereo_pair(flat_floor, SeafloorTexture(seed=1), rig, T_high)[0].mean() < 0.5 * left.mean()


def test_rendered_geometry_is_the_seafloor(flat_floor) -> None:
    """A world point's texture lands where the camera model projects it, in both images."""
    rig = scale_camera_rig(default_stereo_rig(), 0.25)
    T = se3(euler2rot(0.4, 0.02, -0.01), np.array([1.0, 2.0, flat_floor.base_m - 2.0]))
    left, _ = render_stereo_pair(flat_floor, SeafloorTexture(seed=1), rig, T)
    T_left, _ = camera_poses(rig, T)
    # Render a second view shifted sideways and compare the common patch through the true geometry.
    T2 = T.copy()
    T2[:3, 3] += np.array([0.2, -0.1, 0.0])
    left2, _ = render_stereo_pair(flat_floor, SeafloorTexture(seed=1), rig, T2)
    T_left2, _ = camera_poses(rig, T2)
    u, v = np.meshgrid(np.arange(100, 240, 4.0), np.arange(80, 180, 4.0))
    rays = pixel_rays(rig.left, u, v).reshape(-1, 3)
    R, c = T_left[:3, :3], T_left[:3, 3]
    d = rays @ R.T
    ground = c + ((flat_floor.base_m - c[2]) / d[:, 2])[:, None] * d
    p2 = se3_apply(np.linalg.inv(T_left2), ground)
    uv2, _ = cv2.projectPoints(p2[:, None], np.zeros(3), np.zeros(3), rig.left.K, rig.left.D)
    uv2 = uv2.reshape(-1, 2)
    a = cv2.GaussianBlur(left.astype(np.float32), (0, 0), 1.0)[v.ravel().astype(int), u.ravel().astype(int)]
    b = cv2.remap(
        cv2.GaussianBlur(left2.astype(np.float32), (0, 0), 1.0),
        uv2[:, 0:1].astype(np.float32),
        uv2[:, 1:2].astype(np.float32),
        cv2.INTER_LINEAR,
    ).ravel()
    assert np.corrcoef(a, b)[0, 1] > 0.9
