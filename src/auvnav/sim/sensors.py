"""Sensor models of the simulated vehicle: DVL, compass and magnetometer, inclinometer, pressure, GPS, USBL.

Defaults describe the paper's class of vehicle, ACFR's Sirius (Williams et al. 2012, "Monitoring of
benthic reference sites", IEEE Robotics & Automation Magazine 19(1)); the noise figures shared with
processing live in :mod:`auvnav.vehicle` (and so in the dive's ``vehicle.yaml``), the rest here:

- DVL: Teledyne RDI Workhorse Navigator 1200 kHz (RDI Workhorse Navigator datasheet): long-term
  accuracy +-0.2% +-1 mm/s (a scale factor drawn once per dive, 1-sigma 0.2%), single-ping noise,
  bottom-track range 30 m (``valid`` false beyond it) and a minimum altitude of 0.5 m, bottom-track
  ping rate 5 Hz; a small mounting misalignment, 1-sigma 0.1 deg per axis, drawn once per dive
  (the residual of a careful installation; not part of the datasheet).
- Compass: a three-axis flux-gate magnetometer with inclinometer of the PNI TCM2 class (PNI TCM2
  datasheet: heading resolution 0.1 deg, tilt accuracy 0.2 deg, magnetometer resolution 0.01 uT).
  The Earth field is rotated into the body by the true attitude, distorted by hard and soft iron
  (paper eq. 2), perturbed by magnetometer noise (50 nT per axis, 1 sigma), levelled with the
  *measured* pitch and roll and turned into a heading by eq. 1, rounded to 0.1 deg.
  :data:`DEFAULT_IRON` is the distortion that remains after a manufacturer calibration; its
  deviation is a few degrees peak to peak with a constant part (see the constant's comment).
- Pressure: a Paroscientific Digiquartz of 1000 dbar full scale (8000 series datasheet: accuracy
  0.01% FS, the 0.1 dbar 1-sigma of ``vehicle.yaml``; resolution better than 0.0001% FS, 0.001 dbar).
  Absolute pressure = ``gsw.p_from_z`` (TEOS-10) of the depth below the instantaneous sea surface
  (depth below the datum plus the tide) + atmospheric pressure.
- GPS at 1 Hz while at the surface, white noise of ``vehicle.gps_sigma_m`` per horizontal axis;
  USBL (optional) every 10 s under water with ``vehicle.usbl_sigma_m`` per axis.

The closed loop needs the compass and DVL at every step, so this module keeps scalar (``math``)
forms of the rotations and of eq. 2 and eq. 1 for it (:func:`compass_heading`); the tests check them
against the vectorised forms in :mod:`auvnav.compass.magnetometer` and :mod:`auvnav.frames`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from auvnav.compass.field import EarthField
from auvnav.compass.magnetometer import deviation_from_iron
from auvnav.depth.pressure import pressure_from_depth
from auvnav.depth.tide import Constituent, TideModel
from auvnav.frames import FloatArray, wrap_angle
from auvnav.vehicle import Vehicle

DEG = math.pi / 180.0

# ---------------------------------------------------------------------------------------------
# Site
# ---------------------------------------------------------------------------------------------

#: South Scott Reef lagoon, Western Australia, where the paper's field work took place (section IV).
SCOTT_REEF_LATITUDE_DEG = -14.05
SCOTT_REEF_LONGITUDE_DEG = 121.78
#: The Scott Reef campaign of October 2009; 01:00 UTC is 09:00 local time (AWST, UTC+8).
DEFAULT_START_TIME = "2009-10-15T01:00:00Z"
#: Standard atmosphere, Pa (ISO 2533).
STANDARD_ATMOSPHERE_PA = 101325.0

# ---------------------------------------------------------------------------------------------
# Hard and soft iron (paper eq. 2-4)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Iron:
    """Magnetic distortion of the vehicle in its body frame (paper eq. 2).

    Parameters
    ----------
    H_soft : ndarray, shape (3, 3), dimensionless
        Soft-iron scaling and coupling, body FRD.
    h_hard_body_T : ndarray, shape (3,), tesla, body FRD
        Hard-iron offset.
    """

    H_soft: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))
    h_hard_body_T: FloatArray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        H = np.array(self.H_soft, dtype=float)
        h = np.array(self.h_hard_body_T, dtype=float)
        if H.shape != (3, 3) or h.shape != (3,):
            raise ValueError(f"H_soft must be (3, 3) and h_hard_body_T (3,); found {H.shape} and {h.shape}")
        if not (np.all(np.isfinite(H)) and np.all(np.isfinite(h))):
            raise ValueError("H_soft and h_hard_body_T must be finite")
        object.__setattr__(self, "H_soft", H)
        object.__setattr__(self, "h_hard_body_T", h)


#: The residual distortion after a manufacturer calibration, body FRD. At Scott Reef in October 2009
#: (IGRF: horizontal field 35.0 uT, inclination -43 deg, declination +2.2 deg) the level deviation
#: delta(h) (true magnetic heading = h + delta(h)) is 3.6 deg peak to peak: constant 1.0 deg (the
#: antisymmetric x-y coupling, i.e. a yaw misalignment between the compass and the body of about
#: 1 deg), first harmonic 1.6 deg (the horizontal hard iron, 0.3 and 0.86 uT) and second harmonic
#: 0.5 deg (the symmetric soft iron). The paper's section II-C: O(1) deg after calibration, "several
#: degrees" before. The vertical terms matter only under tilt.
DEFAULT_IRON = Iron(
    H_soft=np.array([[-0.004, -0.0105, 0.002], [0.0244, 0.0065, -0.003], [0.003, 0.001, 0.01]]),
    h_hard_body_T=np.array([0.31e-6, 0.86e-6, 0.5e-6]),
)
NO_IRON = Iron()


def deviation_table(
    iron: Iron, earth: EarthField, compass_heading_rad: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The true deviation ``delta(h)`` at level attitude: true magnetic heading = ``h + delta(h)``.

    The sign convention of the compass correction (paper eq. 5, DESIGN section 4). Found by solving
    ``h = psi + error(psi)`` for the true magnetic heading ``psi`` by fixed-point iteration, with
    ``error`` from eq. 2-4 (:func:`auvnav.compass.magnetometer.deviation_from_iron`); it converges
    while the deviation's slope stays below one.

    Parameters
    ----------
    iron : Iron
    earth : EarthField
    compass_heading_rad : ndarray, shape (N,), radians
        Compass (measured magnetic) headings.

    Returns
    -------
    ndarray, shape (N,), radians
    """
    h = np.asarray(compass_heading_rad, dtype=float)
    psi = h.copy()
    for _ in range(100):
        error = deviation_from_iron(iron.H_soft, iron.h_hard_body_T, earth, psi)
        new = wrap_angle(h - error)
        if np.max(np.abs(wrap_angle(new - psi))) < 1e-13:
            psi = new
            break
        psi = new
    return wrap_angle(psi - h)


