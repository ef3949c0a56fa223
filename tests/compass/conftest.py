"""Shared fixtures for the compass tests: NOAA's official WMM test values, a site, a deviation."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from auvnav.compass.deviation import DeviationModel
from auvnav.compass.field import EarthField, decimal_year2posix, earth_field

# NOAA NCEI official WMM test values, as stored in ../shared/reference/magnetic_model_wmm/ (see its
# PROVENANCE.md). Rows the pygeomag author changed ("# Changed values ...") or added ("# Additional
# tests ...", to the end of the file) are not NOAA's and are skipped. WMM2015testvalues.txt tests the
# original WMM-2015, superseded by the out-of-cycle WMM-2015v2 (NOAA NCEI, 2019) that auvnav uses for
# 2015-2020, so it is not used.
_SHORT_COLUMNS = ("year", "height_km", "lat", "lon", "X", "Y", "Z", "H", "F", "I", "D")
_LONG_COLUMNS = ("year", "height_km", "lat", "lon", "D", "I", "H", "X", "Y", "Z", "F")
WMM_TABLES = {
    "WMM2015v2testvalues.txt": (_SHORT_COLUMNS, "WMM2015v2"),
    "WMM2020testvalues.txt": (_SHORT_COLUMNS, "WMM2020"),
    "WMM2020_TEST_VALUES.txt": (_LONG_COLUMNS, "WMM2020"),
    "WMM2025_TEST_VALUES.txt": (_LONG_COLUMNS, "WMM2025"),
}


@dataclass(frozen=True)
class WmmRow:
    """One official test point: inputs and NOAA's D, I (degrees) and X, Y, Z, F (nT)."""

    table: str
    model: str
    year: float
    height_km: float
    lat: float
    lon: float
    D: float
    I: float  # noqa: E741 - NOAA's name for inclination
    X: float
    Y: float
    Z: float
    F: float

    def __str__(self) -> str:
        return f"{self.table}: {self.year} {self.height_km} km {self.lat} {self.lon}"


def read_wmm_table(path: Path, columns: tuple[str, ...], model: str) -> list[WmmRow]:
    """The official rows of one test-value file."""
    rows, skip_next = [], False
    for line in path.read_text().splitlines():
        if line.startswith("# Additional tests"):
            break
        if line.startswith("# Changed values"):
            skip_next = True
            continue
        if line.startswith("#") or not line.strip():
            continue
        if skip_next:
            skip_next = False
            continue
        v = dict(zip(columns, map(float, line.split()[: len(columns)]), strict=True))
        rows.append(WmmRow(path.name, model, **{k: v[k] for k in WmmRow.__dataclass_fields__ if k in v}))
    return rows


@pytest.fixture(scope="session")
def wmm_rows(reference_dir: Path) -> list[WmmRow]:
    """Every official WMM test row in the reference folder."""
    folder = reference_dir / "magnetic_model_wmm"
    rows = [
        row
        for name, (columns, model) in WMM_TABLES.items()
        for row in read_wmm_table(folder / name, columns, model)
    ]
    assert len(rows) == 8 + 11 + 100 + 100, "unexpected number of official rows"
    return rows


# The simulator's default site and date (DESIGN section 8): Scott Reef, Western Australia, 2009-10-15.
SCOTT_REEF_LAT_DEG, SCOTT_REEF_LON_DEG = -14.0, 121.8
SCOTT_REEF_TIME_S = decimal_year2posix(2009.786)


@pytest.fixture(scope="session")
def scott_reef_field() -> EarthField:
    """The Earth field at Scott Reef in October 2009 (IGRF-14)."""
    return earth_field(math.radians(SCOTT_REEF_LAT_DEG), math.radians(SCOTT_REEF_LON_DEG), SCOTT_REEF_TIME_S)


@pytest.fixture(scope="session")
def true_deviation() -> DeviationModel:
    """A known correction: 3 harmonics, about 4 degrees peak to peak, a 0.8 degree constant."""
    return DeviationModel(math.radians(0.8), np.radians([1.5, -0.6, 0.3]), np.radians([-1.0, 0.4, -0.2]))


# Small simulated dives shared by the fit, evaluate and calibrate tests (issue 5's scenarios at a
# size that simulates in seconds): a navcheck star of 8 arms of 15 m with a 4 m grid, a transit of
# 4 legs of 300 m, and a spin of one turn, all with the default deviation.
SMALL_NAVCHECK = {"headings": 8, "leg_m": 15.0, "grid_m": 4.0}
SMALL_TRANSIT = {"legs": 4, "leg_m": 300.0}
SMALL_SPIN = {"turns": 1.0}


@dataclass(frozen=True)
class SimulatedDives:
    navcheck: Path
    transit: Path
    spin: Path


@pytest.fixture(scope="session")
def simulated(tmp_path_factory) -> SimulatedDives:
    """The three small dives, simulated once per session (seeds 1, 2, 4 as in the benchmark)."""
    from auvnav.sim.run import run_scenario

    root = tmp_path_factory.mktemp("compass_dives")
    dives = SimulatedDives(root / "navcheck", root / "transit", root / "spin")
    run_scenario("navcheck", dives.navcheck, seed=1, geometry=SMALL_NAVCHECK)
    run_scenario("transit", dives.transit, seed=2, geometry=SMALL_TRANSIT)
    run_scenario("spin", dives.spin, seed=4, geometry=SMALL_SPIN)
    return dives
