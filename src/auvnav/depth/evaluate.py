"""Scoring the depth stage's products against a simulated dive's truth (``auvnav evaluate``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from auvnav import products as P
from auvnav.depth.tide import read_constituents
from auvnav.depth.validation import LoopDepth, rms
from auvnav.dive import read_dive
from auvnav.streams import read_stream

TRUE_TIDE_FILE = Path("truth") / "tide.csv"


def depth_section(dive_path: Path) -> dict[str, Any] | None:
    """The ``depth`` section of ``auvnav evaluate`` (DESIGN section 7), or None without depth products.

    ``residual_rms_before_m`` and ``residual_rms_after_m`` over all loops, as ``summary.json`` has them
    (``after`` is None when no tide was applied), and the same for the far-apart loops. With the
    simulator's ``truth/tide.csv``: ``residual_rms_true_tide_m``, the residual once the true tide
    change is removed (what pressure and vision leave), and with an estimated tide
    ``estimated_tide_change_rmse_m`` and ``estimated_tide_change_rmse_far_apart_m``, its tide change
    against the truth's over the loops.
    """
    dive_path = Path(dive_path)
    summary_file = P.DEPTH_SUMMARY.path(dive_path)
    if not summary_file.is_file():
        return None
    summary = json.loads(summary_file.read_text(encoding="utf-8"))
    section: dict[str, Any] = {
        "residual_rms_before_m": summary["residual_rms_before_m"],
        "residual_rms_after_m": summary["residual_rms_after_m"],
        "far_apart_residual_rms_before_m": summary["far_apart"]["residual_rms_before_m"],
        "far_apart_residual_rms_after_m": summary["far_apart"]["residual_rms_after_m"],
    }
    truth_file = dive_path / TRUE_TIDE_FILE
    if not truth_file.is_file():
        return section
    dive = read_dive(dive_path)
    latitude_rad = dive.info.origin.latitude_rad
    truth = read_constituents(truth_file, latitude_rad=latitude_rad)
    loops = read_stream(LoopDepth, P.DEPTH_LOOPS.path(dive_path))
    far = loops.dt_s > summary["far_apart_s"]
    true_change = truth.predict(loops.t_j_s) - truth.predict(loops.t_i_s)
    section["residual_rms_true_tide_m"] = rms(loops.residual_before_m - true_change)
    estimated_file = P.DEPTH_TIDE_ESTIMATED.path(dive_path)
    if summary["estimated_tide"] is not None and estimated_file.is_file():
        estimated = read_constituents(estimated_file, latitude_rad=latitude_rad)
        error = estimated.predict(loops.t_j_s) - estimated.predict(loops.t_i_s) - true_change
        section["estimated_tide_change_rmse_m"] = rms(error)
        section["estimated_tide_change_rmse_far_apart_m"] = rms(error[far])
    return section
