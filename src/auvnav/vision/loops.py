"""Loop closures of a dive: features of every stereo pair, candidates, verification.

:func:`find_loops` runs, with an executor (:mod:`auvnav.executor`) and an optional progress callback:

1. stereo features of every pair (:mod:`auvnav.vision.stereo`), cached in ``features/`` of the
   stage's cache (``products/cache/vision/``); a missing or unreadable image skips its pair with a
   warning naming it;
2. rounds of verification: the consecutive pairs and the candidates the prior makes probable
   (:mod:`auvnav.vision.candidates`); each verified non-consecutive loop refines the drift model, so
   the next round searches where the corrected prior now points, until no new candidate appears.
   Each chunk of verified pairs is cached (``verify/``), keyed by the two feature files, the prior
   pose and uncertainty, the registration's settings and the vocabulary, so a run killed in the
   middle loses at most the chunks in flight;
3. a verification (:func:`~auvnav.vision.registration.register`) is accepted when the registration
   is, and when it agrees with the prior: the horizontal displacement within the gate of the corrected
   prior's uncertainty, the relative heading within ``max_heading_disagreement_rad`` of the compass's.
   A pair whose features do not register (too few repeat: featureless sand, ripple fields, turbid
   water) is registered again from its images, photometrically (:mod:`auvnav.vision.direct`), when
   ``LoopSettings.direct`` is set, searched for within the prior's window: the prior through a loop
   already registered from features nearby along both tracks when that is the more certain
   (:meth:`_Priors.anchored`: the loop ties the two passes' headings), or, for a pair that is still
   loose, through the network of every loop registered from features (:mod:`auvnav.vision.network`,
   solved again as they grow); a pair refused for want of a certain prior is searched again when a
   loop found since makes its prior twice as certain.

``loops.csv`` (DESIGN section 6), one row per accepted pair, consecutive pairs included:

- ``i, j``: 0-based rows of ``images/index.csv`` (i < j); ``t_i, t_j``: their times, POSIX seconds;
- ``x_m, y_m, z_m, roll_deg, pitch_deg, yaw_deg``: the pose of body j in body i,
  ``T_i_j = inv(T_ned_body_i) @ T_ned_body_j`` (translation in body i's FRD axes; Euler ZYX angles of
  its rotation, ``R = Rz(yaw) Ry(pitch) Rx(roll)``);
- ``cov00, cov01, ..., cov05, cov11, ..., cov55``: the upper triangle, row-major, of the 6 x 6
  covariance of ``(x, y, z, roll, pitch, yaw)`` in metres and radians (SI, unlike the degree columns);
- ``inliers``: registered point matches (a direct registration: the stereo points of j inside image
  i's view).

The file is written and read by :mod:`auvnav.vision.loopfile`.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.stats import chi2

from auvnav import products as P
from auvnav.dive import Dive, ImageIndex
from auvnav.errors import AuvnavError, ConfigError, InsufficientDataError
from auvnav.executor import Executor, SerialExecutor, chunks
from auvnav.frames import angle_diff, from_pose6, pose6, se3, se3_inverse, wrap_angle
from auvnav.streams import atomic_write
from auvnav.trajectory import Trajectory
from auvnav.vehicle import StereoRig
from auvnav.vision.camera import Rectification, T_body_cam, rectification
from auvnav.vision.candidates import (
    CandidateSettings,
    DriftModel,
    Footprints,
    candidate_pairs,
    footprints,
)
from auvnav.vision.direct import (
    DirectSettings,
    Geometry,
    Prepared,
    pair_geometry,
    plan_search,
    prepare,
    register_direct,
    rejected,
)
from auvnav.vision.features import FeatureSettings, Vocabulary, build_vocabulary
from auvnav.vision.loopfile import LoopClosures, loops_from_transforms
from auvnav.vision.network import Network, solve_network
from auvnav.vision.registration import Registration, RegistrationSettings, expm_so3, register
from auvnav.vision.stereo import cache_path, pair_features, read_features

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class LoopSettings:
    """Everything the stage depends on.

    Parameters
    ----------
    features, registration, candidates : settings of each step
    prior_gate_probability : float
        A loop's horizontal displacement must lie inside this chi-square (2 dof) quantile of the
        corrected prior's relative uncertainty.
    max_heading_disagreement_rad : float
        Largest difference between the loop's relative heading and the compass's (the compass may be
        off by its deviation, several degrees, at each of the two headings).
    max_rounds : int
        Rounds of candidate search and verification.
    per_image_per_round : int
        Most candidates an image takes part in per round, most probable first: the loops found
        refine the prior before less probable candidates are tried.
    vocabulary_words : int
        Words of the coarse vocabulary that splits descriptor matching
        (:class:`~auvnav.vision.features.Vocabulary`), learnt from the dive's own descriptors;
        1: every descriptor against every other.
    direct : DirectSettings or None
        The direct (photometric) registration of pairs whose features fail to register; None: off.
    """

    features: FeatureSettings = field(default_factory=FeatureSettings)
    registration: RegistrationSettings = field(default_factory=RegistrationSettings)
    candidates: CandidateSettings = field(default_factory=CandidateSettings)
    prior_gate_probability: float = 0.99999
    max_heading_disagreement_rad: float = float(np.radians(20.0))
    max_rounds: int = 50
    per_image_per_round: int = 2
    vocabulary_words: int = 8
    direct: DirectSettings | None = field(default_factory=DirectSettings)


@dataclass(frozen=True)
class Verification:
    """One tested pair, in body frames (see the module docstring for the pose convention); ``direct``:
    registered from the images (:mod:`auvnav.vision.direct`), not the features."""

    i: int
    j: int
    accepted: bool
    reason: str
    pose6: FloatArray  # x, y, z (m), roll, pitch, yaw (rad) of T_i_j
    cov6: FloatArray  # (6, 6), SI
    matches: int
    inliers: int
    normalised_residual: float
    direct: bool = False


@dataclass(frozen=True)
class LoopResult:
    """What :func:`find_loops` found.

    Parameters
    ----------
    loops : LoopClosures
        Accepted pairs (the content of ``loops.csv``).
    tested : list of Verification
        Every pair tested, accepted or not.
    summary : dict
        Counts and timings (written as ``products/vision/summary.json``).
    """

    loops: LoopClosures
    tested: list[Verification]
    summary: dict[str, Any]


def body_pose_and_covariance(
    T_cc: FloatArray, cov_xi: FloatArray, T_bc: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The body-frame pose ``T_bi_bj = T_bc T_ci_cj T_bc^-1`` as 6 numbers and their covariance.

    ``cov_xi`` is the covariance of the camera pose perturbation ``(dt, dtheta)`` of
    :class:`~auvnav.vision.registration.Registration`; it is propagated with a central-difference
    Jacobian.
    """
    h = 1e-6
    xi = np.concatenate([np.zeros((1, 6)), h * np.eye(6), -h * np.eye(6)])  # 0, +h e_k, -h e_k
    T = np.broadcast_to(T_cc, (13, 4, 4)).copy()
    T[:, :3, :3] = expm_so3(xi[:, 3:]) @ T_cc[:3, :3]
    T[:, :3, 3] += xi[:, :3]
    p = pose6(T_bc @ T @ se3_inverse(T_bc))
    d = p[1:7] - p[7:]
    d[:, 3:] = wrap_angle(d[:, 3:])
    J = d.T / (2 * h)
    return p[0], J @ cov_xi @ J.T


