"""Simulate a dive: fly a mission in closed loop, make every sensor stream, and write a dive folder.

:func:`simulate` returns a :class:`Simulation` (the :class:`~auvnav.dive.Dive` and its truth);
:func:`write_simulation` writes the dive folder (DESIGN section 5) with ``truth/``:

- ``truth/trajectory.csv``: the true trajectory at the step rate (10 Hz), reference point, local NED;
- ``truth/onboard.csv``: what the vehicle believed in real time (dead-reckoned north and east,
  depth from pressure without tide, compass heading + correction + declination, measured pitch and
  roll), the track its guidance steered;
- ``truth/deviation.csv``: ``compass_heading_deg, deviation_deg``, 360 rows, the true ``delta(h)``
  at level attitude with true magnetic heading = ``h + delta(h)`` (the compass correction's sign);
- ``truth/tide.csv``: the tide's constituents (:func:`auvnav.depth.tide.write_constituents`);
- ``truth/truth.yaml``: every parameter and draw: seed, site, date, field model and vector, hard and
  soft iron, sensor errors (DVL scale and misalignment included), dynamics, seafloor, mission,
  and what came out (time and onboard-minus-true position at each surfacing).

Same seed and options, same files byte for byte.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import yaml

from auvnav.compass.correction import read_correction
from auvnav.compass.deviation import DeviationModel
from auvnav.compass.field import EarthField, earth_field
from auvnav.depth.pressure import depth_from_pressure
from auvnav.depth.tide import TideModel, write_constituents
from auvnav.dive import (
    AttitudeStream,
    Dive,
    DiveInfo,
    DvlStream,
    GpsStream,
    MagnetometerStream,
    PressureStream,
    UsblStream,
    write_dive,
)
from auvnav.errors import ConfigError, OutputExistsError
from auvnav.frames import GeodeticOrigin, euler2rot, ned2geodetic
from auvnav.plan.missions import KINDS, Mission, build_mission, read_mission
from auvnav.sim.seafloor import Seafloor, SeafloorParams
from auvnav.sim.sensors import (
    DEFAULT_IRON,
    DEFAULT_START_TIME,
    NO_IRON,
    SCOTT_REEF_LATITUDE_DEG,
    SCOTT_REEF_LONGITUDE_DEG,
    STANDARD_ATMOSPHERE_PA,
    Iron,
    SensorModels,
    absolute_pressure_pa,
    default_tide,
    deviation_table,
    iron_rows,
)
from auvnav.sim.truthloops import write_truth_loops
from auvnav.sim.vehicle import LoopRecord, PerDiveErrors, Table, VehicleDynamics, fly
from auvnav.streams import write_table
from auvnav.trajectory import Trajectory, write_trajectory
from auvnav.vehicle import Vehicle

log = logging.getLogger(__name__)

DEG = math.pi / 180.0
_TIDE_STEP_S = 10.0  # the tide is predicted on this grid and interpolated (error < 1e-6 m)
_CORRECTION_STEP_RAD = 0.1 * DEG  # the correction's lookup table (interpolation error < 1e-6 deg)


def _posix(iso: str) -> float:
    return dt.datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp()


@dataclass(frozen=True)
class SimConfig:
    """Everything a simulation depends on besides the mission.

    Parameters
    ----------
    seed : int
        The dive's seed: seafloor, per-dive sensor errors (DVL scale factor), noise.
    site_seed : int or None
        The seafloor's seed when it is not the dive's: a repeat survey of a site flies over the
        seafloor of an earlier dive (its seed) with noise of its own (``seed``).
    vehicle_seed : int
        The vehicle's seed: errors that belong to the vehicle, not the dive (the DVL's mounting
        misalignment), shared by every dive of a campaign flown with the same vehicle.
    latitude_rad, longitude_rad : float
        Site (the dive's origin), radians.
    start_time_s : float
        POSIX time of the start, UTC.
    iron : Iron
        The vehicle's magnetic distortion (``NO_IRON`` for a compass without deviation).
    tide : TideModel or None
        None: no tide (a constant sea level at the datum).
    sensor_errors : bool
        False switches every sensor error off (exact measurements).
    sensors : SensorModels or None
        Sensor figures; None: :meth:`SensorModels.from_vehicle` of ``vehicle``.
    vehicle : Vehicle
        Mounts and noise figures, written as the dive's vehicle.yaml.
    dynamics : VehicleDynamics
    seafloor : SeafloorParams
    compass_correction : DeviationModel or None
        The correction the vehicle applies to its compass in real time.
    atmospheric_pa : float
        Atmospheric pressure, Pa.
    usbl : bool
        Also simulate USBL fixes under water.
    dt_s : float
        Step of the loop and rate of the truth, seconds.
    max_duration_s : float or None
        Stop after this much vehicle time (None: when the mission ends).
    """

    seed: int = 0
    vehicle_seed: int = 0
    site_seed: int | None = None
    latitude_rad: float = SCOTT_REEF_LATITUDE_DEG * DEG
    longitude_rad: float = SCOTT_REEF_LONGITUDE_DEG * DEG
    start_time_s: float = field(default_factory=lambda: _posix(DEFAULT_START_TIME))
    iron: Iron = DEFAULT_IRON
    tide: TideModel | None = None
    sensor_errors: bool = True
    sensors: SensorModels | None = None
    vehicle: Vehicle = field(default_factory=Vehicle)
    dynamics: VehicleDynamics = field(default_factory=VehicleDynamics)
    seafloor: SeafloorParams = field(default_factory=SeafloorParams)
    compass_correction: DeviationModel | None = None
    atmospheric_pa: float = STANDARD_ATMOSPHERE_PA
    usbl: bool = False
    dt_s: float = 0.1
    max_duration_s: float | None = None

    def __post_init__(self) -> None:
        if not (self.dt_s > 0 and math.isfinite(self.dt_s)):
            raise ValueError(f"dt_s must be positive; found {self.dt_s}")
        if self.max_duration_s is not None and not self.max_duration_s > 0:
            raise ValueError(f"max_duration_s must be positive; found {self.max_duration_s}")


def default_config(
    *,
    seed: int = 0,
    deviation: Literal["none", "default"] = "default",
    tide: Literal["none", "default"] = "default",
    sensor_errors: Literal["none", "default"] = "default",
    **options: Any,
) -> SimConfig:
    """A configuration from the command's switches; other :class:`SimConfig` fields as keywords."""
    latitude_rad = options.get("latitude_rad", SCOTT_REEF_LATITUDE_DEG * DEG)
    return SimConfig(
        seed=seed,
        iron=DEFAULT_IRON if deviation == "default" else NO_IRON,
        tide=default_tide(latitude_rad) if tide == "default" else None,
        sensor_errors=sensor_errors == "default",
        **options,
    )


@dataclass(frozen=True)
class Simulation:
    """A simulated dive and its truth.

    Parameters
    ----------
    dive : Dive
    trajectory : Trajectory
        The true trajectory (step rate).
    onboard : Trajectory
        The vehicle's real-time navigation.
    deviation_deg : ndarray, shape (360, 2)
        ``compass_heading_deg, deviation_deg`` (true magnetic heading = h + delta(h)).
    tide : TideModel
    truth : dict
        Everything injected, as written to truth.yaml.
    summary : dict
        What happened: duration, distance, onboard-minus-true at each surfacing.
    """

    dive: Dive
    trajectory: Trajectory
    onboard: Trajectory
    deviation_deg: np.ndarray
    tide: TideModel
    truth: dict[str, Any]
    summary: dict[str, Any]


def _per_dive_errors(
    rng: np.random.Generator, rng_vehicle: np.random.Generator, sensors: SensorModels, vehicle: Vehicle
) -> tuple[PerDiveErrors, np.ndarray]:
    """DVL scale factor drawn per dive (it follows the dive's sound speed) and mounting misalignment
    drawn per vehicle (the DVL stays bolted where it is between dives)."""
    scale = sensors.dvl_scale_sigma * float(rng.standard_normal())
    rpy = sensors.dvl_misalignment_sigma_rad * rng_vehicle.standard_normal(3)
    R_body_sensor_nominal = vehicle.dvl.R_body_sensor
    R_body_sensor_true = R_body_sensor_nominal @ euler2rot(rpy[2], rpy[1], rpy[0])
    return PerDiveErrors(scale, R_body_sensor_true.T, R_body_sensor_nominal), rpy


def _tide_table(tide: TideModel, t0_s: float, duration_s: float) -> Table:
    grid = t0_s - _TIDE_STEP_S + _TIDE_STEP_S * np.arange(int(duration_s / _TIDE_STEP_S) + 4)
    return Table(float(grid[0]), _TIDE_STEP_S, tide.predict(grid))


def _correction_table(model: DeviationModel) -> Table:
    grid = -math.pi + _CORRECTION_STEP_RAD * np.arange(round(2 * math.pi / _CORRECTION_STEP_RAD) + 2)
    return Table(-math.pi, _CORRECTION_STEP_RAD, model(grid))


def _onboard_depth(pressure_pa: np.ndarray, config: SimConfig) -> np.ndarray:
    """The vehicle's real-time depth: TEOS-10 of sea pressure, no tide correction."""
    return depth_from_pressure(pressure_pa - config.atmospheric_pa, config.latitude_rad)


def _surfacing_summary(record: LoopRecord) -> list[dict[str, float]]:
    return [
        {
            "t_s": round(float(t), 6),
            "north_error_m": float(dn),
            "east_error_m": float(de),
            "error_m": math.hypot(dn, de),
        }
        for t, dn, de in record.surfacing
    ]


def _file_units(values: dict[str, Any]) -> dict[str, Any]:
    """Radians to degrees and tesla to nanotesla, renaming the keys (``_rad`` -> ``_deg``, ``_T`` -> ``_nT``)."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if "_rad" in key:
            out[key.replace("_rad", "_deg")] = math.degrees(value)
        elif key.endswith("_T"):
            out[key[:-2] + "_nT"] = value * 1e9
        else:
            out[key] = value
    return out


def _truth_dict(
    mission: Mission,
    config: SimConfig,
    earth: EarthField,
    sensors: SensorModels,
    errors: PerDiveErrors,
    misalignment_rpy: np.ndarray,
    deviation: np.ndarray,
    tide: TideModel,
    summary: dict[str, Any],
) -> dict[str, Any]:
    """truth.yaml: every parameter, in file units (degrees, nT), plain Python types."""

    def plain(x: Any) -> Any:
        if isinstance(x, dict):
            return {str(k): plain(v) for k, v in x.items()}
        if isinstance(x, list | tuple | np.ndarray):
            return [plain(v) for v in (x.tolist() if isinstance(x, np.ndarray) else x)]
        if isinstance(x, np.generic):
            return x.item()
        return x

    return plain(
        {
            "format": "auvnav-truth/1",
            "seed": config.seed,
            "vehicle_seed": config.vehicle_seed,
            "site": {
                "latitude_deg": math.degrees(config.latitude_rad),
                "longitude_deg": math.degrees(config.longitude_rad),
                "start_time": dt.datetime.fromtimestamp(config.start_time_s, dt.timezone.utc)
                .isoformat()
                .replace("+00:00", "Z"),
                "atmospheric_dbar": config.atmospheric_pa / 1e4,
            },
            "earth_field": {
                "model": earth.model,
                "b_ned_nT": earth.b_ned_T * 1e9,
                "declination_deg": math.degrees(earth.declination_rad),
                "inclination_deg": math.degrees(earth.inclination_rad),
            },
            "compass": {
                "H_soft": config.iron.H_soft,
                "h_hard_body_nT": config.iron.h_hard_body_T * 1e9,
                "deviation_peak_to_peak_deg": float(np.ptp(deviation[:, 1])),
                "deviation_mean_deg": float(np.mean(deviation[:, 1])),
                "correction_applied": None
                if config.compass_correction is None
                else {
                    "a0_deg": math.degrees(config.compass_correction.a0_rad),
                    "a_deg": np.degrees(config.compass_correction.a_rad),
                    "b_deg": np.degrees(config.compass_correction.b_rad),
                },
            },
            "tide": {
                "constituents": [
                    {"name": c.name, "amplitude_m": c.amplitude_m, "phase_deg": math.degrees(c.phase_rad)}
                    for c in tide.constituents
                ],
                "mean_m": tide.mean_m,
                "reference": tide.reference,
            },
            "sensor_errors": config.sensor_errors,
            "sensors": _file_units(asdict(sensors)),
            "dvl": {
                "scale_factor": errors.dvl_scale,
                "misalignment_rpy_deg": np.degrees(misalignment_rpy),
            },
            "dynamics": _file_units(asdict(config.dynamics)),
            "seafloor": {
                "seed": _site_seed(config),
                **{k: v for k, v in asdict(config.seafloor).items() if k != "removed_cells" or v},
            },
            "dt_s": config.dt_s,
            "usbl": config.usbl,
            "mission": mission.summary(),
            "result": summary,
        }
    )


def _site_seed(config: SimConfig) -> int:
    return config.seed if config.site_seed is None else config.site_seed


def simulate(
    mission: Mission, config: SimConfig, *, progress: Callable[[float, float], None] | None = None
) -> Simulation:
    """Fly ``mission`` with the vehicle, sensors and site of ``config``.

    Parameters
    ----------
    mission : Mission
    config : SimConfig
    progress : callable, optional
        ``progress(elapsed_s, expected_s)`` now and then (vehicle time).

    Returns
    -------
    Simulation
    """
    earth = earth_field(config.latitude_rad, config.longitude_rad, config.start_time_s)
    tide = config.tide if config.tide is not None else TideModel((), config.latitude_rad, reference="none")
    sensors = config.sensors or SensorModels.from_vehicle(config.vehicle)
    if not config.sensor_errors:
        sensors = sensors.without_errors()
    seeds = np.random.SeedSequence(config.seed).spawn(4)
    rng_dive, rng_loop, rng_pressure, rng_usbl = (np.random.default_rng(s) for s in seeds)
    rng_vehicle = np.random.default_rng(np.random.SeedSequence([config.vehicle_seed, 0x7E41C1E]))
    errors, misalignment_rpy = _per_dive_errors(rng_dive, rng_vehicle, sensors, config.vehicle)
    seafloor = Seafloor(_site_seed(config), config.seafloor)

    expected_s = mission.planned_duration_s(
        config.dynamics.vertical_rate_max_mps, config.seafloor.mean_depth_m
    )
    limit_s = config.max_duration_s if config.max_duration_s is not None else 3.0 * expected_s + 3600.0
    t0 = config.start_time_s
    record = fly(
        mission,
        t0_s=t0,
        dt_s=config.dt_s,
        seafloor=seafloor,
        b_ned_T=tuple(float(v) for v in earth.b_ned_T),  # type: ignore[arg-type]
        iron=iron_rows(config.iron),
        declination_rad=earth.declination_rad,
        correction=None
        if config.compass_correction is None
        else _correction_table(config.compass_correction),
        eta=_tide_table(tide, t0, limit_s + 60.0),
        sensors=sensors,
        errors=errors,
        dynamics=config.dynamics,
        rng=rng_loop,
        dvl_lever_body_m=tuple(config.vehicle.dvl.lever_arm_body_m.tolist()),  # type: ignore[arg-type]
        gps_lever_body_m=tuple(config.vehicle.gps.lever_arm_body_m.tolist()),  # type: ignore[arg-type]
        max_duration_s=limit_s,
        progress=None if progress is None else (lambda elapsed: progress(elapsed, expected_s)),
    )
    t = np.round(record.t_s, 6)
    eta = _tide_table(tide, t0, float(t[-1] - t0) + 60.0)
    eta_t = np.interp(t, eta.x0 + eta.step * np.arange(len(eta.values)), eta.values)

    # pressure (10 Hz): the sensor's depth below the instantaneous surface, through TEOS-10
    R = euler2rot(record.yaw_rad, record.pitch_rad, record.roll_rad)
    sensor_down = record.p_ned_m[:, 2] + (R @ config.vehicle.pressure.lever_arm_body_m)[:, 2]
    pressure = absolute_pressure_pa(
        sensor_down + eta_t,
        config.latitude_rad,
        config.atmospheric_pa,
        rng_pressure.standard_normal(t.size),
        sensors,
    )
    origin = GeodeticOrigin(config.latitude_rad, config.longitude_rad)
    gps = None
    if record.gps_t_s.size:
        lat, lon, _ = ned2geodetic(np.column_stack([record.gps_ne_m, np.zeros(record.gps_t_s.size)]), origin)
        gps = GpsStream(
            t_s=np.round(record.gps_t_s, 6),
            latitude_rad=lat,
            longitude_rad=lon,
            sigma_m=np.full(record.gps_t_s.size, config.vehicle.gps_sigma_m),
        )
    usbl = None
    if config.usbl and np.any(~record.at_surface):
        every = max(round(sensors.usbl_period_s / config.dt_s), 1)
        idx = np.flatnonzero(~record.at_surface)
        idx = idx[idx % every == 0]
        noise = sensors.usbl_sigma_m * rng_usbl.standard_normal((idx.size, 3))
        p = record.p_ned_m[idx] + noise
        lat, lon, _ = ned2geodetic(np.column_stack([p[:, :2], np.zeros(idx.size)]), origin)
        usbl = UsblStream(
            t_s=t[idx],
            latitude_rad=lat,
            longitude_rad=lon,
            depth_m=p[:, 2],
            sigma_m=np.full(idx.size, sensors.usbl_sigma_m),
        )
    info = DiveInfo(
        name=mission.name,
        origin=origin,
        start_time_s=t0,
        heading_reference="magnetic",
        declination_rad=earth.declination_rad,
        pressure_type="absolute",
        atmospheric_pa=config.atmospheric_pa,
    )
    dive = Dive(
        info=info,
        vehicle=config.vehicle,
        dvl=DvlStream(
            t_s=np.round(record.dvl_t_s, 6),
            v_sensor_mps=record.dvl_v_sensor_mps,
            altitude_m=record.dvl_altitude_m,
            valid=record.dvl_valid,
        ),
        attitude=AttitudeStream(
            t_s=t,
            heading_rad=record.compass_heading_rad,
            pitch_rad=record.pitch_measured_rad,
            roll_rad=record.roll_measured_rad,
        ),
        pressure=PressureStream(t_s=t, pressure_pa=pressure),
        magnetometer=MagnetometerStream(t_s=t, m_body=record.magnetometer_T),
        gps=gps,
        usbl=usbl,
    )
    trajectory = Trajectory(
        t_s=t,
        p_ned_m=record.p_ned_m,
        roll_rad=record.roll_rad,
        pitch_rad=record.pitch_rad,
        yaw_rad=record.yaw_rad,
    )
    onboard = Trajectory(
        t_s=t,
        p_ned_m=np.column_stack([record.onboard_ne_m, _onboard_depth(pressure, config)]),
        roll_rad=record.roll_measured_rad,
        pitch_rad=record.pitch_measured_rad,
        yaw_rad=record.onboard_yaw_rad,
    )
    h_deg = np.arange(360.0)
    deviation = np.column_stack([h_deg, np.degrees(deviation_table(config.iron, earth, np.radians(h_deg)))])
    surfacing = _surfacing_summary(record)
    horizontal_m = float(np.linalg.norm(np.diff(record.p_ned_m[:, :2], axis=0), axis=1).sum())
    summary = {
        "mission": mission.name,
        "completed": record.completed,
        "duration_s": round(float(t[-1] - t[0]), 6),
        "distance_m": trajectory.distance_m(),
        "horizontal_distance_m": horizontal_m,
        "surfacings": surfacing,
        "end_error_m": surfacing[-1]["error_m"] if surfacing else None,
        "end_error_pct": 100.0 * surfacing[-1]["error_m"] / horizontal_m
        if surfacing and horizontal_m > 0
        else None,
        "dvl_valid_fraction": float(np.mean(record.dvl_valid)) if record.dvl_valid.size else 0.0,
    }
    truth = _truth_dict(mission, config, earth, sensors, errors, misalignment_rpy, deviation, tide, summary)
    return Simulation(dive, trajectory, onboard, deviation, tide, truth, summary)


def _write_deviation(deviation: np.ndarray, path: Path) -> None:
    frame = pd.DataFrame({"compass_heading_deg": deviation[:, 0], "deviation_deg": deviation[:, 1]})
    write_table(frame, path)


def write_simulation(
    sim: Simulation, path: Path, *, overwrite: bool = False, fmt: Literal["csv", "parquet"] = "csv"
) -> Path:
    """Write the dive folder with its ``truth/`` (atomically; an existing folder needs ``overwrite``)."""

    def write_yaml(p: Path) -> None:
        p.write_text(yaml.safe_dump(sim.truth, sort_keys=False, width=100), encoding="utf-8")

    extra = {
        "truth/trajectory.csv": lambda p: write_trajectory(sim.trajectory, p),
        "truth/onboard.csv": lambda p: write_trajectory(sim.onboard, p),
        "truth/deviation.csv": lambda p: _write_deviation(sim.deviation_deg, p),
        "truth/tide.csv": lambda p: write_constituents(sim.tide, p),
        "truth/truth.yaml": write_yaml,
    }
    return write_dive(sim.dive, Path(path), fmt=fmt, overwrite=overwrite, extra=extra)


__all__ = [
    "SimConfig",
    "Simulation",
    "default_config",
    "run_scenario",
    "simulate",
    "write_simulation",
]


def run_scenario(
    scenario: str,
    out: Path,
    *,
    seed: int = 0,
    vehicle_seed: int = 0,
    deviation: Literal["none", "default"] = "default",
    tide: Literal["none", "default"] = "default",
    sensor_errors: Literal["none", "default"] = "default",
    compass_correction: Path | None = None,
    geometry: dict[str, Any] | None = None,
    max_duration_s: float | None = None,
    usbl: bool = False,
    overwrite: bool = False,
    progress: Callable[[float, float], None] | None = None,
    truth_loops: bool = False,
    false_loops: float = 0.0,
    image_rate_hz: float = 1.0,
    site_seed: int | None = None,
    days_later: float = 0.0,
    removed_cells: tuple[tuple[int, int], ...] = (),
) -> dict[str, Any]:
    """``auvnav simulate``: a generated mission (``navcheck|survey|transit|spin``) or a mission file,
    simulated and written as a dive folder; returns the summary.

    Parameters
    ----------
    scenario : str
        A mission kind or the path of an ``auvnav-mission/1`` file.
    out : Path
        The dive folder to write.
    seed, deviation, tide, sensor_errors
        As :func:`default_config`.
    vehicle_seed : int
        As :class:`SimConfig`: the same vehicle (same DVL mounting) for every dive that shares it.
    compass_correction : Path, optional
        A correction file the vehicle applies in real time.
    geometry : dict, optional
        The generator's options (None values are defaults); none are allowed with a mission file.
    max_duration_s : float, optional
        Cut the dive after this much vehicle time.
    usbl : bool
    overwrite : bool
    progress : callable, optional
        As :func:`simulate`.
    truth_loops : bool
        Also write loop closures from the truth (:func:`auvnav.sim.truthloops.write_truth_loops`).
    false_loops : float
        Fraction of them that are false, in [0, 1) (needs ``truth_loops``).
    image_rate_hz : float
        Camera trigger rate of the truth loops' image times when no images are rendered.
    site_seed, days_later, removed_cells
        A repeat survey of a site: the seafloor of the dive with seed ``site_seed`` (the same mission
        flown ``days_later`` days after the default start, so another tide; its own noise, GPS fixes
        and DVL errors from ``seed``), with the reef mounds of ``removed_cells`` gone
        (:class:`auvnav.sim.seafloor.SeafloorParams`, :func:`auvnav.sim.seafloor.tallest_mound`).

    Raises
    ------
    OutputExistsError
        ``out`` exists and ``overwrite`` is False (checked before simulating).
    ConfigError
        A bad mission file, a bad correction file, geometry options a mission does not take, or
        false loops without truth loops.
    """
    if false_loops and not truth_loops:
        raise ConfigError("--false-loops needs --truth-loops")
    given = {k: v for k, v in (geometry or {}).items() if v is not None}
    if Path(out).exists() and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    if scenario in KINDS:
        mission = build_mission(scenario, given)
    else:
        if given:
            names = ", ".join("--" + k.replace("_", "-") for k in sorted(given))
            raise ConfigError(f"{names}: geometry options apply to generated missions, not to {scenario}")
        if not Path(scenario).is_file():
            raise ConfigError(f"{scenario}: neither a mission kind ({', '.join(KINDS)}) nor a mission file")
        mission = read_mission(Path(scenario))
    correction = None if compass_correction is None else read_correction(compass_correction)
    config = default_config(
        seed=seed,
        vehicle_seed=vehicle_seed,
        deviation=deviation,
        tide=tide,
        sensor_errors=sensor_errors,
        compass_correction=correction,
        max_duration_s=max_duration_s,
        usbl=usbl,
        site_seed=site_seed,
        start_time_s=_posix(DEFAULT_START_TIME) + 86400.0 * days_later,
        seafloor=SeafloorParams(removed_cells=tuple((int(i), int(j)) for i, j in removed_cells)),
    )
    sim = simulate(mission, config, progress=progress)
    write_simulation(sim, Path(out), overwrite=overwrite)
    summary = {"dive": str(out), "seed": seed, **sim.summary}
    if truth_loops:
        summary["truth_loops"] = write_truth_loops(
            Path(out), false_fraction=false_loops, seed=seed, rate_hz=image_rate_hz
        )
    return summary
