"""The dive folder format: lossless round trips and one problem line per broken input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from auvnav.cli import main
from auvnav.dive import read_dive, validate_dive, write_dive
from auvnav.errors import DiveFormatError, OutputExistsError


def assert_dives_equal(a, b) -> None:
    assert a.info == b.info
    assert set(a.streams()) == set(b.streams())
    for name, sa in a.streams().items():
        sb = b.streams()[name]
        for f in sa.FIELDS:
            va, vb = getattr(sa, f.name), getattr(sb, f.name)
            if f.kind == "float":
                np.testing.assert_allclose(vb, va, rtol=1e-15, atol=0, err_msg=f"{name}.{f.name}")
            else:
                np.testing.assert_array_equal(vb, va)


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_write_read_round_trip_is_lossless(tmp_path: Path, small_dive, fmt: str) -> None:
    dive = small_dive()
    write_dive(dive, tmp_path / "d", fmt=fmt)
    back = read_dive(tmp_path / "d")
    assert_dives_equal(dive, back)
    # A second write of what was read gives the same bytes: nothing drifts through the file form.
    write_dive(back, tmp_path / "e", fmt=fmt)
    for f in (tmp_path / "d").rglob("*.*"):
        assert f.read_bytes() == (tmp_path / "e" / f.relative_to(tmp_path / "d")).read_bytes(), f.name


def test_write_refuses_to_overwrite(tmp_path: Path, small_dive) -> None:
    write_dive(small_dive(), tmp_path / "d")
    with pytest.raises(OutputExistsError):
        write_dive(small_dive(), tmp_path / "d")
    write_dive(small_dive(30.0), tmp_path / "d", overwrite=True)
    assert len(read_dive(tmp_path / "d").dvl) == 150
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary folders left behind"


def test_valid_dive_passes_with_summary(tmp_path: Path, small_dive, capsys) -> None:
    write_dive(small_dive(), tmp_path / "d")
    assert main(["validate", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    assert "valid dive 'small'" in out and "dvl" in out and "5.00 Hz" in out


def test_validate_json_reports_rates_and_gaps(tmp_path: Path, small_dive, capsys) -> None:
    import json

    write_dive(small_dive(), tmp_path / "d")
    csv = tmp_path / "d/nav/pressure.csv"
    lines = csv.read_text().splitlines()
    csv.write_text("\n".join(lines[:100] + lines[200:]) + "\n")  # a 20 s hole
    assert main(["validate", str(tmp_path / "d"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["duration_s"] == pytest.approx(59.8)
    assert summary["streams"]["pressure"]["gaps"][0]["length_s"] == pytest.approx(20.2)
    assert summary["streams"]["dvl"]["rate_hz"] == pytest.approx(5.0)


def _edit_csv(path: Path, edit) -> None:
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")


def _set_cell(lines: list[str], row: int, column: str, value: str) -> list[str]:
    header = lines[0].split(",")
    cells = lines[row].split(",")
    cells[header.index(column)] = value
    lines[row] = ",".join(cells)
    return lines


def _drop_column(lines: list[str], column: str) -> list[str]:
    k = lines[0].split(",").index(column)
    return [",".join(c for i, c in enumerate(line.split(",")) if i != k) for line in lines]


BROKEN = {
    "missing column": (
        "nav/dvl.csv",
        lambda lines: _drop_column(lines, "valid"),
        "nav/dvl.csv: column valid: missing required column",
    ),
    "NaN": (
        "nav/pressure.csv",
        lambda lines: _set_cell(lines, 7, "pressure_dbar", "nan"),
        "nav/pressure.csv: row 7: column pressure_dbar: NaN",
    ),
    "out of order": (
        "nav/attitude.csv",
        lambda lines: [*lines[:10], lines[11], lines[10], *lines[12:]],
        "nav/attitude.csv: row 11: column t: timestamp out of order",
    ),
    "duplicate": (
        "nav/dvl.csv",
        lambda lines: [*lines[:21], lines[20], *lines[22:]],
        "nav/dvl.csv: row 21: column t: duplicate timestamp",
    ),
    "not a number": (
        "nav/dvl.csv",
        lambda lines: _set_cell(lines, 3, "vx_mps", "fast"),
        "nav/dvl.csv: row 3: column vx_mps: not a number",
    ),
}


@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_stream_gives_one_line_per_problem(tmp_path: Path, small_dive, capsys, case: str) -> None:
    rel, edit, expected = BROKEN[case]
    write_dive(small_dive(), tmp_path / "d")
    _edit_csv(tmp_path / "d" / rel, edit)
    assert main(["validate", str(tmp_path / "d")]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1, err
    assert expected in err[0]
    assert "Traceback" not in captured.err


def test_heading_in_radians_is_caught(tmp_path: Path, small_dive, capsys) -> None:
    write_dive(small_dive(), tmp_path / "d")
    csv = tmp_path / "d/nav/attitude.csv"
    import pandas as pd

    frame = pd.read_csv(csv)
    frame["heading_deg"] = np.radians(frame["heading_deg"])
    frame.to_csv(csv, index=False)
    assert main(["validate", str(tmp_path / "d")]) == 1
    err = capsys.readouterr().err
    assert "nav/attitude.csv: column heading_deg:" in err and "radians" in err


def test_unknown_key_in_dive_yaml(tmp_path: Path, small_dive, capsys) -> None:
    write_dive(small_dive(), tmp_path / "d")
    path = tmp_path / "d/dive.yaml"
    data = yaml.safe_load(path.read_text())
    data["origin"]["altitude_m"] = 3
    path.write_text(yaml.safe_dump(data))
    assert main(["validate", str(tmp_path / "d")]) == 1
    assert capsys.readouterr().err.strip() == "auvnav: error: dive.yaml: key origin.altitude_m: unknown key"


def test_vehicle_rotation_that_is_not_a_rotation(tmp_path: Path, small_dive, capsys) -> None:
    write_dive(small_dive(), tmp_path / "d")
    path = tmp_path / "d/vehicle.yaml"
    data = yaml.safe_load(path.read_text())
    data["dvl"]["mount"]["R_body_sensor"] = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]
    path.write_text(yaml.safe_dump(data))
    assert main(["validate", str(tmp_path / "d")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "vehicle.yaml: key dvl.mount:" in err[0] and "not a rotation" in err[0]


def test_stream_that_is_not_csv(tmp_path: Path, small_dive, capsys) -> None:
    write_dive(small_dive(), tmp_path / "d")
    (tmp_path / "d/nav/gps.csv").write_bytes(bytes(range(256)) * 8)
    assert main(["validate", str(tmp_path / "d")]) == 1
    assert (
        capsys.readouterr().err.strip() == "auvnav: error: nav/gps.csv: not a CSV text file (binary content)"
    )


def test_every_problem_is_reported_not_just_the_first(tmp_path: Path, small_dive) -> None:
    write_dive(small_dive(), tmp_path / "d")
    _edit_csv(tmp_path / "d/nav/dvl.csv", lambda lines: _drop_column(lines, "valid"))
    _edit_csv(tmp_path / "d/nav/pressure.csv", lambda lines: _set_cell(lines, 2, "pressure_dbar", ""))
    (tmp_path / "d/nav/attitude.csv").unlink()
    report = validate_dive(tmp_path / "d")
    assert sorted(p.file for p in report.problems) == ["nav/attitude.csv", "nav/dvl.csv", "nav/pressure.csv"]
    with pytest.raises(DiveFormatError) as info:
        read_dive(tmp_path / "d")
    assert len(info.value.problems) == 3


def test_many_nan_rows_are_counted_not_listed(tmp_path: Path, small_dive) -> None:
    write_dive(small_dive(), tmp_path / "d")

    def nan_rows(lines: list[str]) -> list[str]:
        for r in range(1, 40):
            lines = _set_cell(lines, r, "vz_mps", "NaN")
        return lines

    _edit_csv(tmp_path / "d/nav/dvl.csv", nan_rows)
    messages = [str(p) for p in validate_dive(tmp_path / "d").problems]
    assert messages == [
        "nav/dvl.csv: row 1: column vz_mps: NaN or infinite value "
        "(and 38 more NaN or infinite values: rows 2, 3, 4, 5 and 34 more)"
    ]


def test_start_time_needs_a_time_zone(tmp_path: Path, small_dive) -> None:
    write_dive(small_dive(), tmp_path / "d")
    path = tmp_path / "d/dive.yaml"
    path.write_text(path.read_text().replace("Z", ""))
    problems = validate_dive(tmp_path / "d").problems
    assert len(problems) == 1 and "start_time" in str(problems[0]) and "time zone" in str(problems[0])


def test_missing_required_stream(tmp_path: Path, small_dive) -> None:
    write_dive(small_dive(), tmp_path / "d")
    (tmp_path / "d/nav/pressure.csv").unlink()
    assert [str(p) for p in validate_dive(tmp_path / "d").problems] == [
        "nav/pressure.csv: required stream file missing"
    ]


def test_northbound_heading_in_degrees_is_not_mistaken_for_radians() -> None:
    from auvnav.streams import looks_like_radians

    rng = np.random.default_rng(0)
    wander = np.cumsum(rng.normal(0, 0.2, 2000))
    north = np.clip(-2.5 + 3 * wander / np.abs(wander).max() + rng.normal(0, 0.3, 2000), -5.8, 0.5)
    assert looks_like_radians(north) is None
    turning = np.degrees(np.angle(np.exp(1j * np.linspace(0, 12, 2000))))  # turning in degrees
    assert looks_like_radians(turning) is None
    assert "radians" in (looks_like_radians(np.radians(turning)) or "")


def test_products_are_readable_by_others(tmp_path: Path) -> None:
    from auvnav.streams import atomic_write

    atomic_write(tmp_path / "x.txt", lambda p: p.write_text("x"))
    assert (tmp_path / "x.txt").stat().st_mode & 0o044 == 0o044


def test_heading_reference_true_as_yaml_writes_it_is_true_north(tmp_path: Path, small_dive) -> None:
    """DESIGN writes `heading_reference: true`; YAML reads that as a boolean, which means true north."""
    write_dive(small_dive(), tmp_path / "d")
    path = tmp_path / "d/dive.yaml"
    path.write_text(path.read_text().replace("heading_reference: magnetic", "heading_reference: true"))
    assert read_dive(tmp_path / "d").info.heading_reference == "true"
    path.write_text(path.read_text().replace("heading_reference: true", "heading_reference: on"))
    problems = [str(p) for p in validate_dive(tmp_path / "d").problems]
    assert problems == ["dive.yaml: key heading_reference: Input should be 'magnetic' or 'true' (found 'on')"]


def test_fixes_before_the_dive_and_streams_that_start_late_are_fine(tmp_path: Path, small_dive) -> None:
    """Time sanity has tolerances: GPS fixes at the surface an hour before the dive, a stream that
    starts minutes after start_time."""
    import dataclasses

    dive = small_dive()
    gps = dataclasses.replace(dive.gps, t_s=dive.gps.t_s - 3000.0)
    write_dive(dataclasses.replace(dive, gps=gps), tmp_path / "d")
    assert validate_dive(tmp_path / "d").ok
    late = dataclasses.replace(dive.info, start_time_s=dive.info.start_time_s - 600.0)
    write_dive(dataclasses.replace(dive, info=late), tmp_path / "e")
    assert validate_dive(tmp_path / "e").ok


def test_a_stream_shifted_by_a_time_zone_is_named_with_the_hint(tmp_path: Path, small_dive) -> None:
    import dataclasses

    dive = small_dive()
    att = dataclasses.replace(dive.attitude, t_s=dive.attitude.t_s + 8 * 3600.0)
    write_dive(dataclasses.replace(dive, attitude=att), tmp_path / "d")
    (problem,) = validate_dive(tmp_path / "d").problems
    assert problem.file == "nav/attitude.csv" and "8.0 h after" in problem.message
    assert "local time +8 h from UTC" in problem.message
