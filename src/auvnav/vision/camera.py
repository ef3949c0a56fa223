"""Stereo camera geometry: rectification of feature points, triangulation with covariance, image checks.

The calibration is the vehicle file's :class:`~auvnav.vehicle.StereoRig` (pinhole with OpenCV
radial-tangential distortion, ``X_right = R_right_left X_left + t_right_left``), read inline or from an
OpenCV ``stereoCalibrate`` file or a pair of ROS ``camera_info`` files by :mod:`auvnav.vehicle`.
Only feature points are rectified (``cv2.undistortPoints`` with the rectifying rotation and
projection of ``cv2.stereoRectify``), never whole images: the same geometry for a fraction of the work.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from auvnav.errors import ConfigError
from auvnav.frames import se3
from auvnav.vehicle import CameraModel, StereoRig

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Rectification:
    """Rectified stereo geometry of a rig (``cv2.stereoRectify`` with zero disparity at infinity).

    Parameters
    ----------
    R1, R2 : ndarray, shape (3, 3)
        Rotate left/right camera coordinates into the rectified left/right frames.
    P1, P2 : ndarray, shape (3, 4)
        Rectified projections, pixels.
    f_px, cx_px, cy_px : float
        Rectified focal length and principal point (shared by both views).
    baseline_m : float
        Distance between the optical centres, metres.
    """

    R1: FloatArray
    R2: FloatArray
    P1: FloatArray
    P2: FloatArray
    f_px: float
    cx_px: float
    cy_px: float
    baseline_m: float


@dataclass(frozen=True)
class StereoGeometry:
    """What triangulation needs of a rectification: the rectified focal length, principal point and
    baseline, and the rotation of the left camera into its rectified frame (a :class:`Rectification`
    has them too)."""

    f_px: float
    cx_px: float
    cy_px: float
    baseline_m: float
    R1: FloatArray


def rectification(rig: StereoRig) -> Rectification:
    """The rectified geometry of ``rig`` (both cameras must share an image size)."""
    if (rig.left.width, rig.left.height) != (rig.right.width, rig.right.height):
        raise ConfigError(
            f"stereo calibration: left and right image sizes differ ({rig.left.width}x{rig.left.height} "
            f"and {rig.right.width}x{rig.right.height})"
        )
    R1, R2, P1, P2, _Q, _, _ = cv2.stereoRectify(
        rig.left.K,
        np.asarray(rig.left.D, dtype=float),
        rig.right.K,
        np.asarray(rig.right.D, dtype=float),
        (rig.left.width, rig.left.height),
        np.asarray(rig.R_right_left, dtype=float),
        np.asarray(rig.t_right_left_m, dtype=float).reshape(3, 1),
        flags=cv2.CALIB_ZERO_DISPARITY,
        alpha=-1,
    )
    f = float(P1[0, 0])
    baseline = -float(P2[0, 3]) / float(P2[0, 0])
    if baseline <= 0:
        raise ConfigError(
            "stereo calibration: the right camera is not to the right of the left one "
            f"(rectified baseline {baseline:.4f} m); left and right swapped?"
        )
    return Rectification(R1, R2, P1, P2, f, float(P1[0, 2]), float(P1[1, 2]), baseline)


def pixel_rays(cam: CameraModel, u_px: FloatArray, v_px: FloatArray) -> FloatArray:
    """Unit ray directions (camera frame) through pixels, lens distortion removed.

    Parameters
    ----------
    cam : CameraModel
    u_px, v_px : ndarray, same shape
        Pixel coordinates (column, row), pixel centres at integers.

    Returns
    -------
    ndarray, shape (..., 3), unit vectors, camera frame (x right, y down, z forward).
    """
    pts = np.stack([u_px, v_px], -1).reshape(-1, 1, 2).astype(np.float64)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    xy = cv2.undistortPoints(pts, cam.K, np.asarray(cam.D, dtype=float), criteria=criteria)
    rays = np.concatenate([xy.reshape(-1, 2), np.ones((xy.shape[0], 1))], axis=1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    return rays.reshape(*np.shape(u_px), 3)


def rectify_points(uv_px: FloatArray, cam: CameraModel, R: FloatArray, P: FloatArray) -> FloatArray:
    """Pixel coordinates (N, 2) of a raw (distorted) image mapped into the rectified image."""
    if len(uv_px) == 0:
        return np.zeros((0, 2))
    pts = np.asarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(pts, cam.K, np.asarray(cam.D, dtype=float), R=R, P=P).reshape(-1, 2)


def triangulate(
    uv_left_px: FloatArray,
    uv_right_px: FloatArray,
    rect: Rectification | StereoGeometry,
    sigma_common_px: float,
    sigma_independent_px: float,
    *,
    sigma_disparity_px: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """3-D points and their covariances from rectified stereo matches.

    A keypoint's position error has a part common to the left and right images (the detector's bias on
    a patch seen almost identically by both cameras: it moves the point sideways) and a part independent
    between them (sensor noise: it changes the disparity, hence the range).

    Parameters
    ----------
    uv_left_px, uv_right_px : ndarray, shape (N, 2)
        Rectified pixel coordinates of each match.
    rect : Rectification or StereoGeometry
    sigma_common_px, sigma_independent_px : float
        1-sigma of the two parts of a keypoint's position error, rectified pixels, each axis.
    sigma_disparity_px : ndarray, shape (N,), optional
        A further error of each match's right column, rectified pixels, 1-sigma (a match whose patch
        may straddle a depth edge: :func:`auvnav.vision.stereo.disparity_spread`).

    Returns
    -------
    p_cam_m : ndarray, shape (N, 3)
        Points in the (unrectified) left camera frame, metres.
    cov_cam_m2 : ndarray, shape (N, 3, 3)
        First-order covariance of each point, left camera frame: ``J C J^T`` with J the Jacobian of
        ``X = (u_l - c_x) b / d``, ``Y = (v - c_y) b / d``, ``Z = f b / d`` (``d = u_l - u_r``,
        ``v = (v_l + v_r) / 2``) with respect to ``(u_l, u_r, v_l, v_r)`` and C their covariance.
    """
    ul, vl = uv_left_px[:, 0], uv_left_px[:, 1]
    ur, vr = uv_right_px[:, 0], uv_right_px[:, 1]
    f, b, cx, cy = rect.f_px, rect.baseline_m, rect.cx_px, rect.cy_px
    d = ul - ur
    v = 0.5 * (vl + vr)
    k = b / d
    X, Y, Z = (ul - cx) * k, (v - cy) * k, f * k
    k2 = b / d**2
    n = len(d)
    J = np.zeros((n, 3, 4))  # columns: u_l, u_r, v_l, v_r
    J[:, 0, 0] = k - (ul - cx) * k2
    J[:, 0, 1] = (ul - cx) * k2
    J[:, 1, 0] = -(v - cy) * k2
    J[:, 1, 1] = (v - cy) * k2
    J[:, 1, 2] = J[:, 1, 3] = 0.5 * k
    J[:, 2, 0] = -f * k2
    J[:, 2, 1] = f * k2
    c2, i2 = sigma_common_px**2, sigma_independent_px**2
    C = np.array([[c2 + i2, c2, 0, 0], [c2, c2 + i2, 0, 0], [0, 0, c2 + i2, c2], [0, 0, c2, c2 + i2]])
    cov_rect = (J @ C) @ np.swapaxes(J, 1, 2)  # matrix products: einsum's three-operand path is 5x slower
    if sigma_disparity_px is not None:
        ju = J[:, :, 1]
        cov_rect += (
            ju[:, :, None]
            * ju[:, None, :]
            * (np.asarray(sigma_disparity_px, dtype=float) ** 2)[:, None, None]
        )
    p_rect = np.stack([X, Y, Z], axis=1)
    R1 = np.asarray(rect.R1, dtype=float)
    return p_rect @ R1, R1.T @ cov_rect @ R1


_MAPS: dict[str, tuple[tuple[NDArray, NDArray], tuple[NDArray, NDArray]]] = {}


def rectify_images(
    left: NDArray[np.uint8], right: NDArray[np.uint8], rig: StereoRig, rect: Rectification
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """Both images resampled into the rectified geometry (bilinear); the maps are made once per rig."""
    key = rig_digest(rig)
    if key not in _MAPS:
        size = (rig.left.width, rig.left.height)
        _MAPS[key] = tuple(  # type: ignore[assignment]
            cv2.initUndistortRectifyMap(cam.K, np.asarray(cam.D, dtype=float), R, P, size, cv2.CV_16SC2)
            for cam, R, P in ((rig.left, rect.R1, rect.P1), (rig.right, rect.R2, rect.P2))
        )
    (l1, l2), (r1, r2) = _MAPS[key]
    return cv2.remap(left, l1, l2, cv2.INTER_LINEAR), cv2.remap(right, r1, r2, cv2.INTER_LINEAR)


#: ``cv2.remap`` takes maps under 32,767 pixels a side: :func:`remap_rows` lays a list of points out in
#: rows this long.
REMAP_ROW = 4096


def remap_rows(*values: NDArray) -> list[NDArray]:
    """1-D arrays of equal length (the coordinates of a list of points) as 2-D maps for ``cv2.remap``,
    in rows of :data:`REMAP_ROW` (the last padded with its last value): the first ``n`` values of a
    remapped result, raveled, are the points in order."""
    n = len(values[0])
    cols = max(1, min(n, REMAP_ROW))
    return [np.pad(v, (0, -n % cols), mode="edge").reshape(-1, cols) for v in values]


def check_image_size(cam: CameraModel, shape: tuple[int, ...], name: str) -> None:
    """Raise a one-line :class:`ConfigError` when an image does not have the calibrated size."""
    h, w = shape[:2]
    if (w, h) != (cam.width, cam.height):
        raise ConfigError(
            f"{name}: image is {w}x{h} but the stereo calibration in the vehicle file is for "
            f"{cam.width}x{cam.height}; images and calibration must match (scale the calibration with "
            "the images)"
        )


def T_body_cam(rig: StereoRig) -> FloatArray:
    """Pose of the left camera in the body frame, 4x4."""
    return se3(rig.mount.R_body_sensor, rig.mount.lever_arm_body_m)


def rig_digest(rig: StereoRig) -> str:
    """A short hash of a rig's calibration (for cache keys)."""
    h = hashlib.sha1()
    for cam in (rig.left, rig.right):
        h.update(np.array([cam.width, cam.height], dtype=np.int64).tobytes())
        h.update(np.asarray(cam.K, dtype=float).tobytes())
        h.update(np.asarray(cam.D, dtype=float).tobytes())
        h.update((cam.bayer or "").encode())
    h.update(np.asarray(rig.R_right_left, dtype=float).tobytes())
    h.update(np.asarray(rig.t_right_left_m, dtype=float).tobytes())
    return h.hexdigest()[:16]
