"""Stereo features: SIFT in the left image, found in the right along epipolar lines, triangulated with covariance.

Left keypoints are rectified (:func:`~auvnav.vision.camera.rectify_points`) and found in the rectified
right image by pyramidal Lucas-Kanade tracking (Bouguet 2001, "Pyramidal implementation of the affine
Lucas Kanade feature tracker", Intel; ``cv2.calcOpticalFlowPyrLK``), as stereo visual odometry does
(e.g. VINS-Fusion, Qin et al. 2019): a match must stay on its rectified row (within ``stereo_gate_px``),
return to its start when tracked back, and lie at a disparity that puts the point between
``min_range_m`` and ``max_range_m``. Tracking a patch finds the same surface point in both images to a
small fraction of a pixel, so the disparity (the range) is much better than two independent detections
would give, and a second SIFT pass over the right image is not needed: it halves the front end's time.
Both images are illumination-corrected first: the strobe's falloff and the vignetting differ between
the two views of a surface point, and a brightness gradient across the tracked patch would bias the
disparity (a tilt of the whole point cloud).
Edge-safe stereo: a patch that straddles a depth discontinuity (a ledge, a boulder's side) holds two
disparities and the tracker settles between them; such a match is found by tracking the window shifted
by half its side in four directions (:func:`disparity_spread`), dropped when the disparity moves by
more than ``edge_reject_px``, and otherwise given that spread as extra disparity noise.
Oriented texture (ripple crests, stripes): the tracker slides along it, in columns and rows alike,
and the forward-backward check cannot see it; each match's column is taken where the pair's common
row puts it (:func:`on_epipolar_line`), its disparity noise raised by how little of its window's
gradient runs across the columns, and a window of stripes along the rows is dropped.
Each match is triangulated with a first-order covariance from the keypoint noise
(:func:`~auvnav.vision.camera.triangulate`): the left keypoint's detection noise is common to both
images, the tracker's (measured from the rows of the matches, :func:`split_noise`) independent.

Results are cached per stereo pair in ``products/cache/vision/features/``, one file whose name carries
the left image's name and a hash of everything that determines them (both image files' size and
modification time, the calibration, the settings), so reruns do no work twice. A file holds only what
the points and covariances are made from, compressed: the four rectified coordinates of each match on a
1/256-pixel grid (the matches are put on that grid before they are triangulated, so a point read back
is the point computed, bit for bit), the two noise figures and the rectified geometry, and the
descriptors as :func:`~auvnav.vision.features.compand_descriptors` gives them (4 bits each), and each
match's further disparity noise (one byte), and the rectified, illumination-corrected left image at half the
size SIFT sees, as PNG (:func:`make_thumbnail`: what the direct registration aligns). On the check
dive at half scale in coastal water a pair's file holds about 84 KiB of features and 45 KiB of
thumbnail (median).
"""

from __future__ import annotations

