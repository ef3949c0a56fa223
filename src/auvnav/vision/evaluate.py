"""Scoring loop closures against a simulated dive's truth (the ``loops`` section of ``auvnav evaluate``).

- True overlap of two images: a 9 x 7 grid of the left camera's pixels is cast from the true pose onto a
  level floor at the seafloor depth under the vehicle (true depth plus the DVL altitude) and projected
  into the other image's true pose; the overlap is the fraction that lands inside, averaged both ways.
- ``recall``: of the non-consecutive pairs (``j > i + 1``) with a true overlap of at least
  ``min_overlap`` (30%), the fraction found (accepted in ``loops.csv``).
- ``precision``: of all accepted pairs, the fraction that truly overlap and whose pose is right: its
  error is explained by its covariance (Mahalanobis distance within the chi-square 6-dof 99.9%
  quantile) or is small anyway (under 5 cm and 1 degree). ``within_5cm_1deg`` is the fraction with
  the small error alone.
- Errors: translation (metres) and rotation angle (degrees) of ``T_est^-1 T_true`` for the relative
  pose of body j in body i; ``mahalanobis_mean``: mean over accepted pairs of ``e^T C^-1 e``, ``e`` the
  error of ``(x, y, z, roll, pitch, yaw)`` and ``C`` the reported covariance (6 when it is honest:
  chi-square with 6 degrees of freedom).
- ``candidates_tested`` (from ``products/vision/summary.json``) and ``true_overlaps``: pairs, consecutive
  ones included, with a true overlap of at least ``min_overlap``.
- ``by_method`` (when ``loops.csv`` says how each pair was registered): count, precision, median
  errors and Mahalanobis distance of the loops from features and from images (direct registration).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.stats import chi2

from auvnav.dive import ImageIndex, read_dive
from auvnav.frames import angle_diff, rot2euler, se3, se3_inverse
from auvnav.products import LOOPS, VISION_SUMMARY
from auvnav.trajectory import Trajectory
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import T_body_cam, pixel_rays
from auvnav.vision.loopfile import LoopClosures, read_loops
from auvnav.vision.loops import image_altitude

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
MIN_OVERLAP = 0.3
CORRECT_TRANSLATION_M = 0.05
CORRECT_ROTATION_DEG = 1.0
CORRECT_PROBABILITY = 0.999
OVERLAP_CHUNK = 4096  # pairs projected at once: cv2.projectPoints also fills its Jacobian, 15 doubles a row


def _near_pairs(
    centre: FloatArray, reach: FloatArray, chunk: int = 1024
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Pairs ``i < j`` of footprints whose centres are within their two reaches, found a chunk of
    images at a time (a few high-altitude images must not make every image search their radius)."""
    tree = cKDTree(centre)
    r_max = float(reach.max())
    out_i, out_j = [], []
    for start in range(0, len(centre), chunk):
        rows = np.arange(start, min(start + chunk, len(centre)))
        found = tree.query_ball_point(centre[rows], reach[rows] + r_max, return_sorted=False)
        counts = np.array([len(f) for f in found])
        a = np.repeat(rows, counts)
        b = np.fromiter((k for f in found for k in f), dtype=np.intp, count=int(counts.sum()))
        keep = (b > a) & (np.linalg.norm(centre[a] - centre[b], axis=1) <= reach[a] + reach[b])
        out_i.append(a[keep])
        out_j.append(b[keep])
    return np.concatenate(out_i), np.concatenate(out_j)


