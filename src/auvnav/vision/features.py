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

from dataclasses import asdict, dataclass

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
        Keypoints kept per image, strongest first. 1,500 at a contrast threshold of 0.04 (OpenCV's
        default), with ``lk_window_px`` 15, runs the navigation check dive's front end 1.45 times
        faster than 2,500 at 0.02 with a 21 px window, for a median loop rotation error 0.01 deg
        larger (0.069 against 0.059 deg; ``benchmarks/bench_vision.py``).
    contrast_threshold : float
        SIFT's contrast threshold (OpenCV ``contrastThreshold``), on illumination-corrected images.
    sigma_px : float
        1-sigma keypoint position noise, pixels of the image SIFT runs on (0.4 px, a usual figure for SIFT).
    stereo_gate_px : float
        Largest difference of rectified rows between the left and right feature of a stereo match,
        pixels of the image SIFT runs on.
    lk_window_px : int
        Side of the patch tracked from the left image into the right one, pixels of the image SIFT
        runs on.
    max_round_trip_px : float
        Largest distance, pixels of the image SIFT runs on, between a left keypoint and where it lands
        when tracked to the right image and back.
    min_range_m, max_range_m : float
        Plausible distances of the seafloor from the camera; bound the disparity search.
    """

    scale: float | None = None
    max_features: int = 1500
    contrast_threshold: float = 0.04
    sigma_px: float = 0.4
    stereo_gate_px: float = 2.0
    lk_window_px: int = 15
    max_round_trip_px: float = 0.5
    min_range_m: float = 0.5
    max_range_m: float = 12.0

    def __post_init__(self) -> None:
        if self.scale is not None and not 0 < self.scale <= 1:
            raise ValueError(f"scale must be in (0, 1]; found {self.scale}")
        if min(self.sigma_px, self.stereo_gate_px, self.lk_window_px, self.max_round_trip_px) <= 0:
            raise ValueError("sigma_px, stereo_gate_px, lk_window_px and max_round_trip_px must be positive")
        if not 0 < self.min_range_m < self.max_range_m:
            raise ValueError(
                f"need 0 < min_range_m < max_range_m; found {self.min_range_m}, {self.max_range_m}"
            )

    def scale_for(self, width_px: int) -> float:
        """The resize factor for images ``width_px`` wide."""
        if self.scale is not None:
            return self.scale
        return min(1.0, DEFAULT_FEATURE_WIDTH_PX / width_px)

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


def _sift(settings: FeatureSettings) -> cv2.SIFT:
    key = (settings.max_features, settings.contrast_threshold)
    if key not in _SIFT:
        # nOctaveLayers 3, edgeThreshold 10 and sigma 1.6 are the defaults of Lowe and OpenCV. The image
        # doubled for the first octave is made by the fast resize (enable_precise_upscale False), whose
        # quarter-pixel shift `detect` removes: OpenCV's precise upscale takes about 3% longer.
        _SIFT[key] = cv2.SIFT_create(
            settings.max_features, 3, settings.contrast_threshold, 10.0, 1.6, cv2.CV_8U, False
        )
    return _SIFT[key]


def detect(image: NDArray[np.uint8], settings: FeatureSettings) -> Keypoints:
    """SIFT keypoints of an illumination-corrected grey image (:func:`correct_illumination`), in
    full-image pixel coordinates."""
    h, w = image.shape[:2]
    scale = settings.scale_for(w)
    if scale < 1:
        size = (max(8, round(w * scale)), max(8, round(h * scale)))
        small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    else:
        small = image
    sx, sy = small.shape[1] / w, small.shape[0] / h
    kps, desc = _sift(settings).detectAndCompute(small, None)
    if not kps:
        return Keypoints(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 128), dtype=np.uint8))
    # The doubled image's pixel x shows the input at x/2 - 1/4 (cv2.resize aligns pixel centres), but
    # SIFT reports x/2: every keypoint lies a quarter pixel right of and below its feature.
    pt = np.array([k.pt for k in kps], dtype=float) - UPSCALE_SHIFT_PX
    uv = np.column_stack([(pt[:, 0] + 0.5) / sx - 0.5, (pt[:, 1] + 0.5) / sy - 0.5])
    size = np.array([k.size for k in kps], dtype=float) / sx
    return Keypoints(uv, size, np.asarray(desc, dtype=np.uint8))


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


def match_descriptors(
    desc_a: NDArray[np.uint8], desc_b: NDArray[np.uint8], *, ratio: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Mutual nearest neighbours (all against all) whose best distance passes Lowe's ratio test.

    Squared distances come from one float32 matrix product (``|a|^2 + |b|^2 - 2 a.b``), reduced along
    rows for each descriptor of A's best and second-best, and along columns for each of B's best.

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
    a = desc_a.astype(np.float32)
    b = desc_b.astype(np.float32)
    d2 = a @ b.T
    d2 *= -2.0
    d2 += (a * a).sum(1)[:, None]
    d2 += (b * b).sum(1)[None, :]
    rows = np.arange(len(a))
    ja = np.argmin(d2, axis=1)
    best = d2[rows, ja].copy()
    d2[rows, ja] = np.inf
    second = d2.min(axis=1)
    d2[rows, ja] = best
    ok = (best <= d2.min(axis=0)[ja]) & (best < ratio * ratio * second)
    return rows[ok], ja[ok]


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
