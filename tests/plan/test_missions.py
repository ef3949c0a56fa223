"""Mission generators (geometry: leg counts, lengths, headings) and the auvnav-mission/1 file."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from auvnav.cli import main
from auvnav.errors import ConfigError
from auvnav.plan.missions import (
    Ascend,
    Descend,
    Line,
    Spin,
    Surface,
    build_mission,
    navcheck,
    read_mission,
    spin,
    survey,
    survey_line_spacing,
    transit,
    write_mission,
)

atol_m = 1e-9  # generated coordinates are exact up to floating point


def legs(line: Line) -> np.ndarray:
    """(n, 2) leg vectors of a line segment."""
    return np.diff(np.asarray(line.waypoints_ne_m), axis=0)


def the_line(mission) -> Line:
    lines = [s for s in mission.segments if isinstance(s, Line)]
    assert len(lines) == 1
    return lines[0]


def test_dive_structure() -> None:
    kinds = [type(s) for s in survey().segments]
    assert kinds == [Surface, Descend, Line, Ascend, Surface]


def test_navcheck_star_and_grid() -> None:
    m = navcheck()  # 12 headings, 50 m arms, 10 m grid at 1 m
    v = legs(the_line(m))
    star, grid = v[:24], v[24:]
    # reciprocal legs: out along k * 30 deg, back along the reciprocal, each 50 m
    for k in range(12):
        out, back = star[2 * k], star[2 * k + 1]
        assert np.linalg.norm(out) == pytest.approx(50.0, abs=atol_m)
        assert np.degrees(np.arctan2(out[1], out[0])) % 360 == pytest.approx(30.0 * k, abs=1e-9)
        np.testing.assert_allclose(back, -out, atol=atol_m)
    points = np.asarray(the_line(m).waypoints_ne_m)
    assert np.sum(np.all(np.abs(points[:25]) < atol_m, axis=1)) == 13  # the centre, 12 revisits
    # grid: 11 north-south and 11 east-west lines of 10 m, joined by 1 m steps
    lines = grid[np.linalg.norm(grid, axis=1) > 9.999]
    assert len(lines) == 22
    assert np.all(np.abs(lines[:11, 1]) < atol_m) and np.all(np.abs(lines[11:, 0]) < atol_m)
    assert np.abs(points[25:]).max() == pytest.approx(5.0)
    # about an hour at 0.5 m/s
    assert 2700 < m.line_length_m() / 0.5 < 3600


def test_navcheck_options() -> None:
    m = navcheck(headings=6, leg_m=20.0, grid_m=4.0, grid_spacing_m=2.0)
    v = legs(the_line(m))
    assert np.allclose(np.linalg.norm(v[:12], axis=1), 20.0)
    assert np.sum(np.linalg.norm(v[12:], axis=1) > 3.999) == 6  # 3 + 3 grid lines of 4 m


def test_survey_lawnmower() -> None:
    m = survey()  # 75 m x 50 m at 1 m after a 100 m lead-in (paper section IV-A)
    v = legs(the_line(m))
    assert np.linalg.norm(v[0]) == pytest.approx(100.0)  # lead-in, north
    lines = v[1::2]
    steps = v[2::2]
    assert len(lines) == 51 and len(steps) == 50
    np.testing.assert_allclose(np.abs(lines[:, 0]), 75.0, atol=atol_m)
    np.testing.assert_allclose(np.sign(lines[:, 0]), [(-1) ** i for i in range(51)])  # reciprocal
    np.testing.assert_allclose(steps, np.tile([0.0, 1.0], (50, 1)), atol=atol_m)  # 1 m to the east
    assert m.line_length_m() == pytest.approx(100 + 51 * 75 + 50)
    assert 2.0 < m.planned_duration_s(0.3, 45.0) / 3600 < 3.0


def test_survey_heading_turns_the_pattern() -> None:
    v = legs(the_line(survey(width_m=10, height_m=2, lead_in_m=0, heading_deg=90)))
    np.testing.assert_allclose(v[0], [0.0, 10.0], atol=atol_m)  # first line east
    np.testing.assert_allclose(v[1], [-1.0, 0.0], atol=atol_m)  # step to the right: south


def test_transit_legs() -> None:
    m = transit()  # 4 legs of 2 km
    lines = [s for s in m.segments if isinstance(s, Line)]
    assert len(lines) == 4
    headings = [math.degrees(math.atan2(*legs(s)[0][::-1])) % 360 for s in lines]
    np.testing.assert_allclose(headings, [0, 90, 180, 270], atol=1e-9)
    assert all(s.length_m() == pytest.approx(2000.0) for s in lines)
    assert lines[-1].waypoints_ne_m[-1] == pytest.approx((0.0, 0.0), abs=1e-9)  # a closed square
    kinds = [type(s) for s in m.segments]
    assert kinds == [Surface] + [Descend, Line, Ascend, Surface] * 4  # GPS between legs


def test_spin() -> None:
    s = [x for x in spin(turns=2).segments if isinstance(x, Spin)]
    assert len(s) == 1 and s[0].turns == 2 and s[0].direction == 1


def test_round_trip(tmp_path: Path) -> None:
    for m in (navcheck(headings=4), survey(width_m=5, height_m=2), transit(legs=2, leg_m=10), spin()):
        path = tmp_path / f"{m.name}.yaml"
        write_mission(m, path)
        assert read_mission(path) == m


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("format: auvnav-mission/1\nsegments: [{type: surface, wait_s: 3}]\n", "unknown key"),
        ("format: auvnav-mission/2\nsegments: [{type: surface}]\n", "key format"),
        ("format: auvnav-mission/1\nsegments: [{type: line, waypoints: [[1, 2, 3]]}]\n", "segments.0"),
        ("format: auvnav-mission/1\nspeed_mps: -1\nsegments: [{type: descend}]\n", "key speed_mps"),
        ("format: auvnav-mission/1\nsegments: [{type: hover}]\n", "key segments.0"),
        ("format: auvnav-mission/1\nsegments: [\n", "not valid YAML at line"),
        ("- just a list\n", "must be a mapping"),
    ],
)
def test_bad_mission_file(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        read_mission(path)
    assert str(path) in str(info.value) and message in str(info.value)
    assert "\n" not in str(info.value)


def test_build_mission_options() -> None:
    assert build_mission("survey", {"width_m": 10.0, "headings": None}).geometry["width_m"] == 10.0
    with pytest.raises(ConfigError, match="--headings: not an option of the survey mission"):
        build_mission("survey", {"headings": 6})
    with pytest.raises(ConfigError, match="unknown mission kind"):
        build_mission("zigzag", {})
    with pytest.raises(ConfigError, match="positive"):
        build_mission("survey", {"spacing_m": -1.0})


def test_line_spacing_of_the_plan() -> None:
    """The planned polyline itself, sampled densely, has the planned spacing everywhere."""
    m = survey(width_m=20, height_m=3, lead_in_m=5)
    w = np.asarray(the_line(m).waypoints_ne_m)
    p = np.concatenate([np.linspace(a, b, 200) for a, b in itertools.pairwise(w)])
    spacing = survey_line_spacing(p, p, m, margin_m=2.0)
    assert spacing.shape == (3, 17)
    np.testing.assert_allclose(spacing, 1.0, atol=1e-9)


def test_plan_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "nav.yaml"
    assert main(["plan", "navcheck", "--headings", "8", "--leg-m", "30", "--out", str(out)]) == 0
    m = read_mission(out)
    assert m.geometry["headings"] == 8 and m.geometry["leg_m"] == 30.0
    assert main(["plan", "navcheck", "--out", str(out)]) == 1  # exists
    assert "exists" in capsys.readouterr().err
    assert main(["plan", "survey", "--width-m", "10", "--out", str(out), "--overwrite", "--json"]) == 0
    assert '"legs"' in capsys.readouterr().out
