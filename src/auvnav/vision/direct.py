"""Direct (photometric) registration of two stereo pairs over low-texture, near-planar seafloor.

Where SIFT finds too few repeatable keypoints (featureless sand, the one-dimensional texture of ripple
fields, turbid water), a pair's pixels still carry the texture. This registration uses all of them:
image alignment (Lucas and Kanade 1981; Baker and Matthews 2004, "Lucas-Kanade 20 years on: a
unifying framework", IJCV 56(3)) of pair B's left image, lifted to 3-D by B's own stereo surface,
onto pair A's left image, as direct visual odometry aligns frames through their depth (Engel, Koltun
and Cremers 2018, "Direct sparse odometry", IEEE TPAMI 40(3)). The images are the rectified,
illumination-corrected left images kept small in the feature cache
(:attr:`auvnav.vision.stereo.StereoFeatures.thumbnail`), band-passed (a difference of Gaussians) so
that neither the strobe's residual falloff nor sensor noise dominates.

Steps (:func:`register_direct`):

1. **Surfaces**: each pair's inverse depth over its image, on a regular grid of knots fitted to its
   stereo points with a smoothness prior (:func:`fit_surface`); what the grid cannot follow and
   neighbouring points share is the pair's relief, and a pair whose relief exceeds ``max_relief_m``
   (coral heads) is left to the features, whose parallax it would break. What neighbours do not
   share is noise the stereo understated (its tracker sliding along ripple crests in noisy water),
   and makes the surface less certain, not rough.
2. **Coarse search** (:func:`coarse_search`): A's image warped into B's view by the prior turned about
   B's optical axis in steps of ``yaw_step_rad`` within ``yaw_range_rad``, correlated with B's
   (normalised cross-correlation, ``cv2.matchTemplate``) at every shift within the prior's window,
   at half the thumbnail's resolution, over the largest rectangle of B's image that A sees at the
   prior (:func:`inscribed_box`: where two tracks cross, or pass side by side, they share a corner
   of the image, no row or column of which need be half inside the other view). A pair whose
   window would exceed ``max_window_m`` is not searched (far apart in time, its prior is loose and
   a wide window finds chance look-alikes).
   The local maxima within ``peak_margin`` of the best are kept, at most ``max_peaks`` of them
   (more: a ripple field's crests and their ridges fill the window, the pair is ambiguous).
3. **Refinement** (:func:`refine`) from each peak: Gauss-Newton with Huber weights on the photometric
   residuals of every ``stride``-th pixel of B (A's image where the pixel's 3-D point lands, less
   B's, both standardised over the overlap) over the translation and the turn about the optical
   axis, as perturbations about the overlap's centre on the seafloor; the tilt stays the prior's
   (the attitude sensors'): the images see it only through perspective, which the stereo
   surfaces' own errors would bias. Refinements that slide out of the window are dropped, those
   that meet are one mode. **Ambiguity**: a second mode whose correlation is within
   ``ambiguity_margin`` x (1 - best) of the best rejects the pair (the images at full thumbnail
   resolution tell a ripple field's true crest from its neighbours where they can; where they
   cannot the pair is refused, not registered to the wrong crest), unless the look-alike modes are
   one place seen along a line (:func:`along_a_line`: a crest whose faint texture does not fix the
   position along it): the estimate is then the middle of their stretch, uncertain along it. A best
   mode in the prior's tail with a look-alike nearer the prior is ambiguous too (:func:`nearer_rival`).
   One-dimensional texture (``max_anisotropy``) and a poor correlation reject the pair too.
4. **Covariance**: the inverse normal matrix of the images, scaled by the residuals' variance and
   ``covariance_inflation``, plus what the images cannot see: the parallax of relief finer than the
   surfaces, the error of B's range (which scales the whole motion), B's surface's tilt
   (``surface_tilt_sigma_rad``, through the images' sensitivity to it), and the prior's tilt
   (``tilt_sigma_rad``, through the images' coupling of tilt and translation). The loop closure
   thus says next to nothing about the tilt, which the SLAM's attitude factors hold.

A registration is rejected, with the reason, when a pair lacks a thumbnail or enough stereo points
for its surface, is not near-planar, overlaps too little, has too loose a prior, is ambiguous or
one-dimensional, correlates poorly, or is too uncertain along the floor. The first five are decided
from the pairs' geometry alone (:func:`pair_geometry`, :func:`plan_search`), before their images are
prepared (:func:`prepare`): on the check dive's first 900 s in turbid water that refuses 1,150 of the
1,612 candidates the features leave, and the images of 389 pairs are prepared instead of 1,619.

On the check dive's first 900 s at half scale (``benchmarks/bench_vision.py --seconds 900``), the
pairs it registers are 10.4-10.6 mm and 0.30-0.32 degrees from the truth (median; the features' are
2.5-6.2 mm and 0.07-0.17 degrees), and 11 of 971 are wrong: 1 / 3 / 7 in clear / coastal / turbid
water. Before look-alike modes along a line counted as one place, 8 of 921 were wrong (1 / 3 / 4),
and the turbid water's recall was 0.871 against 0.907 now.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav.frames import rot2euler, se3, se3_apply, se3_inverse, skew
from auvnav.vision.camera import remap_rows
from auvnav.vision.registration import Registration, expm_so3
from auvnav.vision.stereo import StereoFeatures

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DirectSettings:
    """Settings of the direct registration (module docstring).

    Parameters
    ----------
    max_relief_m : float
        Largest relief finer than a pair's surface grid (:attr:`Surface.relief_m`) for the pair to
        count as near-planar.
    min_points : int
        Stereo points a pair needs for its surface.
    surface_cells : (int, int)
        Cells of the surface's grid across and down the image (:func:`fit_surface`).
    surface_roughness_m : float
        1-sigma of the second difference of the seafloor's height between neighbouring knots.
    relief_lag_px : (float, float)
        Stereo points this far apart (thumbnail pixels) are neighbours whose residuals share the
        relief and not the stereo noise (:func:`fit_surface`): beyond the tracker's window (7.5
        thumbnail pixels), within a small coral head.
    band_sigmas_px : (float, float)
        The difference of Gaussians' two sigmas, thumbnail pixels.
    yaw_range_rad, yaw_step_rad : float
        The coarse search turns the prior about B's optical axis over +-``yaw_range_rad`` in steps of
        ``yaw_step_rad``.
    window_sigmas, window_margin_m, max_window_m : float
        The coarse search's translation window: ``window_sigmas`` times the prior's lateral 1-sigma
        plus ``window_margin_m`` (the footprint model's own errors). A pair whose window would be
        wider than ``max_window_m`` is not searched: over a wide window some patch of sand or
        ripples correlates by chance, and the prior of such a pair (far apart in time) can be
        further off than its uncertainty says. Over a ripple field even a narrower window can hold
        the pattern shifted by a wavelength: the pair is then ambiguous and rejected.
    min_overlap : float
        Fraction of B's thumbnail that must fall inside A's at the prior.
    peak_margin : float
        The coarse search's local maxima within this of its best correlation are refined, at most
        ``max_peaks`` of them, best first.
    max_peaks : int
    mode_radius_m : float
        Refinements that put B's centre within this of each other in A are one mode.
    ambiguity_margin : float
        A second mode whose refined correlation is within this fraction of ``1 - best`` of the best
        rejects the pair, unless they lie along one line (:func:`along_a_line`). Neither the images
        nor the prior can choose between them: of the 74 pairs so refused on the check dive's first
        900 s in turbid water (before that exception), the best-correlated mode is the true place in
        29, the mode nearest the prior in 41, and no mode in 18. In 34 of them the modes lie within
        ``mode_radius_m`` of one line, and the truth lies within 1.4 cm of that line and no more
        than 1.1 cm beyond the modes' stretch along it.
    prior_tail_sigmas, rival_margin : float
        A best mode further than ``prior_tail_sigmas`` of the prior's 1-sigmas from the prior is
        refused as ambiguous when another mode within ``rival_margin`` x (1 - best) of its correlation
        lies nearer than that (:func:`nearer_rival`). The prior is then the better judge: on the check
        dive's first 900 s in turbid water, priors from the network of loops put ripple-field pairs 9
        images apart at a crest 5-6 cm off (3.1 sigmas) that correlates 0.02 better than the true
        one at 1.2 sigmas.
    max_anisotropy : float
        Largest ratio of the images' information about the position along the floor in their best
        and worst directions: stripes, or ripples with no texture between the crests, fix the
        position across them only, and nothing stops a refinement sliding along them.
    max_across_sigma_m, max_along_sigma_m, max_yaw_sigma_rad : float
        Largest 1-sigmas, given the tilt, of the position along the floor in the direction the
        images determine best and in the one they determine worst (along ripple crests), and of the
        turn about the optical axis. The turn's 2.5 degrees: over the whole check dive in turbid
        water (``benchmarks/bench_vision.py``, the direct search's window from the network of
        loops), recall / precision 0.894 / 0.9905 at 1.5 degrees, 0.897 / 0.9906 at 2, 0.901 /
        0.9907 at 2.5 and 0.902 / 0.9898 at 3 (the loops from images with a turn's sigma of 1.5-3
        degrees: 172, 11 wrong); its first 900 s: turbid 0.927 -> 0.933 from 1.5 to 2.5 degrees,
        coastal and clear unchanged. The images' turn sigmas are conservative there: the errors of
        those loops' turns are 0.15-0.22 sigmas at the median.
    min_correlation : float
        Normalised cross-correlation of the band-passed images over the overlap at the solution.
    stride : int
        Every ``stride``-th pixel of B (each axis) enters the refinement.
    huber_k : float
        Huber threshold, sigmas.
    iterations : int
        Most Gauss-Newton iterations.
    candidate_iterations : int
        Most iterations from each of several coarse peaks (the best mode is then refined fully).
    covariance_inflation : float
        The images' part of the covariance (the translation and the turn given the tilt) is the
        inverse of their normal matrix times this (neighbouring pixels of a band-passed image are
        not independent; with the terms below, the loops from images on the check dive have a
        median Mahalanobis distance of about 1 against the truth: conservative).
    surface_tilt_sigma_rad : float
        1-sigma of the tilt of a pair's stereo surface (its points' depth errors vary across the
        image: on the check dive a pair's points lean by up to a degree against the true seafloor);
        carried into the pose by the images' sensitivity to it.
    tilt_sigma_rad : float
        1-sigma of the relative tilt, which the direct registration leaves at the prior's (the
        attitude sensors'): large, so that the loop closure says next to nothing about it and the
        SLAM's own attitude factors hold it (the prior's relative tilt is within about a degree).
    """

    max_relief_m: float = 0.10
    min_points: int = 30
    surface_cells: tuple[int, int] = (8, 6)
    surface_roughness_m: float = 0.01
    relief_lag_px: tuple[float, float] = (10.0, 30.0)
    band_sigmas_px: tuple[float, float] = (0.7, 3.0)
    yaw_range_rad: float = float(np.radians(5.0))
    yaw_step_rad: float = float(np.radians(1.0))
    window_sigmas: float = 3.0
    window_margin_m: float = 0.01
    max_window_m: float = 0.2
    min_overlap: float = 0.25
    peak_margin: float = 0.15
    max_peaks: int = 40
    mode_radius_m: float = 0.015
    ambiguity_margin: float = 0.25
    prior_tail_sigmas: float = 2.5
    rival_margin: float = 0.75
    max_anisotropy: float = 200.0
    max_across_sigma_m: float = 0.02
    max_along_sigma_m: float = 0.05
    max_yaw_sigma_rad: float = float(np.radians(2.5))
    min_correlation: float = 0.3
    stride: int = 2
    huber_k: float = 2.0
    iterations: int = 20
    candidate_iterations: int = 4
    covariance_inflation: float = 30.0
    surface_tilt_sigma_rad: float = float(np.radians(1.0))
    tilt_sigma_rad: float = float(np.radians(2.0))


@dataclass(frozen=True)
class Surface:
    """A pair's seafloor as inverse depth over the normalised coordinates (``x = X / Z``, ``y = Y / Z``)
    of its rectified left camera: bilinear between the values at the knots of a regular grid.

    Parameters
    ----------
    values : ndarray, shape (ny, nx)
        Inverse depth at the knots, 1/m.
    covariance : ndarray, shape (ny nx, ny nx)
        Their covariance (row-major knots), 1/m^2.
    x0, y0, dx, dy : float
        The first knot and the knot spacing, normalised coordinates.
    relief_m : float
        The part of the fit's robust RMS residual that the points' own noise does not explain and
        neighbouring points share, along the ray at the median range, metres: the relief finer than
        the grid.
    range_m : float
        Median range of the points, metres.
    """

    values: FloatArray
    covariance: FloatArray
    x0: float
    y0: float
    dx: float
    dy: float
    relief_m: float
    range_m: float

    def inverse_depth(self, x: FloatArray, y: FloatArray) -> FloatArray:
        rows, weights = _bilinear(x, y, self.x0, self.y0, self.dx, self.dy, self.values.shape)
        return np.sum(self.values.ravel()[rows] * weights, axis=-1)

    def variance(self, x: float, y: float) -> float:
        """Variance of the inverse depth at one normalised point: the knots' and the relief's."""
        rows, weights = _bilinear(
            np.array(x), np.array(y), self.x0, self.y0, self.dx, self.dy, self.values.shape
        )
        C = self.covariance[np.ix_(rows, rows)]
        relief = self.relief_m / self.range_m**2
        return float(weights @ C @ weights) + relief**2


def _bilinear(
    x: FloatArray, y: FloatArray, x0: float, y0: float, dx: float, dy: float, shape: tuple[int, int]
) -> tuple[NDArray[np.intp], FloatArray]:
    """The four knots (flat indices, (..., 4)) around each point and their bilinear weights, points
    outside the grid held at its edge."""
    ny, nx = shape
    u = np.clip((np.asarray(x) - x0) / dx, 0.0, nx - 1 - 1e-9)
    v = np.clip((np.asarray(y) - y0) / dy, 0.0, ny - 1 - 1e-9)
    i, j = np.floor(u).astype(np.intp), np.floor(v).astype(np.intp)
    fu, fv = u - i, v - j
    rows = np.stack([j * nx + i, j * nx + i + 1, (j + 1) * nx + i, (j + 1) * nx + i + 1], axis=-1)
    weights = np.stack([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv], axis=-1)
    return rows, weights


#: The stereo points' noise beyond their own figures (oriented texture in noisy images: the tracker
#: slides along ripple crests) need not average out over a pair: its median error, against the truth,
#: is about this fraction of that noise's 1-sigma (check dive, first 900 s, every second pair with
#: such noise in coastal and turbid water: 0.09-0.14 median, 0.17-0.33 at the 90th percentile).
SURFACE_BIAS_FRACTION = 0.14


def fit_surface(
    p_rect_m: FloatArray,
    sigma_inverse_m: FloatArray,
    camera: Pinhole,
    shape: tuple[int, int],
    settings: DirectSettings,
) -> Surface | None:
    """The pair's :class:`Surface` over its image (``camera``, ``shape``: rows, columns) from its stereo
    points in the rectified frame (N, 3) with inverse-depth sigmas (N,); None with fewer than
    ``settings.min_points``.

    Regularised least squares on a grid of ``settings.surface_cells`` cells: the points, weighted by
    their own noise and reweighted (Huber at 2 robust sigmas), and the second differences of the
    knots, whose 1-sigma is ``settings.surface_roughness_m`` of height at the points' range (relief
    the grid follows, where points are dense; smooth across featureless gaps).

    The residuals' robust variance beyond the points' stated noise is split by their covariance
    between neighbours (``settings.relief_lag_px`` apart, :func:`_neighbour_covariance`): the shared
    part is relief; the rest is noise the stereo understated, which scales the points' noise, and
    :data:`SURFACE_BIAS_FRACTION` of which is common to all of them. Without the split, the
    points of a ripple field in turbid water, whose stereo tracker slides along the crests (range
    errors of 6-30 cm against 3-8 stated), read as relief (8.3 cm at the 90th percentile, 1.3 cm
    split; the simulated floor has none that fine): of the 133 overlapping ripple-field pairs missed
    on the check dive's first 900 s in turbid water, 15 were refused as not near-planar and 35 as too
    uncertain (the relief's parallax), and 2 and 6 with the split.
    """
    if len(p_rect_m) < settings.min_points:
        return None
    z = p_rect_m[:, 2]
    x, y, w = p_rect_m[:, 0] / z, p_rect_m[:, 1] / z, 1.0 / z
    nx, ny = settings.surface_cells[0] + 1, settings.surface_cells[1] + 1
    x0, y0 = camera.normalised(np.float64(0.0), np.float64(0.0))
    x1, y1 = camera.normalised(np.float64(shape[1] - 1), np.float64(shape[0] - 1))
    dx, dy = (x1 - x0) / (nx - 1), (y1 - y0) / (ny - 1)
    rows, weights = _bilinear(x, y, x0, y0, dx, dy, (ny, nx))
    K = nx * ny
    # each point's four knots: the normal matrix A^T W A of the sparse design A, summed pair by pair
    pairs = (rows[:, :, None] * K + rows[:, None, :]).ravel()
    products = weights[:, :, None] * weights[:, None, :]

    def normal(wt: FloatArray) -> FloatArray:
        return np.bincount(pairs, (products * wt[:, None, None]).ravel(), minlength=K * K).reshape(K, K)

    range_m = float(np.median(z))
    smooth = settings.surface_roughness_m / range_m**2  # height -> inverse depth
    noise2 = sigma_inverse_m**2
    weight = 1.0 / noise2
    prior = _second_differences(ny, nx) / smooth**2 + np.eye(K) * 1e-6 / float(np.median(w)) ** 2
    values = np.zeros(K)
    sigma = 0.0
    for _ in range(3):
        rhs = np.bincount(rows.ravel(), (weights * (weight * w)[:, None]).ravel(), minlength=K)
        values = np.linalg.solve(normal(weight) + prior, rhs)
        r = w - np.sum(values[rows] * weights, axis=1)
        sigma = 1.4826 * float(np.median(np.abs(r))) + 1e-12
        weight = _huber(np.abs(r) / np.sqrt(noise2 + sigma**2), 2.0) / noise2
    unexplained = max(0.0, sigma**2 - float(np.median(noise2)))
    relief2 = min(
        unexplained, max(0.0, _neighbour_covariance(r, x * camera.fx, y * camera.fy, settings.relief_lag_px))
    )
    # what the points' own noise does not explain and neighbours do not share is noise too
    noise2 = noise2 * (1.0 + (unexplained - relief2) / float(np.median(noise2)))
    # the knots' covariance, each point's variance its noise and the relief the grid misses, and the
    # part of that extra noise common to the whole pair
    covariance = np.linalg.inv(normal(weight * noise2 / (noise2 + relief2)) + prior)
    covariance += (SURFACE_BIAS_FRACTION**2 * (unexplained - relief2)) * np.ones((K, K))
    return Surface(
        values.reshape(ny, nx),
        covariance,
        float(x0),
        float(y0),
        float(dx),
        float(dy),
        np.sqrt(relief2) * range_m**2,
        range_m,
    )


@lru_cache(maxsize=8)
def _second_differences(ny: int, nx: int) -> FloatArray:
    """``D^T D`` of the second differences along the rows and the columns of a grid of knots."""
    idx = np.arange(ny * nx).reshape(ny, nx)
    blocks = []
    for a, b, c in ((idx[:, :-2], idx[:, 1:-1], idx[:, 2:]), (idx[:-2], idx[1:-1], idx[2:])):
        block = np.zeros((a.size, ny * nx))
        r = np.arange(a.size)
        block[r, a.ravel()] = 1.0
        block[r, b.ravel()] = -2.0
        block[r, c.ravel()] = 1.0
        blocks.append(block)
    D = np.concatenate(blocks)
    return D.T @ D


def _neighbour_covariance(r: FloatArray, u: FloatArray, v: FloatArray, lag_px: tuple[float, float]) -> float:
    """The covariance of residuals ``r`` of points (``u``, ``v``, pixels) and their neighbours between
    ``lag_px`` apart: robust (Gnanadesikan and Kettenring 1972, from the MADs of their sums and
    differences); 0 with fewer than 30 such neighbours."""
    lo, hi = lag_px
    tree = cKDTree(np.column_stack([u, v]))
    dist, nearest = tree.query(np.column_stack([u, v]), k=9, distance_upper_bound=hi)
    near = (dist >= lo) & np.isfinite(dist)
    a, b = np.nonzero(near)
    if len(a) < 30:
        return 0.0
    ra, rb = r[a], r[nearest[a, b]]
    return (_robust_sigma(ra + rb) ** 2 - _robust_sigma(ra - rb) ** 2) / 4.0


def _robust_sigma(x: FloatArray) -> float:
    """1.4826 times the median absolute deviation of ``x``: its standard deviation, were it normal."""
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


@dataclass(frozen=True)
class Pinhole:
    """Rectified intrinsics of an image: focal lengths and principal point, pixels."""

    fx: float
    fy: float
    cx: float
    cy: float

    def scaled(self, sx: float, sy: float) -> Pinhole:
        """The same camera for the image resized by (sx, sy) (pixel centres kept)."""
        return Pinhole(self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5)

    def project(self, X: FloatArray) -> tuple[FloatArray, FloatArray]:
        z = X[..., 2]
        return self.fx * X[..., 0] / z + self.cx, self.fy * X[..., 1] / z + self.cy

    def normalised(self, u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        return (u - self.cx) / self.fx, (v - self.cy) / self.fy


@dataclass(frozen=True)
class Geometry:
    """What the direct registration knows of a pair before it looks at its images: enough to refuse
    most candidates (no surface, relief, a loose prior, too little overlap: :func:`plan_search`)
    without preparing an image.

    Parameters
    ----------
    camera : Pinhole
        Rectified intrinsics of the thumbnail.
    shape : (int, int)
        The thumbnail's rows and columns.
    surface : Surface or None
    p_rect_m : ndarray
        The stereo points in the rectified frame (N, 3).
    R1 : ndarray, shape (3, 3)
        The rotation of the left camera's frame into the rectified one.
    """

    camera: Pinhole
    shape: tuple[int, int]
    surface: Surface | None
    p_rect_m: FloatArray
    R1: FloatArray

    @property
    def coarse_shape(self) -> tuple[int, int]:
        """Rows and columns of the half-resolution image of the coarse search."""
        return self.shape[0] // 2, self.shape[1] // 2

    @property
    def camera_coarse(self) -> Pinhole:
        """Rectified intrinsics of the half-resolution image."""
        (h, w), (hc, wc) = self.shape, self.coarse_shape
        return self.camera.scaled(wc / w, hc / h)


@dataclass(frozen=True)
class Prepared:
    """A pair's geometry and images for the direct registration, computed once per pair and reused.

    Parameters
    ----------
    geometry : Geometry
    image_grad : ndarray, float32, shape (H, W, 3)
        Band-passed thumbnail, scaled to unit standard deviation, and its horizontal and vertical
        derivatives, as the channels of one image (the refinement samples all three at once).
    image_coarse : ndarray, float32
        The band-passed thumbnail at half resolution.
    """

    geometry: Geometry
    image_grad: NDArray[np.float32]
    image_coarse: NDArray[np.float32]


def _bandpass(image: NDArray[np.float32], sigmas: tuple[float, float]) -> NDArray[np.float32]:
    out = cv2.GaussianBlur(image, (0, 0), sigmas[0]) - cv2.GaussianBlur(image, (0, 0), sigmas[1])
    return out / np.float32(max(float(out.std()), 1e-6))


def pair_geometry(features: StereoFeatures, settings: DirectSettings) -> Geometry | None:
    """A pair's :class:`Geometry` (the thumbnail's size from its header: the image is not decoded), or
    None when it has no thumbnail."""
    shape = features.thumbnail_shape()
    geometry = features.geometry
    if shape is None or geometry is None:
        return None
    camera = Pinhole(geometry.f_px, geometry.f_px, geometry.cx_px, geometry.cy_px).scaled(
        *features.thumbnail_scale
    )
    R1 = np.asarray(geometry.R1, dtype=float)
    p = features.p_cam_m @ R1.T
    cov_z = np.einsum("i,nij,j->n", R1[2], features.cov_cam_m2, R1[2])
    sigma_inv = np.sqrt(np.maximum(cov_z, 0.0)) / p[:, 2] ** 2
    surface = fit_surface(p, sigma_inv, camera, shape, settings)
    return Geometry(camera, shape, surface, p, R1)


def prepare(
    features: StereoFeatures, settings: DirectSettings, geometry: Geometry | None = None
) -> Prepared | None:
    """A pair's :class:`Prepared` data (``geometry``: its :func:`pair_geometry`, when known), or None
    when it has no thumbnail or the thumbnail does not decode to the size its header gives."""
    if geometry is None:
        geometry = pair_geometry(features, settings)
    thumb = features.thumbnail_image()
    if geometry is None or thumb is None or thumb.shape != geometry.shape:
        return None
    image = _bandpass(thumb.astype(np.float32), settings.band_sigmas_px)
    hc, wc = geometry.coarse_shape
    coarse = cv2.resize(thumb, (wc, hc), interpolation=cv2.INTER_AREA).astype(np.float32)
    coarse = _bandpass(coarse, (settings.band_sigmas_px[0], settings.band_sigmas_px[1] / 2))
    grad_u = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    grad_v = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    return Prepared(geometry, cv2.merge((image, grad_u, grad_v)), coarse)


def _points_of_pixels(surface: Surface, camera: Pinhole, u: FloatArray, v: FloatArray) -> FloatArray:
    """3-D points (rectified frame) on ``surface`` seen at pixels (u, v) of ``camera``."""
    x, y = camera.normalised(u, v)
    z = 1.0 / surface.inverse_depth(x, y)
    return np.stack([x * z, y * z, z], axis=-1)


def _projected(
    camera: Pinhole, shape: tuple[int, int], X: FloatArray
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Where points X (..., 3) project in an image of ``shape`` (rows, columns), and which land inside
    it (1 px border)."""
    u, v = camera.project(X)
    h, w = shape
    return u, v, (X[..., 2] > 0) & (u >= 1) & (u <= w - 2) & (v >= 1) & (v <= h - 2)


