"""Benchmark of the SLAM stage on simulated dives with loop closures from the truth (issue 7).

Measured, each SLAM run in a fresh process (wall time of the solve and of the whole stage, peak
resident set size):

1. The default navigation check dive (seed 1) with truth loop closures: ``ate_aligned_rmse_m``
   (target <= 0.10 m), and the deviation fitted to its SLAM headings (``auvnav compass fit``,
   reference slam) against the true curve, constant excluded (target <= 0.15 deg RMS). The same with
   ``--estimate-compass`` and no reference heading at all (target <= 0.1 deg RMS), and with 20%
   false loop closures (ratio to the clean figure).
2. The paper-scale survey (75 m x 50 m at 1 m, ~9,000 stereo pairs at 1 Hz) with truth loop
   closures, clean and with 20% false ones (targets: <= 0.2 m, and at most 1.2 times the clean figure):
   flown with the navigation check's SLAM-fitted correction applied in real time (the paper's
   campaign: calibrate, then survey; its lines 1 m apart overlap), and as flown with the raw compass
   (the default survey: its deviation spreads the lines 1.5 to 4.6 m apart, so adjacent lines
   barely overlap and the loop closures cannot measure their spacing), solved with the raw compass
   and with ``--estimate-compass`` (the deviation's harmonics, fixed by the GPS at both ends,
   carry the spacing). The false loop closures' rejections are scored against the simulator's
   flags (precision: rejected rows that are false; recall: false rows rejected). Solve time and
   memory, batch and iSAM2.

Images are not rendered: the loop closures come from the truth (``auvnav simulate --truth-loops``,
:mod:`auvnav.sim.truthloops`), 1 cm and 0.1 degree of noise per axis. The depth is the pressure
depth (no tide correction) unless ``--tide`` is given, which corrects it with the dive's true tide
(a perfect astronomical prediction).

With ``--estimate-dvl`` every solve also estimates the DVL's calibration (:mod:`auvnav.slam.dvl`) and
each row says what it found.

Run: ``.venv/bin/python benchmarks/bench_slam_dive.py [--out DIR] [--seed 1] [--tide] [--skip-survey]
[--estimate-dvl]``
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

import yaml

from auvnav.compass.evaluate import compass_section
from auvnav.compass.stage import CompassSettings, fit_to_file
from auvnav.evaluate import evaluate_dive
from auvnav.pipeline import run_stage
from auvnav.sim.run import run_scenario
from auvnav.sim.truthloops import write_truth_loops
from auvnav.slam.stage import SlamSettings

TARGETS = {
    "navcheck_ate_aligned_m": 0.10,
    "navcheck_fit_from_slam_deg": 0.15,
    "navcheck_estimated_deg": 0.10,
    "survey_ate_aligned_m": 0.20,
    "survey_false_ratio": 1.2,
}


def _slam_task(dive: str, options: dict[str, Any]) -> dict[str, Any]:
    """One SLAM run (in a child process): its summary, scores, wall time and peak memory."""
    logging.basicConfig(level=logging.WARNING)
    start = time.perf_counter()
    summary = run_stage(Path(dive), "slam", SlamSettings(**options))
    wall = time.perf_counter() - start
    scores = evaluate_dive(Path(dive))["slam"]
    return {
        "summary": summary,
        "scores": scores,
        "stage_s": wall,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def slam_run(dive: Path, **options: Any) -> dict[str, Any]:
    """Run :func:`_slam_task` in a fresh process (so its peak memory is its own)."""
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1) as pool:
        return pool.apply(_slam_task, (str(dive), options))


def false_rejection(loops: Path, summary: dict[str, Any]) -> dict[str, float]:
    """The rejections against the simulator's false flags (``loops.yaml`` beside the loop file):
    counts, precision (rejected rows that are false) and recall (false rows rejected)."""
    info = yaml.safe_load(loops.with_suffix(".yaml").read_text(encoding="utf-8"))
    false, rejected = set(info["false_rows"]), set(summary["loops"]["rejected_rows"])
    hits = len(false & rejected)
    return {
        "false": len(false),
        "false_rejected": hits,
        "true_rejected": len(rejected - false),
        "true": info["loops"] - len(false),
        "precision": hits / len(rejected) if rejected else 1.0,
        "recall": hits / len(false) if false else 1.0,
    }


def simulate(scenario: str, out: Path, seed: int, **options: Any) -> dict[str, Any]:
    """A dive with truth loops (clean, truth/loops.csv) and 20% false ones (truth/loops_false20.csv)."""
    summary = run_scenario(scenario, out, seed=seed, overwrite=True, truth_loops=True, **options)
    write_truth_loops(out, false_fraction=0.2, seed=seed, out=out / "truth" / "loops_false20.csv")
    return summary


def row(name: str, result: dict[str, Any], extra: str = "") -> str:
    s, sc = result["summary"], result["scores"]
    dvl = s.get("dvl")
    if dvl:
        roll, pitch, yaw = dvl["misalignment_rpy_deg"]
        extra += (
            f" DVL scale {100 * dvl['scale_factor']:+.3f}% (error {100 * sc['dvl_scale_factor_error']:+.3f}%), "
            f"mounting {roll:+.3f} {pitch:+.3f} {yaw:+.3f} deg, time offset {dvl['time_offset_s']:+.4f} s"
        )
    return (
        f"{name:42s} poses {s['poses']:6d} loops {s['loops']['used']:6d} rejected {s['loops']['rejected']:5d} "
        f"ate_aligned {sc['ate_aligned_rmse_m']:.4f} m  solve {s['seconds']:7.1f} s  stage {result['stage_s']:7.1f} s "
        f"peak {result['peak_rss_mb']:6.0f} MB {extra}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench-slam"), help="Folder for the dives.")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--tide", action="store_true", help="Correct the depth with the true tide.")
    parser.add_argument("--skip-survey", action="store_true")
    parser.add_argument("--estimate-dvl", action="store_true", help="Estimate the DVL calibration too.")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"# {platform.node()}, {multiprocessing.cpu_count()} cores, {time.strftime('%Y-%m-%d %H:%M')}")
    results: dict[str, Any] = {}

    def common(dive: Path) -> dict[str, Any]:
        """The options every solve takes: the true tide (``--tide``), the DVL calibration (``--estimate-dvl``)."""
        return {
            **({"tide": dive / "truth" / "tide.csv"} if args.tide else {}),
            **({"estimate_dvl": True} if args.estimate_dvl else {}),
        }

    # 1. The navigation check dive.
    nav = args.out / "navcheck"
    simulate("navcheck", nav, args.seed)
    clean = slam_run(nav, loops=nav / "truth" / "loops.csv", **common(nav))
    fit_to_file([nav], CompassSettings(reference="slam"), args.out / "navcheck_fit.yaml", overwrite=True)
    fit_scores = compass_section(nav, args.out / "navcheck_fit.yaml")
    false = slam_run(nav, loops=nav / "truth" / "loops_false20.csv", **common(nav))
    estimated = slam_run(nav, loops=nav / "truth" / "loops.csv", estimate_compass=True, **common(nav))
    est_scores = compass_section(nav, nav / "products" / "slam" / "correction.yaml")
    print(row("navcheck, clean", clean))
    print(f"{'':42s} deviation fitted to SLAM headings: shape RMS {fit_scores['shape_rmse_deg']:.4f} deg")
    ratio = false["scores"]["ate_aligned_rmse_m"] / clean["scores"]["ate_aligned_rmse_m"]
    print(
        row(
            "navcheck, 20% false",
            false,
            f"ratio {ratio:.3f} {false_rejection(nav / 'truth' / 'loops_false20.csv', false['summary'])}",
        )
    )
    print(row("navcheck, --estimate-compass", estimated, f"shape RMS {est_scores['shape_rmse_deg']:.4f} deg"))
    results["navcheck"] = {
        "clean": clean,
        "fit_from_slam": fit_scores,
        "false20": false,
        "false20_ratio": ratio,
        "estimated": estimated,
        "estimated_deviation": est_scores,
    }

    # 2. The paper-scale survey, corrected as the paper's campaign flew it, and raw (the default
    # survey as flown: its lines barely overlap, so the compass's deviation is estimated in the graph).
    if not args.skip_survey:
        for name, flown, solved in (
            ("survey_corrected", {"compass_correction": args.out / "navcheck_fit.yaml"}, {}),
            ("survey_raw", {}, {}),
            ("survey_raw", {}, {"estimate_compass": True}),
        ):
            dive = args.out / name
            if name not in results:
                simulate("survey", dive, args.seed, **flown)
                results[name] = {}
            label = name + (", --estimate-compass" if solved else "")
            survey_clean = slam_run(dive, loops=dive / "truth" / "loops.csv", **solved, **common(dive))
            survey_false = slam_run(
                dive, loops=dive / "truth" / "loops_false20.csv", **solved, **common(dive)
            )
            ratio = (
                survey_false["scores"]["ate_aligned_rmse_m"] / survey_clean["scores"]["ate_aligned_rmse_m"]
            )
            rejection = false_rejection(dive / "truth" / "loops_false20.csv", survey_false["summary"])
            print(row(f"{label}, clean", survey_clean))
            print(row(f"{label}, 20% false", survey_false, f"ratio {ratio:.3f} {rejection}"))
            results[name][label] = {"clean": survey_clean, "false20": survey_false, "false20_ratio": ratio}
        dive = args.out / "survey_corrected"
        incremental = slam_run(dive, loops=dive / "truth" / "loops.csv", incremental=True, **common(dive))
        print(row("survey_corrected, clean, iSAM2", incremental))
        results["survey_corrected"]["incremental"] = incremental

    (args.out / "results.json").write_text(json.dumps(results, indent=1, default=float), encoding="utf-8")
    print(f"targets: {TARGETS}; details in {args.out / 'results.json'}")


if __name__ == "__main__":
    main()
