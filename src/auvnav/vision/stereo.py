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
Each match is triangulated with a first-order covariance from the keypoint noise
(:func:`~auvnav.vision.camera.triangulate`): the left keypoint's detection noise is common to both
images, the tracker's (measured from the rows of the matches, :func:`split_noise`) independent.

Results are cached per stereo pair in ``products/cache/vision/features/``, one ``.npy`` file of records (one
read, a quarter of a zip archive's time: the verification reads them again and again), whose name
carries the left image's name and a hash of everything that determines them (both image files' size and
modification time, the calibration, the settings), so reruns do no work twice. Pixel positions and
covariances are stored in single precision, far finer than their noise.
"""

from __future__ import annotations

import hashlib
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.streams import atomic_write
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import (
    Rectification,
    check_image_size,
    rectify_images,
    rectify_points,
    rig_digest,
    triangulate,
)
from auvnav.vision.features import FeatureSettings, correct_illumination, detect

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
CACHE_VERSION = 4
_CACHE_RECORD = np.dtype(
    [("uv", "<f4", (2,)), ("p", "<f8", (3,)), ("cov", "<f4", (3, 3)), ("desc", "u1", (128,))]
)


@dataclass(frozen=True)
class StereoFeatures:
    """Triangulated stereo features of one pair.

    Parameters
    ----------
    uv_left_px : ndarray, shape (N, 2)
        Keypoint in the raw left image, pixels.
    p_cam_m : ndarray, shape (N, 3)
        Point in the left camera frame (x right, y down, z forward), metres.
    cov_cam_m2 : ndarray, shape (N, 3, 3)
        Covariance of each point, left camera frame, m^2.
    descriptors : ndarray, shape (N, 128), uint8
        The left keypoint's SIFT descriptor.
    """

    uv_left_px: FloatArray
    p_cam_m: FloatArray
    cov_cam_m2: FloatArray
    descriptors: NDArray[np.uint8]

    def __post_init__(self) -> None:
        n = len(self.p_cam_m)
        shapes = {
            "uv_left_px": (np.shape(self.uv_left_px), (n, 2)),
            "p_cam_m": (np.shape(self.p_cam_m), (n, 3)),
            "cov_cam_m2": (np.shape(self.cov_cam_m2), (n, 3, 3)),
            "descriptors": (np.shape(self.descriptors), (n, 128)),
        }
        for name, (found, want) in shapes.items():
            if found != want:
                raise ValueError(f"StereoFeatures.{name} must have shape {want}; found {found}")

    def __len__(self) -> int:
        return len(self.p_cam_m)


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
    rr, ok = track_right(rl, *flat, rect, settings)
    scale = settings.scale_for(left.shape[1])
    sigma_common, sigma_independent = split_noise(rr[ok, 1] - rl[ok, 1], settings.sigma_px / scale)
    p, cov = triangulate(rl[ok], rr[ok], rect, sigma_common, sigma_independent)
    return StereoFeatures(kl.uv_px[ok], p, cov, kl.descriptors[ok])


def track_right(
    rl: FloatArray,
    left_rect: NDArray[np.uint8],
    right_rect: NDArray[np.uint8],
    rect: Rectification,
    settings: FeatureSettings,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Where rectified left keypoints ``rl`` (N, 2) lie in the rectified right image, by pyramidal
    Lucas-Kanade, and which are trusted.

    The scene's dominant disparity comes from phase correlation of the two images (:func:`image_shift`);
    a first pass on a sample of the keypoints, from that disparity, finds the scene's median disparity
    (over the plausible matches only); every keypoint is then tracked from that disparity, and tracked
    back. A match is kept when both passes converge, the round trip returns within
    ``max_round_trip_px``, it stays within ``stereo_gate_px`` of its row and its disparity puts the
    point between ``min_range_m`` and ``max_range_m``. Returns the right positions (N, 2) and the mask.
    """
    n = len(rl)
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return np.zeros((0, 2)), ok
    scale = settings.scale_for(left_rect.shape[1])
    window = 2 * round(settings.lk_window_px / scale / 2) + 1
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
        return np.zeros((n, 2)), ok
    guess = p0.copy()
    guess[:, 0, 0] -= float(np.median(sample[vote, 0, 0] - q[vote, 0, 0]))
    q, st, _ = cv2.calcOpticalFlowPyrLK(left_rect, right_rect, p0, guess, maxLevel=2, flags=flags, **lk)
    back, st_back, _ = cv2.calcOpticalFlowPyrLK(
        right_rect, left_rect, q, p0.copy(), maxLevel=2, flags=flags, **lk
    )
    fb = scale * np.linalg.norm(back[:, 0] - p0[:, 0], axis=1)
    ok = (st[:, 0] == 1) & (st_back[:, 0] == 1) & (fb <= settings.max_round_trip_px) & plausible(p0, q)
    return q[:, 0].astype(float), ok


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


def read_grey(path: Path) -> NDArray[np.uint8] | None:
    """An image as 8-bit grey, or None (with a warning naming it) when missing or unreadable."""
    if not path.is_file():
        log.warning("%s: image missing; pair skipped", path)
        return None
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        log.warning("%s: not a readable image (corrupt or unknown format); pair skipped", path)
        return None
    return image


def cache_path(cache_dir: Path, left: Path, right: Path, rig: StereoRig, settings: FeatureSettings) -> Path:
    """The cache file of a pair: keyed by image name, file stamps, calibration and settings."""
    h = hashlib.sha1()
    for p in (left, right):
        st = os.stat(p)
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    h.update(f"{CACHE_VERSION}:{rig_digest(rig)}:{settings.key()}".encode())
    stem = left.with_suffix("").name
    return cache_dir / f"{left.parent.name}_{stem}_{h.hexdigest()[:16]}.npy"


def write_features(features: StereoFeatures, path: Path) -> None:
    """Write a pair's features to a cache file (atomically)."""
    records = np.empty(len(features), dtype=_CACHE_RECORD)
    records["uv"] = features.uv_left_px
    records["p"] = features.p_cam_m
    records["cov"] = features.cov_cam_m2
    records["desc"] = features.descriptors

    def write(p: Path) -> None:
        with open(p, "wb") as fh:
            np.save(fh, records)

    atomic_write(path, write)


def read_features(path: Path | str) -> StereoFeatures:
    """A pair's features from a cache file written by :func:`write_features`."""
    records = np.load(path)
    if records.dtype != _CACHE_RECORD:
        raise ValueError(f"not a feature cache file (records {records.dtype})")
    return StereoFeatures(
        records["uv"].astype(float),
        np.ascontiguousarray(records["p"]),
        records["cov"].astype(float),
        np.ascontiguousarray(records["desc"]),
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
    left, right = read_grey(left_path), read_grey(right_path)
    if left is None or right is None:
        return None
    check_image_size(rig.left, left.shape, str(left_path))
    check_image_size(rig.right, right.shape, str(right_path))
    feats = stereo_features(left, right, rig, rect, settings)
    if cached is not None:
        write_features(feats, cached)
    return feats
