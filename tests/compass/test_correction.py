"""The correction file ``auvnav-compass-correction/1``: round trip, firmware table, strict reading."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from auvnav.compass.correction import FitRecord, read_correction, write_correction
from auvnav.compass.deviation import fit_deviation
from auvnav.errors import ConfigError, OutputExistsError
from auvnav.frames import wrap_angle


@pytest.fixture(scope="module")
def fit(true_deviation):
    rng = np.random.default_rng(12)
    h = rng.uniform(0.0, 1.5 * np.pi, 300)  # leaves a 90 degree gap
    ref = wrap_angle(h + true_deviation(h) + rng.normal(0.0, math.radians(0.3), h.size))
    return fit_deviation(h, ref, constant_source="truth")


def test_round_trip_of_a_fit(fit, tmp_path: Path) -> None:
    path = tmp_path / "products" / "compass" / "correction.yaml"
    write_correction(fit, path)
    model = read_correction(path)
    np.testing.assert_allclose(model.coefficients_rad, fit.model.coefficients_rad, rtol=1e-12)
    np.testing.assert_allclose(model.covariance, fit.model.covariance, rtol=1e-12)
    assert model.constant_source == "truth"
    doc = yaml.safe_load(path.read_text())
    assert doc["format"] == "auvnav-compass-correction/1" and doc["model"] == "fourier"
    assert doc["harmonics"] == 3
    assert doc["residual_rms_deg"] == pytest.approx(math.degrees(fit.residual_rms_rad))
    assert doc["constant"]["sigma_deg"] == pytest.approx(math.degrees(math.sqrt(fit.model.covariance[0, 0])))
    assert len(doc["gaps_deg"]) == 1
    assert path.read_text().startswith("# Compass correction (auvnav)")


def test_firmware_table(fit, tmp_path: Path) -> None:
    """360 rows [heading_deg, correction_deg]: the curve at each whole degree, to 1e-4 degree."""
    path = tmp_path / "c.yaml"
    write_correction(fit.model, path)
    table = np.array(yaml.safe_load(path.read_text())["table"])
    assert table.shape == (360, 2)
    np.testing.assert_array_equal(table[:, 0], np.arange(360))
    np.testing.assert_allclose(table[:, 1], np.degrees(fit.model(np.radians(table[:, 0]))), atol=5e-5)
    doc = yaml.safe_load(path.read_text())
    assert doc["residual_rms_deg"] is None and doc["gaps_deg"] is None  # a bare model has no fit


def test_model_without_covariance(true_deviation, tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    write_correction(true_deviation, path)
    model = read_correction(path)
    assert model.covariance is None
    assert yaml.safe_load(path.read_text())["constant"] == {"source": "arbitrary", "sigma_deg": None}


def test_no_silent_overwrite(true_deviation, tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    write_correction(true_deviation, path)
    with pytest.raises(OutputExistsError, match="exists"):
        write_correction(true_deviation, path)
    write_correction(true_deviation, path, overwrite=True)


def _edit(path: Path, edit) -> Path:
    doc = yaml.safe_load(path.read_text())
    edit(doc)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(extra=1), "extra: unknown key"),
        (lambda d: d.pop("a0_deg"), "a0_deg: missing"),
        (lambda d: d["constant"].update(when="yesterday"), "constant.when: unknown key"),
        (lambda d: d["constant"].update(source="guess"), "constant.source: expected one of"),
        (lambda d: d.update(format="auvnav-compass-correction/2"), "format: expected"),
        (lambda d: d.update(model="spline"), "model: expected 'fourier'"),
        (lambda d: d.update(harmonics=2), "a_deg: expected a list of 2 numbers"),
        (lambda d: d.update(harmonics="3"), "harmonics: expected a non-negative integer"),
        (lambda d: d["b_deg"].__setitem__(1, "x"), r"b_deg\[1\]: expected a finite number"),
        (lambda d: d["table"].pop(), "table: expected 360 rows"),
        (lambda d: d["table"][17].__setitem__(1, d["table"][17][1] + 0.5), r"table\[17\]: correction"),
        (lambda d: d["covariance_deg2"][0].__setitem__(1, 9.0), "covariance_deg2: not symmetric"),
        (lambda d: d.update(gaps_deg=[[1.0]]), r"gaps_deg\[0\]: expected a list of 2 numbers"),
    ],
)
def test_strict_reader_names_file_and_key(fit, tmp_path: Path, edit, message: str) -> None:
    path = tmp_path / "c.yaml"
    write_correction(fit, path)
    _edit(path, edit)
    with pytest.raises(ConfigError, match=message) as err:
        read_correction(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ") and "\n" not in text


def test_bad_yaml_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("format: auvnav-compass-correction/1\nmodel: [fourier\n")
    with pytest.raises(ConfigError, match=rf"{path.name}: not valid YAML at line \d+: "):
        read_correction(path)


def test_not_a_mapping(tmp_path: Path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="document: expected a mapping"):
        read_correction(path)


def test_record_of_the_fit_and_constant(fit, tmp_path: Path) -> None:
    """Where the shape and the constant came from is written, and read strictly."""
    path = tmp_path / "c.yaml"
    record = FitRecord(
        reference="slam",
        dives=("navcheck",),
        pairs=300,
        transit_dives=("transit",),
        transit_legs=4,
        transit_rms_rad=math.radians(0.1),
    )
    write_correction(fit, path, record=record)
    doc = yaml.safe_load(path.read_text())
    assert doc["fit"] == {"reference": "slam", "dives": ["navcheck"], "pairs": 300}
    assert doc["constant"]["legs"] == 4 and doc["constant"]["dives"] == ["transit"]
    assert doc["constant"]["transit_rms_deg"] == pytest.approx(0.1)
    assert list(doc)[-1] == "table"
    assert read_correction(path).coefficients_rad == pytest.approx(fit.model.coefficients_rad)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["fit"].update(when=1), "fit.when: unknown key"),
        (lambda d: d["fit"].pop("pairs"), "fit.pairs: missing"),
        (lambda d: d["fit"].update(reference=3), "fit.reference: expected a string"),
        (lambda d: d["fit"].update(dives="navcheck"), "fit.dives: expected a list of names"),
        (lambda d: d["constant"].update(legs=-1), "constant.legs: expected a non-negative integer"),
        (lambda d: d["constant"].update(transit_rms_deg="x"), "constant.transit_rms_deg: expected a finite"),
    ],
)
def test_record_is_read_strictly(fit, tmp_path: Path, edit, message: str) -> None:
    path = tmp_path / "c.yaml"
    record = FitRecord(reference="truth", dives=("a",), pairs=3, transit_dives=("b",), transit_legs=2)
    write_correction(fit, path, record=record)
    _edit(path, edit)
    with pytest.raises(ConfigError, match=message):
        read_correction(path)
