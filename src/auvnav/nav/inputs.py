"""The navigation time base: a dive's sensors brought onto the DVL's samples, in SI units and NED.

Every estimator in :mod:`auvnav.nav` works from :class:`NavInputs`:

- **Time base**: the DVL's sample times inside the span the attitude covers; a hole in the DVL log
  (rows missing) is filled with samples at the DVL's median period, so the attitude keeps steering the
  track through it.
- **Attitude**: the compass heading as logged, corrected by the compass correction (paper eq. 5,
  ``h + delta(h)``, when one is given), turned to true north by the declination when the heading is
  magnetic (DESIGN section 4: true = magnetic + declination), with pitch and roll, as the attitude of
  the compass; the compass mount (``vehicle.compass``) then gives the body attitude,
  ``R_ned_body = R_ned_compass @ R_body_compass^T``. Pitch and roll are first smoothed over
  :data:`TILT_SMOOTHING_S` (:func:`smooth_tilt`: a cheap tilt sensor's noise is white from sample to
  sample, the vehicle's tilt changes over seconds).
- **DVL**: bottom-track velocity rotated from the DVL frame into the body frame
  (``vehicle.dvl.R_body_sensor``). Samples marked invalid and the filled holes are *bridged*: the
  velocity in the level frame (along and across the heading, and down) is interpolated linearly
  between the valid samples on either side (held at the ends), and every bridged run is counted in
  :class:`Dropouts`.
- **Depth** of the vehicle reference point from pressure (TEOS-10 through
  :func:`auvnav.depth.pressure.depth_from_pressure` at the origin's latitude, atmospheric pressure
  removed), less the pressure sensor's lever arm rotated into NED.
- **Position fixes** (GPS at the surface, USBL) in local NED about the dive's origin.

The DVL measures the velocity of its own point, ``v_dvl = v_ref + omega x r``. Rather than
differentiate a noisy attitude for ``omega``, the lever arm is removed on positions: integrating
``R_ned_body v_dvl`` gives the DVL point's track, and the reference point is that track less
``R_ned_body r`` (``d/dt (R r) = R (omega x r)`` for a fixed ``r``).
"""

from __future__ import annotations

import functools
import itertools
import logging
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import savgol_filter

from auvnav.compass.field import earth_field, magnetic2true
from auvnav.depth.pressure import depth_from_pressure, sea_pressure
from auvnav.dive import Dive
from auvnav.errors import InsufficientDataError
from auvnav.frames import FloatArray, euler2rot, geodetic2ned, rot2euler, wrap_angle
from auvnav.streams import GAP_PERIODS, find_gaps

log = logging.getLogger(__name__)

#: A hole in the DVL log longer than this many median periods is filled with bridged samples.
DVL_HOLE_PERIODS = 1.5
#: Pitch and roll are smoothed by a local quadratic over this long a window, seconds
#: (:func:`smooth_tilt`). On the simulated check dive (0.2 deg of white noise at 10 Hz, the PNI TCM2's
#: tilt accuracy) the error at the images falls from 0.20 to 0.10 deg (1 s: 0.11; 2 s: 0.10; 3 s:
#: 0.11, where the quadratic no longer follows the vehicle's pitching), and between two images
#: from 0.28 to 0.14 deg.
TILT_SMOOTHING_S = 1.5
#: GPS fixes closer together than this belong to one stay at the surface; further apart, they bound
#: a sub-sea leg, seconds (GPS gives a fix a second at the surface and none below it).
SURFACE_GAP_S = 60.0
#: A dropout's bridged velocity starts and ends at the mean of the valid samples within this many
#: seconds of its edges, seconds (one ping's white noise held across a 3-minute descent is half a
#: metre).
BRIDGE_WINDOW_S = 5.0


class HeadingCorrection(Protocol):
    """A compass correction: ``correct(h)`` is ``h + delta(h)`` (paper eq. 5), radians."""

    def correct(self, h_rad: ArrayLike) -> FloatArray: ...


@dataclass(frozen=True)
class Dropouts:
    """The DVL dropouts bridged on the time base.

    Parameters
    ----------
    start_s : ndarray, shape (K,)
        POSIX seconds of the last valid sample before each dropout (or the start of the time base).
    duration_s : ndarray, shape (K,)
        Seconds from that sample to the next valid one (or to the end of the time base).
    """

    start_s: FloatArray
    duration_s: FloatArray

    def __post_init__(self) -> None:
        if np.shape(self.start_s) != np.shape(self.duration_s) or np.ndim(self.start_s) != 1:
            raise ValueError(
                f"start_s and duration_s must be 1-D and match; found {np.shape(self.start_s)} "
                f"and {np.shape(self.duration_s)}"
            )

    @property
    def count(self) -> int:
        return len(self.start_s)

    @property
    def total_s(self) -> float:
        return float(np.sum(self.duration_s))

    @property
    def longest_s(self) -> float:
        return float(np.max(self.duration_s)) if self.count else 0.0

    def summary(self) -> dict[str, float | int]:
        """``{"count", "total_s", "longest_s"}``."""
        return {"count": self.count, "total_s": self.total_s, "longest_s": self.longest_s}


