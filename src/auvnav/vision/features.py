"""Image front end: illumination correction and SIFT features at a configurable scale.

Strobe images are bright in the middle and dark at the corners, and brighter at low altitude; the paper
names lighting correction as the slow step of the pipeline (section III). Here it is a division by the
image's own low-pass: the image is reduced 16 times (area averaging), blurred, enlarged again, and the
image divided by it. That costs about as much as one resize of the image, and leaves the albedo: the
strobe's falloff, vignetting and exposure changes are all smooth and multiplicative.

SIFT (Lowe 2004, IJCV 60(2)) runs on images reduced by ``FeatureSettings.scale``; by default to 680 pixels
wide, half the width of the paper's 1360 x 1024 cameras, as the paper's group did (so full-size images are
halved and images already rendered at half size are used as they are). Keypoints are returned in the
pixel coordinates of the image file.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

LOWPASS_REDUCTION = 16  # the low-pass image is computed 16 times smaller in each direction
LOWPASS_SIGMA = 1.5  # Gaussian blur of the reduced image, reduced pixels (~ 24 full pixels)
# Half the width of the Sirius cameras (1360 px; sim/camera.py cites the source): the default SIFT scale.
DEFAULT_FEATURE_WIDTH_PX = 680
# Location bias of OpenCV SIFT keypoints with its fast first-octave upscale, in the pixels SIFT sees.
UPSCALE_SHIFT_PX = 0.25


@dataclass(frozen=True)
class FeatureSettings:
    """How features are found, matched across the stereo pair and triangulated.

    Parameters
    ----------
    scale : float or None
        SIFT runs on images resized by this factor (0 < scale <= 1); None: to
        ``DEFAULT_FEATURE_WIDTH_PX`` wide (never enlarged).
    max_features : int
        Keypoints kept per image, strongest first (``auvnav loops --features``). 1,500 with
        a 17 px stereo window ran the navigation check dive's front end 1.45 times faster than 2,500
        with a 21 px window, for a median loop rotation error 0.01 deg larger (0.069 against 0.059 deg;
        ``benchmarks/bench_vision.py``, the procedural reef before issue 20).
    contrast_threshold : float
        SIFT's contrast threshold (OpenCV ``contrastThreshold``), on illumination-corrected images
        stretched to ``contrast_target_dn``. 0.02 (half OpenCV's default): on the simulator's turbid
        water the stretched images then give 1,000-1,500 keypoints, most of which the stereo tracking
        keeps (so they are texture, not noise).
    sigma_px : float
        1-sigma keypoint position noise, pixels of the image SIFT runs on (0.4 px, a usual figure for SIFT).
    stereo_gate_px : float
        Largest difference of rectified rows between the left and right feature of a stereo match,
        pixels of the image SIFT runs on.
    lk_window_px : int
        Side of the patch tracked from the left image into the right one, pixels of the image SIFT
        runs on; the tracker's window in the rectified image is the odd number of pixels nearest it
        (:meth:`lk_window_for`). 17: the window every benchmark of the half-scale images measured
        (until 2026-11-28 the default read 15, which the rounding then in use made 17).
    max_round_trip_px : float
        Largest distance, pixels of the image SIFT runs on, between a left keypoint and where it lands
        when tracked to the right image and back.
    min_range_m, max_range_m : float
        Plausible distances of the seafloor from the camera; bound the disparity search.
    contrast_target_dn : float
        Adaptive contrast: before SIFT, the illumination-corrected image is stretched about its mean
        until the robust standard deviation of its grey levels (:func:`robust_contrast`) reaches this
        many digital numbers, never reduced and by at most ``max_stretch``; ``contrast_threshold`` is
        thus relative to the image's own contrast wherever that is below the target. 0: no stretch
        (SIFT's threshold is absolute, as in OpenCV).
    max_stretch : float
        The largest contrast stretch (it multiplies the noise as much as the texture).
    retry_fraction : float
        Adaptive threshold: when SIFT finds fewer than this fraction of ``max_features`` (an image of
        featureless sand or smooth ripples), it keeps those down to half ``contrast_threshold``. On the
        check dive in turbid water, 14% of the images had fewer than 1,000 keypoints (370-807) at 0.02;
        all but one reached 1,500 at 0.01. SIFT runs once, at the lower threshold, and the keypoints
        above the full one are kept when there are enough: the keypoints and descriptors of a pass at
        each threshold (identical on 120 images of the three waters); a pair's features took 0.91-0.93
        times the CPU of two passes on the check dive's clear and coastal images (where a third of the
        images need the lower threshold), the same on its turbid ones. 0: one threshold.
    edge_reject_px : float
        Edge-safe stereo: a match is dropped when its disparity moves by more than this, pixels of the
        image SIFT runs on, as the tracked window is shifted by half its side
        (:func:`auvnav.vision.stereo.disparity_spread`: the patch straddles a depth discontinuity); the
        spread of the matches kept is added to their disparity noise. 0: no test. The limit rises in
        noisy images to 5 times the pair's lower quartile of spreads
        (:data:`auvnav.vision.stereo.EDGE_NOISE_FACTOR`). On six rendered scenes with steps
        (``benchmarks/bench_stereo_edges.py``), of the matches whose patch spans more than 1 px of
        disparity, 75% are within 1 px of the truth without the test and 96.5% with it (93% at 1 px),
        for 11% of the other matches.
    spread_cells : int
        Well-spread keypoints: SIFT keeps up to ``SPREAD_OVERSAMPLE`` times ``max_features`` and
        ``max_features`` of them are chosen round-robin over a ``spread_cells`` x ``spread_cells`` grid
        of the image, strongest first in each cell (:func:`spread`). 0: the strongest, wherever they are.
    thumbnail_scale : float
        Each pair keeps its rectified, illumination-corrected left image reduced to this fraction of
        the size SIFT sees (:func:`auvnav.vision.stereo.make_thumbnail`), for the direct registration
        of pairs whose keypoints are too few (:mod:`auvnav.vision.direct`). 0: none kept.
    """

    scale: float | None = None
    max_features: int = 1500
    contrast_threshold: float = 0.02
    contrast_target_dn: float = 32.0
    max_stretch: float = 8.0
    retry_fraction: float = 0.67
    edge_reject_px: float = 0.5
    spread_cells: int = 0
    thumbnail_scale: float = 0.5
    sigma_px: float = 0.4
    stereo_gate_px: float = 2.0
    lk_window_px: int = 17
    max_round_trip_px: float = 0.5
    min_range_m: float = 0.5
    max_range_m: float = 12.0

    def __post_init__(self) -> None:
        if self.scale is not None and not 0 < self.scale <= 1:
            raise ValueError(f"scale must be in (0, 1]; found {self.scale}")
        if min(self.sigma_px, self.stereo_gate_px, self.lk_window_px, self.max_round_trip_px) <= 0:
            raise ValueError("sigma_px, stereo_gate_px, lk_window_px and max_round_trip_px must be positive")
        if self.max_features < 1 or self.contrast_threshold <= 0:
            raise ValueError("max_features and contrast_threshold must be positive")
        if not 0 <= self.thumbnail_scale <= 1:
            raise ValueError(f"thumbnail_scale must be in [0, 1]; found {self.thumbnail_scale}")
        if not 0 <= self.retry_fraction <= 1:
            raise ValueError(f"retry_fraction must be in [0, 1]; found {self.retry_fraction}")
        if (
            self.contrast_target_dn < 0
            or self.max_stretch < 1
            or self.spread_cells < 0
            or self.edge_reject_px < 0
        ):
            raise ValueError(
                "need contrast_target_dn, edge_reject_px, spread_cells >= 0 and max_stretch >= 1"
            )
        if not 0 < self.min_range_m < self.max_range_m:
            raise ValueError(
                f"need 0 < min_range_m < max_range_m; found {self.min_range_m}, {self.max_range_m}"
            )

    def scale_for(self, width_px: int) -> float:
        """The resize factor for images ``width_px`` wide."""
        if self.scale is not None:
            return self.scale
        return min(1.0, DEFAULT_FEATURE_WIDTH_PX / width_px)

    def lk_window_for(self, width_px: int) -> int:
        """The stereo tracker's window side, pixels of images ``width_px`` wide: ``lk_window_px`` at
        the SIFT scale, to the nearest odd number (the larger one on a tie)."""
        return 2 * int(self.lk_window_px / self.scale_for(width_px) // 2) + 1

    def key(self) -> str:
        """A stable text form for cache keys."""
        return repr(sorted(asdict(self).items()))


@dataclass(frozen=True)
class Keypoints:
    """SIFT keypoints of one image.

    Parameters
    ----------
    uv_px : ndarray, shape (N, 2)
        Position (column, row) in the full image's pixels, pixel centres at integers.
    size_px : ndarray, shape (N,)
        Keypoint diameter, full-image pixels.
    descriptors : ndarray, shape (N, 128), uint8
    """

    uv_px: FloatArray
    size_px: FloatArray
    descriptors: NDArray[np.uint8]


def correct_illumination(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Divide a grey image by its own low-pass (strobe falloff, vignetting, exposure) and rescale to 8 bits.

    The result has a mean of about 128 wherever the scene has texture, whatever the lighting.
    """
    h, w = image.shape[:2]
    small = cv2.resize(
        image,
        (max(1, w // LOWPASS_REDUCTION), max(1, h // LOWPASS_REDUCTION)),
        interpolation=cv2.INTER_AREA,
    ).astype(np.float32)
    small = cv2.GaussianBlur(small, (0, 0), LOWPASS_SIGMA, borderType=cv2.BORDER_REFLECT)
    low = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    out = image.astype(np.float32) * (128.0 / np.maximum(low, 1.0))
    return np.clip(out, 0, 255).astype(np.uint8)


_SIFT: dict[tuple, cv2.SIFT] = {}

#: SIFT's scales per octave (nOctaveLayers: Lowe's and OpenCV's 3).
SIFT_OCTAVE_LAYERS = 3


def _sift(settings: FeatureSettings) -> cv2.SIFT:
    n = settings.max_features
    if settings.spread_cells > 0:
        n = round(SPREAD_OVERSAMPLE * n)
    key = (n, settings.contrast_threshold)
    if key not in _SIFT:
        # nOctaveLayers 3, edgeThreshold 10 and sigma 1.6 are the defaults of Lowe and OpenCV. The image
        # doubled for the first octave is made by the fast resize (enable_precise_upscale False), whose
        # quarter-pixel shift `detect` removes: OpenCV's precise upscale takes about 3% longer.
        _SIFT[key] = cv2.SIFT_create(
            n, SIFT_OCTAVE_LAYERS, settings.contrast_threshold, 10.0, 1.6, cv2.CV_8U, False
        )
    return _SIFT[key]


#: With ``spread_cells``, SIFT keeps this many times ``max_features`` for :func:`spread` to choose from.
SPREAD_OVERSAMPLE = 1.5


def robust_contrast(image: NDArray[np.uint8]) -> float:
    """The robust standard deviation of an image's grey levels: 1.4826 times their median absolute
    deviation (from a 256-bin histogram), which neither bright specks nor dark shadows inflate."""
    hist = cv2.calcHist([image], [0], None, [256], [0, 256]).ravel()
    cdf = np.cumsum(hist)
    median = int(np.searchsorted(cdf, cdf[-1] / 2))
    dev = np.abs(np.arange(256) - median)
    dev_hist = np.bincount(dev, weights=hist, minlength=256)
    mad = int(np.searchsorted(np.cumsum(dev_hist), cdf[-1] / 2))
    return 1.4826 * max(mad, 0.5)


def stretch_contrast(image: NDArray[np.uint8], settings: FeatureSettings) -> tuple[NDArray[np.uint8], float]:
    """The image stretched about its mean to ``settings.contrast_target_dn`` of robust contrast
    (:func:`robust_contrast`), by at most ``settings.max_stretch`` and never reduced; and the stretch."""
    if settings.contrast_target_dn <= 0:
        return image, 1.0
    gain = float(np.clip(settings.contrast_target_dn / robust_contrast(image), 1.0, settings.max_stretch))
    if gain <= 1.0:
        return image, 1.0
    mean = float(cv2.mean(image)[0])
    out = np.clip(image.astype(np.float32) * np.float32(gain) + np.float32(mean * (1.0 - gain)), 0, 255)
    return np.rint(out).astype(np.uint8), gain


def spread(
    uv_px: FloatArray, response: FloatArray, width: int, height: int, n: int, cells: int
) -> NDArray[np.intp]:
    """Indices of ``n`` keypoints chosen round-robin over a ``cells`` x ``cells`` grid: every cell's
    strongest, then every cell's second strongest, and so on (strongest first within a round)."""
    if len(uv_px) <= n:
        return np.arange(len(uv_px))
    cu = np.clip((uv_px[:, 0] * cells // width).astype(np.intp), 0, cells - 1)
    cv_ = np.clip((uv_px[:, 1] * cells // height).astype(np.intp), 0, cells - 1)
    cell = cv_ * cells + cu
    order = np.lexsort((-response, cell))  # by cell, strongest first
    sorted_cell = cell[order]
    first = np.searchsorted(sorted_cell, sorted_cell, side="left")
    rank = np.empty(len(order), dtype=np.intp)
    rank[order] = np.arange(len(order)) - first
    chosen = np.lexsort((-response, rank))[:n]
    return np.sort(chosen)


def detect(image: NDArray[np.uint8], settings: FeatureSettings) -> Keypoints:
    """SIFT keypoints of an illumination-corrected grey image (:func:`correct_illumination`), in
    full-image pixel coordinates: on the image stretched to ``settings.contrast_target_dn``
    (:func:`stretch_contrast`), spread over the image when ``settings.spread_cells`` is set."""
    h, w = image.shape[:2]
    scale = settings.scale_for(w)
    if scale < 1:
        size = (max(8, round(w * scale)), max(8, round(h * scale)))
        small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    else:
        small = image
    small, _ = stretch_contrast(small, settings)
    sx, sy = small.shape[1] / w, small.shape[0] / h
    if settings.retry_fraction > 0:
        # One pass at the lower threshold: OpenCV's response is the extremum's interpolated contrast,
        # which its threshold compares with contrast_threshold / nOctaveLayers, and its cap keeps the
        # strongest; so those at or above the full threshold are the keypoints a pass at it finds.
        lower = replace(settings, contrast_threshold=0.5 * settings.contrast_threshold, retry_fraction=0.0)
        kps, desc = _sift(lower).detectAndCompute(small, None)
        strong = [
            i for i, k in enumerate(kps) if k.response * SIFT_OCTAVE_LAYERS >= settings.contrast_threshold
        ]
        if len(strong) >= settings.retry_fraction * settings.max_features:
            kps, desc = [kps[i] for i in strong], desc[strong]
    else:
        kps, desc = _sift(settings).detectAndCompute(small, None)
    if not kps:
        return Keypoints(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 128), dtype=np.uint8))
    # The doubled image's pixel x shows the input at x/2 - 1/4 (cv2.resize aligns pixel centres), but
    # SIFT reports x/2: every keypoint lies a quarter pixel right of and below its feature.
    pt = np.array([k.pt for k in kps], dtype=float) - UPSCALE_SHIFT_PX
    desc = np.asarray(desc, dtype=np.uint8)
    size = np.array([k.size for k in kps], dtype=float)
    if settings.spread_cells > 0 and len(kps) > settings.max_features:
        response = np.array([k.response for k in kps], dtype=float)
        keep = spread(
            pt, response, small.shape[1], small.shape[0], settings.max_features, settings.spread_cells
        )
        pt, desc, size = pt[keep], desc[keep], size[keep]
    uv = np.column_stack([(pt[:, 0] + 0.5) / sx - 0.5, (pt[:, 1] + 0.5) / sy - 0.5])
    return Keypoints(uv, size / sx, desc)


#: The largest SIFT descriptor component OpenCV gives (components of the unit vector are clipped at 0.2,
#: the vector renormalised and scaled by 512; observed at most 182 over a check dive's 3,500 pairs).
SIFT_COMPONENT_MAX = 182.0


def compand_descriptors(descriptors: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """SIFT descriptors square-root companded to 4 bits: ``round(15 sqrt(d / SIFT_COMPONENT_MAX))``.

    The square root is RootSIFT's (Arandjelovic and Zisserman 2012, "Three things everyone should know
    to improve object retrieval", CVPR): Euclidean distance between the roots compares descriptors as
    the Hellinger kernel does, which matches better than Euclidean distance between the raw values; on
    that scale 16 levels keep the matches (``benchmarks/bench_vision.py``) in half the bytes. Matching,
    the vocabulary and the cache all use the companded values.
    """
    d = np.asarray(descriptors, dtype=np.float32)
    return np.minimum(np.rint(15.0 * np.sqrt(d / SIFT_COMPONENT_MAX)), 15.0).astype(np.uint8)


def squared_distances(
    desc_a: NDArray,
    desc_b: NDArray,
    norms_a: NDArray[np.float32] | None = None,
    norms_b: NDArray[np.float32] | None = None,
) -> NDArray[np.float32]:
    """Every squared distance between two sets of descriptors, shape (Na, Nb), from one float32 matrix
    product (``|a|^2 + |b|^2 - 2 a.b``); ``norms_a``, ``norms_b``: the squared norms, when known."""
    a = desc_a.astype(np.float32, copy=False)
    b = desc_b.astype(np.float32, copy=False)
    d2 = a @ b.T
    d2 *= -2.0
    d2 += ((a * a).sum(1) if norms_a is None else norms_a)[:, None]
    d2 += ((b * b).sum(1) if norms_b is None else norms_b)[None, :]
    return d2


def best_two(d2: NDArray[np.float32]) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.intp]]:
    """Each row's smallest and second smallest value of a squared-distance matrix, and the column of
    the smallest. ``d2`` is used as scratch and restored."""
    rows = np.arange(len(d2))
    j = np.argmin(d2, axis=1)
    best = d2[rows, j].copy()
    d2[rows, j] = np.inf
    second = d2.min(axis=1)
    d2[rows, j] = best
    return best, second, j


def mutual_ratio_test(
    best: NDArray[np.float32],
    second: NDArray[np.float32],
    col_best: NDArray[np.float32],
    *,
    ratio: float,
    second_cap: float = np.inf,
) -> NDArray[np.bool_]:
    """Which rows' best matches are mutual (no smaller distance in their column: ``col_best``, the
    column's smallest) and pass Lowe's ratio test against the second best, capped at ``second_cap``."""
    second = np.minimum(second, second_cap)
    return np.isfinite(best) & (best <= col_best) & (best < ratio * ratio * second)


def mutual_matches(
    d2: NDArray[np.float32], *, ratio: float, second_cap: float = np.inf
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Mutual nearest neighbours of a squared-distance matrix (Na, Nb; ``inf``: not a candidate) whose
    best distance passes Lowe's ratio test against the second best of its row, that second best capped
    at ``second_cap`` (squared) (:func:`best_two`, :func:`mutual_ratio_test`). ``d2`` is used as
    scratch and restored."""
    best, second, ja = best_two(d2)
    ok = mutual_ratio_test(best, second, d2.min(axis=0)[ja], ratio=ratio, second_cap=second_cap)
    return np.flatnonzero(ok), ja[ok]


def match_descriptors(
    desc_a: NDArray[np.uint8], desc_b: NDArray[np.uint8], *, ratio: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Mutual nearest neighbours (all against all) whose best distance passes Lowe's ratio test
    (:func:`squared_distances`, :func:`mutual_matches`).

    Parameters
    ----------
    desc_a, desc_b : ndarray, shapes (Na, 128), (Nb, 128)
    ratio : float
        A's best distance must be below ``ratio`` times its second best.

    Returns
    -------
    ia, ib : ndarray of int
        Indices of the matched descriptors.
    """
    empty = np.zeros(0, dtype=np.intp)
    if len(desc_a) < 2 or len(desc_b) < 2:
        return empty, empty
    return mutual_matches(squared_distances(desc_a, desc_b), ratio=ratio)


@dataclass(frozen=True)
class Vocabulary:
    """A coarse visual vocabulary: descriptors are matched only against those of the same word.

    Exhaustive matching of two stereo pairs' descriptors is the verification's main cost; splitting
    both sets by their nearest of ``k`` k-means centres divides it by about ``k``, at the price of the
    true matches that fall on either side of a boundary (the same device as the direct index of
    DBoW2: Galvez-Lopez and Tardos 2012, IEEE Trans. Robotics 28(5)).

    Parameters
    ----------
    centres : ndarray, shape (k, 128), float32
    """

    centres: NDArray[np.float32]

    def words(self, descriptors: NDArray[np.uint8]) -> NDArray[np.intp]:
        """The word (nearest centre) of each descriptor."""
        c = self.centres
        d = descriptors.astype(np.float32)
        return np.argmin((c * c).sum(1)[None, :] - 2.0 * (d @ c.T), axis=1)


def build_vocabulary(descriptors: NDArray[np.uint8], k: int, *, seed: int = 0) -> Vocabulary:
    """k-means (k-means++ seeding, ``cv2.kmeans``) of a sample of a dive's descriptors."""
    data = np.ascontiguousarray(descriptors, dtype=np.float32)
    if len(data) < k:
        raise ValueError(f"need at least {k} descriptors for a vocabulary of {k} words; found {len(data)}")
    cv2.setRNGSeed(seed)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 20, 1.0)
    _, _, centres = cv2.kmeans(data, k, None, criteria, 1, cv2.KMEANS_PP_CENTERS)
    return Vocabulary(centres.astype(np.float32))


def match_by_word(
    desc_a: NDArray[np.uint8],
    desc_b: NDArray[np.uint8],
    vocabulary: Vocabulary | None,
    *,
    ratio: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """:func:`match_descriptors` within each word of ``vocabulary`` (all against all when None)."""
    if vocabulary is None:
        return match_descriptors(desc_a, desc_b, ratio=ratio)
    wa, wb = vocabulary.words(desc_a), vocabulary.words(desc_b)
    ia, ib = [], []
    for w in range(len(vocabulary.centres)):
        sa, sb = np.flatnonzero(wa == w), np.flatnonzero(wb == w)
        ja, jb = match_descriptors(desc_a[sa], desc_b[sb], ratio=ratio)
        ia.append(sa[ja])
        ib.append(sb[jb])
    return np.concatenate(ia), np.concatenate(ib)
