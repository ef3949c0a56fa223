"""The simulated vehicle: dynamics, guidance on its own onboard navigation, and the sensors in the loop.

The vehicle is a kinematic model with first-order responses, in the class of ACFR's Sirius
(Williams et al. 2012, IEEE RAM 19(1): about 0.5 m/s, 2 m altitude, passively stable in pitch and
roll, thrusters for hovering and turning on the spot):

- speed, yaw rate and vertical rate follow their commands with first-order lags; the yaw rate is
  limited (10 deg/s) and so are the descent and ascent rates (0.3 m/s);
- pitch and roll are small and not zero: trim, pitch proportional to the vertical rate, roll
  proportional to the centripetal acceleration of a turn, each plus coloured (first-order
  Gauss-Markov) noise of about half a degree; a passively stable vehicle sits at a degree or two;
- the altitude loop follows the seafloor at the commanded altitude with the DVL's altitude and the
  bottom slope along the track (what a DVL's four beams see) as feed-forward;
- at the surface the vehicle floats at its draft below the instantaneous sea level (datum + tide).

**Guidance closes on the onboard navigation, never on the truth.** The onboard heading is the
compass heading (:mod:`auvnav.sim.sensors`: eq. 2 and eq. 1 on the true attitude, with noise),
plus the compass correction when one is given, plus the declination; the onboard position is dead
reckoning of the measured DVL velocity rotated by the onboard heading and the measured pitch and
roll, reset to the mean GPS fix at the end of every surface wait. A line-following law steers the
onboard position onto each leg (course = leg bearing - atan(cross-track error / lookahead)), a
heading autopilot turns the onboard heading onto that course, and the vehicle slows in sharp turns.
A compass deviation therefore bends the true track while the onboard track stays on the plan: the
paper's 'accordion' and 'figure 8' (Fig. 2) emerge from the loop.

Everything steps at ``dt_s`` (0.1 s) in plain ``math`` for speed. One step of :func:`fly`: the true
vehicle's attitude (``_TrueVehicle``); the sensors measure the true vehicle (``_Instruments``); the
onboard navigation takes their measurements (``_Onboard``); guidance moves through the mission's
segments and commands speed, yaw rate and vertical rate from the onboard state alone
(``_Guidance``); the onboard position is dead reckoned and the true vehicle integrated to the next
step. The result is a :class:`LoopRecord` of arrays that :mod:`auvnav.sim.run` turns into a dive
folder.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray
from auvnav.plan.missions import Ascend, Descend, Line, Mission, Segment, Spin, Surface
from auvnav.sim.seafloor import Seafloor
from auvnav.sim.sensors import (
    SensorModels,
    body2ned,
    compass_heading,
    distort,
    ned2body,
    quantise,
)

log = logging.getLogger(__name__)

DEG = math.pi / 180.0
TWO_PI = 2.0 * math.pi
_NOISE_BLOCK = 8192  # rows of standard normal draws per refill
#: Columns of a step's draws: 0-2 magnetometer xyz, 3-4 inclinometer pitch and roll, 5-6 attitude
#: process pitch and roll, 7-9 DVL velocity xyz, 10 DVL altitude, 11-12 GPS north and east.
_NOISE_COLUMNS = 13


@dataclass(frozen=True)
class VehicleDynamics:
    """Dynamics, autopilot and guidance constants (SI units, radians).

    The values are modelling choices for a slow, passively stable survey AUV of Sirius's class.
    """

    speed_tau_s: float = 2.0
    yaw_rate_tau_s: float = 1.0
    yaw_rate_max_rad_s: float = 10.0 * DEG
    heading_gain_per_s: float = 1.0
    lookahead_m: float = 1.5
    min_speed_fraction: float = 0.1  # of the nominal speed, in turns of 90 degrees or more
    vertical_tau_s: float = 2.0
    vertical_rate_max_mps: float = 0.3
    altitude_gain_per_s: float = 0.4
    altitude_tolerance_m: float = 0.2  # a descent ends within this of the commanded altitude
    lost_bottom_climb_mps: float = 0.1  # climb while bottom lock is lost close to the seafloor
    bottom_clearance_m: float = 0.1  # the hull touches the seafloor at this altitude of the DVL
    turn_anticipation_m: float = 1.5  # the next leg starts this far before a leg's end
    waypoint_capture_m: float = 3.0  # a line starts with a leg to its first point beyond this
    draft_m: float = 0.3  # depth of the reference point when floating
    pitch_trim_rad: float = 1.0 * DEG
    pitch_rad_per_mps: float = -6.0 * DEG  # per m/s of descent: nose down when descending
    roll_trim_rad: float = 0.5 * DEG
    roll_rad_per_mps2: float = -20.0 * DEG  # per m/s^2 of centripetal acceleration: heels outward
    attitude_noise_rad: float = 0.5 * DEG  # 1-sigma of the coloured pitch and roll motion
    attitude_noise_tau_s: float = 8.0


@dataclass(frozen=True)
class PerDiveErrors:
    """Sensor errors drawn once per dive.

    Parameters
    ----------
    dvl_scale : float
        Measured = (1 + scale) x true velocity.
    R_sensor_body_dvl : ndarray, shape (3, 3)
        The DVL's true mounting: body vectors into the DVL frame (nominal mount with misalignment).
    R_body_sensor_dvl_nominal : ndarray, shape (3, 3)
        The mounting the vehicle believes (``vehicle.yaml``).
    """

    dvl_scale: float
    R_sensor_body_dvl: FloatArray
    R_body_sensor_dvl_nominal: FloatArray


@dataclass(frozen=True)
class LoopRecord:
    """What the closed loop produced, as arrays (SI, radians, local NED).

    Step arrays (``t_s``, shape (N,)): true pose, onboard pose, measured attitude and magnetometer,
    and ``at_surface``. DVL arrays at the DVL rate; GPS fixes (NED of the antenna plus noise).
    ``surfacing`` rows are ``(t_s, onboard - true north, onboard - true east)`` each time the
    vehicle reaches the surface.
    """

    t_s: FloatArray
    p_ned_m: FloatArray
    yaw_rad: FloatArray
    pitch_rad: FloatArray
    roll_rad: FloatArray
    onboard_ne_m: FloatArray
    onboard_yaw_rad: FloatArray
    compass_heading_rad: FloatArray
    pitch_measured_rad: FloatArray
    roll_measured_rad: FloatArray
    magnetometer_T: FloatArray
    at_surface: NDArray[np.bool_]
    dvl_t_s: FloatArray
    dvl_v_sensor_mps: FloatArray
    dvl_altitude_m: FloatArray
    dvl_valid: NDArray[np.bool_]
    gps_t_s: FloatArray
    gps_ne_m: FloatArray
    surfacing: FloatArray
    completed: bool


def _normal_rows(rng: np.random.Generator) -> Iterator[list[float]]:
    """Standard normal draws, one row of :data:`_NOISE_COLUMNS` per step, drawn in blocks (deterministic
    for a seed)."""
    while True:
        yield from rng.standard_normal((_NOISE_BLOCK, _NOISE_COLUMNS)).tolist()


class Table:
    """Linear interpolation of a function sampled on a regular grid (plain floats, for the loop)."""

    def __init__(self, x0: float, step: float, values: NDArray[np.float64]) -> None:
        self.x0, self.step = x0, step
        self.values = [float(v) for v in values]
        self.last = len(self.values) - 2

    def __call__(self, x: float) -> float:
        u = (x - self.x0) / self.step
        i = min(max(int(u), 0), self.last)
        f = u - i
        return self.values[i] * (1.0 - f) + self.values[i + 1] * f


def _wrap(a: float) -> float:
    return math.pi - (math.pi - a) % TWO_PI


def _clamp(x: float, limit: float) -> float:
    return limit if x > limit else -limit if x < -limit else x


def _legs(
    waypoints: tuple[tuple[float, float], ...], start: tuple[float, float], capture_m: float
) -> list[tuple[float, float, float, float, float]]:
    """Legs ``(a_n, a_e, unit_n, unit_e, length)``; first a leg from ``start`` when it is far from the line."""
    points = list(waypoints)
    if math.dist(start, points[0]) > capture_m or len(points) == 1:
        points.insert(0, start)
    legs = []
    for (an, ae), (bn, be) in itertools.pairwise(points):
        length = math.hypot(bn - an, be - ae)
        if length > 1e-9:
            legs.append((an, ae, (bn - an) / length, (be - ae) / length, length))
    return legs


def initial_heading(mission: Mission) -> float:
    """The bearing of the mission's first leg (the vehicle is launched pointing along it), radians."""
    for s in mission.segments:
        if isinstance(s, Line):
            legs = _legs(s.waypoints_ne_m, (0.0, 0.0), 0.0)
            if legs:
                return math.atan2(legs[0][3], legs[0][2])
    return 0.0


