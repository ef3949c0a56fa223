"""Benchmark of ``auvnav campaign`` (issue 21): two simulated surveys of one site put in one frame.

The first dive is the default survey (75 m x 50 m at 1 m, seed 1, flown with the raw compass) unless
``--small``; the second flies the same mission over the same seafloor three days later (another
tide; its own seed: noise, DVL errors, GPS fixes) with the tallest coral head of the surveyed area
removed (:func:`auvnav.sim.repeat.simulate_repeat`). Each dive's SLAM runs on its truth loop
closures with its tide (``truth/tide.csv``: a tide prediction, so that the dives' depths share the
datum) and marginals of every 10th pair (the candidates' search uses the sigmas). The inter-dive
candidates are verified from the truth (:class:`auvnav.sim.repeat.TruthRegistration`: 1 cm and 0.1
degree of noise), ``--false`` of what verifies being false matches (default 20%).

Measured: the campaign's wall time and peak memory (in a fresh process), candidates tested, verified
and kept, and ``auvnav evaluate CAMPAIGN``'s campaign section: ``inter_dive_rmse_m`` (target under
0.02 m RMS over the overlap) and ``inter_dive_loop_precision`` (target >= 0.99).

``--images``: inter-dive loops from the images, and the change detection. Two small surveys (12 m x
8 m, seeds ``--site`` and the next: 31 and 32 by default) with quarter-scale images (the repeat's
texture is the site's), each processed by the pipeline (nav, vision loop closures, SLAM with its tide,
recon without the TSDF mesh), then the campaign, its inter-dive candidates verified by the loop
stage's registration of the two dives' images (:class:`auvnav.campaign.ImageRegistration`;
``--truth-registration``: from the truth instead); scored by ``evaluate``: inter-dive RMSE and loop
precision as above, the removed coral head's area and height (targets within 20%) and the largest
false change (target 0.25 m^2).

Run: ``.venv/bin/python benchmarks/bench_campaign.py [--out DIR] [--small] [--false 0.2] [--images
[--site 31] [--truth-registration]]``
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import platform
import resource
import time
from pathlib import Path
from typing import Any

from auvnav.campaign import run_campaign
from auvnav.evaluate import evaluate_dive
from auvnav.pipeline import run_stage
from auvnav.sim.repeat import TruthRegistration, simulate_repeat
from auvnav.sim.run import run_scenario
from auvnav.slam.stage import SlamSettings

SMALL = {"width_m": 20.0, "height_m": 12.0, "lead_in_m": 10.0}
TARGETS = {"inter_dive_rmse_m": 0.02, "inter_dive_loop_precision": 0.99}


def _campaign_task(dives: list[str], out: str, false: float) -> dict[str, Any]:
    logging.basicConfig(level=logging.WARNING)
    start = time.perf_counter()
    paths = [Path(d) for d in dives]
    summary = run_campaign(
        paths,
        Path(out),
        TruthRegistration(paths, false_fraction=false, seed=1),
        overwrite=True,
        registration_name="truth",
    )
    return {
        "summary": summary,
        "wall_s": time.perf_counter() - start,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def images(out: Path, false: float, site: int, truth_registration: bool) -> None:
    """Two small imaged surveys processed in full, then the campaign and its DEM difference."""
    from auvnav.campaign import ImageRegistration
    from auvnav.cli import main as cli
    from auvnav.executor import make_executor
    from auvnav.sim.camera import render_dive_images

    geometry = {"width_m": 12.0, "height_m": 8.0, "lead_in_m": 5.0}
    first, repeat = out / "dive1", out / "dive2"
    start = time.perf_counter()
    run_scenario("survey", first, seed=site, geometry=geometry, overwrite=True)
    render_dive_images(first, scale=0.25, seed=site)
    change = simulate_repeat(first, repeat, seed=site + 1, days_later=3.0, geometry=geometry, overwrite=True)[
        "change"
    ]
    render_dive_images(repeat, scale=0.25, seed=site + 1)
    print(f"simulated and rendered in {time.perf_counter() - start:.0f} s; removed {change['removed']}")
    settings = out / "settings.yaml"
    settings.write_text("recon: {voxel_m: 0.0}\n", encoding="utf-8")
    only = [x for stage in ("nav", "vision", "slam", "recon") for x in ("--only", stage)]
    for dive in (first, repeat):
        start = time.perf_counter()
        args = [
            "process",
            str(dive),
            "--tide",
            str(dive / "truth/tide.csv"),
            "--settings",
            str(settings),
            "-q",
        ]
        code = cli([*args, *only])
        print(f"{dive.name}: processed in {time.perf_counter() - start:.0f} s (exit {code})")
    start = time.perf_counter()
    with make_executor() as executor:
        register: Any = (
            TruthRegistration([first, repeat], false_fraction=false, seed=1)
            if truth_registration
            else ImageRegistration([first, repeat], executor=executor)
        )
        summary = run_campaign(
            [first, repeat], out / "campaign", register, overwrite=True,
            registration_name="truth" if truth_registration else "images",
        )  # fmt: skip
    print(f"campaign in {time.perf_counter() - start:.0f} s: {summary['inter_dive']}, {summary['changes']}")
    scores = evaluate_dive(out / "campaign")["campaign"]
    print("scores:", json.dumps(scores))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench-campaign"))
    parser.add_argument("--small", action="store_true", help="A 20 m x 12 m survey instead of the default.")
    parser.add_argument(
        "--false", type=float, default=0.2, help="Fraction of verified candidates that are false."
    )
    parser.add_argument("--images", action="store_true", help="The change detection on small imaged surveys.")
    parser.add_argument(
        "--site", type=int, default=31, help="With --images: the first dive's seed (the site)."
    )
    parser.add_argument(
        "--truth-registration", action="store_true", help="With --images: inter-dive loops from the truth."
    )
    args = parser.parse_args()
    if args.images:
        images(args.out, args.false, args.site, args.truth_registration)
        return
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"# {platform.node()}, {multiprocessing.cpu_count()} cores, {time.strftime('%Y-%m-%d %H:%M')}")
    geometry = SMALL if args.small else None
    first, repeat = args.out / "dive1", args.out / "dive2"
    start = time.perf_counter()
    run_scenario("survey", first, seed=1, truth_loops=True, geometry=geometry, overwrite=True)
    change = simulate_repeat(
        first, repeat, seed=2, days_later=3.0, truth_loops=True, geometry=geometry, overwrite=True
    )["change"]
    print(f"simulated in {time.perf_counter() - start:.0f} s; removed {change['removed']}")
    for dive in (first, repeat):
        start = time.perf_counter()
        s = run_stage(
            dive,
            "slam",
            SlamSettings(loops=dive / "truth/loops.csv", tide=dive / "truth/tide.csv", marginal_every=10),
        )
        scores = evaluate_dive(dive)["slam"]
        print(
            f"{dive.name}: SLAM {s['poses']} poses in {time.perf_counter() - start:.0f} s, "
            f"aligned ATE {scores['ate_aligned_rmse_m']:.3f} m, ATE {scores['ate_rmse_m']:.3f} m"
        )
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1) as pool:
        result = pool.apply(
            _campaign_task, ([str(first), str(repeat)], str(args.out / "campaign"), args.false)
        )
    scores = evaluate_dive(args.out / "campaign")["campaign"]
    for pair in result["summary"]["inter_dive"]:
        print(
            f"{' x '.join(pair['dives'])}: {pair['candidates_tested']} candidates tested, {pair['seeds_verified']} "
            f"seeds verified, {pair['verified']} verified, {pair['kept']} kept"
        )
    joint = result["summary"]["joint_graph"]
    print(
        f"campaign: {result['wall_s']:.0f} s (joint solve {joint['solve_s']:.0f} s, {joint['variables']} variables), "
        f"peak {result['peak_rss_mb']:.0f} MB"
    )
    print("scores:", json.dumps(scores))
    print("targets:", TARGETS)
    (args.out / "results.json").write_text(
        json.dumps({"campaign": result, "scores": scores, "change": change}, indent=1, default=float),
        encoding="utf-8",
    )


if __name__ == "__main__":
    main()
