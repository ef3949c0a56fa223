"""From a vehicle's raw logs to its products: PD0 (DVL, attitude, pressure) and NMEA (GPS) into a
dive folder, every stage the data allows, and the track for QGIS.

    python examples/raw_logs_to_products.py DVL.pd0 GPS.nmea LAT_DEG LON_DEG WORK_FOLDER [vehicle.yaml]

With a vehicle file holding a stereo calibration and the images under WORK_FOLDER/dive/images/, the
loop-closure, SLAM and compass stages run too.
"""

import sys
from pathlib import Path

from auvnav.io import export_dive, import_dive
from auvnav.pipeline import process

pd0, nmea, lat, lon, work = sys.argv[1:6]
work = Path(work)
settings = {"origin": {"latitude_deg": float(lat), "longitude_deg": float(lon)}}
if len(sys.argv) > 6:
    settings["vehicle"] = sys.argv[6]
import_dive("pd0", [pd0], work / "dvl_only", config=settings)  # DVL, attitude, pressure
import_dive("nmea", [nmea], work / "dive", base=work / "dvl_only", config={"use": ["gps"]})  # + GPS
result = process(work / "dive", say=print)
print(export_dive(work / "dive", "geojson", work / "track.geojson"))
