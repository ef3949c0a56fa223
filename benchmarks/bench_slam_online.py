"""Benchmark of online SLAM (``auvnav slam DIVE --online``, issue 21): its error, where it comes from, its cost.

1. **Figures** (``--part figures``): the navigation check dive (seed 1) and the default survey (75 m x
   50 m at 1 m, seed 1), truth loop closures, each solved in batch and replayed online (batched
   iSAM2, 10 poses per update, 1 s front-end latency) with the compass three ways: raw; corrected by
   the correction an earlier check dive exported (seed 2, the same vehicle and deviation, its SLAM
   with ``--estimate-compass``: the paper's workflow, what a vehicle would run with); the deviation
   estimated in the graph. Per run: the batch's aligned ATE, the online estimate's (each image pose
   as known when the update that added it finished, aligned once for the whole dive as the batch's:
   evaluate's ``online`` section), their ratio (target 2), the online error by quarter of the dive,
   the update time per pose (median, 95th percentile: targets 20 ms and 200 ms), peak memory. Each
   run is a fresh process; marginals skipped. ``--survey-seconds`` cuts the survey.
2. **Diagnosis** (``--part diagnose``, the check dive or ``--diagnose survey``): for each compass mode, the online error of
   iSAM2 against the best any causal estimate of the same graph can do, a Levenberg-Marquardt solve
   run to convergence on the factors known at an update (:func:`auvnav.slam.online.schedule`), for
   every ``--every``-th update, scored on those updates' poses; and the online error with GTSAM's
   default relinearisation (threshold 0.1, every 10th update; the module's is 0.01, every update),
   without front-end latency, pose by pose.

Quote the load average printed with each figure: the machine is shared.

Run: ``.venv/bin/python benchmarks/bench_slam_online.py [--out DIR] [--part figures|diagnose|both]``
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import os
import platform
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from auvnav.evaluate import align_yaw_translation, read_truth
from auvnav.frames import rot_z
from auvnav.pipeline import run_stage
from auvnav.sim.run import run_scenario
from auvnav.slam.stage import SlamSettings
from bench_slam_robust import run

MODES = ("raw", "corrected", "estimated")


def simulate(out: Path, survey_seconds: float | None) -> dict[str, Path]:
    """The check dive, the earlier check dive that exports the correction, the survey; the correction."""
    dives = {"navcheck": out / "navcheck", "earlier": out / "navcheck_earlier", "survey": out / "survey"}
    for name, dive in dives.items():
        if not (dive / "truth" / "loops.csv").is_file():
            scenario = "survey" if name == "survey" else "navcheck"
            duration = survey_seconds if name == "survey" else None
            run_scenario(
                scenario, dive, seed=2 if name == "earlier" else 1, overwrite=True, truth_loops=True,
                max_duration_s=duration,
            )  # fmt: skip
    correction = out / "correction_earlier.yaml"
    if not correction.is_file():
        earlier = dives["earlier"]
        settings = SlamSettings(
            loops=earlier / "truth" / "loops.csv", estimate_compass=True, marginal_every=1
        )
        run_stage(earlier, "slam", settings)
        shutil.copyfile(earlier / "products" / "slam" / "correction.yaml", correction)
    return {**dives, "correction": correction}


def options(mode: str, correction: Path) -> dict[str, Any]:
    if mode == "corrected":
        return {"compass_correction": correction}
    return {"estimate_compass": True} if mode == "estimated" else {}


def figures(paths: dict[str, Path], modes: list[str], results: dict[str, Any]) -> None:
    for name in ("navcheck", "survey"):
        dive = paths[name]
        loops = dive / "truth" / "loops.csv"
        for mode in modes:
            extra = options(mode, paths["correction"])
            batch = run(dive, loops, **extra)
            online = run(dive, loops, online=True, **extra)
            o = online["online"]
            ratio = o["ate_aligned_rmse_m"] / batch["slam"]["ate_aligned_rmse_m"]
            quarters = ", ".join(f"{q:.3f}" for q in o["aligned_rmse_by_quarter_m"])
            print(
                f"{name}, {mode}: aligned ATE batch {batch['slam']['ate_aligned_rmse_m']:.4f} m, online "
                f"{o['ate_aligned_rmse_m']:.4f} m ({ratio:.2f}x; by quarter {quarters}), smoothed "
                f"{online['slam']['ate_aligned_rmse_m']:.4f} m; per pose median {o['update_median_ms']:.2f} "
                f"ms, 95th {o['update_p95_ms']:.1f} ms, max {o['update_max_ms']:.0f} ms; online run "
                f"{online['stage_s']:.1f} s, peak {online['peak_rss_mb']:.0f} MB (batch {batch['stage_s']:.1f}"
                f" s, {batch['peak_rss_mb']:.0f} MB); load {online['load']:.1f}",
                flush=True,
            )
            results[f"{name}_{mode}"] = {"batch": batch, "online": online, "ratio": ratio}


def _aligned_errors(
    T: np.ndarray, ref: np.ndarray, image: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Per-pose aligned position errors (aligned on the image poses, as evaluate does): yaw, t, errors."""
    yaw, t = align_yaw_translation(T[image, :3, 3], ref[image])
    return yaw, t, np.linalg.norm(T[:, :3, 3] @ rot_z(yaw).T + t - ref, axis=1)


