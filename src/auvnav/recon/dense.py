"""Dense stereo: semi-global matching of a rectified, illumination-corrected pair, depth and its uncertainty.

Each pair is rectified (:func:`~auvnav.vision.camera.rectify_images`, the loop stage's geometry), reduced
to the matching scale (half the 1360 px Sirius width by default, as the loop stage's SIFT: images
already that size are matched as they are), corrected for the strobe's falloff
(:func:`~auvnav.vision.features.correct_illumination`) and matched by OpenCV's semi-global block matching
(Hirschmuller 2008, "Stereo processing by semiglobal matching and mutual information", IEEE TPAMI 30(2):
``cv2.StereoSGBM``), with its left-right consistency check (``disp12MaxDiff``), uniqueness test,
speckle filter and parabolic subpixel refinement (disparities in 1/16 pixel). The disparity search
spans the plausible ranges ``min_range_m`` to ``max_range_m``.

A pixel's depth is ``Z = f b / d`` in the rectified left camera; its 1-sigma is
``sigma_Z = Z^2 sigma_d / (f b)``, first order in a disparity error ``sigma_d`` (0.2 matching pixels by
default: the RMS per-pixel depth error of SGBM on the simulator's half-scale pairs at 2 m altitude,
9 mm at 1.65 m range, ``benchmarks/bench_recon.py``).

A pair whose matching leaves fewer than ``min_valid_fraction`` of its pixels (a black or saturated
image, a floor out of range, images that are not a stereo pair) has failed and is skipped, with a
warning naming its images. So has a pair whose seafloor comes nearer than ``min_range_m``: its true
disparities lie beyond the search, and SGBM's matches pile up at the search's limit while the rest are
wrong too (on the check dive, where the vehicle passes 0.65 m over a mound, such pairs' depths are
decimetres off); more than ``max_saturated_fraction`` of the matches within a pixel of the limit fails
the pair, and in the pairs kept the few such matches are dropped. Results are cached per pair (``products/cache/recon/dense/``), keyed by the
image files' names and stamps, the calibration and the settings, so a rerun does no work twice.
"""

from __future__ import annotations

import hashlib
import io
import logging
import os
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.streams import atomic_write
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import Rectification, check_image_size, rectify_images, rig_digest
from auvnav.vision.features import correct_illumination
from auvnav.vision.stereo import read_grey

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: Half the width of the Sirius cameras (1360 px, :mod:`auvnav.sim.camera` cites it): the default
#: matching width, as the loop stage's SIFT (:data:`auvnav.vision.features.DEFAULT_FEATURE_WIDTH_PX`).
DEFAULT_DENSE_WIDTH_PX = 680
#: SGBM's disparities are fixed point with 4 fractional bits.
SUBPIXEL = 16
CACHE_VERSION = 4


@dataclass(frozen=True)
class DenseSettings:
    """How pairs are matched.

    Parameters
    ----------
    scale : float or None
        Matching scale relative to the image files (0 < scale <= 1); None: to
        ``DEFAULT_DENSE_WIDTH_PX`` wide (never enlarged).
    min_range_m, max_range_m : float
        Plausible distances of the seafloor from the camera: bound the disparity search.
    block_px : int
        SGBM's matching block (odd), matching pixels.
    uniqueness_pct : int
        SGBM's uniqueness margin, percent.
    lr_max_diff_px : int
        Largest left-right disparity disagreement kept (SGBM's ``disp12MaxDiff``), matching pixels.
    speckle_window_px : int
        Disparity blobs smaller than this are removed (0: no speckle filter).
    sigma_disparity_px : float
        1-sigma disparity error of a pixel, matching pixels.
    min_valid_fraction : float
        A pair with fewer valid pixels has failed.
    max_saturated_fraction : float
        A pair with more of its matches within a pixel of the disparity search's upper limit (the
        seafloor nearer than ``min_range_m``) has failed.
    range_ratio : float
        Matches farther than this many times the pair's median range, or nearer than its inverse, are
        dropped (mismatches on dark corners and edges; the seafloor's relief under a camera 2 m up
        stays well inside).
    """

    scale: float | None = None
    min_range_m: float = 1.0
    max_range_m: float = 8.0
    block_px: int = 5
    uniqueness_pct: int = 10
    lr_max_diff_px: int = 1
    speckle_window_px: int = 100
    sigma_disparity_px: float = 0.2
    min_valid_fraction: float = 0.05
    max_saturated_fraction: float = 0.01
    range_ratio: float = 2.0

    def __post_init__(self) -> None:
        if self.scale is not None and not 0 < self.scale <= 1:
            raise ValueError(f"scale must be in (0, 1]; found {self.scale}")
        if not 0 < self.min_range_m < self.max_range_m:
            raise ValueError(
                f"need 0 < min_range_m < max_range_m; found {self.min_range_m}, {self.max_range_m}"
            )
        if self.block_px < 1 or self.block_px % 2 == 0:
            raise ValueError(f"block_px must be a positive odd number; found {self.block_px}")
        if self.sigma_disparity_px <= 0 or not 0 <= self.min_valid_fraction < 1:
            raise ValueError("sigma_disparity_px must be positive and min_valid_fraction in [0, 1)")
        if not 0 <= self.max_saturated_fraction <= 1:
            raise ValueError(f"max_saturated_fraction must be in [0, 1]; found {self.max_saturated_fraction}")

    def scale_for(self, width_px: int) -> float:
        """The resize factor for images ``width_px`` wide."""
        if self.scale is not None:
            return self.scale
        return min(1.0, DEFAULT_DENSE_WIDTH_PX / width_px)

    def key(self) -> str:
        """A stable text form for cache keys."""
        return repr(sorted(asdict(self).items()))


