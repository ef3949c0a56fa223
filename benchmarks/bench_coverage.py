"""Benchmark of coverage (issue 17): speed, accuracy against the truth, and the prediction before the dive.

Three parts, each run on its own (``--part``), one at a time on a quiet machine:

``speed``
    10,000 stereo pairs of a synthetic lawnmower (100 lines of 50 m, 1 m apart, an image every 0.5 m
    at 2 m altitude over a flat floor, the Sirius-like rig) through
    :func:`auvnav.coverage.analysis.analyse_coverage` on a 5 cm grid (footprints, images per cell,
    gaps, along-track overlap, line matching and spacing), then the GeoTIFF and the PNG. Targets:
    under 10 s, under 1 GB. Peak memory is the process's peak resident set (the analysis runs in a
    fresh process) and the peak of Python's traced allocations (numpy's included); the CPU time is
    printed beside the wall time, which a loaded machine inflates.

``survey``
    The default survey (75 m x 50 m, 1 m spacing, 100 m lead-in, seed 3) flown three ways: with the
    raw compass (uncorrected), with the correction fitted on the default check dive (seed 1, truth
    headings, constant from the default transits, seed 2) applied in real time (corrected), and with
    no deviation. Before each is flown, its prediction (``auvnav coverage predict``: the correction
    file as the vehicle's deviation estimate, the same file applied, and no deviation). Each is then
    simulated with truth loop closures, navigated and solved by SLAM (the deviating ones with the check
    dive's correction applied in post-processing, as the paper does, whether or not the vehicle applied
    it in real time) and its coverage measured from the SLAM trajectory, then scored against
    the truth (``auvnav evaluate``'s coverage section). A diagnostic row gives the same measurement
    with the SLAM trajectory moved by its mean offset from the truth (its shape, the truth's
    placement): the planned area's coverage depends on where the survey lies, which SLAM knows only
    as well as its GPS-anchored placement. Targets: coverage of the planned area within 0.5
    percentage points of the truth's, gap area within 5% of the true gap area, spacing within 5 cm
    RMS; the prediction's spacing within 10 cm RMS of what the simulator flew.

``reliability``
    The predicted probability of a gap against what the simulator flies, over many seeds. For each
    deviation peak ``X`` in ``--peaks-deg`` (default 0.1 to 2 degrees) and each of ``--seeds`` seeds, the
    vehicle gets a hard iron (horizontal, in a random direction drawn from the seed) whose one-cycle
    deviation has peak ``X``, and flies the default survey uncorrected; the prediction is ``auvnav
    coverage predict --deviation-peak-deg X`` (the same for every seed of a peak: the phase is
    unknown before the dive; ``--draws`` draws). Half the phases open the lines (accordion) and half
    close them (figure 8, no gap between lines), so no predicted probability exceeds about 0.5. The
    outcome is whether the truth's images leave a gap at least ``--widths-m`` wide between the lines
    of the planned area (0.5 and 1 m). ``--seafloor reef`` (default) flies over the simulator's reef,
    whose coral heads the vehicle rides low over: its footprint shrinks there and leaves holes up to
    about 1.6 m wide that no heading error made and the prediction's flat floor does not model;
    ``--seafloor lagoon`` removes the coral heads (same slope, undulation and rugosity), which
    isolates what the prediction models. The dives are not written: the truth's coverage is measured
    straight from the simulation (its image times and the true seafloor). ``--vehicle-seed`` sets
    the vehicle (its DVL's mounting) of every dive, -1 a vehicle per dive. Printed as a reliability
    table: predicted probability against observed frequency, per peak and pooled in bins, with the
    Brier score.

Run: ``.venv/bin/python benchmarks/bench_coverage.py --part speed|survey|reliability [--work DIR]
[--seeds N] [--peaks-deg 0.1,0.3,...] [--seafloor reef|lagoon]``
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import logging
import math
import multiprocessing
import os
import platform
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

SPEED_TARGET_S = 10.0
MEMORY_TARGET_MB = 1024.0
COVERAGE_TARGET_PP = 0.5
GAP_TARGET_PCT = 5.0
SPACING_TARGET_M = 0.05
PREDICTION_SPACING_TARGET_M = 0.10
SEEDS = {"navcheck": 1, "transit": 2, "survey": 3}


def _conditions() -> str:
    load = os.getloadavg()
    return f"{platform.node()}, {os.cpu_count()} cores, load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"


# ---------------------------------------------------------------------------------------------
# speed
# ---------------------------------------------------------------------------------------------


def _speed_task(out: str) -> dict[str, Any]:
    import tracemalloc

    from auvnav.coverage.analysis import CoverageOptions, analyse_coverage
    from auvnav.coverage.figure import write_coverage_png
    from auvnav.coverage.plan import survey_plan
    from auvnav.frames import GeodeticOrigin
    from auvnav.plan.missions import survey
    from auvnav.raster import write_geotiff
    from auvnav.sim.camera import default_stereo_rig
    from auvnav.trajectory import Trajectory

    lines, length, step = 100, 50.0, 0.5
    per_line = int(length / step)
    p, yaw = [], []
    for i in range(lines):
        along = np.arange(per_line) * step
        north = along if i % 2 == 0 else length - along
        p.append(np.column_stack([north, np.full(per_line, float(i)), np.full(per_line, 18.0)]))
        yaw.append(np.full(per_line, 0.0 if i % 2 == 0 else math.pi))
    pos = np.concatenate(p)
    n = len(pos)
    rng = np.random.default_rng(0)
    poses = Trajectory(
        t_s=1.25e9 + np.arange(n, dtype=float),
        p_ned_m=pos + rng.normal(0, 0.01, (n, 3)),
        roll_rad=np.radians(rng.normal(0.5, 0.5, n)),
        pitch_rad=np.radians(rng.normal(1.0, 0.5, n)),
        yaw_rad=np.concatenate(yaw) + np.radians(rng.normal(0, 0.5, n)),
    )
    floor = np.full(n, 20.0)  # 2 m below the vehicle: camera 1.7 m above the floor
    mission = survey(width_m=length, height_m=float(lines - 1), spacing_m=1.0, lead_in_m=0.0)
    plan = survey_plan(mission)
    origin = GeodeticOrigin.from_degrees(-14.05, 121.78)
    rig = default_stereo_rig()
    tracemalloc.start()
    start, cpu0 = time.perf_counter(), time.process_time()
    cov = analyse_coverage(poses, floor, rig, origin, plan, CoverageOptions())
    analysed, analysed_cpu = time.perf_counter() - start, time.process_time() - cpu0
    write_geotiff(Path(out) / "coverage.tif", cov.counts, cov.grid, description=("images per cell",))
    write_coverage_png(cov, Path(out) / "coverage.png", title="speed benchmark")
    total, total_cpu = time.perf_counter() - start, time.process_time() - cpu0
    _, traced = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    s = cov.summary()
    return {
        "images": n,
        "cells": cov.grid.width * cov.grid.height,
        "grid": f"{cov.grid.width} x {cov.grid.height}",
        "analyse_s": analysed,
        "with_files_s": total,
        "analyse_cpu_s": analysed_cpu,
        "with_files_cpu_s": total_cpu,
        "traced_peak_mb": traced / 2**20,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "coverage_pct": s["coverage_pct"],
        "pairs": s["lines"]["pairs"],
        "on_plan": s["lines"]["on_plan"],
    }


def part_speed(work: Path) -> None:
    ctx = multiprocessing.get_context("spawn")
    runs = []
    for _ in range(3):
        with ctx.Pool(1) as pool:
            runs.append(pool.apply(_speed_task, (str(work),)))
    best = min(runs, key=lambda r: r["analyse_s"])
    print(f"speed: {best['images']} images, grid {best['grid']} ({best['cells'] / 1e6:.1f} M cells of 5 cm)")
    for r in runs:
        print(
            f"  analyse {r['analyse_s']:.2f} s, with GeoTIFF and PNG {r['with_files_s']:.2f} s "
            f"(CPU {r['analyse_cpu_s']:.2f} s / {r['with_files_cpu_s']:.2f} s); "
            f"peak RSS {r['peak_rss_mb']:.0f} MB, traced {r['traced_peak_mb']:.0f} MB; "
            f"coverage {r['coverage_pct']:.2f}%, {r['pairs']} pairs ({r['on_plan']} on plan)"
        )
    worst_mem = max(r["peak_rss_mb"] for r in runs)
    ok = best["with_files_s"] < SPEED_TARGET_S and worst_mem < MEMORY_TARGET_MB
    print(
        f"target < {SPEED_TARGET_S:.0f} s and < {MEMORY_TARGET_MB:.0f} MB: {'PASS' if ok else 'FAIL'} "
        f"(best {best['with_files_s']:.2f} s, worst peak RSS {worst_mem:.0f} MB); {_conditions()}"
    )


# ---------------------------------------------------------------------------------------------
# survey: three ways, against the truth, and the prediction before each
# ---------------------------------------------------------------------------------------------


def add_camera_calibration(dive: Path) -> None:
    """Write the simulator's stereo rig into a dive's vehicle.yaml (the trigger log exists, the images
    were not rendered: the vehicle still has its calibrated camera)."""
    from auvnav.sim.camera import default_stereo_rig
    from auvnav.vehicle import read_vehicle, write_vehicle

    path = dive / "vehicle.yaml"
    vehicle = read_vehicle(path)
    if vehicle.stereo is None:
        write_vehicle(dataclasses.replace(vehicle, stereo=default_stereo_rig()), path)


def correction_file(work: Path) -> Path:
    """The default check dive's deviation (truth headings), constant from the default transits."""
    from auvnav.compass.stage import CompassSettings, fit_to_file
    from auvnav.sim.run import run_scenario

    path = work / "correction.yaml"
    if path.is_file():
        return path
    navcheck, transit = work / "navcheck", work / "transit"
    run_scenario("navcheck", navcheck, seed=SEEDS["navcheck"], overwrite=True)
    run_scenario("transit", transit, seed=SEEDS["transit"], overwrite=True)
    fit_to_file([navcheck], CompassSettings(reference="truth", transits=(transit,)), path, overwrite=True)
    return path


