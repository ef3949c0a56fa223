"""Import vendor CSVs described by a mapping file (columns, units, time formats, heading reference).

    python examples/import_csv.py MAPPING.yaml DIVE FILE.csv [FILE.csv ...]

See ``auvnav.io.csvmap`` for the mapping's keys; a minimal one:

    heading_reference: magnetic
    pressure: {type: absolute, atmospheric_dbar: 10.1325}
    files:
      nav.csv:
        time: {column: time, format: iso8601}
        dvl: {vx: {column: u, unit: mm/s}, vy: {column: v, unit: mm/s}, vz: {column: w, unit: mm/s}}
        attitude: {heading: {column: hdg, unit: deg}, pitch: {column: p, unit: deg}, roll: {column: r, unit: deg}}
        pressure: {pressure: {column: pres, unit: dbar}}
"""

import sys

from auvnav.io import import_dive
from auvnav.io.common import format_summary

mapping, out, *files = sys.argv[1:]
print(format_summary(import_dive("csv", files, out, config=mapping)))