@dataclass(frozen=True)
class DenseGeometry:
    """The rectified left camera of the matched (scaled) images.

    Parameters
    ----------
    f_px, cx_px, cy_px : float
        Focal length and principal point, matching pixels.
    baseline_m : float
    width, height : int
        Matched image size, pixels.
    R1 : ndarray, shape (3, 3)
        Rotates left camera coordinates into the rectified left frame.
    scale : float
        Matched size over the image files' size.
    min_disparity, num_disparities : int
        SGBM's search: ``min_disparity`` to ``min_disparity + num_disparities`` pixels.
    """

    f_px: float
    cx_px: float
    cy_px: float
    baseline_m: float
    width: int
    height: int
    R1: FloatArray
    scale: float
    min_disparity: int
    num_disparities: int

    @classmethod
    def of(cls, rig: StereoRig, rect: Rectification, settings: DenseSettings) -> DenseGeometry:
        s = settings.scale_for(rig.left.width)
        f = rect.f_px * s
        fb = f * rect.baseline_m
        lo = max(1, int(np.floor(fb / settings.max_range_m)))
        hi = int(np.ceil(fb / settings.min_range_m))
        num = max(SUBPIXEL, int(np.ceil((hi - lo) / SUBPIXEL)) * SUBPIXEL)
        return cls(
            f_px=f,
            cx_px=(rect.cx_px + 0.5) * s - 0.5,
            cy_px=(rect.cy_px + 0.5) * s - 0.5,
            baseline_m=rect.baseline_m,
            width=max(8, round(rig.left.width * s)),
            height=max(8, round(rig.left.height * s)),
            R1=np.asarray(rect.R1, dtype=float),
            scale=s,
            min_disparity=lo,
            num_disparities=num,
        )

    @property
    def K(self) -> FloatArray:
        """Intrinsic matrix of the rectified, scaled left camera."""
        return np.array([[self.f_px, 0.0, self.cx_px], [0.0, self.f_px, self.cy_px], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class DenseMap:
    """One pair's dense stereo in the rectified, scaled left camera.

    Parameters
    ----------
    disparity_px : ndarray, shape (H, W), float32
        Disparity, matching pixels; NaN where no match was kept.
    image : ndarray, shape (H, W), uint8
        The rectified, illumination-corrected left image (the colour of the points).
    """

    disparity_px: NDArray[np.float32]
    image: NDArray[np.uint8]

    @property
    def valid(self) -> NDArray[np.bool_]:
        return np.isfinite(self.disparity_px)

    def depth_m(self, geom: DenseGeometry) -> NDArray[np.float32]:
        """Depth along the rectified optical axis, metres; NaN where invalid."""
        return (geom.f_px * geom.baseline_m / self.disparity_px).astype(np.float32)

    def sigma_m(self, geom: DenseGeometry, sigma_disparity_px: float) -> NDArray[np.float32]:
        """1-sigma of the depth, metres (``Z^2 sigma_d / (f b)``); NaN where invalid."""
        z = self.depth_m(geom)
        return (z * z * np.float32(sigma_disparity_px / (geom.f_px * geom.baseline_m))).astype(np.float32)

    def points_rect(self, geom: DenseGeometry) -> tuple[FloatArray, NDArray[np.intp]]:
        """Valid pixels' points in the rectified left frame (N, 3), metres, and their flat indices."""
        idx = np.flatnonzero(self.valid.ravel())
        v, u = np.divmod(idx, geom.width)
        z = (geom.f_px * geom.baseline_m / self.disparity_px.ravel()[idx]).astype(np.float64)
        x = (u - geom.cx_px) * z / geom.f_px
        y = (v - geom.cy_px) * z / geom.f_px
        return np.stack([x, y, z], axis=1), idx

    def points_local(
        self, geom: DenseGeometry, R: FloatArray, t: FloatArray
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.intp]]:
        """Valid pixels' points moved by ``(R, t)`` (rectified frame -> a local frame near them),
        float32 (N, 3), their depth ``Z`` (N,) in the rectified frame, and their flat pixel indices.

        Column arithmetic in float32: a (N, 3) @ (3, 3) product costs ten times more here.
        """
        flat = self.disparity_px.ravel()
        idx = np.flatnonzero(np.isfinite(flat))
        uf, vf = _rays(geom)
        z = np.float32(geom.f_px * geom.baseline_m) / flat[idx]
        x = uf[idx] * z
        y = vf[idx] * z
        R32 = np.asarray(R, dtype=np.float32)
        t32 = np.asarray(t, dtype=np.float32)
        out = np.empty((len(idx), 3), dtype=np.float32)
        for i in range(3):
            out[:, i] = R32[i, 0] * x + R32[i, 1] * y + R32[i, 2] * z + t32[i]
        return out, z, idx

    def summary(self, geom: DenseGeometry) -> tuple[float, float]:
        """Fraction of pixels matched, and their median depth (metres; NaN when none)."""
        valid = self.valid
        frac = float(valid.mean())
        return frac, float(np.median(self.depth_m(geom)[valid])) if valid.any() else float("nan")


_RAYS: dict[tuple, tuple[NDArray[np.float32], NDArray[np.float32]]] = {}


def _rays(geom: DenseGeometry) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``(u - cx) / f`` and ``(v - cy) / f`` of every pixel, flat float32; cached per geometry."""
    key = (geom.width, geom.height, geom.f_px, geom.cx_px, geom.cy_px)
    if key not in _RAYS:
        v, u = np.divmod(np.arange(geom.width * geom.height), geom.width)
        _RAYS.clear()
        _RAYS[key] = (
            ((u - geom.cx_px) / geom.f_px).astype(np.float32),
            ((v - geom.cy_px) / geom.f_px).astype(np.float32),
        )
    return _RAYS[key]


class DenseFailed(ValueError):
    """A pair's dense stereo gave too few matches (the message says how many)."""


_MATCHERS: dict[tuple, cv2.StereoSGBM] = {}


def _matcher(geom: DenseGeometry, settings: DenseSettings) -> cv2.StereoSGBM:
    key = (geom.min_disparity, geom.num_disparities, settings.key())
    if key not in _MATCHERS:
        b = settings.block_px
        # P1, P2: OpenCV's documented choice for a single-channel image (8 and 32 times the block area).
        _MATCHERS[key] = cv2.StereoSGBM_create(
            minDisparity=geom.min_disparity,
            numDisparities=geom.num_disparities,
            blockSize=b,
            P1=8 * b * b,
            P2=32 * b * b,
            disp12MaxDiff=settings.lr_max_diff_px,
            uniquenessRatio=settings.uniqueness_pct,
            speckleWindowSize=settings.speckle_window_px,
            speckleRange=2,
            mode=cv2.STEREO_SGBM_MODE_SGBM,
        )
    return _MATCHERS[key]


def prepare_pair(
    left: NDArray[np.uint8],
    right: NDArray[np.uint8],
    rig: StereoRig,
    rect: Rectification,
    geom: DenseGeometry,
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Both images rectified, reduced to the matching size and corrected for the lighting."""
    left_r, right_r = rectify_images(left, right, rig, rect)
    if geom.scale < 1:
        size = (geom.width, geom.height)
        left_r = cv2.resize(left_r, size, interpolation=cv2.INTER_AREA)
        right_r = cv2.resize(right_r, size, interpolation=cv2.INTER_AREA)
    return correct_illumination(left_r), correct_illumination(right_r)


def dense_pair(
    left: NDArray[np.uint8],
    right: NDArray[np.uint8],
    rig: StereoRig,
    rect: Rectification,
    geom: DenseGeometry,
    settings: DenseSettings,
) -> DenseMap:
    """Semi-global matching of a raw (distorted) stereo pair (module docstring).

    Raises
    ------
    DenseFailed
        Fewer than ``settings.min_valid_fraction`` of the pixels matched, or more than
        ``settings.max_saturated_fraction`` of the matches at the search's upper limit.
    """
    left_c, right_c = prepare_pair(left, right, rig, rect, geom)
    raw = _matcher(geom, settings).compute(left_c, right_c)
    disparity = raw.astype(np.float32) / SUBPIXEL
    matched = raw > geom.min_disparity * SUBPIXEL  # unmatched: minDisparity - 1
    disparity[~matched] = np.nan
    # Within a pixel of the largest disparity searched: the seafloor may be nearer than min_range_m.
    limit = (geom.min_disparity + geom.num_disparities - 2) * SUBPIXEL
    saturated = matched & (raw >= limit)
    n_matched = int(matched.sum())
    if n_matched and saturated.sum() > settings.max_saturated_fraction * n_matched:
        raise DenseFailed(
            f"{100 * saturated.sum() / n_matched:.0f}% of the matches at the disparity search's limit: "
            f"the seafloor is nearer than min_range_m ({settings.min_range_m:g} m)"
        )
    disparity[saturated] = np.nan
    if settings.range_ratio > 1 and np.isfinite(disparity).any():
        median = float(np.nanmedian(disparity))  # disparity is inverse range: the same ratio bounds it
        far = (disparity < median / settings.range_ratio) | (disparity > median * settings.range_ratio)
        disparity[far] = np.nan
    dense = DenseMap(disparity, left_c)
    frac = float(dense.valid.mean())
    if frac < settings.min_valid_fraction:
        raise DenseFailed(
            f"{100 * frac:.1f}% of the pixels matched (at least {100 * settings.min_valid_fraction:.0f}% needed)"
        )
    return dense


def cache_path(cache_dir: Path, left: Path, right: Path, rig: StereoRig, settings: DenseSettings) -> Path:
    """The cache file of a pair: keyed by image name, file stamps, calibration and settings."""
    h = hashlib.sha1()
    for p in (left, right):
        st = os.stat(p)
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    h.update(f"{CACHE_VERSION}:{rig_digest(rig)}:{settings.key()}".encode())
    return cache_dir / f"{left.parent.name}_{left.with_suffix('').name}_{h.hexdigest()[:16]}.npz"


def write_dense(dense: DenseMap, path: Path) -> None:
    """Write a dense map, atomically: the fixed-point disparity (uint16, 0 where unmatched) and the
    image, each deflated (zlib level 1: about 90 + 250 KB a half-scale pair, read in 5 ms)."""
    fixed = np.where(dense.valid, np.rint(dense.disparity_px * SUBPIXEL), 0).astype(np.uint16)
    buffer = io.BytesIO()
    np.savez(
        buffer,
        shape=np.array(fixed.shape, dtype=np.int64),
        disparity=np.frombuffer(zlib.compress(fixed.astype("<u2").tobytes(), 1), dtype=np.uint8),
        image=np.frombuffer(zlib.compress(np.ascontiguousarray(dense.image).tobytes(), 1), dtype=np.uint8),
    )

    def write(tmp: Path) -> None:
        tmp.write_bytes(buffer.getvalue())

    atomic_write(path, write)


def read_dense(path: Path) -> DenseMap:
    """A dense map written by :func:`write_dense`; ValueError when it is unreadable."""
    try:
        with np.load(path) as data:
            h, w = (int(v) for v in data["shape"])
            fixed = np.frombuffer(zlib.decompress(data["disparity"].tobytes()), dtype="<u2").reshape(h, w)
            image = np.frombuffer(zlib.decompress(data["image"].tobytes()), dtype=np.uint8).reshape(h, w)
    except (OSError, KeyError, EOFError, ValueError, zlib.error) as err:
        raise ValueError(f"{path}: unreadable dense map ({err})") from None
    disparity = fixed.astype(np.float32) * np.float32(1.0 / SUBPIXEL)
    disparity[fixed == 0] = np.nan
    return DenseMap(disparity, image)


def pair_dense(
    left_path: Path,
    right_path: Path,
    rig: StereoRig,
    rect: Rectification,
    geom: DenseGeometry,
    settings: DenseSettings,
    cache_dir: Path | None,
) -> DenseMap | None:
    """A pair's dense map from its image files, from the cache when present.

    Returns None (with a warning naming the file) for a missing or unreadable image. An image whose
    size differs from the calibration raises :class:`~auvnav.errors.ConfigError`.

    Raises
    ------
    DenseFailed
        The matching failed (too few matches).
    """
    cached = None
    if cache_dir is not None and left_path.is_file() and right_path.is_file():
        cached = cache_path(cache_dir, left_path, right_path, rig, settings)
        if cached.is_file():
            try:
                return read_dense(cached)
            except ValueError as err:
                log.warning("%s; recomputing", err)
    left, right = read_grey(left_path, rig.left.bayer), read_grey(right_path, rig.right.bayer)
    if left is None or right is None:
        return None
    check_image_size(rig.left, left.shape, str(left_path))
    check_image_size(rig.right, right.shape, str(right_path))
    dense = dense_pair(left, right, rig, rect, geom, settings)
    if cached is not None:
        write_dense(dense, cached)
    return dense