def diagnose(
    paths: dict[str, Path], name: str, modes: list[str], every: int, results: dict[str, Any]
) -> None:
    import gtsam

    from auvnav.compass.correction import read_correction
    from auvnav.dive import read_dive
    from auvnav.slam import online as online_module
    from auvnav.slam.compass import COEFFICIENTS_KEY
    from auvnav.slam.graph import SlamOptions
    from auvnav.slam.optimize import lm_solve, solve
    from auvnav.slam.poses import pose_key
    from auvnav.slam.result import sensor_graph
    from auvnav.vision.loopfile import read_loops

    dive_path = paths[name]
    dive = read_dive(dive_path)
    loops = read_loops(dive_path / "truth" / "loops.csv")
    truth = read_truth(dive_path)
    for mode in modes:
        opts = SlamOptions(marginal_every=0, estimate_compass=mode == "estimated")
        correction = read_correction(paths["correction"]) if mode == "corrected" else None
        sg = sensor_graph(dive, dive.images.t_s, loops=loops, correction=correction, options=opts)
        image = sg.times.is_image
        ref = truth.interpolate(sg.times.t_s).p_ned_m
        batch = solve(sg, opts).T_ned_body
        e_batch = _aligned_errors(batch, ref, image)[2]

        def rms(e: np.ndarray) -> float:
            return float(np.sqrt(np.mean(e**2)))

        _, record = online_module.replay(sg, 10, 1.0)
        yaw, t_align, e_online = _aligned_errors(record.T_known, ref, image)
        line = {"batch": rms(e_batch[image]), "online": rms(e_online[image])}
        # The causal optimum at every `every`-th update, on that update's image poses.
        plan = online_module.schedule(sg, 10, 1.0)
        sampled, T_causal = [], []
        start = time.perf_counter()
        for u in range(every - 1, len(plan.firsts), every):
            graph = gtsam.NonlinearFactorGraph()
            for f in plan.known_by(u):
                graph.add(sg.factors[f])
            values = gtsam.Values()
            for k in range(plan.lasts[u] + 1):
                values.insert(pose_key(k), gtsam.Pose3(sg.initial[k]))
            if sg.compass.estimate:
                values.insert(COEFFICIENTS_KEY, np.zeros(sg.compass.n_coefficients))
            solved = lm_solve(graph, values)
            for k in range(plan.firsts[u], plan.lasts[u] + 1):
                if image[k]:
                    sampled.append(k)
                    T_causal.append(solved.atPose3(pose_key(k)).matrix())
        k = np.array(sampled)
        # Aligned as the online estimate (the causal solves stand in for its poses).
        e_causal = np.linalg.norm(np.stack(T_causal)[:, :3, 3] @ rot_z(yaw).T + t_align - ref[k], axis=1)
        line.update(
            sampled_poses=len(k),
            online_sampled=rms(e_online[k]),
            causal_lm_sampled=rms(e_causal),
            batch_sampled=rms(e_batch[k]),
            causal_lm_s=time.perf_counter() - start,
        )
        # Variants of the replay.
        threshold, skip = online_module.RELINEARIZE_THRESHOLD, online_module.RELINEARIZE_SKIP
        try:
            online_module.RELINEARIZE_THRESHOLD, online_module.RELINEARIZE_SKIP = 0.1, 10
            _, coarse = online_module.replay(sg, 10, 1.0)
            line["gtsam_default_relinearisation"] = rms(_aligned_errors(coarse.T_known, ref, image)[2][image])
            line["gtsam_default_relinearisation_median_ms"] = float(np.median(coarse.per_pose_ms()))
        finally:
            online_module.RELINEARIZE_THRESHOLD, online_module.RELINEARIZE_SKIP = threshold, skip
        _, zero = online_module.replay(sg, 10, 0.0)
        line["latency_0"] = rms(_aligned_errors(zero.T_known, ref, image)[2][image])
        _, single = online_module.replay(sg, 1, 1.0)
        line["pose_by_pose"] = rms(_aligned_errors(single.T_known, ref, image)[2][image])
        print(
            f"{name}, {mode}: aligned ATE batch {line['batch']:.4f} m, online {line['online']:.4f} m; "
            f"on {line['sampled_poses']} poses of every {every}th update: online {line['online_sampled']:.4f}"
            f" m, causal optimum (LM on the graph known then) {line['causal_lm_sampled']:.4f} m, batch "
            f"{line['batch_sampled']:.4f} m; online with GTSAM's default relinearisation (0.1, every 10th "
            f"update) {line['gtsam_default_relinearisation']:.4f} m "
            f"({line['gtsam_default_relinearisation_median_ms']:.1f} ms per pose median; "
            f"{float(np.median(record.per_pose_ms())):.1f} ms with the module's), latency 0 {line['latency_0']:.4f} m, pose by pose {line['pose_by_pose']:.4f} m "
            f"(load {os.getloadavg()[0]:.1f})",
            flush=True,
        )
        results[f"diagnose_{name}_{mode}"] = line


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench-slam-online"))
    parser.add_argument("--part", choices=("figures", "diagnose", "both"), default="both")
    parser.add_argument(
        "--diagnose", choices=("navcheck", "survey"), default="navcheck", help="Dive diagnosed."
    )
    parser.add_argument("--modes", default=",".join(MODES), help="Compass modes, comma-separated.")
    parser.add_argument("--every", type=int, default=20, help="Diagnosis: every Nth update solved causally.")
    parser.add_argument("--survey-seconds", type=float, default=None, help="Cut the survey (default: whole).")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"# {platform.node()}, {multiprocessing.cpu_count()} cores, {time.strftime('%Y-%m-%d %H:%M')}")
    paths = simulate(args.out, args.survey_seconds)
    modes = [m for m in args.modes.split(",") if m in MODES]
    results: dict[str, Any] = {}
    if args.part in ("diagnose", "both"):
        diagnose(paths, args.diagnose, modes, args.every, results)
    if args.part in ("figures", "both"):
        figures(paths, modes, results)
    (args.out / f"results_{args.part}.json").write_text(
        json.dumps(results, indent=1, default=float), encoding="utf-8"
    )


if __name__ == "__main__":
    main()
