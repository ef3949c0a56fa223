"""The compass correction in a form a vehicle's firmware reads (``auvnav export DIVE compass-table``).

From a correction file (``auvnav-compass-correction/1``; the dive's compass stage product by
default) two files: ``compass_table.csv`` (360 rows ``heading_deg,correction_deg``: the correction
delta(h) of paper eq. 5 at each whole degree of measured compass heading h) and, beside it, a C
header ``compass_table.h`` with the same table as integer hundredths of a degree (``int16_t``,
range +-327 degrees) and the rule to apply it::

    corrected = h + delta(h),  delta by linear interpolation between the two whole degrees about h

A table of hundredths is within 0.005 degree of the model at each degree; between degrees the
interpolation adds at most the curve's second derivative over eight (a few thousandths of a degree
for three harmonics of a few degrees).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from auvnav import products as P
from auvnav.compass.correction import read_correction
from auvnav.errors import InsufficientDataError
from auvnav.streams import atomic_write

ROWS = 360


def table_deg(model: Any) -> np.ndarray:
    """(360, 2) whole-degree headings and corrections, degrees."""
    h = np.arange(ROWS, dtype=float)
    return np.column_stack([h, np.degrees(model(np.radians(h)))])


def export_table(dive: Path, out: Path, options: Any) -> dict[str, Any]:
    """Write the CSV table and the C header beside it."""
    path = options.correction or P.COMPASS_CORRECTION.path(dive)
    if not Path(path).is_file():
        raise InsufficientDataError(
            f"{path}: no compass correction; run `auvnav compass fit {dive}` (or give --correction FILE)"
        )
    model = read_correction(path)
    table = table_deg(model)
    csv_text = "heading_deg,correction_deg\n" + "".join(f"{int(h)},{c:.4f}\n" for h, c in table)
    centi = np.round(table[:, 1] * 100.0).astype(int)
    if np.any(np.abs(centi) > 32767):
        raise InsufficientDataError(f"{path}: corrections beyond +-327 degrees do not fit the firmware table")
    rows = ",\n".join("    " + ", ".join(f"{v:6d}" for v in centi[k : k + 10]) for k in range(0, ROWS, 10))
    header = out.with_suffix(".h")
    guard = "AUVNAV_COMPASS_TABLE_H"
    h_text = (
        f"/* Compass correction table written by auvnav from {Path(path).name}.\n"
        " * COMPASS_CORRECTION_CENTIDEG[k] = delta(k degrees) in hundredths of a degree (paper eq. 5):\n"
        " * corrected heading = h + delta(h), delta interpolated linearly between floor(h) and\n"
        " * floor(h) + 1 (mod 360), h the measured compass heading in degrees [0, 360). */\n"
        f"#ifndef {guard}\n#define {guard}\n#include <stdint.h>\n"
        f"#define COMPASS_CORRECTION_ROWS {ROWS}\n"
        f"static const int16_t COMPASS_CORRECTION_CENTIDEG[COMPASS_CORRECTION_ROWS] = {{\n{rows}\n}};\n"
        f"#endif /* {guard} */\n"
    )
    atomic_write(out, lambda p: p.write_text(csv_text, encoding="utf-8"))
    atomic_write(header, lambda p: p.write_text(h_text, encoding="utf-8"))
    return {
        "correction": str(path),
        "header": str(header),
        "rows": ROWS,
        "max_abs_correction_deg": float(np.max(np.abs(table[:, 1]))),
        "max_rounding_deg": float(np.max(np.abs(centi / 100.0 - table[:, 1]))) if ROWS else math.nan,
    }
