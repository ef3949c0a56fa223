"""Small synthetic dives with an exact truth, for the navigation tests and benchmark.

The vehicle flies level at constant depth and speed along straight legs joined by smooth turns, its
position integrated from the analytic heading far more finely than any error studied, so every sensor
can be written from the truth exactly: DVL velocity at the DVL (``v + omega x r``, then into the DVL frame), compass
heading of the compass frame (declination removed, an optional constant compass error added),
absolute pressure at the pressure sensor (TEOS-10), GPS at the antenna. Optional white noise and a DVL
scale error make the filter's job realistic. This is not the simulator (:mod:`auvnav.sim`): no
guidance, no seafloor, no camera.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_simpson

from auvnav.depth.pressure import pressure_from_depth
from auvnav.dive import AttitudeStream, Dive, DiveInfo, DvlStream, GpsStream, PressureStream, UsblStream
from auvnav.frames import FloatArray, GeodeticOrigin, ned2geodetic, rot2euler, wrap_angle
from auvnav.trajectory import Trajectory
from auvnav.vehicle import Vehicle

#: Scott Reef, Western Australia (the paper's site), and a date in its campaign.
SCOTT_REEF = GeodeticOrigin.from_degrees(-14.05, 121.85)
START_TIME_S = dt.datetime(2009, 10, 10, 0, 0, tzinfo=dt.timezone.utc).timestamp()
ATMOSPHERIC_PA = 101325.0


@dataclass(frozen=True)
class Motion:
    """A synthetic truth and the body-frame motion that produced it.

    Parameters
    ----------
    truth : Trajectory
        Reference-point poses.
    v_body_mps : ndarray, shape (N, 3)
        Velocity of the reference point over the seafloor, body FRD.
    omega_body_rps : ndarray, shape (N, 3)
        Angular rate, body FRD, rad/s.
    """

    truth: Trajectory
    v_body_mps: FloatArray
    omega_body_rps: FloatArray


def legs_motion(
    legs: Sequence[tuple[float, float]],
    *,
    speed_mps: float = 0.5,
    turn_rate_rps: float = 0.05,
    rate_hz: float = 10.0,
    depth_m: float = 20.0,
    t0_s: float = START_TIME_S,
    oversample: int = 10,
) -> Motion:
    """Straight legs joined by smooth turns.

    A turn through ``dpsi`` has the yaw rate ``r_peak sin^2(pi tau / T)`` with ``T = 2 |dpsi| / r_peak``,
    so the rate (and the velocity of a point off the reference point) is continuous. Positions are
    integrated from the analytic heading by Simpson's rule on a grid ``oversample`` times finer than
    the samples (error of order ``(dt / oversample)^4``, far below a micrometre).

    Parameters
    ----------
    legs : sequence of (heading_rad, length_m)
        Each leg's heading (true, from north) and length; the vehicle turns the short way onto each.
    speed_mps : float
    turn_rate_rps : float
        Peak yaw rate of the turns, rad/s.
    rate_hz : float
        Sample rate.
    depth_m : float
    t0_s : float
        POSIX time of the first sample.
    oversample : int
        Integration grid per sample interval.
    """
    # Segments: (start time, duration, heading at start, heading change); a zero change is a leg.
    segments: list[tuple[float, float, float, float]] = []
    heading, t_seg = legs[0][0], 0.0
    for target, length in legs:
        turn = float(wrap_angle(target - heading))
        if abs(turn) > 1e-12:
            duration = 2.0 * abs(turn) / turn_rate_rps
            segments.append((t_seg, duration, heading, turn))
            t_seg += duration
        segments.append((t_seg, length / speed_mps, target, 0.0))
        t_seg += length / speed_mps
        heading = target
    n = int(t_seg * rate_hz)
    tf = np.arange(n * oversample - oversample + 1) / (rate_hz * oversample)
    start, duration, psi0, turn = (np.array(column) for column in zip(*segments, strict=True))
    k = np.clip(np.searchsorted(start, tf, side="right") - 1, 0, len(segments) - 1)
    tau, T, peak = tf - start[k], duration[k], 2.0 * turn[k] / duration[k]
    yaw = psi0[k] + peak * (tau / 2.0 - T * np.sin(2.0 * np.pi * tau / T) / (4.0 * np.pi))
    rate = peak * np.sin(np.pi * tau / T) ** 2
    north = cumulative_simpson(speed_mps * np.cos(yaw), x=tf, initial=0.0)
    east = cumulative_simpson(speed_mps * np.sin(yaw), x=tf, initial=0.0)
    pick = slice(None, None, oversample)
    zeros = np.zeros(n)
    truth = Trajectory(
        t_s=t0_s + tf[pick],
        p_ned_m=np.column_stack([north[pick], east[pick], np.full(n, depth_m)]),
        roll_rad=zeros,
        pitch_rad=zeros,
        yaw_rad=wrap_angle(yaw[pick]),
    )
    v_body = np.column_stack([np.full(n, speed_mps), zeros, zeros])
    return Motion(truth, v_body, np.column_stack([zeros, zeros, rate[pick]]))


def lawnmower_legs(lines: int, line_m: float, spacing_m: float) -> list[tuple[float, float]]:
    """Legs of a survey: ``lines`` lines of ``line_m`` north and south, ``spacing_m`` apart eastward."""
    legs: list[tuple[float, float]] = []
    for i in range(lines):
        legs.append((0.0 if i % 2 == 0 else math.pi, line_m))
        if i < lines - 1:
            legs.append((math.pi / 2, spacing_m))
    return legs


@dataclass(frozen=True)
class Noise:
    """White sensor noise and biases of a synthetic dive (1-sigma, SI).

    Parameters
    ----------
    dvl_velocity_sigma_mps, heading_sigma_rad, pressure_sigma_pa, gps_sigma_m : float
        White noise per sample.
    dvl_scale_error : float
        DVL scale error applied to every sample.
    seed : int
    """

    dvl_velocity_sigma_mps: float = 0.003
    heading_sigma_rad: float = math.radians(0.1)
    pressure_sigma_pa: float = 100.0
    gps_sigma_m: float = 3.0
    dvl_scale_error: float = 0.0
    seed: int = 0


def synthetic_dive(
    motion: Motion,
    *,
    vehicle: Vehicle | None = None,
    origin: GeodeticOrigin = SCOTT_REEF,
    declination_rad: float = math.radians(1.0),
    compass_error_rad: float | Callable[[FloatArray], FloatArray] = 0.0,
    gps_times_s: FloatArray | None = None,
    usbl_times_s: FloatArray | None = None,
    dvl_valid: FloatArray | None = None,
    noise: Noise | None = None,
    name: str = "synthetic",
) -> Dive:
    """The sensor streams a vehicle on ``motion`` would log.

    Parameters
    ----------
    motion : Motion
    vehicle : Vehicle, optional
        Mounts and lever arms of DVL, compass, pressure sensor and GPS antenna (default: all at the
        reference point, aligned with the body).
    origin : GeodeticOrigin
    declination_rad : float
        Written to dive.yaml; the compass reads magnetic heading.
    compass_error_rad : float or callable
        Error added to the compass heading: a constant (so a correction of ``-compass_error_rad``
        undoes it), or a function of the true magnetic heading (radians to radians), a deviation.
    gps_times_s : ndarray, optional
        Times of GPS fixes (inside the truth's span); none by default. With ``noise``, white noise of
        ``noise.gps_sigma_m`` per horizontal axis.
    usbl_times_s : ndarray, optional
        Times of USBL fixes; none by default. With ``noise``, white noise of ``vehicle.usbl_sigma_m``.
    dvl_valid : ndarray of bool, shape (N,), optional
        The DVL's valid flags; all valid by default.
    noise : Noise, optional
        White noise; exact streams by default.
    name : str
    """
    vehicle = vehicle or Vehicle()
    truth = motion.truth
    t, n = truth.t_s, len(truth.t_s)
    model = noise or Noise()
    rng = np.random.default_rng(model.seed)
    R = truth.R_ned_body

    def white(sigma: float, shape: tuple[int, ...]) -> FloatArray:
        return rng.normal(0.0, sigma, shape) if noise else np.zeros(shape)

    dvl = vehicle.dvl
    v_dvl_body = motion.v_body_mps + np.cross(motion.omega_body_rps, dvl.lever_arm_body_m)
    scale = 1.0 + (noise.dvl_scale_error if noise else 0.0)
    v_sensor = scale * v_dvl_body @ dvl.R_body_sensor + white(model.dvl_velocity_sigma_mps, (n, 3))

    yaw_c, pitch_c, roll_c = rot2euler(R @ vehicle.compass.R_body_sensor)
    magnetic = wrap_angle(yaw_c - declination_rad)
    error = compass_error_rad(magnetic) if callable(compass_error_rad) else compass_error_rad
    heading = wrap_angle(magnetic + error + white(model.heading_sigma_rad, (n,)))

    sensor_depth = truth.p_ned_m[:, 2] + (R @ vehicle.pressure.lever_arm_body_m)[:, 2]
    pressure = pressure_from_depth(sensor_depth, origin.latitude_rad) + ATMOSPHERIC_PA
    pressure = pressure + white(model.pressure_sigma_pa, (n,))

    def fixes(times: FloatArray, lever_arm_body_m: FloatArray, sigma_m: float) -> tuple[FloatArray, ...]:
        """Times, latitude, longitude, depth of fixes with horizontal noise of ``sigma_m``."""
        at = truth.interpolate(np.asarray(times, dtype=float))
        p = at.p_ned_m + at.R_ned_body @ lever_arm_body_m
        p[:, :2] += white(sigma_m, (len(at.t_s), 2))
        lat, lon, _ = ned2geodetic(np.column_stack([p[:, :2], np.zeros(len(at.t_s))]), origin)
        # ned2geodetic gives a scalar latitude for a single row.
        return at.t_s, np.reshape(lat, -1), np.reshape(lon, -1), p[:, 2]

    gps = usbl = None
    if gps_times_s is not None and len(gps_times_s):
        sigma = model.gps_sigma_m if noise else vehicle.gps_sigma_m
        t_fix, lat, lon, _ = fixes(gps_times_s, vehicle.gps.lever_arm_body_m, sigma)
        gps = GpsStream(t_s=t_fix, latitude_rad=lat, longitude_rad=lon, sigma_m=np.full(len(t_fix), sigma))
    if usbl_times_s is not None and len(usbl_times_s):
        sigma = vehicle.usbl_sigma_m
        t_fix, lat, lon, depth = fixes(usbl_times_s, np.zeros(3), sigma)
        usbl = UsblStream(
            t_s=t_fix, latitude_rad=lat, longitude_rad=lon, depth_m=depth, sigma_m=np.full(len(t_fix), sigma)
        )

    info = DiveInfo(
        name=name,
        origin=origin,
        start_time_s=float(t[0]),
        declination_rad=declination_rad,
        atmospheric_pa=ATMOSPHERIC_PA,
    )
    valid = np.ones(n, dtype=bool) if dvl_valid is None else np.asarray(dvl_valid, dtype=bool)
    return Dive(
        info=info,
        vehicle=vehicle,
        dvl=DvlStream(t_s=t, v_sensor_mps=v_sensor, altitude_m=np.full(n, 2.0), valid=valid),
        attitude=AttitudeStream(t_s=t, heading_rad=heading, pitch_rad=pitch_c, roll_rad=roll_c),
        pressure=PressureStream(t_s=t, pressure_pa=pressure),
        gps=gps,
        usbl=usbl,
    )


__all__ = ["Motion", "Noise", "lawnmower_legs", "legs_motion", "synthetic_dive"]
