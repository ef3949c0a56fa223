"""Closed-loop simulation: the compass against eq. 2-4, dead reckoning against the truth and the DVL
specification, the accordion, the tide in the pressure record, determinism, and the command."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from auvnav.cli import main
from auvnav.compass.correction import write_correction
from auvnav.compass.deviation import DeviationModel, fourier_design
from auvnav.compass.field import earth_field
from auvnav.compass.magnetometer import deviation_from_iron
from auvnav.depth.pressure import depth_from_pressure
from auvnav.dive import validate_dive
from auvnav.frames import angle_diff
from auvnav.plan.missions import Descend, Mission, Spin, Surface, survey, survey_line_spacing, transit
from auvnav.sim.run import Simulation, default_config, run_scenario, simulate
from auvnav.sim.seafloor import Seafloor, SeafloorParams
from auvnav.sim.sensors import SensorModels
from auvnav.trajectory import read_trajectory
from auvnav.vehicle import Vehicle

SHALLOW = SeafloorParams(mean_depth_m=12.0)  # short descents for fast tests
SMALL_SURVEY = survey(width_m=20.0, height_m=3.0, lead_in_m=5.0)


def spacing(sim: Simulation, mission: Mission, track: str = "trajectory") -> np.ndarray:
    p = getattr(sim, track).p_ned_m[:, :2]
    return survey_line_spacing(p, sim.onboard.p_ned_m[:, :2], mission, margin_m=5.0)


@pytest.fixture(scope="module")
def spin_sim() -> Simulation:
    mission = Mission("spin", (Surface(10.0), Descend(), Spin(turns=1.1, rate_rad_s=math.radians(10.0))))
    return simulate(mission, default_config(seed=1, sensor_errors="none", seafloor=SHALLOW))


def test_compass_deviation_is_eq_2_to_4(spin_sim: Simulation) -> None:
    """Acceptance: the simulated compass's deviation over 360 deg equals eq. 2-4's, to 0.01 deg."""
    truth, att = spin_sim.trajectory, spin_sim.dive.attitude
    iron = default_config().iron
    declination = spin_sim.dive.info.declination_rad
    assert declination is not None
    true_magnetic = truth.yaw_rad - declination
    simulated = angle_diff(att.heading_rad, true_magnetic)
    field = earth_field(
        spin_sim.dive.info.origin.latitude_rad, spin_sim.dive.info.origin.longitude_rad, truth.t_s[0]
    )
    implied = deviation_from_iron(
        iron.H_soft, iron.h_hard_body_T, field, true_magnetic, truth.pitch_rad, truth.roll_rad
    )
    np.testing.assert_allclose(np.degrees(simulated), np.degrees(implied), atol=0.01)
    covered = np.unique(np.floor(np.degrees(true_magnetic) % 360.0 / 10.0))
    assert covered.size == 36  # every heading sector
    assert np.ptp(np.degrees(implied)) > 2.0  # and the deviation is there to see


def test_truth_deviation_curve(spin_sim: Simulation) -> None:
    """truth/deviation.csv: 360 rows, true magnetic = h + delta(h), checked on the spin's level-ish samples."""
    table = spin_sim.deviation_deg
    assert table.shape == (360, 2)
    np.testing.assert_array_equal(table[:, 0], np.arange(360.0))
    h = spin_sim.dive.attitude.heading_rad
    declination = spin_sim.dive.info.declination_rad
    true_magnetic = spin_sim.trajectory.yaw_rad - declination
    turning = spin_sim.trajectory.t_s > spin_sim.trajectory.t_s[-1] - 36.0  # the spin itself
    delta = np.interp(np.degrees(h[turning]) % 360.0, table[:, 0], table[:, 1], period=360.0)
    residual = np.degrees(angle_diff(true_magnetic[turning], h[turning])) - delta
    assert np.abs(residual).max() < 0.15  # the table is level; the vehicle pitches and rolls a little


def test_vehicle_is_passively_stable(spin_sim: Simulation) -> None:
    truth = spin_sim.trajectory
    pitch, roll = np.degrees(truth.pitch_rad), np.degrees(truth.roll_rad)
    for a in (pitch, roll):
        assert 0.2 < np.std(a) < 3.0 and np.abs(a).max() < 6.0
    level = np.abs(np.gradient(truth.p_ned_m[:, 2], truth.t_s)) < 0.01  # not descending
    assert np.mean(pitch[level]) > 0.3  # trimmed nose up, not zero
    assert np.mean(pitch[~level]) < np.mean(pitch[level]) - 0.5  # nose down while descending