def _true_pairs(dive: Path) -> tuple[dict[tuple[int, int], Any], float]:
    """The truth's adjacent pairs (by line numbers) and its widest gap, metres."""
    from auvnav.coverage.evaluate import true_coverage
    from auvnav.evaluate import read_truth
    from auvnav.sim.camera import seafloor_from_truth

    cov = true_coverage(dive, read_truth(dive), seafloor_from_truth(dive / "truth" / "truth.yaml"))
    assert cov is not None
    return {(p.line_a, p.line_b): p for p in cov.pairs}, cov.summary()["gaps"]["widest_m"]


def placed_as_truth(dive: Path) -> dict[str, Any]:
    """Coverage from the SLAM trajectory moved by its mean offset from the truth (its shape, the truth's
    placement) against the truth's: what the coverage measurement gets right given a placed survey."""
    import dataclasses as dc

    from auvnav.coverage.analysis import (
        CoverageOptions,
        analyse_coverage,
        floor_under_cameras,
        image_poses,
    )
    from auvnav.coverage.evaluate import true_coverage
    from auvnav.coverage.plan import survey_plan
    from auvnav.dive import read_dive
    from auvnav.evaluate import read_truth
    from auvnav.plan.missions import read_mission
    from auvnav.sim.camera import seafloor_from_truth
    from auvnav.trajectory import read_trajectory

    summary = json.loads((dive / "products" / "coverage" / "summary.json").read_text())
    d = read_dive(dive)
    truth = read_truth(dive)
    slam = read_trajectory(dive / summary["trajectory_file"])
    offset = (slam.p_ned_m - truth.interpolate(slam.t_s).p_ned_m).mean(axis=0)
    moved = dc.replace(slam, p_ned_m=slam.p_ned_m - offset)
    poses, _ = image_poses(d, moved)
    assert d.vehicle.stereo is not None
    floor = floor_under_cameras(poses, moved, d, d.vehicle.stereo)
    plan = survey_plan(read_mission(Path(summary["mission"])))
    cov = analyse_coverage(
        poses,
        floor,
        d.vehicle.stereo,
        d.info.origin,
        plan,
        CoverageOptions.from_settings(summary["settings"]),
    )
    true = true_coverage(dive, truth, seafloor_from_truth(dive / "truth" / "truth.yaml"))
    assert true is not None
    a, b = cov.summary(), true.summary()
    return {
        "offset_m": offset.tolist(),
        "coverage_pct": a["coverage_pct"],
        "coverage_pct_true": b["coverage_pct"],
        "gap_area_m2": a["gaps"]["area_m2"],
        "gap_area_true_m2": b["gaps"]["area_m2"],
    }


