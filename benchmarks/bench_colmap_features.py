"""A peer's front end, side by side: pycolmap's SIFT extraction and matching against auvnav's, pair by pair.

Both get the same images: pairs of left images of a simulated dive with images (``--dive``, e.g. the
check dive rendered at half scale, ``auvnav simulate navcheck --water turbid``) that overlap in truth
(left camera centres within ``--max-offset-m`` horizontally, at least ``--min-gap`` images apart),
``--pairs`` of them drawn with a fixed seed. For each pair:

- COLMAP (pycolmap, CPU): SIFT extraction of both left images (``max_num_features`` ``--features``,
  other options COLMAP's defaults), its matcher (ratio 0.8, cross-check) and its relative pose
  (LO-RANSAC on the essential matrix, ``estimate_relative_pose``) with the left camera's calibration:
  a rotation and a direction of travel (one camera: no scale);
- auvnav: the stereo features of both stereo pairs (illumination correction, adaptive SIFT, tracking
  into the right image, triangulation: :func:`~auvnav.vision.stereo.stereo_features`, default
  settings) and the 3-D registration of the loop stage (:func:`~auvnav.vision.registration.register`,
  without a prior): a metric 6-DoF pose.

Printed: keypoints per image, matches (COLMAP: matcher output and RANSAC inliers; auvnav: stereo
matches per pair, descriptor matches and registration inliers), pose errors against the truth
(rotation, direction of the translation; auvnav also metres), the fraction of pairs each one gets within
1 degree, and wall time per pair on this machine (extraction of two images plus matching and pose).

``--colmap-input corrected`` gives COLMAP the images auvnav's SIFT sees (illumination-corrected and
contrast-stretched): what of the difference is the preprocessing.

Usage: ``.venv/bin/python benchmarks/bench_colmap_features.py --dive DIVE [--pairs 30]
[--colmap-input raw|corrected] [--pairs-file PAIRS.json]``; ``--pairs-file``: given pairs (a JSON list
of ``[i, j]``), e.g. the true loops the loop stage missed.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import cv2
import numpy as np

from auvnav.dive import ImageIndex, find_stream_file, vehicle_file_name
from auvnav.frames import se3, se3_inverse
from auvnav.streams import read_stream
from auvnav.trajectory import read_trajectory
from auvnav.vehicle import read_vehicle
from auvnav.vision.camera import rectification
from auvnav.vision.features import FeatureSettings, correct_illumination, stretch_contrast
from auvnav.vision.registration import register
from auvnav.vision.stereo import read_grey, stereo_features


def angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


def direction_error_deg(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return float("nan")
    return float(np.degrees(np.arccos(np.clip(a @ b / (na * nb), -1.0, 1.0))))


def choose_pairs(
    T_left: np.ndarray, count: int, max_offset_m: float, min_gap: int, seed: int
) -> list[tuple[int, int]]:
    c = T_left[:, :3, 3]
    d = np.hypot(c[:, None, 0] - c[None, :, 0], c[:, None, 1] - c[None, :, 1])
    i, j = np.nonzero(np.triu(d <= max_offset_m, k=min_gap))
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(i), size=min(count, len(i)), replace=False) if len(i) else []
    return sorted((int(i[k]), int(j[k])) for k in pick)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dive", type=Path, required=True)
    parser.add_argument("--pairs", type=int, default=30)
    parser.add_argument("--features", type=int, default=1500, help="keypoint cap of both (auvnav's default)")
    parser.add_argument("--max-offset-m", type=float, default=0.5)
    parser.add_argument("--min-gap", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--pairs-file",
        type=Path,
        help="the pairs to compare instead of drawn ones: a JSON list of [i, j] rows of images/index.csv "
        "(e.g. the true loops the loop stage missed)",
    )
    parser.add_argument(
        "--colmap-input",
        choices=("raw", "corrected"),
        default="raw",
        help="COLMAP's images: as recorded, or illumination-corrected and contrast-stretched as auvnav's",
    )
    args = parser.parse_args()
    import pycolmap

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    dive = args.dive
    index_file = find_stream_file(dive, ImageIndex.FILE)
    assert index_file is not None, "the dive has no images"
    index = read_stream(ImageIndex, index_file, str(index_file))
    rig = read_vehicle(dive / (vehicle_file_name(dive) or "vehicle.yaml")).stereo
    assert rig is not None
    truth = read_trajectory(dive / "truth" / "trajectory.csv").interpolate(index.t_s)
    T_body_left = se3(rig.mount.R_body_sensor, rig.mount.lever_arm_body_m)
    T_left = se3(truth.R_ned_body, truth.p_ned_m) @ T_body_left
    if args.pairs_file is not None:
        pairs = [(int(i), int(j)) for i, j in json.loads(args.pairs_file.read_text(encoding="utf-8"))]
    else:
        pairs = choose_pairs(T_left, args.pairs, args.max_offset_m, args.min_gap, args.seed)
    images = index_file.parent

    # COLMAP's conventions: a pixel's centre at +0.5; OPENCV model fx, fy, cx, cy, k1, k2, p1, p2.
    K, D = rig.left.K, np.asarray(rig.left.D, dtype=float)
    camera = pycolmap.Camera(
        model="OPENCV",
        width=rig.left.width,
        height=rig.left.height,
        params=[K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5, D[0], D[1], D[2], D[3]],
    )
    options = pycolmap.FeatureExtractionOptions()
    options.num_threads = 1
    options.sift.max_num_features = args.features
    sift = pycolmap.Sift(options, device=pycolmap.Device.cpu)
    match_options = pycolmap.FeatureMatchingOptions()
    match_options.num_threads = 1
    matcher = pycolmap.FeatureMatcher.create(match_options, device=pycolmap.Device.cpu)
    ransac = pycolmap.RANSACOptions()
    ransac.max_error = 4.0  # pixels, COLMAP's two-view geometry default
    ransac.random_seed = 0
    settings = FeatureSettings(max_features=args.features)
    rect = rectification(rig)

    rows = []
    for i, j in pairs:
        T_true = se3_inverse(T_left[i]) @ T_left[j]  # pose of j's left camera in i's
        grey = {k: read_grey(images / index.left[k]) for k in (i, j)}
        right = {k: read_grey(images / index.right[k]) for k in (i, j)}
        # COLMAP
        t0 = time.perf_counter()
        kp, desc = {}, {}
        for k in (i, j):
            image = grey[k]
            if args.colmap_input == "corrected":
                image = stretch_contrast(correct_illumination(image), settings)[0]
            kp[k], desc[k] = sift.extract(np.ascontiguousarray(image))
        t1 = time.perf_counter()
        if min(len(kp[i]), len(kp[j])):  # COLMAP's byte descriptors: 512 times the float ones, saturated
            as_bytes = {
                k: pycolmap.FeatureDescriptors(
                    pycolmap.FeatureExtractorType.SIFT,
                    np.clip(np.rint(512 * desc[k]), 0, 255).astype(np.uint8),
                )
                for k in (i, j)
            }
            none = pycolmap.FeatureKeypoints()
            m = matcher.match(none, as_bytes[i], none, as_bytes[j])
        else:
            m = np.zeros((0, 2))
        m = np.asarray(m, dtype=int).reshape(-1, 2)
        est = None
        if len(m) >= 5:
            est = pycolmap.estimate_relative_pose(
                camera, kp[i][m[:, 0], :2].astype(float), camera, kp[j][m[:, 1], :2].astype(float), ransac
            )
        t2 = time.perf_counter()
        row = {"i": i, "j": j, "colmap_keypoints": (len(kp[i]) + len(kp[j])) / 2, "colmap_matches": len(m),
               "colmap_extract_s": t1 - t0, "colmap_s": t2 - t0}  # fmt: skip
        if est is not None:
            pose = est["cam2_from_cam1"]  # x_j = R x_i + t: the inverse of T_true
            R = np.asarray(pose.rotation.matrix())
            T_est = se3_inverse(se3(R, np.asarray(pose.translation)))
            row["colmap_inliers"] = int(np.sum(est["inlier_mask"])) if "inlier_mask" in est else len(m)
            row["colmap_rot_err_deg"] = angle_deg(T_est[:3, :3].T @ T_true[:3, :3])
            row["colmap_dir_err_deg"] = direction_error_deg(T_est[:3, 3], T_true[:3, 3])
        # auvnav
        t0 = time.perf_counter()
        feats = {k: stereo_features(grey[k], right[k], rig, rect, settings) for k in (i, j)}
        t1 = time.perf_counter()
        reg = register(feats[i], feats[j])
        t2 = time.perf_counter()
        row.update({"auvnav_stereo_matches": (len(feats[i]) + len(feats[j])) / 2, "auvnav_matches": reg.matches,
                    "auvnav_inliers": reg.inliers, "auvnav_accepted": reg.accepted,
                    "auvnav_extract_s": t1 - t0, "auvnav_s": t2 - t0})  # fmt: skip
        if reg.inliers >= 3:
            T_est = reg.T_a_b
            row["auvnav_rot_err_deg"] = angle_deg(T_est[:3, :3].T @ T_true[:3, :3])
            row["auvnav_dir_err_deg"] = direction_error_deg(T_est[:3, 3], T_true[:3, 3])
            row["auvnav_pos_err_m"] = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
        rows.append(row)
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()}), flush=True)

    def med(key: str) -> float:
        values = [r[key] for r in rows if key in r]
        return float(np.median(values)) if values else float("nan")

    def within(key: str, limit: float) -> float:
        return float(np.mean([r.get(key, np.inf) <= limit for r in rows])) if rows else float("nan")

    summary = {
        "dive": str(dive),
        "colmap_input": args.colmap_input,
        "pairs": len(rows),
        "image_size": [rig.left.width, rig.left.height],
        "colmap": {"keypoints_per_image": med("colmap_keypoints"), "matches": med("colmap_matches"),
                   "inliers": med("colmap_inliers"), "rotation_error_deg": med("colmap_rot_err_deg"),
                   "direction_error_deg": med("colmap_dir_err_deg"),
                   "pairs_within_1deg": within("colmap_rot_err_deg", 1.0), "s_per_pair": med("colmap_s"),
                   "extract_s_per_pair": med("colmap_extract_s")},
        "auvnav": {"stereo_matches_per_pair": med("auvnav_stereo_matches"), "matches": med("auvnav_matches"),
                   "inliers": med("auvnav_inliers"), "accepted": float(np.mean([r["auvnav_accepted"] for r in rows])),
                   "rotation_error_deg": med("auvnav_rot_err_deg"), "direction_error_deg": med("auvnav_dir_err_deg"),
                   "position_error_m": med("auvnav_pos_err_m"),
                   "pairs_within_1deg": within("auvnav_rot_err_deg", 1.0), "s_per_pair": med("auvnav_s"),
                   "extract_s_per_pair": med("auvnav_extract_s")},
        "load_average": os.getloadavg(),
    }  # fmt: skip
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    cv2.setNumThreads(1)
    main()