import hashlib
import logging
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.errors import ConfigError
from auvnav.streams import atomic_write
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import (
    Rectification,
    StereoGeometry,
    check_image_size,
    rectify_images,
    rectify_points,
    rig_digest,
    triangulate,
)
from auvnav.vision.features import FeatureSettings, compand_descriptors, correct_illumination, detect

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
CACHE_VERSION = 12
#: Rectified coordinates are kept on a grid of 1/GRID_PER_PX pixel (0.004 px, well under the tracker's
#: few hundredths).
GRID_PER_PX = 256
#: Each match's disparity noise beyond the keypoints' is kept on a grid of 1/DISPARITY_SIGMA_PER_BYTE
#: pixel, one byte (up to 255/64 = 4 px: the edge term of any spread ``edge_reject_px`` keeps, and the
#: oriented texture's of any share above MIN_ACROSS_SHARE, 4.2 sigma_independent).
DISPARITY_SIGMA_PER_BYTE = 64
#: A match whose window has less than this share of its gradient energy across the columns
#: (:func:`on_epipolar_line`; 1 for texture alike in every direction) is dropped: stripes within about
#: 13 degrees of the rows, whose disparity the window barely sees.
MIN_ACROSS_SHARE = 0.1
#: A match's extra disparity noise, 1-sigma, per pixel of its disparity spread: the RMS disparity error of
#: the matches (with ``edge_reject_px`` 3.9) grows as about a third of their spread (0.035 px at spreads
#: below 0.1 px, 0.11 px at 0.2-0.35, 0.22 px at 0.5-1; ``benchmarks/bench_stereo_edges.py``).
EDGE_SIGMA_PER_SPREAD = 1.0 / 3.0
#: In noisy images (turbid water) the shifted windows' disparities scatter on flat ground too: a match
#: is dropped only when its spread exceeds ``edge_reject_px`` and this many times the lower quartile of
#: the pair's spreads (its tracking noise: 0.06-0.19 px on the check dive in clear water, 0.2-1.1 px in
#: turbid water, 0.09 px on scenes crowded with steps, where the 0.5 px default holds).
EDGE_NOISE_FACTOR = 5.0
#: zlib level of the thumbnails' PNG: on half-scale turbid check-dive images level 1 takes 1.6 ms for
#: 37.3 KiB, level 3 2.8 ms for 35.8 KiB, level 9 28 ms for 35 KiB, lossless WebP 26 ms for 29 KiB
#: (of a front end at about 0.18 CPU s a pair).
THUMBNAIL_PNG_LEVEL = 1
#: zlib level of the other blobs: level 1 takes 1.5 ms a pair for 56.9 KiB, level 6 2.8 ms for 56.1 KiB.
CACHE_ZLIB_LEVEL = 1
_MAGIC = b"AUVNAVF8"
# magic, matches, f, baseline, cx, cy, R1 (9), sigma common, sigma independent, thumbnail scales (2),
# bytes of each blob (geometry, descriptors, disparity sigmas, thumbnail)
_HEADER = struct.Struct("<8sI17dIIII")


