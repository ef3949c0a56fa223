"""Import an ACFR log: ``combined.RAW.auv`` and its ``mission.cfg`` into an auvnav dive folder.

    python examples/import_acfr.py dRAWLOGS_cv/combined.RAW.auv mission.cfg DIVE [vehicle.yaml]

The origin and the declination come from mission.cfg (MAG_VAR_LAT/LNG, MAGNETIC_VAR_DEG); the
compass heading is magnetic; PAROSCI depth becomes sea pressure. A vehicle file gives the lever arms
and the stereo rig (the default vehicle has none).
"""

import json
import sys

from auvnav.io import import_dive

log, cfg, out = sys.argv[1:4]
settings = {"vehicle": sys.argv[4]} if len(sys.argv) > 4 else {}
summary = import_dive("acfr-raw", [log, cfg], out, config=settings)
print(json.dumps({k: summary[k] for k in ("streams", "skipped", "heading_rule", "pressure")}, indent=2))
