"""Vision benchmark: the issue-6 acceptance on the simulated navigation check dive, and speeds.

Steps (simulation, rendering and navigation are skipped when their outputs already exist in
``--work``, so a rerun resumes):

1. ``auvnav simulate navcheck`` (seed 0), images rendered at ``--image-scale`` (0.5 by default): the
   rendering speed, pairs per second with every core;
2. ``auvnav navigate`` (the prior for the candidates);
3. the loop stage with default settings from an empty feature cache, end to end (illumination
   correction, features, stereo, candidates, verification): stereo pairs per second, and
   ``evaluate``'s ``loops`` section: recall, precision, median errors, mean Mahalanobis distance (6 for
   honest covariances), candidates tested against true overlaps;
4. the same throughput on the first ``--speed-seconds`` of the same dive rendered at full scale;
   peak memory of each loop stage (the stage and its worker processes together).

Usage: ``.venv/bin/python benchmarks/bench_vision.py [--work DIR] [--image-scale 0.5] [--water clear]
[--raw] [--seconds S] [--speed-seconds 900] [--set NAME=VALUE ...]``: ``--water coastal|turbid`` renders
the dive in that water (``auvnav simulate --water``; the work folder gets a folder per water), ``--raw``
as raw 12-bit RGGB mosaics (``auvnav simulate --raw-images``: what survey cameras write),
``--seconds`` cuts the half-scale dive after S s of vehicle time (the issue-20 figures are on the
first 900 s: ``--seconds 900 --speed-seconds 0``), ``--speed-seconds 0`` skips step 4, ``--set``
gives the loop stage's settings (``auvnav loops --help``), e.g. ``--set features=2000`` or ``--set
direct=false``.

Besides ``evaluate``'s loops section, it prints the recall by habitat of the simulated seafloor (the
footprint centres' midpoint on reef, a ripple field, featureless sand or other sand:
:meth:`auvnav.sim.texture.SeafloorTexture.habitat`), the loops registered from features and from
images (``by_method``), and the stage's CPU seconds per stereo pair, whose inverse times the cores
is the throughput on an idle machine (the machine is shared: quote the load).
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

from treeusage import TreeUsage

ROOT = Path(__file__).resolve().parents[1]
AUVNAV = [str(Path(sys.executable).with_name("auvnav"))]

TARGETS = {
    "translation_error_median_m": ("<=", 0.01),
    "rotation_error_median_deg": ("<=", 0.1),
    "recall": (">=", 0.9),
    "precision": (">=", 0.99),
    "candidates_per_true_overlap": ("<=", 3.0),
}


def run(args: list[str]) -> None:
    print("$", " ".join(str(a) for a in args), flush=True)
    subprocess.run([str(a) for a in args], check=True, cwd=ROOT)


def render(
    dive: Path, scale: float, seconds: float | None, water: str = "clear", raw: bool = False
) -> dict[str, float]:
    """Simulate and render a dive (when absent); the rendering speed."""
    from auvnav.executor import make_executor
    from auvnav.sim.camera import render_dive_images

    if not (dive / "truth").is_dir():
        extra = [] if seconds is None else ["--duration-s", str(seconds)]
        run([*AUVNAV, "simulate", "navcheck", "--out", dive, "--seed", "0", "--no-images", "--json", *extra])
    index = dive / "images" / "index.csv"
    if index.is_file():
        return {}
    started = time.perf_counter()
    with make_executor() as executor:
        images = render_dive_images(dive, scale=scale, water=water, raw=raw, executor=executor)  # type: ignore[arg-type]
    elapsed = time.perf_counter() - started
    return {"rendered_pairs": len(images), "render_s": elapsed, "render_pairs_per_s": len(images) / elapsed}


def loops(dive: Path, usage: TreeUsage, *, fresh: bool, settings: object = None) -> dict[str, object]:
    """Navigate (when needed), run the loop stage (from an empty cache when ``fresh``), evaluate.

    ``cores_busy_features`` and ``cores_busy_verify``: the stage's CPU time over its wall time and the
    cores, for each phase (1: every core busy throughout).
    """
    from auvnav.evaluate import read_truth
    from auvnav.pipeline import run_stage
    from auvnav.sim.camera import seafloor_from_truth
    from auvnav.sim.texture import SeafloorTexture
    from auvnav.vision.evaluate import loops_section

    if not (dive / "products" / "nav" / "filter.csv").is_file():
        run([*AUVNAV, "navigate", dive, "--json"])
    if fresh:
        shutil.rmtree(dive / "products" / "vision", ignore_errors=True)
        shutil.rmtree(dive / "products" / "cache" / "vision", ignore_errors=True)
    last = [0.0]
    marks: dict[str, tuple[float, float]] = {}

    def progress(stage: str, done: int, total: int) -> None:
        now = time.perf_counter()
        if stage not in marks:
            marks[stage] = (now, usage.cpu_s())
        if stage == "verify" and done == total:  # the end of a round (the pool's workers still live)
            marks["end"] = (now, usage.cpu_s())
        if now - last[0] > 30 or done == total:
            print(f"  {stage} {done}/{total}", flush=True)
            last[0] = now

    start = (time.perf_counter(), usage.cpu_s())
    summary = run_stage(dive, "vision", settings, progress=progress)
    end = marks["end"]
    cores = os.cpu_count() or 1
    busy = {
        "cores_busy_features": (marks["verify"][1] - start[1]) / (marks["verify"][0] - start[0]) / cores,
        "cores_busy_verify": (end[1] - marks["verify"][1]) / (end[0] - marks["verify"][0]) / cores,
    }
    cpu_s = end[1] - start[1]
    truth = read_truth(dive)
    texture = SeafloorTexture(
        seed=int(getattr(seafloor_from_truth(dive / "truth" / "truth.yaml"), "seed", 0))
    )
    scores = (
        loops_section(dive, truth, truth.distance_m(), group=lambda ne: texture.habitat(ne[:, 0], ne[:, 1]))
        or {}
    )
    keep = (
        "pairs_with_features",
        "features_median",
        "candidates_tested",
        "rounds",
        "features_s",
        "elapsed_s",
    )
    return {
        **{k: summary[k] for k in keep},
        "pairs_per_s": summary["pairs_per_s"],
        "direct_accepted": summary.get("direct_accepted", 0),
        "cpu_s_per_pair": cpu_s / summary["pairs_with_features"],
        "pairs_per_s_idle_cores": (os.cpu_count() or 1) * summary["pairs_with_features"] / cpu_s,
        **busy,
        "rejected": summary["rejected"],
        **scores,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("/tmp/auvnav-bench-vision"))
    parser.add_argument("--image-scale", type=float, default=0.5)
    parser.add_argument("--seconds", type=float, default=None, help="cut the half-scale dive (vehicle time)")
    parser.add_argument("--speed-seconds", type=float, default=900.0, help="0: no full-scale run")
    parser.add_argument("--water", choices=("clear", "coastal", "turbid"), default="clear")
    parser.add_argument("--raw", action="store_true", help="raw 12-bit RGGB mosaics, not colour images")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args()
    from auvnav.config import parse_yaml
    from auvnav.stagekit import make_settings
    from auvnav.vision.stage import VisionSettings

    values = {k: parse_yaml(v, "--set")[0] for k, _, v in (item.partition("=") for item in args.set)}
    settings = make_settings(VisionSettings, values, "--set")
    args.work.mkdir(parents=True, exist_ok=True)
    print(f"cores {os.cpu_count()}, load average {os.getloadavg()}", flush=True)

    water = ("" if args.water == "clear" else f"-{args.water}") + ("-raw" if args.raw else "")
    cut = "" if args.seconds is None else f"-{args.seconds:.0f}s"
    dive = args.work / f"navcheck{water}{cut}"
    results: dict[str, object] = {
        "image_scale": args.image_scale,
        "water": args.water,
        "settings": values,
        "load_average": os.getloadavg(),
    }
    out = args.work / f"results{water}{cut}.json"

    def save() -> None:
        out.write_text(json.dumps(results, indent=2, default=float), encoding="utf-8")

    results.update(render(dive, args.image_scale, args.seconds, args.water, args.raw))
    with TreeUsage() as usage:
        results["half"] = loops(dive, usage, fresh=True, settings=settings)
    results["half_peak_memory_mib"] = usage.peak_mib
    save()  # the half-scale figures are kept should the full-scale run fail
    print(f"half scale done: {out}", flush=True)
    if args.speed_seconds > 0:
        full_dive = args.work / f"navcheck{water}-{args.speed_seconds:.0f}s-x1"
        results["full_render"] = render(full_dive, 1.0, args.speed_seconds, args.water, args.raw)
        with TreeUsage() as usage:
            results["full"] = loops(full_dive, usage, fresh=True, settings=settings)
        results["full_peak_memory_mib"] = usage.peak_mib
    results["load_average_end"] = os.getloadavg()
    save()
    print(json.dumps(results, indent=2, default=float))
    half = results["half"]
    assert isinstance(half, dict)
    print("\nacceptance (half-scale images, default settings):")
    for key, (op, target) in TARGETS.items():
        value = half.get(key, float("nan"))
        ok = value <= target if op == "<=" else value >= target
        print(f"  {key:32s} {value:10.4g}  target {op} {target:<6g} {'ok' if ok else 'MISSED'}")
    print(f"  {'mahalanobis_mean (about 6)':32s} {half.get('mahalanobis_mean', float('nan')):10.4g}")
    for name in ("half", "full"):
        if name not in results:
            continue
        speed = results[name]
        assert isinstance(speed, dict)
        target = " (target >= 8)" if name == "half" else ""
        print(f"  {name + ' scale pairs/s' + target:32s} {speed['pairs_per_s']:10.4g}")
        print(f"  {name + ' scale CPU s per pair':32s} {speed['cpu_s_per_pair']:10.4g}")
        print(f"  {name + ' scale pairs/s, idle cores':32s} {speed['pairs_per_s_idle_cores']:10.4g}")
    for habitat, (found, total) in half.get("recall_by_group", {}).items():
        print(f"  recall on {habitat:22s} {found / total:10.3f}  ({found} of {total})")
    for method, scores in half.get("by_method", {}).items():
        print(
            f"  loops from {method:21s} {scores['n']:10d}  precision {scores['precision']:.4f}, median "
            f"{1000 * scores['translation_error_median_m']:.1f} mm, {scores['rotation_error_median_deg']:.3f} deg"
        )


if __name__ == "__main__":
    main()
