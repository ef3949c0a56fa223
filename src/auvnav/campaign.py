"""Several dives in one frame (``auvnav campaign DIVE... --out CAMPAIGN``): inter-dive loop closures,
one joint graph, the campaign's products.

Each dive needs its SLAM (``products/slam/``: ``trajectory.csv`` with its marginal sigmas,
``graph.g2o``, ``summary.json``). The common frame is local NED about the first dive's origin; a dive
whose origin differs is shifted by its origin's position in it (a translation: the meridians'
convergence across a site, a millionth of a radian per 100 m, is neglected).

**Inter-dive loop-closure candidates** (dives A < B, each pair), from the dives' GPS-referenced SLAM
trajectories and their uncertainty:

1. *Seeds*: every ``seed_every``-th image of A against every image of B whose position lies within
   ``reach + search_sigmas * sqrt(sigma_A^2 + sigma_B^2)`` (horizontal, the marginal sigmas; ``reach``
   the centre distance at which two footprints still overlap by ``min_overlap``, from the rig and the
   median altitude). Verified.
2. *Dense*: the verified seeds measure where B lies against A (each seed's relative pose predicts
   B's position from A's); each image of A takes the offset of its nearest seeds in time (their
   median, and their spread as the new uncertainty, at least ``dense_sigma_floor_m``) and is tested
   against its ``max_per_image`` nearest images of B so corrected, within the new search radius.

A candidate is verified by the registration given to :func:`run_campaign` (a callable: images of two
dives and their prior relative pose and sigma from the trajectories above, the seeds' correction
applied to the dense candidates -> verified, relative pose, covariance):
:class:`ImageRegistration`, the loop stage's own verification of the two dives' images (their
feature caches, :func:`auvnav.vision.registration.register` with the prior, the loop stage's gates on
the displacement and heading against the prior), or, for simulated dives without images and chosen
explicitly (``--truth-loops``), :class:`auvnav.sim.repeat.TruthRegistration`, a testing aid.

**Selection**: the verified inter-dive loop closures go through pairwise consistency against both
dives' odometry (:func:`auvnav.slam.pcm.select_pairwise`), the dives' own loop closures through their
own (:mod:`auvnav.slam.pcm`).

**Joint graph**: each dive's sensor graph rebuilt as its SLAM built it (its loop file, compass mode,
correction and tide, from its ``summary.json``) with the common origin (so its GPS fixes are in the
common frame), its keys renamed per dive; the inter-dive loop closures between them (Cauchy kernel);
solved by Levenberg-Marquardt (:func:`auvnav.slam.optimize.lm_solve`) from the dives' own solutions.

Products (in ``CAMPAIGN/``, written into a temporary folder and renamed into place):

- ``campaign.yaml``: the dives (paths, names, origin offsets), the common origin, the settings;
- ``dives/<name>/trajectory.csv``: each dive's image poses in the common frame;
- ``inter_dive_loops.csv``: every verified inter-dive loop closure (dives, image rows, times, relative
  pose as the loop-file format's ``x, y, z, roll, pitch, yaw`` in metres and degrees, ``kept``, the
  chi-square at the joint solution);
- ``dem_difference.tif`` and ``changes.csv`` where two dives have a reconstruction
  (``products/recon/dem.tif``): the later DEM less the earlier on the earlier's grid, each DEM shifted
  by how far the joint solution moved its dive, less the median difference (a tide datum error),
  over the cells that at least ``change_min_support`` stereo pairs of each dive saw (their footprints
  on the floor at the DVL's altitude, :func:`image_support`; not checked for a dive without a stereo
  calibration); regions where the difference exceeds ``change_threshold_m`` (rises and falls apart; cells within
  ``change_merge_m`` of each other joined: a change seen through the gaps between lines is one) over at least
  ``change_min_area_m2``, with the peak change and its position;
- ``summary.json``.
"""

from __future__ import annotations

import json
import logging
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav import products as P
from auvnav.config import dump_yaml, load_yaml
from auvnav.dive import Dive, image_files, read_dive
from auvnav.errors import AuvnavError, DiveFormatError, InsufficientDataError, OutputExistsError, Problem
from auvnav.footprint import footprints_on_plane
from auvnav.frames import FloatArray, GeodeticOrigin, geodetic2ned, rot2euler, se3, se3_inverse
from auvnav.raster import map2ned, ned2map
from auvnav.streams import write_json
from auvnav.trajectory import Trajectory, read_trajectory, write_trajectory

log = logging.getLogger(__name__)

CAMPAIGN_FILE = "campaign.yaml"
INTER_DIVE_LOOPS_FILE = "inter_dive_loops.csv"
SUMMARY_FILE = "summary.json"
DEM_DIFFERENCE_FILE = "dem_difference.tif"
CHANGES_FILE = "changes.csv"
FORMAT = "auvnav-campaign/1"
#: Centre distance at which two footprints still overlap, metres, when the vehicle has no stereo rig
#: calibration (the default rig's footprint is about 1 m along track at 2 m altitude).
DEFAULT_REACH_M = 0.8

#: The registration of candidate pairs: (dive a, its image rows, dive b, its image rows, the prior
#: body pose of b in a (N, 4, 4) from the dives' trajectories in the common frame, its horizontal
#: 1-sigma (N,), metres) -> (verified mask, T_a_b (N, 4, 4), covariance of x, y, z, roll, pitch, yaw
#: (N, 6, 6), ...).
Registration = Callable[
    [int, NDArray[np.int64], int, NDArray[np.int64], FloatArray, FloatArray], tuple[Any, ...]
]


