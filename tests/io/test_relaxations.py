"""What real logs lack (issue 15): gap warnings relative to each stream's own rate, a DVL log without
altitude (the loop stage falls back to the stereo range), an explicit heading reference."""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from auvnav.dive import DvlStream, read_dive
from auvnav.errors import InsufficientDataError
from auvnav.io import import_dive
from auvnav.nav.inputs import nav_inputs
from auvnav.nav.synthetic import lawnmower_legs, legs_motion, synthetic_dive


@pytest.fixture(scope="module")
def slow_log():
    """A dive logged every 8 s, as some vehicles' navigation logs are."""
    motion = legs_motion(lawnmower_legs(2, 200.0, 20.0), rate_hz=1 / 8.0, turn_rate_rps=0.02)
    return synthetic_dive(motion, gps_times_s=motion.truth.t_s[:1])


def test_gaps_are_relative_to_the_stream_rate(slow_log, caplog) -> None:
    """An 8 s log has no gap at every sample (the fixed 5 s threshold warned 1180 times on a real
    one); a hole of ten samples is still reported."""
    with caplog.at_level(logging.WARNING, logger="auvnav.nav.inputs"):
        nav_inputs(slow_log)
    assert "gap(s)" not in caplog.text
    keep = np.ones(len(slow_log.attitude), dtype=bool)
    keep[20:30] = False
    holed = dataclasses.replace(slow_log, attitude=slow_log.attitude.select(keep))
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="auvnav.nav.inputs"):
        nav_inputs(holed)
    assert "nav/attitude: 1 gap(s) longer than 5 median periods (40 s), the longest 88.0 s" in caplog.text


def test_dvl_without_altitude_imports_and_navigates(tmp_path: Path) -> None:
    """A vendor CSV with no altitude column gives a valid dive with no altitude_m; the summary says
    what needs it."""
    t = 1255568400.0 + 0.2 * np.arange(200)
    rows = "\n".join(f"{x!r},0.5,0.0,0.0,{30.0 + 0.01 * k!r},0.5,-0.2,1.0" for k, x in enumerate(t.tolist()))
    data = tmp_path / "nav.csv"
    data.write_text("t,vx,vy,vz,heading,pitch,roll,depth\n" + rows + "\n", encoding="utf-8")
    mapping = tmp_path / "map.yaml"
    mapping.write_text(
        """heading_reference: true
origin: {latitude_deg: -14.05, longitude_deg: 121.78}
files:
  nav.csv:
    time: {column: t, format: posix_s}
    dvl: {vx: {column: vx, unit: m/s}, vy: {column: vy, unit: m/s}, vz: {column: vz, unit: m/s}}
    attitude: {heading: {column: heading, unit: deg}, pitch: {column: pitch, unit: deg}, roll: {column: roll, unit: deg}}
    pressure: {depth: {column: depth, unit: m}}
""",
        encoding="utf-8",
    )
    summary = import_dive("csv", [data], tmp_path / "dive", config=mapping)
    assert any("no DVL altitude" in n for n in summary["notes"])
    assert summary["heading_reference"] == "true" and summary["declination_deg"] is None
    assert summary["pressure"]["type"] == "sea"
    dive = read_dive(tmp_path / "dive")
    assert dive.dvl.altitude_m is None
    assert dive.pressure.pressure_pa[0] == pytest.approx(1.0e4, rel=0.02)  # 1 m: about 1 dbar
    inputs = nav_inputs(dive)
    assert inputs.v_body_mps[:, 0] == pytest.approx(0.5)


def test_image_altitude_falls_back_to_the_stereo_range(slow_log) -> None:
    from auvnav.vision.loops import dvl_altitude_available, image_altitude

    t = slow_log.dvl.t_s
    no_alt = dataclasses.replace(
        slow_log, dvl=DvlStream(t, slow_log.dvl.v_sensor_mps, None, slow_log.dvl.valid)
    )
    assert dvl_altitude_available(slow_log) and not dvl_altitude_available(no_alt)
    np.testing.assert_allclose(image_altitude(slow_log, t[:3]), 2.0)
    with pytest.raises(InsufficientDataError, match="no altitude_m column; cannot place image footprints"):
        image_altitude(no_alt, t[:3])
    stereo = (t[[0, -1]], np.array([1.5, 2.5]))
    np.testing.assert_allclose(image_altitude(no_alt, t[[0, -1]], stereo=stereo), [1.5, 2.5])


def test_stereo_altitude_of_a_flat_floor(tmp_path: Path) -> None:
    """Points of a level floor 2 m below the vehicle give 2 m (the camera sits 0.3 m down)."""
    from auvnav.frames import euler2rot
    from auvnav.sim.camera import default_stereo_rig
    from auvnav.vision.camera import rectification
    from auvnav.vision.loops import stereo_altitude
    from auvnav.vision.stereo import StereoFeatures, write_features

    rig = default_stereo_rig()
    rect = rectification(rig)
    u, v = np.meshgrid(np.linspace(200, 1100, 12), np.linspace(200, 800, 9))
    depth_cam = 2.0 - rig.mount.lever_arm_body_m[2]
    disparity = rect.f_px * rect.baseline_m / depth_cam
    uv = np.column_stack([u.ravel(), v.ravel(), u.ravel() - disparity, v.ravel()])
    n = len(uv)
    features = StereoFeatures(uv, np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 128), np.uint8))
    path = tmp_path / "pair.feat"
    write_features(features, rect, path)
    level = euler2rot(np.array([0.3]), np.array([0.0]), np.array([0.0]))
    altitude = stereo_altitude([str(path)], rig, level)
    assert altitude[0] == pytest.approx(2.0, abs=0.01)
    tilted = euler2rot(np.array([0.3]), np.array([math.radians(10)]), np.array([0.0]))
    assert stereo_altitude([str(path)], rig, tilted)[0] != pytest.approx(
        2.0, abs=0.01
    )  # levelled with the attitude
