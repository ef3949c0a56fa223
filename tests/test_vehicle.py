"""vehicle.yaml: strict keys, real rotations, stereo calibrations from OpenCV and ROS files."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from auvnav.errors import ConfigError
from auvnav.frames import euler2rot
from auvnav.vehicle import Vehicle, read_vehicle, vehicle_to_mapping, write_vehicle

K = np.array([[1600.0, 0, 679.5], [0, 1600.0, 511.5], [0, 0, 1]])
D = np.array([0.01, -0.02, 0.0005, -0.0003, 0.0])
R_RL = euler2rot(0.002, -0.001, 0.003)
T_RL = np.array([-0.0701, 0.0004, 0.0012])


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "vehicle.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_defaults_and_round_trip(tmp_path: Path) -> None:
    v = read_vehicle(
        _write(
            tmp_path,
            {"name": "sirius", "dvl": {"mount": {"rpy_deg": [0, 0, 45], "lever_arm_m": [0.5, 0, 0.3]}}},
        )
    )
    assert v.heading_sigma_rad == pytest.approx(np.radians(1.0))
    np.testing.assert_allclose(v.dvl.R_body_sensor @ [1, 0, 0], [np.sqrt(0.5), np.sqrt(0.5), 0], atol=1e-12)
    write_vehicle(v, tmp_path / "again.yaml")
    again = read_vehicle(tmp_path / "again.yaml")
    np.testing.assert_allclose(again.dvl.R_body_sensor, v.dvl.R_body_sensor, atol=1e-15)
    assert vehicle_to_mapping(again) == vehicle_to_mapping(v)


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        ({"dvl": {"speed": 1}}, "key dvl.speed: unknown key"),
        ({"compass": {"mount": {"R_body_sensor": [[1, 0, 0], [0, 0, 1], [0, 1, 0]]}}}, "not a rotation"),
        ({"gps": {"mount": {"lever_arm_m": [1, 2]}}}, "must have 3 elements"),
        ({"dvl": {"mount": {"rpy_deg": [0, 0, 1], "R_body_sensor": np.eye(3).tolist()}}}, "not both"),
        ({"stereo": {"calibration_file": "x.yaml"}}, "calibration_format"),
        (
            {"stereo": {"calibration_file": "x.yml", "calibration_format": "opencv", "left_bayer": "rgb"}},
            "rggb",
        ),
    ],
)
def test_bad_vehicle_files_are_one_line_errors(tmp_path: Path, data: dict, expected: str) -> None:
    with pytest.raises(ConfigError) as info:
        read_vehicle(_write(tmp_path, data))
    message = str(info.value)
    assert expected in message and len(message.splitlines()) == 1 and "vehicle.yaml" in message


def _write_opencv_stereo(path: Path) -> None:
    """A stereo calibration as OpenCV's samples write it (M1, D1, M2, D2, R, T, image size)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1360)
    fs.write("image_height", 1024)
    for name, m in [("M1", K), ("D1", D), ("M2", K), ("D2", D), ("R", R_RL), ("T", T_RL.reshape(3, 1))]:
        fs.write(name, m)
    fs.release()


def test_opencv_filestorage_stereo(tmp_path: Path) -> None:
    _write_opencv_stereo(tmp_path / "stereo.yml")
    v = read_vehicle(
        _write(tmp_path, {"stereo": {"calibration_file": "stereo.yml", "calibration_format": "opencv"}})
    )
    assert v.stereo is not None
    np.testing.assert_allclose(v.stereo.left.K, K)
    np.testing.assert_allclose(v.stereo.R_right_left, R_RL, atol=1e-12)
    assert v.stereo.baseline_m == pytest.approx(np.linalg.norm(T_RL))
    assert np.degrees(v.stereo.left.hfov_rad) == pytest.approx(46.05, abs=0.01)
    assert v.stereo.left.bayer is None


def test_a_raw_colour_camera_keeps_its_bayer_filter(tmp_path: Path) -> None:
    """The ACFR layout: a raw colour left camera (its filter named by the top-left 2 x 2 block), a
    monochrome right one; the filter survives the round trip and enters the cache key."""
    from auvnav.vision.camera import rig_digest

    _write_opencv_stereo(tmp_path / "stereo.yml")
    stereo = {"calibration_file": "stereo.yml", "calibration_format": "opencv"}
    plain = read_vehicle(_write(tmp_path, {"stereo": stereo}))
    v = read_vehicle(_write(tmp_path, {"stereo": {**stereo, "left_bayer": "rggb"}}))
    assert v.stereo is not None and plain.stereo is not None
    assert (v.stereo.left.bayer, v.stereo.right.bayer) == ("rggb", None)
    write_vehicle(v, tmp_path / "again.yaml")
    again = read_vehicle(tmp_path / "again.yaml")
    assert again.stereo is not None and again.stereo.left.bayer == "rggb"
    assert vehicle_to_mapping(again) == vehicle_to_mapping(v)
    assert rig_digest(v.stereo) != rig_digest(plain.stereo)


def test_ros_camera_info_stereo(tmp_path: Path) -> None:
    """Build camera_info files the way ROS camera_calibration does (cv2.stereoRectify), read them back."""
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K, D, K, D, (1360, 1024), R_RL, T_RL.reshape(3, 1), alpha=0)
    for name, R, P in [("left", R1, P1), ("right", R2, P2)]:
        info = {
            "image_width": 1360,
            "image_height": 1024,
            "camera_name": name,
            "camera_matrix": {"rows": 3, "cols": 3, "data": K.ravel().tolist()},
            "distortion_model": "plumb_bob",
            "distortion_coefficients": {"rows": 1, "cols": 5, "data": D.tolist()},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": R.ravel().tolist()},
            "projection_matrix": {"rows": 3, "cols": 4, "data": P.ravel().tolist()},
        }
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(info))
    v = read_vehicle(
        _write(
            tmp_path,
            {"stereo": {"calibration_file": ["left.yaml", "right.yaml"], "calibration_format": "ros"}},
        )
    )
    assert v.stereo is not None
    np.testing.assert_allclose(v.stereo.R_right_left, R_RL, atol=1e-9)
    np.testing.assert_allclose(v.stereo.t_right_left_m, T_RL, atol=1e-9)


def test_ros_file_that_is_not_camera_info(tmp_path: Path) -> None:
    (tmp_path / "left.yaml").write_text("a: 1\n")
    (tmp_path / "right.yaml").write_text("a: 1\n")
    with pytest.raises(ConfigError, match=r"left.yaml: not a ROS camera_info YAML"):
        read_vehicle(
            _write(
                tmp_path,
                {"stereo": {"calibration_file": ["left.yaml", "right.yaml"], "calibration_format": "ros"}},
            )
        )


def test_camera_scaling_keeps_field_of_view() -> None:
    from auvnav.vehicle import CameraModel

    cam = CameraModel(1360, 1024, K)
    half = cam.scaled(0.5)
    assert (half.width, half.height) == (680, 512)
    assert half.hfov_rad == pytest.approx(cam.hfov_rad, rel=1e-3)


def test_vehicle_dataclass_rejects_bad_mount() -> None:
    from auvnav.vehicle import Mount

    with pytest.raises(ValueError, match="not a rotation"):
        Mount(R_body_sensor=np.diag([1.0, -1.0, 1.0]))
    assert Vehicle().dvl.lever_arm_body_m.shape == (3,)
