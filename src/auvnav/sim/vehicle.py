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

Everything steps at ``dt_s`` (0.1 s) in plain ``math`` for speed; the result is a
:class:`LoopRecord` of arrays that :mod:`auvnav.sim.run` turns into a dive folder.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray
from auvnav.plan.missions import Ascend, Descend, Line, Mission, Spin, Surface
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
_NOISE_COLUMNS = 13  # mag xyz, tilt pitch/roll, attitude process pitch/roll, DVL vxyz, altitude, GPS ne


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


class _Normals:
    """Standard normal draws in blocks, handed out one row per step (deterministic for a seed)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self._rng = rng

    def block(self) -> list[list[float]]:
        return self._rng.standard_normal((_NOISE_BLOCK, _NOISE_COLUMNS)).tolist()


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
    dyn = dynamics
    dt = dt_s
    bn_T, be_T, bd_T = b_ned_T
    dvl_every = max(round(1.0 / (sensors.dvl_rate_hz * dt)), 1)
    gps_every = max(round(1.0 / (sensors.gps_rate_hz * dt)), 1)
    s_mag, s_tilt, res = sensors.magnetometer_sigma_T, sensors.tilt_sigma_rad, sensors.heading_resolution_rad
    s_dvl, s_alt = sensors.dvl_velocity_sigma_mps, sensors.dvl_altitude_sigma_m
    alt_min, alt_max = sensors.dvl_min_altitude_m, sensors.dvl_max_altitude_m
    s_gps = sensors.gps_sigma_m
    scale = 1.0 + errors.dvl_scale
    M = [float(v) for v in errors.R_sensor_body_dvl.ravel()]
    N = [float(v) for v in errors.R_body_sensor_dvl_nominal.ravel()]
    lx, ly, lz = dvl_lever_body_m
    ga = math.exp(-dt / dyn.attitude_noise_tau_s)
    gb = dyn.attitude_noise_rad * math.sqrt(1.0 - ga * ga)
    k_speed, k_yaw, k_vert = dt / dyn.speed_tau_s, dt / dyn.yaw_rate_tau_s, dt / dyn.vertical_tau_s
    r_max, w_max = dyn.yaw_rate_max_rad_s, dyn.vertical_rate_max_mps

    normals = _Normals(rng)
    rows: list[list[float]] = []
    row_i = 0

    # true state
    n = e = 0.0
    psi = initial_heading(mission)
    r = u = w = 0.0
    x_pitch = x_roll = 0.0
    at_surface = True
    d = -eta(t0_s) + dyn.draft_m
    # onboard state
    pn = pe = 0.0
    v_ob = (0.0, 0.0, 0.0)
    alt_meas, alt_ok = 0.0, False
    slope_rate = 0.0
    # the records
    rec_t: list[float] = []
    rec_true: list[tuple[float, ...]] = []
    rec_ob: list[tuple[float, float, float]] = []
    rec_meas: list[tuple[float, ...]] = []
    rec_surface: list[bool] = []
    dvl_rows: list[tuple[float, ...]] = []
    gps_rows: list[tuple[float, float, float]] = []
    surfacing: list[tuple[float, float, float]] = []

    segments = list(mission.segments)
    seg_i = -1
    seg: object = None
    seg_t0 = 0.0
    legs: list[tuple[float, float, float, float, float]] = []
    leg_i = 0
    hold = psi
    spun = 0.0
    last_psi_ob = 0.0
    fixes: list[tuple[float, float]] = []
    speed = mission.speed_mps
    altitude = mission.altitude_m
    vrate = w_max
    u_cmd = 0.0
    last_alt_m = math.inf  # the last altitude the DVL measured: lock lost near the bottom means too close
    floor_d = math.inf
    bottom_contacts = 0

    k = 0
    completed = False
    steps_max = int(max_duration_s / dt)
    psi_ob = psi
    seg_done = True  # enter the first segment
    while k <= steps_max:
        t = t0_s + k * dt
        if row_i == len(rows):
            rows, row_i = normals.block(), 0
        z = rows[row_i]
        row_i += 1

        # ---- the vehicle's attitude (passively stable: small, not zero) ----
        x_pitch = ga * x_pitch + gb * z[5]
        x_roll = ga * x_roll + gb * z[6]
        theta = dyn.pitch_trim_rad + dyn.pitch_rad_per_mps * w + x_pitch
        phi = dyn.roll_trim_rad + dyn.roll_rad_per_mps2 * u * r + x_roll

        # ---- sensors ----
        theta_m = theta + s_tilt * z[3]
        phi_m = phi + s_tilt * z[4]
        bx, by, bz = ned2body(psi, theta, phi, bn_T, be_T, bd_T)
        mx, my, mz = distort(iron, bx, by, bz)
        mx += s_mag * z[0]
        my += s_mag * z[1]
        mz += s_mag * z[2]
        h_meas = _wrap(quantise(compass_heading(mx, my, mz, theta_m, phi_m), res))
        h_corr = h_meas + correction(h_meas) if correction is not None else h_meas
        psi_ob = _wrap(h_corr + declination_rad)

        vn, ve = u * math.cos(psi), u * math.sin(psi)
        if k % dvl_every == 0:
            vx, vy, vz = ned2body(psi, theta, phi, vn, ve, w)
            vx, vy = vx - r * ly, vy + r * lx  # + omega x lever, omega ~ (0, 0, r)
            sx = scale * (M[0] * vx + M[1] * vy + M[2] * vz) + s_dvl * z[7]
            sy = scale * (M[3] * vx + M[4] * vy + M[5] * vz) + s_dvl * z[8]
            sz = scale * (M[6] * vx + M[7] * vy + M[8] * vz) + s_dvl * z[9]
            floor_d, gn, ge = seafloor.depth_and_gradient(n, e)
            alt_true = floor_d - (d + lz)
            alt_ok = alt_min <= alt_true <= alt_max
            alt_meas = alt_true + s_alt * z[10]
            slope_rate = gn * vn + ge * ve
            if alt_ok:
                last_alt_m = alt_meas
                dvl_rows.append((t, sx, sy, sz, alt_meas, 1.0))
                v_ob = (
                    N[0] * sx + N[1] * sy + N[2] * sz,
                    N[3] * sx + N[4] * sy + N[5] * sz,
                    N[6] * sx + N[7] * sy + N[8] * sz,
                )
            else:
                dvl_rows.append((t, 0.0, 0.0, 0.0, 0.0, 0.0))
                v_ob = (u_cmd, 0.0, 0.0)  # no bottom lock: speed through water from the thrust command
        if at_surface and k % gps_every == 0:
            an, ae, _ = body2ned(psi, theta, phi, *gps_lever_body_m)
            gps_rows.append((t, n + an + s_gps * z[11], e + ae + s_gps * z[12]))
            fixes.append((gps_rows[-1][1], gps_rows[-1][2]))

        # ---- mission segments and guidance on the onboard state ----
        if seg_done:
            if isinstance(seg, Surface) and fixes:
                an, ae, _ = body2ned(psi_ob, theta_m, phi_m, *gps_lever_body_m)
                pn = sum(f[0] for f in fixes) / len(fixes) - an
                pe = sum(f[1] for f in fixes) / len(fixes) - ae
            seg_i += 1
            seg = segments[seg_i]
            seg_t0 = t
            hold = psi_ob
            fixes = []
            spun = 0.0
            last_psi_ob = psi_ob
            if isinstance(seg, Descend | Ascend):
                vrate = seg.rate_mps or w_max
            if isinstance(seg, Line):
                legs = _legs(seg.waypoints_ne_m, (pn, pe), dyn.waypoint_capture_m)
                leg_i = 0
                speed = seg.speed_mps or mission.speed_mps
                altitude = seg.altitude_m or mission.altitude_m
        seg_done = False

        u_cmd = 0.0
        heading_cmd = hold
        r_cmd = None
        alt_cmd = altitude
        if isinstance(seg, Surface):
            seg_done = t - seg_t0 >= seg.duration_s
        elif isinstance(seg, Descend):
            alt_cmd = mission.altitude_m
            if alt_ok and abs(alt_meas - alt_cmd) < dyn.altitude_tolerance_m:
                seg_done = True
        elif isinstance(seg, Ascend):
            pass  # straight up (w_cmd below) until the surface
        elif isinstance(seg, Spin):
            spun += _wrap(psi_ob - last_psi_ob)
            last_psi_ob = psi_ob
            r_cmd = seg.direction * seg.rate_rad_s
            seg_done = abs(spun) >= seg.turns * TWO_PI
        else:  # Line
            while leg_i < len(legs):
                an, ae, tn, te, length = legs[leg_i]
                dn, de = pn - an, pe - ae
                if dn * tn + de * te < length - min(dyn.turn_anticipation_m, 0.5 * length):
                    break
                leg_i += 1
            if leg_i == len(legs):
                seg_done = True
            else:
                cross = -dn * te + de * tn  # positive: right of the leg
                heading_cmd = math.atan2(te, tn) - math.atan(cross / dyn.lookahead_m)
                hold = heading_cmd
                u_cmd = speed * max(dyn.min_speed_fraction, math.cos(_wrap(heading_cmd - psi_ob)))
        if r_cmd is None:
            r_cmd = _clamp(dyn.heading_gain_per_s * _wrap(heading_cmd - psi_ob), r_max)
        if isinstance(seg, Ascend):
            w_cmd = -vrate
        elif isinstance(seg, Surface):
            w_cmd = 0.0
        elif alt_ok:
            w_cmd = _clamp(slope_rate + dyn.altitude_gain_per_s * (alt_meas - alt_cmd), vrate)
        elif last_alt_m > 0.5 * alt_max:
            w_cmd = vrate  # no bottom in sight yet: descend
        else:
            w_cmd = -dyn.lost_bottom_climb_mps  # lock lost close to the seafloor: back off

        # ---- record step k ----
        rec_t.append(t)
        rec_true.append((n, e, d, psi, theta, phi))
        rec_ob.append((pn, pe, psi_ob))
        rec_meas.append((h_meas, theta_m, phi_m, mx, my, mz))
        rec_surface.append(at_surface)

        # ---- integrate to step k + 1 ----
        vn_ob, ve_ob, _ = body2ned(psi_ob, theta_m, phi_m, *v_ob)
        pn += vn_ob * dt
        pe += ve_ob * dt
        n += vn * dt
        e += ve * dt
        psi = _wrap(psi + r * dt)
        r = _clamp(r + (r_cmd - r) * k_yaw, r_max)
        u += (u_cmd - u) * k_speed
        if at_surface and w_cmd > 0.0 and not isinstance(seg, Surface):
            at_surface = False  # leave the surface
        if at_surface:
            w = 0.0
            d = -eta(t + dt) + dyn.draft_m
        else:
            d += w * dt
            w += (w_cmd - w) * k_vert
            if d + lz > floor_d - dyn.bottom_clearance_m:  # the seafloor stops the vehicle
                d, w = floor_d - dyn.bottom_clearance_m - lz, min(w, 0.0)
                bottom_contacts += 1
            surface_d = -eta(t + dt) + dyn.draft_m
            if d <= surface_d and w < 0.0:
                d, w, at_surface = surface_d, 0.0, True
                surfacing.append((t + dt, pn - n, pe - e))
                if isinstance(seg, Ascend):
                    seg_done = True
        k += 1
        if seg_done and seg_i == len(segments) - 1:
            completed = True
            break
        if progress is not None and k % 2000 == 0:
            progress(k * dt)
    if not completed:
        log.warning("the mission was cut at %.0f s of vehicle time before its end", max_duration_s)
    if bottom_contacts:
        log.warning("the vehicle touched the seafloor in %d time steps", bottom_contacts)

    true = np.array(rec_true)
    ob = np.array(rec_ob)
    meas = np.array(rec_meas)
    dvl = np.array(dvl_rows).reshape(-1, 6)
    gps = np.array(gps_rows).reshape(-1, 3)
    return LoopRecord(
        t_s=np.array(rec_t),
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
        at_surface=np.array(rec_surface, dtype=bool),
        dvl_t_s=dvl[:, 0],
        dvl_v_sensor_mps=dvl[:, 1:4],
        dvl_altitude_m=dvl[:, 4],
        dvl_valid=dvl[:, 5] > 0.5,
        gps_t_s=gps[:, 0],
        gps_ne_m=gps[:, 1:3],
        surfacing=np.array(surfacing).reshape(-1, 3),
        completed=completed,
    )
