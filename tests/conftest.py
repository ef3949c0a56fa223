"""Shared fixtures: the reference data folder and small helpers for every test module."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    """The folder named by AUVNAV_REFERENCE_DATA (``../shared/reference``); skip when unset."""
    value = os.environ.get("AUVNAV_REFERENCE_DATA")
    if not value:
        pytest.skip("AUVNAV_REFERENCE_DATA is not set")
    path = Path(value)
    if not path.is_dir():
        pytest.skip(f"AUVNAV_REFERENCE_DATA={value} is not a folder")
    return path


@pytest.fixture
def small_dive():
    """A factory for a small valid Dive: a 60 s circle at 0.5 m/s with every stream (no images)."""
    import numpy as np

    from auvnav.dive import (
        AttitudeStream,
        Dive,
        DiveInfo,
        DvlStream,
        GpsStream,
        MagnetometerStream,
        PressureStream,
    )
    from auvnav.frames import GeodeticOrigin
    from auvnav.vehicle import Vehicle

    def make(seconds: float = 60.0, start_s: float = 1_255_564_800.0) -> Dive:
        rng = np.random.default_rng(7)
        t = start_s + np.arange(0.0, seconds, 0.2)
        n = t.size
        yaw = np.angle(np.exp(1j * (0.05 * (t - start_s) + 0.3)))
        return Dive(
            info=DiveInfo(
                name="small",
                origin=GeodeticOrigin.from_degrees(-14.05, 121.78),
                start_time_s=start_s,
                declination_rad=float(np.radians(1.7)),
            ),
            vehicle=Vehicle(name="test"),
            dvl=DvlStream(
                t,
                np.column_stack([np.full(n, 0.5), rng.normal(0, 0.003, (n, 2))]),
                np.full(n, 2.0),
                np.ones(n, bool),
            ),
            attitude=AttitudeStream(t, yaw, rng.normal(0, 0.01, n), rng.normal(0, 0.01, n)),
            pressure=PressureStream(t, 101325.0 + 2.0e5 + rng.normal(0, 100, n)),
            magnetometer=MagnetometerStream(t, rng.normal(0, 1e-5, (n, 3))),
            gps=GpsStream(
                t[:5], np.radians(np.full(5, -14.05)), np.radians(np.full(5, 121.78)), np.full(5, 3.0)
            ),
        )

    return make


@dataclass(frozen=True)
class FlatFloor:
    """A horizontal seafloor at ``base_m`` metres (the simulator's seafloor interface)."""

    base_m: float = 20.0

    def depth_m(self, north_m, east_m):
        import numpy as np

        return np.full(np.broadcast_shapes(np.shape(north_m), np.shape(east_m)), self.base_m)


@pytest.fixture(scope="session")
def level_floor() -> type[FlatFloor]:
    """The class of a horizontal seafloor: ``level_floor(depth_m)``."""
    return FlatFloor
