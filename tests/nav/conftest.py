"""Fixtures of the navigation tests: small synthetic missions with an exact truth."""

from __future__ import annotations

import math

import pytest

from auvnav.nav.synthetic import Motion, lawnmower_legs, legs_motion


@pytest.fixture(scope="session")
def survey() -> Motion:
    """Four 100 m survey lines 10 m apart at 0.5 m/s, 5 Hz: about 17 minutes, 4200 samples."""
    return legs_motion(lawnmower_legs(4, 100.0, 10.0), rate_hz=5.0, turn_rate_rps=0.1)


@pytest.fixture(scope="session")
def transit() -> Motion:
    """A 600 m transit on 030 after a dog-leg, 5 Hz."""
    return legs_motion([(math.radians(100.0), 50.0), (math.radians(30.0), 600.0)], rate_hz=5.0)
