"""The poses of a dive's SLAM graph, and what the sensors say at each.

One pose ``X(k) = gtsam.symbol("x", k)`` (``gtsam.Pose3``: ``R_ned_body`` and the reference point's
position, metres, local NED) per stereo pair, at the times of ``images/index.csv``, so pose ``i`` of
a loop file is row ``i`` of the index. Auxiliary poses fill the rest of the navigated span
(:class:`PoseTimes`): at every GPS or USBL fix that does not fall on an image (within
:data:`MERGE_S`), and every ``aux_period_s`` through gaps without images (the descent, the
surface), so the fixes reach the images through the DVL. The attitude at a pose is the mean of the
navigation samples within a window of its time (circular for headings), as is its depth
(:func:`pose_measurements`).
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from auvnav.depth.tide import TideModel
from auvnav.errors import InsufficientDataError
from auvnav.frames import FloatArray, euler2rot, wrap_angle
from auvnav.nav.inputs import NavInputs

log = logging.getLogger(__name__)

#: A fix this close to an image time is attached to the image's pose, seconds.
MERGE_S = 0.05


def pose_key(k: int) -> int:
    """The GTSAM key of pose ``k``."""
    return gtsam.symbol("x", k)


@dataclass(frozen=True)
class PoseTimes:
    """The graph's poses in time order.

    Parameters
    ----------
    t_s : ndarray, shape (P,)
        POSIX seconds, strictly increasing.
    image_row : ndarray of int64, shape (P,)
        Row of the image times of each pose, -1 for auxiliary poses.
    n_images : int
        Rows of the image times (images outside the navigated span have no pose).
    source : str
        Where the image times came from.
    """

    t_s: FloatArray
    image_row: NDArray[np.int64]
    n_images: int
    source: str

    def __post_init__(self) -> None:
        if np.shape(self.t_s) != np.shape(self.image_row) or np.ndim(self.t_s) != 1:
            raise ValueError(f"t_s and image_row must be 1-D and match; found {np.shape(self.t_s)}")
        if not np.all(np.diff(self.t_s) > 0):
            raise ValueError("pose times must be strictly increasing")

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def is_image(self) -> NDArray[np.bool_]:
        return self.image_row >= 0

    def pose_of_image(self) -> NDArray[np.int64]:
        """Pose index of each image row, -1 for images without a pose; shape (n_images,)."""
        out = np.full(self.n_images, -1, dtype=np.int64)
        out[self.image_row[self.is_image]] = np.flatnonzero(self.is_image)
        return out


def _distance_to_sorted(sorted_values: FloatArray, x: FloatArray) -> FloatArray:
    """Distance from each ``x`` to the nearest of ``sorted_values`` (ascending, not empty)."""
    j = np.searchsorted(sorted_values, x)
    last = len(sorted_values) - 1
    return np.minimum(
        np.abs(x - sorted_values[np.clip(j - 1, 0, last)]), np.abs(sorted_values[np.clip(j, 0, last)] - x)
    )


def build_pose_times(
    image_t_s: FloatArray, inputs: NavInputs, *, aux_period_s: float = 1.0, source: str = ""
) -> PoseTimes:
    """Image poses inside the navigated span, plus auxiliary poses at fixes and through gaps.

    Parameters
    ----------
    image_t_s : ndarray, shape (I,)
        Stereo pair times, POSIX seconds, strictly increasing.
    inputs : NavInputs
        The navigated span (its time base) and its fixes.
    aux_period_s : float
        Largest spacing of poses through gaps without images, seconds.
    source : str
        Where the image times came from.
    """
    t0, t1 = float(inputs.t_s[0]), float(inputs.t_s[-1])
    inside = (image_t_s >= t0) & (image_t_s <= t1)
    if not np.all(inside):
        log.warning(
            "%s: %d of %d stereo pairs lie outside the navigated span (DVL and attitude): no pose",
            source,
            np.count_nonzero(~inside),
            len(image_t_s),
        )
    if not np.any(inside):
        raise InsufficientDataError(f"{source}: no stereo pair lies inside the navigated span")
    t_img = image_t_s[inside]
    fixes = np.concatenate([f.t_s for f in inputs.fixes]) if inputs.fixes else np.zeros(0)
    anchors = np.unique(np.concatenate([t_img, fixes[_distance_to_sorted(t_img, fixes) > MERGE_S]]))
    filler = [
        a + aux_period_s * np.arange(1, math.ceil((b - a) / aux_period_s))
        for a, b in itertools.pairwise(anchors)
        if b - a > 1.5 * aux_period_s
    ]
    t = np.unique(np.concatenate([anchors, *filler]))
    row = np.full(len(t), -1, dtype=np.int64)
    row[np.searchsorted(t, t_img)] = np.flatnonzero(inside)
    return PoseTimes(t, row, len(image_t_s), source)


@dataclass(frozen=True)
class PoseMeasurements:
    """What the sensors say at each pose (window means on the navigation time base).

    Parameters
    ----------
    R_ned_body : ndarray, shape (P, 3, 3)
        Navigated attitude (compass correction if given, declination, mount).
    compass_heading_rad : ndarray, shape (P,)
        The heading as the compass gives it.
    depth_m : ndarray, shape (P,)
        Depth of the reference point from pressure (less the tide when given), metres.
    samples : ndarray of int, shape (P,)
        Navigation samples averaged (1 where interpolated).
    """

    R_ned_body: FloatArray
    compass_heading_rad: FloatArray
    depth_m: FloatArray
    samples: NDArray[np.int64]


def _window_means(
    t: FloatArray, t_s: FloatArray, columns: FloatArray, window_s: float
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Means of ``columns`` (N, c) over ``|t_s - t| <= window_s / 2``; interpolated where empty."""
    lo = np.searchsorted(t_s, t - 0.5 * window_s, side="left")
    hi = np.searchsorted(t_s, t + 0.5 * window_s, side="right")
    count = hi - lo
    cum = np.concatenate([np.zeros((1, columns.shape[1])), np.cumsum(columns, axis=0)])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (cum[hi] - cum[lo]) / count[:, None]
    empty = count == 0
    if np.any(empty):
        mean[empty] = np.stack([np.interp(t[empty], t_s, columns[:, c]) for c in range(columns.shape[1])], -1)
    return mean, np.maximum(count, 1).astype(np.int64)


def pose_measurements(
    inputs: NavInputs, t: FloatArray, window_s: float, tide: TideModel | None = None
) -> PoseMeasurements:
    """Attitude, compass heading and depth at pose times, each the mean over a window."""
    yaw, h = inputs.yaw_rad, inputs.compass_heading_rad
    columns = np.column_stack(
        [
            np.cos(yaw),
            np.sin(yaw),
            np.cos(h),
            np.sin(h),
            inputs.pitch_rad,
            np.unwrap(inputs.roll_rad),
            inputs.depth_m,
        ]
    )
    mean, count = _window_means(t, inputs.t_s, columns, window_s)
    depth = mean[:, 6] if tide is None else mean[:, 6] - tide.predict(t)
    return PoseMeasurements(
        R_ned_body=euler2rot(np.arctan2(mean[:, 1], mean[:, 0]), mean[:, 4], wrap_angle(mean[:, 5])),
        compass_heading_rad=np.arctan2(mean[:, 3], mean[:, 2]),
        depth_m=depth,
        samples=count,
    )