# ---------------------------------------------------------------------------------------------
# Sensor parameters
# ---------------------------------------------------------------------------------------------

DVL_RATE_HZ = 5.0  # RDI Workhorse bottom-track ping rate at short range
DVL_MIN_ALTITUDE_M = 0.5  # RDI Workhorse 1200 kHz minimum bottom-track altitude
DVL_MISALIGNMENT_SIGMA_DEG = 0.1  # residual after an installation alignment, per axis
DVL_ALTITUDE_SIGMA_M = 0.01  # range noise of the averaged beams at 2 m
MAGNETOMETER_SIGMA_T = 50e-9  # flux-gate noise per axis (PNI TCM2 class; resolution 10 nT)
HEADING_RESOLUTION_DEG = 0.1  # PNI TCM2 heading resolution
PRESSURE_RESOLUTION_DBAR = 0.001  # Digiquartz: better than 0.0001% of 1000 dbar
GPS_RATE_HZ = 1.0
USBL_PERIOD_S = 10.0


@dataclass(frozen=True)
class SensorModels:
    """Every sensor error figure the simulator injects (1 sigma, SI units, radians).

    Build it with :meth:`from_vehicle`; :meth:`without_errors` switches every error off (noise,
    scale factor, misalignment, quantisation), leaving exact measurements for checking integration.
    """

    dvl_velocity_sigma_mps: float
    dvl_scale_sigma: float
    dvl_misalignment_sigma_rad: float
    dvl_altitude_sigma_m: float
    dvl_max_altitude_m: float
    magnetometer_sigma_T: float
    heading_resolution_rad: float
    tilt_sigma_rad: float
    pressure_sigma_pa: float
    pressure_resolution_pa: float
    gps_sigma_m: float
    usbl_sigma_m: float
    dvl_min_altitude_m: float = DVL_MIN_ALTITUDE_M
    dvl_rate_hz: float = DVL_RATE_HZ
    gps_rate_hz: float = GPS_RATE_HZ
    usbl_period_s: float = USBL_PERIOD_S

    @classmethod
    def from_vehicle(cls, vehicle: Vehicle) -> SensorModels:
        """The default errors: the vehicle's noise figures plus this module's datasheet values."""
        return cls(
            dvl_velocity_sigma_mps=vehicle.dvl_velocity_sigma_mps,
            dvl_scale_sigma=vehicle.dvl_scale_sigma,
            dvl_misalignment_sigma_rad=DVL_MISALIGNMENT_SIGMA_DEG * DEG,
            dvl_altitude_sigma_m=DVL_ALTITUDE_SIGMA_M,
            dvl_max_altitude_m=vehicle.dvl_max_altitude_m,
            magnetometer_sigma_T=MAGNETOMETER_SIGMA_T,
            heading_resolution_rad=HEADING_RESOLUTION_DEG * DEG,
            tilt_sigma_rad=vehicle.pitch_roll_sigma_rad,
            pressure_sigma_pa=vehicle.pressure_sigma_pa,
            pressure_resolution_pa=PRESSURE_RESOLUTION_DBAR * 1e4,
            gps_sigma_m=vehicle.gps_sigma_m,
            usbl_sigma_m=vehicle.usbl_sigma_m,
        )

    def without_errors(self) -> SensorModels:
        """The same sensors with every error set to zero (ranges and rates kept)."""
        return replace(
            self,
            dvl_velocity_sigma_mps=0.0,
            dvl_scale_sigma=0.0,
            dvl_misalignment_sigma_rad=0.0,
            dvl_altitude_sigma_m=0.0,
            magnetometer_sigma_T=0.0,
            heading_resolution_rad=0.0,
            tilt_sigma_rad=0.0,
            pressure_sigma_pa=0.0,
            pressure_resolution_pa=0.0,
            gps_sigma_m=0.0,
            usbl_sigma_m=0.0,
        )