@dataclass(frozen=True)
class CampaignSettings:
    """How inter-dive loop closures are sought (module docstring)."""

    search_sigmas: float = 3.0
    seed_every: int = 20
    max_per_image: int = 4
    min_overlap: float = 0.2
    dense_sigma_floor_m: float = 0.1
    seed_neighbours: int = 5
    change_threshold_m: float = 0.15
    change_min_area_m2: float = 0.25
    change_merge_m: float = 0.5
    change_min_support: int = 2


def origin_offset(origin: GeodeticOrigin, common: GeodeticOrigin) -> FloatArray:
    """A dive origin's position about the common origin (north, east, down), metres."""
    return geodetic2ned(origin.latitude_rad, origin.longitude_rad, origin.height_m, common).reshape(3)


@dataclass
class _DiveData:
    path: Path
    name: str
    dive: Dive  # with the common origin
    offset: FloatArray  # its own origin in the common frame (north, east, down)
    trajectory: Trajectory  # its SLAM image poses, common frame
    sigma_h: FloatArray  # horizontal 1-sigma of each image pose, metres
    summary: dict[str, Any]
    reach_m: float


def _load(path: Path, common: GeodeticOrigin | None, min_overlap: float) -> _DiveData:
    dive = read_dive(path)
    summary_path = P.SLAM_SUMMARY.path(path)
    traj_path = P.SLAM_TRAJECTORY.path(path)
    if not summary_path.is_file() or not traj_path.is_file():
        raise InsufficientDataError(f"{path}: no SLAM products (products/slam/): run `auvnav slam` first")
    summary = json.loads(summary_path.read_text(encoding="utf-8"))
    traj = read_trajectory(traj_path)
    if traj.sigma_ned_m is None:
        raise InsufficientDataError(
            f"{traj_path}: no marginal sigmas (the candidates' search needs them): run `auvnav slam` "
            "with --marginal-every 1 or more"
        )
    common = common or dive.info.origin
    offset = origin_offset(dive.info.origin, common)
    shifted = replace(traj, p_ned_m=traj.p_ned_m + offset[None, :] * np.array([1.0, 1.0, 0.0]))
    altitude = 2.0
    if dive.dvl.altitude_m is not None and np.any(np.isfinite(dive.dvl.altitude_m)):
        altitude = float(np.nanmedian(dive.dvl.altitude_m))
    reach = DEFAULT_REACH_M
    if dive.vehicle.stereo is not None:
        level = se3(np.eye(3), np.zeros(3))[None]
        poly = footprints_on_plane(level, dive.vehicle.stereo, np.array([altitude]))[0]
        reach = float(np.min(np.ptp(poly, axis=0))) * (1.0 - min_overlap)
    return _DiveData(
        path=path,
        name=dive.info.name,
        dive=replace(dive, info=replace(dive.info, origin=common)),
        offset=offset,
        trajectory=shifted,
        sigma_h=np.hypot(traj.sigma_ned_m[:, 0], traj.sigma_ned_m[:, 1]),
        summary=summary,
        reach_m=reach,
    )


@dataclass
class InterDiveLoops:
    """Verified inter-dive loop closures between dives ``a`` and ``b`` (image rows, relative poses)."""

    a: int
    b: int
    rows_a: NDArray[np.int64]
    rows_b: NDArray[np.int64]
    T_a_b: FloatArray
    covariance: FloatArray
    tested: int
    seeds_verified: int
    keep: NDArray[np.bool_] | None = None
    chi2: FloatArray | None = None


def _verify(
    register: Registration,
    a: int,
    b: int,
    ra: NDArray[np.int64],
    rb: NDArray[np.int64],
    prior: FloatArray,
    sigma: FloatArray,
) -> tuple[NDArray[np.int64], NDArray[np.int64], FloatArray, FloatArray]:
    if len(ra) == 0:
        return ra, rb, np.zeros((0, 4, 4)), np.zeros((0, 6, 6))
    out = register(a, ra, b, rb, prior, sigma)
    ok, T, C = np.asarray(out[0], dtype=bool), np.asarray(out[1]), np.asarray(out[2])
    return ra[ok], rb[ok], T[ok], C[ok]


@dataclass(frozen=True)
class _RegisterContext:
    """What each worker needs to register inter-dive pairs (picklable)."""

    rigs: tuple[Any, ...]  # StereoRig per dive
    rects: tuple[Any, ...]  # Rectification per dive
    features: tuple[Any, ...]  # FeatureSettings per dive (its loop stage's: its feature cache)
    cache_dirs: tuple[Path, ...]  # the loop stage's feature cache of each dive
    settings: Any  # LoopSettings of the first dive of the pair (registration, gates)
    vocabulary: Any  # Vocabulary or None


#: One pair to register: (dive a, left and right image of a, dive b, left and right image of b, prior
#: camera pose of b in a, its lateral 1-sigma).
_RegisterItem = tuple[int, str, str, int, str, str, FloatArray, float]


