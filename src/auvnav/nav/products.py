"""The navigation stage: dead reckoning, filter and smoother, course made good, and their products.

Products (DESIGN section 6), in ``DIVE/products/nav/``:

- ``dr.csv`` and ``dr.tum``: the dead-reckoned track;
- ``filter.csv`` and ``filter.tum``: the smoothed filter track with 1-sigma position and heading;
- ``innovations.csv``: every position fix's innovation in the forward filter (``t, sensor,
  innovation_north_m, innovation_east_m, sigma_north_m, sigma_east_m, cov_north_east_m2,
  mahalanobis, accepted, reset``; sigma = square root of the innovation covariance's diagonal, so
  the paper's Fig. 9 bounds are +-2 sigma);
- ``cmg.csv``: course made good on the sub-sea legs between GPS fixes (:mod:`auvnav.nav.cmg`);
- ``summary.json``: what :meth:`NavResult.summary` gives.

The stage is rerunnable: a rerun replaces these files (each written atomically) and nothing else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from auvnav.compass.correction import read_correction
from auvnav.depth.pressure import depth_from_pressure
from auvnav.dive import Dive, read_dive
from auvnav.nav.cmg import TransitLeg, course_made_good
from auvnav.nav.deadreckon import Start, dead_reckon, start_position
from auvnav.nav.filter import FilterConfig, FilterResult, run_filter
from auvnav.nav.inputs import HeadingCorrection, NavInputs, nav_inputs
from auvnav.streams import write_json, write_table
from auvnav.trajectory import Trajectory, write_trajectory, write_tum

PRODUCTS_DIR = Path("products") / "nav"


@dataclass(frozen=True)
class NavResult:
    """Everything the navigation stage computes for one dive.

    Parameters
    ----------
    name : str
        The dive's name.
    inputs : NavInputs
    start : Start
    dr : Trajectory
        Dead reckoning.
    filter : FilterResult
        The smoothed track and the forward filter's innovations.
    legs : list of TransitLeg
        Course made good, computed on ``dr``.
    compass_correction : str or None
        The correction file applied, as given.
    """

    name: str
    inputs: NavInputs
    start: Start
    dr: Trajectory
    filter: FilterResult
    legs: list[TransitLeg]
    compass_correction: str | None = None

    def summary(self) -> dict[str, Any]:
        """The machine-readable summary (``summary.json``, ``auvnav navigate --json``).

        ``end_fix`` compares the last position fix with the dead reckoning (``dr_error_m``, horizontal)
        and with the forward filter's prediction (``filter_innovation_m``); it is null without fixes.
        ``heading_error_deg`` is the smoothed heading correction the filter applied to the navigated
        heading; ``deviation_deg`` its part that changes with compass heading (eq. 5 harmonics).
        """
        inputs, inn = self.inputs, self.filter.innovations
        fixes: dict[str, dict[str, int]] = {}
        for f in inputs.fixes:
            mine = inn.sensor == f.sensor
            fixes[f.sensor] = {
                "n": int(np.count_nonzero(mine)),
                "accepted": int(np.count_nonzero(inn.accepted & mine)),
                "rejected": int(np.count_nonzero(~inn.accepted & mine)),
                "resets": int(np.count_nonzero(inn.reset & mine)),
            }
        heading_deg = np.degrees(self.filter.heading_error_rad)
        harmonics = [f"{ab}{k}" for k in range(1, len(self.filter.deviation_rad) // 2 + 1) for ab in "ab"]
        return {
            "dive": self.name,
            "samples": len(inputs),
            "start_s": float(inputs.t_s[0]),
            "duration_s": float(inputs.t_s[-1] - inputs.t_s[0]),
            "dr_distance_m": float(np.linalg.norm(np.diff(self.dr.p_ned_m[:, :2], axis=0), axis=1).sum()),
            "declination_deg": math.degrees(inputs.declination_rad),
            "declination_source": inputs.declination_source,
            "compass_correction": self.compass_correction,
            "start": {
                "source": self.start.source,
                "t_fix_s": self.start.t_fix_s,
                "n_fixes": self.start.n_fixes,
                "sigma_m": self.start.sigma_m,
            },
            "dvl_dropouts": inputs.dropouts.summary(),
            "fixes": fixes,
            "innovations_inside_2sigma": float(np.mean(inn.inside(2.0))) if len(inn) else None,
            "end_fix": self._end_fix(),
            "heading_error_deg": {
                "mean": float(np.mean(heading_deg)),
                "max_abs": float(np.max(np.abs(heading_deg))),
            },
            "deviation_deg": dict(
                zip(harmonics, np.degrees(self.filter.deviation_rad).tolist(), strict=True)
            ),
            "deviation_sigma_deg": dict(
                zip(harmonics, np.degrees(self.filter.deviation_sigma_rad).tolist(), strict=True)
            ),
            "dvl_scale_error": self.filter.dvl_scale_error,
            "dvl_scale_sigma": self.filter.dvl_scale_sigma,
            "legs": len(self.legs),
        }

    def _end_fix(self) -> dict[str, Any] | None:
        if not self.inputs.fixes:
            return None
        last = max(self.inputs.fixes, key=lambda f: f.t_s[-1])
        t = float(last.t_s[-1])
        at = self.dr.interpolate(np.array([t]))
        reference = last.p_ned_m[-1] - at.R_ned_body[0] @ last.lever_arm_body_m
        inn = self.filter.innovations
        row = int(np.flatnonzero((inn.t_s == t) & (inn.sensor == last.sensor))[-1])
        return {
            "sensor": last.sensor,
            "t_s": t,
            "dr_error_m": float(np.hypot(*(reference[:2] - at.p_ned_m[0, :2]))),
            "filter_innovation_m": float(np.hypot(*inn.nu_ne_m[row])),
            "filter_innovation_sigma_m": float(np.sqrt(np.trace(inn.S_ne_m2[row]))),
        }


def navigate(
    dive: Dive,
    *,
    correction: HeadingCorrection | None = None,
    correction_name: str | None = None,
    config: FilterConfig | None = None,
) -> NavResult:
    """Dead-reckon, filter and smooth a dive, and measure course made good on its sub-sea legs.

    Parameters
    ----------
    dive : Dive
    correction : HeadingCorrection, optional
        Compass correction (paper eq. 5) applied to the logged heading.
    correction_name : str, optional
        What to call it in the summary (the file it came from).
    config : FilterConfig, optional
        Defaults to :meth:`FilterConfig.for_vehicle` with the pressure sensor's sigma as depth.

    Returns
    -------
    NavResult
    """
    inputs = nav_inputs(dive, correction)
    if config is None:
        depth_sigma_m = float(
            depth_from_pressure(dive.vehicle.pressure_sigma_pa, dive.info.origin.latitude_rad)
        )
        config = FilterConfig.for_vehicle(dive.vehicle, depth_sigma_m)
    start = start_position(inputs, inputs.displacement_ned_m())
    dr = dead_reckon(inputs, start)
    return NavResult(
        name=dive.info.name,
        inputs=inputs,
        start=start,
        dr=dr,
        filter=run_filter(inputs, start, config),
        legs=course_made_good(dive, dr),
        compass_correction=correction_name,
    )


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


def write_products(result: NavResult, out_dir: Path) -> list[Path]:
    """Write the stage's products into ``out_dir`` (normally ``DIVE/products/nav``), replacing them.

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for stem, traj in (("dr", result.dr), ("filter", result.filter.smoothed)):
        write_trajectory(traj, out_dir / f"{stem}.csv")
        write_tum(traj, out_dir / f"{stem}.tum")
        written += [out_dir / f"{stem}.csv", out_dir / f"{stem}.tum"]
    write_table(result.filter.innovations.to_frame(), out_dir / "innovations.csv")
    write_table(legs_frame(result.legs), out_dir / "cmg.csv")
    write_json(result.summary(), out_dir / "summary.json")
    written += [out_dir / "innovations.csv", out_dir / "cmg.csv", out_dir / "summary.json"]
    return written


def run_navigation(dive_path: Path, *, compass_correction: Path | None = None) -> dict[str, Any]:
    """Read a dive folder, navigate it and write ``products/nav/``; the summary (for ``auvnav demo``).

    Parameters
    ----------
    dive_path : Path
        A dive folder.
    compass_correction : Path, optional
        A compass correction file (``auvnav-compass-correction/1``).
    """
    dive = read_dive(Path(dive_path))
    correction = None if compass_correction is None else read_correction(Path(compass_correction))
    result = navigate(
        dive,
        correction=correction,
        correction_name=None if compass_correction is None else str(compass_correction),
    )
    write_products(result, Path(dive_path) / PRODUCTS_DIR)
    return result.summary()


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable account of :meth:`NavResult.summary`."""
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
