"""``auvnav compass calibrate`` on a simulated spin (issue 5): hard iron and heading against the truth."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

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