def _register_task(
    ctx: _RegisterContext, items: list[_RegisterItem]
) -> list[tuple[bool, FloatArray, FloatArray]]:
    """The loop stage's verification of each pair (:func:`auvnav.vision.registration.register` on
    the pairs' cached stereo features, the pose and covariance moved into the body frames)."""
    from auvnav.vision.camera import T_body_cam
    from auvnav.vision.loops import body_pose_and_covariance
    from auvnav.vision.registration import register
    from auvnav.vision.stereo import pair_features

    loaded: dict[tuple[int, str], Any] = {}

    def features(d: int, left: str, right: str) -> Any:
        if (d, left) not in loaded:
            loaded[(d, left)] = pair_features(
                Path(left), Path(right), ctx.rigs[d], ctx.rects[d], ctx.features[d], ctx.cache_dirs[d]
            )
        return loaded[(d, left)]

    out = []
    for a, la, ra, b, lb, rb, T_prior, sigma in items:
        fa, fb = features(a, la, ra), features(b, lb, rb)
        if fa is None or fb is None or len(fa) == 0 or len(fb) == 0:
            out.append((False, np.eye(4), np.full((6, 6), np.nan)))
            continue
        reg = register(fa, fb, ctx.settings.registration, prior=(T_prior, sigma), vocabulary=ctx.vocabulary)
        if not reg.accepted:
            out.append((False, np.eye(4), np.full((6, 6), np.nan)))
            continue
        T_bc = T_body_cam(ctx.rigs[a])
        # The two dives' rigs may differ: T_ba_bb = T_bc(a) T_ca_cb T_bc(b)^-1, taken with a's mount
        # for the covariance (a vehicle's mount moves by millimetres between dives).
        p6, c6 = body_pose_and_covariance(reg.T_a_b, reg.cov_xi, T_bc)
        T = T_bc @ reg.T_a_b @ se3_inverse(T_body_cam(ctx.rigs[b]))
        out.append((True, T, c6 if np.all(np.isfinite(p6)) else np.full((6, 6), np.nan)))
    return out


def _loop_settings(dive: Path) -> Any:
    """The loop stage's settings of a dive, from its ``products/vision/summary.json`` (defaults when
    it has none), so that its feature cache serves the campaign."""
    from auvnav.vision.candidates import CandidateSettings
    from auvnav.vision.features import FeatureSettings
    from auvnav.vision.loops import LoopSettings
    from auvnav.vision.registration import RegistrationSettings

    path = P.VISION_SUMMARY.path(dive)
    if not path.is_file():
        return LoopSettings()
    try:
        s = dict(json.loads(path.read_text(encoding="utf-8"))["settings"])
        return LoopSettings(
            features=FeatureSettings(**s.pop("features")),
            registration=RegistrationSettings(**s.pop("registration")),
            candidates=CandidateSettings(**s.pop("candidates")),
            **s,
        )
    except (OSError, ValueError, KeyError, TypeError) as err:
        log.warning("%s: loop settings unreadable (%s); the defaults are used", path, err)
        return LoopSettings()