# ---------------------------------------------------------------------------------------------
# Work done in the process pool
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Context:
    images_dir: Path
    rig: StereoRig
    rect: Rectification
    settings: LoopSettings
    cache_dir: Path
    verify_dir: Path
    vocabulary: Vocabulary | None = None


def _features_task(ctx: _Context, items: list[tuple[int, str, str]]) -> list[tuple[int, str | None, int]]:
    """Fill the cache for pairs; return (index, cache file or None when skipped, feature count)."""
    out = []
    for k, left, right in items:
        lp, rp = ctx.images_dir / left, ctx.images_dir / right
        feats = pair_features(lp, rp, ctx.rig, ctx.rect, ctx.settings.features, ctx.cache_dir)
        if feats is None:
            out.append((k, None, 0))
        else:
            out.append(
                (k, str(cache_path(ctx.cache_dir, lp, rp, ctx.rig, ctx.settings.features)), len(feats))
            )
    return out


_load = lru_cache(maxsize=512)(read_features)  # each worker's recently used feature files


@lru_cache(maxsize=512)
def _geometry(path: str, settings: DirectSettings) -> Geometry | None:
    """A pair's geometry for the direct registration (each worker's recently used: about 60 KB each).
    Over the whole check dive, whose rounds sweep it again and again, each is fitted about 5 times
    (2.2 ms each); 2,048 of them halve that for 0.2 GB more memory, 3% of the verification's time."""
    return pair_geometry(_load(path), settings)


@lru_cache(maxsize=128)
def _prepared(path: str, settings: DirectSettings) -> Prepared | None:
    """A pair's images for the direct registration (each worker's recently used: 1 MB each)."""
    return prepare(_load(path), settings, _geometry(path, settings))


def _register_direct(
    pi: str, pj: str, T_prior: FloatArray, sigma_m: float, settings: DirectSettings
) -> Registration:
    """The direct registration of pair ``pj`` in pair ``pi``: its images prepared only when the pairs'
    geometry does not refuse it (as most candidates are refused)."""
    search = plan_search(_geometry(pi, settings), _geometry(pj, settings), T_prior, sigma_m, settings)
    if isinstance(search, str):
        return rejected(search)
    A, B = _prepared(pi, settings), _prepared(pj, settings)
    if A is None or B is None:
        return rejected("thumbnail unreadable")
    return register_direct(A, B, search, settings)


_REASON_BYTES = 160
#: One verified pair in the verification cache (``products/cache/vision/verify/``): its key, then
#: the registration's outcome (before the prior's check, which depends on the round).
_VERIFY_RECORD = np.dtype(
    [
        ("key", "S20"),
        ("accepted", "?"),
        ("reason", f"S{_REASON_BYTES}"),
        ("pose6", "<f8", (6,)),
        ("cov6", "<f8", (21,)),
        ("matches", "<i8"),
        ("inliers", "<i8"),
        ("residual", "<f8"),
        ("direct", "?"),
    ]
)
_UPPER = np.triu_indices(6)

WorkItem = tuple[int, int, str, str, FloatArray, float, FloatArray, float, bytes]


