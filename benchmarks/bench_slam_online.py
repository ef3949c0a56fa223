"""Benchmark of online SLAM (``auvnav slam DIVE --online``, issue 21): its error, where it comes from, its cost.

1. **Figures** (``--part figures``): the navigation check dive (seed 1) and the default survey (75 m x
   50 m at 1 m, seed 1), truth loop closures, each solved in batch and replayed online (batched
   iSAM2, 10 poses per update, 1 s front-end latency) with the compass three ways: raw; corrected by
   the correction an earlier check dive exported (seed 2, the same vehicle and deviation, its SLAM
   with ``--estimate-compass``: the paper's workflow, what a vehicle would run with); the deviation
   estimated in the graph; each without and with the DVL's calibration estimated in the graph
   (``--estimate-dvl``, :mod:`auvnav.slam.dvl`; ``--dvl no|yes|both``), the batch solve with the
   same options as the online replay. Per run: the batch's aligned ATE, the online estimate's (each
   image pose as known when the update that added it finished, aligned once for the whole dive as
   the batch's: evaluate's ``online`` section), their ratio (target 2), the online error by quarter
   of the dive, the update time per pose (median, 95th percentile: targets 20 ms and 200 ms), peak
   memory, and the calibration found. Each run is a fresh process; marginals skipped.
   ``--survey-seconds`` cuts the survey.
2. **Diagnosis** (``--part diagnose``, the check dive or ``--diagnose survey``, ``--dvl`` as
   above): for each compass mode, the online error of iSAM2 against the best any causal estimate
   of the same graph can do, a Levenberg-Marquardt solve run to convergence on the factors known at
   an update (:func:`auvnav.slam.online.schedule`), for every ``--every``-th update, scored on those
   updates' poses; and the online error with GTSAM's default relinearisation (threshold 0.1, every
   10th update; the module's is 0.01, every update), without front-end latency, pose by pose.
3. **Factor cost** (``--part factor-cost``): the calibrated DVL odometry as the stage builds it
   (a ``LinearContainerFactor`` per odometry, linearised in Python and relinearised where the
   solver relinearises) against a ``gtsam.CustomFactor`` computing the same error: one
   Levenberg-Marquardt iteration on the whole check dive (and with plain uncalibrated
   ``BetweenFactorPose3`` odometry), and iSAM2 on the survey, 10 poses per update, for its first
   ``--cost-updates`` updates (the custom factor is too slow for the whole survey), time per pose.

Quote the load average printed with each figure: the machine is shared.

Run: ``.venv/bin/python benchmarks/bench_slam_online.py [--out DIR] [--part figures|diagnose|factor-cost|all]``
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


def options(mode: str, correction: Path, dvl: bool) -> dict[str, Any]:
    extra: dict[str, Any] = {"estimate_dvl": True} if dvl else {}
    if mode == "corrected":
        return {"compass_correction": correction, **extra}
    return {"estimate_compass": True, **extra} if mode == "estimated" else extra


def _calibration(summary: dict[str, Any]) -> str:
    dvl = summary.get("dvl")
    if not dvl:
        return ""
    roll, pitch, yaw = dvl["misalignment_rpy_deg"]
    return (
        f"; DVL scale {100 * dvl['scale_factor']:+.3f}%, mounting {roll:+.3f} {pitch:+.3f} {yaw:+.3f} deg, "
        f"time offset {dvl['time_offset_s']:+.4f} s"
    )


def figures(paths: dict[str, Path], modes: list[str], dvls: list[bool], results: dict[str, Any]) -> None:
    for name in ("navcheck", "survey"):
        dive = paths[name]
        loops = dive / "truth" / "loops.csv"
        for mode in modes:
            for dvl in dvls:
                extra = options(mode, paths["correction"], dvl)
                batch = run(dive, loops, **extra)
                online = run(dive, loops, online=True, **extra)
                o = online["online"]
                ratio = o["ate_aligned_rmse_m"] / batch["slam"]["ate_aligned_rmse_m"]
                quarters = ", ".join(f"{q:.3f}" for q in o["aligned_rmse_by_quarter_m"])
                label = f"{name}, {mode}{', --estimate-dvl' if dvl else ''}"
                print(
                    f"{label}: aligned ATE batch {batch['slam']['ate_aligned_rmse_m']:.4f} m, online "
                    f"{o['ate_aligned_rmse_m']:.4f} m ({ratio:.2f}x; by quarter {quarters}), smoothed "
                    f"{online['slam']['ate_aligned_rmse_m']:.4f} m; per pose median "
                    f"{o['update_median_ms']:.2f} ms, 95th {o['update_p95_ms']:.1f} ms, max "
                    f"{o['update_max_ms']:.0f} ms; online run {online['stage_s']:.1f} s, peak "
                    f"{online['peak_rss_mb']:.0f} MB (batch {batch['stage_s']:.1f} s, {batch['peak_rss_mb']:.0f} "
                    f"MB){_calibration(online['summary'])}; load {online['load']:.1f}",
                    flush=True,
                )
                if dvl:
                    print(f"{'':{len(label)}}  batch{_calibration(batch['summary'])}", flush=True)
                key = f"{name}_{mode}{'_dvl' if dvl else ''}"
                results[key] = {"batch": batch, "online": online, "ratio": ratio}


def _aligned_errors(
    T: np.ndarray, ref: np.ndarray, image: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Per-pose aligned position errors (aligned on the image poses, as evaluate does): yaw, t, errors."""
    yaw, t = align_yaw_translation(T[image, :3, 3], ref[image])
    return yaw, t, np.linalg.norm(T[:, :3, 3] @ rot_z(yaw).T + t - ref, axis=1)