class ImageRegistration:
    """Inter-dive registration of images: the loop stage's own verification (its feature cache, its
    registration, its gates) applied to pairs of images of two dives.

    A pair is verified when :func:`auvnav.vision.registration.register` accepts it (with the prior
    pose of the candidate, as the loop stage gives its own) and when it agrees with the prior as the
    loop stage's do (:func:`auvnav.vision.loops.measurement_sigma`): the horizontal displacement
    within the ``prior_gate_probability`` chi-square (2 dof) quantile of the prior's sigma, the
    relative heading within ``max_heading_disagreement_rad`` of the prior's. The settings are the
    first dive's loop stage's (``products/vision/summary.json``).
    """

    def __init__(self, dives: list[Path], executor: Any = None) -> None:
        from auvnav.executor import SerialExecutor
        from auvnav.vision.camera import rectification

        self.dives = [Path(d) for d in dives]
        self.executor = executor or SerialExecutor()
        rigs, rects, features, caches, self.images = [], [], [], [], []
        settings = [_loop_settings(d) for d in self.dives]
        for d, path in enumerate(self.dives):
            dive = read_dive(path)
            if dive.images is None or len(dive.images) == 0:
                raise InsufficientDataError(
                    f"{path}: no images (images/index.csv): give --truth-loops for simulated dives without images"
                )
            if dive.vehicle.stereo is None:
                raise InsufficientDataError(
                    f"{path}: the vehicle has no stereo calibration (simulated without images: give --truth-loops)"
                )
            if not image_files(path, dive.images):
                raise InsufficientDataError(
                    f"{path}: none of the images that images/index.csv lists is in images/ "
                    "(simulated without images: give --truth-loops)"
                )
            rigs.append(dive.vehicle.stereo)
            rects.append(rectification(dive.vehicle.stereo))
            features.append(settings[d].features)
            caches.append(P.cache_dir(path, "vision") / "features")
            self.images.append(
                (
                    [str(path / "images" / f) for f in dive.images.left],
                    [str(path / "images" / f) for f in dive.images.right],
                )
            )
        self.settings = settings
        self._base = (tuple(rigs), tuple(rects), tuple(features), tuple(caches))
        self._vocabulary: dict[int, Any] = {}

    def _context(self, a: int) -> _RegisterContext:
        words = self.settings[a].vocabulary_words
        if a not in self._vocabulary:
            self._vocabulary[a] = self._learn_vocabulary(a, words) if words > 1 else None
        return _RegisterContext(*self._base, settings=self.settings[a], vocabulary=self._vocabulary[a])

    def _learn_vocabulary(self, d: int, words: int) -> Any:
        """A vocabulary learnt from dive ``d``'s pairs as the loop stage learns its own
        (:func:`auvnav.vision.loops.learn_vocabulary`)."""
        from auvnav.vision.loops import learn_vocabulary
        from auvnav.vision.stereo import pair_features

        rigs, rects, features, caches = self._base
        left, right = self.images[d]

        def descriptors(k: int) -> Any:
            f = pair_features(Path(left[k]), Path(right[k]), rigs[d], rects[d], features[d], caches[d])
            return None if f is None else f.descriptors

        return learn_vocabulary(descriptors, len(left), words)

    def __call__(
        self,
        a: int,
        rows_a: NDArray[np.int64],
        b: int,
        rows_b: NDArray[np.int64],
        prior_T_a_b: FloatArray,
        sigma_m: FloatArray,
    ) -> tuple[NDArray[np.bool_], FloatArray, FloatArray]:
        from auvnav.executor import chunks
        from auvnav.frames import angle_diff
        from auvnav.vision.camera import T_body_cam
        from auvnav.vision.loops import prior_agreement

        ctx = self._context(a)
        T_bc_a, T_bc_b = T_body_cam(ctx.rigs[a]), T_body_cam(ctx.rigs[b])
        T_cam = se3_inverse(T_bc_a)[None] @ prior_T_a_b @ T_bc_b[None]  # camera b in camera a
        # The camera pose's lateral sigma: the positions' plus the heading error turning it (as the
        # loop stage's prior: 0.1 rad).
        sigma_cam = np.hypot(sigma_m, 0.1 * np.linalg.norm(T_cam[:, :2, 3], axis=1))
        (la, ra_), (lb, rb_) = self.images[a], self.images[b]
        items = [
            (a, la[i], ra_[i], b, lb[j], rb_[j], T_cam[n], float(sigma_cam[n]))
            for n, (i, j) in enumerate(zip(rows_a.tolist(), rows_b.tolist(), strict=True))
        ]
        results: list[tuple[bool, FloatArray, FloatArray]] = []
        for part in self.executor.map(_register_task, ctx, chunks(items, 16)):
            results.extend(part)
        ok = np.array([r[0] for r in results], dtype=bool)
        T = np.stack([r[1] for r in results]) if results else np.zeros((0, 4, 4))
        C = np.stack([r[2] for r in results]) if results else np.zeros((0, 6, 6))
        # Agreement with the prior, as the loop stage's: the displacement of b from a (in a's body
        # frame, level to within the pitch and roll) and the relative heading.
        yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])
        yaw_prior = np.arctan2(prior_T_a_b[:, 1, 0], prior_T_a_b[:, 0, 0])
        in_gate, heading, _ = prior_agreement(
            T[:, :2, 3], prior_T_a_b[:, :2, 3], sigma_m, angle_diff(yaw, yaw_prior), ctx.settings
        )
        agree = in_gate & heading
        verified = ok & agree
        log.info(
            "dives %d x %d: %d pairs registered, %d accepted, %d of them agree with the prior",
            a, b, len(items), int(ok.sum()), int(verified.sum()),
        )  # fmt: skip
        return verified, T, C


def inter_dive_candidates(
    A: _DiveData, B: _DiveData, a: int, b: int, register: Registration, settings: CampaignSettings
) -> InterDiveLoops:
    """Seeds, then dense candidates, verified (module docstring)."""
    pa, pb = A.trajectory.p_ned_m[:, :2], B.trajectory.p_ned_m[:, :2]
    reach = max(A.reach_m, B.reach_m)
    tree_b = cKDTree(pb)
    seeds = np.arange(0, len(pa), settings.seed_every)
    ra_list, rb_list = [], []
    sigma_b = float(np.max(B.sigma_h))
    for r in seeds:
        radius = reach + settings.search_sigmas * math.hypot(A.sigma_h[r], sigma_b)
        near = np.array(tree_b.query_ball_point(pa[r], radius), dtype=np.int64)
        if near.size:
            d = np.linalg.norm(pb[near] - pa[r], axis=1)
            near = near[d <= reach + settings.search_sigmas * np.hypot(A.sigma_h[r], B.sigma_h[near])]
            ra_list.append(np.full(len(near), r, dtype=np.int64))
            rb_list.append(near)
    ra = np.concatenate(ra_list) if ra_list else np.zeros(0, np.int64)
    rb = np.concatenate(rb_list) if rb_list else np.zeros(0, np.int64)
    tested = len(ra)
    TA = _poses(A.trajectory)
    TB = _poses(B.trajectory)
    prior = se3_inverse(TA[ra]) @ TB[rb]
    sa, sb, sT, sC = _verify(register, a, b, ra, rb, prior, np.hypot(A.sigma_h[ra], B.sigma_h[rb]))
    log.info("%s x %s: %d seed candidates, %d verified", A.name, B.name, tested, len(sa))
    if len(sa) == 0:
        return InterDiveLoops(a, b, sa, sb, sT, sC, tested, 0)
    # Where B lies against A, by the seeds: B's position predicted from A's through the relative pose.
    predicted = (TA[sa] @ sT)[:, :2, 3]
    delta = predicted - TB[sb, :2, 3]
    order = np.argsort(sa, kind="stable")
    sa_sorted, delta_sorted = sa[order], delta[order]
    k = min(settings.seed_neighbours, len(sa))
    seed_tree = cKDTree(sa_sorted[:, None].astype(float))
    _, idx = seed_tree.query(np.arange(len(pa))[:, None].astype(float), k=k)
    idx = idx.reshape(len(pa), k)
    local = np.median(delta_sorted[idx], axis=1)  # (A images, 2)
    spread = np.median(np.abs(delta_sorted[idx] - local[:, None, :]), axis=1) * 1.4826
    sigma = np.maximum(np.hypot(spread[:, 0], spread[:, 1]), settings.dense_sigma_floor_m)
    # Dense: each image of A against its nearest images of B, B corrected by the local offset.
    radius = reach + settings.search_sigmas * sigma
    dist, nearest = tree_b.query(
        pa - local, k=settings.max_per_image, distance_upper_bound=float(radius.max())
    )
    dist, nearest = dist.reshape(len(pa), -1), nearest.reshape(len(pa), -1)
    ok = np.isfinite(dist) & (dist <= radius[:, None])
    da = np.repeat(np.arange(len(pa)), dist.shape[1]).reshape(dist.shape)[ok]
    db = nearest[ok].astype(np.int64)
    seen = set(zip(sa.tolist(), sb.tolist(), strict=True))
    new = np.array([(x, y) not in seen for x, y in zip(da.tolist(), db.tolist(), strict=True)], dtype=bool)
    da, db = da[new].astype(np.int64), db[new]
    TB_corrected = TB[db].copy()
    TB_corrected[:, :2, 3] += local[da]
    ta, tb, tT, tC = _verify(register, a, b, da, db, se3_inverse(TA[da]) @ TB_corrected, sigma[da])
    log.info("%s x %s: %d dense candidates, %d verified", A.name, B.name, len(da), len(ta))
    return InterDiveLoops(
        a,
        b,
        np.concatenate([sa, ta]),
        np.concatenate([sb, tb]),
        np.concatenate([sT, tT]),
        np.concatenate([sC, tC]),
        tested + len(da),
        len(sa),
    )


