"""Export the track and loop closures as GeoJSON (WGS84) for QGIS.

    python examples/export_geojson.py DIVE OUT

DIVE must have been processed (`auvnav process DIVE`); the trajectory is SLAM's when there is one,
else the filter's, else dead reckoning.
"""

import sys

from auvnav.io import export_dive

dive, out = sys.argv[1:3]
summary = export_dive(dive, "geojson", out)
print(", ".join(f"{key}: {value}" for key, value in summary.items()))