def test_dead_reckoning_without_errors_is_the_truth() -> None:
    """With every sensor exact and no deviation, onboard DR reproduces the truth (DVL at 10 Hz: to a mm;
    at its 5 Hz ping rate the sampling of speed changes in turns leaves centimetres)."""
    exact = dataclasses.replace(SensorModels.from_vehicle(Vehicle()), dvl_rate_hz=10.0)
    for sensors, tolerance_m in ((exact, 0.002), (None, 0.05)):
        config = default_config(
            seed=2, deviation="none", sensor_errors="none", sensors=sensors, seafloor=SHALLOW
        )
        sim = simulate(SMALL_SURVEY, config)
        error = np.linalg.norm(sim.onboard.p_ned_m[:, :2] - sim.trajectory.p_ned_m[:, :2], axis=1)
        assert error.max() < tolerance_m
        assert sim.summary["horizontal_distance_m"] > 80.0


def test_transit_dead_reckoning_within_dvl_specification() -> None:
    """Acceptance: with --deviation none, DR over each transit leg stays within what the RDI Workhorse
    specification allows (long-term accuracy +-0.2% +-1 mm/s: 0.002 x distance + 0.001 m/s x time)."""
    sim = simulate(transit(legs=2, leg_m=300.0), default_config(seed=0, deviation="none", seafloor=SHALLOW))
    truth, onboard = sim.trajectory, sim.onboard
    error = onboard.p_ned_m[:, :2] - truth.p_ned_m[:, :2]
    surfaced = np.searchsorted(truth.t_s, [s["t_s"] for s in sim.summary["surfacings"]])
    under = truth.p_ned_m[:, 2] > 1.0
    assert len(surfaced) == 2
    start = 0
    for end in surfaced:
        dive_start = start + int(np.flatnonzero(under[start:end])[0])  # onboard was reset to GPS here
        distance = np.linalg.norm(np.diff(truth.p_ned_m[dive_start:end, :2], axis=0), axis=1).sum()
        duration = truth.t_s[end] - truth.t_s[dive_start]
        drift = np.linalg.norm(error[end] - error[dive_start])
        assert distance > 290.0
        assert drift < 0.002 * distance + 0.001 * duration
        start = end + 1


@pytest.fixture(scope="module")
def accordion() -> dict[str, np.ndarray]:
    """Line spacing of a small survey flown north-first and south-first, with and without deviation."""
    out = {}
    for heading in (0.0, 180.0):
        mission = survey(width_m=20.0, height_m=3.0, lead_in_m=5.0, heading_deg=heading)
        for deviation in ("default", "none"):
            sim = simulate(mission, default_config(seed=3, deviation=deviation, seafloor=SHALLOW))
            out[f"{heading:.0f} {deviation}"] = spacing(sim, mission)
            out[f"{heading:.0f} {deviation} onboard"] = spacing(sim, mission, "onboard")
            out[f"{heading:.0f} {deviation} deviation"] = sim.deviation_deg[:, 1]
            out[f"{heading:.0f} {deviation} declination"] = np.degrees(sim.dive.info.declination_rad)
    return out


def test_accordion_and_figure_8_emerge(accordion: dict[str, np.ndarray]) -> None:
    """A compass deviation bends the true lines while the onboard lines keep the planned 1 m.

    The vehicle steers its compass heading h to the line; it truly heads h + delta(h). Reciprocal lines
    drift across by delta(h_north) - delta(h_south) per metre between them, so adjacent lines open
    (accordion) or close (figure 8) on average by W/2 x tan(difference) (W = 20 m line length), with
    the sign set by which way the survey steps.
    """
    delta = accordion["0 default deviation"]
    declination = float(accordion["0 default declination"])
    h_north, h_south = round(-declination) % 360, round(180 - declination) % 360
    opening = 10.0 * math.tan(math.radians(delta[h_north] - delta[h_south]))
    assert opening > 0.3  # the injected deviation makes a visible effect
    north_first, south_first = accordion["0 default"], accordion["180 default"]
    assert np.nanmean(north_first) - 1.0 == pytest.approx(opening, rel=0.3)  # accordion
    assert np.nanmean(south_first) - 1.0 == pytest.approx(-opening, rel=0.3)  # figure 8
    for key in ("0 default onboard", "180 default onboard", "0 none", "180 none"):
        assert np.nanmax(np.abs(accordion[key] - 1.0)) < 0.15, key  # on plan, or no deviation