def part_survey(work: Path) -> None:
    from auvnav.compass.correction import read_correction
    from auvnav.coverage.plan import survey_plan
    from auvnav.coverage.predict import FootprintExtent, HeadingErrorPrior, predict_survey
    from auvnav.coverage.stage import CoverageSettings
    from auvnav.dive import read_dive_info
    from auvnav.evaluate import evaluate_dive
    from auvnav.nav.stage import NavSettings
    from auvnav.pipeline import run_stage
    from auvnav.plan.missions import survey, write_mission
    from auvnav.sim.camera import default_stereo_rig
    from auvnav.sim.run import run_scenario
    from auvnav.slam.stage import SlamSettings
    from auvnav.vehicle import Vehicle

    start = time.perf_counter()
    correction = correction_file(work)
    mission = survey()
    mission_file = work / "survey.yaml"
    write_mission(mission, mission_file)
    plan = survey_plan(mission)
    footprint = FootprintExtent.of_vehicle(Vehicle(stereo=default_stereo_rig()), mission.altitude_m)
    declination = read_dive_info(work / "navcheck").declination_rad or 0.0
    model = read_correction(correction)
    ways = {
        "uncorrected": ({}, HeadingErrorPrior.from_correction(model, applied=False, source=str(correction)),
                        {"compass_correction": correction}, correction),
        "corrected": ({"compass_correction": correction},
                      HeadingErrorPrior.from_correction(model, applied=True, source=str(correction)),
                      {"compass_correction": correction}, correction),
        "no deviation": ({"deviation": "none"}, HeadingErrorPrior.deviation_peak(0.0), {}, None),
    }  # fmt: skip
    print(f"survey: correction and check dives ready in {time.perf_counter() - start:.0f} s")
    rows = []
    placed: dict[str, dict[str, Any]] = {}
    for name, (sim_options, prior, slam_options, nav_correction) in ways.items():
        t0 = time.perf_counter()
        prediction = predict_survey(plan, prior, footprint, declination_rad=declination, draws=500, seed=0)
        predicted_s = time.perf_counter() - t0
        dive = work / f"survey-{name.replace(' ', '-')}"
        t0 = time.perf_counter()
        run_scenario("survey", dive, seed=SEEDS["survey"], truth_loops=True, overwrite=True, **sim_options)
        add_camera_calibration(dive)
        simulated_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_stage(dive, "nav", NavSettings(compass_correction=nav_correction))
        run_stage(dive, "slam", SlamSettings(loops=dive / "truth" / "loops.csv", **slam_options))
        processed_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_stage(dive, "coverage", CoverageSettings(mission=mission_file))
        coverage_s = time.perf_counter() - t0
        scores = evaluate_dive(dive)
        c = scores["coverage"]
        true_pairs, widest_true = _true_pairs(dive)
        diffs = []
        for p in prediction.pairs:
            t = true_pairs.get((p.line_a, p.line_b))
            if t is not None:
                d = p.mean_m - np.interp(p.along_m, t.along_m, t.spacing_m, left=np.nan, right=np.nan)
                diffs.append(d[np.isfinite(d)])
        d = np.concatenate(diffs)
        true_gap = {w: widest_true >= w for w in (0.5, 1.0)}
        p_gap = {w: float(np.mean(prediction.widest_gap_m >= w)) for w in (0.5, 1.0)}
        placed[name] = placed_as_truth(dive)
        summary = {**prediction.summary(), "p_gap_by_width": p_gap, "widest_true_m": widest_true}
        rows.append((name, c, scores["slam"], summary, float(np.sqrt(np.mean(d**2))), true_gap))
        print(
            f"  {name}: predicted in {predicted_s:.1f} s; simulated {simulated_s:.0f} s, nav + SLAM {processed_s:.0f} s, "
            f"coverage stage {coverage_s:.1f} s"
        )
    print()
    print(f"{'':34s}" + "".join(f"{name:>16s}" for name, *_ in rows))

    def line(label: str, values: list[str]) -> None:
        print(f"{label:34s}" + "".join(f"{v:>16s}" for v in values))

    line(
        "SLAM ate / aligned (m)",
        [f"{s['ate_rmse_m']:.3f}/{s['ate_aligned_rmse_m']:.3f}" for _, _, s, *_ in rows],
    )
    line(
        "coverage % SLAM / truth",
        [f"{c['coverage_pct']:.2f}/{c['coverage_pct_true']:.2f}" for _, c, *_ in rows],
    )
    line("  error (pp, target 0.5)", [f"{c['coverage_pct_error']:+.3f}" for _, c, *_ in rows])
    line(
        "gap area m2 SLAM / truth",
        [f"{c['gap_area_m2']:.1f}/{c['gap_area_true_m2']:.1f}" for _, c, *_ in rows],
    )
    line("  error (%, target 5)", [f"{c['gap_area_error_pct']:+.2f}" for _, c, *_ in rows])
    line("SLAM mean offset from truth n/e (m)", [
        f"{placed[n]['offset_m'][0]:+.2f}/{placed[n]['offset_m'][1]:+.2f}" for n, *_ in rows
    ])  # fmt: skip
    line("  placed as the truth: coverage err", [
        f"{placed[n]['coverage_pct'] - placed[n]['coverage_pct_true']:+.3f} pp" for n, *_ in rows
    ])  # fmt: skip
    line("  placed as the truth: gap err", [
        f"{100 * (placed[n]['gap_area_m2'] / placed[n]['gap_area_true_m2'] - 1):+.2f}%" for n, *_ in rows
    ])  # fmt: skip
    line("spacing RMSE vs truth (m, 0.05)", [f"{c['spacing_rmse_m']:.4f}" for _, c, *_ in rows])
    line("  pair means RMSE (m)", [f"{c['spacing_pair_mean_rmse_m']:.4f}" for _, c, *_ in rows])
    line(
        "pairs compared / same class", [f"{c['pairs']}/{c['pairs_class_agreement']:.2f}" for _, c, *_ in rows]
    )
    line("true spacing min/mean/max (m)", [
        f"{c['spacing_true_min_m']:.2f}/{c['spacing_true_mean_m']:.2f}/{c['spacing_true_max_m']:.2f}" for _, c, *_ in rows
    ])  # fmt: skip
    line("true classes on/acc/fig8", [
        f"{c['classes_true']['on_plan']}/{c['classes_true']['accordion']}/{c['classes_true']['figure_8']}" for _, c, *_ in rows
    ])  # fmt: skip
    line("predicted spacing mean (m)", [f"{p['spacing']['mean_m']:.3f}" for *_, p, _, _ in rows])
    line("prediction spacing RMSE (m, 0.1)", [f"{r:.4f}" for *_, r, _ in rows])
    line(
        "predicted coverage % (truth)",
        [f"{p['coverage_pct_mean']:.2f} ({c['coverage_pct_true']:.2f})" for _, c, _, p, _, _ in rows],
    )
    for w in (0.5, 1.0):
        line(
            f"predicted P(gap >= {w:.1f} m) / flown",
            [f"{p['p_gap_by_width'][w]:.2f} / {'yes' if g[w] else 'no'}" for *_, p, _, g in rows],
        )
    line("true widest gap (m)", [f"{p['widest_true_m']:.2f}" for *_, p, _, _ in rows])
    verdicts = []
    for name, c, _, _, rmse, _ in rows:
        ok = (
            abs(c["coverage_pct_error"]) <= COVERAGE_TARGET_PP
            and abs(c["gap_area_error_pct"]) <= GAP_TARGET_PCT
            and c["spacing_rmse_m"] <= SPACING_TARGET_M
        )
        verdicts.append(
            f"{name}: {'PASS' if ok else 'FAIL'} (prediction {'PASS' if rmse <= PREDICTION_SPACING_TARGET_M else 'FAIL'})"
        )
    print("; ".join(verdicts))
    print(f"total {time.perf_counter() - start:.0f} s; {_conditions()}")
    (work / "survey_results.json").write_text(
        json.dumps(
            [
                {"way": n, "coverage": c, "slam": s, "prediction": p, "prediction_rmse_m": r}
                for n, c, s, p, r, _ in rows
            ],
            indent=1,
            default=float,
        )
    )