# ---------------------------------------------------------------------------------------------
# The true vehicle
# ---------------------------------------------------------------------------------------------


class _TrueVehicle:
    """The true vehicle (guidance never reads it): its state and its integration from step to step.

    State (SI, radians, local NED): position ``n, e, d``, heading ``psi``, yaw rate ``r``, speed
    ``u``, vertical rate ``w`` (down), this step's pitch ``theta``, roll ``phi`` and velocity over
    ground ``vn, ve``; ``at_surface``; ``floor_d``, the seafloor depth below the vehicle at the last
    DVL ping (what stops the hull). Every step is logged (``t_s``, ``pose``, ``surface``).
    """

    def __init__(
        self,
        dynamics: VehicleDynamics,
        *,
        dt_s: float,
        psi_rad: float,
        d_m: float,
        eta: Table,
        dvl_lever_down_m: float,
    ) -> None:
        dyn = self.dyn = dynamics
        self.dt, self.eta, self.lz = dt_s, eta, dvl_lever_down_m
        self.ga = math.exp(-dt_s / dyn.attitude_noise_tau_s)  # attitude noise: first-order Gauss-Markov
        self.gb = dyn.attitude_noise_rad * math.sqrt(1.0 - self.ga * self.ga)
        self.k_speed = dt_s / dyn.speed_tau_s
        self.k_yaw = dt_s / dyn.yaw_rate_tau_s
        self.k_vert = dt_s / dyn.vertical_tau_s
        self.r_max = dyn.yaw_rate_max_rad_s
        self.n = self.e = 0.0
        self.d = d_m
        self.psi = psi_rad
        self.r = self.u = self.w = 0.0
        self.x_pitch = self.x_roll = 0.0
        self.theta = self.phi = self.vn = self.ve = 0.0
        self.at_surface = True
        self.floor_d = math.inf
        self.bottom_contacts = 0
        self.t_s: list[float] = []
        self.pose: list[tuple[float, float, float, float, float, float]] = []
        self.surface: list[bool] = []

    def start_step(self, z: list[float]) -> None:
        """This step's attitude (passively stable: small, not zero) and velocity over ground."""
        dyn, u = self.dyn, self.u
        self.x_pitch = x_pitch = self.ga * self.x_pitch + self.gb * z[5]
        self.x_roll = x_roll = self.ga * self.x_roll + self.gb * z[6]
        self.theta = dyn.pitch_trim_rad + dyn.pitch_rad_per_mps * self.w + x_pitch
        self.phi = dyn.roll_trim_rad + dyn.roll_rad_per_mps2 * u * self.r + x_roll
        self.vn, self.ve = u * math.cos(self.psi), u * math.sin(self.psi)

    def advance(self, t_s: float, u_cmd: float, r_cmd: float, w_cmd: float) -> bool:
        """Log step ``t_s``, then integrate to the next under the commands; True when the vehicle
        reaches the surface."""
        dyn, dt, r, w = self.dyn, self.dt, self.r, self.w
        self.t_s.append(t_s)
        self.pose.append((self.n, self.e, self.d, self.psi, self.theta, self.phi))
        self.surface.append(self.at_surface)
        self.n += self.vn * dt
        self.e += self.ve * dt
        self.psi = _wrap(self.psi + r * dt)
        self.r = _clamp(r + (r_cmd - r) * self.k_yaw, self.r_max)
        self.u += (u_cmd - self.u) * self.k_speed
        if self.at_surface and w_cmd > 0.0:  # leave the surface (never in a surface wait: w_cmd = 0)
            self.at_surface = False
        if self.at_surface:  # floating at its draft below the instantaneous sea level
            self.w = 0.0
            self.d = -self.eta(t_s + dt) + dyn.draft_m
            return False
        d = self.d + w * dt
        w += (w_cmd - w) * self.k_vert
        if d + self.lz > self.floor_d - dyn.bottom_clearance_m:  # the seafloor stops the vehicle
            d, w = self.floor_d - dyn.bottom_clearance_m - self.lz, min(w, 0.0)
            self.bottom_contacts += 1
        surface_d = -self.eta(t_s + dt) + dyn.draft_m
        surfaced = d <= surface_d and w < 0.0
        if surfaced:
            d, w, self.at_surface = surface_d, 0.0, True
        self.d, self.w = d, w
        return surfaced