@dataclass(frozen=True)
class StereoFeatures:
    """Triangulated stereo features of one pair.

    Parameters
    ----------
    uv_rect_px : ndarray, shape (N, 4)
        Each match's rectified coordinates ``(u_left, v_left, u_right, v_right)``, pixels, on the
        1/:data:`GRID_PER_PX` grid the points are triangulated from.
    p_cam_m : ndarray, shape (N, 3)
        Point in the left camera frame (x right, y down, z forward), metres.
    cov_cam_m2 : ndarray, shape (N, 3, 3)
        Covariance of each point, left camera frame, m^2.
    descriptors : ndarray, shape (N, 128), uint8
        The left keypoint's SIFT descriptor, companded to 4 bits
        (:func:`~auvnav.vision.features.compand_descriptors`).
    sigma_px : (float, float)
        The keypoint noise's parts common to and independent between the images (:func:`split_noise`).
    disparity_sigma_px : ndarray, shape (N,), optional
        Each match's disparity noise beyond the keypoints' (1-sigma, rectified pixels, on a
        1/:data:`DISPARITY_SIGMA_PER_BYTE` grid), in the point's covariance: a depth edge's,
        :data:`EDGE_SIGMA_PER_SPREAD` times the disparity spread over shifted windows
        (:func:`disparity_spread`), and an oriented texture's (:func:`on_epipolar_line`). None: zeros.
    thumbnail : bytes, optional
        The rectified, illumination-corrected left image, reduced (:func:`make_thumbnail`), as PNG:
        what the direct registration (:mod:`auvnav.vision.direct`) aligns. None: not kept.
    thumbnail_scale : (float, float)
        The thumbnail's width and height over the image's ((0, 0) without one).
    geometry : StereoGeometry, optional
        The rectified geometry the points were triangulated in.
    """

    uv_rect_px: FloatArray
    p_cam_m: FloatArray
    cov_cam_m2: FloatArray
    descriptors: NDArray[np.uint8]
    sigma_px: tuple[float, float] = (0.0, 0.0)
    disparity_sigma_px: FloatArray | None = None
    thumbnail: bytes | None = None
    thumbnail_scale: tuple[float, float] = (0.0, 0.0)
    geometry: StereoGeometry | None = None

    def __post_init__(self) -> None:
        n = len(self.p_cam_m)
        if self.disparity_sigma_px is None:
            object.__setattr__(self, "disparity_sigma_px", np.zeros(n))
        shapes = {
            "uv_rect_px": (np.shape(self.uv_rect_px), (n, 4)),
            "p_cam_m": (np.shape(self.p_cam_m), (n, 3)),
            "cov_cam_m2": (np.shape(self.cov_cam_m2), (n, 3, 3)),
            "descriptors": (np.shape(self.descriptors), (n, 128)),
            "disparity_sigma_px": (np.shape(self.disparity_sigma_px), (n,)),
        }
        for name, (found, want) in shapes.items():
            if found != want:
                raise ValueError(f"StereoFeatures.{name} must have shape {want}; found {found}")

    def __len__(self) -> int:
        return len(self.p_cam_m)

    def thumbnail_shape(self) -> tuple[int, int] | None:
        """The thumbnail's rows and columns from its PNG header (the image is not decoded), or None
        when there is none (or its header is not a PNG's, or gives a size no thumbnail has)."""
        if not self.thumbnail or self.thumbnail[:8] != _PNG_SIGNATURE or self.thumbnail[12:16] != b"IHDR":
            return None
        width, height = struct.unpack(">II", self.thumbnail[16:24])
        return (height, width) if min(width, height) >= THUMBNAIL_MIN_PX else None

    def thumbnail_image(self) -> NDArray[np.uint8] | None:
        """The decoded thumbnail (grey, uint8), or None."""
        if not self.thumbnail:
            return None
        return cv2.imdecode(np.frombuffer(self.thumbnail, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)


#: The smallest side of a thumbnail, pixels.
THUMBNAIL_MIN_PX = 8
#: The eight bytes that open a PNG file; its first chunk, IHDR, then gives the width and height.
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def make_thumbnail(rectified_left: NDArray[np.uint8], scale: float) -> tuple[bytes, tuple[float, float]]:
    """The illumination-corrected, rectified left image reduced by ``scale`` (area averaging), as PNG
    (compression level :data:`THUMBNAIL_PNG_LEVEL`), and its width and height over the image's."""
    h, w = rectified_left.shape
    size = (max(THUMBNAIL_MIN_PX, round(w * scale)), max(THUMBNAIL_MIN_PX, round(h * scale)))
    small = cv2.resize(rectified_left, size, interpolation=cv2.INTER_AREA)
    ok, encoded = cv2.imencode(".png", small, [cv2.IMWRITE_PNG_COMPRESSION, THUMBNAIL_PNG_LEVEL])
    if not ok:
        raise RuntimeError("could not encode a thumbnail as PNG")
    return encoded.tobytes(), (size[0] / w, size[1] / h)


def stereo_features(
    left: NDArray[np.uint8],
    right: NDArray[np.uint8],
    rig: StereoRig,
    rect: Rectification,
    settings: FeatureSettings,
) -> StereoFeatures:
    """Detect in the left image, find each keypoint in the right one along its epipolar line, and
    triangulate one stereo pair (grey uint8 images)."""
    flat_left, flat_right = correct_illumination(left), correct_illumination(right)
    kl = detect(flat_left, settings)
    rl = rectify_points(kl.uv_px, rig.left, rect.R1, rect.P1)
    flat = rectify_images(flat_left, flat_right, rig, rect)
    rr, ok, spread, share = track_right(rl, *flat, rect, settings)
    scale = settings.scale_for(left.shape[1])
    sigma = split_noise(rr[ok, 1] - rl[ok, 1], settings.sigma_px / scale)
    uv = np.round(np.column_stack([rl[ok], rr[ok]]) * GRID_PER_PX) / GRID_PER_PX
    # the disparity's noise beyond the keypoints' (2 sigma_independent^2): a depth edge's, and the
    # oriented texture's, which makes it 2 sigma_independent^2 / share
    extra = np.hypot(
        EDGE_SIGMA_PER_SPREAD * spread[ok], sigma[1] * np.sqrt(np.maximum(2.0 / share[ok] - 2.0, 0.0))
    )
    extra = _sigma_bytes(extra) / DISPARITY_SIGMA_PER_BYTE  # as the cache keeps it
    p, cov = triangulate(uv[:, :2], uv[:, 2:], rect, *sigma, sigma_disparity_px=extra)
    thumb, thumb_scale = None, (0.0, 0.0)
    if settings.thumbnail_scale > 0:
        thumb, thumb_scale = make_thumbnail(flat[0], scale * settings.thumbnail_scale)
    geometry = StereoGeometry(rect.f_px, rect.cx_px, rect.cy_px, rect.baseline_m, rect.R1)
    descriptors = compand_descriptors(kl.descriptors[ok])
    return StereoFeatures(uv, p, cov, descriptors, sigma, extra, thumb, thumb_scale, geometry)


def track_right(
    rl: FloatArray,
    left_rect: NDArray[np.uint8],
    right_rect: NDArray[np.uint8],
    rect: Rectification,
    settings: FeatureSettings,
) -> tuple[FloatArray, NDArray[np.bool_], FloatArray, FloatArray]:
    """Where rectified left keypoints ``rl`` (N, 2) lie in the rectified right image, by pyramidal
    Lucas-Kanade, which are trusted, how far each one's disparity moves when its window is shifted
    (:func:`disparity_spread`, pixels; 0 where not trusted), and each window's share of gradient
    energy across the columns (:func:`on_epipolar_line`; 1 where not trusted).

    The scene's dominant disparity comes from phase correlation of the two images (:func:`image_shift`);
    a first pass on a sample of the keypoints, from that disparity, finds the scene's median disparity
    (over the plausible matches only); every keypoint is then tracked from that disparity, and tracked
    back. A match is kept when both passes converge, the round trip returns within
    ``max_round_trip_px``, it stays within ``stereo_gate_px`` of its row and its disparity puts the
    point between ``min_range_m`` and ``max_range_m``, and, edge-safe stereo, its disparity moves by at
    most ``edge_reject_px`` (or :data:`EDGE_NOISE_FACTOR` times the lower quartile over the pair's
    matches, whichever is larger) when the window is shifted by half its side (a patch across a depth
    discontinuity does not). The column of each match is then the one on the pair's common row
    (:func:`on_epipolar_line`: Lucas-Kanade drifts along oriented texture, ripple crests), and a match
    whose window has less than :data:`MIN_ACROSS_SHARE` of its gradient energy across the columns
    (stripes along the rows: no disparity to measure) is dropped.
    """
    n = len(rl)
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return np.zeros((0, 2)), ok, np.zeros(0), np.ones(0)
    scale = settings.scale_for(left_rect.shape[1])
    window = settings.lk_window_for(left_rect.shape[1])
    lk = {
        "winSize": (window, window),
        "criteria": (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01),
    }
    fb_m = rect.f_px * rect.baseline_m

    def plausible(p: NDArray[np.float32], q: NDArray[np.float32]) -> NDArray[np.bool_]:
        """On the row (within the gate), at a disparity that puts the point in the range bounds."""
        disparity = p[:, 0, 0] - q[:, 0, 0]
        on_row = np.abs(q[:, 0, 1] - p[:, 0, 1]) * scale <= settings.stereo_gate_px
        return on_row & (disparity > fb_m / settings.max_range_m) & (disparity < fb_m / settings.min_range_m)

    p0 = np.ascontiguousarray(rl, dtype=np.float32).reshape(-1, 1, 2)
    sample = np.ascontiguousarray(p0[:: max(1, n // 200)])
    # Tracked from zero disparity through a deep pyramid instead, many samples locked on to the wrong
    # place (the top levels are a few windows wide), and their median could be far off: then no
    # keypoint was tracked (10 of 12 full-size views of a flat floor tried, 2 of 12 at half size).
    flags = cv2.OPTFLOW_USE_INITIAL_FLOW
    guess = sample.copy()
    guess[:, 0, 0] += image_shift(left_rect, right_rect)[0]
    q, st, _ = cv2.calcOpticalFlowPyrLK(left_rect, right_rect, sample, guess, maxLevel=3, flags=flags, **lk)
    vote = (st[:, 0] == 1) & plausible(sample, q)
    if not vote.any():
        return np.zeros((n, 2)), ok, np.zeros(n), np.ones(n)
    guess = p0.copy()
    guess[:, 0, 0] -= float(np.median(sample[vote, 0, 0] - q[vote, 0, 0]))
    q, st, _ = cv2.calcOpticalFlowPyrLK(left_rect, right_rect, p0, guess, maxLevel=2, flags=flags, **lk)
    back, st_back, _ = cv2.calcOpticalFlowPyrLK(
        right_rect, left_rect, q, p0.copy(), maxLevel=2, flags=flags, **lk
    )
    fb = scale * np.linalg.norm(back[:, 0] - p0[:, 0], axis=1)
    ok = (st[:, 0] == 1) & (st_back[:, 0] == 1) & (fb <= settings.max_round_trip_px) & plausible(p0, q)
    if settings.edge_reject_px > 0:
        spread = np.full(n, np.inf)
        spread[ok] = disparity_spread(p0[ok], q[ok], left_rect, right_rect, window)
        # relative to the image's own tracking noise: most matches lie on one surface
        finite = spread[ok][np.isfinite(spread[ok])]
        noise = EDGE_NOISE_FACTOR * float(np.percentile(finite, 25)) * scale if len(finite) else 0.0
        ok &= spread * scale <= max(settings.edge_reject_px, noise)
    else:
        spread = np.zeros(n)
    right, share = q[:, 0].astype(float), np.ones(n)
    if ok.any():
        right[:, 0], share = on_epipolar_line(p0[:, 0], right, ok, left_rect, window)
        ok &= share >= MIN_ACROSS_SHARE
    return right, ok, np.where(ok, spread, 0.0), np.where(ok, share, 1.0)


def on_epipolar_line(
    p: NDArray[np.float32], q: FloatArray, ok: NDArray[np.bool_], left: NDArray[np.uint8], window: int
) -> tuple[FloatArray, FloatArray]:
    """The right columns of matches ``p`` -> ``q`` (N, 2, rectified pixels) given that each lies on the
    pair's common row offset (the median over the trusted matches ``ok``: 0 for a perfect
    rectification), and each window's share of its gradient energy across the columns (1 for texture
    alike in every direction, 0 for stripes along the rows).

    Lucas-Kanade finds a 2-D displacement whose covariance is the noise over the window's structure
    tensor ``G = sum [gx^2, gx gy; gx gy, gy^2]`` (Lucas and Kanade 1981; Shi and Tomasi 1994, "Good
    features to track", CVPR). Along an oriented texture (ripple crests) it drifts along the texture,
    in columns and rows alike. The row is known, so the column is the Gaussian conditional of the two:
    ``x + (G01 / G00) (y - y0)``, whose variance, noise / ``G00``, has none of the drift; over a window
    of texture alike in every direction it is noise / (``trace G`` / 2), and the share ``2 G00 /
    trace G`` says how much larger it is elsewhere."""
    img = left.astype(np.float32)
    gx = cv2.Scharr(img, cv2.CV_32F, 1, 0)
    gy = cv2.Scharr(img, cv2.CV_32F, 0, 1)
    h, w = img.shape
    col = np.clip(np.rint(p[:, 0]).astype(np.intp), 0, w - 1)
    row = np.clip(np.rint(p[:, 1]).astype(np.intp), 0, h - 1)
    a, b, c = (
        cv2.boxFilter(g, -1, (window, window), normalize=False)[row, col].astype(float)
        for g in (gx * gx, gx * gy, gy * gy)
    )
    dy = q[:, 1] - p[:, 1]
    columns = q[:, 0] + b / np.maximum(a, 1e-12) * (dy - float(np.median(dy[ok])))
    return columns, 2.0 * a / np.maximum(a + c, 1e-12)


def disparity_spread(
    p: NDArray[np.float32],
    q: NDArray[np.float32],
    left: NDArray[np.uint8],
    right: NDArray[np.uint8],
    window: int,
) -> FloatArray:
    """How much the disparity of matches ``p`` -> ``q`` (N, 1, 2) changes when the tracked window is
    shifted by half its side left, right, up and down (pixels: the largest change; infinite when the
    tracker loses a shifted window, which is skipped where it would leave the image). The keypoint lies
    in all five windows; a patch that straddles a depth discontinuity has shifted windows on either
    side of it, at the two depths' disparities, and one on a single surface has the same disparity in
    all of them (the "shiftable windows" of stereo matching: Bobick and Intille 1999, "Large occlusion
    stereo", IJCV 33(3); Hirschmueller, Innocent and Garibaldi 2002, "Real-time correlation-based
    stereo vision with reduced border errors", IJCV 47(1-3))."""
    lk = {
        "winSize": (window, window),
        "criteria": (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.01),
    }
    h = window // 2
    if len(p) == 0:  # OpenCV refuses empty point sets
        return np.zeros(0)
    # the four shifted windows of every match tracked in one call (each point is tracked on its own;
    # one call computes the image derivatives once, not four times)
    shifts = np.array([(-h, 0), (h, 0), (0, -h), (0, h)], dtype=np.float32)[:, None, None, :]
    ps = np.ascontiguousarray((p[None] + shifts).reshape(-1, 1, 2))
    qs, st, _ = cv2.calcOpticalFlowPyrLK(
        left,
        right,
        ps,
        np.ascontiguousarray((q[None] + shifts).reshape(-1, 1, 2)),
        maxLevel=0,
        flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        **lk,
    )
    ps, qs, lost = ps.reshape(4, -1, 2), qs.reshape(4, -1, 2), st.reshape(4, -1) != 1
    change = np.abs(ps[..., 0] - qs[..., 0] - (p[:, 0, 0] - q[:, 0, 0])) + np.abs(
        qs[..., 1] - ps[..., 1] - (q[:, 0, 1] - p[:, 0, 1])
    )
    # a shifted window that would leave the image is skipped
    inside = (ps[..., 0] >= h) & (ps[..., 0] < left.shape[1] - h)
    inside &= (ps[..., 1] >= h) & (ps[..., 1] < left.shape[0] - h)
    return np.where(inside, np.where(lost, np.inf, change), 0.0).max(axis=0)


def image_shift(a: NDArray[np.uint8], b: NDArray[np.uint8], width_px: int = 170) -> tuple[float, float]:
    """The translation ``(dx, dy)`` that best maps image ``a`` onto image ``b``, pixels, by phase
    correlation (Kuglin and Hines 1975; ``cv2.phaseCorrelate`` with a Hann window) of the two reduced
    to about ``width_px`` wide: for a rectified stereo pair, minus the scene's dominant disparity."""
    f = max(1, a.shape[1] // width_px)
    small = [
        cv2.resize(x, (x.shape[1] // f, x.shape[0] // f), interpolation=cv2.INTER_AREA).astype(np.float32)
        for x in (a, b)
    ]
    window = cv2.createHanningWindow(small[0].shape[::-1], cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(small[0], small[1], window)
    return dx * a.shape[1] / small[0].shape[1], dy * a.shape[0] / small[0].shape[0]


def split_noise(dy_px: FloatArray, total: float) -> tuple[float, float]:
    """Split a keypoint's position noise ``total`` into parts common to and independent between the images.

    The rectified row difference of stereo matches sees only the independent part (``var(dy) =
    2 sigma_i^2``); it is measured robustly (1.4826 MAD) and the rest of ``total`` is common.
    Returns ``(sigma_common, sigma_independent)``, in the unit of ``dy_px`` and ``total`` (pixels).
    """
    if len(dy_px) < 10:
        return total * np.sqrt(0.5), total * np.sqrt(0.5)
    mad = float(np.median(np.abs(dy_px - np.median(dy_px))))
    independent = min(1.4826 * mad / np.sqrt(2.0), total)
    return float(np.sqrt(total**2 - independent**2)), independent


#: A deeper image (16-bit, float) is put on 8 bits with this quantile of its grey levels at 255.
GREY_TOP_QUANTILE = 0.999


def read_grey(path: Path, bayer: str | None = None) -> NDArray[np.uint8] | None:
    """An image as 8-bit grey, or None (with a warning naming it) when missing or unreadable.

    The codec reduces colour to luminance (``cv2.IMREAD_GRAYSCALE``); a raw image, from a camera whose
    colour filter ``bayer`` is given (:attr:`auvnav.vehicle.CameraModel.bayer`), is demosaiced to
    luminance (OpenCV's bilinear ``COLOR_Bayer*2GRAY``). A deeper image (16-bit, float) is then scaled
    by its own brightest grey levels (:data:`GREY_TOP_QUANTILE` at 255), not by its container: a
    machine-vision camera writes 10- or 12-bit data in 16-bit files (ROS ``mono16``), which OpenCV's
    own reduction to 8 bits (the high byte) would leave at 4 to 16 grey levels. The scale does not
    matter beyond that: :func:`~auvnav.vision.features.correct_illumination` divides each image by its
    own low-pass.

    Raises :class:`~auvnav.errors.ConfigError` when a raw camera's image is not a one-channel 8- or
    16-bit mosaic.
    """
    if not path.is_file():
        log.warning("%s: image missing; pair skipped", path)
        return None
    flags = cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH if bayer is None else cv2.IMREAD_UNCHANGED
    image = cv2.imread(str(path), flags)
    if image is None:
        log.warning("%s: not a readable image (corrupt or unknown format); pair skipped", path)
        return None
    if bayer is not None:
        if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
            channels = image.shape[2] if image.ndim == 3 else 1
            raise ConfigError(
                f"{path}: vehicle.yaml gives its camera a Bayer filter ({bayer}), but the image is not a "
                f"raw mosaic (one channel of 8 or 16 bits; found {channels} of {image.dtype})"
            )
        image = cv2.cvtColor(image, _BAYER_TO_GREY[bayer])
    if image.dtype == np.uint8:
        return image
    if image.dtype != np.uint16:  # floats: no light below zero, none in a NaN
        image = np.maximum(np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0), 0)
    top = float(np.quantile(image[:: max(1, image.shape[0] // 128)], GREY_TOP_QUANTILE))
    if top <= 0:
        log.warning("%s: image has no light (every grey level 0 or below); pair skipped", path)
        return None
    return cv2.convertScaleAbs(image, alpha=255.0 / top)  # rounded, saturated at 255


#: OpenCV's demosaicing to luminance for each colour filter (OpenCV >= 4.5 names them as cameras do).
_BAYER_TO_GREY = {
    "rggb": cv2.COLOR_BayerRGGB2GRAY,
    "bggr": cv2.COLOR_BayerBGGR2GRAY,
    "grbg": cv2.COLOR_BayerGRBG2GRAY,
    "gbrg": cv2.COLOR_BayerGBRG2GRAY,
}


def cache_path(cache_dir: Path, left: Path, right: Path, rig: StereoRig, settings: FeatureSettings) -> Path:
    """The cache file of a pair: keyed by image name, file stamps, calibration and settings."""
    h = hashlib.sha1()
    for p in (left, right):
        st = os.stat(p)
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    h.update(f"{CACHE_VERSION}:{rig_digest(rig)}:{settings.key()}".encode())
    stem = left.with_suffix("").name
    return cache_dir / f"{left.parent.name}_{stem}_{h.hexdigest()[:16]}.feat"


def _sigma_bytes(sigma_px: FloatArray) -> NDArray[np.uint8]:
    """Disparity sigmas on the cache's one-byte grid (1/:data:`DISPARITY_SIGMA_PER_BYTE` px, saturating)."""
    return np.minimum(np.round(sigma_px * DISPARITY_SIGMA_PER_BYTE), 255).astype(np.uint8)


def write_features(features: StereoFeatures, rect: Rectification, path: Path) -> None:
    """Write a pair's features to a cache file (atomically; the module docstring says what it holds)."""
    grid = np.round(features.uv_rect_px * GRID_PER_PX).astype("<i4")
    # The bytes of each coordinate together (their high bytes alike): a third smaller once compressed.
    geometry = zlib.compress(
        grid.view(np.uint8).reshape(len(grid), 4, 4).transpose(1, 2, 0).tobytes(), CACHE_ZLIB_LEVEL
    )
    q = features.descriptors
    descriptors = zlib.compress((q[:, ::2] << 4 | q[:, 1::2]).astype(np.uint8).tobytes(), CACHE_ZLIB_LEVEL)
    assert features.disparity_sigma_px is not None  # StereoFeatures fills it
    sigmas = zlib.compress(_sigma_bytes(features.disparity_sigma_px).tobytes(), CACHE_ZLIB_LEVEL)
    thumb = features.thumbnail or b""
    header = _HEADER.pack(
        _MAGIC,
        len(features),
        rect.f_px,
        rect.baseline_m,
        rect.cx_px,
        rect.cy_px,
        *np.asarray(rect.R1, dtype=float).ravel(),
        *features.sigma_px,
        *features.thumbnail_scale,
        len(geometry),
        len(descriptors),
        len(sigmas),
        len(thumb),
    )
    atomic_write(path, lambda p: p.write_bytes(header + geometry + descriptors + sigmas + thumb))


def read_features(path: Path | str) -> StereoFeatures:
    """A pair's features from a cache file written by :func:`write_features`: the points and their
    covariances triangulated again from the stored matches (bit for bit the ones computed)."""
    data = Path(path).read_bytes()
    if len(data) < _HEADER.size or not data.startswith(_MAGIC):
        raise ValueError("not a feature cache file of this version")
    _, n, f, b, cx, cy, *rest = _HEADER.unpack_from(data)
    R1, (sc, si), thumb_scale = np.array(rest[:9]).reshape(3, 3), rest[9:11], tuple(rest[11:13])
    ng, nd, ne, nt = rest[13:17]
    start = _HEADER.size
    expected = start + ng + nd + ne + nt
    if len(data) != expected:
        raise ValueError(f"truncated feature cache file ({len(data)} bytes, expected {expected})")
    try:
        grid = np.frombuffer(zlib.decompress(data[start : start + ng]), dtype=np.uint8)
        packed = np.frombuffer(zlib.decompress(data[start + ng : start + ng + nd]), dtype=np.uint8)
        sigma_q = np.frombuffer(zlib.decompress(data[start + ng + nd : start + ng + nd + ne]), dtype=np.uint8)
    except zlib.error as err:
        raise ValueError(f"corrupt feature cache file ({err})") from None
    if grid.size != 16 * n or packed.size != 64 * n or sigma_q.size != n:
        raise ValueError("corrupt feature cache file (sizes disagree with its header)")
    uv = grid.reshape(4, 4, n).transpose(2, 0, 1).copy().view("<i4").reshape(n, 4) / GRID_PER_PX
    desc = np.empty((n, 128), dtype=np.uint8)
    desc[:, ::2] = packed.reshape(n, 64) >> 4
    desc[:, 1::2] = packed.reshape(n, 64) & 15
    extra = sigma_q / DISPARITY_SIGMA_PER_BYTE
    geometry = StereoGeometry(f, cx, cy, b, R1)
    p, cov = triangulate(uv[:, :2], uv[:, 2:], geometry, sc, si, sigma_disparity_px=extra)
    thumb = data[expected - nt :] if nt else None
    return StereoFeatures(
        uv, p, cov, desc, (sc, si), extra, thumb, thumb_scale if nt else (0.0, 0.0), geometry
    )


def pair_features(
    left_path: Path,
    right_path: Path,
    rig: StereoRig,
    rect: Rectification,
    settings: FeatureSettings,
    cache_dir: Path | None,
) -> StereoFeatures | None:
    """Stereo features of a pair of image files, from the cache when present.

    Returns None (with a warning naming the file) for a missing or corrupt image. An image whose size
    differs from the calibration raises :class:`~auvnav.errors.ConfigError`.
    """
    cached = None
    if cache_dir is not None and left_path.is_file() and right_path.is_file():
        cached = cache_path(cache_dir, left_path, right_path, rig, settings)
        if cached.is_file():
            try:
                return read_features(cached)
            except (OSError, ValueError) as err:
                log.warning("%s: unreadable feature cache (%s); recomputing", cached, err)
    left, right = read_grey(left_path, rig.left.bayer), read_grey(right_path, rig.right.bayer)
    if left is None or right is None:
        return None
    check_image_size(rig.left, left.shape, str(left_path))
    check_image_size(rig.right, right.shape, str(right_path))
    feats = stereo_features(left, right, rig, rect, settings)
    if cached is not None:
        write_features(feats, rect, cached)
    return feats
