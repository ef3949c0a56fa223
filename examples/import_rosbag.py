"""Import a ROS 1 .bag or a ROS 2 bag folder into a dive folder.

    python examples/import_rosbag.py BAG DIVE magnetic|true [dvl_topic]

Topics are found by message type (TwistWithCovarianceStamped, Imu, FluidPressure, NavSatFix, Range,
CompressedImage left/right); name them when a bag has several of one type. A bag does not say
whether its orientation refers to magnetic or true north: say it.
"""

import sys

from auvnav.io import import_dive
from auvnav.io.common import format_summary

bag, out, reference = sys.argv[1:4]
settings = {"heading_reference": reference}
if len(sys.argv) > 4:
    settings["dvl_topic"] = sys.argv[4]
print(format_summary(import_dive("rosbag", [bag], out, config=settings)))