# ---------------------------------------------------------------------------------------------
# Sensors of one step
# ---------------------------------------------------------------------------------------------


class _Instruments:
    """The sensors of one step, measuring the true vehicle with noise (one row of standard normal
    draws ``z`` per step, columns as in :data:`_NOISE_COLUMNS`) and the dive's errors; each logs what
    it measured (``compass_log``, ``dvl_log``, ``gps_log``)."""

    def __init__(
        self,
        sensors: SensorModels,
        errors: PerDiveErrors,
        *,
        dt_s: float,
        seafloor: Seafloor,
        b_ned_T: tuple[float, float, float],
        iron: tuple[float, ...],
        dvl_lever_body_m: tuple[float, float, float],
        gps_lever_body_m: tuple[float, float, float],
    ) -> None:
        self.dvl_every = max(round(1.0 / (sensors.dvl_rate_hz * dt_s)), 1)  # steps between pings
        self.gps_every = max(round(1.0 / (sensors.gps_rate_hz * dt_s)), 1)
        self.seafloor, self.iron = seafloor, iron
        self.bn_T, self.be_T, self.bd_T = b_ned_T
        self.s_mag, self.s_tilt = sensors.magnetometer_sigma_T, sensors.tilt_sigma_rad
        self.res = sensors.heading_resolution_rad
        self.s_dvl, self.s_alt = sensors.dvl_velocity_sigma_mps, sensors.dvl_altitude_sigma_m
        self.alt_min, self.alt_max = sensors.dvl_min_altitude_m, sensors.dvl_max_altitude_m
        self.s_gps = sensors.gps_sigma_m
        self.scale = 1.0 + errors.dvl_scale
        self.M = [float(v) for v in errors.R_sensor_body_dvl.ravel()]
        self.lx, self.ly, self.lz = dvl_lever_body_m
        self.gps_lever = gps_lever_body_m
        self.compass_log: list[tuple[float, float, float, float, float, float]] = []
        self.dvl_log: list[tuple[float, float, float, float, float, float]] = []
        self.gps_log: list[tuple[float, float, float]] = []

    def compass(self, v: _TrueVehicle, z: list[float]) -> tuple[float, float, float]:
        """Magnetometer (eq. 2, noise) and inclinometer: the compass heading (eq. 1 with the measured
        tilt, quantised) and the measured pitch and roll, radians."""
        theta_m = v.theta + self.s_tilt * z[3]
        phi_m = v.phi + self.s_tilt * z[4]
        bx, by, bz = ned2body(v.psi, v.theta, v.phi, self.bn_T, self.be_T, self.bd_T)
        mx, my, mz = distort(self.iron, bx, by, bz)
        mx += self.s_mag * z[0]
        my += self.s_mag * z[1]
        mz += self.s_mag * z[2]
        h_meas = _wrap(quantise(compass_heading(mx, my, mz, theta_m, phi_m), self.res))
        self.compass_log.append((h_meas, theta_m, phi_m, mx, my, mz))
        return h_meas, theta_m, phi_m

    def dvl(
        self, t_s: float, v: _TrueVehicle, z: list[float]
    ) -> tuple[bool, float, float, float, float, float]:
        """One bottom-track ping: ``(valid, vx, vy, vz, altitude_m, slope_rate_mps)``, the velocity in
        the DVL frame (true mounting, scale error), the altitude of the DVL and the rate at which the
        seafloor deepens along the track (what the four beams see); ``valid`` within the DVL's
        altitude range. Also refreshes the true vehicle's ``floor_d``."""
        vn, ve = v.vn, v.ve
        vx, vy, vz = ned2body(v.psi, v.theta, v.phi, vn, ve, v.w)
        vx, vy = vx - v.r * self.ly, vy + v.r * self.lx  # + omega x lever, omega ~ (0, 0, r)
        M, scale, s_dvl = self.M, self.scale, self.s_dvl
        sx = scale * (M[0] * vx + M[1] * vy + M[2] * vz) + s_dvl * z[7]
        sy = scale * (M[3] * vx + M[4] * vy + M[5] * vz) + s_dvl * z[8]
        sz = scale * (M[6] * vx + M[7] * vy + M[8] * vz) + s_dvl * z[9]
        floor_d, gn, ge = self.seafloor.depth_and_gradient(v.n, v.e)
        v.floor_d = floor_d
        alt_true = floor_d - (v.d + self.lz)
        valid = self.alt_min <= alt_true <= self.alt_max
        alt_meas = alt_true + self.s_alt * z[10]
        self.dvl_log.append((t_s, sx, sy, sz, alt_meas, 1.0) if valid else (t_s, 0.0, 0.0, 0.0, 0.0, 0.0))
        return valid, sx, sy, sz, alt_meas, gn * vn + ge * ve

    def gps(self, t_s: float, v: _TrueVehicle, z: list[float]) -> tuple[float, float]:
        """One GPS fix: north and east of the antenna plus noise, metres."""
        an, ae, _ = body2ned(v.psi, v.theta, v.phi, *self.gps_lever)
        fix = (v.n + an + self.s_gps * z[11], v.e + ae + self.s_gps * z[12])
        self.gps_log.append((t_s, *fix))
        return fix