@dataclass(frozen=True)
class PositionFixes:
    """Absolute position fixes of one sensor, in local NED about the dive's origin.

    Parameters
    ----------
    sensor : {"gps", "usbl"}
    t_s : ndarray, shape (M,)
        POSIX seconds.
    p_ned_m : ndarray, shape (M, 3)
        Position of the antenna or transponder, metres, local NED.
    sigma_m : ndarray, shape (M,)
        1-sigma horizontal uncertainty, metres.
    lever_arm_body_m : ndarray, shape (3,)
        The antenna or transponder relative to the vehicle reference point, metres, body FRD.
    """

    sensor: Literal["gps", "usbl"]
    t_s: FloatArray
    p_ned_m: FloatArray
    sigma_m: FloatArray
    lever_arm_body_m: FloatArray

    def __post_init__(self) -> None:
        m = np.shape(self.t_s)
        if len(m) != 1 or np.shape(self.p_ned_m) != (*m, 3) or np.shape(self.sigma_m) != m:
            raise ValueError(
                f"fixes must have t_s (M,), p_ned_m (M, 3), sigma_m (M,); found {np.shape(self.t_s)}, "
                f"{np.shape(self.p_ned_m)}, {np.shape(self.sigma_m)}"
            )

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass(frozen=True)
class NavInputs:
    """A dive's sensors on the navigation time base (see the module docstring).

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        POSIX seconds, strictly increasing.
    yaw_rad, pitch_rad, roll_rad : ndarray, shape (N,)
        Body attitude, Euler ZYX of ``R_ned_body``, true north, compass correction applied.
    compass_heading_rad : ndarray, shape (N,)
        The heading as the compass gives it (no correction, no declination), radians.
    v_body_mps : ndarray, shape (N, 3)
        Velocity of the DVL point over the seafloor, m/s, body FRD; bridged where ``bridged``.
    bridged : ndarray of bool, shape (N,)
        Samples whose velocity is interpolated across a dropout.
    depth_m : ndarray, shape (N,)
        Depth of the reference point from pressure, metres, positive down.
    dvl_lever_arm_body_m : ndarray, shape (3,)
        The DVL relative to the reference point, metres, body FRD.
    dropouts : Dropouts
    declination_rad : float
        Declination added to the compass heading (0 for a true-north heading).
    declination_source : str
        Where it came from: ``"dive.yaml"``, the geomagnetic model's name, or ``"none"``.
    fixes : tuple of PositionFixes
        GPS then USBL, those the dive has.
    """

    t_s: FloatArray
    yaw_rad: FloatArray
    pitch_rad: FloatArray
    roll_rad: FloatArray
    compass_heading_rad: FloatArray
    v_body_mps: FloatArray
    bridged: NDArray[np.bool_]
    depth_m: FloatArray
    dvl_lever_arm_body_m: FloatArray
    dropouts: Dropouts
    declination_rad: float
    declination_source: str
    fixes: tuple[PositionFixes, ...] = ()

    def __post_init__(self) -> None:
        n = np.shape(self.t_s)
        if len(n) != 1 or n[0] < 2:
            raise ValueError(f"t_s must be 1-D with at least 2 samples; found shape {n}")
        for name in ("yaw_rad", "pitch_rad", "roll_rad", "compass_heading_rad", "bridged", "depth_m"):
            if np.shape(getattr(self, name)) != n:
                raise ValueError(f"{name} must have shape {n}; found {np.shape(getattr(self, name))}")
        if np.shape(self.v_body_mps) != (*n, 3):
            raise ValueError(f"v_body_mps must have shape ({n[0]}, 3); found {np.shape(self.v_body_mps)}")
        if not np.all(np.diff(self.t_s) > 0):
            raise ValueError("t_s must be strictly increasing")

    def __len__(self) -> int:
        return len(self.t_s)

    @functools.cached_property
    def R_ned_body(self) -> FloatArray:
        """Body attitude, shape (N, 3, 3) (computed once)."""
        return euler2rot(self.yaw_rad, self.pitch_rad, self.roll_rad)

    def dvl_displacement_ned_m(self) -> FloatArray:
        """Cumulative displacement of the DVL point from the first sample, shape (N, 3), metres, NED.

        The trapezoidal integral of ``R_ned_body @ v_body_mps``.
        """
        v_ned = np.einsum("nij,nj->ni", self.R_ned_body, self.v_body_mps)
        steps = 0.5 * (v_ned[1:] + v_ned[:-1]) * np.diff(self.t_s)[:, None]
        return np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])

    def lever_arm_ned_m(self) -> FloatArray:
        """The DVL's lever arm in NED, ``R_ned_body @ r``, shape (N, 3), metres."""
        return self.R_ned_body @ self.dvl_lever_arm_body_m

    def displacement_ned_m(self) -> FloatArray:
        """Cumulative displacement of the reference point from the first sample, shape (N, 3), metres.

        The DVL point's displacement less the change of its lever arm in NED.
        """
        lever = self.lever_arm_ned_m()
        return self.dvl_displacement_ned_m() - (lever - lever[0])

    def R_ned_body_at(self, t_s: ArrayLike) -> FloatArray:
        """Body attitude interpolated at other times inside the time base, shape (M, 3, 3)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        return euler2rot(
            _interp_angle(t, self.t_s, self.yaw_rad),
            np.interp(t, self.t_s, self.pitch_rad),
            _interp_angle(t, self.t_s, self.roll_rad),
        )


def interp_rows(t_new: FloatArray, t_s: FloatArray, values: FloatArray) -> FloatArray:
    """Linear interpolation in time of an array of any shape (N, ...) at ``t_new``; shape (M, ...)."""
    flat = values.reshape(len(t_s), -1)
    out = np.empty((len(t_new), flat.shape[1]))
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(t_new, t_s, flat[:, k])
    return out.reshape(len(t_new), *values.shape[1:])


def declination(dive: Dive) -> tuple[float, str]:
    """The declination to add to the dive's compass heading, radians, and where it came from.

    A true-north heading needs none; a number in dive.yaml is used as given; ``auto`` evaluates the
    geomagnetic model (:func:`auvnav.compass.field.earth_field`) at the origin and the dive's start.
    """
    if dive.info.heading_reference == "true":
        return 0.0, "none"
    if dive.info.declination_rad is not None:
        return float(dive.info.declination_rad), "dive.yaml"
    origin = dive.info.origin
    field = earth_field(origin.latitude_rad, origin.longitude_rad, dive.info.start_time_s)
    return float(field.declination_rad), field.model


def _time_base(t_dvl: FloatArray, t0: float, t1: float) -> tuple[FloatArray, NDArray[np.intp]]:
    """The DVL times inside [t0, t1] with holes filled; also, per time, its DVL row or -1."""
    rows = np.flatnonzero((t_dvl >= t0) & (t_dvl <= t1))
    t = t_dvl[rows]
    dt = np.diff(t)
    period = float(np.median(dt))
    fills = [
        np.linspace(t[i], t[i + 1], round(dt[i] / period) + 1)[1:-1]
        for i in np.flatnonzero(dt > DVL_HOLE_PERIODS * period)
    ]
    if not fills:
        return t, rows
    t_all = np.concatenate([t, *fills])
    rows_all = np.concatenate([rows, np.full(len(t_all) - len(t), -1)])
    order = np.argsort(t_all, kind="stable")
    return t_all[order], rows_all[order]


def _find_dropouts(t_s: FloatArray, bridged: NDArray[np.bool_]) -> Dropouts:
    """Runs of bridged samples, each timed from the last valid sample to the next one."""
    edges = np.diff(np.concatenate([[0], bridged.astype(np.int8), [0]]))
    first, after = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # run = [first, after)
    start = t_s[np.maximum(first - 1, 0)]
    end = t_s[np.minimum(after, len(t_s) - 1)]
    return Dropouts(start_s=start, duration_s=end - start)


def _interp_angle(t_s: FloatArray, t_src: FloatArray, a_rad: FloatArray) -> FloatArray:
    return wrap_angle(np.interp(t_s, t_src, np.unwrap(a_rad)))


def smooth_tilt(t_s: FloatArray, angle_rad: FloatArray, window_s: float = TILT_SMOOTHING_S) -> FloatArray:
    """Pitch or roll records (one per column of ``angle_rad``, or one record) smoothed along time by a
    local quadratic over ``window_s`` (Savitzky and Golay 1964, "Smoothing and differentiation of data
    by simplified least squares procedures", Anal. Chem. 36(8)), run over each stretch without a gap
    (:func:`auvnav.streams.find_gaps`); stretches shorter than the window, and records too coarse for
    it (fewer than 5 samples a window), are kept as they are. A quadratic over a second or two follows
    a vehicle's pitching and rolling and averages the white noise of a cheap tilt sensor; an attitude
    already filtered is left nearly as it was."""
    out = np.unwrap(np.asarray(angle_rad, dtype=float), axis=0)
    if len(t_s) < 5:
        return wrap_angle(out)
    gaps, period = find_gaps(t_s)
    n = round(window_s / period) // 2 * 2 + 1
    if n < 5:
        return wrap_angle(out)
    edges = np.concatenate([[0], gaps + 1, [len(t_s)]])
    for a, b in itertools.pairwise(edges.tolist()):
        if b - a >= n:
            out[a:b] = savgol_filter(out[a:b], n, 2, axis=0)
    return wrap_angle(out)


def _bridge(
    t_s: FloatArray,
    good: NDArray[np.bool_],
    yaw_rad: FloatArray,
    R_ned_body: FloatArray,
    v_body_mps: FloatArray,
) -> FloatArray:
    """Body velocities at the samples that are not ``good``, interpolated in the level frame.

    The valid velocities are expressed in the level frame (forward and right along the heading, and
    down); each dropout's edge velocity is their mean over the :data:`BRIDGE_WINDOW_S` of valid
    samples next to it, interpolated linearly across the dropout (held before the first valid sample
    and after the last), and turned back into the body frame with the attitude of each bridged sample.
    A vehicle turning through a dropout keeps its speed along its heading; pitch changes (a descent,
    the surface) do not turn a vertical velocity into a horizontal one; and one ping's white noise is
    not carried across the whole dropout.
    """
    at = ~good
    if not at.any():
        return np.zeros((0, 3))
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    v_ned = np.einsum("nij,nj->ni", R_ned_body[good], v_body_mps[good])
    level = np.column_stack(
        [
            c[good] * v_ned[:, 0] + s[good] * v_ned[:, 1],
            -s[good] * v_ned[:, 0] + c[good] * v_ned[:, 1],
            v_ned[:, 2],
        ]
    )
    t_good = t_s[good]
    # The valid samples on either side of each dropout: the window's mean at both edges.
    edges = np.flatnonzero(np.diff(good.astype(np.int8)) != 0)
    before = good[edges] & ~good[edges + 1]
    anchor_t = t_s[np.where(before, edges, edges + 1)]
    lo = np.searchsorted(t_good, np.where(before, anchor_t - BRIDGE_WINDOW_S, anchor_t), side="left")
    hi = np.searchsorted(t_good, np.where(before, anchor_t, anchor_t + BRIDGE_WINDOW_S), side="right")
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(level, axis=0)])
    edge_level = (cum[hi] - cum[lo]) / (hi - lo)[:, None]
    f, r, d = (np.interp(t_s[at], anchor_t, edge_level[:, k]) for k in range(3))
    bridged_ned = np.column_stack([c[at] * f - s[at] * r, s[at] * f + c[at] * r, d])
    return np.einsum("nji,nj->ni", R_ned_body[at], bridged_ned)


def position_fixes(dive: Dive, t0_s: float, t1_s: float) -> tuple[PositionFixes, ...]:
    """The dive's GPS and USBL fixes in [t0_s, t1_s], local NED about its origin (GPS at the surface).

    Fixes outside the span cannot be placed on the track; they are counted in a warning.
    """
    name = dive.path.name if dive.path is not None else dive.info.name
    origin = dive.info.origin
    found: list[tuple[Literal["gps", "usbl"], FloatArray, FloatArray, FloatArray, FloatArray]] = []
    if dive.gps is not None:
        g = dive.gps
        p = geodetic2ned(g.latitude_rad, g.longitude_rad, np.zeros_like(g.t_s), origin)
        found.append(("gps", g.t_s, p, g.sigma_m, dive.vehicle.gps.lever_arm_body_m))
    if dive.usbl is not None:
        u = dive.usbl
        p = geodetic2ned(u.latitude_rad, u.longitude_rad, -u.depth_m, origin)
        found.append(("usbl", u.t_s, p, u.sigma_m, np.zeros(3)))
    fixes = []
    for sensor, t, p, sigma, lever in found:
        inside = (t >= t0_s) & (t <= t1_s)
        if not np.all(inside):
            log.warning(
                "%s/nav/%s: %d of %d fixes lie outside the navigated span (DVL and attitude), not used",
                name,
                sensor,
                np.count_nonzero(~inside),
                len(t),
            )
        if np.any(inside):
            fixes.append(PositionFixes(sensor, t[inside], p[inside], sigma[inside], np.asarray(lever, float)))
    return tuple(fixes)


def nav_inputs(dive: Dive, correction: HeadingCorrection | None = None) -> NavInputs:
    """Bring a dive's sensors onto the navigation time base (see the module docstring).

    Parameters
    ----------
    dive : Dive
    correction : HeadingCorrection, optional
        Compass correction applied to the logged heading before the declination (paper eq. 5).

    Raises
    ------
    InsufficientDataError
        The DVL and attitude logs do not overlap, or no DVL sample is valid.
    """
    name = dive.path.name if dive.path is not None else dive.info.name
    att, dvl = dive.attitude, dive.dvl
    t0, t1 = max(att.t_s[0], dvl.t_s[0]), min(att.t_s[-1], dvl.t_s[-1])
    if np.count_nonzero((dvl.t_s >= t0) & (dvl.t_s <= t1)) < 2:
        raise InsufficientDataError(f"{name}: nav/dvl and nav/attitude do not overlap in time")
    if not np.any(dvl.valid):
        raise InsufficientDataError(f"{name}/nav/dvl: no sample is marked valid (no bottom lock)")
    t, row = _time_base(dvl.t_s, t0, t1)

    # Attitude: the compass heading, corrected (eq. 5), to true north, then the compass mount removed.
    t_att = att.t_s[(att.t_s >= t0) & (att.t_s <= t1)]
    gaps, period = find_gaps(t_att)
    if gaps.size:
        log.warning(
            "%s/nav/attitude: %d gap(s) longer than %g median periods (%.3g s), the longest %.1f s; "
            "the attitude is interpolated",
            name,
            gaps.size,
            GAP_PERIODS,
            GAP_PERIODS * period,
            np.diff(t_att).max(),
        )
    compass_heading = _interp_angle(t, att.t_s, att.heading_rad)
    heading = compass_heading if correction is None else correction.correct(compass_heading)
    decl, decl_source = declination(dive)
    pitch, roll = smooth_tilt(att.t_s, np.column_stack([att.pitch_rad, att.roll_rad])).T
    R_ned_compass = euler2rot(
        magnetic2true(heading, decl), np.interp(t, att.t_s, pitch), _interp_angle(t, att.t_s, roll)
    )
    yaw, pitch, roll = rot2euler(R_ned_compass @ dive.vehicle.compass.R_body_sensor.T)
    R_ned_body = euler2rot(yaw, pitch, roll)

    # DVL velocity in the body frame, bridged across invalid and missing samples.
    good = row >= 0
    good[good] = dvl.valid[row[good]]
    v_body = np.zeros((len(t), 3))
    v_body[good] = dvl.v_sensor_mps[row[good]] @ dive.vehicle.dvl.R_body_sensor.T
    v_body[~good] = _bridge(t, good, yaw, R_ned_body, v_body)
    dropouts = _find_dropouts(t, ~good)
    if dropouts.count:
        log.warning(
            "%s/nav/dvl: bridged %d dropout(s) of bottom-track velocity (invalid or missing), "
            "%.1f s in all, the longest %.1f s",
            name,
            dropouts.count,
            dropouts.total_s,
            dropouts.longest_s,
        )

    # Depth of the reference point from pressure (TEOS-10), less the sensor's lever arm.
    pr = dive.pressure
    if pr.t_s[0] > t[0] or pr.t_s[-1] < t[-1]:
        log.warning(
            "%s/nav/pressure: starts %.1f s after or ends %.1f s before the DVL; depth is held there",
            name,
            max(pr.t_s[0] - t[0], 0.0),
            max(t[-1] - pr.t_s[-1], 0.0),
        )
    sea = sea_pressure(
        pr.pressure_pa, pr.t_s, pressure_type=dive.info.pressure_type, atmospheric_pa=dive.info.atmospheric_pa
    )
    sensor_depth = np.interp(t, pr.t_s, depth_from_pressure(sea, dive.info.origin.latitude_rad))
    depth = sensor_depth - (R_ned_body @ dive.vehicle.pressure.lever_arm_body_m)[:, 2]

    return NavInputs(
        t_s=t,
        yaw_rad=yaw,
        pitch_rad=pitch,
        roll_rad=roll,
        compass_heading_rad=compass_heading,
        v_body_mps=v_body,
        bridged=~good,
        depth_m=depth,
        dvl_lever_arm_body_m=np.asarray(dive.vehicle.dvl.lever_arm_body_m, dtype=float),
        dropouts=dropouts,
        declination_rad=decl,
        declination_source=decl_source,
        fixes=position_fixes(dive, float(t[0]), float(t[-1])),
    )
