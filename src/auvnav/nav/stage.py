"""The navigation stage (``auvnav navigate``): dead reckoning, filter and smoother, and their products.

Products (DESIGN section 6), in ``DIVE/products/nav/``:

- ``dr.csv`` and ``dr.tum``: the dead-reckoned track;
- ``filter.csv`` and ``filter.tum``: the smoothed filter track with 1-sigma position and heading;
- ``innovations.csv``: every position fix's innovation in the forward filter (``t, sensor,
  innovation_north_m, innovation_east_m, sigma_north_m, sigma_east_m, cov_north_east_m2,
  mahalanobis, accepted, reset``; sigma = square root of the innovation covariance's diagonal, so
  the paper's Fig. 9 bounds are +-2 sigma);
- ``cmg.csv``: course made good on the sub-sea legs between GPS fixes (:mod:`auvnav.nav.cmg`);
- ``summary.json``: what :meth:`~auvnav.nav.navigate.NavResult.summary` gives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from auvnav import products as P
from auvnav.dive import dive_files, read_dive
from auvnav.stagekit import Stage, StageContext, setting
from auvnav.streams import write_json, write_table
from auvnav.trajectory import write_trajectory, write_tum

if TYPE_CHECKING:  # the models load when the stage runs, not when the pipeline checks its key
    from auvnav.nav.cmg import TransitLeg
    from auvnav.nav.navigate import NavResult


@dataclass(frozen=True)
class NavSettings:
    """Settings of the navigation stage."""

    compass_correction: Path | None = setting(None, "Compass correction file applied to the heading (eq. 5).")


def legs_frame(legs: list[TransitLeg]) -> pd.DataFrame:
    """Course made good as a table in file units (``cmg.csv``)."""
    deg = math.degrees
    columns = [
        "t_start",
        "t_end",
        "duration_s",
        "length_m",
        "dr_length_m",
        "cmg_deg",
        "dr_course_deg",
        "course_error_deg",
        "course_sigma_deg",
        "mean_compass_heading_deg",
        "compass_heading_spread_deg",
    ]
    rows = [
        [
            leg.t_start_s,
            leg.t_end_s,
            leg.duration_s,
            leg.length_m,
            leg.dr_length_m,
            deg(leg.cmg_rad),
            deg(leg.dr_course_rad),
            deg(leg.course_error_rad),
            deg(leg.course_sigma_rad),
            deg(leg.mean_compass_heading_rad),
            deg(leg.compass_heading_spread_rad),
        ]
        for leg in legs
    ]
    return pd.DataFrame(rows, columns=columns)


def write_products(result: NavResult, out: Path) -> None:
    """Write the stage's products into ``out`` (a stage folder being written)."""
    for csv, tum, traj in (
        (P.NAV_DR, P.NAV_DR_TUM, result.dr),
        (P.NAV_FILTER, P.NAV_FILTER_TUM, result.filter.smoothed),
    ):
        write_trajectory(traj, csv.inside(out))
        write_tum(traj, tum.inside(out))
    write_table(result.filter.innovations.to_frame(), P.NAV_INNOVATIONS.inside(out))
    write_table(legs_frame(result.legs), P.NAV_CMG.inside(out))
    write_json(result.summary(), P.NAV_SUMMARY.inside(out))


def _inputs(dive: Path, settings: NavSettings) -> dict[str, Path]:
    files = dive_files(dive)
    if settings.compass_correction is not None:
        files["compass_correction"] = settings.compass_correction
    return files


def _run(ctx: StageContext, settings: NavSettings, out: Path) -> dict[str, Any]:
    from auvnav.compass.correction import read_correction
    from auvnav.nav.navigate import navigate

    dive = read_dive(ctx.dive, allow_outside=ctx.allow_outside)
    name = settings.compass_correction
    result = navigate(
        dive,
        correction=None if name is None else read_correction(name),
        correction_name=None if name is None else str(name),
    )
    write_products(result, out)
    return result.summary()


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable account of :meth:`~auvnav.nav.navigate.NavResult.summary`."""
    drop = summary["dvl_dropouts"]
    correction = summary["compass_correction"] or "none"
    lines = [
        f"dive '{summary['dive']}': {summary['duration_s'] / 3600:.2f} h, {summary['samples']} samples, "
        f"dead-reckoned distance {summary['dr_distance_m']:.1f} m",
        f"declination {summary['declination_deg']:.2f} deg ({summary['declination_source']}), "
        f"compass correction {correction}, track starts from {summary['start']['source']}",
        f"DVL dropouts bridged: {drop['count']}, {drop['total_s']:.1f} s in all, longest {drop['longest_s']:.1f} s",
    ]
    if summary["fixes"]:
        lines.append(f"{'fixes':8s} {'n':>6s} {'used':>6s} {'rejected':>9s} {'resets':>7s}")
        for sensor, n in summary["fixes"].items():
            lines.append(f"  {sensor:6s} {n['n']:6d} {n['accepted']:6d} {n['rejected']:9d} {n['resets']:7d}")
        lines.append(f"innovations inside 2 sigma: {100 * summary['innovations_inside_2sigma']:.1f}%")
    end = summary["end_fix"]
    if end is not None:
        lines.append(
            f"last fix ({end['sensor']}): dead reckoning off by {end['dr_error_m']:.2f} m, filter innovation "
            f"{end['filter_innovation_m']:.2f} m (sigma {end['filter_innovation_sigma_m']:.2f} m)"
        )
    lines.append(f"sub-sea legs with course made good: {summary['legs']}")
    return "\n".join(lines)


STAGE = Stage(
    name="nav",
    title="dead reckoning, EKF and RTS smoother with GPS/USBL, course made good",
    after=(),
    settings=NavSettings,
    inputs=_inputs,
    unavailable=lambda dive, settings: None,
    run=_run,
    describe=format_summary,
)
