"""Valid sample files of every kind the project reads, for the bad-input catalogue and the fuzz test.

Not a test module: ``tests/test_catalogue.py`` and ``tests/test_fuzz.py`` load it by its path
(the suite imports test files by path, so they cannot import each other). :func:`write_samples`
writes a small valid dive (every stream, an image index with tiny images matching an inline stereo
calibration) and, beside it, one valid file of every other format: loop closures of that dive, a
compass correction, a tide constituent file, an atmospheric series, a g2o graph, a mission, a ROS
and an OpenCV stereo calibration and a settings file. Each test corrupts a copy.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

START_S = 1_255_564_800.0  # 2009-10-15T00:00:00Z
IMAGE_W, IMAGE_H = 64, 48
N_IMAGES = 8

TINY_2D = """\
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1 0 0.1
VERTEX_SE2 2 2 0.1 0.2
EDGE_SE2 0 1 1 0 0.1 100 0 0 100 0 400
EDGE_SE2 1 2 1 0 0.1 100 0 0 100 0 400
EDGE_SE2 0 2 2 0.2 0.2 50 0 0 50 0 200
"""

TINY_3D = """\
VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1
EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400
"""


@dataclass(frozen=True)
class Samples:
    """Paths of the valid sample files (all inside ``root``; the dive is ``root/dive``)."""

    root: Path
    dive: Path
    loops: Path
    correction: Path
    tide: Path
    atmospheric: Path
    g2o: Path
    g2o_3d: Path
    mission: Path
    ros_left: Path
    ros_right: Path
    opencv: Path
    settings: Path


def _stereo():
    from auvnav.vehicle import CameraModel, Mount, StereoRig

    K = np.array([[50.0, 0.0, 31.5], [0.0, 50.0, 23.5], [0.0, 0.0, 1.0]])
    cam = CameraModel(IMAGE_W, IMAGE_H, K, np.zeros(5))
    return StereoRig(cam, cam, np.eye(3), np.array([-0.1, 0.0, 0.0]), Mount())


def small_dive(seconds: float = 120.0, rate_hz: float = 5.0):
    """A valid Dive: a slow circle with every stream, GPS at the start, an image index."""
    from auvnav.dive import (
        AttitudeStream,
        Dive,
        DiveInfo,
        DvlStream,
        GpsStream,
        ImageIndex,
        MagnetometerStream,
        PressureStream,
        UsblStream,
    )
    from auvnav.frames import GeodeticOrigin
    from auvnav.vehicle import Vehicle

    rng = np.random.default_rng(7)
    t = START_S + np.arange(0.0, seconds, 1.0 / rate_hz)
    n = t.size
    yaw = np.angle(np.exp(1j * (0.05 * (t - START_S) + 0.3)))
    lat, lon = np.radians(-14.05), np.radians(121.78)
    image_t = START_S + 10.0 + np.arange(N_IMAGES, dtype=float)
    return Dive(
        info=DiveInfo(
            name="sample",
            origin=GeodeticOrigin.from_degrees(-14.05, 121.78),
            start_time_s=START_S,
            declination_rad=float(np.radians(1.7)),
        ),
        vehicle=Vehicle(name="test", stereo=_stereo()),
        dvl=DvlStream(
            t,
            np.column_stack([np.full(n, 0.5), rng.normal(0, 0.003, (n, 2))]),
            np.full(n, 2.0),
            np.ones(n, bool),
        ),
        attitude=AttitudeStream(t, yaw, rng.normal(0, 0.01, n), rng.normal(0, 0.01, n)),
        pressure=PressureStream(t, 101325.0 + 2.0e5 + rng.normal(0, 100, n)),
        magnetometer=MagnetometerStream(t, rng.normal(0, 1e-5, (n, 3))),
        gps=GpsStream(t[:5], np.full(5, lat), np.full(5, lon), np.full(5, 3.0)),
        usbl=UsblStream(
            t[::50],
            np.full(t[::50].size, lat),
            np.full(t[::50].size, lon),
            np.full(t[::50].size, 20.0),
            np.full(t[::50].size, 5.0),
        ),
        images=ImageIndex(
            image_t,
            np.array([f"left/{k:04d}.png" for k in range(N_IMAGES)]),
            np.array([f"right/{k:04d}.png" for k in range(N_IMAGES)]),
        ),
    )


def _images(dive_path: Path) -> None:
    import cv2

    rng = np.random.default_rng(1)
    for side in ("left", "right"):
        (dive_path / "images" / side).mkdir(parents=True, exist_ok=True)
        for k in range(N_IMAGES):
            image = rng.integers(0, 255, (IMAGE_H, IMAGE_W), dtype=np.uint8)
            cv2.imwrite(str(dive_path / "images" / side / f"{k:04d}.png"), image)


def _loops(path: Path, image_t: np.ndarray) -> None:
    from auvnav.frames import euler2rot, se3
    from auvnav.vision.loopfile import loops_from_transforms, write_loops

    i, j = np.array([0, 1, 2]), np.array([4, 5, 6])
    T = se3(euler2rot(np.zeros(3), np.zeros(3), np.zeros(3)), np.tile([0.1, 0.0, 0.0], (3, 1)))
    cov = np.tile(np.diag([1e-4, 1e-4, 1e-4, 1e-5, 1e-5, 1e-5]), (3, 1, 1))
    write_loops(loops_from_transforms(i, j, image_t[i], image_t[j], T, cov, np.full(3, 40)), path)


def _ros(left: Path, right: Path) -> None:
    from auvnav.config import dump_yaml

    for path, tx in ((left, 0.0), (right, -5.0)):
        info = {
            "image_width": IMAGE_W,
            "image_height": IMAGE_H,
            "camera_name": path.stem,
            "camera_matrix": {"rows": 3, "cols": 3, "data": [50.0, 0, 31.5, 0, 50.0, 23.5, 0, 0, 1]},
            "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.0] * 5},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": [1.0, 0, 0, 0, 1, 0, 0, 0, 1]},
            "projection_matrix": {
                "rows": 3,
                "cols": 4,
                "data": [50.0, 0, 31.5, tx, 0, 50, 23.5, 0, 0, 0, 1, 0],
            },
        }
        path.write_text(dump_yaml(info), encoding="utf-8")


def _opencv(path: Path) -> None:
    import cv2

    rig = _stereo()
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", IMAGE_W)
    fs.write("image_height", IMAGE_H)
    fs.write("K1", rig.left.K)
    fs.write("D1", rig.left.D.reshape(1, -1))
    fs.write("K2", rig.right.K)
    fs.write("D2", rig.right.D.reshape(1, -1))
    fs.write("R", rig.R_right_left)
    fs.write("T", rig.t_right_left_m.reshape(3, 1))
    fs.release()


def write_samples(root: Path, *, seconds: float = 120.0, rate_hz: float = 5.0) -> Samples:
    """Write every valid sample under ``root`` (see the module docstring)."""
    from auvnav.compass.correction import write_correction
    from auvnav.compass.deviation import DeviationModel
    from auvnav.config import dump_yaml
    from auvnav.depth.tide import Constituent, TideModel, write_constituents
    from auvnav.dive import write_dive
    from auvnav.plan.missions import survey, write_mission

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    dive = small_dive(seconds, rate_hz)
    write_dive(dive, root / "dive")
    _images(root / "dive")
    s = Samples(
        root=root,
        dive=root / "dive",
        loops=root / "loops.csv",
        correction=root / "correction.yaml",
        tide=root / "tide.csv",
        atmospheric=root / "atmosphere.csv",
        g2o=root / "graph.g2o",
        g2o_3d=root / "graph3d.g2o",
        mission=root / "mission.yaml",
        ros_left=root / "left.yaml",
        ros_right=root / "right.yaml",
        opencv=root / "stereo.yml",
        settings=root / "settings.yaml",
    )
    _loops(s.loops, dive.images.t_s)
    model = DeviationModel(
        np.radians(0.5),
        np.radians([1.5, -0.6, 0.3]),
        np.radians([-1.0, 0.4, -0.2]),
        constant_source="arbitrary",
    )
    write_correction(model, s.correction)
    tide = TideModel(
        (Constituent("M2", 0.8, 1.0), Constituent("K1", 0.3, 2.0)), np.radians(-14.05), reference="sample"
    )
    write_constituents(tide, s.tide)
    times = START_S - 600 + 300.0 * np.arange(6)
    s.atmospheric.write_text(
        "t,pressure_dbar\n" + "".join(f"{t:.1f},{10.13 + 0.01 * k:.4f}\n" for k, t in enumerate(times)),
        encoding="utf-8",
    )
    s.g2o.write_text(TINY_2D, encoding="utf-8")
    s.g2o_3d.write_text(TINY_3D, encoding="utf-8")
    write_mission(survey(width_m=10.0, height_m=2.0, spacing_m=1.0, lead_in_m=5.0), s.mission)
    _ros(s.ros_left, s.ros_right)
    _opencv(s.opencv)
    s.settings.write_text(dump_yaml({"slam": {"robust": "huber"}, "nav": {}}), encoding="utf-8")
    dive.dvl.to_frame().to_parquet(root / "dvl.parquet", index=False)  # the DVL stream as Parquet
    return s
