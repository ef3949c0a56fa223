"""Exporters (issue 15): GeoJSON read by shapely with the right coordinates, KML, the trajectory CSV,
ACFR stereo poses, camera priors imported into a COLMAP database with pycolmap, the firmware table."""

from __future__ import annotations

import json
import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from auvnav.cli import main
from auvnav.dive import read_dive
from auvnav.frames import euler2rot, ned2geodetic
from auvnav.io import export_dive
from auvnav.vision.camera import T_body_cam
from conftest import DEVIATION, LOOPS, Exportable


def _latlon(track, origin, k: int) -> tuple[float, float]:
    p = track.p_ned_m[k].copy()
    p[2] = 0.0
    lat, lon, _ = ned2geodetic(p, origin)
    return math.degrees(float(lat)), math.degrees(float(lon))


def test_geojson_opens_in_shapely(exportable: Exportable, tmp_path: Path) -> None:
    from shapely.geometry import shape

    out = tmp_path / "track.geojson"
    summary = export_dive(exportable.path, "geojson", out)
    assert summary["trajectory"] == "filter" and summary["loops"] == len(LOOPS)
    doc = json.loads(out.read_text())
    assert doc["type"] == "FeatureCollection"
    shapes = [shape(f["geometry"]) for f in doc["features"]]
    assert all(s.is_valid for s in shapes)
    track = shapes[0]
    assert track.geom_type == "LineString" and len(track.coords) == len(exportable.track)
    lat, lon = _latlon(exportable.track, exportable.origin, -1)
    x, y, z = track.coords[-1]
    assert (x, y) == pytest.approx((lon, lat), abs=1e-9)  # RFC 7946: longitude first
    assert z == pytest.approx(-exportable.track.p_ned_m[-1, 2], abs=1e-4)
    assert 121.7 < x < 121.9 and -14.1 < y < -14.0
    loops = [f for f in doc["features"] if f["properties"]["kind"] == "loop"]
    assert [(f["properties"]["i"], f["properties"]["j"]) for f in loops] == LOOPS
    assert all(s.length > 0 for s in shapes[1:])


def test_kml(exportable: Exportable, tmp_path: Path) -> None:
    out = tmp_path / "track.kml"
    export_dive(exportable.path, "kml", out)
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    root = ET.parse(out).getroot()
    placemarks = root.findall(".//k:Placemark", ns)
    assert len(placemarks) == 1 + len(LOOPS)
    coords = placemarks[0].find(".//k:coordinates", ns).text.split()
    assert len(coords) == len(exportable.track)
    lon, lat = map(float, coords[0].split(","))
    assert (lat, lon) == pytest.approx(_latlon(exportable.track, exportable.origin, 0), abs=1e-9)


def test_trajectory_csv(exportable: Exportable, tmp_path: Path) -> None:
    out = tmp_path / "trajectory.csv"
    summary = export_dive(exportable.path, "csv", out)
    assert summary["sigmas"]
    frame = pd.read_csv(out)
    assert {"latitude_deg", "longitude_deg", "sigma_north_m", "sigma_yaw_deg", "time_utc"} <= set(
        frame.columns
    )
    assert len(frame) == len(exportable.track)
    k = len(frame) // 2
    assert (frame.latitude_deg[k], frame.longitude_deg[k]) == pytest.approx(
        _latlon(exportable.track, exportable.origin, k), abs=1e-9
    )
    np.testing.assert_allclose(frame.sigma_north_m, exportable.track.sigma_ned_m[:, 0])
    assert frame.time_utc[0].startswith("2009-10-15T") and frame.time_utc[0].endswith("Z")


def test_acfr_stereo_pose(exportable: Exportable, tmp_path: Path) -> None:
    out = tmp_path / "stereo_pose_est.data"
    summary = export_dive(exportable.path, "acfr-stereo-pose", out)
    lines = out.read_text().splitlines()
    assert lines[0] == "% STEREO_POSE_FILE VERSION 2"
    origin = [x for x in lines if x.startswith("ORIGIN_")]
    assert float(origin[0].split()[1]) == pytest.approx(-14.05)
    rows = [x.split() for x in lines if x and not x.startswith(("%", "ORIGIN_"))]
    assert len(rows) == summary["poses"] and all(len(r) == 15 for r in rows)
    dive = read_dive(exportable.path)
    k = 100
    row = rows[k]
    t = float(row[1])
    at = exportable.track.interpolate(np.array([t]))
    T_bc = T_body_cam(dive.vehicle.stereo)
    p = at.p_ned_m[0] + at.R_ned_body[0] @ T_bc[:3, 3]
    np.testing.assert_allclose([float(v) for v in row[4:7]], p, atol=1e-9)
    x, y, z = (float(v) for v in row[7:10])
    np.testing.assert_allclose(euler2rot(z, y, x), at.R_ned_body[0] @ T_bc[:3, :3], atol=1e-9)
    assert row[10] == str(dive.images.left[k]) and float(row[12]) > 0.5  # altitude from the DVL


