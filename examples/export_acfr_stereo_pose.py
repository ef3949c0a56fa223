"""Export the left camera's pose at every stereo pair as ACFR stereo_pose_est.data.

    python examples/export_acfr_stereo_pose.py DIVE OUT

DIVE must have been processed (`auvnav process DIVE`); the trajectory is SLAM's when there is one,
else the filter's, else dead reckoning.
"""

import sys

from auvnav.io import export_dive

dive, out = sys.argv[1:3]
summary = export_dive(dive, "acfr-stereo-pose", out)
print(", ".join(f"{key}: {value}" for key, value in summary.items()))