def _causal_solve(sg: Any, factors: np.ndarray, n_poses: int) -> Any:
    """Levenberg-Marquardt to convergence on the ``factors`` of ``sg`` over its first ``n_poses``
    poses, the calibrated DVL odometry (if any) relinearised as the batch solve does it."""
    import gtsam

    from auvnav.slam.optimize import lm_relinearized, lm_solve
    from auvnav.slam.poses import pose_key

    values = sg.unknowns()
    for k in range(n_poses):
        values.insert(pose_key(k), gtsam.Pose3(sg.initial[k]))
    odometry = [int(f) for f in factors if sg.kinds[f] == "odometry"] if sg.dvl is not None else []
    others = gtsam.NonlinearFactorGraph()
    for f in set(map(int, factors)) - set(odometry):
        others.add(sg.factors[f])
    if not odometry:
        return lm_solve(others, values)

    def build(at: Any) -> Any:
        graph = gtsam.NonlinearFactorGraph(others)
        for f in odometry:
            graph.add(sg.odometry_at(f, at))
        return graph

    return lm_relinearized(build, values)[0]


def diagnose(
    paths: dict[str, Path], name: str, modes: list[str], dvls: list[bool], every: int, results: dict[str, Any]
) -> None:
    from auvnav.compass.correction import read_correction
    from auvnav.dive import read_dive
    from auvnav.slam import online as online_module
    from auvnav.slam.graph import SlamOptions
    from auvnav.slam.optimize import solve
    from auvnav.slam.poses import pose_key
    from auvnav.slam.result import sensor_graph
    from auvnav.vision.loopfile import read_loops

    dive_path = paths[name]
    dive = read_dive(dive_path)
    loops = read_loops(dive_path / "truth" / "loops.csv")
    truth = read_truth(dive_path)
    for mode in modes:
        for dvl in dvls:
            opts = SlamOptions(marginal_every=0, estimate_compass=mode == "estimated", estimate_dvl=dvl)
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
                solved = _causal_solve(sg, plan.known_by(u), int(plan.lasts[u]) + 1)
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
                line["gtsam_default_relinearisation"] = rms(
                    _aligned_errors(coarse.T_known, ref, image)[2][image]
                )
                line["gtsam_default_relinearisation_median_ms"] = float(np.median(coarse.per_pose_ms()))
            finally:
                online_module.RELINEARIZE_THRESHOLD, online_module.RELINEARIZE_SKIP = threshold, skip
            _, zero = online_module.replay(sg, 10, 0.0)
            line["latency_0"] = rms(_aligned_errors(zero.T_known, ref, image)[2][image])
            _, single = online_module.replay(sg, 1, 1.0)
            line["pose_by_pose"] = rms(_aligned_errors(single.T_known, ref, image)[2][image])
            label = f"{name}, {mode}{', --estimate-dvl' if dvl else ''}"
            print(
                f"{label}: aligned ATE batch {line['batch']:.4f} m, online {line['online']:.4f} m; on "
                f"{line['sampled_poses']} poses of every {every}th update: online {line['online_sampled']:.4f}"
                f" m, causal optimum (LM on the graph known then) {line['causal_lm_sampled']:.4f} m, batch "
                f"{line['batch_sampled']:.4f} m; online with GTSAM's default relinearisation (0.1, every "
                f"10th update) {line['gtsam_default_relinearisation']:.4f} m "
                f"({line['gtsam_default_relinearisation_median_ms']:.1f} ms per pose median; "
                f"{float(np.median(record.per_pose_ms())):.1f} ms with the module's), latency 0 "
                f"{line['latency_0']:.4f} m, pose by pose {line['pose_by_pose']:.4f} m "
                f"(load {os.getloadavg()[0]:.1f})",
                flush=True,
            )
            results[f"diagnose_{name}_{mode}{'_dvl' if dvl else ''}"] = line


