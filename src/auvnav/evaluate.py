"""Scoring a simulated dive's products against its truth (DESIGN section 7, ``auvnav evaluate``).

Each section of the result scores one stage's products and appears only when they exist; the truth
is ``DIVE/truth/trajectory.csv`` written by the simulator. A stage adds its section to
:data:`SECTIONS`: a function of the dive folder and the truth that returns the section's keys, or
None when the stage's products are absent.

Trajectory scores (:func:`score_trajectory`) compare positions at the estimate's times, the truth
interpolated there (estimate samples outside the truth's span are left out, with a warning):

- ``ate_rmse_m``: root mean square of the 3D position error with no alignment (truth and estimate
  share the dive's origin); the same number as evo's APE on the translation part
  (``evo_ape tum truth.tum estimate.tum``) for the same samples;
- ``ate_aligned_rmse_m``: the same after the best rigid alignment in x, y, z and yaw
  (:func:`align_yaw_translation`), the consistency the paper is about;
- ``end_error_m``: 3D error at the estimate's last sample, and ``end_error_pct`` = end error /
  ``distance_m`` x 100, ``distance_m`` the length of the whole true track (3D);
- ``yaw_rmse_deg``: root mean square of the heading error.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from auvnav import products as P
from auvnav.compass.evaluate import compass_section
from auvnav.errors import DiveFormatError, Problem
from auvnav.frames import FloatArray, angle_diff, rot_z
from auvnav.trajectory import Trajectory, read_trajectory

log = logging.getLogger(__name__)

TRUTH_FILE = Path("truth") / "trajectory.csv"


@dataclass(frozen=True)
class TrajectoryScore:
    """How an estimated trajectory compares with the truth (see the module docstring).

    Parameters
    ----------
    end_error_m, end_error_pct, ate_rmse_m, ate_aligned_rmse_m : float
        Metres, percent of the true distance, metres, metres.
    yaw_rmse_deg : float
        Degrees.
    """

    end_error_m: float
    end_error_pct: float
    ate_rmse_m: float
    ate_aligned_rmse_m: float
    yaw_rmse_deg: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def align_yaw_translation(p_est_m: FloatArray, p_ref_m: FloatArray) -> tuple[float, FloatArray]:
    """The rotation about the vertical and translation that best map ``p_est`` onto ``p_ref``.

    Least squares, ``min sum |Rz(yaw) p_est_i + t - p_ref_i|^2``: with the centred points ``e``,
    ``r``, ``yaw = atan2(sum e_n r_e - e_e r_n, sum e_n r_n + e_e r_e)`` and
    ``t = mean(p_ref) - Rz(yaw) mean(p_est)`` (the 4-DOF case of Umeyama, "Least-squares estimation
    of transformation parameters between two point patterns", IEEE TPAMI 13(4), 1991).

    Parameters
    ----------
    p_est_m, p_ref_m : ndarray, shape (N, 3), metres, local NED

    Returns
    -------
    yaw_rad : float
    t_ned_m : ndarray, shape (3,)
    """
    mean_est, mean_ref = p_est_m.mean(axis=0), p_ref_m.mean(axis=0)
    e, r = p_est_m - mean_est, p_ref_m - mean_ref
    yaw = math.atan2(
        float(np.sum(e[:, 0] * r[:, 1] - e[:, 1] * r[:, 0])),
        float(np.sum(e[:, 0] * r[:, 0] + e[:, 1] * r[:, 1])),
    )
    return yaw, mean_ref - rot_z(yaw) @ mean_est


def _rms_norm(x: FloatArray) -> float:
    """Root mean square of the row norms of ``x`` (N, k), or of ``x`` (N,)."""
    squares = x**2 if x.ndim == 1 else np.sum(x**2, axis=1)
    return float(np.sqrt(np.mean(squares)))


def score_trajectory(
    truth: Trajectory, estimate: Trajectory, distance_m: float, what: str = "estimate"
) -> TrajectoryScore:
    """Score an estimate against the truth at the estimate's times (see the module docstring).

    Parameters
    ----------
    truth, estimate : Trajectory
    distance_m : float
        Length of the true track, metres (for ``end_error_pct``).
    what : str
        Names the estimate in messages.

    Raises
    ------
    DiveFormatError
        No estimate sample lies inside the truth's span.
    """
    inside = (estimate.t_s >= truth.t_s[0]) & (estimate.t_s <= truth.t_s[-1])
    if not np.any(inside):
        raise DiveFormatError([Problem(what, "no sample lies inside the truth's time span")])
    if not np.all(inside):
        log.warning(
            "%s: %d of %d samples lie outside the truth's time span, not scored",
            what,
            np.count_nonzero(~inside),
            len(inside),
        )
    est = estimate.select(inside)
    ref = truth.interpolate(est.t_s)
    error = est.p_ned_m - ref.p_ned_m
    yaw, t = align_yaw_translation(est.p_ned_m, ref.p_ned_m)
    aligned = est.p_ned_m @ rot_z(yaw).T + t
    end = float(np.linalg.norm(error[-1]))
    return TrajectoryScore(
        end_error_m=end,
        end_error_pct=100.0 * end / distance_m if distance_m > 0 else math.nan,
        ate_rmse_m=_rms_norm(error),
        ate_aligned_rmse_m=_rms_norm(aligned - ref.p_ned_m),
        yaw_rmse_deg=math.degrees(_rms_norm(angle_diff(est.yaw_rad, ref.yaw_rad))),
    )


Section = Callable[[Path, Trajectory, float], "dict[str, Any] | None"]


def trajectory_section(product: P.Product) -> Section:
    """A section scoring a trajectory product."""

    def section(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
        path = product.path(dive_path)
        if not path.is_file():
            return None
        return score_trajectory(truth, read_trajectory(path), distance_m, str(path)).as_dict()

    return section


def _compass(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """The dive's own compass correction against its true deviation (:mod:`auvnav.compass.evaluate`)."""
    path = P.COMPASS_CORRECTION.path(dive_path)
    return compass_section(dive_path, path) if path.is_file() else None


def _slam(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """The SLAM trajectory's scores; with a deviation estimated in the graph, also that curve's
    (``deviation_rmse_deg`` as the compass section's, ``deviation_shape_rmse_deg`` without the
    constant); with the DVL calibrated in the graph, its errors (:func:`dvl_errors`)."""
    scores = trajectory_section(P.SLAM_TRAJECTORY)(dive_path, truth, distance_m)
    estimated = P.existing(dive_path, P.SLAM_CORRECTION)
    if scores is not None and estimated is not None:
        compass = compass_section(dive_path, estimated)
        scores["deviation_rmse_deg"] = compass["deviation_rmse_deg"]
        scores["deviation_shape_rmse_deg"] = compass["shape_rmse_deg"]
    summary = P.SLAM_SUMMARY.path(dive_path)
    if scores is not None and summary.is_file():
        calibration = json.loads(summary.read_text(encoding="utf-8")).get("dvl")
        if calibration is not None:
            scores.update(dvl_errors(dive_path, calibration))
    return scores


def dvl_errors(dive_path: Path, calibration: dict[str, Any]) -> dict[str, Any]:
    """A DVL calibration estimated by SLAM (``summary.json``'s ``dvl``,
    :meth:`auvnav.slam.dvl.DvlCalibration.summary`) against the simulator's truth (``truth.yaml``):
    ``dvl_scale_factor_error`` (estimated less true, measured = (1 + scale) x true),
    ``dvl_misalignment_error_deg`` (roll, pitch, yaw) and ``dvl_time_offset_error_s``, the
    simulator's own offset being half its step (:mod:`auvnav.slam.dvl`). Empty when the truth has
    no DVL errors."""
    from auvnav.config import load_yaml

    path = Path(dive_path) / "truth" / "truth.yaml"
    data, _ = load_yaml(path, str(path))
    if not isinstance(data, dict) or not isinstance(data.get("dvl"), dict):
        return {}
    true = data["dvl"]
    errors: dict[str, Any] = {
        "dvl_scale_factor_error": calibration["scale_factor"] - float(true["scale_factor"]),
        "dvl_misalignment_error_deg": (
            np.asarray(calibration["misalignment_rpy_deg"])
            - np.asarray(true["misalignment_rpy_deg"], dtype=float)
        ).tolist(),
    }
    if isinstance(data.get("dt_s"), (int, float)):
        errors["dvl_time_offset_error_s"] = calibration["time_offset_s"] + 0.5 * float(data["dt_s"])
    return errors


def _online(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """The SLAM estimate as the vehicle knew it at each moment (``slam/online.csv``, ``--online``) and
    the time per pose of its updates (``slam/summary.json``).

    The online error is each image pose's estimate as known when the iSAM2 update that added it
    finished, scored as any trajectory (``ate_aligned_rmse_m``: one yaw and translation alignment for
    the whole dive, as the batch's); ``ratio_to_smoothed`` is it over the ``slam`` section's (the same
    run's smoothed estimate after the last update, the batch solution's within a millimetre), and
    ``aligned_rmse_by_quarter_m`` the same aligned errors' RMS over each quarter of the dive's time
    (the online error early in a dive, before loop closures or a deviation are observable)."""
    path = P.SLAM_ONLINE.path(dive_path)
    if not path.is_file():
        return None
    online = read_trajectory(path)
    score = score_trajectory(truth, online, distance_m, str(path))
    scores: dict[str, Any] = {"ate_aligned_rmse_m": score.ate_aligned_rmse_m, "ate_rmse_m": score.ate_rmse_m}
    smoothed = P.SLAM_TRAJECTORY.path(dive_path)
    if smoothed.is_file():
        batch = score_trajectory(truth, read_trajectory(smoothed), distance_m, str(smoothed))
        scores["ratio_to_smoothed"] = score.ate_aligned_rmse_m / batch.ate_aligned_rmse_m
    est = online.select((online.t_s >= truth.t_s[0]) & (online.t_s <= truth.t_s[-1]))
    ref = truth.interpolate(est.t_s).p_ned_m
    yaw, t = align_yaw_translation(est.p_ned_m, ref)
    error = np.linalg.norm(est.p_ned_m @ rot_z(yaw).T + t - ref, axis=1)
    quarter = np.minimum((4 * (est.t_s - est.t_s[0]) / max(est.t_s[-1] - est.t_s[0], 1e-9)).astype(int), 3)
    scores["aligned_rmse_by_quarter_m"] = [
        _rms_norm(error[quarter == q]) if np.any(quarter == q) else math.nan for q in range(4)
    ]
    summary = P.SLAM_SUMMARY.path(dive_path)
    record = json.loads(summary.read_text(encoding="utf-8")).get("online") if summary.is_file() else None
    if record:
        for key in ("update_median_ms", "update_p95_ms", "update_max_ms", "loop_delay_median_s"):
            scores[key] = record[key]
    return scores


def _loops(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """Visual loop closures against the truly overlapping pairs (:mod:`auvnav.vision.evaluate`)."""
    from auvnav.vision.evaluate import loops_section

    return loops_section(dive_path, truth, distance_m)


def _depth(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """Loop-closure depth residuals before and after the tide (:mod:`auvnav.depth.evaluate`)."""
    from auvnav.depth.evaluate import depth_section

    return depth_section(dive_path)


def _coverage(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """Coverage, gaps and line spacing against the truth's (:mod:`auvnav.coverage.evaluate`), the
    true footprints on the simulator's seafloor."""
    from auvnav.coverage.evaluate import coverage_section

    if not P.COVERAGE_SUMMARY.path(dive_path).is_file():
        return None
    floor = None
    truth_yaml = Path(dive_path) / "truth" / "truth.yaml"
    if truth_yaml.is_file():
        from auvnav.sim.camera import seafloor_from_truth

        floor = seafloor_from_truth(truth_yaml)
    return coverage_section(dive_path, truth, floor)


def _recon(dive_path: Path, truth: Trajectory, distance_m: float) -> dict[str, Any] | None:
    """The reconstruction against the simulator's seafloor and albedo (:mod:`auvnav.recon.evaluate`):
    DEM error, orthophoto misregistration, false relief before and after the tide (DESIGN keys first)."""
    from auvnav.recon.evaluate import recon_section

    truth_yaml = Path(dive_path) / "truth" / "truth.yaml"
    if not P.RECON_SUMMARY.path(dive_path).is_file() or not truth_yaml.is_file():
        return None
    floor, texture = _seafloor_and_texture(truth_yaml)
    scores = recon_section(dive_path, truth, floor, texture, align_yaw_translation)
    if scores is None:
        return None
    first = [
        "dem_rmse_m", "mosaic_misregistration_median_px", "mosaic_misregistration_p95_px",
        "relief_step_before_m", "relief_step_after_m",
    ]  # fmt: skip
    return {**{k: scores.get(k) for k in first}, **{k: v for k, v in scores.items() if k not in first}}


def evaluate_recon(dive_path: Path, *, folder: Path | None = None) -> dict[str, Any] | None:
    """The ``recon`` section for a reconstruction in ``folder`` (default the dive's own products)."""
    from auvnav.recon.evaluate import recon_section

    truth_yaml = Path(dive_path) / "truth" / "truth.yaml"
    if not truth_yaml.is_file():
        return None
    floor, texture = _seafloor_and_texture(truth_yaml)
    return recon_section(
        dive_path, read_truth(dive_path), floor, texture, align_yaw_translation, folder=folder
    )


def _seafloor_and_texture(truth_yaml: Path) -> tuple[Any, Any]:
    """The simulated seafloor and albedo of a dive (the images are rendered with the dive's seed)."""
    from auvnav.config import load_yaml
    from auvnav.sim.camera import seafloor_from_truth
    from auvnav.sim.texture import SeafloorTexture

    data, _ = load_yaml(truth_yaml, str(truth_yaml))
    seed = data.get("seed") if isinstance(data, dict) else None
    texture = SeafloorTexture(seed=int(seed)) if isinstance(seed, int) else None
    return seafloor_from_truth(truth_yaml), texture


#: Sections in output order (DESIGN section 7): name -> scorer (None when its products are absent).
SECTIONS: dict[str, Section] = {
    "dr": trajectory_section(P.NAV_DR),
    "filter": trajectory_section(P.NAV_FILTER),
    "slam": _slam,
    "online": _online,
    "loops": _loops,
    "compass": _compass,
    "depth": _depth,
    "coverage": _coverage,
    "recon": _recon,
}


def read_truth(dive_path: Path) -> Trajectory:
    """A simulated dive's true trajectory; a one-line error when the dive has none."""
    path = Path(dive_path) / TRUTH_FILE
    if not path.is_file():
        raise DiveFormatError(
            [Problem(str(path), "not found: only simulated dives have a truth to score against")]
        )
    return read_trajectory(path)


#: Inter-dive scores compare images of two dives whose true positions lie within this distance
#: (horizontal, metres): the overlap, where the dives' footprints share most of their area.
OVERLAP_RADIUS_M = 0.5
#: An inter-dive loop closure is true when its relative pose is within these of the truth's.
TRUE_LOOP_TRANSLATION_M = 0.1
TRUE_LOOP_ROTATION_DEG = 1.0


def evaluate_campaign(folder: Path) -> dict[str, Any]:
    """The ``campaign`` section of a campaign folder (:mod:`auvnav.campaign`), its dives simulated.

    - ``inter_dive_rmse_m``: over every pair of images of two dives whose true positions lie within
      :data:`OVERLAP_RADIUS_M` of each other (each image of the later dive with its nearest of the
      earlier), the root mean square of the 3D error of their relative position in the common frame
      (``inter_dive_horizontal_rmse_m``: north and east only);
    - ``inter_dive_loop_precision``: the kept inter-dive loop closures whose relative pose is within
      :data:`TRUE_LOOP_TRANSLATION_M` and :data:`TRUE_LOOP_ROTATION_DEG` of the truth's, over all kept;
      ``inter_dive_loops_kept``, ``inter_dive_false_kept``, ``inter_dive_false_rejected``.
    """
    import pandas as pd
    from scipy.spatial import cKDTree

    from auvnav.campaign import INTER_DIVE_LOOPS_FILE, read_campaign
    from auvnav.frames import se3

    info = read_campaign(folder)
    dives = info["dives"]
    est: dict[str, Trajectory] = {}
    true: dict[str, Trajectory] = {}
    distance = 0.0
    for d in dives:
        truth = read_truth(Path(d["path"]))
        distance += truth.distance_m()
        estimate = read_trajectory(Path(folder) / "dives" / d["name"] / "trajectory.csv")
        ref = truth.interpolate(estimate.t_s)
        offset = np.array([d["offset_ned_m"][0], d["offset_ned_m"][1], 0.0])
        true[d["name"]] = Trajectory(
            t_s=ref.t_s, p_ned_m=ref.p_ned_m + offset, roll_rad=ref.roll_rad, pitch_rad=ref.pitch_rad,
            yaw_rad=ref.yaw_rad,
        )  # fmt: skip
        est[d["name"]] = estimate
    errors = []
    for a in range(len(dives)):
        for b in range(a + 1, len(dives)):
            na, nb = dives[a]["name"], dives[b]["name"]
            dist, nearest = cKDTree(true[na].p_ned_m[:, :2]).query(true[nb].p_ned_m[:, :2])
            rows_b = np.flatnonzero(dist <= OVERLAP_RADIUS_M)
            rows_a = nearest[rows_b]
            d_est = est[nb].p_ned_m[rows_b] - est[na].p_ned_m[rows_a]
            d_true = true[nb].p_ned_m[rows_b] - true[na].p_ned_m[rows_a]
            errors.append(d_est - d_true)
    error = np.concatenate(errors) if errors else np.zeros((0, 3))
    loops = pd.read_csv(Path(folder) / INTER_DIVE_LOOPS_FILE)
    good = np.zeros(len(loops), dtype=bool)
    for (na, nb), group in loops.groupby(["dive_a", "dive_b"]):
        ra, rb = group["row_a"].to_numpy(), group["row_b"].to_numpy()
        Ta = se3(true[str(na)].R_ned_body[ra], true[str(na)].p_ned_m[ra])
        Tb = se3(true[str(nb)].R_ned_body[rb], true[str(nb)].p_ned_m[rb])
        T_true = np.linalg.inv(Ta) @ Tb
        t_meas = group[["x_m", "y_m", "z_m"]].to_numpy()
        yaw_true = np.arctan2(T_true[:, 1, 0], T_true[:, 0, 0])
        yaw_err = np.degrees(np.abs(angle_diff(np.radians(group["yaw_deg"].to_numpy()), yaw_true)))
        ok = (np.linalg.norm(t_meas - T_true[:, :3, 3], axis=1) < TRUE_LOOP_TRANSLATION_M) & (
            yaw_err < TRUE_LOOP_ROTATION_DEG
        )
        good[group.index.to_numpy()] = ok
    kept = loops["kept"].to_numpy().astype(bool)
    change = _campaign_change(Path(folder), info, est, true)
    return {
        "inter_dive_rmse_m": _rms_norm(error) if len(error) else math.nan,
        "inter_dive_loop_precision": float(np.count_nonzero(kept & good) / max(np.count_nonzero(kept), 1)),
        "inter_dive_horizontal_rmse_m": _rms_norm(error[:, :2]) if len(error) else math.nan,
        "overlap_pairs": len(error),
        "inter_dive_loops_kept": int(np.count_nonzero(kept)),
        "inter_dive_false_kept": int(np.count_nonzero(kept & ~good)),
        "inter_dive_false_rejected": int(np.count_nonzero(~kept & ~good)),
        "inter_dive_true_rejected": int(np.count_nonzero(~kept & good)),
        **change,
        "distance_m": distance,
    }


def _true_changed_area(
    folder: Path,
    info: dict[str, Any],
    dive: dict[str, Any],
    centre: FloatArray,
    shift: FloatArray,
    mound: dict[str, Any],
    threshold: float,
) -> float:
    """Area of the DEM difference's observed cells (both DEMs there) near a removed mound (``centre``,
    campaign frame) where the true seafloor changed by more than ``threshold``: the first dive's
    seafloor against ``dive``'s, a cell's true position its campaign one less ``shift``."""
    import rasterio

    from auvnav.campaign import DEM_DIFFERENCE_FILE
    from auvnav.frames import GeodeticOrigin
    from auvnav.raster import map2ned
    from auvnav.sim.camera import seafloor_from_truth

    path = folder / DEM_DIFFERENCE_FILE
    if not path.is_file():
        return math.nan
    with rasterio.open(path) as src:
        diff, transform = src.read(1), src.transform
    rows, cols = np.nonzero(np.isfinite(diff))
    x, y = transform @ (cols + 0.5, rows + 0.5)
    o = info["origin"]
    origin = GeodeticOrigin(math.radians(o["latitude_deg"]), math.radians(o["longitude_deg"]), o["height_m"])
    ne = map2ned(np.column_stack([x, y]), origin)
    near = np.hypot(ne[:, 0] - centre[0], ne[:, 1] - centre[1]) <= mound["a_m"] + 0.5
    first = info["dives"][0]
    before = seafloor_from_truth(Path(first["path"]) / "truth" / "truth.yaml")
    after = seafloor_from_truth(Path(dive["path"]) / "truth" / "truth.yaml")
    pts = ne[near] - shift
    change = after.depth_m(
        pts[:, 0] - dive["offset_ned_m"][0], pts[:, 1] - dive["offset_ned_m"][1]
    ) - before.depth_m(pts[:, 0] - first["offset_ned_m"][0], pts[:, 1] - first["offset_ned_m"][1])
    return float(np.count_nonzero(np.abs(change) > threshold) * abs(transform.a * transform.e))


def _campaign_change(
    folder: Path, info: dict[str, Any], est: dict[str, Trajectory], true: dict[str, Trajectory]
) -> dict[str, Any]:
    """The DEM difference's changed regions (``changes.csv``) against the coral heads the simulator
    removed (``truth/change.yaml`` of a dive): the largest region whose peak lies within the mound's
    half-length of its centre, its area against the true one (the observed cells where the true
    seafloor changed by more than the campaign's threshold, :func:`_true_changed_area`), its peak
    change against the mound's height, and the largest region that matches none."""
    import pandas as pd
    import yaml

    from auvnav.campaign import CHANGES_FILE

    path = folder / CHANGES_FILE
    if not path.is_file():
        return {}
    regions = pd.read_csv(path)
    threshold = float(info["settings"]["change_threshold_m"])
    matched = np.zeros(len(regions), dtype=bool)
    out: dict[str, Any] = {}
    for d in info["dives"]:
        change_file = Path(d["path"]) / "truth" / "change.yaml"
        if not change_file.is_file():
            continue
        for mound in yaml.safe_load(change_file.read_text(encoding="utf-8")).get("removed", []):
            centre = np.array([mound["north_m"], mound["east_m"]]) + np.array(d["offset_ned_m"][:2])
            # The campaign's frame against the truth's there (its GPS-referenced placement error):
            # the first dive's estimate less the truth at its images within 6 m of the mound.
            ref = info["dives"][0]["name"]
            near_images = np.hypot(*(true[ref].p_ned_m[:, :2] - centre).T) <= 6.0
            shift = np.zeros(2)
            if np.any(near_images):
                shift = np.median(
                    est[ref].p_ned_m[near_images, :2] - true[ref].p_ned_m[near_images, :2], axis=0
                )
            centre = centre + shift
            dist = np.hypot(regions["north_m"] - centre[0], regions["east_m"] - centre[1]).to_numpy()
            near = dist <= max(mound["a_m"], 1.0)
            true_area = _true_changed_area(folder, info, d, centre, shift, mound, threshold)
            out["change_found"] = bool(np.any(near))
            if np.any(near):
                k = int(np.argmax(np.where(near, regions["area_m2"].to_numpy(), -1.0)))
                matched |= near
                out["change_area_m2"] = float(regions["area_m2"].iloc[k])
                out["change_area_true_m2"] = true_area
                out["change_height_m"] = float(abs(regions["height_change_m"].iloc[k]))
                out["change_height_true_m"] = float(mound["height_m"])
    if out:
        others = regions["area_m2"].to_numpy()[~matched]
        out["false_change_max_area_m2"] = float(others.max()) if len(others) else 0.0
    return out


def evaluate_dive(dive_path: Path, *, compass_correction: Path | None = None) -> dict[str, Any]:
    """Score every product of a simulated dive that exists against its truth.

    Parameters
    ----------
    dive_path : Path
        A dive folder with ``truth/trajectory.csv``.
    compass_correction : Path, optional
        A compass correction file to score in the ``compass`` section instead of the dive's own
        ``products/compass/correction.yaml``.

    Returns
    -------
    dict
        ``{"distance_m": float, <section>: {...}, ...}`` (DESIGN section 7), a section per stage whose
        products exist.
    """
    dive_path = Path(dive_path)
    from auvnav.campaign import CAMPAIGN_FILE

    if (dive_path / CAMPAIGN_FILE).is_file():  # a campaign folder: its section alone
        campaign = evaluate_campaign(dive_path)
        return {"distance_m": campaign.pop("distance_m"), "campaign": campaign}
    truth = read_truth(dive_path)
    distance = truth.distance_m()
    result: dict[str, Any] = {"distance_m": distance}
    for name, section in SECTIONS.items():
        if name == "compass" and compass_correction is not None:
            scores = compass_section(dive_path, Path(compass_correction))
        else:
            scores = section(dive_path, truth, distance)
        if scores is not None:
            result[name] = scores
    return result


def _cell(value: Any) -> str:
    """A score as shown: floats to 4 significant digits, lists of floats as ``[a b ...]``."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list) and value and all(isinstance(v, float) for v in value):
        return "[" + " ".join(f"{v:.4g}" for v in value) + "]"
    return str(value)


def format_scores(result: dict[str, Any]) -> str:
    """A short human-readable table of :func:`evaluate_dive`'s result."""
    lines = [f"distance travelled (truth): {result['distance_m']:.1f} m"]
    sections = [(name, value) for name, value in result.items() if isinstance(value, dict)]
    if not sections:
        lines.append("no products to score")
    for name, scores in sections:
        cells = ", ".join(f"{key} {_cell(value)}" for key, value in scores.items())
        lines.append(f"{name:8s} {cells}")
    return "\n".join(lines)
