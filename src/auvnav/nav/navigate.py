"""Navigating a dive: dead reckoning, filter and smoother, course made good, in one result.

:func:`navigate` runs the navigation of one :class:`~auvnav.dive.Dive`; :class:`NavResult` carries
what it found and its machine-readable summary. The stage that writes the products is
:mod:`auvnav.nav.stage`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from auvnav.depth.pressure import depth_from_pressure
from auvnav.dive import Dive
from auvnav.nav.cmg import TransitLeg, course_made_good
from auvnav.nav.deadreckon import Start, dead_reckon, start_position
from auvnav.nav.filter import FilterConfig, FilterResult, run_filter
from auvnav.nav.inputs import HeadingCorrection, NavInputs, nav_inputs
from auvnav.trajectory import Trajectory


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