# ---------------------------------------------------------------------------------------------
# The onboard navigation and the guidance on it
# ---------------------------------------------------------------------------------------------


class _Onboard:
    """The vehicle's own navigation, all that guidance sees.

    Heading ``psi`` (compass, correction, declination), measured ``pitch`` and ``roll``, position
    ``pn, pe`` by dead reckoning of the DVL velocity ``v_body`` (the thrust command as speed through
    the water without bottom lock), reset to the mean GPS fix at the end of a surface wait; the DVL's
    altitude ``alt_m``, ``bottom_lock``, ``last_alt_m`` (the last valid altitude) and the seafloor's
    ``slope_rate``. Every step is logged (``log``: north, east, heading).
    """

    def __init__(
        self,
        *,
        declination_rad: float,
        correction: Table | None,
        R_body_sensor_dvl_nominal: FloatArray,
        gps_lever_body_m: tuple[float, float, float],
    ) -> None:
        self.declination_rad, self.correction = declination_rad, correction
        self.N = [float(v) for v in R_body_sensor_dvl_nominal.ravel()]
        self.gps_lever = gps_lever_body_m
        self.pn = self.pe = 0.0
        self.psi = self.pitch = self.roll = 0.0
        self.v_body = (0.0, 0.0, 0.0)
        self.alt_m, self.bottom_lock = 0.0, False
        self.last_alt_m = math.inf  # lock lost close to the bottom means too close
        self.slope_rate = 0.0
        self.fixes: list[tuple[float, float]] = []  # GPS fixes since the mission's segment started
        self.log: list[tuple[float, float, float]] = []

    def compass(self, h_meas: float, pitch_m: float, roll_m: float) -> None:
        """Heading from the compass heading (correction and declination added); measured pitch and roll."""
        h_corr = h_meas + self.correction(h_meas) if self.correction is not None else h_meas
        self.psi = _wrap(h_corr + self.declination_rad)
        self.pitch, self.roll = pitch_m, roll_m

    def dvl(self, ping: tuple[bool, float, float, float, float, float], u_cmd: float) -> None:
        """Take a DVL ping (:meth:`_Instruments.dvl`); ``u_cmd`` is the speed command in force."""
        valid, sx, sy, sz, self.alt_m, self.slope_rate = ping
        self.bottom_lock = valid
        if valid:
            self.last_alt_m = self.alt_m
            N = self.N  # the mounting the vehicle believes
            self.v_body = (
                N[0] * sx + N[1] * sy + N[2] * sz,
                N[3] * sx + N[4] * sy + N[5] * sz,
                N[6] * sx + N[7] * sy + N[8] * sz,
            )
        else:
            self.v_body = (u_cmd, 0.0, 0.0)  # no bottom lock: speed through water from the thrust command

    def new_segment(self, after_surface_wait: bool) -> None:
        """The mission moves on: after a surface wait, reset the position to the mean of its GPS
        fixes (antenna lever arm removed with the onboard attitude); the fixes start anew."""
        fixes = self.fixes
        if after_surface_wait and fixes:
            an, ae, _ = body2ned(self.psi, self.pitch, self.roll, *self.gps_lever)
            self.pn = sum(f[0] for f in fixes) / len(fixes) - an
            self.pe = sum(f[1] for f in fixes) / len(fixes) - ae
        self.fixes = []

    def dead_reckon(self, dt_s: float) -> None:
        """Log this step, then move the position on to the next."""
        self.log.append((self.pn, self.pe, self.psi))
        vn, ve, _ = body2ned(self.psi, self.pitch, self.roll, *self.v_body)
        self.pn += vn * dt_s
        self.pe += ve * dt_s