def true_overlaps(
    T_ned_cam: FloatArray, floor_down_m: FloatArray, rig: StereoRig, *, samples: tuple[int, int] = (9, 7)
) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
    """Pairs of images whose true footprints overlap, and by how much.

    Parameters
    ----------
    T_ned_cam : ndarray, shape (N, 4, 4)
        True poses of the left camera.
    floor_down_m : ndarray, shape (N,)
        Depth of the (level) seafloor under each image, metres.
    rig : StereoRig

    Returns
    -------
    i, j : ndarray of int, i < j
    overlap : ndarray
        Mean of the two fractions of each footprint seen by the other image, 0..1.
    """
    cam = rig.left
    u, v = np.meshgrid(np.linspace(0, cam.width - 1, samples[0]), np.linspace(0, cam.height - 1, samples[1]))
    rays_cam = pixel_rays(cam, u.ravel(), v.ravel())  # (S, 3)
    R, c = T_ned_cam[:, :3, :3], T_ned_cam[:, :3, 3]
    rays = np.einsum("nij,sj->nsi", R, rays_cam)
    s = (floor_down_m - c[:, 2])[:, None] / np.maximum(rays[..., 2], 1e-3)
    ground = c[:, None, :] + s[..., None] * rays  # (N, S, 3)
    centre = ground.mean(axis=1)[:, :2]
    reach = np.max(np.linalg.norm(ground[..., :2] - centre[:, None, :], axis=2), axis=1)
    i, j = _near_pairs(centre, reach)

    def seen(a: NDArray[np.intp], b: NDArray[np.intp]) -> FloatArray:
        T_cam_ned = se3_inverse(T_ned_cam[b])
        p = np.einsum("nij,nsj->nsi", T_cam_ned[:, :3, :3], ground[a]) + T_cam_ned[:, None, :3, 3]
        z = p[..., 2]
        uv, _ = cv2.projectPoints(
            p.reshape(-1, 1, 3).astype(np.float64),
            np.zeros(3),
            np.zeros(3),
            cam.K,
            np.asarray(cam.D, dtype=float),
        )
        uv = uv.reshape(p.shape[0], p.shape[1], 2)
        inside = (z > 0) & (uv[..., 0] >= -0.5) & (uv[..., 0] <= cam.width - 0.5)
        inside &= (uv[..., 1] >= -0.5) & (uv[..., 1] <= cam.height - 0.5)
        return inside.mean(axis=1)

    overlap = np.empty(len(i))
    for k in range(0, len(i), OVERLAP_CHUNK):  # bounded memory: (chunk, samples, 3) at a time
        a, b = i[k : k + OVERLAP_CHUNK], j[k : k + OVERLAP_CHUNK]
        overlap[k : k + OVERLAP_CHUNK] = 0.5 * (seen(a, b) + seen(b, a))
    keep = overlap > 0
    return i[keep], j[keep], overlap[keep]


