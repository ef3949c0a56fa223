"""Adaptive features and edge-safe stereo (issue 20): low-contrast images, depth discontinuities."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from auvnav.errors import ConfigError
from auvnav.frames import euler2rot, se3
from auvnav.sim.camera import (
    SteppedFloor,
    camera_poses,
    default_stereo_rig,
    render_stereo_pair,
    rggb_mosaic,
    scale_camera_rig,
    to_grey,
)
from auvnav.sim.texture import SeafloorTexture
from auvnav.vision.camera import rectification
from auvnav.vision.features import FeatureSettings, correct_illumination, detect, robust_contrast, spread
from auvnav.vision.stereo import (
    disparity_spread,
    on_epipolar_line,
    read_features,
    read_grey,
    stereo_features,
    write_features,
)


def test_robust_contrast_is_the_standard_deviation_of_the_bulk() -> None:
    rng = np.random.default_rng(0)
    image = np.clip(np.rint(128 + 10 * rng.standard_normal((200, 300))), 0, 255).astype(np.uint8)
    assert robust_contrast(image) == pytest.approx(10.0, rel=0.1)
    image[:20] = 255  # specks and glare do not count
    assert robust_contrast(image) == pytest.approx(10.0, rel=0.25)


@pytest.fixture(scope="module")
def textured(level_floor) -> np.ndarray:
    rig = scale_camera_rig(default_stereo_rig(), 0.25)
    T = se3(euler2rot(0.3, 0.0, 0.0), np.array([0.0, 0.0, 18.0]))
    left, _ = render_stereo_pair(level_floor(20.0), SeafloorTexture(seed=2, bare_fraction=0.0), rig, T)
    return correct_illumination(to_grey(left))


def test_stretch_reaches_the_target_on_a_low_contrast_image(textured) -> None:
    """A sixth of the contrast (the real photograph of the issue: grey-level std about 8): the fixed
    threshold loses most keypoints, the adaptive detector keeps the target count, spread out."""
    rng = np.random.default_rng(1)
    faint = 128 + (textured.astype(float) - 128) / 6 + 1.0 * rng.standard_normal(textured.shape)
    faint = np.clip(np.rint(faint), 0, 255).astype(np.uint8)
    fixed = FeatureSettings(max_features=300, contrast_threshold=0.04, contrast_target_dn=0.0)
    adaptive = FeatureSettings(max_features=300)
    n_fixed = len(detect(faint, fixed).uv_px)
    kp = detect(faint, adaptive)
    print(n_fixed, len(kp.uv_px), len(detect(textured, fixed).uv_px))
    assert n_fixed < 100 and len(kp.uv_px) >= 295
    h, w = faint.shape
    cells = np.unique((kp.uv_px[:, 1] * 8 // h) * 8 + kp.uv_px[:, 0] * 8 // w)
    assert len(cells) >= 0.9 * 64


@pytest.mark.parametrize(
    ("suffix", "dtype", "full_scale"), [(".png", np.uint16, 4095), (".tiff", np.float32, 1.0)]
)
def test_a_deeper_image_is_read_on_its_own_scale(
    textured, tmp_path, suffix: str, dtype, full_scale: float
) -> None:
    """A 12-bit camera's image in a 16-bit file (ROS mono16), or as floats, reads as the picture its
    8-bit version shows, not as OpenCV's high byte (which leaves 12-bit data 16 grey levels), and SIFT
    finds the same keypoints in it."""
    top = float(np.quantile(textured, 0.999))
    deep = textured.astype(np.float64) * (full_scale / 255.0)
    path = tmp_path / f"deep{suffix}"
    assert cv2.imwrite(str(path), deep.astype(dtype) if dtype == np.float32 else np.rint(deep).astype(dtype))
    assert len(np.unique(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE))) <= 16 or dtype == np.float32
    grey = read_grey(path)
    assert grey is not None and grey.dtype == np.uint8
    expected = np.clip(textured * (255.0 / top), 0, 255)
    assert np.abs(grey - expected).max() <= 1.0
    settings = FeatureSettings(max_features=300)
    a, b = detect(grey, settings).uv_px, detect(np.rint(expected).astype(np.uint8), settings).uv_px
    near = np.min(np.linalg.norm(a[:, None] - b[None], axis=2), axis=1)
    assert min(len(a), len(b)) >= 295 and np.mean(near < 0.5) > 0.9


def test_a_raw_mosaic_is_demosaiced_to_the_picture_the_camera_saw(level_floor, tmp_path) -> None:
    """A survey camera's raw 12-bit RGGB mosaic in a 16-bit PNG (oplab_pipeline's cameras name
    rggb, grbg): demosaiced by its filter, it is the colour image's luminance to a grey level; read as
    grey, or with the green sites taken for red, it is a checkerboard. A colour image where the vehicle
    says raw is a one-line error naming the file."""
    rig = scale_camera_rig(default_stereo_rig(), 0.25)
    T = se3(euler2rot(0.3, 0.0, 0.0), np.array([0.0, 0.0, 18.0]))
    colour, _ = render_stereo_pair(level_floor(20.0), SeafloorTexture(seed=2, bare_fraction=0.0), rig, T)
    cv2.imwrite(str(tmp_path / "raw.png"), rggb_mosaic(colour[..., ::-1]).astype(np.uint16) * 16)
    truth = to_grey(colour)[2:-2, 2:-2].astype(float)

    def agreement(bayer: str | None) -> tuple[float, float]:
        grey = read_grey(tmp_path / "raw.png", bayer)
        assert grey is not None
        g = grey[2:-2, 2:-2].astype(float)
        g *= np.median(truth) / np.median(g)
        return float(np.corrcoef(g.ravel(), truth.ravel())[0, 1]), float(np.median(np.abs(g - truth)))

    correlation, grey_levels = agreement("rggb")
    assert correlation > 0.995 and grey_levels < 1.5
    assert agreement(None)[0] < 0.8 and agreement("grbg")[0] < 0.95
    cv2.imwrite(str(tmp_path / "colour.png"), colour)
    with pytest.raises(ConfigError, match=r"colour\.png: vehicle\.yaml gives its camera a Bayer filter"):
        read_grey(tmp_path / "colour.png", "rggb")


def test_an_image_without_light_is_skipped(tmp_path, caplog) -> None:
    path = tmp_path / "dark.png"
    cv2.imwrite(str(path), np.zeros((40, 60), np.uint16))
    assert read_grey(path) is None and "no light" in caplog.text and "dark.png" in caplog.text


def _rows(kp) -> np.ndarray:
    rows = np.column_stack([kp.uv_px, kp.size_px, kp.descriptors])
    return rows[np.lexsort(rows.T[::-1])]


@pytest.mark.parametrize(("divide", "retried"), [(1.0, False), (4.5, False), (6.0, True)])
def test_one_pass_keeps_what_a_pass_at_each_threshold_finds(textured, divide: float, retried: bool) -> None:
    """The retry's single pass at half the threshold gives exactly the keypoints of a pass at the full
    threshold when that finds enough (the textured image; at 2/9 of its contrast 195 of the lower
    pass's 300, the rest dropped), else those of a pass at half (at a sixth, 7 against 300)."""
    image = np.clip(np.rint(128 + (textured.astype(float) - 128) / divide), 0, 255).astype(np.uint8)
    settings = FeatureSettings(
        max_features=300, contrast_threshold=0.02, contrast_target_dn=0.0, retry_fraction=0.5, spread_cells=0
    )
    full = detect(image, replace(settings, retry_fraction=0.0))
    half = detect(image, replace(settings, retry_fraction=0.0, contrast_threshold=0.01))
    assert (len(full.uv_px) < 150) == retried and len(half.uv_px) == 300
    assert len(full.uv_px) < 300 or divide == 1
    np.testing.assert_array_equal(_rows(detect(image, settings)), _rows(half if retried else full))


def test_spread_takes_each_cells_strongest_first() -> None:
    rng = np.random.default_rng(2)
    uv = np.vstack([rng.uniform(0, 10, (500, 2)), rng.uniform(0, 100, (50, 2))])  # a crowded corner
    response = np.concatenate([np.full(500, 10.0), np.full(50, 1.0)]) + rng.uniform(0, 0.1, 550)
    keep = spread(uv, response, 100, 100, 60, 4)
    assert len(keep) == 60 and len(np.unique(keep)) == 60
    cells = np.unique((uv[keep, 1] * 4 // 100) * 4 + uv[keep, 0] * 4 // 100)
    all_cells = np.unique((uv[:, 1] * 4 // 100) * 4 + uv[:, 0] * 4 // 100)
    assert len(cells) == len(all_cells)  # every occupied cell is represented
    assert np.array_equal(spread(uv[:10], response[:10], 100, 100, 60, 4), np.arange(10))


def _true_disparity(scene, rect, T_left, uv):
    f, cx, cy = rect.f_px, rect.cx_px, rect.cy_px
    rays = np.column_stack([(uv[:, 0] - cx) / f, (uv[:, 1] - cy) / f, np.ones(len(uv))]) @ rect.R1
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    s, _ = scene.intersect_rays(T_left[:3, 3], rays @ T_left[:3, :3].T)
    p = rays * s[:, None]
    q = (rect.P2 @ np.column_stack([p @ rect.R1.T, np.ones(len(p))]).T).T
    return uv[:, 0] - q[:, 0] / q[:, 2]


def test_edge_safe_stereo_drops_matches_across_depth_steps_and_keeps_the_cache_exact(tmp_path) -> None:
    scene = SteppedFloor.random(5, 20.0, extent_m=2.5, count=12, heights_m=(0.15, 0.35))
    rig = scale_camera_rig(default_stereo_rig(), 0.25)
    rect = rectification(rig)
    T = se3(euler2rot(0.7, 0.0, 0.0), np.array([0.0, 0.0, 17.7]))
    left, right = (to_grey(x) for x in render_stereo_pair(scene, SeafloorTexture(seed=5), rig, T))
    T_left = camera_poses(rig, T)[0]
    result = {}
    for reject in (0.0, 0.5):
        settings = FeatureSettings(max_features=600, edge_reject_px=reject)
        feats = stereo_features(left, right, rig, rect, settings)
        uv = feats.uv_rect_px
        err = np.abs(uv[:, 0] - uv[:, 2] - _true_disparity(scene, rect, T_left, uv[:, :2]))
        lo, hi = np.full(len(uv), np.inf), np.full(len(uv), -np.inf)
        for du in (-7.5, 0.0, 7.5):
            for dv in (-7.5, 0.0, 7.5):
                d = _true_disparity(scene, rect, T_left, uv[:, :2] + [du, dv])
                lo, hi = np.minimum(lo, d), np.maximum(hi, d)
        near = hi - lo > 1.0
        result[reject] = (np.mean(err[near] <= 1.0), near.sum(), (~near).sum(), feats)
    assert result[0.0][1] >= 20  # the scene has matches across its steps
    # without the test, 118 matches near steps, 93% within 1 px; with it, 58 and 98%
    assert result[0.0][0] < 0.95 and result[0.5][0] >= 0.97
    assert result[0.5][2] > 0.9 * result[0.0][2]  # at little cost away from the edges
    feats = result[0.5][3]
    assert feats.disparity_sigma_px.max() > 0
    write_features(feats, rect, tmp_path / "pair.feat")
    back = read_features(tmp_path / "pair.feat")
    np.testing.assert_array_equal(back.disparity_sigma_px, feats.disparity_sigma_px)
    np.testing.assert_array_equal(back.cov_cam_m2, feats.cov_cam_m2)


@pytest.mark.parametrize("angle_deg", [20.0, 45.0, 75.0])
def test_a_match_slid_along_stripes_is_put_back_on_its_row(angle_deg: float) -> None:
    # Stripes (ripple crests) at an angle to the rows: Lucas-Kanade can slide a match along them, by
    # up to a few pixels, moving its column and its row; the row is known (the pair's common offset,
    # the median over its matches), so the column comes back.
    rng = np.random.default_rng(3)
    theta = np.radians(angle_deg)
    y, x = np.mgrid[0:200, 0:300].astype(float)
    phase = (-x * np.sin(theta) + y * np.cos(theta)) * 2 * np.pi / 9.0
    left = np.clip(128 + 60 * np.sin(phase) + rng.normal(0, 1, x.shape), 0, 255).astype(np.uint8)
    p = np.column_stack([rng.uniform(40, 260, 51), rng.uniform(40, 160, 51)]).astype(np.float32)
    row_offset, disparity = 0.3, 12.0  # a rectification 0.3 px off, as a real one may be
    true = np.column_stack([p[:, 0] - disparity, p[:, 1] + row_offset])
    slide = rng.permutation(np.linspace(-3.0, 3.0, 51)) / np.cos(theta)  # by up to 3 px in columns
    q = true + slide[:, None] * [np.cos(theta), np.sin(theta)]
    columns, share = on_epipolar_line(p, q, np.ones(51, dtype=bool), left, 15)
    assert np.abs(q[:, 0] - true[:, 0]).max() > 2.0  # the slide moved the columns
    assert np.abs(columns - true[:, 0]).max() < 0.06  # 0.03 px with Scharr derivatives, 0.11 with Sobel
    # the share of gradient energy across the columns: 2 sin^2 of the angle for stripes
    np.testing.assert_allclose(np.median(share), 2 * np.sin(theta) ** 2, atol=0.05)


def test_the_disparity_spread_of_no_matches_is_empty() -> None:
    # a turbid pair whose every match fails the round trip reached OpenCV with no points, which it refuses
    image = np.full((64, 64), 128, dtype=np.uint8)
    none = np.zeros((0, 1, 2), dtype=np.float32)
    assert disparity_spread(none, none, image, image, 15).shape == (0,)
