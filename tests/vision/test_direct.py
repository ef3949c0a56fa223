"""Direct (photometric) registration of stereo pairs whose features do not register (issue 20)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
import pytest
from scipy.stats import chi2

from auvnav.frames import euler2rot, se3, se3_inverse
from auvnav.sim.camera import camera_poses, default_stereo_rig, render_stereo_pair, scale_camera_rig, to_grey
from auvnav.sim.texture import SeafloorTexture
from auvnav.vision.camera import rectification
from auvnav.vision.direct import (
    DirectSettings,
    Pinhole,
    Refined,
    along_a_line,
    fit_surface,
    inscribed_box,
    nearer_rival,
    pair_geometry,
    plan_search,
    prepare,
    register_direct,
    rejected,
)
from auvnav.vision.features import FeatureSettings
from auvnav.vision.registration import RegistrationSettings, register
from auvnav.vision.stereo import stereo_features

RIG = scale_camera_rig(default_stereo_rig(), 0.25)
#: Featureless sand everywhere (the texture's bare patches).
BARE_SAND = SeafloorTexture(seed=5, bare_fraction=1.0, coral_fraction=0.0, ripple_field_fraction=0.0)
#: Two poses of the vehicle 2 m above a level floor 20 m down, 0.4 m apart and turned by 25 degrees.
T_A = se3(euler2rot(0.3, 0.01, -0.01), np.array([0.0, 0.0, 18.0]))
T_B = se3(euler2rot(0.3 + np.radians(25), -0.005, 0.01), np.array([0.35, 0.2, 18.02]))


@dataclass(frozen=True)
class Stripes:
    """A texture of straight stripes 9 cm apart and nothing else (a perfectly regular ripple field)."""

    def albedo_rgb(self, north_m, east_m, *, footprint_m: float = 0.0):
        grey = 0.4 + 0.15 * np.sin(2 * np.pi * np.asarray(north_m) / 0.09)
        return np.repeat(grey[..., None], 3, axis=-1).astype(np.float32)


@pytest.fixture(scope="module")
def bare_images(level_floor):
    """The grey stereo pairs of the two poses over featureless sand (the texture's bare patches everywhere)."""
    floor = level_floor(20.0)

    def render(T, seed):
        left, right = render_stereo_pair(floor, BARE_SAND, RIG, T, rng=np.random.default_rng(seed))
        return to_grey(left), to_grey(right)

    return render(T_A, 0), render(T_B, 1)


def features_of(images, settings: FeatureSettings) -> list:
    rect = rectification(RIG)
    return [stereo_features(left, right, RIG, rect, settings) for left, right in images]


@pytest.fixture(scope="module")
def bare(bare_images):
    """Features of the two poses over featureless sand."""
    return features_of(bare_images, FeatureSettings())


def true_relative() -> np.ndarray:
    (left_a, _), (left_b, _) = camera_poses(RIG, T_A), camera_poses(RIG, T_B)
    return se3_inverse(left_a) @ left_b


def errors(T_est: np.ndarray, cov: np.ndarray, T_true: np.ndarray) -> tuple[float, float, float]:
    """Translation (m) and rotation (deg) errors, and the Mahalanobis distance of the 6-dof error."""
    dt = T_true[:3, 3] - T_est[:3, 3]
    dtheta = cv2.Rodrigues(T_true[:3, :3] @ T_est[:3, :3].T)[0].ravel()
    e = np.concatenate([dt, dtheta])
    return (
        float(np.linalg.norm(dt)),
        float(np.degrees(np.linalg.norm(dtheta))),
        float(e @ np.linalg.solve(cov, e)),
    )


def direct(fa, fb, prior: np.ndarray, sigma_m: float, settings: DirectSettings):
    """The direct registration as the loop stage runs it: the search planned from the pairs'
    geometry, then the images compared."""
    A, B = prepare(fa, settings), prepare(fb, settings)
    search = plan_search(A.geometry, B.geometry, prior, sigma_m, settings)
    return rejected(search) if isinstance(search, str) else register_direct(A, B, search, settings)


def assert_registers(fa, fb, prior: np.ndarray, T_true: np.ndarray, settings: DirectSettings) -> np.ndarray:
    """The direct registration of a pair (prior lateral 1-sigma 1.5 cm) is accepted, within 8 mm and
    0.2 degrees of the truth and within its covariance; its covariance."""
    reg = direct(fa, fb, prior, 0.015, settings)
    assert reg.accepted, reg.reason
    translation, rotation, mahalanobis = errors(reg.T_a_b, reg.cov_xi, T_true)
    assert translation < 0.008 and rotation < 0.2
    assert mahalanobis < chi2.ppf(0.999, 6)
    return reg.cov_xi


def test_featureless_sand_registers_from_its_images_where_its_features_do_not(bare) -> None:
    fa, fb = bare
    T_true = true_relative()
    # the prior: 2.5 cm and 1.5 degrees off, its lateral 1-sigma 1.5 cm
    prior = T_true @ se3(euler2rot(np.radians(1.5), 0.0, 0.0), np.array([0.02, -0.015, 0.0]))
    assert not register(fa, fb, RegistrationSettings(), prior=(prior, 0.015)).accepted
    cov = assert_registers(fa, fb, prior, T_true, DirectSettings())
    # the uncertainty it reports is what the images hold: tight along the floor, loose in tilt
    sigma = np.sqrt(np.diag(cov))
    assert sigma[5] < np.radians(0.5) and sigma[3] > np.radians(1.0)


def test_a_large_thumbnail_registers_at_every_pixel(bare_images) -> None:
    """Thumbnails the size SIFT sees, at stride 1: the refinement samples more pixels than OpenCV's
    remap takes in one row (as a larger feature scale on a large camera's images does)."""
    fa, fb = features_of(bare_images, FeatureSettings(thumbnail_scale=1.0))
    T_true = true_relative()
    settings = replace(DirectSettings(), stride=1)
    assert fa.thumbnail_image().size > 2**15
    prior = T_true @ se3(np.eye(3), np.array([0.01, -0.01, 0.0]))
    assert_registers(fa, fb, prior, T_true, settings)


def test_a_pair_that_overlaps_by_a_corner_registers(level_floor, bare_images) -> None:
    """B off A diagonally (42% of the image's width and 23% of its height at 2 m): the views share a
    corner, a third of B's thumbnail, and no row of it is half inside A's view."""
    cam_a = camera_poses(RIG, T_A)[0]
    width_m, height_m = (
        2.0 * n / f for n, f in ((RIG.left.width, RIG.left.K[0, 0]), (RIG.left.height, RIG.left.K[1, 1]))
    )
    offset = 0.42 * width_m * cam_a[:3, 0] + 0.23 * height_m * cam_a[:3, 1]
    T_C = se3(T_A[:3, :3], T_A[:3, 3] + np.array([offset[0], offset[1], 0.0]))
    left, right = render_stereo_pair(level_floor(20.0), BARE_SAND, RIG, T_C, rng=np.random.default_rng(2))
    fa, fc = features_of([bare_images[0], (to_grey(left), to_grey(right))], FeatureSettings())
    T_true = se3_inverse(cam_a) @ camera_poses(RIG, T_C)[0]
    prior = T_true @ se3(euler2rot(np.radians(1.0), 0.0, 0.0), np.array([0.015, -0.01, 0.0]))
    assert_registers(fa, fc, prior, T_true, DirectSettings())


def test_the_search_template_is_the_largest_rectangle_inside_the_overlap() -> None:
    box = np.zeros((40, 50), bool)
    box[5:30, 10:45] = True
    assert inscribed_box(box) == (5, 30, 10, 45)
    # a corner: 45% of each row, 60% of each column, which a rule of rows and columns more than half
    # inside would refuse
    corner = np.zeros((100, 100), bool)
    corner[40:, 55:] = True
    assert inscribed_box(corner) == (40, 100, 55, 100)
    # a diamond (two views turned 45 degrees): all inside, half the diamond (the most a rectangle holds)
    diamond = np.zeros((101, 101), np.uint8)
    cv2.fillConvexPoly(diamond, np.array([[50, 0], [100, 50], [50, 100], [0, 50]], np.int32), 1)
    r0, r1, c0, c1 = inscribed_box(diamond.astype(bool))
    assert diamond[r0:r1, c0:c1].all()
    assert (r1 - r0) * (c1 - c0) > 0.45 * diamond.sum()
    assert inscribed_box(np.zeros((30, 30), bool)) is None
    thin = np.zeros((30, 30), bool)
    thin[:, 10:17] = True  # 7 columns: under 8 pixels a side
    assert inscribed_box(thin) is None


def test_a_loose_prior_no_thumbnail_or_no_overlap_is_refused_from_the_geometry(bare) -> None:
    fa, fb = bare
    settings = DirectSettings()
    A, B = pair_geometry(fa, settings), pair_geometry(fb, settings)
    # the thumbnail's size from its header is the decoded image's
    assert A.shape == fa.thumbnail_image().shape
    far = plan_search(A, B, true_relative(), 0.2, settings)
    assert far.startswith("prior too uncertain")
    assert pair_geometry(replace(fa, thumbnail=None), settings) is None
    assert prepare(replace(fa, thumbnail=None), settings) is None
    # a thumbnail cut short: its header still gives the size, but it decodes to nothing
    cut = replace(fa, thumbnail=fa.thumbnail[:64])
    assert pair_geometry(cut, settings).shape == A.shape
    assert prepare(cut, settings) is None
    # a header whose size no thumbnail has (a flipped bit): no geometry
    header = bytearray(fa.thumbnail)
    header[16:20] = (3).to_bytes(4, "big")
    assert pair_geometry(replace(fa, thumbnail=bytes(header)), settings) is None
    assert plan_search(None, B, true_relative(), 0.01, settings) == "no thumbnail"
    # B a whole footprint (2.5 m at 20 m) off to the side: nothing to compare
    away = true_relative() @ se3(np.eye(3), np.array([2.5, 0.0, 0.0]))
    assert plan_search(A, B, away, 0.01, settings) == "overlap too small"
    # at the prior, most of B is in A's view: a search, over the largest rectangle A sees
    search = plan_search(A, B, true_relative(), 0.01, settings)
    r0, r1, c0, c1 = search.box
    assert (r1 - r0) * (c1 - c0) > 0.25 * np.prod(B.coarse_shape)


def test_stripes_are_never_a_position(level_floor) -> None:
    """Along the stripes nothing tells one place from another, and across them every 9 cm looks the
    same: whatever the prior, the pair is refused, never registered to a wrong place."""
    floor = level_floor(20.0)
    rect = rectification(RIG)

    def render(T, seed):
        left, right = render_stereo_pair(floor, Stripes(), RIG, T, rng=np.random.default_rng(seed))
        feats = stereo_features(to_grey(left), to_grey(right), RIG, rect, FeatureSettings())
        # SIFT finds next to nothing on stripes: the floor's points as a perfect stereo would give them
        T_cam = camera_poses(RIG, T)[0]
        n, e = np.meshgrid(np.linspace(-0.6, 0.6, 12), np.linspace(-0.6, 0.6, 12))
        world = np.column_stack([n.ravel() + T[0, 3], e.ravel() + T[1, 3], np.full(n.size, 20.0)])
        p = (world - T_cam[:3, 3]) @ T_cam[:3, :3]
        p = p[p[:, 2] > 0]
        return replace(
            feats,
            uv_rect_px=np.zeros((len(p), 4)),
            p_cam_m=p,
            cov_cam_m2=np.tile(np.eye(3) * 1e-6, (len(p), 1, 1)),
            descriptors=np.zeros((len(p), 128), np.uint8),
            disparity_sigma_px=np.zeros(len(p)),
        )

    settings = DirectSettings()
    fa, fb = render(T_A, 0), render(T_B, 1)
    for sigma in (0.01, 0.04):
        reg = direct(fa, fb, true_relative(), sigma, settings)
        assert not reg.accepted
        refusals = ("ambiguous", "one-dimensional", "no refinement stayed", "best correlation at the edge")
        assert reg.reason.startswith(refusals), reg.reason


def test_the_surface_measures_the_relief_its_grid_misses_not_the_noise_its_points_understate() -> None:
    camera = Pinhole(443.0, 443.0, 169.5, 127.5)
    shape = (256, 340)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(0, 339, 1500), rng.uniform(0, 255, 1500)
    x, y = camera.normalised(u, v)
    heads = rng.uniform([-0.4, -0.3], [0.4, 0.3], (40, 2))  # coral heads about 10 cm across

    def depth(x, y, height):
        smooth = 2.0 + 0.05 * x + 0.1 * np.sin(2.0 * y) + 0.05 * x * y
        bumps = np.exp(
            -((x[..., None] - heads[:, 0]) ** 2 + (y[..., None] - heads[:, 1]) ** 2) / 0.025**2 / 2
        )
        return smooth - height * bumps.sum(axis=-1)

    def fit(height: float, noise_m: float, stated_m: float):
        """The surface of points with ``noise_m`` of range noise whose stereo states ``stated_m``."""
        z = depth(x, y, height) + rng.normal(0, noise_m, x.size)
        points = np.column_stack([x * z, y * z, z])
        surface = fit_surface(points, np.full(x.size, stated_m) / z**2, camera, shape, DirectSettings())
        assert surface is not None
        return surface, points

    grid = np.meshgrid(np.linspace(x.min(), x.max(), 20), np.linspace(y.min(), y.max(), 15))
    flat, points = fit(0.0, 0.005, 0.005)
    error = 1.0 / flat.inverse_depth(*grid) - depth(*grid, 0.0)
    assert np.sqrt(np.mean(error**2)) < 0.006  # the smooth floor to a few millimetres
    assert flat.relief_m < 0.004
    # coral heads 10 cm high (their heights' spread over the image: 4 cm) are relief
    assert 0.01 <= fit(0.1, 0.005, 0.005)[0].relief_m <= 0.04
    # points four times noisier than their stereo says (the tracker sliding along ripple crests) are
    # not: the surface is as uncertain as when the noise is stated, not rough
    understated, honest = fit(0.0, 0.02, 0.005)[0], fit(0.0, 0.02, 0.02)[0]
    assert understated.relief_m < 0.004
    assert understated.variance(0.0, 0.0) >= 0.8 * honest.variance(0.0, 0.0)
    assert (
        fit_surface(points[:10], np.full(10, 0.005) / points[:10, 2] ** 2, camera, shape, DirectSettings())
        is None
    )


def look_alike(
    x: float, y: float, turn_deg: float = 0.0, edge: bool = False
) -> tuple[Refined, bool, np.ndarray]:
    """A mode of the direct search: B's centre at (x, y) in A, 2 m down, turned ``turn_deg`` about the
    optical axis, and whether its coarse peak was at the edge of the search."""
    T = se3(euler2rot(np.radians(turn_deg), 0.0, 0.0), np.array([x, y, 0.0]))
    refined = Refined(T, np.eye(6) * 1e-6, np.eye(4) * 1e-6, 2.0, 0.9, 1000, 100, 1.0)
    return refined, edge, np.array([x, y, 2.0])


def test_look_alike_places_along_a_crest_become_one_place_uncertain_along_it() -> None:
    """Modes strung along one line (a ripple crest's faint texture cannot fix the position along it)
    are one place: the estimate moves to the middle of their stretch, which a uniform distribution
    along the line covers, and the crest's across position keeps its own certainty."""
    settings = DirectSettings()
    r = settings.mode_radius_m
    u = np.array([np.cos(0.5), np.sin(0.5)])
    modes = [look_alike(*(s * u), turn_deg=0.3 * s / 0.05) for s in (0.0, 0.03, -0.02, 0.05)]
    start = np.array([0.01, -0.01, 2.0])
    shift, extra = along_a_line(modes, start, 0.1, settings)
    assert np.allclose(shift[:2], 0.5 * (0.05 - 0.02) * u) and shift[2] == 0.0
    half = 0.5 * (0.07 + 2 * r)
    assert np.allclose(extra[:2, :2], np.outer(u, u) * half**2 / 3)
    assert np.isclose(extra[5, 5], np.radians(0.5 * 0.42) ** 2 / 3)
    assert np.count_nonzero(extra) == 5
    # every place on the stretch is within sqrt(3) sigma of the estimate along the line
    along = np.array([-0.02 - r, 0.05 + r]) - shift[:2] @ u
    assert np.all(np.abs(along) <= np.sqrt(3 * u @ extra[:2, :2] @ u) + 1e-12)
    # a mode at the edge of the window: the line may go on beyond it, so the whole chord counts
    edged = [*modes[:3], look_alike(*(0.05 * u), edge=True)]
    shift, extra = along_a_line(edged, np.array([0.0, 0.0, 2.0]), 0.1, settings)
    assert np.allclose(shift[:2], 0.0, atol=1e-12)
    assert np.isclose(u @ extra[:2, :2] @ u, 0.1**2 / 3)


def test_look_alikes_off_one_line_or_turned_are_not_one_place() -> None:
    """A mode a wavelength across the crests beside two along them, or one turned further than the
    coarse search's yaw step from the best, is another place: the pair stays ambiguous."""
    settings = DirectSettings()
    across = [look_alike(0.0, 0.0), look_alike(0.04, 0.0), look_alike(0.02, 0.09)]
    assert along_a_line(across, np.zeros(3), 0.15, settings) is None
    turned = [look_alike(0.0, 0.0), look_alike(0.03, 0.0, turn_deg=np.degrees(settings.yaw_step_rad) + 0.2)]
    assert along_a_line(turned, np.zeros(3), 0.15, settings) is None
    assert along_a_line([*turned[:1], look_alike(0.03, 0.0, turn_deg=0.5)], np.zeros(3), 0.15, settings)


def test_a_best_mode_in_the_priors_tail_yields_to_a_look_alike_near_the_prior() -> None:
    """As on a turbid ripple field: the best mode 3.1 sigmas from the prior at correlation 0.929, a
    look-alike 1.2 sigmas from it at 0.909 (outside the ambiguity margin): refused. Not when the
    look-alike is in the tail too, when the best is not in the tail, or when the look-alike
    correlates beyond the rival margin."""
    settings = DirectSettings()
    sigma = 0.018
    window = settings.window_sigmas * sigma + settings.window_margin_m
    start = np.zeros(3)

    def mode(sigmas: float, correlation: float) -> tuple[Refined, bool, np.ndarray]:
        refined, edge, where = look_alike(sigmas * sigma, 0.0)
        return replace(refined, correlation=correlation), edge, where

    assert 0.909 < 0.929 - settings.ambiguity_margin * (1 - 0.929)  # not ambiguous by correlation alone
    assert nearer_rival([mode(3.1, 0.929), mode(1.2, 0.909)], start, window, settings)
    assert not nearer_rival([mode(3.1, 0.929), mode(2.8, 0.909)], start, window, settings)
    assert not nearer_rival([mode(2.0, 0.929), mode(0.5, 0.909)], start, window, settings)
    assert not nearer_rival([mode(3.1, 0.929), mode(1.2, 0.85)], start, window, settings)