class _Guidance:
    """Mission segments and the speed, yaw-rate and vertical-rate commands, from the onboard state
    only.

    A line follows its legs (course = leg bearing - atan(cross-track error / lookahead), the next leg
    taken ``turn_anticipation_m`` before a leg's end, slower in sharp turns); a heading autopilot
    turns the onboard heading onto the course; the altitude loop holds the commanded altitude with
    the seafloor's slope as feed-forward. ``done`` marks the current segment finished: the next
    starts at the next step.
    """

    def __init__(self, mission: Mission, dynamics: VehicleDynamics, *, dvl_max_altitude_m: float) -> None:
        self.mission, self.dyn = mission, dynamics
        self.alt_max = dvl_max_altitude_m
        self.segments = list(mission.segments)
        self.i = -1
        self.segment: Segment | None = None
        self.t0 = 0.0
        self.legs: list[tuple[float, float, float, float, float]] = []
        self.leg_i = 0
        self.hold = 0.0  # the heading to hold off lines, from each segment's start
        self.spun = 0.0
        self.last_psi = 0.0
        self.speed = mission.speed_mps
        self.altitude = mission.altitude_m
        self.vrate = dynamics.vertical_rate_max_mps
        self.done = True  # enter the first segment

    @property
    def finished(self) -> bool:
        """The mission's last segment is done."""
        return self.done and self.i == len(self.segments) - 1

    def surfaced(self) -> None:
        """The vehicle reached the surface: an ascent is done."""
        if isinstance(self.segment, Ascend):
            self.done = True

    def _next_segment(self, t_s: float, nav: _Onboard) -> None:
        nav.new_segment(after_surface_wait=isinstance(self.segment, Surface))
        self.i += 1
        self.segment = seg = self.segments[self.i]
        self.t0 = t_s
        self.hold = self.last_psi = nav.psi
        self.spun = 0.0
        if isinstance(seg, Descend | Ascend):
            self.vrate = seg.rate_mps or self.dyn.vertical_rate_max_mps
        if isinstance(seg, Line):
            self.legs = _legs(seg.waypoints_ne_m, (nav.pn, nav.pe), self.dyn.waypoint_capture_m)
            self.leg_i = 0
            self.speed = seg.speed_mps or self.mission.speed_mps
            self.altitude = seg.altitude_m or self.mission.altitude_m

    def commands(self, t_s: float, nav: _Onboard) -> tuple[float, float, float]:
        """``(u_cmd, r_cmd, w_cmd)``: speed, yaw rate and vertical rate (down) for step ``t_s``,
        after moving on to the next segment when the current one is done."""
        dyn, psi = self.dyn, nav.psi
        if self.done:
            self._next_segment(t_s, nav)
        self.done = False
        seg = self.segment
        u_cmd = 0.0
        heading_cmd = self.hold
        r_cmd = None
        alt_cmd = self.altitude
        if isinstance(seg, Surface):
            self.done = t_s - self.t0 >= seg.duration_s
        elif isinstance(seg, Descend):
            alt_cmd = self.mission.altitude_m
            if nav.bottom_lock and abs(nav.alt_m - alt_cmd) < dyn.altitude_tolerance_m:
                self.done = True
        elif isinstance(seg, Ascend):
            pass  # straight up (w_cmd below) until the surface
        elif isinstance(seg, Spin):
            self.spun += _wrap(psi - self.last_psi)
            self.last_psi = psi
            r_cmd = seg.direction * seg.rate_rad_s
            self.done = abs(self.spun) >= seg.turns * TWO_PI
        else:  # Line
            u_cmd, heading_cmd = self._follow_line(nav.pn, nav.pe, psi)
        if r_cmd is None:
            r_cmd = _clamp(dyn.heading_gain_per_s * _wrap(heading_cmd - psi), dyn.yaw_rate_max_rad_s)
        return u_cmd, r_cmd, self._vertical_rate(nav, alt_cmd)

    def _follow_line(self, pn: float, pe: float, psi: float) -> tuple[float, float]:
        """Speed and heading commands on a line: the current leg is the first whose end (less the
        turn anticipation) the onboard position has not passed; the line is done past the last."""
        dyn, legs, leg_i = self.dyn, self.legs, self.leg_i
        while leg_i < len(legs):
            an, ae, tn, te, length = legs[leg_i]
            dn, de = pn - an, pe - ae
            if dn * tn + de * te < length - min(dyn.turn_anticipation_m, 0.5 * length):
                break
            leg_i += 1
        self.leg_i = leg_i
        if leg_i == len(legs):
            self.done = True
            return 0.0, self.hold
        cross = -dn * te + de * tn  # positive: right of the leg
        heading_cmd = math.atan2(te, tn) - math.atan(cross / dyn.lookahead_m)
        self.hold = heading_cmd
        return self.speed * max(dyn.min_speed_fraction, math.cos(_wrap(heading_cmd - psi))), heading_cmd

    def _vertical_rate(self, nav: _Onboard, alt_cmd: float) -> float:
        if isinstance(self.segment, Ascend):
            return -self.vrate
        if isinstance(self.segment, Surface):
            return 0.0
        if nav.bottom_lock:
            return _clamp(nav.slope_rate + self.dyn.altitude_gain_per_s * (nav.alt_m - alt_cmd), self.vrate)
        if nav.last_alt_m > 0.5 * self.alt_max:
            return self.vrate  # no bottom in sight yet: descend
        return -self.dyn.lost_bottom_climb_mps  # lock lost close to the seafloor: back off


