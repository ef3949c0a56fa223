"""Loop closures from the simulator's truth: a testing aid for the SLAM back end without rendering.

``auvnav simulate ... --truth-loops [--false-loops F]`` writes, beside the dive's truth:

- ``images/index.csv``, when the images are not rendered: the camera's trigger log, the times and
  the file names the renderer would use (:func:`auvnav.sim.camera.select_image_times`: 1 Hz while the
  vehicle is within imaging altitude), as a vehicle whose images were not downloaded has it. Row
  ``k`` (0-based) is pose ``k`` of the loop file and of the SLAM graph.
- ``truth/loops.csv``: loop closures in the one loop-file format (:mod:`auvnav.vision.loopfile`:
  ``T_i_j = inv(T_ned_body_i) @ T_ned_body_j``, covariance of (x, y, z, roll, pitch, yaw)), ``i``
  and ``j`` rows of ``images/index.csv``.
- ``truth/loops.yaml``: how they were made (noise, threshold, seed) and which rows are false.

**Which pairs.** Each pair's footprint is the left camera's image rectangle (pinhole, corners of the
image) projected on the horizontal plane at the seafloor's depth below the camera
(:mod:`auvnav.footprint`). Two pairs whose footprints overlap by at least ``min_overlap`` of the
smaller one (convex polygon clipping) become a
loop closure, consecutive pairs included (the visual odometry a vision front end measures). The
default, 20%, is the vision front end's candidate threshold (:class:`auvnav.vision.candidates.
CandidateSettings`): the default rig sees 1.3 m across track from 1.7 m above the floor, so the lines
of a survey 1 m apart overlap by about 23% and a 30% threshold would join none of them. An image
takes part in at most ``max_per_image`` non-consecutive loop closures, the largest overlaps first
(a front end's budget; where every arm of a navigation check crosses, hundreds of images overlap).

**Noise.** The true relative pose's six parameters (x, y, z in body ``i``; roll, pitch, yaw of
``R_i_j``) are perturbed by independent Gaussian noise, ``sigma_translation_m`` (1 cm) and
``sigma_rotation_rad`` (0.1 degree) per axis, the vision front end's target; the file's covariance is
that diagonal, so it matches the noise drawn exactly.

**False loop closures.** A fraction ``false_fraction`` of the rows written (false / all) joins two
random non-consecutive pairs near each other (footprint centres within :data:`FALSE_RADIUS_M`, as
a front end's candidates are) whose footprints do not overlap at all, with a plausible-looking but
wrong relative pose: what a false match between similar-looking images claims, a horizontal offset
within a footprint (uniform in +-0.6 m), a small vertical offset (5 cm), roll and pitch of a degree
and any yaw, with the same covariance as the true ones. ``inliers`` is not simulated: true rows carry
``round(400 x overlap)``, false rows 20 to 60.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav.dive import ImageIndex, vehicle_file_name
from auvnav.errors import ConfigError
from auvnav.footprint import SeafloorLike, footprints, overlapping_pairs
from auvnav.frames import FloatArray, from_pose6, se3_inverse
from auvnav.sim.camera import (
    body_poses,
    default_stereo_rig,
    image_names,
    seafloor_from_truth,
    select_image_times,
)
from auvnav.streams import atomic_write, read_stream, write_stream
from auvnav.trajectory import Trajectory, read_trajectory
from auvnav.vehicle import StereoRig, read_vehicle
from auvnav.vision.loopfile import LoopClosures, loops_from_transforms, write_loops

log = logging.getLogger(__name__)

LOOPS_FILE = Path("truth") / "loops.csv"
LOOPS_INFO_FILE = Path("truth") / "loops.yaml"

#: The vision front end's target accuracy per axis (issue 7): 1 cm and 0.1 degree.
SIGMA_TRANSLATION_M = 0.01
SIGMA_ROTATION_RAD = math.radians(0.1)
#: Footprints overlapping by at least this fraction of the smaller one make a loop closure (the
#: vision front end's ``CandidateSettings.min_overlap``).
MIN_OVERLAP = 0.2
#: Most non-consecutive loop closures per image: a front end registers a bounded number of candidates
#: per image (the vision stage tests at most two per image and round), the most overlapping first.
MAX_PER_IMAGE = 10
#: False loops join pairs whose footprint centres lie within this distance, metres: the candidates a
#: front end tests, which dead reckoning (drifting metres per hundred metres) places near each other.
FALSE_RADIUS_M = 4.0
#: A false loop claims a horizontal offset within a footprint: uniform in +-this, metres.
FALSE_OFFSET_M = 0.6
_FALSE_VERTICAL_SIGMA_M = 0.05
_FALSE_TILT_SIGMA_RAD = math.radians(1.0)


@dataclass(frozen=True)
class TruthLoops:
    """Loop closures derived from a true trajectory.

    Parameters
    ----------
    image_times_s : ndarray, shape (P,)
        Stereo pair times, POSIX seconds; row k is pose k.
    loops : LoopClosures
        The rows written to ``truth/loops.csv`` (true ones first, then the false ones).
    is_false : ndarray of bool, shape (N,)
        Which rows are false loop closures.
    overlap : ndarray, shape (N,)
        Footprint overlap of each row, fraction of the smaller footprint (0 for the false ones).
    """

    image_times_s: FloatArray
    loops: LoopClosures
    is_false: NDArray[np.bool_]
    overlap: FloatArray

    def __post_init__(self) -> None:
        n = len(self.loops)
        if np.shape(self.is_false) != (n,) or np.shape(self.overlap) != (n,):
            raise ValueError(
                f"is_false and overlap must have shape ({n},); found {np.shape(self.is_false)} "
                f"and {np.shape(self.overlap)}"
            )


def _limit_per_image(
    pairs: NDArray[np.int64], overlap: FloatArray, cap: int
) -> tuple[NDArray[np.int64], FloatArray]:
    """Consecutive pairs, and the non-consecutive ones by decreasing overlap while both images have
    fewer than ``cap``; sorted by i, then j."""
    count = np.zeros(int(pairs.max()) + 1 if len(pairs) else 0, dtype=np.int64)
    keep = pairs[:, 1] - pairs[:, 0] == 1
    for r in np.argsort(-overlap, kind="stable"):
        a, b = pairs[r]
        if not keep[r] and count[a] < cap and count[b] < cap:
            keep[r] = True
            count[a] += 1
            count[b] += 1
    return pairs[keep], overlap[keep]


def _pose6_noise(rng: np.random.Generator, n: int, sigma_t: float, sigma_r: float) -> FloatArray:
    return rng.standard_normal((n, 6)) * np.repeat([sigma_t, sigma_r], 3)


def truth_loops(
    truth: Trajectory,
    seafloor: SeafloorLike,
    image_times_s: FloatArray,
    *,
    rig: StereoRig | None = None,
    min_overlap: float = MIN_OVERLAP,
    max_per_image: int = MAX_PER_IMAGE,
    sigma_translation_m: float = SIGMA_TRANSLATION_M,
    sigma_rotation_rad: float = SIGMA_ROTATION_RAD,
    false_fraction: float = 0.0,
    seed: int = 0,
) -> TruthLoops:
    """Loop closures between the stereo pairs of a true trajectory (see the module docstring).

    Parameters
    ----------
    truth : Trajectory
        The true trajectory (interpolated at the image times).
    seafloor : object with ``depth_m(north_m, east_m)``
    image_times_s : ndarray, shape (P,)
        Stereo pair times inside the trajectory, POSIX seconds.
    rig : StereoRig, optional
        Default :func:`auvnav.sim.camera.default_stereo_rig`.
    min_overlap : float
        Footprint overlap (fraction of the smaller footprint) that makes a loop closure, in (0, 1].
    max_per_image : int
        Most non-consecutive loop closures an image takes part in (the largest overlaps first).
    sigma_translation_m, sigma_rotation_rad : float
        Noise per axis of the translation (metres) and of roll, pitch and yaw (radians).
    false_fraction : float
        Fraction of the rows that are false, in [0, 1).
    seed : int
        Seed of the noise and of the false loops.

    Returns
    -------
    TruthLoops

    Raises
    ------
    ConfigError
        A setting out of range.
    """
    if not 0.0 < min_overlap <= 1.0 or max_per_image < 0:
        raise ConfigError(
            f"min_overlap must lie in (0, 1] and max_per_image be 0 or more; found {min_overlap} and {max_per_image}"
        )
    if not 0.0 <= false_fraction < 1.0:
        raise ConfigError(f"--false-loops must lie in [0, 1); found {false_fraction}")
    if not (sigma_translation_m > 0 and sigma_rotation_rad > 0):
        raise ConfigError("loop-closure noise must be positive")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x100B5]))
    times = np.asarray(image_times_s, dtype=float)
    T = body_poses(truth.interpolate(times))
    polygons = footprints(T, rig or default_stereo_rig(), seafloor)
    pairs, overlap = overlapping_pairs(polygons)
    keep = overlap >= min_overlap
    pairs, overlap = _limit_per_image(pairs[keep], overlap[keep], max_per_image)
    i, j = pairs[:, 0], pairs[:, 1]
    T_true = se3_inverse(T[i]) @ T[j]
    loops = loops_from_transforms(
        i, j, times[i], times[j], T_true, np.zeros((len(i), 6, 6)), np.rint(400 * overlap).astype(np.int64)
    )
    pose6 = np.column_stack([loops.t_ij_m, loops.rpy_ij_rad]) + _pose6_noise(
        rng, len(i), sigma_translation_m, sigma_rotation_rad
    )

    n_false = round(false_fraction * len(i) / (1.0 - false_fraction))
    fi, fj = _false_pairs(rng, polygons, n_false)
    false6 = np.column_stack(
        [
            rng.uniform(-FALSE_OFFSET_M, FALSE_OFFSET_M, (n_false, 2)),
            rng.normal(0.0, _FALSE_VERTICAL_SIGMA_M, n_false),
            rng.normal(0.0, _FALSE_TILT_SIGMA_RAD, (n_false, 2)),
            rng.uniform(-math.pi, math.pi, n_false),
        ]
    )
    all6 = np.concatenate([pose6, false6])
    ii, jj = np.concatenate([i, fi]), np.concatenate([j, fj])
    cov = np.broadcast_to(
        np.diag(np.repeat([sigma_translation_m, sigma_rotation_rad], 3) ** 2), (len(ii), 6, 6)
    )
    inliers = np.concatenate([loops.inliers, rng.integers(20, 61, n_false)])
    measured = loops_from_transforms(
        ii,
        jj,
        times[ii],
        times[jj],
        from_pose6(all6),
        np.ascontiguousarray(cov),
        inliers,
    )
    is_false = np.concatenate([np.zeros(len(i), dtype=bool), np.ones(n_false, dtype=bool)])
    log.info(
        "truth loops: %d stereo pairs, %d loop closures (%d consecutive), %d false",
        len(times),
        len(i),
        int(np.count_nonzero(j - i == 1)),
        n_false,
    )
    return TruthLoops(times, measured, is_false, np.concatenate([overlap, np.zeros(n_false)]))


def _false_pairs(
    rng: np.random.Generator, polygons: FloatArray, n: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``n`` random non-consecutive pairs (i < j) near each other whose footprints do not overlap.

    Near: footprint centres within :data:`FALSE_RADIUS_M`, as the candidate pairs a front end tests
    are; no overlap: centres further apart than two footprint radii.
    """
    p = len(polygons)
    centre = polygons.mean(axis=1)
    reach = 2.0 * float(np.max(np.linalg.norm(polygons - centre[:, None, :], axis=2)))
    tree = cKDTree(centre)
    out: set[tuple[int, int]] = set()
    for _ in range(100 * max(n, 1)):
        if len(out) == n:
            break
        a = int(rng.integers(0, p))
        near = np.array(tree.query_ball_point(centre[a], FALSE_RADIUS_M), dtype=np.int64)
        near = near[(np.abs(near - a) > 1) & (np.linalg.norm(centre[near] - centre[a], axis=1) > reach)]
        if near.size:
            b = int(rng.choice(near))
            out.add((min(a, b), max(a, b)))
    if len(out) < n:
        raise ConfigError(
            f"could place only {len(out)} of {n} false loop closures: too few pairs lie near each other "
            "without overlapping"
        )
    pairs = np.array(sorted(out), dtype=np.int64).reshape(-1, 2)
    pairs = pairs[rng.permutation(len(pairs))]
    return pairs[:, 0], pairs[:, 1]


