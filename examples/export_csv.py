"""Export the trajectory as CSV with latitude, longitude and 1-sigma uncertainties.

    python examples/export_csv.py DIVE OUT

DIVE must have been processed (`auvnav process DIVE`); the trajectory is SLAM's when there is one,
else the filter's, else dead reckoning.
"""

import sys

from auvnav.io import export_dive

dive, out = sys.argv[1:3]
summary = export_dive(dive, "csv", out)
print(", ".join(f"{key}: {value}" for key, value in summary.items()))
