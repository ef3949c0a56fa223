"""Camera position priors with accuracies, for COLMAP and Metashape (``auvnav export DIVE colmap-priors``).

One row per image of every stereo pair inside the trajectory (left and right cameras), the camera's
optical centre where the image was taken:

``name`` (the image's path relative to the dive's ``images/``, COLMAP's image name),
``latitude_deg``, ``longitude_deg``, ``height_m`` (WGS84, height above the ellipsoid = -depth),
``east_m``, ``north_m``, ``up_m`` (local east-north-up about the dive's origin, for a Cartesian
prior), ``sigma_east_m``, ``sigma_north_m``, ``sigma_up_m`` (1 sigma, from the trajectory's
uncertainty at that time, or ``--sigma-m`` for a trajectory without one), ``t`` (POSIX s).

COLMAP: each row becomes a ``PosePrior`` (position and diagonal covariance, ``WGS84`` with
``[latitude, longitude, height]`` or ``CARTESIAN`` with the local east-north-up) for the image of
that name. Metashape: import as a reference with columns label = name, longitude, latitude,
altitude = height, and accuracies sigma_east, sigma_north, sigma_up (skip one header row).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from auvnav.errors import ConfigError, InsufficientDataError
from auvnav.frames import ned2geodetic
from auvnav.io.tracks import camera_track
from auvnav.streams import write_table


def export_priors(dive_path: Path, out: Path, options: Any) -> dict[str, Any]:
    """Write the camera position priors CSV."""
    cams = camera_track(dive_path, options.source, "colmap-priors")
    dive, source, inside, at = cams.dive, cams.source, cams.inside, cams.at
    t, rig = dive.images.t_s, dive.vehicle.stereo
    if at.sigma_ned_m is not None:
        sigma = at.sigma_ned_m
        sigma_source = f"the {source} trajectory's uncertainty"
    elif options.sigma_m is not None:
        sigma = np.full((len(at), 3), float(options.sigma_m))
        sigma_source = f"--sigma-m {options.sigma_m:g}"
    else:
        raise ConfigError(
            f"the {source} trajectory has no uncertainty: give --sigma-m (the accuracy to write), or export "
            "from the filter or SLAM (--source filter|slam)"
        )
    R_nc, left = cams.R_ned_cam, cams.p_ned_cam_m
    centre_right_in_left = -rig.R_right_left.T @ rig.t_right_left_m
    right = left + R_nc @ centre_right_in_left
    rows = []
    for names, p in ((dive.images.left[inside], left), (dive.images.right[inside], right)):
        lat, lon, _ = ned2geodetic(p, dive.info.origin)
        rows.append(
            pd.DataFrame(
                {
                    "name": names,
                    "latitude_deg": np.degrees(np.reshape(lat, -1)),
                    "longitude_deg": np.degrees(np.reshape(lon, -1)),
                    "height_m": -p[:, 2],
                    "east_m": p[:, 1],
                    "north_m": p[:, 0],
                    "up_m": -p[:, 2],
                    "sigma_east_m": sigma[:, 1],
                    "sigma_north_m": sigma[:, 0],
                    "sigma_up_m": sigma[:, 2],
                    "t": t[inside],
                }
            )
        )
    frame = pd.concat(rows, ignore_index=True)
    if not np.all(np.isfinite(frame[["sigma_east_m", "sigma_north_m", "sigma_up_m"]].to_numpy())):
        raise InsufficientDataError(f"the {source} trajectory's uncertainty is not finite at every image")
    write_table(frame, out)
    return {
        "trajectory": source,
        "images": len(frame),
        "sigma": sigma_source,
        "sigma_median_m": float(np.median(sigma)) if len(sigma) else math.nan,
    }
