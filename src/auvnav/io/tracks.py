"""The trajectory an exporter writes: SLAM's, the filter's or dead reckoning, from the products."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from auvnav import products as P
from auvnav.errors import InsufficientDataError
from auvnav.frames import GeodeticOrigin, ned2geodetic
from auvnav.trajectory import Trajectory, read_trajectory
from auvnav.vision.loopfile import LoopClosures, loops_file, read_loops

SOURCES = {"slam": P.SLAM_TRAJECTORY, "filter": P.NAV_FILTER, "dr": P.NAV_DR}


def read_track(dive: Path, source: str = "auto") -> tuple[Trajectory, str]:
    """A dive's trajectory and its name: ``source``'s, or with ``auto`` the best there is (SLAM, then
    the filter, then dead reckoning).

    Raises
    ------
    InsufficientDataError
        The dive has no such product (the message says which command makes it).
    """
    dive = Path(dive)
    names = list(SOURCES) if source == "auto" else [source]
    for name in names:
        path = SOURCES[name].path(dive)
        if path.is_file():
            return read_trajectory(path), name
    wanted = " or ".join(str(SOURCES[n].path(dive)) for n in names)
    raise InsufficientDataError(f"{wanted}: no trajectory to export; run `auvnav process {dive}` first")


def read_loop_closures(dive: Path) -> LoopClosures | None:
    """The dive's loop closures (``products/vision/loops.csv``), or None."""
    path = loops_file(Path(dive))
    return None if path is None else read_loops(path)


def geodetic(track: Trajectory, origin: GeodeticOrigin) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude of a trajectory's positions, degrees (WGS84)."""
    p = track.p_ned_m.copy()
    p[:, 2] = 0.0
    lat, lon, _ = ned2geodetic(p, origin)
    return np.degrees(np.reshape(lat, -1)), np.degrees(np.reshape(lon, -1))


def nonconsecutive(loops: LoopClosures) -> np.ndarray:
    """Mask of the loop closures between non-consecutive images (the revisits)."""
    return np.asarray(loops.j) - np.asarray(loops.i) > 1