def relative_errors(
    loops: LoopClosures, truth_T_ned_body: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Translation error (m), rotation error (deg) and Mahalanobis distance of each loop against truth."""
    T_true = se3_inverse(truth_T_ned_body[loops.i]) @ truth_T_ned_body[loops.j]
    T_est = loops.T_i_j
    E = se3_inverse(T_est) @ T_true
    trans = np.linalg.norm(T_true[:, :3, 3] - loops.t_ij_m, axis=1)
    cos = np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)
    rot = np.degrees(np.arccos(cos))
    y_t, p_t, r_t = rot2euler(T_true[:, :3, :3])
    r, p, y = loops.rpy_ij_rad.T
    e = np.column_stack(
        [T_true[:, :3, 3] - loops.t_ij_m, angle_diff(r_t, r), angle_diff(p_t, p), angle_diff(y_t, y)]
    )
    maha = np.einsum("ni,ni->n", e, np.linalg.solve(loops.covariance, e[..., None])[..., 0])
    return trans, rot, maha


def score_loops(
    loops: LoopClosures,
    images: ImageIndex,
    truth: Trajectory,
    altitude_m: FloatArray,
    rig: StereoRig,
    candidates_tested: int | None,
    *,
    min_overlap: float = MIN_OVERLAP,
    group: Callable[[FloatArray], NDArray[np.str_]] | None = None,
) -> dict[str, Any]:
    """The ``loops`` section (module docstring) from the loop table and the truth at the image times.

    ``group``: a label for true positions (north, east; (N, 2)); the section then also gives the
    recall over the pairs whose footprint centres' midpoint has each label (``recall_by_group``:
    found, pairs).
    """
    t = images.t_s
    inside = (t >= truth.t_s[0]) & (t <= truth.t_s[-1])
    at = truth.interpolate(np.clip(t, truth.t_s[0], truth.t_s[-1]))
    T_body = se3(at.R_ned_body, at.p_ned_m)
    T_cam = T_body @ T_body_cam(rig)
    floor = at.p_ned_m[:, 2] + altitude_m
    oi, oj, ov = true_overlaps(T_cam[inside], floor[inside], rig)
    rows = np.flatnonzero(inside)
    oi, oj = rows[oi], rows[oj]
    overlap = {(int(a), int(b)): float(o) for a, b, o in zip(oi, oj, ov, strict=True)}
    big = {k for k, o in overlap.items() if o >= min_overlap}
    big_loops = {k for k in big if k[1] - k[0] > 1}
    found = {(int(a), int(b)) for a, b in zip(loops.i, loops.j, strict=True)}
    trans, rot, maha = relative_errors(loops, T_body) if len(loops) else (np.zeros(0),) * 3
    small = (trans < CORRECT_TRANSLATION_M) & (rot < CORRECT_ROTATION_DEG)
    overlapping = np.array(
        [overlap.get((int(a), int(b)), 0.0) > 0 for a, b in zip(loops.i, loops.j, strict=True)],
        dtype=bool,
    )
    correct = overlapping & (small | (maha <= chi2.ppf(CORRECT_PROBABILITY, 6)))
    nonconsec = loops.j - loops.i > 1

    def median(x: FloatArray) -> float:
        return float(np.median(x)) if len(x) else float("nan")

    extra: dict[str, Any] = {}
    if loops.method is not None:
        extra["by_method"] = {
            m: {
                "n": int((loops.method == m).sum()),
                "precision": float(correct[loops.method == m].mean()),
                "translation_error_median_m": median(trans[loops.method == m]),
                "rotation_error_median_deg": median(rot[loops.method == m]),
                "mahalanobis_median": median(maha[loops.method == m]),
            }
            for m in np.unique(loops.method)
        }
    if group is not None and big_loops:
        pairs = np.array(sorted(big_loops))
        axis = T_cam[:, :3, 2]  # the optical axis, where it meets the level floor
        ground = T_cam[:, :3, 3] + axis * ((floor - T_cam[:, 2, 3]) / axis[:, 2])[:, None]
        labels = group(0.5 * (ground[pairs[:, 0], :2] + ground[pairs[:, 1], :2]))
        hit = np.array([(int(a), int(b)) in found for a, b in pairs])
        extra["recall_by_group"] = {
            str(g): [int(hit[labels == g].sum()), int((labels == g).sum())] for g in np.unique(labels)
        }
    return {
        **extra,
        "n": len(loops),
        "n_nonconsecutive": int(nonconsec.sum()),
        "recall": len(big_loops & found) / len(big_loops) if big_loops else float("nan"),
        "precision": float(correct.mean()) if len(correct) else float("nan"),
        "within_5cm_1deg": float(small.mean()) if len(small) else float("nan"),
        "translation_error_median_m": median(trans),
        "rotation_error_median_deg": median(rot),
        "translation_error_median_nonconsecutive_m": median(trans[nonconsec]),
        "rotation_error_median_nonconsecutive_deg": median(rot[nonconsec]),
        "mahalanobis_mean": float(np.mean(maha)) if len(maha) else float("nan"),
        "mahalanobis_median": median(maha),
        "candidates_tested": candidates_tested,
        "true_overlaps": len(big),
        "true_overlaps_nonconsecutive": len(big_loops),
        "candidates_per_true_overlap": candidates_tested / len(big)
        if candidates_tested and big
        else float("nan"),
    }


def loops_section(
    dive_path: Path,
    truth: Trajectory,
    distance_m: float,
    *,
    group: Callable[[FloatArray], NDArray[np.str_]] | None = None,
) -> dict[str, Any] | None:
    """``auvnav evaluate``'s ``loops`` section, or None when ``products/vision/loops.csv`` is absent
    (``group``: as :func:`score_loops`)."""
    dive_path = Path(dive_path)
    path = LOOPS.path(dive_path)
    if not path.is_file():
        return None
    dive = read_dive(dive_path)
    if dive.images is None or dive.vehicle.stereo is None:
        log.warning("%s: the dive has no images or no stereo calibration; loops not scored", dive_path)
        return None
    loops = read_loops(path, n_poses=len(dive.images))
    summary_path = VISION_SUMMARY.path(dive_path)
    tested = None
    if summary_path.is_file():
        tested = json.loads(summary_path.read_text(encoding="utf-8")).get("candidates_tested")
    return score_loops(
        loops,
        dive.images,
        truth,
        image_altitude(dive, dive.images.t_s),
        dive.vehicle.stereo,
        tested,
        group=group,
    )