# ---------------------------------------------------------------------------------------------
# Scalar kinematics for the closed loop (R_ned_body = Rz(yaw) Ry(pitch) Rx(roll))
# ---------------------------------------------------------------------------------------------


def ned2body(
    yaw: float, pitch: float, roll: float, x: float, y: float, z: float
) -> tuple[float, float, float]:
    """``R_ned_body^T @ v`` for one NED vector, the body FRD components (scalar form)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    l1 = cy * x + sy * y
    l2 = -sy * x + cy * y
    y1 = cp * l1 - sp * z
    y3 = sp * l1 + cp * z
    return y1, cr * l2 + sr * y3, -sr * l2 + cr * y3


def body2ned(
    yaw: float, pitch: float, roll: float, x: float, y: float, z: float
) -> tuple[float, float, float]:
    """``R_ned_body @ v`` for one body FRD vector, the NED components (scalar form)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    x2 = cr * y - sr * z
    z2 = sr * y + cr * z
    x3 = cp * x + sp * z2
    z3 = -sp * x + cp * z2
    return cy * x3 - sy * x2, sy * x3 + cy * x2, z3


def distort(iron_rows: tuple[float, ...], bx: float, by: float, bz: float) -> tuple[float, float, float]:
    """Eq. 2 for one vector: ``(H_soft + I) b + h_hard`` with ``iron_rows`` from :func:`iron_rows`."""
    s00, s01, s02, s10, s11, s12, s20, s21, s22, hx, hy, hz = iron_rows
    return (
        s00 * bx + s01 * by + s02 * bz + hx,
        s10 * bx + s11 * by + s12 * bz + hy,
        s20 * bx + s21 * by + s22 * bz + hz,
    )


