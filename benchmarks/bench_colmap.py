"""A peer, side by side: COLMAP (pycolmap, CPU) and auvnav's loops + SLAM on the same rendered images.

COLMAP is what the paper's users pick instead of auvnav: it takes position priors (3.11 and later) but
knows nothing of the compass, the DVL or the tide. Both get the same images, the left images of the
stereo pairs of the check dive's grid (``--half-m`` around the origin, placed with the dive's SLAM to
choose them), and the same prior: the navigation filter's positions of the left camera at each image,
with the filter's 1-sigma as the prior's covariance.

- COLMAP: SIFT extraction (one camera, the left camera's OpenCV calibration, fixed), spatial matching
  of each image with its ``--neighbours`` nearest priors (15), at most ``--max-features`` SIFT features
  an image (2,000; auvnav keeps 1,500), incremental mapping with the position priors
  (``use_prior_position``); its wall time, the images it registered, and their camera centres against
  the true ones, RMSE after the best rotation about the vertical and translation (auvnav's
  ``ate_aligned_rmse_m``) and after the best similarity (7 degrees of freedom);
- auvnav: a dive made of the same stereo pairs (the dive's navigation logs, its images index cut to
  those pairs), ``auvnav loops`` then ``auvnav slam`` on two workers, timed; its left camera centres
  against the truth the same two ways. (The navigation that gives both their prior is not timed.) And
  the dive's own SLAM (loops among all its images) at the same cameras, untimed: what a user has.

Usage: ``.venv/bin/python benchmarks/bench_colmap.py --dive NAVCHECK [--work DIR]`` with a processed
check dive (images at half scale, ``products/nav`` and ``products/slam``: the demo's ``navcheck``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
AUVNAV = [str(Path(sys.executable).with_name("auvnav"))]


def camera_centres(traj, t_s: np.ndarray, rig) -> np.ndarray:
    """Left camera centres (n, 3), local NED, of a trajectory at times ``t_s``."""
    from auvnav.frames import se3
    from auvnav.vision.camera import T_body_cam

    poses = traj.interpolate(t_s)
    T = se3(poses.R_ned_body, poses.p_ned_m) @ T_body_cam(rig)
    return T[:, :3, 3]


def aligned_rmse(p: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    """RMSE after the best yaw + translation, and after the best similarity (Umeyama 1991)."""
    from auvnav.evaluate import align_yaw_translation
    from auvnav.frames import rot_z

    yaw, t = align_yaw_translation(p, ref)
    four = p @ rot_z(yaw).T + t
    mp, mr = p.mean(axis=0), ref.mean(axis=0)
    a, b = p - mp, ref - mr
    U, S, Vt = np.linalg.svd(b.T @ a / len(p))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    scale = np.trace(np.diag(S) @ D) / np.mean(np.sum(a * a, axis=1))
    seven = scale * a @ R.T + mr

    def rmse(q: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((q - ref) ** 2, axis=1))))

    return {"aligned_4dof_rmse_m": rmse(four), "aligned_sim3_rmse_m": rmse(seven), "sim3_scale": float(scale)}


def run_colmap(dive: Path, work: Path, rows: np.ndarray, neighbours: int, max_features: int = 2000) -> dict:
    import pycolmap

    from auvnav import products as P
    from auvnav.dive import read_dive
    from auvnav.trajectory import read_trajectory

    d = read_dive(dive)
    rig = d.vehicle.stereo
    t = d.images.t_s[rows]
    names = [str(d.images.left[k]) for k in rows]
    prior = read_trajectory(P.NAV_FILTER.path(dive))
    prior_c = camera_centres(prior, t, rig)
    sigma = prior.interpolate(t).sigma_ned_m
    work.mkdir(parents=True, exist_ok=True)
    database = work / "database.db"
    database.unlink(missing_ok=True)
    cam = rig.left
    params = [cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], *np.asarray(cam.D, dtype=float)[:4]]
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "OPENCV"
    reader.camera_params = ",".join(f"{v:.10g}" for v in params)
    times: dict[str, float] = {}
    started = time.perf_counter()
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.sift.max_num_features = max_features  # auvnav keeps 1,500 per image
    extraction.num_threads = os.cpu_count() or 2
    pycolmap.extract_features(
        database, dive / "images", image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader, extraction_options=extraction, device=pycolmap.Device.cpu,
    )  # fmt: skip
    times["extract_s"] = time.perf_counter() - started
    with pycolmap.Database.open(database) as db:
        by_name = {img.name: img for img in db.read_all_images()}
        for k, name in enumerate(names):
            cov = np.diag(np.maximum(sigma[k], 0.01) ** 2) if sigma is not None else np.eye(3)
            db.write_pose_prior(
                pycolmap.PosePrior(
                    corr_data_id=by_name[name].data_id,
                    position=prior_c[k],
                    position_covariance=cov,
                    coordinate_system=pycolmap.PosePriorCoordinateSystem.CARTESIAN,
                )
            )
    pairing = pycolmap.SpatialPairingOptions()
    pairing.max_num_neighbors = neighbours
    pairing.ignore_z = False
    started = time.perf_counter()
    pycolmap.match_spatial(database, pairing_options=pairing, device=pycolmap.Device.cpu)
    times["match_s"] = time.perf_counter() - started
    options = pycolmap.IncrementalPipelineOptions()
    options.use_prior_position = True
    options.ba_refine_focal_length = False
    options.ba_refine_principal_point = False
    options.ba_refine_extra_params = False
    sparse = work / "sparse"
    shutil.rmtree(sparse, ignore_errors=True)
    sparse.mkdir()
    started = time.perf_counter()
    models = pycolmap.incremental_mapping(database, dive / "images", sparse, options=options)
    times["map_s"] = time.perf_counter() - started
    times["total_s"] = times["extract_s"] + times["match_s"] + times["map_s"]
    if not models:
        return {"registered": 0, **times}
    model = max(models.values(), key=lambda m: m.num_reg_images())
    centres, truth_rows = [], []
    index = {name: k for k, name in enumerate(names)}
    for image in model.images.values():
        if image.has_pose and image.name in index:
            centres.append(image.projection_center())
            truth_rows.append(index[image.name])
    order = np.argsort(truth_rows)
    centres, truth_rows = [centres[k] for k in order], [truth_rows[k] for k in order]
    truth = read_trajectory(dive / "truth" / "trajectory.csv")
    ref = camera_centres(truth, t[truth_rows], rig)
    return {
        "images": len(names),
        "registered": len(centres),
        "models": len(models),
        **times,
        **aligned_rmse(np.asarray(centres), ref),
        "prior_aligned_4dof_rmse_m": aligned_rmse(prior_c[truth_rows], ref)["aligned_4dof_rmse_m"],
    }


def run_auvnav(dive: Path, work: Path, rows: np.ndarray) -> dict:
    """Loops and SLAM on a dive cut to the same pairs; their wall time and camera centres' error."""
    import pandas as pd

    from auvnav import products as P
    from auvnav.dive import read_dive
    from auvnav.trajectory import read_trajectory

    sub = work / "auvnav"
    shutil.rmtree(sub, ignore_errors=True)
    sub.mkdir(parents=True)
    for name in ("dive.yaml", "vehicle.yaml"):
        shutil.copy2(dive / name, sub / name)
    shutil.copytree(dive / "nav", sub / "nav")
    shutil.copytree(dive / "truth", sub / "truth")
    index = pd.read_csv(dive / "images" / "index.csv").iloc[np.sort(rows)]
    for side in ("left", "right"):  # copies: a dive's images/ may not lead outside its folder
        (sub / "images" / side).mkdir(parents=True)
        for name in index[side]:
            shutil.copy2(dive / "images" / name, sub / "images" / name)
    index.to_csv(sub / "images" / "index.csv", index=False)
    subprocess.run([*AUVNAV, "navigate", str(sub), "-q"], check=True, cwd=ROOT)
    started = time.perf_counter()
    subprocess.run([*AUVNAV, "loops", str(sub), "--workers", "2", "-q"], check=True, cwd=ROOT)
    loops_s = time.perf_counter() - started
    started = time.perf_counter()
    subprocess.run([*AUVNAV, "slam", str(sub), "-q"], check=True, cwd=ROOT)
    slam_s = time.perf_counter() - started
    d = read_dive(sub)
    t = d.images.t_s
    slam = read_trajectory(P.SLAM_TRAJECTORY.path(sub))
    truth = read_trajectory(sub / "truth" / "trajectory.csv")
    rig = d.vehicle.stereo
    return {
        "images": len(t),
        "loops_s": loops_s,
        "slam_s": slam_s,
        "total_s": loops_s + slam_s,
        **aligned_rmse(camera_centres(slam, t, rig), camera_centres(truth, t, rig)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dive", type=Path, required=True)
    parser.add_argument("--work", type=Path, default=Path("/tmp/auvnav-bench-colmap"))
    parser.add_argument("--half-m", type=float, default=6.0)
    parser.add_argument("--neighbours", type=int, default=15)
    parser.add_argument("--max-features", type=int, default=2000)
    parser.add_argument(
        "--reuse-colmap",
        action="store_true",
        help="take COLMAP's figures from WORK/colmap.json (a run before)",
    )
    args = parser.parse_args()
    from auvnav import products as P
    from auvnav.dive import read_dive
    from auvnav.trajectory import read_trajectory

    d = read_dive(args.dive)
    slam = read_trajectory(P.SLAM_TRAJECTORY.path(args.dive))
    inside = (d.images.t_s >= slam.t_s[0]) & (d.images.t_s <= slam.t_s[-1])
    p = np.full((len(d.images), 2), np.inf)
    p[inside] = slam.interpolate(d.images.t_s[inside]).p_ned_m[:, :2]
    rows = np.flatnonzero(np.all(np.abs(p) <= args.half_m, axis=1))
    print(f"{len(rows)} stereo pairs in the grid (+-{args.half_m:g} m); cores {os.cpu_count()}, "
          f"load average {os.getloadavg()}", flush=True)  # fmt: skip
    results = {"pairs": len(rows), "load_average": os.getloadavg()}
    saved = args.work / "colmap.json"
    if args.reuse_colmap and saved.is_file():
        results["colmap"] = json.loads(saved.read_text(encoding="utf-8"))
    else:
        results["colmap"] = run_colmap(
            args.dive, args.work / "colmap", rows, args.neighbours, args.max_features
        )
        saved.write_text(json.dumps(results["colmap"], indent=1, default=float), encoding="utf-8")
    print(json.dumps(results["colmap"], indent=1), flush=True)
    results["auvnav"] = run_auvnav(args.dive, args.work, rows)
    # The dive's own SLAM (loops among all its images) at the same cameras: what a user of auvnav has.
    truth = read_trajectory(args.dive / "truth" / "trajectory.csv")
    t_rows, rig = d.images.t_s[rows], d.vehicle.stereo
    results["auvnav_whole_dive"] = aligned_rmse(
        camera_centres(slam, t_rows, rig), camera_centres(truth, t_rows, rig)
    )
    results["load_average_end"] = os.getloadavg()
    (args.work / "results.json").write_text(json.dumps(results, indent=2, default=float), encoding="utf-8")
    print(json.dumps(results, indent=2, default=float))
    c, a = results["colmap"], results["auvnav"]
    print(f"\n{'':8s}{'registered':>12s}{'4-DOF RMSE':>12s}{'sim3 RMSE':>12s}{'wall s':>10s}")
    print(f"{'COLMAP':8s}{c['registered']:>7d}/{len(rows):<4d}{1000 * c.get('aligned_4dof_rmse_m', np.nan):>9.1f} mm"
          f"{1000 * c.get('aligned_sim3_rmse_m', np.nan):>9.1f} mm{c['total_s']:>10.0f}")  # fmt: skip
    print(f"{'auvnav':8s}{a['images']:>7d}/{len(rows):<4d}{1000 * a['aligned_4dof_rmse_m']:>9.1f} mm"
          f"{1000 * a['aligned_sim3_rmse_m']:>9.1f} mm{a['total_s']:>10.0f}")  # fmt: skip
    w = results["auvnav_whole_dive"]
    print(f"{'(dive)':8s}{len(rows):>7d}/{len(rows):<4d}{1000 * w['aligned_4dof_rmse_m']:>9.1f} mm"
          f"{1000 * w['aligned_sim3_rmse_m']:>9.1f} mm{'-':>10s}   the dive's SLAM on all its images")  # fmt: skip


if __name__ == "__main__":
    main()