def test_priors_import_into_pycolmap(exportable: Exportable, tmp_path: Path) -> None:
    pycolmap = pytest.importorskip("pycolmap")
    out = tmp_path / "camera_priors.csv"
    summary = export_dive(exportable.path, "colmap-priors", out)
    frame = pd.read_csv(out)
    dive = read_dive(exportable.path)
    assert len(frame) == summary["images"] == 2 * len(dive.images)
    db = pycolmap.Database.open(str(tmp_path / "colmap.db"))
    cam = dive.vehicle.stereo.left
    camera_id = db.write_camera(
        pycolmap.Camera(
            model="PINHOLE",
            width=cam.width,
            height=cam.height,
            params=[cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]],
        )
    )
    for row in frame.itertuples():
        image_id = db.write_image(pycolmap.Image(name=row.name, camera_id=camera_id))
        prior = pycolmap.PosePrior(
            position=np.array([row.latitude_deg, row.longitude_deg, row.height_m]),
            position_covariance=np.diag([row.sigma_north_m, row.sigma_east_m, row.sigma_up_m]) ** 2,
            coordinate_system=pycolmap.PosePriorCoordinateSystem.WGS84,
        )
        prior.corr_data_id = pycolmap.data_t(
            sensor_id=pycolmap.sensor_t(type=pycolmap.SensorType.CAMERA, id=camera_id), id=image_id
        )
        db.write_pose_prior(prior)
    priors = db.read_all_pose_priors()
    assert db.num_pose_priors() == len(frame) and all(p.has_position_cov() for p in priors)
    assert priors[0].position[0] == pytest.approx(frame.latitude_deg[0])
    db.close()
    # The left and right cameras of a pair are a baseline apart.
    n = len(dive.images)
    left = frame[["east_m", "north_m", "up_m"]].to_numpy()[:n]
    right = frame[["east_m", "north_m", "up_m"]].to_numpy()[n:]
    np.testing.assert_allclose(
        np.linalg.norm(right - left, axis=1), dive.vehicle.stereo.baseline_m, atol=1e-9
    )


def test_compass_table(exportable: Exportable, tmp_path: Path) -> None:
    out = tmp_path / "compass_table.csv"
    summary = export_dive(exportable.path, "compass-table", out)
    table = pd.read_csv(out)
    assert list(table.columns) == ["heading_deg", "correction_deg"] and len(table) == 360
    np.testing.assert_allclose(
        table.correction_deg, np.degrees(DEVIATION(np.radians(np.arange(360.0)))), atol=1e-4
    )
    header = (tmp_path / "compass_table.h").read_text()
    body = header[header.index("{") + 1 : header.index("}")]
    centi = np.array([int(v) for v in body.replace("\n", " ").split(",")])
    assert len(centi) == 360 and np.abs(centi / 100 - table.correction_deg).max() <= 0.005 + 1e-9
    assert summary["max_rounding_deg"] <= 0.005 + 1e-9


def test_cli_export_errors_are_one_line(exportable: Exportable, simulated, tmp_path: Path, capsys) -> None:
    bare = tmp_path / "bare"
    shutil.copytree(simulated.path, bare, ignore=shutil.ignore_patterns("products"))
    capsys.readouterr()
    assert main(["export", str(bare), "geojson"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no trajectory to export; run `auvnav process" in err[0]
    assert not (bare / "exports").exists()
    assert (
        main(
            [
                "export",
                str(exportable.path),
                "colmap-priors",
                "--source",
                "dr",
                "--out",
                str(tmp_path / "p.csv"),
            ]
        )
        == 1
    )
    assert "has no uncertainty: give --sigma-m" in capsys.readouterr().err
    assert (
        main(
            [
                "export",
                str(exportable.path),
                "colmap-priors",
                "--source",
                "dr",
                "--sigma-m",
                "2",
                "--out",
                str(tmp_path / "p.csv"),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["export", str(exportable.path), "kml", "--out", str(tmp_path / "p.csv")]) == 1
    assert "exists (use --overwrite" in capsys.readouterr().err