def iron_rows(iron: Iron) -> tuple[float, ...]:
    """``(H_soft + I)`` row by row, then ``h_hard``, as plain floats for :func:`distort`."""
    S = iron.H_soft + np.eye(3)
    return (*(float(v) for v in S.ravel()), *(float(v) for v in iron.h_hard_body_T))


def compass_heading(mx: float, my: float, mz: float, pitch: float, roll: float) -> float:
    """Eq. 1 for one sample: level the field with pitch and roll, ``atan2(-l_y, l_x)``, radians."""
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    l2 = cr * my - sr * mz
    l1 = cp * mx + sp * (sr * my + cr * mz)
    return math.atan2(-l2, l1)


def quantise(x: float, step: float) -> float:
    """Round to a multiple of ``step`` (no rounding when ``step`` is 0)."""
    return round(x / step) * step if step > 0 else x


# ---------------------------------------------------------------------------------------------
# Tide and pressure
# ---------------------------------------------------------------------------------------------


def default_tide(latitude_rad: float) -> TideModel:
    """A macro-tidal harmonic tide, illustrative of Scott Reef.

    Scott Reef lies on the macro-tidal North West Shelf of Australia (spring range about 4 m;
    Holloway, "Tides on the Australian North-West Shelf", Aust. J. Mar. Freshwater Res. 34, 1983).
    The amplitudes follow that scale (M2 1.2 m, S2 0.6 m, K1 0.3 m, O1 0.2 m: a spring range of
    about 4 m); the Greenwich phases are illustrative, not a published analysis.
    """
    constituents = (
        Constituent("M2", 1.2, math.radians(150.0)),
        Constituent("S2", 0.6, math.radians(210.0)),
        Constituent("K1", 0.3, math.radians(300.0)),
        Constituent("O1", 0.2, math.radians(270.0)),
    )
    return TideModel(
        constituents, latitude_rad, reference="auvnav simulator: illustrative macro-tidal (Scott Reef scale)"
    )


def absolute_pressure_pa(
    depth_below_surface_m: NDArray[np.float64],
    latitude_rad: float,
    atmospheric_pa: float,
    noise: NDArray[np.float64],
    sensors: SensorModels,
) -> NDArray[np.float64]:
    """What the pressure sensor reads, Pa: TEOS-10 sea pressure + atmospheric + noise, quantised.

    Parameters
    ----------
    depth_below_surface_m : ndarray, shape (N,), metres, positive down
        Depth of the sensor below the instantaneous sea surface (depth below datum + tide).
    latitude_rad : float
    atmospheric_pa : float
    noise : ndarray, shape (N,)
        Standard normal draws, scaled by ``sensors.pressure_sigma_pa``.
    sensors : SensorModels
    """
    p = pressure_from_depth(depth_below_surface_m, latitude_rad) + atmospheric_pa
    p = p + sensors.pressure_sigma_pa * noise
    step = sensors.pressure_resolution_pa
    return np.round(p / step) * step if step > 0 else p
