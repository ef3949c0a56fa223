"""Pose-graph back end: reference optima, batch and incremental speed, peak memory (issue 7).

Targets: ``auvnav graph optimize`` reaches the reference optimum of sphere2500 and parking-garage
within 0.1%; a batch solve of 10,000 poses with 30,000 loop closures in under 30 s; iSAM2 median
under 20 ms per added pose; peak memory reported.

Run::

    AUVNAV_REFERENCE_DATA=../shared/reference .venv/bin/python benchmarks/bench_slam.py
    .venv/bin/python benchmarks/bench_slam.py --isam-poses 2000      # a shorter iSAM2 run
    .venv/bin/python benchmarks/bench_slam.py --poses-per-update 1,10,20

The synthetic graph is a lawnmower survey (auvnav.slam.synthetic.survey_pose_graph): 100 poses per
track line, 1 m apart, lines 1 m apart, loop closures between poses on adjacent lines within 2.3 m.

iSAM2 adds the poses in order, K per update (``--poses-per-update``, a list: one run each), each
with every edge to the poses before it: a vehicle that triggers its camera at 1 Hz and updates its
solution every K seconds. Time per added pose = an update's wall time (building its factors, the
iSAM2 update, reading the newest pose's estimate) / K, each pose of the update counted; the
median, 95th percentile and maximum are over the poses, and the update times (the latency of a
new solution) are reported too. Each iSAM2 run is a fresh process, so its peak memory is its own.
Peak memory is the process's peak resident set (``resource.getrusage``, which sees GTSAM's C++
allocations); tracemalloc shows the Python-side peak of the batch solve. Pose by pose (K = 1) the
full 10,000-pose run takes about half an hour on a shared 2-core machine.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

from auvnav.slam.g2o import read_g2o
from auvnav.slam.solve import optimize_batch, optimize_incremental
from auvnav.slam.synthetic import survey_pose_graph

# 2 x the GTSAM error after LM, gtsam_computed_reference_costs.csv in ../shared/reference/pose_graph_g2o
# (computed with GTSAM from PyPI, prior 1e-6 on the first pose; torus3D from the chordal initialisation).
REFERENCES = [
    ("parking-garage.g2o", "file", 2 * 0.6341924),
    ("sphere2500.g2o", "file", 2 * 675.700963),
    ("sphere2500.g2o", "chordal", 2 * 675.700963),
    ("torus3D.g2o", "chordal", 2 * 12117.6369),
    ("smallGrid3D.g2o", "file", 2 * 517.925332),
    ("intel.g2o", "file", 2 * 22.5021165),
    ("MIT.g2o", "file", 2 * 385.119492),
    ("city10000.g2o", "file", 2 * 255.993725),
]

INCREMENTAL = ("parking-garage.g2o", "sphere2500.g2o", "intel.g2o", "city10000.g2o")


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, MB (Linux reports kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def bench_references(folder: Path) -> None:
    print(f"\n## Reference graphs ({folder})\n")
    print("| graph | init | poses | edges | read s | solve s | iters | chi2 after | reference | rel. diff |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, initial, reference in REFERENCES:
        path = folder / name
        if not path.exists():
            print(f"| {name} | {initial} | missing | | | | | | | |")
            continue
        t0 = time.perf_counter()
        graph = read_g2o(path)
        read_s = time.perf_counter() - t0
        result = optimize_batch(graph, initial=initial)
        diff = (result.cost_after - reference) / reference
        print(
            f"| {name} | {initial} | {graph.n_poses} | {graph.n_edges} | {read_s:.2f} | {result.seconds:.2f} "
            f"| {result.iterations} | {result.cost_after:.6g} | {reference:.6g} | {diff:+.2e} |"
        )


def bench_references_incremental(folder: Path) -> None:
    print(
        "\niSAM2 on reference graphs, ms per added pose (building its factors, update, reading its estimate):\n"
    )
    print("| graph | poses | edges | median | 95th pct | max | total s | chi2 after | batch optimum |")
    print("|---|---|---|---|---|---|---|---|---|")
    optimum = {name: reference for name, _, reference in REFERENCES}
    for name in INCREMENTAL:
        if not (folder / name).exists():
            continue
        graph = read_g2o(folder / name)
        result = optimize_incremental(graph)
        ms = result.step_seconds * 1e3
        print(
            f"| {name} | {graph.n_poses} | {graph.n_edges} | {np.median(ms):.2f} | {np.percentile(ms, 95):.1f} "
            f"| {ms.max():.0f} | {result.seconds:.1f} | {result.cost_after:.6g} | {optimum[name]:.6g} |",
            flush=True,
        )


def _isam2_task(n_poses: int, n_loops: int, seed: int, poses_per_update: int) -> dict[str, object]:
    """iSAM2 on a synthetic survey, in a child process: timings, cost, poses and peak memory."""
    graph = survey_pose_graph(n_poses, n_loops, seed=seed).graph
    result = optimize_incremental(graph, poses_per_update=poses_per_update)
    return {
        "step_ms": result.step_seconds * 1e3,
        "update_ms": result.update_seconds * 1e3,
        "seconds": result.seconds,
        "cost_after": result.cost_after,
        "p_m": result.graph.T_world_pose[:, :3, 3],
        "peak_rss_mb": peak_rss_mb(),
    }


def bench_synthetic(n_poses: int, n_loops: int, isam_poses: int, ks: list[int], seed: int) -> None:
    print(f"\n## Synthetic survey: {n_poses} poses, {n_loops} loop closures (seed {seed})\n")
    t0 = time.perf_counter()
    survey = survey_pose_graph(n_poses, n_loops, seed=seed)
    graph = survey.graph
    print(f"generated in {time.perf_counter() - t0:.1f} s; peak RSS {peak_rss_mb():.0f} MB\n")
    tracemalloc.start()
    batch = optimize_batch(graph)
    py_peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    print("| solver | poses | seconds | iterations | chi2 before | chi2 after | peak RSS MB | py peak MB |")
    print("|---|---|---|---|---|---|---|---|")
    print(
        f"| batch LM | {graph.n_poses} | {batch.seconds:.2f} | {batch.iterations} | {batch.cost_before:.6g} "
        f"| {batch.cost_after:.6g} | {peak_rss_mb():.0f} | {py_peak:.0f} |",
        flush=True,
    )
    if isam_poses <= 0:
        return
    # A shorter run solves a smaller survey of the same kind (same loop closures per pose).
    size = (n_poses, n_loops) if isam_poses >= n_poses else (isam_poses, isam_poses * n_loops // n_poses)
    reference = batch if isam_poses >= n_poses else optimize_batch(survey_pose_graph(*size, seed=seed).graph)
    print(
        f"\niSAM2 on {size[0]} poses, K poses per update; ms per added pose (update time / K) "
        "and per update:\n"
    )
    print(
        "| K | per pose: median | 95th | max | per update: median | 95th | max | total s "
        "| chi2 after (batch) | vs batch: max mm | peak RSS MB |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    ctx = multiprocessing.get_context("spawn")
    for k in ks:
        with ctx.Pool(1) as pool:
            run = pool.apply(_isam2_task, (*size, seed, k))
        step, update = run["step_ms"], run["update_ms"]
        gap = np.linalg.norm(run["p_m"] - reference.graph.T_world_pose[:, :3, 3], axis=1)
        print(
            f"| {k} | **{np.median(step):.1f}** | {np.percentile(step, 95):.1f} | {step.max():.1f} "
            f"| {np.median(update):.0f} | {np.percentile(update, 95):.0f} | {update.max():.0f} "
            f"| {run['seconds']:.0f} | {run['cost_after']:.6g} ({reference.cost_after:.6g}) "
            f"| {gap.max() * 1e3:.1f} | {run['peak_rss_mb']:.0f} |",
            flush=True,
        )
        blocks = np.array_split(np.arange(len(step)), min(10, len(step)))
        growth = ", ".join(f"{np.median(step[rows]):.1f}" for rows in blocks)
        print(f"|  | median per pose by tenth of the survey: {growth} | | | | | | | | | |", flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=Path, default=None, help="folder holding pose_graph_g2o/")
    parser.add_argument("--poses", type=int, default=10_000)
    parser.add_argument("--loops", type=int, default=30_000)
    parser.add_argument(
        "--isam-poses", type=int, default=10_000, help="iSAM2 on a survey of N poses (0: skip)"
    )
    parser.add_argument(
        "--poses-per-update", default="10,20", help="iSAM2 runs, K poses per update (comma-separated)"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    reference = args.reference or (
        Path(os.environ["AUVNAV_REFERENCE_DATA"]) if "AUVNAV_REFERENCE_DATA" in os.environ else None
    )
    print(f"# bench_slam  (python {sys.version.split()[0]}, {os.cpu_count()} cpus)")
    if reference is not None:
        bench_references(reference / "pose_graph_g2o")
        bench_references_incremental(reference / "pose_graph_g2o")
    else:
        print("\n(reference graphs skipped: set AUVNAV_REFERENCE_DATA or --reference)")
    ks = [int(k) for k in args.poses_per_update.split(",")]
    bench_synthetic(args.poses, args.loops, args.isam_poses, ks, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