def _sample(image: NDArray[np.float32], camera: Pinhole, X: FloatArray) -> tuple[NDArray, NDArray]:
    """An image (H, W) or (H, W, C) sampled (bilinear) where points X (..., 3) project (shape ``X``'s
    without its last axis, then C), and which points land inside (1 px border)."""
    u, v, inside = _projected(camera, image.shape[:2], X)
    mu, mv = u.astype(np.float32), v.astype(np.float32)
    if mu.ndim == 1:
        mu, mv = remap_rows(mu, mv)
    out = cv2.remap(image, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    channels = image.shape[2:]
    return out.reshape(-1, *channels)[: u.size].reshape(*u.shape, *channels), inside


@dataclass(frozen=True)
class CoarseResult:
    """The coarse search: its peaks (rectified poses, best first, with their correlations and whether
    each lies at the edge of the search; none when there are more than ``max_peaks``) and the number
    of peaks found."""

    peaks: list[tuple[FloatArray, float, bool]]
    candidates: int


#: Peaks of the coarse search closer than this (coarse pixels) to a stronger one are not refined apart.
PEAK_SEPARATION_PX = 3.0


def _turn(T: FloatArray, yaw: float, shift: tuple[float, float] = (0.0, 0.0)) -> FloatArray:
    """``T`` followed by a turn of ``yaw`` about the optical axis and a shift in the image plane."""
    c, s = np.cos(yaw), np.sin(yaw)
    return T @ se3(
        np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([shift[0], shift[1], 0.0])
    )


def _yaws(settings: DirectSettings) -> FloatArray:
    """The turns about B's optical axis the coarse search tries, radians."""
    return np.arange(-settings.yaw_range_rad, settings.yaw_range_rad + 1e-9, settings.yaw_step_rad)


def inscribed_box(mask: NDArray[np.bool_], min_side: int = 8) -> tuple[int, int, int, int] | None:
    """The largest rectangle ``(r0, r1, c0, c1)`` (rows r0 to r1 - 1, columns c0 to c1 - 1) within the
    span of ``mask``'s true pixels on each of its rows (all true where each row's are one run, as where
    two views overlap), or None when none is ``min_side`` pixels a side."""
    h, w = mask.shape
    on = mask.any(axis=1)
    first = np.append(np.where(on, mask.argmax(axis=1), w), w)
    last = np.append(np.where(on, w - mask[:, ::-1].argmax(axis=1), 0), 0)
    # [r0, k]: the rectangle of rows r0 to r0 + k (row h: a row of nothing, past the end)
    rows = np.minimum(np.arange(h)[:, None] + np.arange(h)[None, :], h)
    left = np.maximum.accumulate(first[rows], axis=1)
    right = np.minimum.accumulate(last[rows], axis=1)
    width, height = right - left, np.arange(1, h + 1)[None, :]
    area = np.where((width >= min_side) & (height >= min_side), width * height, 0)
    r0, k = np.unravel_index(int(area.argmax()), area.shape)
    if area[r0, k] == 0:
        return None
    return int(r0), int(r0 + k + 1), int(left[r0, k]), int(right[r0, k])


@dataclass(frozen=True)
class Search:
    """Where the coarse search looks (:func:`plan_search`).

    Parameters
    ----------
    T_rect : ndarray, shape (4, 4)
        The prior ``T_a_b`` between the pairs' rectified frames.
    window_m : float
        The radius of the translation window.
    margin : int
        The window's radius in B's coarse pixels.
    points : ndarray, shape (h + 2 margin, w + 2 margin, 3)
        B's coarse pixels, and a margin about them, lifted to 3-D by its surface (B's rectified frame).
    box : (int, int, int, int)
        The largest rectangle of B's coarse image (rows r0 to r1 - 1, columns c0 to c1 - 1) that A
        sees at the prior turned by the search's first yaw (:func:`inscribed_box`).
    """

    T_rect: FloatArray
    window_m: float
    margin: int
    points: FloatArray
    box: tuple[int, int, int, int]


def plan_search(
    A: Geometry | None, B: Geometry | None, T_prior: FloatArray, sigma_m: float, settings: DirectSettings
) -> Search | str:
    """The coarse search for pair B in pair A (``T_prior``: the prior ``T_a_b``, unrectified camera
    frames, as :func:`auvnav.vision.registration.register`; ``sigma_m``: the 1-sigma of its lateral
    position, metres), or why the pair is refused: from the pairs' geometry alone (no thumbnail, no
    surface, relief, too loose a prior, too little overlap), before any image is prepared."""
    if A is None or B is None:
        return "no thumbnail"
    if A.surface is None or B.surface is None:
        return "too few stereo points for a surface"
    relief = max(A.surface.relief_m, B.surface.relief_m)
    if relief > settings.max_relief_m:
        return f"not near-planar (relief {100 * relief:.1f} cm)"
    window = settings.window_sigmas * sigma_m + settings.window_margin_m
    if window > settings.max_window_m:
        return f"prior too uncertain (search radius {100 * window:.0f} cm)"
    S = se3(A.R1, np.zeros(3))
    T_rect = S @ T_prior @ se3_inverse(S)
    h, w = B.coarse_shape
    cam = B.camera_coarse
    m = max(1, int(np.ceil(window * cam.fx / B.surface.range_m)))
    u, v = np.meshgrid(np.arange(-m, w + m, dtype=float), np.arange(-m, h + m, dtype=float))
    X = _points_of_pixels(B.surface, cam, u, v)
    _, _, inside = _projected(
        A.camera_coarse, A.coarse_shape, se3_apply(_turn(T_rect, float(_yaws(settings)[0])), X)
    )
    core = inside[m : m + h, m : m + w]
    box = inscribed_box(core)
    if core.mean() < settings.min_overlap or box is None:
        return "overlap too small"
    return Search(T_rect, window, m, X, box)


def coarse_search(A: Prepared, B: Prepared, search: Search, settings: DirectSettings) -> CoarseResult | None:
    """Correlation over yaw and shift at half resolution (module docstring, step 2) where ``search``
    says; None when no shift is seen whole."""
    img_b = B.image_coarse
    cam_a, cam = A.geometry.camera_coarse, B.geometry.camera_coarse
    m, X, (r0, r1, c0, c1) = search.margin, search.points, search.box
    yaws = _yaws(settings)
    maps = []
    for dyaw in yaws:
        warped, inside = _sample(A.image_coarse, cam_a, se3_apply(_turn(search.T_rect, dyaw), X))
        corr = cv2.matchTemplate(
            warped[r0 : r1 + 2 * m, c0 : c1 + 2 * m], img_b[r0:r1, c0:c1], cv2.TM_CCOEFF_NORMED
        )
        # shifts that put the template partly outside A's image are not compared (where A is blank
        # the normalised correlation is meaningless)
        seen = cv2.matchTemplate(
            inside[r0 : r1 + 2 * m, c0 : c1 + 2 * m].astype(np.float32),
            np.ones((r1 - r0, c1 - c0), np.float32),
            cv2.TM_CCORR,
        )
        corr[seen < 0.95 * (r1 - r0) * (c1 - c0)] = -1.0
        maps.append(corr)
    stack = np.stack(maps)
    yy, xx = np.mgrid[-m : m + 1, -m : m + 1]
    stack[:, yy**2 + xx**2 > m * m] = -1.0
    flat, which = stack.max(axis=0), stack.argmax(axis=0)
    best = float(flat.max())
    # local maxima (3 x 3) within the peak margin of the best, best first
    if best <= -1.0:
        return None
    is_peak = (flat >= cv2.dilate(flat, np.ones((3, 3), np.uint8))) & (flat >= best - settings.peak_margin)
    iy, ix = np.nonzero(is_peak)
    # strongest first, each at least PEAK_SEPARATION_PX from those kept
    kept: list[int] = []
    for n in np.argsort(-flat[iy, ix]):
        if all((iy[n] - iy[k]) ** 2 + (ix[n] - ix[k]) ** 2 >= PEAK_SEPARATION_PX**2 for k in kept):
            kept.append(int(n))
    if len(kept) > settings.max_peaks:
        return CoarseResult([], len(kept))
    order = np.array(kept, dtype=np.intp)
    surface = B.geometry.surface
    assert surface is not None  # plan_search refuses pairs without one
    scale = (surface.range_m / cam.fx, surface.range_m / cam.fy)
    peaks = []
    for y, x in zip(iy[order], ix[order], strict=True):
        k = int(which[y, x])
        edge = (x - m) ** 2 + (y - m) ** 2 > (m - 1.5) ** 2 or (len(yaws) > 1 and k in (0, len(yaws) - 1))
        shift = ((x - m) * scale[0], (y - m) * scale[1])
        peaks.append((_turn(search.T_rect, float(yaws[k]), shift), float(flat[y, x]), bool(edge)))
    return CoarseResult(peaks, len(kept))


@dataclass(frozen=True)
class Refined:
    """The refinement's pose (rectified frames), its covariance (``(dt, dtheta)``, rectified frame of
    A), the covariance of its in-plane components (x, y, z, yaw) given the tilt (what the images
    measure), the ratio of the images' largest to smallest information about the position along the
    floor (large for one-dimensional texture), the correlation at the solution, the counts of pixels
    and stereo points, and the normalised residual."""

    T_a_b: FloatArray
    covariance: FloatArray
    in_plane_covariance: FloatArray
    anisotropy: float
    correlation: float
    pixels: int
    points: int
    normalised_residual: float


#: The components of the pose perturbation ``(dt, dtheta)`` (A's rectified camera axes: z along the
#: optical axis, which looks at the seafloor) that the images determine (across the seafloor, the
#: height through the image's scale, and the turn about the optical axis) and those left at the
#: prior's (the tilt).
IN_PLANE = np.array([0, 1, 2, 5])
TILT = np.array([3, 4])


def _perturb(R: FloatArray, t: FloatArray, d: FloatArray, pivot: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The pose ``(R, t)`` perturbed by ``d = (dt, dtheta)`` about ``pivot`` (frame A): ``X_a <-
    exp(dtheta) (X_a - pivot) + pivot + dt``."""
    E = expm_so3(d[3:])
    return E @ R, E @ (t - pivot) + pivot + d[:3]


def overlap_points(
    P: FloatArray, T_other_this: FloatArray, other: Pinhole, shape: tuple[int, int]
) -> NDArray[np.bool_]:
    """Which points of one pair (its rectified frame) the other pair's image sees."""
    X = se3_apply(T_other_this, P)
    u, v = other.project(X)
    return (X[:, 2] > 0) & (u >= 0) & (u <= shape[1] - 1) & (v >= 0) & (v <= shape[0] - 1)


def lift(B: Prepared, stride: int) -> tuple[FloatArray, NDArray[np.float32]]:
    """Every ``stride``-th pixel of B's image (each axis) lifted to 3-D by its surface (rectified
    frame, (N, 3)), and the image there (N,): what :func:`refine` compares with A's image."""
    surface = B.geometry.surface
    assert surface is not None  # plan_search refuses pairs without one
    h, w = B.image_grad.shape[:2]
    u, v = np.meshgrid(
        np.arange(stride / 2, w - 1, stride, dtype=float), np.arange(stride / 2, h - 1, stride, dtype=float)
    )
    Xb = _points_of_pixels(surface, B.geometry.camera, u.ravel(), v.ravel())
    image = cv2.remap(B.image_grad, u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR)
    return Xb, image[..., 0].ravel()


def refine(
    A: Prepared,
    B: Prepared,
    T0: FloatArray,
    settings: DirectSettings,
    lifted: tuple[FloatArray, NDArray[np.float32]],
) -> Refined | None:
    """The relative pose by Gauss-Newton on the images, its tilt held at ``T0``'s; None when too
    little overlaps.

    The images see a tilt only through perspective, and tilting a camera moves its image as a shift
    along the floor does: the tilt is left at the prior's (the attitude sensors'), with
    ``settings.tilt_sigma_rad``, and the images give the rest (:data:`IN_PLANE`), as perturbations
    about the overlap's centre on the seafloor, which a tilt leaves in place in the images. The
    covariance of those adds the tilt's, carried through the images' coupling of the two, the
    parallax of relief finer than the surfaces, and the uncertainty of B's range (which scales the
    whole motion); it is turned at the end into the registration's perturbation about A's camera.
    """
    ga, gb = A.geometry, B.geometry
    assert ga.surface is not None and gb.surface is not None
    Xb, Ib = lifted
    cam = ga.camera
    R, t = T0[:3, :3].copy(), T0[:3, 3].copy()
    Xa = se3_apply(se3(R, t), Xb)
    looks, inside = _sample(A.image_grad, cam, Xa)
    seen = np.flatnonzero(inside)
    if len(seen) < 200:
        return None
    # the pivot: the centre of B's part of the overlap, on B's surface
    pivot_b = Xb[seen].mean(axis=0)
    ii = np.ix_(IN_PLANE, IN_PLANE)
    for _ in range(settings.iterations):
        pivot = R @ pivot_b + t
        if len(seen) < 200:
            return None
        used = seen  # the points of this linearisation
        Ia, gu, gv = looks.take(used, axis=0).T
        ib, Xs = Ib.take(used), Xa.take(used, axis=0)
        # both sides standardised over the overlap: the residuals' sum of squares is then that of
        # a normalised cross-correlation, which sliding into a blank patch of A cannot lower
        scale_a = 1.0 / max(float(Ia.std()), 1e-6)
        r = _standardised(Ia) - _standardised(ib)
        sigma_r = _robust_sigma(r) + 1e-9
        z = Xs[:, 2]
        # d I / d X_a = (gu fx, gv fy, -(gu fx x + gv fy y) / z) / z; d X_a / d(dt, dtheta) = [I, -[X_a - pivot]x]
        a_u, a_v = scale_a * gu * cam.fx / z, scale_a * gv * cam.fy / z
        dI = np.column_stack([a_u, a_v, -(a_u * Xs[:, 0] + a_v * Xs[:, 1]) / z])
        J = np.empty((len(used), 6))
        J[:, :3] = dI
        # (X_a - pivot) x dI by components: numpy's cross computes the same products four times slower
        (l0, l1, l2), (d0, d1, d2) = (Xs - pivot).T, dI.T
        J[:, 3], J[:, 4], J[:, 5] = l1 * d2 - l2 * d1, l2 * d0 - l0 * d2, l0 * d1 - l1 * d0
        wp = _huber(np.abs(r) / sigma_r, settings.huber_k) / sigma_r**2
        H = J.T @ (J * wp[:, None])
        step = np.zeros(6)
        try:
            step[IN_PLANE] = -np.linalg.solve(H[ii], J[:, IN_PLANE].T @ (wp * r))
        except np.linalg.LinAlgError:
            return None
        # a step that does not lower the robust cost is halved (a few times) before it is taken; the
        # images sampled at the step taken are the next iteration's
        cost = _robust_cost(r / sigma_r, settings.huber_k)
        for _ in range(4):
            R_new, t_new = _perturb(R, t, step, pivot)
            Xa = se3_apply(se3(R_new, t_new), Xb)
            looks, inside = _sample(A.image_grad, cam, Xa)
            seen = np.flatnonzero(inside)
            trial = (_standardised(looks[seen, 0]) - _standardised(Ib.take(seen))) / sigma_r
            if len(seen) >= 200 and _robust_cost(trial, settings.huber_k) <= cost:
                break
            step = 0.5 * step
        R, t = R_new, t_new
        if np.abs(step).max() < 1e-5:  # 10 micrometres, 10 microradians
            break
    pivot = R @ pivot_b + t
    cov_images = settings.covariance_inflation * np.linalg.inv(H[ii])
    information = np.linalg.eigvalsh(H[:2, :2])  # across the floor, from the images alone
    anisotropy = float(information[1] / max(information[0], 1e-12 * information[1]))
    # parallax of the relief finer than the surfaces (a point off the surface by h, seen from two
    # cameras a baseline b apart at range Z, is displaced by h b / Z between the views), and B's
    # range, whose relative error scales the whole motion
    baseline = float(np.linalg.norm(t))
    relief = max(ga.surface.relief_m, gb.surface.relief_m)
    parallax = relief * baseline / float(np.median(z))
    reach = float(np.sqrt(np.mean(np.sum((Xs[:, :2] - pivot[:2]) ** 2, axis=1))))
    ray = pivot_b[:2] / pivot_b[2]
    scale = baseline * pivot_b[2] * np.sqrt(gb.surface.variance(ray[0], ray[1]))
    cov_images += np.diag([parallax**2 + scale**2, parallax**2 + scale**2, scale**2, (parallax / reach) ** 2])
    # B's surface tilted by a small angle (its inverse depth scaled by 1 + a x + b y) moves its lifted
    # pixels by -X_b x (or y): the solution's sensitivity to that tilt, times its 1-sigma
    xb, yb = Xb[used, 0] / Xb[used, 2], Xb[used, 1] / Xb[used, 2]
    lever = np.sum(dI * (Xs - t), axis=1)
    J_s = -np.column_stack([xb * lever, yb * lever])
    sensitivity = -np.linalg.solve(H[ii], J[:, IN_PLANE].T @ (J_s * wp[:, None]))
    cov_images += settings.surface_tilt_sigma_rad**2 * sensitivity @ sensitivity.T
    cov_tilt = np.eye(2) * settings.tilt_sigma_rad**2
    K = -np.linalg.solve(H[ii], H[np.ix_(IN_PLANE, TILT)])
    cov = np.zeros((6, 6))
    cov[np.ix_(TILT, TILT)] = cov_tilt
    cov[ii] = cov_images + K @ cov_tilt @ K.T
    cov[np.ix_(IN_PLANE, TILT)] = K @ cov_tilt
    cov[np.ix_(TILT, IN_PLANE)] = (K @ cov_tilt).T
    # about the pivot -> about A's camera: dt = dt_pivot - [t - pivot]x dtheta
    G = np.eye(6)
    G[:3, 3:] = -skew(t - pivot)
    n_pix = len(used)
    return Refined(
        se3(R, t),
        G @ cov @ G.T,
        cov_images,
        anisotropy,
        float(np.corrcoef(Ia, ib)[0, 1]),
        n_pix,
        int(overlap_points(gb.p_rect_m, se3(R, t), cam, ga.shape).sum()),
        float(np.sqrt(np.sum(wp * r * r) / max(n_pix - 4, 1))),
    )


def _standardised(x: NDArray) -> NDArray:
    """``x`` less its mean, over its standard deviation."""
    return (x - x.mean()) / max(float(x.std()), 1e-6)


def _robust_cost(a: FloatArray, k: float) -> float:
    """Mean Huber cost of residuals ``a`` in sigmas."""
    b = np.abs(a)
    return float(np.mean(np.where(b <= k, 0.5 * b * b, k * (b - 0.5 * k))))


def _huber(a: FloatArray, k: float) -> FloatArray:
    """Huber weights of residuals ``a`` in sigmas."""
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-12))


