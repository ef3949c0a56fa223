"""Reconstruction benchmark: the issue-18 acceptance on the simulated navigation check dive.

Needs a check dive at half scale with its images, navigation and SLAM (``--dive``; the full demo's
``navcheck`` is one: ``auvnav demo --out DEMO`` then ``--dive DEMO/navcheck``). Without ``--dive``, one
is made in ``--work`` (simulate seed 1, render at half scale, ``auvnav process --only nav vision slam``:
about 20 minutes on two cores). Products go to ``--work``, never into the dive's own ``products/recon``.

1. The check dive's grid (a 10 m square flown in 1 m lines, crossed by the star's arms an hour
   earlier: the patch ``--half-m`` around the origin) placed with SLAM, from an empty dense-stereo
   cache, on two local workers: dense stereo + fusion throughput (pairs per second), peak memory of the
   process tree, and ``evaluate``'s ``recon`` section (DEM RMSE against the true seafloor, orthophoto
   misregistration against the true albedo, false-relief steps before and after the tide);
2. the same pairs placed with dead reckoning (dense maps from the cache);
3. a patch ``--large-half-m`` around the origin (more tiles, more pairs): peak memory, to show it is
   bounded by the tile and not by the patch;
4. Open3D's two TSDF integrators on the same tiles: the tensor ``VoxelBlockGrid`` and the legacy
   ``ScalableTSDFVolume`` (time and faces);
5. SGBM's per-pixel depth error on 20 pairs placed with the true poses (the ``sigma_disparity_px``
   of :mod:`auvnav.recon.dense`).

Usage: ``.venv/bin/python benchmarks/bench_recon.py [--dive DIR] [--work DIR]``.
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

from treeusage import TreeUsage

ROOT = Path(__file__).resolve().parents[1]
AUVNAV = [str(Path(sys.executable).with_name("auvnav"))]


def run(args: list[str]) -> None:
    print("$", " ".join(str(a) for a in args), flush=True)
    subprocess.run([str(a) for a in args], check=True, cwd=ROOT)


def make_dive(work: Path) -> Path:
    """A processed check dive at half scale (when absent)."""
    dive = work / "navcheck"
    if not (dive / "products" / "slam" / "trajectory.csv").is_file():
        if not (dive / "truth").is_dir():
            run([*AUVNAV, "simulate", "navcheck", "--out", dive, "--seed", "1", "--image-scale", "0.5", "-q"])
        run([*AUVNAV, "process", dive, "--only", "nav", "--only", "vision", "--only", "slam", "-q"])
    return dive


def inputs_for(dive: Path, name: str, tide_file: Path):
    from auvnav import products as P
    from auvnav.depth.tide import read_constituents
    from auvnav.dive import read_dive_info
    from auvnav.recon.reconstruct import ReconInputs
    from auvnav.trajectory import read_trajectory

    product = {"slam": P.SLAM_TRAJECTORY, "filter": P.NAV_FILTER, "dr": P.NAV_DR}[name]
    tide = read_constituents(tide_file, latitude_rad=read_dive_info(dive).origin.latitude_rad)
    return ReconInputs(
        trajectory=read_trajectory(product.path(dive)),
        trajectory_name=name,
        tide=tide,
        tide_source=str(tide_file),
        apply_tide=name != "slam",
        pressure_track=read_trajectory(P.NAV_FILTER.path(dive)),
    )


def reconstruct_into(
    dive: Path, out: Path, name: str, tide_file: Path, cache: Path, *, half_m: float | None = None,
    pairs=None, workers: int = 2, fusion=None,
) -> tuple[dict, float]:  # fmt: skip
    """Run a reconstruction into ``out``; its summary and the process tree's peak memory (MiB)."""
    from auvnav.dive import read_dive
    from auvnav.executor import make_executor
    from auvnav.recon.reconstruct import Region, reconstruct

    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    region = Region() if half_m is None else Region(-half_m, half_m, -half_m, half_m)
    last = [0.0]

    def progress(what: str, done: int, total: int) -> None:
        if time.monotonic() - last[0] > 30 or done == total:
            last[0] = time.monotonic()
            print(f"  {what} {done}/{total}", flush=True)

    before_cpu = sum(os.times()[:2])
    with TreeUsage() as usage, make_executor(workers=workers) as executor:
        summary = reconstruct(
            read_dive(dive), inputs_for(dive, name, tide_file), out, region=region, pairs=pairs,
            cache_dir=cache, executor=executor, progress=progress, **({} if fusion is None else {"fusion": fusion}),
        )  # fmt: skip
    # CPU seconds of the run (this process's own before it are subtracted): throughput on free cores.
    summary["cpu_s"] = usage.cpu_s() - before_cpu
    summary["pairs_per_cpu_s"] = summary["pairs"]["used"] / summary["cpu_s"] if summary["cpu_s"] > 0 else None
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float), encoding="utf-8")
    return summary, usage.peak_mib