# ---------------------------------------------------------------------------------------------
# The closed loop
# ---------------------------------------------------------------------------------------------


def fly(
    mission: Mission,
    *,
    t0_s: float,
    dt_s: float,
    seafloor: Seafloor,
    b_ned_T: tuple[float, float, float],
    iron: tuple[float, ...],
    declination_rad: float,
    correction: Table | None,
    eta: Table,
    sensors: SensorModels,
    errors: PerDiveErrors,
    dynamics: VehicleDynamics,
    rng: np.random.Generator,
    dvl_lever_body_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gps_lever_body_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    max_duration_s: float,
    progress: Callable[[float], None] | None = None,
) -> LoopRecord:
    """Fly a mission in closed loop; every sensor the loop uses is simulated inside it.

    Parameters
    ----------
    mission : Mission
    t0_s : float
        POSIX time of the first step.
    dt_s : float
        Step, seconds (the truth rate).
    seafloor : Seafloor
    b_ned_T : (float, float, float)
        Earth field, tesla, NED.
    iron : tuple of float
        :func:`auvnav.sim.sensors.iron_rows` of the vehicle's distortion.
    declination_rad : float
        What the vehicle adds to its magnetic heading.
    correction : callable or None
        Compass heading -> correction ``delta(h)``, radians (the vehicle's correction file).
    eta : callable
        POSIX time -> tide, metres up.
    sensors : SensorModels
    errors : PerDiveErrors
    dynamics : VehicleDynamics
    rng : numpy Generator
        Source of every draw in the loop.
    dvl_lever_body_m, gps_lever_body_m : tuple
        Sensor positions relative to the reference point, body FRD.
    max_duration_s : float
        Stop after this much vehicle time even when the mission is not done.
    progress : callable, optional
        Called now and then with the elapsed vehicle time, seconds.
    """
    truth = _TrueVehicle(
        dynamics,
        dt_s=dt_s,
        psi_rad=initial_heading(mission),
        d_m=-eta(t0_s) + dynamics.draft_m,
        eta=eta,
        dvl_lever_down_m=dvl_lever_body_m[2],
    )
    instruments = _Instruments(
        sensors,
        errors,
        dt_s=dt_s,
        seafloor=seafloor,
        b_ned_T=b_ned_T,
        iron=iron,
        dvl_lever_body_m=dvl_lever_body_m,
        gps_lever_body_m=gps_lever_body_m,
    )
    nav = _Onboard(
        declination_rad=declination_rad,
        correction=correction,
        R_body_sensor_dvl_nominal=errors.R_body_sensor_dvl_nominal,
        gps_lever_body_m=gps_lever_body_m,
    )
    guidance = _Guidance(mission, dynamics, dvl_max_altitude_m=sensors.dvl_max_altitude_m)
    dvl_every, gps_every = instruments.dvl_every, instruments.gps_every
    surfacing: list[tuple[float, float, float]] = []
    noise = _normal_rows(rng)
    u_cmd = 0.0  # the speed command in force (dead reckoning uses it without bottom lock)
    completed = False
    for k in range(int(max_duration_s / dt_s) + 1):
        t = t0_s + k * dt_s
        z = next(noise)
        truth.start_step(z)
        nav.compass(*instruments.compass(truth, z))
        if k % dvl_every == 0:
            nav.dvl(instruments.dvl(t, truth, z), u_cmd)
        if truth.at_surface and k % gps_every == 0:
            nav.fixes.append(instruments.gps(t, truth, z))
        u_cmd, r_cmd, w_cmd = guidance.commands(t, nav)
        nav.dead_reckon(dt_s)
        if truth.advance(t, u_cmd, r_cmd, w_cmd):  # reached the surface
            surfacing.append((t + dt_s, nav.pn - truth.n, nav.pe - truth.e))
            guidance.surfaced()
        if guidance.finished:
            completed = True
            break
        if progress is not None and (k + 1) % 2000 == 0:
            progress((k + 1) * dt_s)
    if not completed:
        log.warning("the mission was cut at %.0f s of vehicle time before its end", max_duration_s)
    if truth.bottom_contacts:
        log.warning("the vehicle touched the seafloor in %d time steps", truth.bottom_contacts)
    return _loop_record(truth, instruments, nav, surfacing, completed)


