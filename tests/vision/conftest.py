"""A tiny simulated dive with images, shared by the vision tests (rendered once per session).

The vehicle flies 3.5 m north, turns, and flies back 0.3 m to the east of its outbound track over a
gently undulating stand-in seafloor, so the return images overlap the outbound ones (loop closures).
Images are 340 x 256 (a quarter of the Sirius cameras' size).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from auvnav.dive import AttitudeStream, Dive, DiveInfo, DvlStream, PressureStream, write_dive
from auvnav.frames import GeodeticOrigin
from auvnav.sim.camera import default_stereo_rig, render_images, scale_camera_rig
from auvnav.trajectory import Trajectory, write_trajectory
from auvnav.vehicle import Vehicle

IMAGE_SCALE = 0.25
START_S = 1_255_564_800.0


@dataclass(frozen=True)
class WavyFloor:
    """A stand-in seafloor: 20 m deep, a slope and a few gentle undulations (anything with depth_m)."""

    base_m: float = 20.0

    def depth_m(self, north_m, east_m):
        n, e = np.asarray(north_m, dtype=float), np.asarray(east_m, dtype=float)
        return (
            self.base_m
            + 0.01 * n
            + 0.12 * np.sin(n / 1.3) * np.cos(e / 1.7)
            + 0.03 * np.sin(3.1 * n + 2.3 * e)
        )


def out_and_back(seconds: float = 20.0) -> Trajectory:
    """10 Hz truth: 7 s north at 0.5 m/s, a 6 s turn to the east, 7 s back south, 2 m above the floor."""
    t = np.arange(0.0, seconds, 0.1)
    turn = np.pi * (t - 7) / 6
    north = np.where(t < 7, 0.5 * t, np.where(t < 13, 3.5 + 0.15 * np.sin(turn), 3.5 - 0.5 * (t - 13)))
    east = np.where(t < 7, 0.0, np.where(t < 13, 0.15 * (1 - np.cos(turn)), 0.3))
    yaw = np.where(t < 7, 0.0, np.where(t < 13, turn, np.pi))
    floor = WavyFloor()
    down = floor.depth_m(north, east) - 2.0
    rng = np.random.default_rng(1)
    roll = 0.01 * np.sin(0.3 * t) + rng.normal(0, 1e-4, t.size)
    pitch = 0.01 * np.cos(0.2 * t)
    return Trajectory(
        START_S + t, np.column_stack([north, east, down]), roll, pitch, np.angle(np.exp(1j * yaw))
    )


@dataclass(frozen=True)
class TinyDive:
    path: Path
    truth: Trajectory
    floor: WavyFloor


@pytest.fixture(scope="session")
def tiny_dive(tmp_path_factory) -> TinyDive:
    """The dive folder (with images, truth and a drifting navigation prior in products/nav/filter.csv)."""
    root = tmp_path_factory.mktemp("vision") / "dive"
    truth = out_and_back()
    floor = WavyFloor()
    rig = scale_camera_rig(default_stereo_rig(), IMAGE_SCALE)
    n = len(truth)
    alt = floor.depth_m(truth.p_ned_m[:, 0], truth.p_ned_m[:, 1]) - truth.p_ned_m[:, 2]
    dive = Dive(
        info=DiveInfo("tiny", GeodeticOrigin.from_degrees(-14.05, 121.78), START_S, declination_rad=0.0),
        vehicle=Vehicle(name="tiny", stereo=rig),
        dvl=DvlStream(truth.t_s, np.tile([0.5, 0.0, 0.0], (n, 1)), alt, np.ones(n, bool)),
        attitude=AttitudeStream(truth.t_s, truth.yaw_rad, truth.pitch_rad, truth.roll_rad),
        pressure=PressureStream(truth.t_s, 101325.0 + 1e4 * truth.p_ned_m[:, 2]),
    )
    write_dive(dive, root)
    times = START_S + np.arange(0.5, 20.0, 1.0)
    render_images(truth, floor, rig, times, root / "images", seed=3)
    write_trajectory(truth, root / "truth" / "trajectory.csv")
    # The navigation prior: the truth plus a drift of 2% of the distance travelled, to the east.
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(truth.p_ned_m[:, :2], axis=0), axis=1))])
    p = truth.p_ned_m + np.column_stack([0.2 * np.ones(n), 0.02 * s, np.zeros(n)])
    sigma = np.column_stack([0.5 + 0.02 * s, 0.5 + 0.02 * s, np.full(n, 0.1)])
    prior = Trajectory(truth.t_s, p, truth.roll_rad, truth.pitch_rad, truth.yaw_rad, sigma, np.full(n, 0.02))
    write_trajectory(prior, root / "products" / "nav" / "filter.csv")
    return TinyDive(root, truth, floor)


@pytest.fixture
def flat_floor(level_floor):
    """A level seafloor 20 m down."""
    return level_floor(20.0)
