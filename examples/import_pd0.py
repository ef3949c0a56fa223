"""Import RDI PD0 files (bottom track, attitude and pressure in the leaders) into a dive folder.

    python examples/import_pd0.py DIVE LAT_DEG LON_DEG FILE.pd0 [FILE.pd0 ...]

PD0 carries no position, so the dive's origin is given here; its GPS fixes can be added afterwards
with an NMEA log (examples/import_nmea.py, with --base).
"""

import sys

from auvnav.io import import_dive
from auvnav.io.common import format_summary

out, lat, lon, *files = sys.argv[1:]
settings = {"origin": {"latitude_deg": float(lat), "longitude_deg": float(lon)}}
print(format_summary(import_dive("pd0", files, out, config=settings)))
