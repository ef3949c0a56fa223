"""A tiny simulated dive with images and a revisit 20 minutes later, shared by the reconstruction tests.

The vehicle flies 3 m north over a gently undulating stand-in seafloor textured as the simulator's
reef, waits 20 minutes to the east, and flies back south over the same strip; 14 stereo pairs of 340 x
256 (a quarter of the Sirius cameras' size). The tide rises about 0.17 m between the two passes. The SLAM
trajectory is the truth (depth below the datum); the navigation filter's depth is pressure depth (the
truth plus the tide), as a real vehicle's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from auvnav.depth.tide import Constituent, TideModel, write_constituents
from auvnav.dive import AttitudeStream, Dive, DiveInfo, DvlStream, PressureStream, write_dive
from auvnav.frames import GeodeticOrigin
from auvnav.sim.camera import default_stereo_rig, render_images, scale_camera_rig
from auvnav.sim.texture import SeafloorTexture
from auvnav.trajectory import Trajectory, write_trajectory
from auvnav.vehicle import Vehicle

IMAGE_SCALE = 0.25
START_S = 1_255_564_800.0
WAIT_S = 1250.0  # between the passes: more than the 20 minutes of the false-relief check
ORIGIN = GeodeticOrigin.from_degrees(-14.05, 121.78)  # UTM zone 51 south: EPSG:32751


@dataclass(frozen=True)
class WavyFloor:
    """A stand-in seafloor: 20 m deep, a slope and gentle undulations (anything with depth_m)."""

    def depth_m(self, north_m, east_m):
        n, e = np.asarray(north_m, dtype=float), np.asarray(east_m, dtype=float)
        return 20.0 + 0.01 * n + 0.12 * np.sin(n / 1.3) * np.cos(e / 1.7) + 0.03 * np.sin(3.1 * n + 2.3 * e)


def passes() -> Trajectory:
    """10 Hz truth: 6 s north at 0.5 m/s, a slow turn east while waiting, 6 s back south 0.2 m east."""
    t = np.arange(0.0, 12.0 + WAIT_S + 0.05, 0.1)
    back = 6.0 + WAIT_S
    turn = np.clip((t - 6.0) / WAIT_S, 0.0, 1.0)
    north = np.where(t < 6, 0.5 * t, np.where(t < back, 3.0, 3.0 - 0.5 * (t - back)))
    east = 0.2 * turn
    yaw = np.pi * turn
    down = WavyFloor().depth_m(north, east) - 2.0
    roll = 0.01 * np.sin(0.3 * t)
    pitch = 0.01 * np.cos(0.2 * t)
    return Trajectory(
        START_S + t, np.column_stack([north, east, down]), roll, pitch, np.angle(np.exp(1j * yaw))
    )


@dataclass(frozen=True)
class ReconDive:
    path: Path
    truth: Trajectory
    floor: WavyFloor
    texture: SeafloorTexture
    tide: TideModel
    tide_file: Path


@pytest.fixture(scope="session")
def recon_dive(tmp_path_factory) -> ReconDive:
    root = tmp_path_factory.mktemp("recon") / "dive"
    truth = passes()
    floor = WavyFloor()
    texture = SeafloorTexture(seed=5)
    rig = scale_camera_rig(default_stereo_rig(), IMAGE_SCALE)
    tide = TideModel((Constituent("M2", 1.0, 0.0),), ORIGIN.latitude_rad, "test")
    eta = tide.predict(truth.t_s)
    n = len(truth)
    alt = floor.depth_m(truth.p_ned_m[:, 0], truth.p_ned_m[:, 1]) - truth.p_ned_m[:, 2]
    dive = Dive(
        info=DiveInfo("revisit", ORIGIN, START_S, declination_rad=0.0),
        vehicle=Vehicle(name="tiny", stereo=rig),
        dvl=DvlStream(truth.t_s, np.tile([0.5, 0.0, 0.0], (n, 1)), alt, np.ones(n, bool)),
        attitude=AttitudeStream(truth.t_s, truth.yaw_rad, truth.pitch_rad, truth.roll_rad),
        pressure=PressureStream(truth.t_s, 101325.0 + 1e4 * (truth.p_ned_m[:, 2] + eta)),
    )
    write_dive(dive, root)
    times = START_S + np.concatenate([np.arange(0.25, 6.0, 0.8), 6.0 + WAIT_S + np.arange(0.25, 6.0, 0.8)])
    render_images(truth, floor, rig, times, root / "images", texture=texture, seed=3)
    write_trajectory(truth, root / "truth" / "trajectory.csv")
    write_trajectory(truth, root / "products" / "slam" / "trajectory.csv")
    pressure = Trajectory(
        truth.t_s, truth.p_ned_m + np.column_stack([np.zeros((n, 2)), eta]), truth.roll_rad, truth.pitch_rad,
        truth.yaw_rad,
    )  # fmt: skip
    write_trajectory(pressure, root / "products" / "nav" / "filter.csv")
    tide_file = root / "tide.csv"
    write_constituents(tide, tide_file)
    return ReconDive(root, truth, floor, texture, tide, tide_file)
