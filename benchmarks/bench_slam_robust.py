"""Benchmark of outlier-robust loop-closure selection and of online SLAM (issue 21).

1. **Selection**: the default survey flown with the raw compass (75 m x 50 m at 1 m, seed 1) with
   truth loop closures, clean and with 20% and 40% false ones, solved with pairwise-consistency
   selection before the graduated Cauchy solve (``loop_selection="pcm"``, the default now) and with the
   Cauchy kernel alone (``"none"``, the solver before issue 21) on the same graphs: aligned ATE, its
   ratio to the clean solve (target 1.2), the rejections against the simulator's false flags
   (precision: rejected rows that are false; recall: false rows rejected; both for every rejection,
   and for the pairwise-consistency step alone), solve time.
2. **Online** (``--online``): the navigation check dive (seed 1) and the same survey, clean and 20%
   false, replayed in time order with batched iSAM2 (10 poses per update, 1 s front-end latency):
   update time per pose (an update's wall time over the poses it adds; targets median 20 ms, 95th
   percentile 200 ms), the aligned ATE of the estimate known at each moment (target within 2x of
   batch) and of the final smoothed one, peak memory.

Each run is a fresh process (its peak memory its own). Marginals are skipped (``marginal_every=0``).
Quote the load average printed with each figure: the machine is shared.

Run: ``.venv/bin/python benchmarks/bench_slam_robust.py [--out DIR] [--skip-cauchy] [--skip-online]``
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import os
import platform
import resource
import time
from pathlib import Path
from typing import Any

import yaml

from auvnav.evaluate import evaluate_dive
from auvnav.pipeline import run_stage
from auvnav.sim.run import run_scenario
from auvnav.sim.truthloops import write_truth_loops
from auvnav.slam.stage import SlamSettings

FALSE = (0.2, 0.4)


def _task(dive: str, loops: str, options: dict[str, Any]) -> dict[str, Any]:
    logging.basicConfig(level=logging.WARNING)
    start = time.perf_counter()
    summary = run_stage(Path(dive), "slam", SlamSettings(loops=Path(loops), marginal_every=0, **options))
    wall = time.perf_counter() - start
    scores = evaluate_dive(Path(dive))
    return {
        "summary": summary,
        "slam": scores["slam"],
        "online": scores.get("online"),
        "stage_s": wall,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "load": os.getloadavg()[0],
    }


def run(dive: Path, loops: Path, **options: Any) -> dict[str, Any]:
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1) as pool:
        return pool.apply(_task, (str(dive), str(loops), options))


def rejection(loops: Path, result: dict[str, Any]) -> dict[str, float]:
    info = yaml.safe_load(loops.with_suffix(".yaml").read_text(encoding="utf-8"))
    false = set(info["false_rows"])
    rejected = set(result["summary"]["loops"]["rejected_rows"])
    hits = len(false & rejected)
    return {
        "false": len(false),
        "rejected": len(rejected),
        "precision": hits / len(rejected) if rejected else 1.0,
        "recall": hits / len(false) if false else 1.0,
    }


def simulate(scenario: str, out: Path) -> None:
    if (out / "truth" / "loops_false40.csv").is_file():
        return
    run_scenario(scenario, out, seed=1, overwrite=True, truth_loops=True)
    for f in FALSE:
        write_truth_loops(
            out, false_fraction=f, seed=1, out=out / "truth" / f"loops_false{round(100 * f)}.csv"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench-slam-robust"))
    parser.add_argument("--skip-cauchy", action="store_true", help="Skip the Cauchy-only solves (slow).")
    parser.add_argument("--skip-online", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"# {platform.node()}, {multiprocessing.cpu_count()} cores, {time.strftime('%Y-%m-%d %H:%M')}")
    results: dict[str, Any] = {}
    survey, navcheck = args.out / "survey_raw", args.out / "navcheck"
    simulate("survey", survey)
    simulate("navcheck", navcheck)

    selections = ("pcm",) if args.skip_cauchy else ("pcm", "none")
    for selection in selections:
        clean = run(survey, survey / "truth" / "loops.csv", loop_selection=selection)
        print(
            f"survey raw, clean, {selection:4s}: aligned ATE {clean['slam']['ate_aligned_rmse_m']:.3f} m, "
            f"solve {clean['summary']['seconds']:.1f} s (load {clean['load']:.1f})"
        )
        results[f"survey_clean_{selection}"] = clean
        for f in FALSE:
            loops = survey / "truth" / f"loops_false{round(100 * f)}.csv"
            r = run(survey, loops, loop_selection=selection)
            ratio = r["slam"]["ate_aligned_rmse_m"] / clean["slam"]["ate_aligned_rmse_m"]
            rej = rejection(loops, r)
            sel = r["summary"]["loops"]["selection"]
            print(
                f"survey raw, {round(100 * f)}% false, {selection:4s}: aligned ATE {r['slam']['ate_aligned_rmse_m']:.3f} m "
                f"(ratio {ratio:.3f}), rejected {rej['rejected']} (precision {rej['precision']:.4f}, recall "
                f"{rej['recall']:.4f}), selection {sel}, solve {r['summary']['seconds']:.1f} s, peak "
                f"{r['peak_rss_mb']:.0f} MB (load {r['load']:.1f})"
            )
            results[f"survey_false{round(100 * f)}_{selection}"] = {**r, "ratio": ratio, "rejection": rej}

    if not args.skip_online:
        for dive in (navcheck, survey):
            batch = run(dive, dive / "truth" / "loops.csv")
            for name in ("loops", "loops_false20"):
                r = run(dive, dive / "truth" / f"{name}.csv", online=True)
                o, ratio = (
                    r["online"],
                    r["online"]["ate_aligned_rmse_m"] / batch["slam"]["ate_aligned_rmse_m"],
                )
                print(
                    f"{dive.name}, {name}, online: per pose median {o['update_median_ms']:.1f} ms, 95th "
                    f"{o['update_p95_ms']:.1f} ms, max {o['update_max_ms']:.0f} ms; aligned ATE online "
                    f"{o['ate_aligned_rmse_m']:.3f} m ({ratio:.2f}x batch {batch['slam']['ate_aligned_rmse_m']:.3f} m), "
                    f"smoothed {r['slam']['ate_aligned_rmse_m']:.3f} m; loop delay median {o['loop_delay_median_s']:.0f} s; "
                    f"peak {r['peak_rss_mb']:.0f} MB (load {r['load']:.1f})"
                )
                results[f"{dive.name}_{name}_online"] = {**r, "batch": batch["slam"], "ratio": ratio}
    (args.out / "results.json").write_text(json.dumps(results, indent=1, default=float), encoding="utf-8")


if __name__ == "__main__":
    main()
