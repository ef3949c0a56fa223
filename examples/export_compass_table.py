"""Export the compass correction as a 360-row table (CSV) and a C header for firmware.

    python examples/export_compass_table.py DIVE OUT

DIVE must have been processed (`auvnav process DIVE`); the trajectory is SLAM's when there is one,
else the filter's, else dead reckoning.
"""

import sys

from auvnav.io import export_dive

dive, out = sys.argv[1:3]
summary = export_dive(dive, "compass-table", out)
print(", ".join(f"{key}: {value}" for key, value in summary.items()))
