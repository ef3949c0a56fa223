"""Every script in examples/ runs (issue 15), on small files this test writes, as a user would run it
(``python examples/NAME.py ARGS``; here in-process, with ``sys.argv`` set)."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest

from auvnav.dive import read_dive

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run(name: str, *args: object, monkeypatch, capsys) -> str:
    monkeypatch.setattr(sys, "argv", [str(EXAMPLES / name), *map(str, args)])
    capsys.readouterr()
    runpy.run_path(str(EXAMPLES / name), run_name="__main__")
    return capsys.readouterr().out


def test_every_example_is_tested() -> None:
    tested = {
        "import_acfr.py",
        "import_pd0.py",
        "import_rosbag.py",
        "import_nmea.py",
        "import_csv.py",
        "export_geojson.py",
        "export_kml.py",
        "export_csv.py",
        "export_acfr_stereo_pose.py",
        "export_colmap_priors.py",
        "export_compass_table.py",
        "raw_logs_to_products.py",
    }
    assert {p.name for p in EXAMPLES.glob("*.py")} == tested


def test_import_examples(simulated, written, tmp_path: Path, monkeypatch, capsys) -> None:
    dive = simulated.dive
    raw, cfg = written.acfr
    out = run(
        "import_acfr.py",
        raw,
        cfg,
        tmp_path / "acfr_dive",
        simulated.path / "vehicle.yaml",
        monkeypatch=monkeypatch,
        capsys=capsys,
    )
    assert (
        '"heading_rule": "ACFR compass is magnetic' in out
        and read_dive(tmp_path / "acfr_dive").usbl is not None
    )

    out = run(
        "import_pd0.py",
        tmp_path / "pd0_dive",
        -14.05,
        121.78,
        written.pd0,
        monkeypatch=monkeypatch,
        capsys=capsys,
    )
    assert "imported pd0" in out and "origin: -14.050000, 121.780000 (the settings file)" in out

    out = run(
        "import_rosbag.py",
        written.bags[2],
        tmp_path / "ros_dive",
        "magnetic",
        "/dvl/twist",
        monkeypatch=monkeypatch,
        capsys=capsys,
    )
    assert "imported rosbag" in out and len(read_dive(tmp_path / "ros_dive").images) == 3

    out = run(
        "import_nmea.py",
        written.nmea,
        simulated.path,
        tmp_path / "nmea_dive",
        monkeypatch=monkeypatch,
        capsys=capsys,
    )
    assert "AIS sentences" in out and f"gps fixes: {len(dive.gps)}" in out

    files, mapping = written.csv
    out = run("import_csv.py", mapping, tmp_path / "csv_dive", *files, monkeypatch=monkeypatch, capsys=capsys)
    assert "imported csv" in out and "(the settings file)" in out


@pytest.mark.parametrize(
    ("name", "expect"),
    [
        ("export_geojson.py", "loops: 3"),
        ("export_kml.py", "loops: 3"),
        ("export_csv.py", "sigmas: True"),
        ("export_acfr_stereo_pose.py", "poses: "),
        ("export_compass_table.py", "rows: 360"),
    ],
)
def test_export_examples(exportable, tmp_path: Path, monkeypatch, capsys, name: str, expect: str) -> None:
    out = run(name, exportable.path, tmp_path / "out", monkeypatch=monkeypatch, capsys=capsys)
    assert expect in out and (tmp_path / "out").is_file()


def test_colmap_priors_example(exportable, tmp_path: Path, monkeypatch, capsys) -> None:
    pytest.importorskip("pycolmap")
    out = run(
        "export_colmap_priors.py",
        exportable.path,
        tmp_path / "priors.csv",
        tmp_path / "colmap.db",
        monkeypatch=monkeypatch,
        capsys=capsys,
    )
    n = 2 * len(read_dive(exportable.path).images)
    assert f"{n} pose priors in" in out


def test_raw_logs_to_products(simulated, written, tmp_path: Path, monkeypatch, capsys) -> None:
    out = run(
        "raw_logs_to_products.py",
        written.pd0,
        written.nmea,
        -14.05,
        121.78,
        tmp_path / "work",
        simulated.path / "vehicle.yaml",
        monkeypatch=monkeypatch,
        capsys=capsys,
    )
    assert (tmp_path / "work" / "dive" / "products" / "nav" / "filter.csv").is_file()
    assert (tmp_path / "work" / "track.geojson").is_file() and "'trajectory': 'filter'" in out
