"""Export camera position priors with accuracies and load them into a COLMAP database.

    python examples/export_colmap_priors.py DIVE OUT.csv [COLMAP.db]

The CSV is also a Metashape reference file (label = name, longitude, latitude, altitude = height,
accuracies sigma_east/north/up). With a database path and pycolmap installed, each image gets a
PosePrior (WGS84 position and its covariance).
"""

import sys

import numpy as np
import pandas as pd

from auvnav.dive import read_dive
from auvnav.io import export_dive

dive, out = sys.argv[1:3]
print(export_dive(dive, "colmap-priors", out))
if len(sys.argv) > 3:
    import pycolmap

    cam = read_dive(dive).vehicle.stereo.left
    db = pycolmap.Database.open(sys.argv[3])
    camera = pycolmap.Camera(
        model="PINHOLE",
        width=cam.width,
        height=cam.height,
        params=[cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]],
    )
    camera_id = db.write_camera(camera)
    for row in pd.read_csv(out).itertuples():
        image_id = db.write_image(pycolmap.Image(name=row.name, camera_id=camera_id))
        prior = pycolmap.PosePrior(
            position=np.array([row.latitude_deg, row.longitude_deg, row.height_m]),
            position_covariance=np.diag([row.sigma_north_m, row.sigma_east_m, row.sigma_up_m]) ** 2,
            coordinate_system=pycolmap.PosePriorCoordinateSystem.WGS84,
        )
        sensor = pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=camera_id)
        prior.corr_data_id = pycolmap.data_t(sensor_id=sensor, id=image_id)
        db.write_pose_prior(prior)
    print(f"{db.num_pose_priors()} pose priors in {sys.argv[3]}")
    db.close()
