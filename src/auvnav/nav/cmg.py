"""Course made good on sub-sea legs: GPS before and after a dive against dead reckoning (paper Fig. 5b).

A leg runs from the last GPS fix before the vehicle goes below the surface to the first fix after it
comes back (GPS fixes more than ``min_gap_s`` apart). The GPS course made good is the direction from
the first fix to the second; the dead-reckoned course is the direction of the dead-reckoned
displacement over the same times. On a transit flown at a steady compass heading ``h``, their
difference is the heading error of the compass at ``h`` as the dead reckoning saw it: with a track
dead-reckoned from the *uncorrected* compass (declination applied), the whole correction
``delta(h)`` of eq. 5, which fixes the correction's constant term (paper section III.B;
:func:`auvnav.compass.deviation.fix_constant`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from auvnav.dive import Dive
from auvnav.frames import geodetic2ned, wrap_angle
from auvnav.nav.inputs import SURFACE_GAP_S
from auvnav.trajectory import Trajectory


@dataclass(frozen=True)
class TransitLeg:
    """One sub-sea leg between GPS fixes.

    Parameters
    ----------
    t_start_s, t_end_s : float
        Times of the fix before and the fix after, POSIX seconds.
    length_m : float
        Horizontal distance between the two fixes (antenna lever arm removed), metres.
    dr_length_m : float
        Horizontal dead-reckoned displacement over the leg, metres.
    cmg_rad : float
        GPS course made good, radians from true north, clockwise.
    dr_course_rad : float
        Dead-reckoned course over the same times, radians.
    course_error_rad : float
        ``wrap(cmg - dr_course)``: the heading error the dead reckoning carried.
    course_sigma_rad : float
        1-sigma of ``cmg`` from the two fixes' uncertainties, ``sqrt(s1^2 + s2^2) / length``.
    mean_compass_heading_rad : float
        Circular mean of the heading as the compass gave it (no correction, no declination) over the
        leg, each sample weighted by the distance dead-reckoned in its step (turning on the spot at
        the surface does not count), radians.
    compass_heading_spread_rad : float
        Circular standard deviation of that heading, radians: a steady transit has a small one.
    """

    t_start_s: float
    t_end_s: float
    length_m: float
    dr_length_m: float
    cmg_rad: float
    dr_course_rad: float
    course_error_rad: float
    course_sigma_rad: float
    mean_compass_heading_rad: float
    compass_heading_spread_rad: float

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


def course_made_good(dive: Dive, dr: Trajectory, *, min_gap_s: float = SURFACE_GAP_S) -> list[TransitLeg]:
    """The sub-sea legs of a dive, their GPS course made good and dead-reckoned course.

    Parameters
    ----------
    dive : Dive
        Its GPS fixes and compass heading.
    dr : Trajectory
        A dead-reckoned track of the dive (:func:`auvnav.nav.deadreckon.dead_reckon`); legs it does
        not cover are left out.
    min_gap_s : float
        GPS fixes further apart than this bound a leg.

    Returns
    -------
    list of TransitLeg
        In time order; empty without GPS or without a leg.
    """
    gps = dive.gps
    if gps is None:
        return []
    gps = gps.select((gps.t_s >= dr.t_s[0]) & (gps.t_s <= dr.t_s[-1]))
    if len(gps) < 2:
        return []
    at_fixes = dr.interpolate(gps.t_s)
    antenna = geodetic2ned(gps.latitude_rad, gps.longitude_rad, np.zeros(len(gps)), dive.info.origin)
    p = antenna - np.einsum("nij,j->ni", at_fixes.R_ned_body, dive.vehicle.gps.lever_arm_body_m)
    # The compass heading at the track's samples, each weighted by the distance run in its step.
    att = dive.attitude
    heading = np.interp(dr.t_s, att.t_s, np.unwrap(att.heading_rad))
    step = np.linalg.norm(np.diff(dr.p_ned_m[:, :2], axis=0), axis=1)
    weight = np.concatenate([[0.0], step])
    legs = []
    for i in np.flatnonzero(np.diff(gps.t_s) > min_gap_s):
        t0, t1 = float(gps.t_s[i]), float(gps.t_s[i + 1])
        fix = p[i + 1, :2] - p[i, :2]
        moved = at_fixes.p_ned_m[i + 1, :2] - at_fixes.p_ned_m[i, :2]
        cmg = math.atan2(fix[1], fix[0])
        dr_course = math.atan2(moved[1], moved[0])
        length = float(np.hypot(*fix))
        inside = (dr.t_s > t0) & (dr.t_s <= t1)
        w = weight[inside]
        mean_vector = complex(np.sum(w * np.exp(1j * heading[inside])) / w.sum()) if w.sum() > 0 else 0j
        resultant = min(abs(mean_vector), 1.0)
        legs.append(
            TransitLeg(
                t_start_s=t0,
                t_end_s=t1,
                length_m=length,
                dr_length_m=float(np.hypot(*moved)),
                cmg_rad=cmg,
                dr_course_rad=dr_course,
                course_error_rad=float(wrap_angle(cmg - dr_course)),
                course_sigma_rad=float(np.hypot(gps.sigma_m[i], gps.sigma_m[i + 1]) / max(length, 1e-9)),
                mean_compass_heading_rad=math.atan2(mean_vector.imag, mean_vector.real),
                compass_heading_spread_rad=math.sqrt(-2.0 * math.log(resultant))
                if resultant > 0
                else math.inf,
            )
        )
    return legs
