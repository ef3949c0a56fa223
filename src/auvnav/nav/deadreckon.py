"""Dead reckoning: DVL bottom-track velocity rotated into NED by the attitude and integrated.

The horizontal track is the trapezoidal integral of ``R_ned_body @ v_body`` on the navigation time
base (:mod:`auvnav.nav.inputs`: the compass heading corrected by paper eq. 5 where a correction is
given, declination added, DVL mount and lever arm removed, dropouts bridged); the depth is the pressure
depth (TEOS-10). The track starts from the first position fixes (the GPS fixes of the first stay at
the surface, or a USBL fix when it comes first), carried back to the first sample along the
dead-reckoned displacement, so the part before the fixes is kept; without fixes it starts at the
dive's origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from auvnav.frames import FloatArray
from auvnav.nav.inputs import SURFACE_GAP_S, NavInputs
from auvnav.trajectory import Trajectory


@dataclass(frozen=True)
class Start:
    """Where a track starts.

    Parameters
    ----------
    p_ne_m : ndarray, shape (2,)
        North and east of the reference point at the first sample, metres, local NED.
    source : str
        ``"gps"`` or ``"usbl"`` (the first fix, carried back) or ``"origin"``.
    t_fix_s : float or None
        Time of the first fix used, POSIX seconds.
    sigma_m : float or None
        1-sigma horizontal uncertainty of the start from the fixes, metres.
    n_fixes : int
        Fixes averaged.
    """

    p_ne_m: FloatArray
    source: str
    t_fix_s: float | None = None
    sigma_m: float | None = None
    n_fixes: int = 0

    def __post_init__(self) -> None:
        if np.shape(self.p_ne_m) != (2,):
            raise ValueError(f"p_ne_m must have shape (2,); found {np.shape(self.p_ne_m)}")


def start_position(inputs: NavInputs, displacement_ned_m: FloatArray) -> Start:
    """The track's start: the first fixes, each less the displacement dead-reckoned up to it.

    With GPS first, every fix of the first stay at the surface (fixes less than
    :data:`~auvnav.nav.inputs.SURFACE_GAP_S` apart) is carried back to the first sample and the
    results averaged, weighted by the fixes' variances, so one noisy fix does not place the whole
    track; a USBL fix is used alone.

    Parameters
    ----------
    inputs : NavInputs
    displacement_ned_m : ndarray, shape (N, 3), metres, NED
        :meth:`NavInputs.displacement_ned_m`.
    """
    if not inputs.fixes:
        return Start(np.zeros(2), "origin")
    fixes = min(inputs.fixes, key=lambda f: f.t_s[0])
    n = 1
    if fixes.sensor == "gps":
        gaps = np.flatnonzero(np.diff(fixes.t_s) > SURFACE_GAP_S)
        n = int(gaps[0]) + 1 if gaps.size else len(fixes)
    t = fixes.t_s[:n]
    lever = np.einsum("nij,j->ni", inputs.R_ned_body_at(t), fixes.lever_arm_body_m)
    moved = np.stack([np.interp(t, inputs.t_s, displacement_ned_m[:, k]) for k in range(2)], -1)
    weight = 1.0 / fixes.sigma_m[:n] ** 2
    p = (weight[:, None] * (fixes.p_ned_m[:n, :2] - lever[:, :2] - moved)).sum(axis=0) / weight.sum()
    return Start(p, fixes.sensor, float(t[0]), float(1.0 / np.sqrt(weight.sum())), n)


def dead_reckon(inputs: NavInputs, start: Start | None = None) -> Trajectory:
    """The dead-reckoned track of the reference point on the navigation time base.

    Parameters
    ----------
    inputs : NavInputs
    start : Start, optional
        Defaults to :func:`start_position`.

    Returns
    -------
    Trajectory
        Positions in local NED (depth from pressure), attitude as navigated; no uncertainties.
    """
    displacement = inputs.displacement_ned_m()
    start = start_position(inputs, displacement) if start is None else start
    p = np.column_stack(
        [start.p_ne_m[0] + displacement[:, 0], start.p_ne_m[1] + displacement[:, 1], inputs.depth_m]
    )
    return Trajectory(
        t_s=inputs.t_s,
        p_ned_m=p,
        roll_rad=inputs.roll_rad,
        pitch_rad=inputs.pitch_rad,
        yaw_rad=inputs.yaw_rad,
    )