def score(dive: Path, folder: Path) -> dict:
    from auvnav.evaluate import _seafloor_and_texture, align_yaw_translation, read_truth
    from auvnav.recon.evaluate import recon_section

    floor, texture = _seafloor_and_texture(dive / "truth" / "truth.yaml")
    return recon_section(dive, read_truth(dive), floor, texture, align_yaw_translation, folder=folder) or {}


def tsdf_backends(dive: Path, work: Path, tide_file: Path, cache: Path, pairs) -> dict:
    """Both TSDF integrators on the same pairs (serial, one worker, mesh only timed by difference)."""
    from auvnav.recon.fusion import FusionSettings

    out = {}
    for tsdf in ("blockgrid", "scalable"):
        for voxel in (0.0, 0.02):
            fusion = FusionSettings(tsdf=tsdf, voxel_m=voxel)
            started = time.perf_counter()
            summary, _ = reconstruct_into(
                dive,
                work / f"tsdf-{tsdf}-{voxel}",
                "slam",
                tide_file,
                cache,
                pairs=pairs,
                workers=1,
                fusion=fusion,
            )
            out[f"{tsdf} voxel {voxel}"] = {
                "seconds": time.perf_counter() - started,
                "faces": (summary["mesh"] or {}).get("faces"),
            }
    return out


