"""``auvnav compass declination`` through ``auvnav.cli.main`` against NOAA's official WMM values."""

from __future__ import annotations

import json

import pytest

from auvnav.cli import main

JSON_KEYS = {
    "declination_deg",
    "inclination_deg",
    "north_nT",
    "east_nT",
    "down_nT",
    "total_nT",
    "model",
}
ATOL_DEG = 0.01  # issue 5 acceptance
ATOL_NT = 0.15  # 0.1 nT, plus half the last digit of the tables rounded to 0.1 nT


def _declination_json(capsys, *args: str) -> dict:
    capsys.readouterr()
    assert main(["compass", "declination", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_declination_matches_noaa(wmm_rows, capsys) -> None:
    for row in wmm_rows:
        out = _declination_json(
            capsys, str(row.lat), str(row.lon), repr(row.year), "--height-km", str(row.height_km)
        )
        assert JSON_KEYS <= out.keys()
        assert out["model"] == row.model, row
        assert abs((out["declination_deg"] - row.D + 180.0) % 360.0 - 180.0) <= ATOL_DEG, row
        assert abs(out["inclination_deg"] - row.I) <= ATOL_DEG, row
        for key, ref in (("north_nT", row.X), ("east_nT", row.Y), ("down_nT", row.Z), ("total_nT", row.F)):
            assert abs(out[key] - ref) <= ATOL_NT, (row, key)


def test_iso_date_equals_decimal_year(capsys) -> None:
    """2020-07-02 is decimal year 2020.5 (WMM convention)."""
    a = _declination_json(capsys, "-33", "151.2", "2020-07-02")
    b = _declination_json(capsys, "-33", "151.2", "2020.5")
    assert a["declination_deg"] == pytest.approx(b["declination_deg"], abs=1e-9)


def test_human_summary(capsys) -> None:
    """Negative coordinates are arguments, not options; the summary reads like NOAA's calculator."""
    assert main(["compass", "declination", "-14.0", "121.8", "2009-10-15"]) == 0
    out = capsys.readouterr().out
    assert "14.0000 S, 121.8000 E" in out
    assert "IGRF14" in out
    assert "deg E" in out and "deg up" in out  # easterly declination, field points up
    for label in ("Declination", "Inclination", "North", "East", "Down", "Horizontal", "Total"):
        assert label in out


def test_western_declination(capsys) -> None:
    """NOAA WMM2025 test row (2025.0, 28 km, 89 N, 121 W): D = -99.77, printed as west."""
    assert main(["compass", "declination", "89", "-121", "2025.0", "--height-km", "28"]) == 0
    assert "99.77 deg W" in capsys.readouterr().out


def test_date_outside_models_is_one_line_error(capsys) -> None:
    assert main(["compass", "declination", "0", "0", "1850-01-01"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("auvnav: error: no geomagnetic model covers 1850")


@pytest.mark.parametrize("date", ["2020-13-01", "next week", "20x9"])
def test_bad_date_is_usage_error(date: str, capsys) -> None:
    assert main(["compass", "declination", "0", "0", date]) == 2
    assert "DATE" in capsys.readouterr().err