def _verify_task(ctx: _Context, items: list[WorkItem]) -> list[Verification]:
    """Register each pair; the chunk's outcomes go to the verification cache as one file."""
    T_bc = T_body_cam(ctx.rig)
    out = []
    records = np.zeros(len(items), dtype=_VERIFY_RECORD)
    reg_settings, direct = ctx.settings.registration, ctx.settings.direct
    for n, (i, j, pi, pj, T_prior, sigma, T_near, sigma_near, key) in enumerate(items):
        reg = register(_load(pi), _load(pj), reg_settings, prior=(T_prior, sigma), vocabulary=ctx.vocabulary)
        reason, by_images = reg.reason, False
        if not reg.accepted and direct is not None:
            again = _register_direct(pi, pj, T_near, sigma_near, direct)
            by_images = again.accepted
            reg = again if again.accepted else reg
            reason = "" if again.accepted else f"{reason}; direct: {again.reason}"
        if reg.accepted:
            p6, c6 = body_pose_and_covariance(reg.T_a_b, reg.cov_xi, T_bc)
        else:
            p6, c6 = np.full(6, np.nan), np.full((6, 6), np.nan)
        v = Verification(
            i, j, reg.accepted, reason, p6, c6, reg.matches, reg.inliers, reg.normalised_residual, by_images
        )
        out.append(v)
        records[n] = (
            key,
            v.accepted,
            v.reason.encode()[:_REASON_BYTES],
            p6,
            c6[_UPPER],
            v.matches,
            v.inliers,
            v.normalised_residual,
            v.direct,
        )
    name = hashlib.sha1(b"".join(item[-1] for item in items)).hexdigest()
    path = ctx.verify_dir / f"{name}.npy"

    def write(p: Path) -> None:
        with open(p, "wb") as fh:
            np.save(fh, records)

    atomic_write(path, write)
    return out


def _read_verified(verify_dir: Path) -> dict[bytes, np.void]:
    """Every cached verification, by key (unreadable files are ignored: they are redone)."""
    out: dict[bytes, np.void] = {}
    if not verify_dir.is_dir():
        return out
    for path in sorted(verify_dir.glob("*.npy")):
        try:
            records = np.load(path)
        except (OSError, ValueError):
            log.warning("%s: unreadable verification cache file ignored", path)
            continue
        if records.dtype == _VERIFY_RECORD:
            # NumPy gives a bytes field back without its trailing NUL bytes: pad the key to its
            # length again, or one verification in 256 (a key ending in 0x00) is never found
            size = _VERIFY_RECORD["key"].itemsize
            out.update((bytes(r["key"]).ljust(size, b"\0"), r) for r in records)
    return out


def _from_cache(i: int, j: int, r: np.void) -> Verification:
    cov = np.zeros((6, 6))
    cov[_UPPER] = r["cov6"]
    cov = cov + np.triu(cov, 1).T
    return Verification(
        i,
        j,
        bool(r["accepted"]),
        r["reason"].decode(),
        np.array(r["pose6"]),
        cov,
        int(r["matches"]),
        int(r["inliers"]),
        float(r["residual"]),
        bool(r["direct"]),
    )


