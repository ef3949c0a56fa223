"""Pressure to depth against TEOS-10 and UNESCO 1983 check values; sea pressure; atmospheric files."""

from __future__ import annotations

import csv
import logging
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from auvnav.depth.pressure import (
    DBAR_TO_PA,
    AtmosphericSeries,
    depth_from_pressure,
    pressure_from_depth,
    read_atmospheric,
    sea_pressure,
)
from auvnav.errors import DiveFormatError

atol_teos10_m = 1e-6  # 1 micrometre (the GSW tolerance z_from_p_ca is 2.3e-8 m)
atol_teos10_pa = 1e-6 * DBAR_TO_PA  # 1e-6 dbar
atol_unesco_m = 0.01  # the published table is rounded to 1 cm

# UNESCO (1983) depth check values, Fofonoff & Millard, UNESCO Tech. Pap. Mar. Sci. 44, p. 28, as
# printed in the CSIRO SEAWATER v3.3 test report
# (reference/pressure_depth/unesco1983_seawater_v3.3_matlab_test_report.txt, sw_dpth section).
# (latitude deg, sea pressure dbar, depth m)
UNESCO_1983_DEPTH = [
    (0.0, 500.0, 496.65),
    (30.0, 500.0, 496.00),
    (45.0, 500.0, 495.34),
    (90.0, 500.0, 494.03),
    (0.0, 5000.0, 4915.04),
    (30.0, 5000.0, 4908.56),
    (45.0, 5000.0, 4902.08),
    (90.0, 5000.0, 4889.13),
    (0.0, 10000.0, 9725.47),
    (30.0, 10000.0, 9712.65),
    (45.0, 10000.0, 9699.84),
    (90.0, 10000.0, 9674.23),
]


def _teos10_checks(reference_dir: Path, source: str) -> tuple[np.ndarray, ...]:
    """(p_dbar, lat_deg, z_from_p_m, p_from_z_dbar) from the GSW v3 check values (PROVENANCE.md)."""
    folder = reference_dir / "pressure_depth"
    if source == "csv":
        rows = pd.read_csv(folder / "gsw_z_from_p_check_values.csv", comment="#")
        columns = ["p_dbar", "lat_deg", "z_from_p_m", "p_from_z_roundtrip_dbar"]
        return tuple(rows[c].to_numpy() for c in columns)
    cv = np.load(folder / "gsw_cv_v3_0.npz")
    p, lat, z, p_back = np.broadcast_arrays(
        cv["p_chck_cast"], cv["lat_chck_cast"], cv["z_from_p"], cv["p_from_z"]
    )
    good = np.isfinite(p) & np.isfinite(z)
    return p[good], lat[good], z[good], p_back[good]


@pytest.mark.parametrize("source", ["csv", "npz"])
def test_teos10_check_values(reference_dir: Path, source: str) -> None:
    p_dbar, lat_deg, z_m, p_back_dbar = _teos10_checks(reference_dir, source)
    assert p_dbar.size >= 98
    cases = list(zip(p_dbar, lat_deg, z_m, strict=True))
    depth = [depth_from_pressure(p * DBAR_TO_PA, math.radians(lat)) for p, lat, _ in cases]
    np.testing.assert_allclose(depth, -z_m, rtol=0, atol=atol_teos10_m)
    back = [pressure_from_depth(-z, math.radians(lat)) for _, lat, z in cases]
    np.testing.assert_allclose(back, p_back_dbar * DBAR_TO_PA, rtol=0, atol=atol_teos10_pa)


@pytest.mark.parametrize(("latitude_deg", "p_dbar", "depth_m"), UNESCO_1983_DEPTH)
def test_unesco1983_table(latitude_deg: float, p_dbar: float, depth_m: float) -> None:
    depth = depth_from_pressure(p_dbar * DBAR_TO_PA, math.radians(latitude_deg), method="unesco1983")
    assert depth == pytest.approx(depth_m, abs=atol_unesco_m)


def test_teos10_and_unesco_differ_at_depth_not_at_auv_depths() -> None:
    """TEOS-10 and UNESCO 1983 differ by decimetres at 10000 dbar (PROVENANCE.md), mm at 100 m."""
    lat = math.radians(-14.0)
    deep = [depth_from_pressure(1e4 * DBAR_TO_PA, lat, method=m) for m in ("teos10", "unesco1983")]
    assert abs(deep[0] - deep[1]) > 0.1
    shallow = [depth_from_pressure(100 * DBAR_TO_PA, lat, method=m) for m in ("teos10", "unesco1983")]
    assert abs(shallow[0] - shallow[1]) < 0.01


def test_depth_pressure_round_trip_keeps_shape() -> None:
    depth_m = np.linspace(0.0, 6000.0, 24).reshape(4, 6)
    p_pa = pressure_from_depth(depth_m, math.radians(-14.0))
    assert p_pa.shape == (4, 6)
    assert np.all(np.diff(p_pa.ravel()) > 0)
    np.testing.assert_allclose(depth_from_pressure(p_pa, math.radians(-14.0)), depth_m, atol=1e-9)


