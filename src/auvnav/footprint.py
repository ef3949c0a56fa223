"""Where a camera's image lies on the seafloor, and how much two such footprints overlap.

Shared by the simulator (its truth loop closures) and processing (coverage, reconstruction): a
footprint is a camera's image rectangle (pinhole, the corner rays) projected on the horizontal
plane at the seafloor's depth below the camera (:func:`footprints` for the left camera over a
seafloor, :func:`footprints_on_plane` for either camera over a given floor depth per pose); the
stereo footprint (:func:`stereo_footprints`) is where both cameras see, the intersection of the two.
Two footprints overlap by the area of their intersection (convex polygon clipping, Sutherland and
Hodgman 1974, "Reentrant polygon clipping", CACM 17(1)) over the smaller one's.
"""

from __future__ import annotations

from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav.frames import FloatArray
from auvnav.vehicle import CameraModel, StereoRig


class SeafloorLike(Protocol):
    """Anything with a vectorised seafloor depth (positive down, metres, local NED)."""

    def depth_m(self, north_m: FloatArray, east_m: FloatArray) -> FloatArray: ...


def _camera_pose(
    T_ned_body: FloatArray, rig: StereoRig, camera: Literal["left", "right"]
) -> tuple[CameraModel, FloatArray, FloatArray]:
    """The camera model, ``R_ned_cam`` (P, 3, 3) and the optical centre (P, 3) in local NED."""
    R_body_left = rig.mount.R_body_sensor
    c_body = rig.mount.lever_arm_body_m
    if camera == "left":
        cam, R_body_cam = rig.left, R_body_left
    else:  # X_right = R X_left + t: the right centre is -R^T t in the left frame
        cam = rig.right
        R_body_cam = R_body_left @ rig.R_right_left.T
        c_body = c_body + R_body_left @ (-rig.R_right_left.T @ rig.t_right_left_m)
    R_ned_body = T_ned_body[:, :3, :3]
    return cam, R_ned_body @ R_body_cam, T_ned_body[:, :3, 3] + R_ned_body @ c_body


def footprints_on_plane(
    T_ned_body: FloatArray,
    rig: StereoRig,
    floor_down_m: FloatArray,
    *,
    camera: Literal["left", "right"] = "left",
) -> FloatArray:
    """A camera's image rectangle on a horizontal floor, as north-east polygons.

    Parameters
    ----------
    T_ned_body : ndarray, shape (P, 4, 4)
        Body poses, metres, local NED.
    rig : StereoRig
    floor_down_m : ndarray, shape (P,)
        Depth of the floor under each pose, metres, positive down, local NED.
    camera : {"left", "right"}

    Returns
    -------
    ndarray, shape (P, 4, 2)
        Corners (north, east), metres, in image order (top-left, top-right, bottom-right, bottom-left):
        the corner rays (pinhole, distortion ignored) meet the plane ``down = floor_down_m``.
    """
    cam, R_ned_cam, c_ned = _camera_pose(np.asarray(T_ned_body, dtype=float), rig, camera)
    u = np.array([0.0, cam.width, cam.width, 0.0])
    v = np.array([0.0, 0.0, cam.height, cam.height])
    rays_cam = np.linalg.solve(cam.K, np.stack([u, v, np.ones(4)]))  # (3, 4)
    rays = R_ned_cam @ rays_cam  # (P, 3, 4)
    height = np.asarray(floor_down_m, dtype=float) - c_ned[:, 2]
    down = np.maximum(rays[:, 2, :], 1e-6)  # a ray at or above the horizon: far away
    s = (height[:, None] / down)[:, None, :]
    return np.swapaxes(c_ned[:, :2, None] + s * rays[:, :2, :], 1, 2)


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
        As :func:`footprints_on_plane`, the plane at the seafloor's depth below the left camera.
    """
    T = np.asarray(T_ned_body, dtype=float)
    _, _, c_ned = _camera_pose(T, rig, "left")
    floor = np.asarray(seafloor.depth_m(c_ned[:, 0], c_ned[:, 1]), dtype=float)
    return footprints_on_plane(T, rig, floor)


#: Vertices of a stereo footprint: the intersection of two quadrilaterals has at most eight.
STEREO_VERTICES = 8


def stereo_footprints(T_ned_body: FloatArray, rig: StereoRig, floor_down_m: FloatArray) -> FloatArray:
    """Where both cameras of the rig see a horizontal floor: the intersection of their footprints.

    Parameters
    ----------
    T_ned_body : ndarray, shape (P, 4, 4)
        Body poses, metres, local NED.
    rig : StereoRig
    floor_down_m : ndarray, shape (P,)
        Depth of the floor under each pose, metres, positive down.

    Returns
    -------
    ndarray, shape (P, 8, 2)
        Convex polygons (north, east), metres, counter-clockwise in (north, east); those with fewer
        than eight corners repeat their last one. A pose whose two footprints do not meet gives
        eight copies of the left footprint's centre (zero area).
    """
    left = footprints_on_plane(T_ned_body, rig, floor_down_m, camera="left")
    right = footprints_on_plane(T_ned_body, rig, floor_down_m, camera="right")
    out = np.empty((len(left), STEREO_VERTICES, 2))
    if len(left) == 0:
        return out
    inter, count = convex_intersections(left, right)
    width = min(inter.shape[1], STEREO_VERTICES)
    out[:, :width] = inter[:, :width]
    out[:, width:] = inter[:, -1:]
    for k in np.flatnonzero((count == 0) | (count > STEREO_VERTICES)):  # apart, or corners on an edge
        poly = convex_intersection(left[k], right[k])
        if len(poly) == 0:
            out[k] = left[k].mean(axis=0)
            continue
        poly = poly[:STEREO_VERTICES]
        out[k, : len(poly)] = poly
        out[k, len(poly) :] = poly[-1]
    return out


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


def _ccw(poly: FloatArray) -> list[tuple[float, float]]:
    out = [(p[0], p[1]) for p in np.asarray(poly, dtype=float).tolist()]
    if _area(out) < 0:
        out.reverse()
    return out


def polygon_area(poly: FloatArray) -> float:
    """Area of a simple polygon (K, 2), either orientation (repeated corners add nothing)."""
    return abs(_area([(p[0], p[1]) for p in np.asarray(poly, dtype=float).tolist()]))


def convex_intersection(a: FloatArray, b: FloatArray) -> FloatArray:
    """The intersection of two convex polygons (K, 2), either orientation, as a polygon (M, 2),
    counter-clockwise in the coordinates' (x, y) order; shape (0, 2) when they do not meet."""
    pa, pb = _ccw(a), _ccw(b)
    inter = pa
    for k in range(len(pb)):
        inter = _clip(inter, pb[k - 1], pb[k])
        if not inter:
            return np.zeros((0, 2))
    return np.array(inter, dtype=float)


