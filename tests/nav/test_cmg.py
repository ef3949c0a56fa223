"""Course made good between GPS fixes against the dead-reckoned course (paper Fig. 5b)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from auvnav.frames import wrap_angle
from auvnav.nav.cmg import course_made_good
from auvnav.nav.deadreckon import dead_reckon
from auvnav.nav.inputs import nav_inputs
from auvnav.nav.synthetic import Motion, legs_motion, synthetic_dive

DEG = math.pi / 180.0


@pytest.fixture(scope="module")
def two_transits() -> Motion:
    """Transits on 030 and 210, 400 m each, with a turn between."""
    return legs_motion([(30 * DEG, 400.0), (210 * DEG, 400.0)], rate_hz=2.0, turn_rate_rps=0.1)


def test_course_error_is_the_compass_error(two_transits: Motion) -> None:
    """GPS at the start, at the turn and at the end; the compass reads 4 degrees high."""
    t = two_transits.truth.t_s
    turn_start = int(400.0 / 0.5 * 2.0)  # samples on the first leg
    gps = t[[0, 1, turn_start, len(t) - 2, len(t) - 1]]
    dive = synthetic_dive(two_transits, gps_times_s=gps, compass_error_rad=4 * DEG, declination_rad=2 * DEG)
    legs = course_made_good(dive, dead_reckon(nav_inputs(dive)))
    assert len(legs) == 2  # fixes more than a minute apart bound a leg
    first, second = legs
    assert first.length_m == pytest.approx(399.75, abs=1e-3)  # from the second fix, 0.5 s in
    assert first.cmg_rad == pytest.approx(30 * DEG, abs=1e-9)
    assert first.dr_course_rad == pytest.approx(34 * DEG, abs=1e-6)
    assert first.course_error_rad == pytest.approx(-4 * DEG, abs=1e-6)  # cmg - dr course
    # The compass heading as logged: true - declination + error.
    assert first.mean_compass_heading_rad == pytest.approx(32 * DEG, abs=1e-9)
    assert first.compass_heading_spread_rad < 1e-6
    assert first.course_sigma_rad == pytest.approx(math.hypot(3.0, 3.0) / first.length_m)
    assert first.duration_s == pytest.approx(799.5)
    # The second leg holds the 180 degree turn: its compass heading spreads, its course is still right.
    assert second.compass_heading_spread_rad > 0.3
    assert float(wrap_angle(second.course_error_rad + 4 * DEG)) == pytest.approx(0.0, abs=1e-6)


def test_no_gps_no_legs(two_transits: Motion) -> None:
    dive = synthetic_dive(two_transits)
    assert course_made_good(dive, dead_reckon(nav_inputs(dive))) == []


def test_fixes_close_together_are_no_leg(two_transits: Motion) -> None:
    t = two_transits.truth.t_s
    dive = synthetic_dive(two_transits, gps_times_s=t[:60:2])  # 30 s of 1 Hz fixes
    assert course_made_good(dive, dead_reckon(nav_inputs(dive))) == []
    assert np.all(np.diff(dive.gps.t_s) <= 60.0)