def rejected(reason: str, T: FloatArray | None = None) -> Registration:
    """A refused registration, with its reason (and the pose it reached, when it reached one)."""
    return Registration(
        False, reason, np.eye(4) if T is None else T, np.full((6, 6), np.nan), 0, 0, float("nan")
    )


def along_a_line(
    alike: list[tuple[Refined, bool, FloatArray]], start: FloatArray, window: float, settings: DirectSettings
) -> tuple[FloatArray, FloatArray] | None:
    """Look-alike modes (best first, each with whether its coarse peak was at the edge of the search and
    where it puts B's centre in A, rectified frame) that are one place seen along a line of the floor:
    ripple crests whose faint texture does not fix the position along them. They are one place when
    all lie within ``mode_radius_m`` of one line and are turned within ``yaw_step_rad`` of the best.

    Returns the shift from the best mode to the middle of the line's stretch where the place can be,
    and the covariance of ``(dt, dtheta)`` that stretch and the modes' turns add, each a uniform
    distribution: the stretch is the modes' span and ``mode_radius_m`` beyond its ends, or the
    whole chord of the search window (centre ``start``, radius ``window``) when a mode was at its
    edge, the line perhaps going on beyond it. None when the modes are not one place."""
    P = np.array([w[:2] for _, _, w in alike]) - alike[0][2][:2]
    _, _, vt = np.linalg.svd(P - P.mean(axis=0))
    u = vt[0]
    R0 = alike[0][0].T_a_b[:3, :3]
    turns = rot2euler(np.array([m.T_a_b[:3, :3] for m, _, _ in alike]) @ R0.T)[0]
    radius = settings.mode_radius_m
    if np.abs(P @ np.array([-u[1], u[0]])).max() > radius or np.abs(turns).max() > settings.yaw_step_rad:
        return None
    along = P @ u
    lo, hi = along.min() - radius, along.max() + radius
    if any(at_edge for _, at_edge, _ in alike):
        c = alike[0][2][:2] - start[:2]
        b = float(c @ u)
        reach = np.sqrt(max(b * b - (c @ c - window**2), 0.0))
        lo, hi = min(lo, -b - reach), max(hi, -b + reach)
    extra = np.zeros((6, 6))
    extra[:2, :2] = np.outer(u, u) * (0.5 * (hi - lo)) ** 2 / 3.0
    extra[5, 5] = (0.5 * np.ptp(turns)) ** 2 / 3.0
    return np.array([*(0.5 * (lo + hi) * u), 0.0]), extra


