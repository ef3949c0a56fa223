"""The trajectory an exporter writes: SLAM's, the filter's or dead reckoning, from the products."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from auvnav import products as P
from auvnav.dive import Dive, read_dive
from auvnav.errors import ConfigError, InsufficientDataError
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


@dataclass(frozen=True)
class CameraTrack:
    """The left camera at every stereo pair inside a trajectory.

    Parameters
    ----------
    dive : Dive
    source : str
        The trajectory's name (slam, filter, dr).
    inside : ndarray of bool, (N,)
        The dive's stereo pairs that lie inside the trajectory's time span.
    at : Trajectory
        The vehicle's trajectory at those pairs.
    R_ned_cam : ndarray, (n, 3, 3)
        The left camera's orientation.
    p_ned_cam_m : ndarray, (n, 3)
        The left camera's optical centre, metres, local NED.
    """

    dive: Dive
    source: str
    inside: np.ndarray
    at: Trajectory
    R_ned_cam: np.ndarray
    p_ned_cam_m: np.ndarray


def camera_track(dive_path: Path, source: str, fmt: str) -> CameraTrack:
    """Where the left camera was at each stereo pair, for the exporter ``fmt``.

    Raises
    ------
    InsufficientDataError
        The dive has no stereo pairs, no such trajectory, or no pair inside it.
    ConfigError
        The vehicle has no stereo rig.
    """
    from auvnav.vision.camera import T_body_cam

    dive = read_dive(dive_path)
    if dive.images is None or len(dive.images) == 0:
        raise InsufficientDataError(f"{dive_path}/images/index.csv: {fmt} needs the stereo pairs")
    rig = dive.vehicle.stereo
    if rig is None:
        raise ConfigError(f"{dive_path}/{dive.info.vehicle_file}: {fmt} needs the stereo rig (key stereo)")
    track, name = read_track(dive_path, source)
    t = dive.images.t_s
    inside = (t >= track.t_s[0]) & (t <= track.t_s[-1])
    if not inside.any():
        raise InsufficientDataError(f"{dive_path}: no stereo pair inside the {name} trajectory's time span")
    at = track.interpolate(t[inside])
    T_bc = T_body_cam(rig)
    return CameraTrack(
        dive, name, inside, at, at.R_ned_body @ T_bc[:3, :3], at.p_ned_m + at.R_ned_body @ T_bc[:3, 3]
    )


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