# ---------------------------------------------------------------------------------------------
# reliability
# ---------------------------------------------------------------------------------------------


def iron_with_peak(peak_rad: float, direction_rad: float, earth: Any) -> Any:
    """A horizontal hard iron whose deviation (level, the simulator's :func:`deviation_table`) has
    the given peak; its direction in the body sets the phase."""
    from auvnav.sim.sensors import Iron, deviation_table

    b_h = math.hypot(float(earth.b_ned_T[0]), float(earth.b_ned_T[1]))
    h = np.radians(np.arange(0.0, 360.0, 1.0))
    magnitude = b_h * math.sin(peak_rad)
    for _ in range(3):  # rescale to the exact peak
        iron = Iron(
            h_hard_body_T=magnitude * np.array([math.cos(direction_rad), math.sin(direction_rad), 0.0])
        )
        peak = float(np.max(np.abs(deviation_table(iron, earth, h))))
        if peak == 0:
            break
        magnitude *= peak_rad / peak
    return Iron(h_hard_body_T=magnitude * np.array([math.cos(direction_rad), math.sin(direction_rad), 0.0]))


#: ``--seafloor``: the simulator's default reef, or a lagoon floor without its coral mounds (the same
#: slope, undulation and 3 cm rugosity): the flat floor the prediction assumes, give or take the
#: undulation.
SEAFLOORS = {"reef": {}, "lagoon": {"reef_probability": 0.0}}