def _poses(traj: Trajectory) -> FloatArray:
    return se3(traj.R_ned_body, traj.p_ned_m)


def _loop_tangent(T: FloatArray, C: FloatArray) -> FloatArray:
    """Loop-file covariances (x, y, z, roll, pitch, yaw) in GTSAM's tangent (:mod:`auvnav.slam.graph`)."""
    from auvnav.slam.graph import loop_covariance_tangent
    from auvnav.vision.loopfile import loops_from_transforms

    n = len(T)
    zeros = np.zeros(n, dtype=np.int64)
    lc = loops_from_transforms(zeros, zeros + 1, np.zeros(n), np.ones(n), T, C, zeros)
    return loop_covariance_tangent(lc)


def _dive_graph(d: _DiveData) -> Any:
    """The dive's sensor graph as its SLAM built it, with the common origin (the DVL odometry
    corrected by the calibration the dive's SLAM estimated, if it did)."""
    from auvnav.compass.correction import read_correction
    from auvnav.depth.tide import read_constituents
    from auvnav.slam.dvl import DvlCalibration
    from auvnav.slam.graph import SlamOptions
    from auvnav.slam.result import sensor_graph
    from auvnav.vision.loopfile import read_loops

    s = d.summary
    loops_file = s["loops"]["file"]
    correction = s["compass"]["correction"]
    tide = s["tide"]
    options = SlamOptions(
        estimate_compass=s["compass"]["mode"] == "estimated",
        harmonics=int(s["compass"].get("harmonics", 3)),
        robust=s["robust"],
    )
    image_t = d.dive.images.t_s if d.dive.images is not None else None
    if image_t is None:
        raise InsufficientDataError(f"{d.path}: no images/index.csv")
    return sensor_graph(
        d.dive,
        image_t,
        image_source="images/index.csv",
        loops=None if loops_file is None else read_loops(Path(loops_file), n_poses=len(image_t)),
        correction=None if correction is None else read_correction(Path(correction)),
        tide=None
        if tide is None
        else read_constituents(Path(tide), latitude_rad=d.dive.info.origin.latitude_rad),
        dvl_calibration=None
        if s.get("dvl") is None
        else DvlCalibration.from_summary(s["dvl"], d.dive.vehicle.dvl.R_body_sensor),
        options=options,
        loops_name=str(loops_file),
    )


def _keys(d: int, sg: Any) -> dict[int, int]:
    import gtsam

    from auvnav.slam.compass import COEFFICIENTS_KEY
    from auvnav.slam.poses import pose_key

    mapping = {pose_key(k): gtsam.symbol(chr(ord("A") + d), k) for k in range(len(sg.times))}
    mapping[COEFFICIENTS_KEY] = gtsam.symbol(chr(ord("a") + d), 0)
    return mapping