def test_correction_straightens_the_lines(tmp_path: Path) -> None:
    """With the true deviation as its correction file (eq. 5), the vehicle flies the planned spacing."""
    uncorrected = simulate(SMALL_SURVEY, default_config(seed=4, seafloor=SHALLOW))
    h, delta = np.radians(uncorrected.deviation_deg[:, 0]), np.radians(uncorrected.deviation_deg[:, 1])
    x = np.linalg.lstsq(fourier_design(h, 3), delta, rcond=None)[0]  # eq. 5-6 fitted to the truth
    path = tmp_path / "correction.yaml"
    write_correction(DeviationModel.from_coefficients(x, constant_source="truth"), path)
    out = tmp_path / "dive"
    geometry = {"width_m": 20.0, "height_m": 3.0, "lead_in_m": 5.0}
    run_scenario("survey", out, seed=4, compass_correction=path, geometry=geometry)
    truth = yaml.safe_load((out / "truth" / "truth.yaml").read_text(encoding="utf-8"))
    assert truth["compass"]["correction_applied"]["a0_deg"] == pytest.approx(math.degrees(x[0]))
    true_ne = read_trajectory(out / "truth" / "trajectory.csv").p_ned_m[:, :2]
    onboard_ne = read_trajectory(out / "truth" / "onboard.csv").p_ned_m[:, :2]
    corrected = survey_line_spacing(true_ne, onboard_ne, SMALL_SURVEY, margin_m=5.0)
    assert abs(np.nanmean(spacing(uncorrected, SMALL_SURVEY)) - 1.0) > 0.3
    assert np.nanmax(np.abs(corrected - 1.0)) < 0.15


def test_pressure_carries_the_tide() -> None:
    """Exact sensors: depth from pressure (TEOS-10) minus true depth is the tide, eta(t)."""
    sim = simulate(SMALL_SURVEY, default_config(seed=5, sensor_errors="none", seafloor=SHALLOW))
    p = sim.dive.pressure
    depth = depth_from_pressure(
        p.pressure_pa - sim.dive.info.atmospheric_pa, sim.dive.info.origin.latitude_rad
    )
    eta = sim.tide.predict(p.t_s)
    np.testing.assert_allclose(depth - sim.trajectory.p_ned_m[:, 2], eta, atol=1e-4)
    assert np.ptp(eta) > 0.02  # the tide moves during the dive
    np.testing.assert_allclose(sim.onboard.p_ned_m[:, 2], depth)  # onboard: no tide correction


def test_dvl_dropouts_and_altitude() -> None:
    """Bottom track is lost beyond 30 m altitude (the default 45 m site); the vehicle holds 2 m."""
    sim = simulate(SMALL_SURVEY, default_config(seed=6))
    dvl = sim.dive.dvl
    truth = sim.trajectory.interpolate(dvl.t_s)
    altitude = Seafloor(6).depth_m(truth.p_ned_m[:, 0], truth.p_ned_m[:, 1]) - truth.p_ned_m[:, 2]
    np.testing.assert_array_equal(dvl.valid, (altitude >= 0.5) & (altitude <= 30.0))
    assert 0.2 < np.mean(~dvl.valid) < 0.8  # surface and the first 15 m of the descent
    assert np.all(dvl.v_sensor_mps[~dvl.valid] == 0.0)
    on_lines = dvl.valid & (np.linalg.norm(dvl.v_sensor_mps[:, :2], axis=1) > 0.3)
    assert np.abs(dvl.altitude_m[on_lines] - 2.0).max() < 0.7
    assert np.sqrt(np.mean((dvl.altitude_m[on_lines] - 2.0) ** 2)) < 0.25
    gps = sim.dive.gps
    assert gps is not None and 200 <= len(gps) <= 260  # 1 Hz during two 2-minute surface waits


def _dive_files(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    geometry = {"width_m": 4.0, "height_m": 1.0, "lead_in_m": 2.0}
    for name, seed in (("a", 9), ("b", 9), ("c", 10)):
        run_scenario("survey", tmp_path / name, seed=seed, geometry=geometry, max_duration_s=500.0)
    a, b, c = (_dive_files(tmp_path / n) for n in "abc")
    assert set(a) >= {"dive.yaml", "nav/dvl.csv", "truth/trajectory.csv", "truth/truth.yaml"}
    assert a == b
    for f in ("nav/dvl.csv", "nav/attitude.csv", "nav/pressure.csv", "truth/trajectory.csv"):
        assert a[f] != c[f], f
    assert validate_dive(tmp_path / "a").ok


def test_simulate_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "dive"
    args = [
        "simulate",
        "survey",
        "--out",
        str(out),
        "--width-m",
        "4",
        "--height-m",
        "1",
        "--lead-in-m",
        "2",
        "--no-images",
    ]
    assert main([*args, "--seed", "3", "--tide", "none", "--usbl", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["completed"] and summary["end_error_m"] < 10.0
    report = validate_dive(out)
    assert report.ok and report.dive is not None and report.dive.usbl is not None
    assert (out / "truth" / "onboard.csv").is_file() and (out / "truth" / "tide.csv").is_file()
    assert main([*args, "-q"]) == 1  # exists
    assert "exists (use --overwrite" in capsys.readouterr().err
    assert main(["simulate", "survey", "--out", str(tmp_path / "x"), "--headings", "6"]) == 1
    assert "--headings: not an option of the survey mission" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: auvnav-mission/1\nsegments: [{type: line}]\n", encoding="utf-8")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "y")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0] and "waypoints" in err[0]
    assert main(["simulate", "nowhere.yaml", "--out", str(tmp_path / "z")]) == 1
    assert "neither a mission kind" in capsys.readouterr().err
