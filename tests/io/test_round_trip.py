"""Round trips (issue 15): a simulated dive written in each vendor format by an independent writer,
imported, navigated: the end error identical within 1 mm.

Formats that quantise (PD0: 1 mm/s, 0.01 deg, 10 Pa, 0.01 s) are compared with the dive as the
format holds it (the writer returns it); the others carry full precision and are compared with the
simulated dive itself.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from auvnav.dive import read_dive, write_dive
from auvnav.io import import_dive
from auvnav.nav.inputs import declination
from conftest import assert_same_navigation, navigate


def _settings(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _declination_deg(dive) -> float:
    return math.degrees(declination(dive)[0])


def test_acfr_round_trip(simulated, written, tmp_path: Path) -> None:
    dive = simulated.dive
    raw, _cfg = written.acfr
    settings = _settings(tmp_path / "acfr.yaml", f"vehicle: {simulated.path / 'vehicle.yaml'}\n")
    out = tmp_path / "imported"
    summary = import_dive("acfr-raw", [raw], out, config=settings)  # mission.cfg found beside the log
    assert summary["heading_reference"] == "magnetic"
    assert summary["declination_deg"] == pytest.approx(_declination_deg(dive), abs=1e-12)
    assert "MAGNETIC_VAR_DEG" in summary["heading_rule"]
    assert summary["pressure"]["type"] == "sea" and "TEOS-10" in summary["pressure"]["rule"]
    assert summary["origin"]["rule"].startswith("mission.cfg")
    assert {k for k, s in summary["streams"].items() if s["from"] == "sources"} == {
        "dvl",
        "attitude",
        "pressure",
        "gps",
        "usbl",
        "images",
    }
    assert summary["read"]["RDI lines"] == len(dive.dvl)
    imported = read_dive(out)
    np.testing.assert_array_equal(imported.dvl.valid, dive.dvl.valid)
    assert len(imported.images) == len(dive.images)
    assert_same_navigation(navigate(out, simulated.truth), simulated.nav)


def test_pd0_round_trip(simulated, written, tmp_path: Path) -> None:
    dive = simulated.dive
    pd0, held = written.pd0, written.pd0_held
    expected = write_dive(held, tmp_path / "expected")
    settings = _settings(tmp_path / "pd0.yaml", f"declination_deg: {_declination_deg(dive)!r}\n")
    out = tmp_path / "imported"
    summary = import_dive("pd0", [pd0], out, config=settings, base=simulated.path)
    assert summary["streams"]["dvl"]["from"] == "sources" and summary["streams"]["gps"]["from"] == "base"
    assert summary["pressure"]["type"] == "sea" and summary["heading_reference"] == "magnetic"
    assert summary["read"]["ensembles"] == len(dive.dvl)
    imported = read_dive(out)
    np.testing.assert_allclose(imported.dvl.v_sensor_mps, held.dvl.v_sensor_mps, atol=1e-12)
    np.testing.assert_allclose(imported.attitude.heading_rad, held.attitude.heading_rad, atol=1e-12)
    np.testing.assert_allclose(imported.pressure.pressure_pa, held.pressure.pressure_pa, atol=1e-6)
    assert_same_navigation(navigate(out, simulated.truth), navigate(expected, simulated.truth))


def test_nmea_round_trip(simulated, written, tmp_path: Path) -> None:
    dive = simulated.dive
    log = written.nmea
    out = tmp_path / "imported"
    summary = import_dive("nmea", [log], out, base=simulated.path)
    assert {k for k, s in summary["streams"].items() if s["from"] == "sources"} == {"gps", "attitude"}
    skipped = summary["skipped"]
    n_junk = len(range(0, len(dive.gps), 10))
    assert skipped["AIS sentences (!...)"]["count"] == n_junk
    assert skipped["proprietary sentences ($P...)"]["count"] == n_junk
    assert skipped["GSV sentences (not used)"]["count"] == n_junk
    assert skipped["GGA fixes with quality 0 (no fix)"]["count"] == n_junk
    assert skipped["RMC fixes merged into the GGA fix of the same time"]["count"] == len(dive.gps)
    assert summary["heading_reference"] == "magnetic" and "variation" in summary["heading_rule"]
    imported = read_dive(out)
    np.testing.assert_allclose(imported.gps.sigma_m, dive.gps.sigma_m, rtol=1e-9)
    assert_same_navigation(navigate(out, simulated.truth), simulated.nav)


def test_csv_round_trip(simulated, written, tmp_path: Path) -> None:
    dive = simulated.dive
    files, mapping = written.csv
    out = tmp_path / "imported"
    summary = import_dive("csv", files, out, config=mapping, base=simulated.path)
    assert {k for k, s in summary["streams"].items() if s["from"] == "sources"} == {
        "dvl",
        "attitude",
        "pressure",
    }
    imported = read_dive(out)
    np.testing.assert_allclose(imported.pressure.t_s, dive.pressure.t_s, atol=1e-6)  # GPS week and seconds
    np.testing.assert_allclose(imported.attitude.heading_rad, dive.attitude.heading_rad, atol=1e-12)
    assert_same_navigation(navigate(out, simulated.truth), simulated.nav)


def test_rosbag_raw_images_keep_their_mosaic_and_the_vehicle_its_filter(
    simulated, exportable, tmp_path: Path
) -> None:
    """A raw colour camera on a ROS topic (``bayer_rggb16``, as camera drivers publish ``image_raw``)
    and a monochrome one (``mono16``): the files hold the sensor's values as they were, and the
    vehicle's stereo rig learns the left camera's filter; without a rig, the summary says what to add."""
    from io_writers import raw_image, write_bag

    from auvnav.vehicle import read_vehicle

    bag = tmp_path / "raw_bag"
    write_bag(simulated.dive, bag, version=2, images=3, raw=("bayer_rggb16", "mono16"))
    settings = _settings(
        tmp_path / "ros.yaml",
        f"heading_reference: magnetic\ndeclination_deg: {_declination_deg(simulated.dive)!r}\n",
    )
    out = tmp_path / "imported"
    summary = import_dive("rosbag", [bag], out, config=settings, base=exportable.path)
    imported = read_dive(out)
    assert len(imported.images) == 3
    for k, (left, right) in enumerate(zip(imported.images.left, imported.images.right, strict=True)):
        for name in (left, right):
            pixels = cv2.imread(str(out / "images" / str(name)), cv2.IMREAD_UNCHANGED)
            assert pixels.dtype == np.uint16 and np.array_equal(pixels, raw_image(k))
    rig = read_vehicle(out / "vehicle.yaml").stereo
    assert rig is not None and (rig.left.bayer, rig.right.bayer) == ("rggb", None)
    assert any("raw rggb mosaics" in note for note in summary["notes"])
    bare = import_dive("rosbag", [bag], tmp_path / "bare", config=settings, base=simulated.path)
    assert any("left_bayer: rggb" in note for note in bare["notes"])


@pytest.mark.parametrize("version", [1, 2], ids=["ros1", "ros2"])
def test_rosbag_round_trip(simulated, written, tmp_path: Path, version: int) -> None:
    dive = simulated.dive
    bag = written.bags[version]
    settings = _settings(
        tmp_path / "ros.yaml", f"heading_reference: magnetic\ndeclination_deg: {_declination_deg(dive)!r}\n"
    )
    out = tmp_path / "imported"
    summary = import_dive("rosbag", [bag], out, config=settings, base=simulated.path)
    assert {k for k, s in summary["streams"].items() if s["from"] == "sources"} == {
        "dvl",
        "attitude",
        "pressure",
        "gps",
        "images",
    }
    assert summary["pressure"]["type"] == "absolute"
    imported = read_dive(out)
    assert len(imported.images) == 3
    assert all((out / "images" / str(n)).is_file() for n in (*imported.images.left, *imported.images.right))
    np.testing.assert_allclose(imported.attitude.heading_rad, dive.attitude.heading_rad, atol=1e-9)
    assert_same_navigation(navigate(out, simulated.truth), simulated.nav)