def _custom_odometry(sg: Any, f: int) -> Any:
    """Odometry factor ``f`` of ``sg`` as a ``gtsam.CustomFactor``: the error and Jacobians of the
    stage's linearised odometry (:meth:`~auvnav.slam.graph.SensorGraph.odometry_at`), recomputed at
    each call, whitened (unit noise)."""
    import gtsam

    from auvnav.slam.dvl import CALIBRATION_KEY
    from auvnav.slam.poses import pose_key

    k = int(sg.last_pose[f])
    keys = [pose_key(k - 1), pose_key(k), CALIBRATION_KEY]

    def error(_: Any, values: Any, H: Any) -> np.ndarray:
        point = gtsam.Values()
        point.insert(keys[0], values.atPose3(keys[0]))
        point.insert(keys[1], values.atPose3(keys[1]))
        point.insert(keys[2], values.atVector(keys[2]))
        A, b = sg.odometry_at(f, point).linearize(point).jacobian()
        if H is not None:
            H[0], H[1], H[2] = A[:, :6], A[:, 6:12], A[:, 12:]
        return -b

    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(6), keys, error)


def factor_cost(paths: dict[str, Path], updates: int, results: dict[str, Any]) -> None:
    import gtsam

    from auvnav.compass.correction import read_correction
    from auvnav.dive import read_dive
    from auvnav.slam.graph import SlamOptions
    from auvnav.slam.online import (
        RELINEARIZE_SKIP,
        RELINEARIZE_THRESHOLD,
        CalibratedOdometry,
        relinearize_thresholds,
    )
    from auvnav.slam.poses import pose_key
    from auvnav.slam.result import sensor_graph
    from auvnav.vision.loopfile import read_loops

    correction = read_correction(paths["correction"])

    def graph_of(name: str, dvl: bool) -> Any:
        dive = read_dive(paths[name])
        loops = read_loops(paths[name] / "truth" / "loops.csv")
        opts = SlamOptions(marginal_every=0, estimate_dvl=dvl)
        return sensor_graph(dive, dive.images.t_s, loops=loops, correction=correction, options=opts)

    # One Levenberg-Marquardt iteration on the whole check dive, from dead reckoning.
    plain, sg = graph_of("navcheck", False), graph_of("navcheck", True)
    values = sg.values()
    start = time.perf_counter()
    containers = sg.graph(linearized_at=values)
    build_s = time.perf_counter() - start
    custom = gtsam.NonlinearFactorGraph()
    for f, (factor, kind) in enumerate(zip(sg.factors, sg.kinds, strict=True)):
        custom.add(_custom_odometry(sg, f) if kind == "odometry" else factor)
    line: dict[str, float] = {"odometry_factors": sg.kinds.count("odometry"), "containers_build_s": build_s}
    for label, graph, at in (
        ("plain", plain.graph(), plain.values()),
        ("containers", containers, values),
        ("custom", custom, values),
    ):
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(1)
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, at, params)
        start = time.perf_counter()
        optimizer.iterate()
        line[f"lm_iteration_{label}_s"] = time.perf_counter() - start
    print(
        f"navcheck, one LM iteration ({line['odometry_factors']} odometry factors): plain BetweenFactorPose3 "
        f"{line['lm_iteration_plain_s']:.2f} s; containers {line['lm_iteration_containers_s']:.2f} s "
        f"(+ {line['containers_build_s']:.2f} s linearising them); CustomFactor "
        f"{line['lm_iteration_custom_s']:.2f} s (load {os.getloadavg()[0]:.1f})",
        flush=True,
    )
    results["factor_cost_lm_navcheck"] = line

    # iSAM2 on the survey, the first `updates` updates of 10 poses, each factor at its last pose.
    for name in ("survey",):
        plain, sg = graph_of(name, False), graph_of(name, True)
        times: dict[str, list[float]] = {}
        for label in ("plain", "containers", "custom"):
            graph = plain if label == "plain" else sg
            order = np.argsort(graph.last_pose, kind="stable")
            bounds = np.searchsorted(graph.last_pose[order], np.arange(-1, len(graph.times) + 1))
            params = gtsam.ISAM2Params()
            params.setFactorization("QR")
            params.setRelinearizeThreshold(relinearize_thresholds(graph))
            params.relinearizeSkip = RELINEARIZE_SKIP
            isam = gtsam.ISAM2(params)
            odometry = CalibratedOdometry(sg, RELINEARIZE_THRESHOLD, RELINEARIZE_SKIP)
            current = graph.initial[0]
            spent: list[float] = []
            for u in range(min(updates, (len(graph.times) + 9) // 10)):
                first, last = 10 * u, min(10 * u + 10, len(graph.times)) - 1
                start = time.perf_counter()
                new_factors, new_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
                if first == 0:
                    new_values.insert(graph.unknowns())
                for k in range(first, last + 1):
                    if k > 0:
                        current = current @ graph.pose_graph.T_ij[k - 1]
                    new_values.insert(pose_key(k), gtsam.Pose3(current))
                new_odometry = []
                for f in order[bounds[first + 1 if first else 0] : bounds[last + 2]]:
                    if label == "containers" and graph.kinds[f] == "odometry":
                        new_odometry.append(int(f))
                    elif label == "custom" and graph.kinds[f] == "odometry":
                        new_factors.add(_custom_odometry(graph, int(f)))
                    else:
                        new_factors.add(graph.factors[f])
                if label == "containers":
                    odometry.update(isam, new_factors, new_values, new_odometry)
                else:
                    isam.update(new_factors, new_values)
                current = isam.calculateEstimatePose3(pose_key(last)).matrix()
                spent.append(time.perf_counter() - start)
            times[label] = spent
        per_pose = {label: 100.0 * np.array(v) for label, v in times.items()}  # ms per pose, 10 a update
        print(
            f"{name}, iSAM2, first {len(times['plain'])} updates of 10 poses, per pose median / 95th / last "
            "update (all updates): "
            + "; ".join(
                f"{label} {np.median(v):.2f} / {np.percentile(v, 95):.1f} / {v[-1]:.1f} ms ({sum(times[label]):.0f} s)"
                for label, v in per_pose.items()
            )
            + f" (load {os.getloadavg()[0]:.1f})",
            flush=True,
        )
        results[f"factor_cost_isam2_{name}"] = {label: v.tolist() for label, v in per_pose.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench-slam-online"))
    parser.add_argument("--part", choices=("figures", "diagnose", "factor-cost", "all"), default="figures")
    parser.add_argument(
        "--diagnose", choices=("navcheck", "survey"), default="navcheck", help="Dive diagnosed."
    )
    parser.add_argument("--modes", default=",".join(MODES), help="Compass modes, comma-separated.")
    parser.add_argument(
        "--dvl",
        choices=("no", "yes", "both"),
        default="both",
        help="DVL calibration estimated (--estimate-dvl).",
    )
    parser.add_argument("--every", type=int, default=20, help="Diagnosis: every Nth update solved causally.")
    parser.add_argument("--survey-seconds", type=float, default=None, help="Cut the survey (default: whole).")
    parser.add_argument(
        "--cost-updates", type=int, default=150, help="Factor cost: iSAM2 updates of the survey timed."
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"# {platform.node()}, {multiprocessing.cpu_count()} cores, {time.strftime('%Y-%m-%d %H:%M')}")
    paths = simulate(args.out, args.survey_seconds)
    modes = [m for m in args.modes.split(",") if m in MODES]
    dvls = {"no": [False], "yes": [True], "both": [False, True]}[args.dvl]
    results: dict[str, Any] = {}
    if args.part in ("diagnose", "all"):
        diagnose(paths, args.diagnose, modes, dvls, args.every, results)
    if args.part in ("factor-cost", "all"):
        factor_cost(paths, args.cost_updates, results)
    if args.part in ("figures", "all"):
        figures(paths, modes, dvls, results)
    (args.out / f"results_{args.part}.json").write_text(
        json.dumps(results, indent=1, default=float), encoding="utf-8"
    )


if __name__ == "__main__":
    main()