def run_campaign(
    dives: list[Path],
    out: Path,
    register: Registration,
    settings: CampaignSettings | None = None,
    *,
    overwrite: bool = False,
    registration_name: str = "images",
) -> dict[str, Any]:
    """Put dives in one frame (module docstring); returns the summary (``summary.json``).

    Raises
    ------
    InsufficientDataError
        Fewer than two dives, or a dive without SLAM products.
    OutputExistsError
        ``out`` exists and ``overwrite`` is False.
    """
    import gtsam

    from auvnav.slam.g2o import read_g2o
    from auvnav.slam.optimize import lm_solve
    from auvnav.slam.pcm import graph_chain, select_loops, select_pairwise
    from auvnav.slam.poses import pose_key

    settings = settings or CampaignSettings()
    if len(dives) < 2:
        raise InsufficientDataError("a campaign needs at least two dives")
    if len({Path(d).resolve() for d in dives}) != len(dives):
        raise InsufficientDataError("a dive is given twice")
    if len(dives) > 26:
        raise AuvnavError("at most 26 dives in a campaign")
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    started = time.perf_counter()
    first = _load(Path(dives[0]), None, settings.min_overlap)
    data = [first] + [_load(Path(p), first.dive.info.origin, settings.min_overlap) for p in dives[1:]]
    names = [d.name for d in data]
    if len(set(names)) != len(names):
        names = [f"{n}_{k}" for k, n in enumerate(names)]

    # Inter-dive loop closures, pair by pair.
    pairs = [
        inter_dive_candidates(data[a], data[b], a, b, register, settings)
        for a in range(len(data))
        for b in range(a + 1, len(data))
    ]

    # The dives' graphs, renamed, and their own loop selection.
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    graphs = []
    for d, dd in enumerate(data):
        sg = _dive_graph(dd)
        graphs.append(sg)
        keys = _keys(d, sg)
        drop = ~select_loops(sg.pose_graph, len(sg.times) - 1).keep
        own = read_g2o(P.SLAM_GRAPH.path(dd.path)).T_world_pose
        if len(own) != len(sg.times):
            raise InsufficientDataError(f"{dd.path}: products/slam/graph.g2o does not match the dive's poses")
        own = own.copy()
        own[:, :2, 3] += dd.offset[:2]
        for k, T in enumerate(own):
            values.insert(keys[pose_key(k)], gtsam.Pose3(T))
        if sg.compass.estimate:
            from auvnav.slam.compass import COEFFICIENTS_KEY

            values.insert(keys[COEFFICIENTS_KEY], np.zeros(sg.compass.n_coefficients))
        own_graph = sg.graph(drop_loops=drop)
        for f in range(own_graph.size()):
            factor = own_graph.at(f)
            graph.add(factor.rekey([keys[k] for k in factor.keys()]))

    # Inter-dive loop closures: pairwise consistency against both dives' odometry, then the graph.
    kernel = gtsam.noiseModel.mEstimator.Cauchy.Create(graphs[0].loop_k)
    inter_factors = []
    for loops in pairs:
        ga, gb = graphs[loops.a], graphs[loops.b]
        pa = ga.times.pose_of_image()[loops.rows_a]
        pb = gb.times.pose_of_image()[loops.rows_b]
        C = _loop_tangent(loops.T_a_b, loops.covariance) if len(loops.T_a_b) else np.zeros((0, 6, 6))
        selection = select_pairwise(
            graph_chain(ga.pose_graph, len(ga.times) - 1),
            graph_chain(gb.pose_graph, len(gb.times) - 1),
            pa.astype(np.int64),
            pb.astype(np.int64),
            loops.T_a_b,
            C,
        )
        loops.keep = selection.keep
        ka, kb = _keys(loops.a, ga), _keys(loops.b, gb)
        for n in range(len(pa)):
            noise = gtsam.noiseModel.Robust.Create(kernel, gtsam.noiseModel.Gaussian.Covariance(C[n]))
            factor = gtsam.BetweenFactorPose3(
                ka[pose_key(int(pa[n]))], kb[pose_key(int(pb[n]))], gtsam.Pose3(loops.T_a_b[n]), noise
            )
            plain = gtsam.BetweenFactorPose3(
                ka[pose_key(int(pa[n]))],
                kb[pose_key(int(pb[n]))],
                gtsam.Pose3(loops.T_a_b[n]),
                gtsam.noiseModel.Gaussian.Covariance(C[n]),
            )
            inter_factors.append(plain)
            if selection.keep[n]:
                graph.add(factor)
    solve_start = time.perf_counter()
    solution = lm_solve(graph, values)
    solve_s = time.perf_counter() - solve_start
    n = 0
    for loops in pairs:
        m = len(loops.rows_a)
        loops.chi2 = np.array([2.0 * f.error(solution) for f in inter_factors[n : n + m]])
        assert loops.keep is not None
        loops.keep = loops.keep & (np.sqrt(loops.chi2) <= graphs[0].loop_k)
        n += m

    # Products.
    tmp = out.with_name(out.name + ".partial")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    per_dive = []
    for d, (dd, sg) in enumerate(zip(data, graphs, strict=True)):
        keys = _keys(d, sg)
        image = sg.times.is_image
        T = np.stack([solution.atPose3(keys[pose_key(k)]).matrix() for k in np.flatnonzero(image)])
        yaw, pitch, roll = rot2euler(T[:, :3, :3])
        traj = Trajectory(
            t_s=sg.times.t_s[image], p_ned_m=T[:, :3, 3], roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw
        )
        folder = tmp / "dives" / names[d]
        folder.mkdir(parents=True)
        write_trajectory(traj, folder / "trajectory.csv")
        moved = T[:, :3, 3] - dd.trajectory.p_ned_m
        per_dive.append(
            {
                "name": names[d],
                "path": str(dd.path),
                "offset_ned_m": dd.offset.tolist(),
                "image_poses": int(np.count_nonzero(image)),
                "moved_median_m": [float(v) for v in np.median(moved, axis=0)],
            }
        )
    _write_inter_dive_loops(pairs, data, names, tmp / INTER_DIVE_LOOPS_FILE)
    changes = dem_differences(data, per_dive, tmp, settings)
    origin = first.dive.info.origin
    text = dump_yaml(
        {
            "format": FORMAT,
            "origin": {
                "latitude_deg": math.degrees(origin.latitude_rad),
                "longitude_deg": math.degrees(origin.longitude_rad),
                "height_m": origin.height_m,
            },
            "dives": per_dive,
            "registration": registration_name,
            "settings": {k: getattr(settings, k) for k in settings.__dataclass_fields__},
        }
    )
    (tmp / CAMPAIGN_FILE).write_text(text, encoding="utf-8")
    summary = {
        "dives": names,
        "registration": registration_name,
        "inter_dive": [
            {
                "dives": [names[loops.a], names[loops.b]],
                "candidates_tested": loops.tested,
                "seeds_verified": loops.seeds_verified,
                "verified": len(loops.rows_a),
                "kept": int(np.count_nonzero(loops.keep)) if loops.keep is not None else 0,
            }
            for loops in pairs
        ],
        "joint_graph": {"factors": graph.size(), "variables": values.size(), "solve_s": solve_s},
        "changes": changes,
        "seconds": time.perf_counter() - started,
    }
    write_json(summary, tmp / SUMMARY_FILE)
    if out.exists():
        shutil.rmtree(out)
    tmp.rename(out)
    return summary


