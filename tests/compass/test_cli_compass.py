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


# ---------------------------------------------------------------------------------------------
# --samples and --model (issue 15)
# ---------------------------------------------------------------------------------------------


def _samples_csv(path, tilt_deg: float, *, constant: bool = False):
    import numpy as np

    from auvnav.compass.field import decimal_year2posix, earth_field
    from auvnav.compass.magnetometer import distort_field
    from auvnav.frames import euler2rot

    f = earth_field(np.radians(-14.0), np.radians(121.8), decimal_year2posix(2009.786))
    n = 900
    heading = np.full(n, 0.4) if constant else np.linspace(0.0, 6.0 * np.pi, n)
    pitch = np.radians(tilt_deg * np.sin(np.linspace(0.0, 23.0, n)))
    roll = np.radians(tilt_deg * np.sin(np.linspace(0.7, 31.0, n)))
    b = np.einsum("nji,j->ni", euler2rot(heading + f.declination_rad, pitch, roll), f.b_ned_T) * 1e6  # uT
    m = distort_field(b, np.diag([0.03, -0.02, 0.01]), [9.0, -4.0, 6.0])
    m += np.random.default_rng(3).normal(0.0, 0.05, m.shape)
    path.write_text("x,y,z\n" + "\n".join(",".join(f"{v!r}" for v in row.tolist()) for row in m) + "\n")
    return path


def test_calibrate_samples(tmp_path, capsys) -> None:
    path = _samples_csv(tmp_path / "mag.csv", 40.0)
    capsys.readouterr()
    assert main(["compass", "calibrate", "--samples", str(path), "--json", "-q"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["method"] == "general" and s["n_samples"] == 900
    assert s["h_hard_body"] == pytest.approx([9.0, -4.0, 6.0], abs=0.3)  # uT, 0.6% of the field
    assert main(["compass", "calibrate", "--samples", str(path)]) == 0
    out = capsys.readouterr().out
    assert "general calibration of 900 magnetometer samples (without attitude)" in out


@pytest.mark.parametrize(
    ("tilt", "constant", "message"),
    [
        (0.0, True, "samples are a constant"),
        (0.3, False, "lie in a plane"),
        (10.0, False, "do not determine the hard iron"),
    ],
    ids=["constant", "plane", "tilted-plane"],
)
def test_calibrate_degenerate_samples_is_one_line(tmp_path, capsys, tilt, constant, message) -> None:
    path = _samples_csv(tmp_path / "mag.csv", tilt, constant=constant)
    capsys.readouterr()
    assert main(["compass", "calibrate", "--samples", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_calibrate_needs_one_source(simulated, tmp_path, capsys) -> None:
    assert main(["compass", "calibrate"]) == 2
    path = _samples_csv(tmp_path / "mag.csv", 40.0)
    assert main(["compass", "calibrate", str(simulated.spin), "--samples", str(path)]) == 2
    assert "one of them" in capsys.readouterr().err


def test_declination_model_choice(capsys) -> None:
    """--model igrf inside the WMM years names IGRF14; --model wmm outside them is an error."""
    a = _model(capsys, "-14", "121.8", "2020-06-01", "--model", "igrf")
    b = _model(capsys, "-14", "121.8", "2020-06-01")
    assert (a["model"], b["model"]) == ("IGRF14", "WMM2020")
    assert a["declination_deg"] == pytest.approx(b["declination_deg"], abs=0.05)
    assert main(["compass", "declination", "-14", "121.8", "2005-06-01", "--model", "wmm"]) == 1
    assert "the WMM does not cover 2005" in capsys.readouterr().err


def _model(capsys, *args: str) -> dict:
    capsys.readouterr()
    assert main(["compass", "declination", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)
