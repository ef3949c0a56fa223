"""Stereo features: SIFT in both images, matches along epipolar lines, triangulated points with covariance.

Left and right keypoints are rectified (:func:`~auvnav.vision.camera.rectify_points`) and matched by
descriptor among the candidates on the same rectified row (within ``stereo_gate_px``) at a disparity
that puts the point between ``min_range_m`` and ``max_range_m``; each match is triangulated with a
first-order covariance from the keypoint noise (:func:`~auvnav.vision.camera.triangulate`).

Results are cached per stereo pair in ``products/vision/features/`` as ``.npz`` files whose name
carries the left image's name and a hash of everything that determines them (both image files' size and
modification time, the calibration, the settings), so reruns do no work twice.
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
from auvnav.vision.camera import Rectification, check_image_size, rectify_points, rig_digest, triangulate
from auvnav.vision.features import FeatureSettings, detect, match_candidates

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
CACHE_VERSION = 1


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
    """Detect, match along epipolar lines and triangulate one stereo pair (grey uint8 images)."""
    kl, kr = detect(left, settings), detect(right, settings)
    rl = rectify_points(kl.uv_px, rig.left, rect.R1, rect.P1)
    rr = rectify_points(kr.uv_px, rig.right, rect.R2, rect.P2)
    ci, cj = epipolar_candidates(rl, rr, rect, settings)
    il, ir = match_candidates(kl.descriptors, kr.descriptors, ci, cj, ratio=settings.ratio)
    scale = settings.scale_for(left.shape[1])
    sigma_common, sigma_independent = split_noise(rl[il, 1] - rr[ir, 1], settings.sigma_px / scale)
    p, cov = triangulate(rl[il], rr[ir], rect, sigma_common, sigma_independent)
    return StereoFeatures(kl.uv_px[il], p, cov, kl.descriptors[il])


def epipolar_candidates(
    rl: FloatArray, rr: FloatArray, rect: Rectification, settings: FeatureSettings
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pairs (left, right) of rectified keypoints on the same row (within the gate) at a plausible
    disparity; found by sorting the right keypoints by row, so the work grows with the pairs found."""
    if len(rl) == 0 or len(rr) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    order = np.argsort(rr[:, 1])
    y_sorted = rr[order, 1]
    lo = np.searchsorted(y_sorted, rl[:, 1] - settings.stereo_gate_px, side="right")
    hi = np.searchsorted(y_sorted, rl[:, 1] + settings.stereo_gate_px, side="left")
    counts = hi - lo
    ci = np.repeat(np.arange(len(rl)), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    cj = order[np.repeat(lo, counts) + offsets]
    fb = rect.f_px * rect.baseline_m
    d = rl[ci, 0] - rr[cj, 0]
    ok = (d > fb / settings.max_range_m) & (d < fb / settings.min_range_m)
    return ci[ok], cj[ok]


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
    return cache_dir / f"{left.parent.name}_{stem}_{h.hexdigest()[:16]}.npz"


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
                with np.load(cached) as z:
                    return StereoFeatures(z["uv"], z["p"], z["cov"], z["desc"])
            except (OSError, ValueError, KeyError) as err:
                log.warning("%s: unreadable feature cache (%s); recomputing", cached, err)
    left, right = read_grey(left_path), read_grey(right_path)
    if left is None or right is None:
        return None
    check_image_size(rig.left, left.shape, str(left_path))
    check_image_size(rig.right, right.shape, str(right_path))
    feats = stereo_features(left, right, rig, rect, settings)
    if cached is not None:

        def write(p: Path) -> None:
            with open(p, "wb") as fh:
                np.savez(
                    fh, uv=feats.uv_left_px, p=feats.p_cam_m, cov=feats.cov_cam_m2, desc=feats.descriptors
                )

        atomic_write(cached, write)
    return feats
