"""``auvnav compass calibrate`` on a simulated spin (issue 5): hard iron and heading against the truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from auvnav.cli import main

# Issue 5 acceptance for the calibration on a spin.
HARD_IRON_PCT = 1.0  # of the field
HEADING_RMS_DEG = 0.3
# The field's inclination at the simulator's site and date (IGRF-14 at -14.05, 121.78 on
# 2009-10-15; truth/truth.yaml): the calibration must use the dive's own site and date.
SCOTT_REEF_INCLINATION_DEG = -43.01


def test_levelled_calibration_of_a_simulated_spin(simulated, capsys) -> None:
    """The default iron on a one-turn spin: hard iron within 1% of the field on all three axes (the
    vertical referenced to the geomagnetic model's inclination), heading within 0.3 deg RMS about
    its constant offset (a rotation about the vertical, the deviation's constant, is invisible to a
    calibration: the default iron's is about 1 deg)."""
    capsys.readouterr()
    assert main(["compass", "calibrate", str(simulated.spin), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    truth = summary["truth"]
    assert all(abs(v) <= HARD_IRON_PCT for v in truth["hard_iron_error_pct"])
    assert truth["heading_rms_deg"] <= HEADING_RMS_DEG < truth["compass_rms_deg"]
    assert 0.5 <= abs(truth["heading_offset_deg"]) <= 1.5
    assert summary["field_spread_after_pct"] < 0.5 * summary["field_spread_before_pct"]
    assert summary["horizontal_spread_after_pct"] < 0.5 * summary["horizontal_spread_before_pct"]
    assert summary["method"] == "levelled" and summary["field_model"] == "IGRF14"  # 2009: before WMM2010
    assert summary["inclination_deg"] == pytest.approx(SCOTT_REEF_INCLINATION_DEG, abs=0.01)
    capsys.readouterr()
    assert main(["compass", "calibrate", str(simulated.spin), "-q"]) == 0
    out = capsys.readouterr().out
    assert "hard iron" in out and "soft iron" in out and "against the truth" in out and "IGRF14" in out


def test_without_the_field_model_the_vertical_offset_is_left_out(simulated, capsys) -> None:
    capsys.readouterr()
    assert main(["compass", "calibrate", str(simulated.spin), "--no-field-model", "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["field_model"] is None and summary["h_hard_body"][2] == 0.0
    assert summary["truth"]["hard_iron_error_pct"][2] is None


def test_dive_without_magnetometer_is_one_line(simulated, tmp_path: Path, capsys) -> None:
    dive = tmp_path / "spin"
    shutil.copytree(simulated.spin, dive)
    (dive / "nav" / "magnetometer.csv").unlink()
    capsys.readouterr()
    assert main(["compass", "calibrate", str(dive)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(
        "nav/magnetometer.csv: not found: calibration needs the raw magnetometer"
    )


# ---------------------------------------------------------------------------------------------
# Raw samples from a CSV (issue 15)
# ---------------------------------------------------------------------------------------------


def _write_samples(path: Path, m, pitch=None, roll=None, names=("x", "y", "z")) -> Path:
    import pandas as pd

    frame = pd.DataFrame({names[0]: m[:, 0], names[1]: m[:, 1], names[2]: m[:, 2]})
    if pitch is not None:
        frame["pitch_deg"], frame["roll_deg"] = np.degrees(pitch), np.degrees(roll)
    frame.to_csv(path, index=False)
    return path


def _spin_samples(field, tilt_deg: float, n: int = 1200, seed: int = 5):
    from auvnav.compass.magnetometer import distort_field
    from auvnav.frames import euler2rot

    rng = np.random.default_rng(seed)
    heading = np.linspace(0.0, 6.0 * np.pi, n)
    pitch = np.radians(tilt_deg * np.sin(np.linspace(0.0, 23.0, n)))
    roll = np.radians(tilt_deg * np.sin(np.linspace(0.7, 31.0, n)))
    R = euler2rot(heading + field.declination_rad, pitch, roll)
    b = np.einsum("nji,j->ni", R, field.b_ned_T) * 1e9  # nT: any one unit will do
    hard = np.array([9000.0, -4500.0, 7000.0])
    soft = np.array([[0.05, 0.02, -0.01], [0.02, -0.03, 0.015], [-0.01, 0.015, 0.04]])
    m = distort_field(b, soft, hard) + rng.normal(0.0, 50.0, b.shape)
    return m, pitch, roll, hard


def test_samples_alone(scott_reef_field, tmp_path: Path) -> None:
    from auvnav.compass.calibrate import calibrate_samples, format_samples_calibration

    m, _, _, hard = _spin_samples(scott_reef_field, 40.0)
    path = _write_samples(tmp_path / "mag.csv", m, names=("mx", "my", "mz"))
    s = calibrate_samples(path)
    assert s["method"] == "general" and not s["attitude"] and s["field_model"] is None
    total = scott_reef_field.total_T * 1e9
    assert np.all(np.abs(np.array(s["h_hard_body"]) - hard) < 0.01 * total)
    assert s["field_spread_after_pct"] < 0.2 < 5.0 < s["field_spread_before_pct"]
    assert "hard-iron 1-sigma" in format_samples_calibration(s)


def test_samples_with_attitude_and_site(scott_reef_field, tmp_path: Path) -> None:
    """The tilted-plane set (within 10 degrees) with pitch, roll and the site: the ellipsoid held to
    the model's inclination; the hard iron within 1% of the field."""
    import math

    from auvnav.compass.calibrate import calibrate_samples
    from auvnav.compass.field import decimal_year2posix

    m, pitch, roll, hard = _spin_samples(scott_reef_field, 10.0)
    path = _write_samples(tmp_path / "mag.csv", m, pitch, roll)
    site = (math.radians(-14.0), math.radians(121.8), decimal_year2posix(2009.786))
    s = calibrate_samples(path, site=site)
    assert s["method"] == "ellipsoid" and s["field_model"] == "IGRF14" and s["attitude"]
    assert np.all(np.abs(np.array(s["h_hard_body"]) - hard) < 0.01 * scott_reef_field.total_T * 1e9)


def test_samples_errors(scott_reef_field, tmp_path: Path) -> None:
    from auvnav.compass.calibrate import calibrate_samples
    from auvnav.errors import ConfigError, DiveFormatError, InsufficientDataError

    m, *_ = _spin_samples(scott_reef_field, 10.0)
    path = _write_samples(tmp_path / "mag.csv", m)
    with pytest.raises(InsufficientDataError, match="do not determine the hard iron along body"):
        calibrate_samples(path)
    with pytest.raises(ConfigError, match="needs pitch_deg and roll_deg columns"):
        calibrate_samples(path, method="levelled")
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z\n1,2,3\n4,five,6\n", encoding="utf-8")
    with pytest.raises(DiveFormatError, match="row 2: column y: not a number"):
        calibrate_samples(bad)