def _write_inter_dive_loops(
    pairs: list[InterDiveLoops], data: list[_DiveData], names: list[str], path: Path
) -> None:
    import pandas as pd

    frames = []
    for loops in pairs:
        ta = data[loops.a].trajectory.t_s[loops.rows_a]
        tb = data[loops.b].trajectory.t_s[loops.rows_b]
        yaw, pitch, roll = rot2euler(loops.T_a_b[:, :3, :3]) if len(loops.rows_a) else (np.zeros(0),) * 3
        frames.append(
            pd.DataFrame(
                {
                    "dive_a": names[loops.a],
                    "row_a": loops.rows_a,
                    "dive_b": names[loops.b],
                    "row_b": loops.rows_b,
                    "t_a": ta,
                    "t_b": tb,
                    "x_m": loops.T_a_b[:, 0, 3],
                    "y_m": loops.T_a_b[:, 1, 3],
                    "z_m": loops.T_a_b[:, 2, 3],
                    "roll_deg": np.degrees(roll),
                    "pitch_deg": np.degrees(pitch),
                    "yaw_deg": np.degrees(yaw),
                    "kept": np.asarray(loops.keep, dtype=int),
                    "chi2": loops.chi2,
                }
            )
        )
    pd.concat(frames).to_csv(path, index=False, float_format="%.9g")


def read_campaign(folder: Path) -> dict[str, Any]:
    """A campaign folder's ``campaign.yaml``."""
    path = Path(folder) / CAMPAIGN_FILE
    if not path.is_file():
        raise InsufficientDataError(f"{path}: not found (not a campaign folder)")
    data, problems = load_yaml(path, str(path))
    if problems or not isinstance(data, dict) or data.get("format") != FORMAT:
        raise DiveFormatError(problems or [Problem(str(path), f"not a campaign file (format {FORMAT})")])
    return data


def dem_differences(
    data: list[_DiveData], per_dive: list[dict[str, Any]], out: Path, settings: CampaignSettings
) -> dict[str, Any]:
    """The DEM difference of the first two dives with a reconstruction (module docstring), or why not."""
    have = [d for d, dd in enumerate(data) if P.RECON_DEM.path(dd.path).is_file()]
    if len(have) < 2:
        return {"status": "skipped", "reason": "fewer than two dives have products/recon/dem.tif"}
    return dem_difference(data[have[0]], data[have[1]], per_dive[have[0]], per_dive[have[1]], out, settings)


def image_support(
    d: _DiveData, move_ne_m: FloatArray, ne_m: FloatArray, cell_m: float = 0.05
) -> FloatArray | None:
    """How many of a dive's stereo pairs saw each point ``ne_m`` (..., 2; common frame, north and
    east): their stereo footprints from the dive's SLAM poses moved by ``move_ne_m``, on the floor
    below the DVL (:mod:`auvnav.coverage.analysis`, 2 m when it logs no altitude), counted on
    ``cell_m`` cells (:func:`auvnav.coverage.grid.count_polygons`); None when the vehicle has no
    stereo calibration (a DEM made otherwise)."""
    from auvnav.coverage.analysis import floor_below_dvl, image_altitude_m, image_footprints
    from auvnav.coverage.grid import count_polygons
    from auvnav.raster import MapGrid

    rig = d.dive.vehicle.stereo
    if rig is None:
        return None
    poses = replace(d.trajectory, p_ned_m=d.trajectory.p_ned_m + np.array([*move_ne_m[:2], 0.0]))
    altitude = image_altitude_m(d.dive, poses.t_s, fallback_m=2.0)
    floor = floor_below_dvl(poses, altitude, d.dive.vehicle.dvl.lever_arm_body_m)
    polygons, ok = image_footprints(poses, floor, rig, "stereo")
    grid = MapGrid.covering(polygons[ok], d.dive.info.origin, cell_m, margin_m=cell_m)
    count = count_polygons(polygons[ok], grid)
    rc = grid.cells_of_map(ned2map(ne_m, d.dive.info.origin))
    inside = np.all((rc >= 0) & (rc < (grid.height, grid.width)), axis=-1)
    out = np.zeros(ne_m.shape[:-1])
    out[inside] = count[rc[inside][:, 0], rc[inside][:, 1]]
    return out


