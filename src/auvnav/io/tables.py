"""The trajectory as a CSV with latitude, longitude and sigmas (``auvnav export DIVE csv``).

Columns: ``t`` (POSIX s), ``time_utc`` (ISO 8601), ``latitude_deg``, ``longitude_deg`` (WGS84),
``depth_m``, ``north_m``, ``east_m``, ``down_m`` (local NED about the dive's origin),
``roll_deg``, ``pitch_deg``, ``yaw_deg`` (Euler ZYX, yaw from true north), and, when the trajectory
has them (SLAM, the filter), ``sigma_north_m``, ``sigma_east_m``, ``sigma_down_m``,
``sigma_yaw_deg`` (1 sigma).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from auvnav.dive import read_dive_info
from auvnav.io.tracks import geodetic, read_track
from auvnav.streams import write_table


def export_csv(dive: Path, out: Path, options: Any) -> dict[str, Any]:
    """Write the trajectory with latitude, longitude and sigmas."""
    info = read_dive_info(dive)
    track, source = read_track(dive, options.source)
    lat, lon = geodetic(track, info.origin)
    frame = pd.DataFrame(
        {
            "t": track.t_s,
            "time_utc": pd.to_datetime(track.t_s, unit="s", utc=True).strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
            "latitude_deg": lat,
            "longitude_deg": lon,
            "depth_m": track.p_ned_m[:, 2],
            "north_m": track.p_ned_m[:, 0],
            "east_m": track.p_ned_m[:, 1],
            "down_m": track.p_ned_m[:, 2],
            "roll_deg": np.degrees(track.roll_rad),
            "pitch_deg": np.degrees(track.pitch_rad),
            "yaw_deg": np.degrees(track.yaw_rad),
        }
    )
    if track.sigma_ned_m is not None:
        for k, axis in enumerate(("north", "east", "down")):
            frame[f"sigma_{axis}_m"] = track.sigma_ned_m[:, k]
    if track.sigma_yaw_rad is not None:
        frame["sigma_yaw_deg"] = np.degrees(track.sigma_yaw_rad)
    write_table(frame, out)
    return {"trajectory": source, "rows": len(frame), "sigmas": track.sigma_ned_m is not None}
