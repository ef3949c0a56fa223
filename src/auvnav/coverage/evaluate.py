"""Scoring the coverage products against a simulated dive's truth (``coverage`` of ``auvnav evaluate``).

The truth's coverage is measured as the stage measured the dive's (:func:`analyse_coverage`, same
settings, same mission, same images), with the true poses at the image times and the true floor
under each camera (the simulator's seafloor, given by the caller; else the DVL's altitudes placed on
the true track, :func:`~auvnav.coverage.analysis.floor_under_cameras`), over the same stretches of
line (the lines matched on the product's trajectory). Keys (DESIGN section 7):

- ``coverage_pct`` / ``coverage_pct_true``: the planned area's coverage from the products / the truth;
- ``gap_area_m2`` / ``gap_area_true_m2``: the gaps' total area;
- ``spacing_rmse_m``: root mean square over every station of every adjacent pair of the product's
  spacing minus the true spacing there; ``spacing_pair_mean_rmse_m`` the same of each pair's mean;
- ``pairs``, ``pairs_class_agreement``: adjacent pairs compared, and the fraction classified alike
  (on plan, accordion, figure 8);
- ``gaps_wider`` / ``gaps_wider_true``: gaps at least ``gap_width_m`` wide.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from auvnav import products as P
from auvnav.coverage.analysis import Coverage
from auvnav.errors import DiveFormatError, Problem
from auvnav.footprint import SeafloorLike
from auvnav.trajectory import Trajectory, read_trajectory


def true_coverage(dive_path: Path, truth: Trajectory, floor: SeafloorLike | None = None) -> Coverage | None:
    """The truth's coverage measured as the coverage stage measured the dive's (module docstring);
    None when the dive has no coverage products."""
    from auvnav.coverage.analysis import (
        CoverageOptions,
        analyse_coverage,
        floor_under_cameras,
        image_poses,
        lines_of,
    )
    from auvnav.coverage.plan import survey_plan
    from auvnav.dive import read_dive
    from auvnav.plan.missions import read_mission

    dive_path = Path(dive_path)
    path = P.COVERAGE_SUMMARY.path(dive_path)
    if not path.is_file():
        return None
    summary = json.loads(path.read_text(encoding="utf-8"))
    settings = summary["settings"]
    options = CoverageOptions.from_settings(settings)
    dive = read_dive(dive_path)
    rig = dive.vehicle.stereo
    if rig is None or dive.images is None:
        raise DiveFormatError(
            [Problem(str(dive_path), "coverage products but no stereo rig or images/index.csv")]
        )
    trajectory = read_trajectory(dive_path / summary["trajectory_file"])
    estimate, _ = image_poses(dive, trajectory)
    mission = summary.get("mission") or settings["mission"]  # the summary's is absolute
    plan = (
        None if mission is None else survey_plan(read_mission(Path(mission)), min_line_m=options.min_line_m)
    )
    plan_used, flown, planned = lines_of(estimate, plan, options)
    if estimate.t_s[0] < truth.t_s[0] or estimate.t_s[-1] > truth.t_s[-1]:
        raise DiveFormatError(
            [Problem(str(dive_path / "truth"), "the true trajectory does not span the images")]
        )
    true_poses = truth.interpolate(estimate.t_s)
    if floor is not None:
        cam = true_poses.p_ned_m + (true_poses.R_ned_body @ rig.mount.lever_arm_body_m)
        floor_down = np.asarray(floor.depth_m(cam[:, 0], cam[:, 1]), dtype=float)
    else:
        floor_down = floor_under_cameras(true_poses, truth, dive, rig, settings["altitude_m"])
    return analyse_coverage(
        true_poses, floor_down, rig, dive.info.origin, plan_used, options, flown=flown, planned_lines=planned
    )


def coverage_section(
    dive_path: Path, truth: Trajectory, floor: SeafloorLike | None = None
) -> dict[str, Any] | None:
    """The coverage products of a simulated dive against its truth (module docstring); None without them."""
    dive_path = Path(dive_path)
    true_cov = true_coverage(dive_path, truth, floor)
    if true_cov is None:
        return None
    summary = json.loads(P.COVERAGE_SUMMARY.path(dive_path).read_text(encoding="utf-8"))
    t = true_cov.summary()

    spacing = pd.read_csv(P.COVERAGE_SPACING.path(dive_path))
    lines = pd.read_csv(P.COVERAGE_LINES.path(dive_path))
    truth_rows = {(p.line_a, p.line_b): p for p in true_cov.pairs}
    diffs, pair_diffs, agree, compared = [], [], 0, 0
    for (a, b), group in spacing.groupby(["line_a", "line_b"], sort=False):
        true_pair = truth_rows.get((int(a), int(b)))
        if true_pair is None:
            continue
        true_at = np.interp(
            group["along_m"].to_numpy(), true_pair.along_m, true_pair.spacing_m, left=np.nan, right=np.nan
        )
        d = group["spacing_m"].to_numpy() - true_at
        d = d[np.isfinite(d)]
        if d.size == 0:
            continue
        compared += 1
        diffs.append(d)
        pair_diffs.append(float(np.nanmean(group["spacing_m"].to_numpy())) - float(np.nanmean(true_at)))
        row = lines[(lines["line_a"] == a) & (lines["line_b"] == b)]
        if len(row) and row["class"].iloc[0] == true_pair.classification:
            agree += 1
    all_d = np.concatenate(diffs) if diffs else np.zeros(0)

    cov, cov_true = summary["coverage_pct"], t["coverage_pct"]
    gap, gap_true = summary["gaps"]["area_m2"], t["gaps"]["area_m2"]
    return {
        "coverage_pct": cov,
        "coverage_pct_true": cov_true,
        "coverage_pct_error": None if cov is None or cov_true is None else cov - cov_true,
        "gap_area_m2": gap,
        "gap_area_true_m2": gap_true,
        "gap_area_error_pct": 100.0 * (gap - gap_true) / gap_true
        if gap_true > 0
        else (0.0 if gap == 0 else math.inf),
        "gaps_wider": summary["gaps"]["count_wider"],
        "gaps_wider_true": t["gaps"]["count_wider"],
        "spacing_rmse_m": float(np.sqrt(np.mean(all_d**2))) if all_d.size else None,
        "spacing_pair_mean_rmse_m": float(np.sqrt(np.mean(np.square(pair_diffs)))) if pair_diffs else None,
        "pairs": compared,
        "pairs_class_agreement": agree / compared if compared else None,
        "classes_true": {
            "on_plan": t["lines"]["on_plan"],
            "accordion": t["lines"]["accordion"],
            "figure_8": t["lines"]["figure_8"],
        },
        "spacing_true_mean_m": t["lines"]["spacing_mean_m"],
        "spacing_true_min_m": t["lines"]["spacing_min_m"],
        "spacing_true_max_m": t["lines"]["spacing_max_m"],
    }