def dem_difference(
    A: _DiveData,
    B: _DiveData,
    info_a: dict[str, Any],
    info_b: dict[str, Any],
    out: Path,
    settings: CampaignSettings,
) -> dict[str, Any]:
    """B's DEM less A's on A's grid, each shifted by its dive's move in the joint solution; changed
    regions with their peak's position (north, east in the common frame)."""
    import pandas as pd
    import rasterio
    from rasterio.warp import Resampling, reproject
    from scipy import ndimage

    with rasterio.open(P.RECON_DEM.path(A.path)) as src:
        dem_a = src.read(1).astype(float)
        transform_a, crs = src.transform, src.crs
        nodata_a = src.nodata
    with rasterio.open(P.RECON_DEM.path(B.path)) as src:
        dem_b_src = src.read(1).astype(float)
        transform_b, crs_b, nodata_b = src.transform, src.crs, src.nodata

    common = A.dive.info.origin

    def shifted(transform: Any, info: dict[str, Any], dive: _DiveData) -> Any:
        # The DEM was made in the dive's own SLAM frame about its own origin: move it by how far the
        # joint solution moved the dive, through the map projection of the common origin.
        move = np.array(info["moved_median_m"][:2])
        dx, dy = ned2map(move, common) - ned2map(np.zeros(2), common)
        return rasterio.Affine.translation(float(dx), float(dy)) @ transform

    dem_b = np.full_like(dem_a, np.nan)
    reproject(
        dem_b_src,
        dem_b,
        src_transform=shifted(transform_b, info_b, B),
        src_crs=crs_b,
        src_nodata=nodata_b,
        dst_transform=shifted(transform_a, info_a, A),
        dst_crs=crs,
        dst_nodata=np.nan,
        resampling=Resampling.bilinear,
    )
    if nodata_a is not None:
        dem_a[dem_a == nodata_a] = np.nan
    diff = dem_b - dem_a
    cell_area = abs(transform_a.a * transform_a.e)
    if settings.change_min_support > 0:
        # Cells both dives saw from enough stereo pairs: a cell at the edge of a dive's coverage
        # (one oblique view, often a lone line of the lead-in or a turn) declares no change.
        # Counted on blocks of about 5 cm of cells (the DEM's cells may be a centimetre).
        step = max(1, round(0.05 / math.sqrt(cell_area)))
        h, w = diff.shape
        rows_, cols_ = np.mgrid[0:h:step, 0:w:step].astype(float)
        x, y = shifted(transform_a, info_a, A) @ (cols_.ravel() + 0.5 * step, rows_.ravel() + 0.5 * step)
        ne = map2ned(np.column_stack([x, y]), common)[:, :2].reshape(*rows_.shape, 2)
        for dd, info in ((A, info_a), (B, info_b)):
            support = image_support(dd, np.array(info["moved_median_m"][:2]), ne)
            if support is None:
                log.warning("%s: no stereo calibration: its DEM's cells are not checked for support", dd.path)
                continue
            seen = np.repeat(np.repeat(support >= settings.change_min_support, step, 0), step, 1)
            diff[~seen[:h, :w]] = np.nan
    diff -= np.nanmedian(diff)  # the tide's datum error left in either DEM
    # Changed cells; a region joins those within change_merge_m of each other (a change seen through the
    # gaps between survey lines is one change), its area counting the changed cells only.
    # Rises and falls are labelled apart.
    reach = max(round(0.5 * settings.change_merge_m / math.sqrt(cell_area)), 0)  # each side half way
    labels = np.zeros(diff.shape, dtype=np.int64)
    n = 0
    for sign in (1.0, -1.0):
        changed = sign * np.nan_to_num(diff) > settings.change_threshold_m
        joined = ndimage.binary_dilation(changed, ndimage.generate_binary_structure(2, 1), iterations=reach)
        part, m = ndimage.label(joined if reach else changed)
        labels[changed] = part[changed] + n
        n += m
    rows = []
    for k in range(1, n + 1):
        mask = labels == k
        area = float(mask.sum() * cell_area)
        if area < settings.change_min_area_m2:
            continue
        r, c = np.nonzero(mask)
        values = diff[mask]
        peak = int(np.argmax(np.abs(values)))
        x, y = shifted(transform_a, info_a, A) @ (c[peak] + 0.5, r[peak] + 0.5)
        north, east = map2ned(np.array([x, y]), common)[:2]
        rows.append(
            {
                "area_m2": area,
                "height_change_m": float(values[peak]),
                "volume_m3": float(np.nansum(values) * cell_area),
                "north_m": float(north),
                "east_m": float(east),
            }
        )
    pd.DataFrame(rows, columns=["area_m2", "height_change_m", "volume_m3", "north_m", "east_m"]).to_csv(
        out / CHANGES_FILE, index=False
    )
    profile = {
        "driver": "GTiff",
        "height": diff.shape[0],
        "width": diff.shape[1],
        "count": 1,
        "dtype": "float32",
        "crs": crs,
        "transform": shifted(transform_a, info_a, A),
        "nodata": np.nan,
        "compress": "deflate",
    }
    with rasterio.open(out / DEM_DIFFERENCE_FILE, "w", **profile) as dst:
        dst.write(diff.astype(np.float32), 1)
    return {
        "status": "done",
        "dives": [info_a["name"], info_b["name"]],
        "changes": len(rows),
        "cell_m": math.sqrt(cell_area),
    }