def learn_vocabulary(
    descriptors: Callable[[int], NDArray[np.uint8] | None], n: int, words: int, sample: int = 20_000
) -> Vocabulary | None:
    """A vocabulary learnt from about ``sample`` descriptors drawn evenly from ``n`` stereo pairs
    (``descriptors(k)``: pair k's, None when it has none); None when there are too few to split."""
    rng = np.random.default_rng(0)
    picked = range(0, n, max(1, n // 50))
    per_pair = max(1, sample // len(picked))
    desc = []
    for k in picked:
        d = descriptors(k)
        if d is not None and len(d):
            desc.append(d[rng.choice(len(d), min(per_pair, len(d)), replace=False)])
    if not desc:
        return None
    data = np.concatenate(desc)
    return build_vocabulary(data, words) if len(data) >= 20 * words else None


def _map(
    executor: Executor,
    fn: Callable[[_Context, list], list],
    ctx: _Context,
    items: list,
    chunk: int,
    stage: str,
    progress: Progress | None,
    done0: int = 0,
    total: int | None = None,
) -> list:
    """``fn`` over ``items`` in chunks through the executor, with progress; results in order."""
    total = len(items) if total is None else total
    results: list = []
    done = done0
    for out in executor.map(fn, ctx, chunks(items, chunk)):
        results.extend(out)
        done += len(out)
        if progress:
            progress(stage, done, total)
    return results


# ---------------------------------------------------------------------------------------------
# The stage
# ---------------------------------------------------------------------------------------------


def dvl_altitude_available(dive: Dive) -> bool:
    """Whether the DVL log has at least two valid altitudes (a real log may have none)."""
    alt = dive.dvl.altitude_m
    if alt is None:
        return False
    return int(np.count_nonzero(dive.dvl.valid & np.isfinite(alt) & (alt > 0))) >= 2


def stereo_altitude(files: list[str], rig: StereoRig, R_ned_body: FloatArray) -> FloatArray:
    """Altitude of each stereo pair from its own triangulated points, metres (NaN without points).

    The median, over the pair's points, of their depth below the body origin (the points moved into
    the body frame with the rig's mount and levelled with the prior's attitude): the stereo range to
    the seafloor, used for footprints when the DVL log has no altitude.
    """
    T_bc = T_body_cam(rig)
    out = np.full(len(files), np.nan)
    for k, (path, R) in enumerate(zip(files, R_ned_body, strict=True)):
        p = _load(path).p_cam_m
        if len(p):
            out[k] = float(np.median((p @ T_bc[:3, :3].T + T_bc[:3, 3]) @ R[2]))
    return out


def image_altitude(
    dive: Dive, t_s: FloatArray, *, stereo: tuple[FloatArray, FloatArray] | None = None
) -> FloatArray:
    """Altitude at the image times, metres: the DVL's (valid samples interpolated) or, when the DVL
    log has none, ``stereo`` (times and altitudes, :func:`stereo_altitude`) interpolated."""
    if dvl_altitude_available(dive):
        ok = dive.dvl.valid & np.isfinite(dive.dvl.altitude_m) & (dive.dvl.altitude_m > 0)  # type: ignore[operator]
        return np.interp(t_s, dive.dvl.t_s[ok], dive.dvl.altitude_m[ok])  # type: ignore[index]
    if stereo is not None and len(stereo[0]) >= 2:
        return np.interp(t_s, stereo[0], stereo[1])
    what = "no altitude_m column" if dive.dvl.altitude_m is None else "fewer than two valid altitudes"
    raise InsufficientDataError(
        f"nav/dvl: {what}; cannot place image footprints (the loop stage falls back to the stereo range)"
    )


@lru_cache(maxsize=4)
def _chi2_2dof(probability: float) -> float:
    return float(chi2.ppf(probability, 2))


def prior_agreement(
    measured_ne_m: FloatArray,
    predicted_ne_m: FloatArray,
    sigma_m: FloatArray,
    dyaw_rad: FloatArray,
    settings: LoopSettings,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], FloatArray]:
    """Whether registered loops (N) agree with their priors: the measured displacement within the
    ``prior_gate_probability`` chi-square (2 dof) of the predicted one, its sigma the prior's
    ``sigma_m`` and the measurement's own (:func:`measurement_sigma`); and the relative heading within
    ``max_heading_disagreement_rad`` of the prior's (``dyaw_rad``: measured less predicted). Returns
    both tests and the sigma."""
    err = measured_ne_m - predicted_ne_m
    sigma = np.hypot(sigma_m, measurement_sigma(measured_ne_m))
    in_gate = np.sum(err**2, axis=1) / sigma**2 <= _chi2_2dof(settings.prior_gate_probability)
    return in_gate, np.abs(dyaw_rad) <= settings.max_heading_disagreement_rad, sigma


def _prior_check(
    v: Verification, fp: Footprints, centre: FloatArray, sigma: float, settings: LoopSettings
) -> str:
    """Why a registered loop disagrees with the corrected prior ("" when it agrees).

    ``sigma``: the corrected prior's relative uncertainty (:func:`prior_agreement`).
    """
    measured = fp.measured_displacement(np.array([v.i]), np.array([v.j]), v.pose6[None, :])
    predicted = (centre[v.j] - centre[v.i])[None, :]
    dyaw = angle_diff(v.pose6[5], angle_diff(fp.yaw_rad[v.j], fp.yaw_rad[v.i]))
    in_gate, heading, total = prior_agreement(
        measured, predicted, np.array([sigma]), np.array([dyaw]), settings
    )
    if not in_gate[0]:
        off = float(np.linalg.norm(measured[0] - predicted[0]))
        return f"disagrees with the prior ({off:.2f} m off, sigma {total[0]:.2f} m)"
    if not heading[0]:
        return f"relative heading {np.degrees(dyaw):.1f} deg off the compass's"
    return ""


def find_loops(
    dive: Dive,
    prior: Trajectory,
    *,
    settings: LoopSettings | None = None,
    cache_dir: Path | None = None,
    executor: Executor | None = None,
    progress: Progress | None = None,
) -> LoopResult:
    """Loop closures of a dive with images.

    Parameters
    ----------
    dive : Dive
        Must have images and a stereo calibration; ``dive.path`` locates ``images/``.
    prior : Trajectory
        Navigation covering the image times (``products/nav/filter.csv`` or ``dr.csv``).
    settings : LoopSettings, optional
    cache_dir : Path, optional
        The stage's cache: features in ``features/``, verified pairs in ``verify/`` (default
        ``DIVE/products/cache/vision``). Both are reused by content: a rerun, or a run resumed after
        a kill, does again only what no file holds.
    executor : Executor, optional
        Runs the per-pair work (default: in this process).
    progress : callable(stage, done, total), optional
        Stages ``"features"`` and ``"verify"`` (its total grows as rounds add candidates).

    Returns
    -------
    LoopResult
    """
    settings = settings or LoopSettings()
    executor = executor or SerialExecutor()
    if dive.images is None or len(dive.images) == 0:
        raise InsufficientDataError("images/index.csv: the dive has no images")
    if dive.vehicle.stereo is None:
        raise ConfigError(f"{dive.info.vehicle_file}: no stereo calibration (key stereo)")
    if dive.path is None:
        raise ValueError("find_loops needs dive.path to locate images/")
    rig = dive.vehicle.stereo
    images: ImageIndex = dive.images
    t = images.t_s
    inside = (t >= prior.t_s[0]) & (t <= prior.t_s[-1])
    if not inside.all():
        log.warning(
            "images/index.csv: %d image(s) outside the navigation's time span ignored", int((~inside).sum())
        )
    index = np.flatnonzero(inside)
    if len(index) < 2:
        raise InsufficientDataError(
            "images/index.csv: fewer than two images inside the navigation's time span"
        )
    cache_dir = Path(cache_dir) if cache_dir is not None else P.cache_dir(dive.path, "vision")
    verify_dir = cache_dir / "verify"
    ctx = _Context(
        dive.path / "images", rig, rectification(rig), settings, cache_dir / "features", verify_dir
    )
    started = time.perf_counter()
    items = [(int(k), str(images.left[k]), str(images.right[k])) for k in index]
    feats = _map(executor, _features_task, ctx, items, 4, "features", progress)
    t_features = time.perf_counter() - started
    files = {k: f for k, f, _ in feats if f is not None}
    n_features = {k: n for k, f, n in feats if f is not None}
    usable = np.array(sorted(files), dtype=np.intp)
    if len(usable) < 2:
        raise InsufficientDataError("images: fewer than two readable stereo pairs")
    if settings.vocabulary_words > 1:
        picked = [files[k] for k in usable]
        vocabulary = learn_vocabulary(
            lambda k: _load(picked[k]).descriptors, len(picked), settings.vocabulary_words
        )
        ctx = replace(ctx, vocabulary=vocabulary)
    verified = _read_verified(verify_dir)
    salt = _verification_salt(settings, ctx.vocabulary)
    pri = prior.interpolate(t[usable])
    stereo = None
    if not dvl_altitude_available(dive):
        what = "no altitude_m column" if dive.dvl.altitude_m is None else "fewer than two valid altitudes"
        log.warning(
            "nav/dvl: %s: loop closures need the altitude to place the image footprints; using the "
            "stereo range instead (each pair's median point depth)",
            what,
        )
        ranges = stereo_altitude([files[int(k)] for k in usable], rig, pri.R_ned_body)
        ok = np.isfinite(ranges) & (ranges > 0)
        if ok.sum() < 2:
            raise InsufficientDataError(
                f"nav/dvl: {what}, and fewer than two stereo pairs give a range: cannot place image footprints"
            )
        stereo = (pri.t_s[ok], ranges[ok])
    fp_u = footprints(pri, image_altitude(dive, t[usable], stereo=stereo), rig)
    steps = np.linalg.norm(np.diff(pri.p_ned_m[:, :2], axis=0), axis=1)  # horizontal, between images
    drift = DriftModel(pri.t_s, float(np.median(steps / np.diff(pri.t_s))), settings.candidates)
    priors = _Priors(
        drift,
        fp_u,
        T_body_cam(rig),
        se3(pri.R_ned_body, pri.p_ned_m) @ T_body_cam(rig),
        pri,
        path_turn(pri.yaw_rad),
        np.concatenate([[0.0], np.cumsum(steps)]),
    )
    # Work in positions within `usable` (u) and map back to image rows at the end.
    tested: dict[tuple[int, int], Verification] = {}
    consecutive = [(a, a + 1) for a in range(len(usable) - 1)]
    todo = consecutive
    rounds = 0
    done = 0
    total = 0
    reused = 0
    anchors: list[Verification] = []
    network: Network | None = None
    network_solves, network_s, network_from = 0, 0.0, 0  # network_from: the loops at the last attempt
    searched: dict[tuple[int, int], float] = {}  # each tested pair's direct search sigma
    while todo and rounds < settings.max_rounds:
        rounds += 1
        total += len(todo)
        work = _work_items(todo, usable, files, priors, salt, anchors, network)
        searched.update(((w[0], w[1]), w[7]) for w in work)
        cached = [_from_cache(w[0], w[1], verified[w[-1]]) for w in work if w[-1] in verified]
        fresh = [w for w in work if w[-1] not in verified]
        reused += len(cached)
        done += len(cached)
        results = cached + _map(executor, _verify_task, ctx, fresh, 16, "verify", progress, done, total)
        done += len(fresh)
        centre = fp_u.centre_ne_m + drift.correction(fp_u.t_s)
        for v in sorted(results, key=lambda v: (v.i, v.j)):
            if v.accepted and v.j - v.i > 1:
                sigma = float(drift.relative_sigma(fp_u.t_s[[v.i]], fp_u.t_s[[v.j]])[0])
                reason = _prior_check(v, fp_u, centre, sigma, settings)
                if reason:
                    v = replace(v, accepted=False, reason=reason)
            tested[(v.i, v.j)] = v
        _refit(drift, fp_u, tested)
        anchors = _anchors(tested)
        if settings.direct is not None and len(anchors) > (1 + NETWORK_GROWTH) * network_from:
            # tried again only once the loops have grown, whether or not GTSAM solved it last time
            solving = time.perf_counter()
            network = priors.network(anchors) or network
            network_s += time.perf_counter() - solving
            network_solves += 1
            network_from = len(anchors)
        ci, cj, _ = candidate_pairs(fp_u, drift, settings.candidates, exclude=set(tested))
        # Verified in image order: a worker's chunk then shares feature files (its cache).
        todo = sorted(_limit_per_image(ci, cj, settings.per_image_per_round))
        if settings.direct is not None:
            again = _searched_again(tested, searched, priors, anchors, network)
            for pair in again:
                del tested[pair]
            todo = sorted(set(todo) | set(again))
    if todo:
        log.warning("stopped after %d rounds with %d candidates untested", rounds, len(todo))
    # Back to image rows.
    out = [
        replace(v, i=int(usable[v.i]), j=int(usable[v.j]))
        for v in sorted(tested.values(), key=lambda v: (v.i, v.j))
    ]
    loops = loop_closures([v for v in out if v.accepted], t)
    # why pairs were refused: the features' reason (or the prior's) and, apart, the images'
    reasons: dict[str, int] = {}
    direct_reasons: dict[str, int] = {}
    for v in out:
        if not v.accepted:
            features, _, images = v.reason.partition("; direct: ")
            key = features.split(" (")[0]
            reasons[key] = reasons.get(key, 0) + 1
            if images:
                key = images.split(" (")[0]
                direct_reasons[key] = direct_reasons.get(key, 0) + 1
    elapsed = time.perf_counter() - started
    summary = {
        "pairs": len(t),
        "pairs_with_features": len(usable),
        "pairs_skipped": int(len(index) - len(usable)),
        "features_median": float(np.median(list(n_features.values()))) if n_features else 0.0,
        "candidates_tested": len(out),
        "consecutive_tested": len(consecutive),
        "loops_accepted": int(sum(v.accepted for v in out)),
        "nonconsecutive_accepted": int(sum(v.accepted and v.j - v.i > 1 for v in out)),
        "direct_accepted": int(sum(v.accepted and v.direct for v in out)),
        "rejected": reasons,
        "direct_rejected": direct_reasons,
        "rounds": rounds,
        "network_solves": network_solves,
        "network_s": network_s,
        "verifications_reused": reused,
        "executor": executor.name,
        "workers": executor.workers,
        "features_s": t_features,
        "elapsed_s": elapsed,
        "pairs_per_s": len(usable) / elapsed if elapsed > 0 else float("nan"),
        "altitude_source": "dvl" if stereo is None else "stereo",
        "settings": json.loads(json.dumps(asdict(settings), default=float)),
    }
    return LoopResult(loops, out, summary)


def _verification_salt(settings: LoopSettings, vocabulary: Vocabulary | None) -> bytes:
    """What every verification depends on besides its pair and prior: the registration's settings and
    the vocabulary (learnt from the dive's features)."""
    h = hashlib.sha1(f"verify/3:{asdict(settings.registration)}:{settings.direct}".encode())
    if vocabulary is not None:
        h.update(np.ascontiguousarray(vocabulary.centres).tobytes())
    return h.digest()


@dataclass(frozen=True)
class _Priors:
    """Where the priors of a pair's relative pose come from (:meth:`of`).

    ``drift`` is refitted in place after each round; ``T_raw``: the camera poses of the uncorrected
    prior ``prior`` (``T_bc``: the camera in the body); ``turns``: :func:`path_turn` of its headings;
    ``path_m``: distance along its track at each image."""

    drift: DriftModel
    fp: Footprints
    T_bc: FloatArray
    T_raw: FloatArray
    prior: Trajectory
    turns: Callable[[NDArray[np.intp], NDArray[np.intp]], FloatArray]
    path_m: FloatArray

    def heading_sigma(self, a: NDArray[np.intp], b: NDArray[np.intp]) -> FloatArray:
        """The relative heading's 1-sigma between images a and b (either order):
        :data:`HEADING_SIGMA_RAD` once the vehicle has turned a quarter turn or more between them, in
        proportion below."""
        return HEADING_SIGMA_RAD * np.minimum(
            1.0, self.turns(np.minimum(a, b), np.maximum(a, b)) / (np.pi / 2)
        )

    def track_sigma(self, a: NDArray[np.intp], b: NDArray[np.intp]) -> FloatArray:
        """The dead reckoning's relative 1-sigma over the track between images a and b, before its
        heading's share (:data:`SHORT_SIGMA_FLOOR_M` and :data:`SHORT_DRIFT_FRACTION` of the distance)."""
        return np.hypot(SHORT_SIGMA_FLOOR_M, SHORT_DRIFT_FRACTION * np.abs(self.path_m[b] - self.path_m[a]))

    def of(
        self,
        a: NDArray[np.intp],
        b: NDArray[np.intp],
        anchors: list[Verification],
        network: Network | None = None,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Two priors of the camera pose of b in a (pairs a < b), each with its lateral 1-sigma.

        The first, for the features' guided matching, is the prior corrected by the drift model,
        with the drift model's uncertainty. The second, for the direct registration's search window,
        is the same, or, when the dead reckoning over the track between the two images is more
        certain (:meth:`track_sigma`), the prior as it is with that uncertainty: the drift model's
        knots are 20 s apart, its correction between them is a straight line, and it has a floor of
        its own. Both add the compass's heading error turning the displacement
        (:meth:`heading_sigma`). With ``anchors`` (loops already registered from features), the
        second prior is the one through the nearest of them when that is more certain still
        (:meth:`anchored`); with a ``network`` of them (:mod:`auvnav.vision.network`), a pair whose
        second prior is still looser than :data:`NETWORK_FROM_SIGMA_M` takes the network's when that
        is more certain (with :data:`SHORT_SIGMA_FLOOR_M` added)."""
        p_ned = self.prior.p_ned_m.copy()
        p_ned[:, :2] += self.drift.correction(self.prior.t_s)
        T = se3(self.prior.R_ned_body, p_ned) @ self.T_bc
        T_ab = se3_inverse(T[a]) @ T[b]
        drift_sigma = self.drift.relative_sigma(self.fp.t_s[a], self.fp.t_s[b])
        short = self.track_sigma(a, b)
        heading = self.heading_sigma(a, b) * np.linalg.norm(T_ab[:, :2, 3], axis=1)
        sigma = np.hypot(drift_sigma, heading)
        near = short < drift_sigma
        T_near = np.where(near[:, None, None], se3_inverse(self.T_raw[a]) @ self.T_raw[b], T_ab)
        sigma_near = np.hypot(np.where(near, short, drift_sigma), heading)
        if anchors:
            T_anchor, sigma_anchor = self.anchored(a, b, anchors)
            better = sigma_anchor < sigma_near
            T_near = np.where(better[:, None, None], T_anchor, T_near)
            sigma_near = np.where(better, sigma_anchor, sigma_near)
        if network is not None:
            loose = np.flatnonzero(sigma_near > NETWORK_FROM_SIGMA_M)
            T_net, sigma_net = network.relative(a[loose], b[loose], self.T_bc)
            sigma_net = np.hypot(SHORT_SIGMA_FLOOR_M, sigma_net)
            better = sigma_net < sigma_near[loose]
            T_near[loose[better]] = T_net[better]
            sigma_near[loose[better]] = sigma_net[better]
        return T_ab, sigma, T_near, sigma_near

    def network(self, anchors: list[Verification]) -> Network | None:
        """The network of the images and ``anchors`` (:func:`auvnav.vision.network.solve_network`), or
        None, with a warning, when GTSAM cannot solve it (the stage then keeps the network it had)."""
        try:
            return solve_network(
                se3(self.prior.R_ned_body, self.prior.p_ned_m),
                np.array([v.i for v in anchors], dtype=np.intp),
                np.array([v.j for v in anchors], dtype=np.intp),
                from_pose6(np.array([v.pose6 for v in anchors])),
                np.array([v.cov6 for v in anchors]),
            )
        except AuvnavError as err:
            log.warning(
                "the network of %d loops was not solved (%s); priors through single loops", len(anchors), err
            )
            return None

    def anchored(
        self, a: NDArray[np.intp], b: NDArray[np.intp], anchors: list[Verification]
    ) -> tuple[FloatArray, FloatArray]:
        """The camera pose of b in a through a registered loop (c, d) near them along the track, and
        its lateral 1-sigma (metres): the dead reckoning from a to c, the loop, the dead reckoning from
        d to b. Each leg has the uncertainty of :meth:`track_sigma` and its heading's share of its
        length; the loop adds its covariance and its yaw's share over the second leg. The loop ties
        the two passes' headings, which the drift model's prior does not: a pair on a ripple field,
        whose crests repeat a few centimetres apart, is searched in a window of a centimetre or two
        instead of the drift model's ten or more. Of the :data:`ANCHOR_NEIGHBOURS` loops nearest
        (a, b) along the track, the most certain."""
        c = np.array([v.i for v in anchors], dtype=np.intp)
        d = np.array([v.j for v in anchors], dtype=np.intp)
        cov = np.array([v.cov6 for v in anchors])
        loop_sigma = np.sqrt(cov[:, 0, 0] + cov[:, 1, 1])
        yaw_sigma = np.sqrt(cov[:, 5, 5])
        path = self.path_m
        tree = cKDTree(np.column_stack([path[c], path[d]]))
        k = min(ANCHOR_NEIGHBOURS, len(anchors))
        _, nearest = tree.query(np.column_stack([path[a], path[b]]), k=k)
        nearest = nearest.reshape(len(a), k)

        def leg(x: NDArray[np.intp], y: NDArray[np.intp]) -> FloatArray:
            return np.hypot(self.track_sigma(x, y), self.heading_sigma(x, y) * np.abs(path[y] - path[x]))

        sigmas = np.empty((len(a), k))
        for n in range(k):
            m = nearest[:, n]
            second = np.abs(path[b] - path[d[m]])
            sigmas[:, n] = np.sqrt(
                leg(a, c[m]) ** 2 + leg(d[m], b) ** 2 + loop_sigma[m] ** 2 + (yaw_sigma[m] * second) ** 2
            )
        best = np.argmin(sigmas, axis=1)
        m = nearest[np.arange(len(a)), best]
        T_cd = from_pose6(np.array([anchors[q].pose6 for q in m]))
        T_cd_cam = se3_inverse(self.T_bc) @ T_cd @ self.T_bc
        T_raw = self.T_raw
        T = se3_inverse(T_raw[a]) @ T_raw[c[m]] @ T_cd_cam @ se3_inverse(T_raw[d[m]]) @ T_raw[b]
        return T, sigmas[np.arange(len(a)), best]


def _work_items(
    pairs: list[tuple[int, int]],
    usable: NDArray[np.intp],
    files: dict[int, str],
    priors: _Priors,
    salt: bytes,
    anchors: list[Verification],
    network: Network | None,
) -> list[WorkItem]:
    """Verification work: pairs with their feature files, their two priors (:meth:`_Priors.of`) and
    the key of the outcome in the verification cache."""
    a = np.array([p[0] for p in pairs], dtype=np.intp)
    b = np.array([p[1] for p in pairs], dtype=np.intp)
    T_ab, sigma, T_near, sigma_near = priors.of(a, b, anchors, network)
    out = []
    for k, (i, j) in enumerate(zip(a, b, strict=True)):
        fi, fj = files[int(usable[i])], files[int(usable[j])]
        key = hashlib.sha1(
            salt
            + os.path.basename(fi).encode()
            + b"|"
            + os.path.basename(fj).encode()
            + b"|"
            + T_ab[k].tobytes()
            + float(sigma[k]).hex().encode()
            + T_near[k].tobytes()
            + float(sigma_near[k]).hex().encode()
        ).digest()
        out.append((int(i), int(j), fi, fj, T_ab[k], float(sigma[k]), T_near[k], float(sigma_near[k]), key))
    return out


#: The dead reckoning's relative error between two images close along the track, 1-sigma, metres (the
#: DVL's noise and the footprint model's own errors), before the share of the distance travelled.
SHORT_SIGMA_FLOOR_M = 0.005
#: ... and its growth with the distance travelled. On the check dive in turbid water (raw compass), the
#: filter's relative error between images 1, 2, 4, 8 and 16 apart is a median 0.5-0.9% of the distance
#: along the track and a 90th percentile of 1.8-2.8% (the DVL's scale error, 0.2%, and the compass's
#: noise and deviation turning it); the deviation's change through turns is the heading term.
SHORT_DRIFT_FRACTION = 0.01
#: The relative heading error of two images, 1-sigma, once the vehicle has turned through a quarter
#: turn or more between them: the compass's deviation differs from heading to heading by degrees
#: (paper section II-C), and the same heading error is shared by images on one straight leg.
HEADING_SIGMA_RAD = 0.1


#: A pair whose prior through the dead reckoning or single loops is looser than this (1-sigma, metres)
#: takes the network's, when more certain (:meth:`_Priors.of`). Below it the network's random walk of
#: steps understates the dead reckoning's steady drift between images close along the track: over the
#: whole check dive in turbid water, recall 0.871 from 1 cm, 0.892 from 2 cm, 0.894 from 3 cm.
NETWORK_FROM_SIGMA_M = 0.03
#: The network is solved again once the loops registered from features have grown by this fraction.
NETWORK_GROWTH = 0.1

#: Loop closures through which :meth:`_Priors.anchored` looks for a pair's prior, nearest first along
#: the track.
ANCHOR_NEIGHBOURS = 4


def path_turn(yaw_rad: FloatArray) -> Callable[[NDArray[np.intp], NDArray[np.intp]], FloatArray]:
    """A function of index pairs (a, b), a <= b, giving how far the heading strays from its value at
    ``a`` over ``yaw_rad[a..b]`` (radians, the largest absolute difference of the unwrapped
    heading), in constant time per pair (a sparse table of range minima and maxima)."""
    y = np.unwrap(np.asarray(yaw_rad, dtype=float))
    lo, hi = [y], [y]
    span = 1
    while 2 * span <= len(y):
        lo.append(np.minimum(lo[-1][:-span], lo[-1][span:]))
        hi.append(np.maximum(hi[-1][:-span], hi[-1][span:]))
        span *= 2

    def turned(a: NDArray[np.intp], b: NDArray[np.intp]) -> FloatArray:
        a, b = np.minimum(a, b), np.maximum(a, b)
        if len(a) == 0:
            return np.zeros(0)
        level = np.floor(np.log2(b - a + 1)).astype(np.intp)
        out = np.empty(len(a))
        for k in np.unique(level):
            m = level == k
            start, end = a[m], b[m] - (1 << int(k)) + 1
            top = np.maximum(hi[k][start], hi[k][end])
            bottom = np.minimum(lo[k][start], lo[k][end])
            out[m] = np.maximum(top - y[a[m]], y[a[m]] - bottom)
        return out

    return turned


def _limit_per_image(i: NDArray[np.intp], j: NDArray[np.intp], cap: int) -> list[tuple[int, int]]:
    """The pairs, in order, in which no image appears more than ``cap`` times."""
    count: dict[int, int] = {}
    out = []
    for a, b in zip(i.tolist(), j.tolist(), strict=True):
        if count.get(a, 0) < cap and count.get(b, 0) < cap:
            out.append((a, b))
            count[a] = count.get(a, 0) + 1
            count[b] = count.get(b, 0) + 1
    return out


def _anchors(tested: dict[tuple[int, int], Verification]) -> list[Verification]:
    """The loops registered from features so far, not between consecutive pairs: the anchors of
    :meth:`_Priors.anchored` (a loop from the images may have taken the wrong one of look-alike places, and
    a prior through it would lead its neighbours to the same mistake)."""
    return [v for v in tested.values() if v.accepted and not v.direct and v.j - v.i > 1]


#: The direct registration's refusals that a more certain prior may overturn.
PRIOR_LIMITED = ("prior too uncertain", "ambiguous", "best correlation at the edge", "no refinement stayed")
#: A refused pair is searched again when a loop found since makes its prior this much more certain.
SEARCH_AGAIN_RATIO = 0.5


def _searched_again(
    tested: dict[tuple[int, int], Verification],
    searched: dict[tuple[int, int], float],
    priors: _Priors,
    anchors: list[Verification],
    network: Network | None,
) -> list[tuple[int, int]]:
    """Pairs the direct registration refused for want of a certain prior whose prior through the
    loops found since (``anchors``, :meth:`_Priors.anchored`) is :data:`SEARCH_AGAIN_RATIO` times as
    uncertain or less than the one they were searched with (``searched``)."""
    refused = [
        pair
        for pair, v in tested.items()
        if not v.accepted and v.reason.partition("; direct: ")[2].startswith(PRIOR_LIMITED)
    ]
    if not anchors or not refused:
        return []
    a, b = np.array(refused, dtype=np.intp).T
    sigma_near = priors.of(a, b, anchors, network)[3]
    return [
        pair for pair, s in zip(refused, sigma_near, strict=True) if s < SEARCH_AGAIN_RATIO * searched[pair]
    ]


def _refit(drift: DriftModel, fp: Footprints, tested: dict[tuple[int, int], Verification]) -> None:
    """Refit the drift model to the accepted non-consecutive loops (footprint-centre displacements)."""
    acc = [v for v in tested.values() if v.accepted and v.j - v.i > 1]
    if not acc:
        return
    i = np.array([v.i for v in acc])
    j = np.array([v.j for v in acc])
    measured = fp.measured_displacement(i, j, np.array([v.pose6 for v in acc]))
    sigma = measurement_sigma(measured)
    drift.fit(fp.t_s[i], fp.t_s[j], measured - (fp.centre_ne_m[j] - fp.centre_ne_m[i]), sigma)


def measurement_sigma(measured_ne_m: FloatArray) -> FloatArray:
    """1-sigma (per axis) of loop displacements turned into the world with the prior's heading: 5 cm
    (footprint model) plus 3% of the length (a compass error of a couple of degrees turns the vector)."""
    return 0.05 + 0.03 * np.linalg.norm(measured_ne_m, axis=1)


def loop_closures(accepted: list[Verification], t_s: FloatArray) -> LoopClosures:
    """The ``loops.csv`` content (:mod:`auvnav.vision.loopfile`) of accepted verifications."""
    i = np.array([v.i for v in accepted], dtype=np.int64)
    j = np.array([v.j for v in accepted], dtype=np.int64)
    p6 = np.array([v.pose6 for v in accepted]).reshape(-1, 6)
    cov = np.array([v.cov6 for v in accepted]).reshape(-1, 6, 6)
    T = from_pose6(p6)
    inliers = np.array([v.inliers for v in accepted], dtype=np.int64)
    method = np.array(["images" if v.direct else "features" for v in accepted], dtype=str)
    return loops_from_transforms(i, j, t_s[i], t_s[j], T, cov, inliers, method)
