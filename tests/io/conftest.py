"""Shared fixtures of the importer and exporter tests: one small simulated dive, navigated once."""

from __future__ import annotations

import math
import shutil
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

from auvnav.compass.deviation import DeviationModel

sys.path.insert(0, str(Path(__file__).parent))  # io_writers, the independent format writers

END_TOL_M = 1e-3  # issue 15: the navigation's end error identical within 1 mm


@dataclass(frozen=True)
class Navigated:
    """A dive folder and the end of its navigation."""

    path: Path
    dr_end_m: np.ndarray
    filter_end_m: np.ndarray
    dr_end_error_m: float
    filter_end_error_m: float


def navigate(path: Path, truth_dir: Path) -> Navigated:
    """Run the navigation stage on a dive and measure its end errors against a truth trajectory."""
    from auvnav import products as P
    from auvnav.pipeline import run_stage
    from auvnav.trajectory import read_trajectory

    run_stage(path, "nav")
    truth = read_trajectory(truth_dir / "trajectory.csv")
    out = {}
    for name, product in (("dr", P.NAV_DR), ("filter", P.NAV_FILTER)):
        track = read_trajectory(product.path(path))
        end = track.p_ned_m[-1]
        out[name] = (end, float(np.linalg.norm(end - truth.interpolate(track.t_s[-1:]).p_ned_m[0])))
    return Navigated(path, out["dr"][0], out["filter"][0], out["dr"][1], out["filter"][1])


def assert_same_navigation(a: Navigated, b: Navigated) -> dict[str, float]:
    """End positions within 1 mm (so the end errors are identical within 1 mm); the differences."""
    diff = {
        "dr_end_m": float(np.linalg.norm(a.dr_end_m - b.dr_end_m)),
        "filter_end_m": float(np.linalg.norm(a.filter_end_m - b.filter_end_m)),
        "dr_end_error_m": abs(a.dr_end_error_m - b.dr_end_error_m),
        "filter_end_error_m": abs(a.filter_end_error_m - b.filter_end_error_m),
    }
    assert all(v < END_TOL_M for v in diff.values()), diff
    print(
        f"end error {a.filter_end_error_m:.4f} m (filter), {a.dr_end_error_m:.4f} m (dr); differences", diff
    )
    return diff


@dataclass(frozen=True)
class Simulated:
    path: Path
    truth: Path
    nav: Navigated

    @property
    def dive(self):
        from auvnav.dive import read_dive

        return read_dive(self.path)


@pytest.fixture(scope="session")
def simulated(tmp_path_factory) -> Simulated:
    """A 20-minute transit (two 60 m legs, GPS at the surface, USBL, the camera's trigger log),
    simulated and navigated once."""
    from auvnav.sim.run import run_scenario

    root = tmp_path_factory.mktemp("io_sim")
    path = root / "transit"
    run_scenario("transit", path, seed=3, geometry={"legs": 2, "leg_m": 60.0}, usbl=True, truth_loops=True)
    return Simulated(path, path / "truth", navigate(path, path / "truth"))


LOOPS = [(3, 40), (10, 200), (50, 250)]  # image pairs of the loop closures written
DEVIATION = DeviationModel(math.radians(0.8), np.radians([1.5, -0.6, 0.3]), np.radians([-1.0, 0.4, -0.2]))


@dataclass(frozen=True)
class Exportable:
    path: Path
    track: object
    origin: object


@pytest.fixture(scope="session")
def exportable(simulated, tmp_path_factory) -> Exportable:
    """The simulated dive with a stereo rig, three loop closures and a compass correction."""
    from auvnav import products as P
    from auvnav.compass.correction import write_correction
    from auvnav.dive import read_dive
    from auvnav.frames import se3
    from auvnav.sim.camera import default_stereo_rig
    from auvnav.trajectory import read_trajectory
    from auvnav.vehicle import write_vehicle
    from auvnav.vision.loopfile import loops_from_transforms, write_loops

    path = tmp_path_factory.mktemp("export") / "dive"
    shutil.copytree(simulated.path, path)
    dive = read_dive(path)
    write_vehicle(replace(dive.vehicle, stereo=default_stereo_rig()), path / "vehicle.yaml")
    i = np.array([a for a, _ in LOOPS])
    j = np.array([b for _, b in LOOPS])
    t = dive.images.t_s
    T = np.repeat(se3(np.eye(3), np.zeros(3))[None], len(LOOPS), axis=0)
    write_loops(
        loops_from_transforms(
            i, j, t[i], t[j], T, np.repeat(np.eye(6)[None] * 1e-4, len(LOOPS), 0), np.full(3, 50)
        ),
        P.LOOPS.path(path),
    )
    write_correction(DEVIATION, P.COMPASS_CORRECTION.path(path))
    return Exportable(path, read_trajectory(P.NAV_FILTER.path(path)), dive.info.origin)


@dataclass(frozen=True)
class Written:
    """The simulated dive in every vendor format, written once (io_writers)."""

    acfr: tuple[Path, Path]  # combined.RAW.auv, mission.cfg
    pd0: Path
    pd0_held: object  # the dive as PD0 holds it
    nmea: Path
    csv: tuple[list[Path], Path]  # files, mapping
    bags: dict[int, Path]  # ROS version -> bag


@pytest.fixture(scope="session")
def written(simulated, tmp_path_factory) -> Written:
    from io_writers import write_acfr, write_bag, write_csvs, write_nmea, write_pd0

    root = tmp_path_factory.mktemp("formats")
    dive = simulated.dive
    acfr = write_acfr(dive, root / "acfr")
    held = write_pd0(dive, root / "dvl.pd0", layout="workhorse", coords="ship")
    write_nmea(dive, root / "gps.nmea")
    csv = write_csvs(dive, root / "csv")
    bags = {1: root / "dive.bag", 2: root / "dive_bag"}
    for version, bag in bags.items():
        write_bag(dive, bag, version=version, images=3)
    return Written(acfr, root / "dvl.pd0", held, root / "gps.nmea", csv, bags)