def nearer_rival(
    modes: list[tuple[Refined, bool, FloatArray]], start: FloatArray, window: float, settings: DirectSettings
) -> bool:
    """Whether the best of ``modes`` (best first; B's centre in A at each, ``start`` at the prior) lies
    in the prior's tail, beyond ``prior_tail_sigmas``, while another within ``rival_margin`` x (1 -
    best) of its correlation lies inside it: a ripple crest a wavelength from the true one that
    correlates a shade better (the prior's sigma is the window's: ``(window - window_margin_m) /
    window_sigmas``)."""
    sigma = (window - settings.window_margin_m) / settings.window_sigmas
    if sigma <= 0:
        return False
    best = modes[0][0].correlation
    limit = best - settings.rival_margin * (1.0 - best)
    far = [float(np.linalg.norm((where - start)[:2])) / sigma for _, _, where in modes]
    return far[0] > settings.prior_tail_sigmas and any(
        mode[0].correlation > limit and d <= settings.prior_tail_sigmas
        for mode, d in zip(modes[1:], far[1:], strict=True)
    )


def register_direct(A: Prepared, B: Prepared, search: Search, settings: DirectSettings) -> Registration:
    """Estimate ``T_a_b`` (pair B's left camera in pair A's, unrectified camera frames, as
    :func:`auvnav.vision.registration.register`) photometrically (module docstring), within the
    search :func:`plan_search` planned for the pairs' geometry."""
    ga, gb = A.geometry, B.geometry
    assert gb.surface is not None  # plan_search refuses pairs without one
    coarse = coarse_search(A, B, search, settings)
    if coarse is None:
        return rejected("overlap too small")
    if not coarse.peaks:
        return rejected(f"ambiguous ({coarse.candidates} peaks within the window)")
    # refine from every peak; peaks that converge together are one mode
    X_b = _points_of_pixels(gb.surface, gb.camera, np.array(gb.camera.cx), np.array(gb.camera.cy))
    modes: list[tuple[Refined, bool, FloatArray]] = []
    many = len(coarse.peaks) > 1
    first = (
        replace(settings, iterations=settings.candidate_iterations, stride=2 * settings.stride)
        if many
        else settings
    )
    lifted = lift(B, first.stride)
    T_rect, window = search.T_rect, search.window_m
    start = T_rect[:3, :3] @ X_b + T_rect[:3, 3]
    for T0, _, edge in coarse.peaks:
        fine = refine(A, B, T0, first, lifted)
        if fine is None:
            continue
        where = fine.T_a_b[:3, :3] @ X_b + fine.T_a_b[:3, 3]
        if np.linalg.norm((where - start)[:2]) > window:
            continue  # slid out of the search window: along a ridge, or to another place
        same = [
            k for k, (_, _, w) in enumerate(modes) if np.linalg.norm((w - where)[:2]) < settings.mode_radius_m
        ]
        if not same:
            modes.append((fine, edge, where))
        elif fine.correlation > modes[same[0]][0].correlation:
            modes[same[0]] = (fine, edge, where)
    if not modes:
        return rejected("no refinement stayed in the search window")
    modes.sort(key=lambda mode: -mode[0].correlation)
    fine, edge, _ = modes[0]
    if many:  # the winner refined to convergence
        fine = refine(A, B, fine.T_a_b, settings, lift(B, settings.stride)) or fine
    S = se3(ga.R1, np.zeros(3))
    T = se3_inverse(S) @ fine.T_a_b @ S
    if fine.correlation < settings.min_correlation:
        return rejected(f"poor correlation ({fine.correlation:.2f} < {settings.min_correlation})", T)
    widening = None
    if len(modes) > 1:
        second = modes[1][0].correlation
        limit = fine.correlation - settings.ambiguity_margin * (1.0 - fine.correlation)
        if nearer_rival(modes, start, window, settings):
            return rejected(
                f"ambiguous (correlation {fine.correlation:.3f} in the prior's tail, a look-alike nearer it)",
                T,
            )
        if second > limit:
            alike = [mode for mode in modes if mode[0].correlation > limit]
            widening = along_a_line(alike, start, window, settings)
            final = fine.T_a_b[:3, :3] @ X_b + fine.T_a_b[:3, 3]
            if widening is None or np.linalg.norm((final - alike[0][2])[:2]) > settings.mode_radius_m:
                return rejected(
                    f"ambiguous (correlation {fine.correlation:.3f}, another mode {second:.3f})", T
                )
    if edge:
        return rejected("best correlation at the edge of the search", T)
    if widening is not None:  # the middle of the look-alike positions, uncertain along them
        shift, extra = widening
        fine = replace(
            fine,
            T_a_b=se3(fine.T_a_b[:3, :3], fine.T_a_b[:3, 3] + shift),
            covariance=fine.covariance + extra,
            in_plane_covariance=fine.in_plane_covariance + extra[np.ix_(IN_PLANE, IN_PLANE)],
        )
        T = se3_inverse(S) @ fine.T_a_b @ S
    if fine.anisotropy > settings.max_anisotropy:
        return rejected(
            f"one-dimensional texture (the images fix one direction {fine.anisotropy:.0f} times better)", T
        )
    across, along = np.sqrt(np.maximum(np.linalg.eigvalsh(fine.in_plane_covariance[:2, :2]), 0.0))
    yaw_sigma = float(np.sqrt(fine.in_plane_covariance[3, 3]))
    if not (
        across <= settings.max_across_sigma_m
        and along <= settings.max_along_sigma_m
        and yaw_sigma <= settings.max_yaw_sigma_rad
    ):
        return rejected(
            f"pose too uncertain (sigma {across:.3f} m across, {along:.3f} m along, {np.degrees(yaw_sigma):.2f} deg)",
            T,
        )
    # (dt, dtheta) of the rectified frames into the camera frames: both rotate by R1^T.
    R1t = ga.R1.T
    G = np.zeros((6, 6))
    G[:3, :3] = G[3:, 3:] = R1t
    return Registration(
        True, "", T, G @ fine.covariance @ G.T, fine.pixels, fine.points, fine.normalised_residual
    )