def _loop_record(
    truth: _TrueVehicle,
    instruments: _Instruments,
    nav: _Onboard,
    surfacing: list[tuple[float, float, float]],
    completed: bool,
) -> LoopRecord:
    true = np.array(truth.pose)
    ob = np.array(nav.log)
    meas = np.array(instruments.compass_log)
    dvl = np.array(instruments.dvl_log).reshape(-1, 6)
    gps = np.array(instruments.gps_log).reshape(-1, 3)
    return LoopRecord(
        t_s=np.array(truth.t_s),
        p_ned_m=true[:, :3],
        yaw_rad=true[:, 3],
        pitch_rad=true[:, 4],
        roll_rad=true[:, 5],
        onboard_ne_m=ob[:, :2],
        onboard_yaw_rad=ob[:, 2],
        compass_heading_rad=meas[:, 0],
        pitch_measured_rad=meas[:, 1],
        roll_measured_rad=meas[:, 2],
        magnetometer_T=meas[:, 3:6],
        at_surface=np.array(truth.surface, dtype=bool),
        dvl_t_s=dvl[:, 0],
        dvl_v_sensor_mps=dvl[:, 1:4],
        dvl_altitude_m=dvl[:, 4],
        dvl_valid=dvl[:, 5] > 0.5,
        gps_t_s=gps[:, 0],
        gps_ne_m=gps[:, 1:3],
        surfacing=np.array(surfacing).reshape(-1, 3),
        completed=completed,
    )