def polygon_overlap(a: FloatArray, b: FloatArray) -> float:
    """Overlap of two convex polygons (K, 2), either orientation: intersection over the smaller area."""
    pa, pb = _ccw(a), _ccw(b)
    inter = pa
    for k in range(len(pb)):
        inter = _clip(inter, pb[k - 1], pb[k])
        if not inter:
            return 0.0
    smaller = min(_area(pa), _area(pb))
    return _area(inter) / smaller if smaller > 0 else 0.0


def _signed_areas(polys: FloatArray) -> FloatArray:
    """Signed areas (shoelace) of polygons (P, K, 2), positive counter-clockwise in (x, y); repeated
    corners add nothing."""
    x, y = polys[..., 0], polys[..., 1]
    xp, yp = np.roll(x, 1, axis=-1), np.roll(y, 1, axis=-1)
    return 0.5 * np.sum(xp * y - x * yp, axis=-1)


def _ccw_batch(polys: FloatArray) -> FloatArray:
    """Polygons (P, K, 2) with their corners reversed where clockwise."""
    polys = np.asarray(polys, dtype=float)
    return np.where((_signed_areas(polys) < 0)[:, None, None], polys[:, ::-1], polys)


def _clip_batch(
    subject: FloatArray, count: NDArray[np.intp], a: FloatArray, b: FloatArray
) -> tuple[FloatArray, NDArray[np.intp]]:
    """One Sutherland-Hodgman step (:func:`_clip`) for P polygons at once: the part of each subject
    (P, M, 2; its first ``count`` corners, the rest repeating the last) on the left of its edge a -> b
    (each (P, 2)); returns the clipped polygons, padded the same way, and their corner counts."""
    P, M, _ = subject.shape
    e = b - a
    side = e[:, None, 0] * (subject[..., 1] - a[:, None, 1]) - e[:, None, 1] * (
        subject[..., 0] - a[:, None, 0]
    )
    prev, sprev = np.roll(subject, 1, axis=1), np.roll(side, 1, axis=1)
    valid = np.arange(M)[None, :] < count[:, None]
    # the padding repeats the last corner: the corner before the first is the last valid one
    last = np.maximum(count - 1, 0)
    prev[:, 0], sprev[:, 0] = subject[np.arange(P), last], side[np.arange(P), last]
    inside, pinside = side >= 0.0, sprev >= 0.0
    with np.errstate(invalid="ignore", divide="ignore"):  # no crossing there: not kept
        w = sprev / (sprev - side)
        crossing = prev + w[..., None] * (subject - prev)
    slots = np.stack([crossing, subject], axis=2).reshape(P, 2 * M, 2)
    keep = np.stack([valid & (inside != pinside), valid & inside], axis=2).reshape(P, 2 * M)
    n = keep.sum(axis=1)
    width = max(int(n.max()) if P else 0, 1)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    out = np.take_along_axis(slots, order[..., None], axis=1)
    pad = np.arange(width)[None, :] >= n[:, None]
    fill = out[np.arange(P), np.maximum(n - 1, 0)]
    out = np.where(pad[..., None], fill[:, None, :], out)
    return out, n


def convex_intersections(a: FloatArray, b: FloatArray) -> tuple[FloatArray, NDArray[np.intp]]:
    """The intersections of P pairs of convex polygons at once (:func:`convex_intersection`).

    Parameters
    ----------
    a, b : ndarray, shape (P, K, 2) and (P, L, 2)
        Convex polygons, either orientation (repeated corners allowed).

    Returns
    -------
    polygons : ndarray, shape (P, M, 2)
        Counter-clockwise in the coordinates' (x, y) order, padded by repeating the last corner.
    count : ndarray of int, shape (P,)
        Corners of each (0: the two do not meet; its row is then meaningless).
    """
    inter, pb = _ccw_batch(a), _ccw_batch(b)
    count = np.full(len(inter), inter.shape[1], dtype=np.intp)
    for k in range(pb.shape[1]):
        inter, count = _clip_batch(inter, count, pb[:, k - 1], pb[:, k])
    return inter, count


def polygon_overlaps(a: FloatArray, b: FloatArray) -> FloatArray:
    """:func:`polygon_overlap` of P pairs of convex polygons (P, K, 2) at once, shape (P,)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if len(a) == 0:
        return np.zeros(0)
    inter, count = convex_intersections(a, b)
    area = np.where(count > 0, np.abs(_signed_areas(inter)), 0.0)
    smaller = np.minimum(np.abs(_signed_areas(a)), np.abs(_signed_areas(b)))
    return np.where(smaller > 0, area / np.where(smaller > 0, smaller, 1.0), 0.0)


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
