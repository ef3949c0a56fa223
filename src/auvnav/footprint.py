"""Where a camera's image lies on the seafloor, and how much two such footprints overlap.

Shared by the simulator (its truth loop closures) and processing (coverage, reconstruction): a
footprint is the left camera's image rectangle (pinhole, the corner rays) projected on the horizontal
plane at the seafloor's depth below the camera; two footprints overlap by the area of their
intersection (convex polygon clipping, Sutherland and Hodgman 1974, "Reentrant polygon clipping",
CACM 17(1)) over the smaller one's.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav.frames import FloatArray
from auvnav.vehicle import StereoRig


class SeafloorLike(Protocol):
    """Anything with a vectorised seafloor depth (positive down, metres, local NED)."""

    def depth_m(self, north_m: FloatArray, east_m: FloatArray) -> FloatArray: ...


def footprints(T_ned_body: FloatArray, rig: StereoRig, seafloor: SeafloorLike) -> FloatArray:
    """The left camera's image rectangle on the seafloor, as north-east polygons.

    Parameters
    ----------
    T_ned_body : ndarray, shape (P, 4, 4)
        Body poses, metres, local NED.
    rig : StereoRig
        The stereo rig (its left camera and mount).
    seafloor : object with ``depth_m(north_m, east_m)``

    Returns
    -------
    ndarray, shape (P, 4, 2)
        Corners (north, east), metres, in image order (top-left, top-right, bottom-right, bottom-left):
        the corner rays (pinhole, distortion ignored) meet the horizontal plane at the seafloor's
        depth below the camera.
    """
    cam = rig.left
    u = np.array([0.0, cam.width, cam.width, 0.0])
    v = np.array([0.0, 0.0, cam.height, cam.height])
    rays_cam = np.linalg.solve(cam.K, np.stack([u, v, np.ones(4)]))  # (3, 4)
    R_ned_cam = T_ned_body[:, :3, :3] @ rig.mount.R_body_sensor
    c_ned = T_ned_body[:, :3, 3] + T_ned_body[:, :3, :3] @ rig.mount.lever_arm_body_m
    rays = R_ned_cam @ rays_cam  # (P, 3, 4)
    floor = np.asarray(seafloor.depth_m(c_ned[:, 0], c_ned[:, 1]), dtype=float)
    height = floor - c_ned[:, 2]
    down = np.maximum(rays[:, 2, :], 1e-6)  # a ray at or above the horizon: far away
    s = (height[:, None] / down)[:, None, :]
    return np.swapaxes(c_ned[:, :2, None] + s * rays[:, :2, :], 1, 2)


def _clip(subject: list[tuple[float, float]], a: tuple[float, float], b: tuple[float, float]) -> list:
    """The part of a polygon on the left of the directed edge a -> b (one Sutherland-Hodgman step)."""

    def side(p: tuple[float, float]) -> float:
        return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])

    out = []
    for k, p in enumerate(subject):
        q = subject[k - 1]
        sp, sq = side(p), side(q)
        if sp >= 0.0:
            if sq < 0.0:
                out.append(_cross(q, p, sq, sp))
            out.append(p)
        elif sq >= 0.0:
            out.append(_cross(q, p, sq, sp))
    return out


def _cross(q: tuple[float, float], p: tuple[float, float], sq: float, sp: float) -> tuple[float, float]:
    w = sq / (sq - sp)
    return (q[0] + w * (p[0] - q[0]), q[1] + w * (p[1] - q[1]))


def _area(poly: list[tuple[float, float]]) -> float:
    """Signed area (shoelace), positive counter-clockwise in (x, y)."""
    return 0.5 * sum(poly[k - 1][0] * p[1] - p[0] * poly[k - 1][1] for k, p in enumerate(poly))


def polygon_overlap(a: FloatArray, b: FloatArray) -> float:
    """Overlap of two convex polygons (K, 2), either orientation: intersection over the smaller area."""
    pa = [tuple(map(float, p)) for p in a]
    pb = [tuple(map(float, p)) for p in b]
    if _area(pa) < 0:
        pa.reverse()
    if _area(pb) < 0:
        pb.reverse()
    inter = pa
    for k in range(len(pb)):
        inter = _clip(inter, pb[k - 1], pb[k])
        if not inter:
            return 0.0
    smaller = min(_area(pa), _area(pb))
    return _area(inter) / smaller if smaller > 0 else 0.0


def overlapping_pairs(polygons: FloatArray) -> tuple[NDArray[np.int64], FloatArray]:
    """Pairs (i < j) of overlapping footprints, with their overlap (:func:`polygon_overlap`).

    Parameters
    ----------
    polygons : ndarray, shape (P, K, 2)
        Convex footprints.

    Returns
    -------
    pairs : ndarray of int64, shape (M, 2)
        Sorted by i, then j.
    overlap : ndarray, shape (M,)
        In (0, 1].
    """
    if len(polygons) < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    centre = polygons.mean(axis=1)
    radius = np.max(np.linalg.norm(polygons - centre[:, None, :], axis=2), axis=1)
    tree = cKDTree(centre)
    candidates = tree.query_pairs(2.0 * float(radius.max()), output_type="ndarray")
    if len(candidates) == 0:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    i, j = candidates[:, 0], candidates[:, 1]
    near = np.linalg.norm(centre[i] - centre[j], axis=1) < radius[i] + radius[j]
    candidates = np.sort(candidates[near], axis=1)
    overlap = np.array([polygon_overlap(polygons[a], polygons[b]) for a, b in candidates])
    keep = overlap > 0.0
    order = np.lexsort((candidates[keep, 1], candidates[keep, 0]))
    return candidates[keep][order].astype(np.int64), overlap[keep][order]
