"""Add the GPS fixes (and heading) of an NMEA 0183 log to a dive: a new dive folder with the log's
streams and the base dive's others.

    python examples/import_nmea.py LOG.nmea BASE_DIVE NEW_DIVE

Proprietary and AIS sentences, invalid fixes, bad checksums and truncated lines are skipped and
counted; the summary lists each kind with its first line.
"""

import sys

from auvnav.io import import_dive

log, base, out = sys.argv[1:4]
summary = import_dive("nmea", [log], out, base=base)
for reason, skipped in summary["skipped"].items():
    print(f"skipped {skipped['count']:6d}  {reason} (first at {skipped['first']})")
print(f"gps fixes: {summary['streams']['gps']['rows']}")