def stereo_error(dive: Path, cache: Path, pairs) -> dict:
    """Per-pixel depth error of SGBM against the true seafloor (pairs placed with the true poses)."""
    from auvnav.dive import read_dive
    from auvnav.evaluate import _seafloor_and_texture, read_truth
    from auvnav.recon.dense import DenseGeometry, DenseSettings, pair_dense
    from auvnav.recon.placement import place_pairs
    from auvnav.vision.camera import rectification

    d = read_dive(dive)
    rig = d.vehicle.stereo
    rect = rectification(rig)
    settings = DenseSettings()
    geom = DenseGeometry.of(rig, rect, settings)
    floor, _ = _seafloor_and_texture(dive / "truth" / "truth.yaml")
    truth = read_truth(dive)
    errors, normalised = [], []
    for k in pairs:
        dense = pair_dense(dive / "images" / d.images.left[k], dive / "images" / d.images.right[k], rig, rect, geom,
                           settings, cache)  # fmt: skip
        placed = place_pairs(truth, d.images.t_s[k : k + 1], rig, geom)
        T = placed.T_ned_rect[0]
        p, z, _ = dense.points_local(geom, T[:3, :3], T[:3, 3])
        err = p[:, 2] - floor.depth_m(p[:, 0], p[:, 1])  # along the vertical: about the range error
        errors.append(err)
        normalised.append(err / (z * z / (geom.f_px * geom.baseline_m)))
    e, n = np.concatenate(errors), np.concatenate(normalised)
    mad = 1.4826 * np.median(np.abs(n - np.median(n)))
    return {
        "pairs": len(pairs),
        "depth_error_rms_mm": 1000 * float(np.sqrt(np.mean(e**2))),
        "depth_error_median_mm": 1000 * float(np.median(e)),
        "disparity_error_rms_px": float(np.sqrt(np.mean(n**2))),
        "disparity_error_robust_sigma_px": float(mad),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dive", type=Path, default=None)
    parser.add_argument("--work", type=Path, default=Path("/tmp/auvnav-bench-recon"))
    parser.add_argument("--half-m", type=float, default=6.0)
    parser.add_argument("--large-half-m", type=float, default=20.0)
    parser.add_argument("--skip", nargs="*", default=[], help="steps to skip: dr large tsdf stereo")
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    dive = args.dive or make_dive(args.work)
    tide = dive / "truth" / "tide.csv"
    cache = args.work / "cache"
    shutil.rmtree(cache, ignore_errors=True)
    results: dict[str, object] = {"dive": str(dive), "cores": os.cpu_count(), "load_average": os.getloadavg()}
    print(f"cores {os.cpu_count()}, load average {os.getloadavg()}", flush=True)

    print("1. the check dive's grid with SLAM, empty dense cache, 2 workers", flush=True)
    summary, peak = reconstruct_into(dive, args.work / "slam", "slam", tide, cache, half_m=args.half_m)
    results["slam"] = {"summary": summary, "peak_memory_mib": peak, "scores": score(dive, args.work / "slam")}
    results["load_average_after_slam"] = os.getloadavg()
    import pandas as pd

    pairs = pd.read_csv(args.work / "slam" / "pairs.csv")["i"].to_numpy()
    if "dr" not in args.skip:
        print("2. the same pairs with dead reckoning", flush=True)
        summary, peak = reconstruct_into(dive, args.work / "dr", "dr", tide, cache, pairs=pairs)
        results["dr"] = {"summary": summary, "peak_memory_mib": peak, "scores": score(dive, args.work / "dr")}
    if "large" not in args.skip:
        print(f"3. a larger patch (+-{args.large_half_m:g} m) with SLAM", flush=True)
        summary, peak = reconstruct_into(
            dive, args.work / "large", "slam", tide, cache, half_m=args.large_half_m
        )
        results["large"] = {"summary": summary, "peak_memory_mib": peak}
    if "tsdf" not in args.skip:
        print("4. TSDF integrators", flush=True)
        results["tsdf"] = tsdf_backends(dive, args.work, tide, cache, pairs[:60])
    if "stereo" not in args.skip:
        print("5. SGBM per-pixel error", flush=True)
        results["stereo"] = stereo_error(dive, cache, pairs[:: max(1, len(pairs) // 20)][:20])
    results["load_average_end"] = os.getloadavg()
    (args.work / "results.json").write_text(json.dumps(results, indent=2, default=float), encoding="utf-8")

    def line(name: str) -> None:
        r = results.get(name)
        if not isinstance(r, dict):
            return
        s, sc = r["summary"], r.get("scores", {})
        cells = f"{name:6s} pairs {s['pairs']['used']:5d}  tiles {s['grid']['tiles_with_data']:3d} "
        cells += f"(at most {s['grid'].get('pairs_per_tile_max')} pairs)  "
        cells += f"{s['pairs_per_s']:.2f} pairs/s ({s['seconds']['dense']:.0f} s dense, {s['seconds']['fusion']:.0f} s fusion)  "
        cells += f"peak {r['peak_memory_mib']:.0f} MiB; {s['pairs_per_cpu_s']:.2f} pairs per CPU second"
        print(cells)
        if sc and sc.get("relief_step_before_m") is None:
            sc = {**sc, "relief_step_before_m": float("nan"), "relief_step_after_m": float("nan"),
                  "relief_removed_pct": float("nan")}  # fmt: skip
        if sc:
            print(
                f"       DEM RMSE {1000 * sc['dem_rmse_m']:.1f} mm (unaligned {1000 * sc['dem_rmse_unaligned_m']:.0f} mm), "
                f"placement aligned RMSE {1000 * sc['placement_aligned_rmse_m']:.1f} mm; mosaic misregistration median "
                f"{sc['mosaic_misregistration_median_px']:.2f} px ({sc['mosaic_misregistration_median_mm']:.2f} mm), "
                f"p95 {sc['mosaic_misregistration_p95_px']:.2f} px ({sc['mosaic_misregistration_p95_mm']:.2f} mm); "
                f"relief steps (pressure depth) {100 * sc['relief_step_before_m']:.1f} cm before the tide, "
                f"{100 * sc['relief_step_after_m']:.1f} cm after ({sc['relief_removed_pct']:.0f}% removed); "
                f"as placed {100 * (s['relief']['step_placed_rms_m'] or 0):.1f} cm"
            )

    print("\nresults:")
    for name in ("slam", "dr", "large"):
        line(name)
    print(json.dumps({k: results[k] for k in ("tsdf", "stereo") if k in results}, indent=1, default=float))
    print(f"load average at the end {os.getloadavg()}")


if __name__ == "__main__":
    main()