def test_depth_rejects_degrees_and_unknown_method() -> None:
    with pytest.raises(ValueError, match="latitude"):
        depth_from_pressure(1e5, 21.0)
    with pytest.raises(ValueError, match="latitude"):
        pressure_from_depth(10.0, -14.0)
    with pytest.raises(ValueError, match="method"):
        depth_from_pressure(1e5, 0.3, method="eos80")  # type: ignore[arg-type]


def test_sea_pressure_constant_and_sea() -> None:
    t_s = np.array([0.0, 1.0, 2.0])
    p_pa = np.array([2.0e5, 2.1e5, 2.2e5])
    np.testing.assert_allclose(
        sea_pressure(p_pa, t_s, pressure_type="absolute", atmospheric_pa=101325.0),
        p_pa - 101325.0,
    )
    sea = sea_pressure(p_pa, t_s, pressure_type="sea", atmospheric_pa=101325.0)
    np.testing.assert_array_equal(sea, p_pa)
    sea[0] = 0.0
    assert p_pa[0] == 2.0e5  # the input is not shared


def test_sea_pressure_bad_arguments() -> None:
    t_s = np.array([0.0, 1.0])
    p_pa = np.array([2.0e5, 2.1e5])
    with pytest.raises(ValueError, match="atmospheric pressure"):
        sea_pressure(p_pa, t_s, pressure_type="absolute", atmospheric_pa=10.1325)  # dbar given
    with pytest.raises(ValueError, match="pressure_type"):
        sea_pressure(p_pa, t_s, pressure_type="gauge", atmospheric_pa=1e5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="match"):
        sea_pressure(p_pa, t_s[:1], pressure_type="sea", atmospheric_pa=1e5)


def test_sea_pressure_with_series_interpolates_and_warns_outside(
    caplog: pytest.LogCaptureFixture,
) -> None:
    series = AtmosphericSeries(t_s=np.array([100.0, 200.0]), pressure_pa=np.array([1.00e5, 1.02e5]))
    t_s = np.array([150.0, 200.0, 260.0])
    with caplog.at_level(logging.WARNING):
        sea = sea_pressure(np.full(3, 3.0e5), t_s, pressure_type="absolute", atmospheric_pa=series)
    np.testing.assert_allclose(sea, [3.0e5 - 1.01e5, 3.0e5 - 1.02e5, 3.0e5 - 1.02e5])
    assert "1 of 3 times lie outside the atmospheric series (up to 60 s" in caplog.text


def test_atmospheric_series_validation() -> None:
    with pytest.raises(ValueError, match="strictly increasing"):
        AtmosphericSeries(t_s=np.array([1.0, 1.0]), pressure_pa=np.array([1e5, 1e5]))
    with pytest.raises(ValueError, match="atmospheric pressure"):
        AtmosphericSeries(t_s=np.array([1.0]), pressure_pa=np.array([1013.25]))
    with pytest.raises(ValueError, match="match"):
        AtmosphericSeries(t_s=np.array([1.0, 2.0]), pressure_pa=np.array([1e5]))
    series = AtmosphericSeries(t_s=[1.0, 2.0], pressure_pa=[1e5, 1e5])
    with pytest.raises(ValueError, match="read-only"):
        series.t_s[0] = 0.0


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_read_atmospheric_sorts_and_converts(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "atm.csv",
        ["# barometer on the ship", "t,pressure_dbar,station", "20,10.2,A", "10,10.1,A"],
    )
    series = read_atmospheric(path)
    np.testing.assert_array_equal(series.t_s, [10.0, 20.0])
    np.testing.assert_allclose(series.pressure_pa, [101000.0, 102000.0])


@pytest.mark.parametrize(
    ("lines", "expected"),
    [
        (["t,pressure_hpa", "0,1013"], "row 0: missing column(s) pressure_dbar"),
        (["t,pressure_dbar", "0,10.1", "1,abc"], "row 2: column pressure_dbar: 'abc' is not a finite"),
        (["t,pressure_dbar", "0,nan"], "row 1: column pressure_dbar: 'nan' is not a finite number"),
        (["t,pressure_dbar", "0,10.1", "1"], "row 2: expected 2 fields, found 1"),
        (["t,pressure_dbar", "0,10.1", "0,10.2"], "row 2: column t: duplicate time 0.0"),
        (["t,pressure_dbar", "0,1013.2", "1,1013.3"], "row 1: column pressure_dbar: 2 pressures"),
        (["t,pressure_dbar"], "no data rows"),
    ],
)
def test_read_atmospheric_errors(tmp_path: Path, lines: list[str], expected: str) -> None:
    path = _write(tmp_path / "atm.csv", lines)
    with pytest.raises(DiveFormatError) as err:
        read_atmospheric(path)
    message = str(err.value)
    assert message.startswith(str(path))
    assert expected in message


def test_read_atmospheric_reports_every_problem_up_to_a_cap(tmp_path: Path) -> None:
    path = tmp_path / "atm.csv"
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["t", "pressure_dbar"])
        writer.writerows([i, "x"] for i in range(25))
    with pytest.raises(DiveFormatError) as err:
        read_atmospheric(path)
    lines = str(err.value).splitlines()
    assert len(lines) == 11
    assert lines[-1].endswith("and 15 more problems")