def write_truth_loops(
    dive_path: Path,
    *,
    false_fraction: float = 0.0,
    seed: int = 0,
    rate_hz: float = 1.0,
    out: Path | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """Write truth loop closures for a simulated dive folder (see the module docstring).

    Parameters
    ----------
    dive_path : Path
        A dive folder written by the simulator (``truth/trajectory.csv``, ``truth/truth.yaml``).
    false_fraction : float
        Fraction of the rows that are false, in [0, 1).
    seed : int
        Seed of the noise and the false loops.
    rate_hz : float
        Camera trigger rate of the image times, when there is no ``images/index.csv``.
    out : Path, optional
        The loop file to write [``DIVE/truth/loops.csv``]; ``loops.yaml`` is written beside it, with
        the same stem.
    **settings
        ``min_overlap``, ``max_per_image``, ``sigma_translation_m``, ``sigma_rotation_rad`` of :func:`truth_loops`.

    Returns
    -------
    dict
        ``{"image_pairs", "loops", "consecutive", "false", "loops_file"}``.
    """
    dive_path = Path(dive_path)
    truth = read_trajectory(dive_path / "truth" / "trajectory.csv")
    seafloor = seafloor_from_truth(dive_path / "truth" / "truth.yaml")
    index = dive_path / "images" / "index.csv"
    rendered = index.is_file()
    if rendered:
        times = read_stream(ImageIndex, index, str(index)).t_s
    else:
        times = select_image_times(truth, seafloor, rate_hz=rate_hz)
        names = [image_names(k) for k in range(len(times))]
        log_ = ImageIndex(times, np.array([a for a, _ in names]), np.array([b for _, b in names]))
        write_stream(log_, index)
    rig = read_vehicle(dive_path / (vehicle_file_name(dive_path) or "vehicle.yaml")).stereo
    result = truth_loops(
        truth, seafloor, times, rig=rig, false_fraction=false_fraction, seed=seed, **settings
    )
    loops_path = dive_path / LOOPS_FILE if out is None else Path(out)
    write_loops(result.loops, loops_path)
    info = {
        "format": "auvnav-truth-loops/1",
        "image_times": "images/index.csv" + ("" if rendered else " (trigger log; images not rendered)"),
        "seed": seed,
        "min_overlap": settings.get("min_overlap", MIN_OVERLAP),
        "max_per_image": settings.get("max_per_image", MAX_PER_IMAGE),
        "sigma_translation_m": settings.get("sigma_translation_m", SIGMA_TRANSLATION_M),
        "sigma_rotation_deg": math.degrees(settings.get("sigma_rotation_rad", SIGMA_ROTATION_RAD)),
        "false_fraction": false_fraction,
        "loops": len(result.loops),
        "false_rows": [int(r) + 1 for r in np.flatnonzero(result.is_false)],  # 1-based data rows
    }
    text = yaml.safe_dump(info, sort_keys=False, width=100)
    atomic_write(loops_path.with_suffix(".yaml"), lambda p: p.write_text(text, encoding="utf-8"))
    return {
        "image_pairs": len(times),
        "loops": int(np.count_nonzero(~result.is_false)),
        "consecutive": int(np.count_nonzero((result.loops.j - result.loops.i == 1) & ~result.is_false)),
        "false": int(np.count_nonzero(result.is_false)),
        "loops_file": str(loops_path),
    }