def _outcome_task(args: tuple[float, int, str, int | None, str]) -> dict[str, Any]:
    """Fly the default survey with a one-cycle deviation of the given peak (phase from the seed);
    the truth's coverage of the planned area."""
    peak_deg, seed, mission_file, vehicle_seed, seafloor_kind = args
    from auvnav.compass.field import earth_field
    from auvnav.coverage.analysis import CoverageOptions, analyse_coverage
    from auvnav.coverage.plan import survey_plan
    from auvnav.footprint import footprints  # noqa: F401 (the footprint model the truth uses)
    from auvnav.frames import GeodeticOrigin
    from auvnav.plan.missions import read_mission
    from auvnav.sim.camera import default_stereo_rig, select_image_times
    from auvnav.sim.run import default_config, simulate
    from auvnav.sim.seafloor import Seafloor

    logging.basicConfig(level=logging.ERROR)
    mission = read_mission(Path(mission_file))
    from auvnav.sim.seafloor import SeafloorParams

    config = default_config(seed=seed, vehicle_seed=seed if vehicle_seed is None else vehicle_seed)
    config = dataclasses.replace(config, seafloor=SeafloorParams(**SEAFLOORS[seafloor_kind]))
    earth = earth_field(config.latitude_rad, config.longitude_rad, config.start_time_s)
    direction = float(np.random.default_rng([seed, 0x1204]).uniform(0, 2 * math.pi))
    config = dataclasses.replace(config, iron=iron_with_peak(math.radians(peak_deg), direction, earth))
    sim = simulate(mission, config)
    seafloor = Seafloor(config.seed, config.seafloor)
    times = select_image_times(sim.trajectory, seafloor)
    poses = sim.trajectory.interpolate(times)
    rig = default_stereo_rig()
    cam = poses.p_ned_m + poses.R_ned_body @ rig.mount.lever_arm_body_m
    floor = seafloor.depth_m(cam[:, 0], cam[:, 1])
    origin = GeodeticOrigin(config.latitude_rad, config.longitude_rad)
    cov = analyse_coverage(poses, floor, rig, origin, survey_plan(mission), CoverageOptions())
    s = cov.summary()
    dev = sim.deviation_deg[:, 1]
    return {
        "peak_deg": peak_deg,
        "seed": seed,
        "deviation_peak_deg": float(np.max(np.abs(dev))),
        "coverage_pct": s["coverage_pct"],
        "widest_m": s["gaps"]["widest_m"],
        "spacing_mean_m": s["lines"]["spacing_mean_m"],
        "pairs": s["lines"]["pairs"],
    }


def part_reliability(
    work: Path,
    seeds: int,
    peaks_deg: list[float],
    widths_m: list[float],
    vehicle_seed: int | None,
    draws: int = 500,
    seafloor: str = "reef",
    seed_offset: int = 0,
) -> None:
    from auvnav.coverage.plan import survey_plan
    from auvnav.coverage.predict import FootprintExtent, HeadingErrorPrior, predict_survey
    from auvnav.dive import read_dive_info  # noqa: F401
    from auvnav.plan.missions import survey, write_mission
    from auvnav.sim.camera import default_stereo_rig
    from auvnav.vehicle import Vehicle

    start = time.perf_counter()
    mission = survey()
    mission_file = work / "survey.yaml"
    write_mission(mission, mission_file)
    plan = survey_plan(mission)
    footprint = FootprintExtent.of_vehicle(Vehicle(stereo=default_stereo_rig()), mission.altitude_m)
    from auvnav.compass.field import earth_field
    from auvnav.sim.run import default_config

    config = default_config()
    declination = earth_field(config.latitude_rad, config.longitude_rad, config.start_time_s).declination_rad
    predicted = {}
    for peak in peaks_deg:
        prior = HeadingErrorPrior.deviation_peak(math.radians(peak))
        predicted[peak] = predict_survey(
            plan, prior, footprint, declination_rad=declination, draws=draws, seed=1
        )
    print(f"reliability: predictions for {len(peaks_deg)} peaks in {time.perf_counter() - start:.0f} s")
    tasks = [  # independent dives (their own phase, seafloor, noise) for every peak
        (peak, 1000 + 100 * i + k, str(mission_file), vehicle_seed, seafloor)
        for i, peak in enumerate(peaks_deg)
        for k in range(seed_offset, seed_offset + seeds)
    ]
    print(
        f"vehicle: {'one per dive (seed)' if vehicle_seed is None else f'vehicle seed {vehicle_seed} for every dive'}; "
        f"seafloor: {seafloor}"
    )
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(2, maxtasksperchild=4) as pool:
        outcomes = pool.map(_outcome_task, tasks, chunksize=1)
    (work / "reliability.json").write_text(json.dumps(outcomes, indent=1))
    print(f"{len(outcomes)} dives flown and measured in {time.perf_counter() - start:.0f} s")
    for width in widths_m:
        print()
        print(f"gaps at least {width:.2f} m wide in the planned area:")
        print(
            f"{'peak deg':>9s} {'P(gap) predicted':>17s} {'observed':>16s} {'coverage % pred / flown':>26s}"
        )
        pooled = []
        for peak in peaks_deg:
            mine = [o for o in outcomes if o["peak_deg"] == peak]
            p = float(np.mean(predicted[peak].widest_gap_m >= width))
            gaps = [o["widest_m"] >= width for o in mine]
            pooled += [(p, g) for g in gaps]
            print(
                f"{peak:9.3f} {p:17.2f} {np.mean(gaps):8.2f} ({sum(gaps):2d}/{len(mine)}) "
                f"{predicted[peak].summary()['coverage_pct_mean']:12.1f} / "
                f"{np.mean([o['coverage_pct'] for o in mine]):.1f}"
            )
        print("pooled (bins of predicted probability):")
        edges = [0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0001]
        for lo, hi in itertools.pairwise(edges):
            inside = [(p, g) for p, g in pooled if lo <= p < hi]
            if inside:
                print(
                    f"  [{lo:.1f}, {min(hi, 1.0):.1f}{']' if hi > 1 else ')'}: {len(inside)} dives, mean "
                    f"predicted {np.mean([p for p, _ in inside]):.2f}, observed {np.mean([g for _, g in inside]):.2f}"
                )
        brier = np.mean([(p - g) ** 2 for p, g in pooled])
        print(f"Brier score {brier:.3f} over {len(pooled)} dives")
    print(_conditions())
    print(
        "flown widest gap per dive (m):",
        ", ".join(f"{o['peak_deg']:g}/{o['seed']}: {o['widest_m']:.2f}" for o in outcomes),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=("speed", "survey", "reliability"), required=True)
    parser.add_argument("--work", type=Path, help="keep dives and results here")
    parser.add_argument("--seeds", type=int, default=6, help="reliability: seeds per peak")
    parser.add_argument(
        "--peaks-deg", default="0.1,0.3,0.5,0.7,1.0,1.5,2.0", help="reliability: deviation peaks"
    )
    parser.add_argument(
        "--seed-offset",
        type=int,
        default=0,
        help="reliability: skip this many seeds of each peak (more dives)",
    )
    parser.add_argument(
        "--seafloor", choices=tuple(SEAFLOORS), default="reef", help="reliability: the simulated seafloor"
    )
    parser.add_argument("--draws", type=int, default=500, help="reliability: Monte Carlo draws per peak")
    parser.add_argument("--widths-m", default="0.5,1.0", help="reliability: gap widths that count")
    parser.add_argument(
        "--vehicle-seed",
        type=int,
        default=0,
        help="reliability: the vehicle (its DVL mounting) of every dive; -1: a vehicle per dive",
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-coverage-"))
    work.mkdir(parents=True, exist_ok=True)
    if args.part == "speed":
        part_speed(work)
    elif args.part == "survey":
        part_survey(work)
    else:
        part_reliability(
            work,
            args.seeds,
            [float(x) for x in args.peaks_deg.split(",")],
            [float(x) for x in args.widths_m.split(",")],
            None if args.vehicle_seed < 0 else args.vehicle_seed,
            args.draws,
            args.seafloor,
            args.seed_offset,
        )


if __name__ == "__main__":
    main()
