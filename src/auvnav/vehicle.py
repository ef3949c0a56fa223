"""Vehicle configuration (``vehicle.yaml``): sensor mounts, lever arms, noise figures, stereo rig.

Checked strictly: an unknown key is an error, a rotation must be a rotation. Mounts give the sensor's
rotation into the body frame (``R_body_sensor``, or ``rpy_deg`` as roll, pitch, yaw of Euler ZYX) and its
lever arm in body FRD. Noise figures are 1-sigma. The stereo rig is inline or imported from an OpenCV
``FileStorage`` YAML (``stereoCalibrate`` output) or a pair of ROS ``camera_info`` YAML files.

Default noise figures (the ``DEFAULT_*`` constants) describe the paper's class of vehicle, ACFR's
Sirius (Williams et al. 2012, "Monitoring of benthic reference sites", IEEE Robotics & Automation
Magazine 19(1)): a Teledyne RDI Workhorse Navigator 1200 kHz DVL (long-term accuracy +-0.2% +-1 mm/s,
RDI datasheet), a flux-gate compass with inclinometer of the PNI TCM2 class (heading +-1 deg after
calibration, tilt +-0.2 deg: PNI TCM2 datasheet; the paper's section II-C gives the same one-degree
budget), and a Paroscientific Digiquartz pressure sensor (0.01% of full scale: Paroscientific 8000
series datasheet; 0.1 dbar for a 1000 dbar rating).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, ValidationError, field_validator, model_validator
from pydantic import Field as PydanticField

from auvnav.config import MAX_BYTES, dump_yaml, load_yaml, parse_yaml, pydantic_problems, quote, read_text
from auvnav.errors import ConfigError, Problem
from auvnav.frames import euler2rot, is_rotation, rot2euler

FloatArray = NDArray[np.float64]

DEFAULT_DVL_VELOCITY_SIGMA_MPS = 0.003  # RDI Workhorse 1200 kHz: single-ping noise at 0.5 m/s, 2 m range
DEFAULT_DVL_SCALE_SIGMA = 0.002  # RDI Workhorse long-term accuracy +-0.2%
DEFAULT_DVL_MAX_ALTITUDE_M = 30.0  # RDI Workhorse 1200 kHz bottom-track range
DEFAULT_HEADING_SIGMA_DEG = 1.0  # PNI TCM2 heading accuracy; paper section II-C
DEFAULT_PITCH_ROLL_SIGMA_DEG = 0.2  # PNI TCM2 tilt accuracy
DEFAULT_PRESSURE_SIGMA_DBAR = 0.1  # Digiquartz 0.01% of a 1000 dbar full scale
DEFAULT_GPS_SIGMA_M = 3.0  # consumer GPS horizontal accuracy, 1 sigma
DEFAULT_USBL_SIGMA_M = 5.0  # USBL at 100 m slant range, ~ 0.5% of range plus ship motion

# ---------------------------------------------------------------------------------------------
# Typed configuration (SI, radians)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Mount:
    """Where a sensor sits on the body.

    Parameters
    ----------
    R_body_sensor : ndarray, shape (3, 3)
        Maps sensor-frame vectors into the body frame (FRD).
    lever_arm_body_m : ndarray, shape (3,)
        Sensor origin relative to the vehicle reference point, metres, body FRD.
    """

    R_body_sensor: FloatArray = field(default_factory=lambda: np.eye(3))
    lever_arm_body_m: FloatArray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        if not is_rotation(self.R_body_sensor):
            raise ValueError(
                f"R_body_sensor is not a rotation (orthonormal, det +1); found {self.R_body_sensor!r}"
            )
        if np.shape(self.lever_arm_body_m) != (3,):
            raise ValueError(
                f"lever_arm_body_m must have shape (3,); found {np.shape(self.lever_arm_body_m)}"
            )


#: Colour filter layouts of raw images, named by the 2 x 2 block at the top-left corner.
Bayer = Literal["rggb", "bggr", "grbg", "gbrg"]
BAYER_PATTERNS: tuple[str, ...] = get_args(Bayer)


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with OpenCV radial-tangential distortion.

    Parameters
    ----------
    width, height : int
        Image size, pixels.
    K : ndarray, shape (3, 3)
        Intrinsic matrix, pixels.
    D : ndarray, shape (k,)
        Distortion (k1, k2, p1, p2[, k3]), OpenCV order.
    bayer : str, optional
        The colour filter of a camera that writes its sensor's raw mosaic (one channel; survey cameras
        often write 12- or 16-bit raw TIFF or PNG): the 2 x 2 block at the image's top-left corner,
        one of :data:`BAYER_PATTERNS`. Its images are demosaiced when read. None: images already grey
        or colour.
    """

    width: int
    height: int
    K: FloatArray
    D: FloatArray = field(default_factory=lambda: np.zeros(5))
    bayer: str | None = None

    def __post_init__(self) -> None:
        if not (0 < self.width <= MAX_IMAGE_PX and 0 < self.height <= MAX_IMAGE_PX):
            raise ValueError(f"image size must be positive; found {self.width}x{self.height}")
        K = np.asarray(self.K)
        if (
            K.shape != (3, 3)
            or not np.all(np.isfinite(K))
            or K[0, 0] <= 0
            or K[1, 1] <= 0
            or not np.allclose(K[2], [0, 0, 1])
        ):
            raise ValueError(
                f"K must be a 3x3 intrinsic matrix with positive focal lengths; found {quote(K.tolist())}"
            )
        D = np.asarray(self.D)
        if D.ndim != 1 or D.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(D)):
            raise ValueError(f"D must hold 4, 5, 8, 12 or 14 finite coefficients; found {quote(D.tolist())}")
        if self.bayer is not None and self.bayer not in BAYER_PATTERNS:
            raise ValueError(f"bayer must be one of {', '.join(BAYER_PATTERNS)}; found {quote(self.bayer)}")

    @property
    def hfov_rad(self) -> float:
        """Horizontal field of view (undistorted pinhole), radians."""
        return float(2 * np.arctan(self.width / (2 * self.K[0, 0])))

    def scaled(self, factor: float) -> CameraModel:
        """The same camera for images resized by ``factor`` (pixel-centre convention; a resized image is
        a demosaiced one: no Bayer pattern)."""
        S = np.diag([factor, factor, 1.0])
        K = S @ self.K
        K[0, 2] = (self.K[0, 2] + 0.5) * factor - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * factor - 0.5
        return CameraModel(round(self.width * factor), round(self.height * factor), K, self.D.copy())


@dataclass(frozen=True)
class StereoRig:
    """A calibrated stereo pair mounted on the body.

    ``X_right = R_right_left @ X_left + t_right_left_m`` (OpenCV ``stereoCalibrate``'s R, T).
    ``mount`` places the left camera (z forward along the optical axis, x right, y down in the image)
    in the body frame.
    """

    left: CameraModel
    right: CameraModel
    R_right_left: FloatArray
    t_right_left_m: FloatArray
    mount: Mount

    def __post_init__(self) -> None:
        if not is_rotation(self.R_right_left):
            raise ValueError("R_right_left is not a rotation")
        t = np.asarray(self.t_right_left_m, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)) or np.linalg.norm(t) <= 0:
            raise ValueError(f"t_right_left_m must be a non-zero 3-vector; found {quote(t.tolist())}")
        if (self.left.width, self.left.height) != (self.right.width, self.right.height):
            raise ValueError(
                f"left and right image sizes differ ({self.left.width}x{self.left.height} and "
                f"{self.right.width}x{self.right.height})"
            )
        # The rectification (OpenCV stereoRectify) needs the right camera to the right of the left.
        centre = -np.asarray(self.R_right_left, dtype=float).T @ t  # right camera centre, left frame
        if not centre[0] > abs(centre[1]):
            raise ValueError(
                f"the right camera is not to the right of the left one (its centre is at "
                f"{np.round(centre, 4).tolist()} m in the left camera's frame): left and right swapped?"
            )

    @property
    def baseline_m(self) -> float:
        return float(np.linalg.norm(self.t_right_left_m))

    def with_bayer(self, left: str | None, right: str | None) -> StereoRig:
        """The same rig with the cameras' colour filters (:attr:`CameraModel.bayer`) set to these."""
        return replace(self, left=replace(self.left, bayer=left), right=replace(self.right, bayer=right))


@dataclass(frozen=True)
class Vehicle:
    """Sensor mounts and noise figures (1 sigma, SI)."""

    name: str = "auv"
    dvl: Mount = field(default_factory=Mount)
    dvl_velocity_sigma_mps: float = DEFAULT_DVL_VELOCITY_SIGMA_MPS
    dvl_scale_sigma: float = DEFAULT_DVL_SCALE_SIGMA
    dvl_max_altitude_m: float = DEFAULT_DVL_MAX_ALTITUDE_M
    compass: Mount = field(default_factory=Mount)
    heading_sigma_rad: float = float(np.radians(DEFAULT_HEADING_SIGMA_DEG))
    pitch_roll_sigma_rad: float = float(np.radians(DEFAULT_PITCH_ROLL_SIGMA_DEG))
    pressure: Mount = field(default_factory=Mount)
    pressure_sigma_pa: float = DEFAULT_PRESSURE_SIGMA_DBAR * 1e4
    gps: Mount = field(default_factory=Mount)
    gps_sigma_m: float = DEFAULT_GPS_SIGMA_M
    usbl_sigma_m: float = DEFAULT_USBL_SIGMA_M
    stereo: StereoRig | None = None


# ---------------------------------------------------------------------------------------------
# vehicle.yaml schema (file units: degrees, dbar)
# ---------------------------------------------------------------------------------------------


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


#: A noise figure: positive and finite (the filter and the graph divide by it).
Sigma = Annotated[float, PydanticField(gt=0)]
#: Largest lever arm accepted, metres (a vehicle is a few metres long).
MAX_LEVER_ARM_M = 100.0
#: Largest image side accepted, pixels.
MAX_IMAGE_PX = 100_000


def _vec3(v: list[float]) -> list[float]:
    if len(v) != 3:
        raise ValueError(f"must have 3 elements; found {len(v)}")
    return v


class _MountFile(_Strict):
    R_body_sensor: list[list[float]] | None = None
    rpy_deg: list[float] | None = None
    lever_arm_m: list[float] = [0.0, 0.0, 0.0]

    @field_validator("lever_arm_m")
    @classmethod
    def _lever(cls, v: list[float]) -> list[float]:
        _vec3(v)
        if max(abs(x) for x in v) > MAX_LEVER_ARM_M:
            raise ValueError(f"a lever arm is at most {MAX_LEVER_ARM_M:g} m; found {v}")
        return v

    @model_validator(mode="after")
    def _rotation(self) -> _MountFile:
        if self.R_body_sensor is not None and self.rpy_deg is not None:
            raise ValueError("give R_body_sensor or rpy_deg, not both")
        if self.rpy_deg is not None:
            _vec3(self.rpy_deg)
        if self.R_body_sensor is not None and not is_rotation(np.asarray(self.R_body_sensor, dtype=float)):
            raise ValueError(
                f"R_body_sensor is not a rotation (orthonormal with det +1): {self.R_body_sensor}"
            )
        return self

    def to_mount(self) -> Mount:
        if self.rpy_deg is not None:
            r, p, y = np.radians(self.rpy_deg)
            R = euler2rot(y, p, r)
        else:
            R = np.asarray(self.R_body_sensor if self.R_body_sensor is not None else np.eye(3), dtype=float)
        return Mount(R, np.asarray(self.lever_arm_m, dtype=float))


class _DvlFile(_Strict):
    mount: _MountFile = _MountFile()
    velocity_sigma_mps: Sigma = DEFAULT_DVL_VELOCITY_SIGMA_MPS
    scale_sigma: Sigma = DEFAULT_DVL_SCALE_SIGMA
    max_altitude_m: Sigma = DEFAULT_DVL_MAX_ALTITUDE_M


class _CompassFile(_Strict):
    mount: _MountFile = _MountFile()
    heading_sigma_deg: Annotated[float, PydanticField(gt=0, le=180)] = DEFAULT_HEADING_SIGMA_DEG
    pitch_roll_sigma_deg: Annotated[float, PydanticField(gt=0, le=90)] = DEFAULT_PITCH_ROLL_SIGMA_DEG


class _PressureSensorFile(_Strict):
    mount: _MountFile = _MountFile()
    sigma_dbar: Sigma = DEFAULT_PRESSURE_SIGMA_DBAR


class _GpsFile(_Strict):
    mount: _MountFile = _MountFile()
    sigma_m: Sigma = DEFAULT_GPS_SIGMA_M


class _UsblFile(_Strict):
    sigma_m: Sigma = DEFAULT_USBL_SIGMA_M


class _CameraFile(_Strict):
    width: Annotated[int, PydanticField(gt=0, le=MAX_IMAGE_PX)]
    height: Annotated[int, PydanticField(gt=0, le=MAX_IMAGE_PX)]
    K: list[list[float]]
    D: list[float] = PydanticField(default=[0.0, 0.0, 0.0, 0.0, 0.0], max_length=14)


class _StereoFile(_Strict):
    mount: _MountFile = _MountFile()
    left: _CameraFile | None = None
    right: _CameraFile | None = None
    R_right_left: list[list[float]] | None = None
    t_right_left_m: list[float] | None = None
    calibration_file: str | list[str] | None = None
    calibration_format: Literal["opencv", "ros"] | None = None
    left_bayer: Bayer | None = None
    right_bayer: Bayer | None = None

    @model_validator(mode="after")
    def _one_source(self) -> _StereoFile:
        inline = [self.left, self.right, self.R_right_left, self.t_right_left_m]
        if self.calibration_file is None and any(v is None for v in inline):
            raise ValueError("give left, right, R_right_left and t_right_left_m, or calibration_file")
        if self.calibration_file is not None and any(v is not None for v in inline):
            raise ValueError("give an inline calibration or calibration_file, not both")
        if self.calibration_file is not None and self.calibration_format is None:
            raise ValueError("calibration_file needs calibration_format: opencv or ros")
        return self


class _VehicleFile(_Strict):
    name: str = "auv"
    dvl: _DvlFile = _DvlFile()
    compass: _CompassFile = _CompassFile()
    pressure: _PressureSensorFile = _PressureSensorFile()
    gps: _GpsFile = _GpsFile()
    usbl: _UsblFile = _UsblFile()
    stereo: _StereoFile | None = None


def _camera(c: _CameraFile) -> CameraModel:
    return CameraModel(c.width, c.height, np.asarray(c.K, dtype=float), np.asarray(c.D, dtype=float))


def _calibration_file(path: Path) -> None:
    """Raise ConfigError unless ``path`` is a regular file of at most :data:`MAX_BYTES` (a named pipe
    would block OpenCV for ever)."""
    try:
        if not path.exists():
            raise ConfigError(f"{path}: calibration file not found")
        if not path.is_file():
            raise ConfigError(f"{path}: not a regular file")
        if path.stat().st_size > MAX_BYTES:
            raise ConfigError(f"{path}: too large for a calibration ({path.stat().st_size} bytes)")
    except OSError as err:
        raise ConfigError(f"{path}: cannot be read ({err.strerror or type(err).__name__})") from None


def read_opencv_stereo(path: Path) -> tuple[CameraModel, CameraModel, FloatArray, FloatArray]:
    """Read an OpenCV ``FileStorage`` stereo calibration (YAML, JSON or XML).

    Accepts the names OpenCV's samples and ``stereoCalibrate`` users write: ``K1``/``M1``/
    ``cameraMatrix1``, ``D1``/``distCoeffs1`` (and 2), ``R``, ``T``, and the image size as
    ``image_width``/``image_height`` or ``imageSize``. ``T`` is in metres.

    The file is parsed here (the strict YAML loader, or the standard library's XML parser with no
    document type), not by OpenCV: ``cv2.FileStorage`` corrupts its heap and aborts the process on
    some malformed files (found by ``tests/test_fuzz.py``).
    """
    path = Path(path)
    _calibration_file(path)
    doc = _opencv_document(path)

    def mat(*names: str) -> FloatArray:
        for n in names:
            if n in doc:
                return _opencv_matrix(path, n, doc[n])
        raise ConfigError(f"{path}: missing matrix {' / '.join(names)}")

    def number(name: str) -> float | None:
        value = doc.get(name)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: {name}: expected a number; found {quote(value)}")
        return float(value)

    w, h = number("image_width"), number("image_height")
    if w is None or h is None:
        if "imageSize" not in doc:
            raise ConfigError(f"{path}: missing image_width/image_height or imageSize")
        size = doc["imageSize"]
        if isinstance(size, dict):
            size = _opencv_matrix(path, "imageSize", size).ravel().tolist()
        if not (isinstance(size, list) and len(size) == 2):
            raise ConfigError(f"{path}: imageSize: expected [width, height]; found {quote(size)}")
        w, h = (
            float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan for v in size
        )
    if not (math.isfinite(w) and math.isfinite(h) and w == int(w) and h == int(h)):
        raise ConfigError(f"{path}: image size {w} x {h} is not a whole number of pixels")
    try:
        left = CameraModel(int(w), int(h), mat("K1", "M1", "cameraMatrix1"), mat("D1", "distCoeffs1").ravel())
        right = CameraModel(
            int(w), int(h), mat("K2", "M2", "cameraMatrix2"), mat("D2", "distCoeffs2").ravel()
        )
    except ValueError as err:
        raise ConfigError(f"{path}: {err}") from err
    R, T = mat("R"), mat("T").ravel()
    if R.shape != (3, 3) or T.shape != (3,):
        raise ConfigError(f"{path}: R must be 3x3 and T 3x1; found {R.shape} and {T.shape}")
    return left, right, R, T


#: Element types of an OpenCV matrix (``dt``) read: one channel of a number type.
_OPENCV_TYPES = ("u", "c", "w", "s", "i", "f", "d")


def _opencv_document(path: Path) -> dict[str, Any]:
    """The top-level mapping of an OpenCV FileStorage file; matrices as mappings with ``rows``,
    ``cols``, ``dt`` and ``data``."""
    text, problems = read_text(path, str(path))
    if text is None:
        raise ConfigError(str(problems[0]))
    body = text.removeprefix("\ufeff").lstrip()
    if body.startswith("<"):
        return _opencv_xml(path, body)
    lines = body.splitlines()
    if lines and re.match(r"%YAML[: ]", lines[0]):
        lines = lines[1:]
    doc, problems = parse_yaml(
        "\n".join(lines), str(path), mapping_tags=("opencv-matrix", "opencv-nd-matrix")
    )
    if problems:
        raise ConfigError(str(problems[0]))
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: not an OpenCV FileStorage file (expected a mapping of names)")
    return doc


def _opencv_xml(path: Path, text: str) -> dict[str, Any]:
    """An OpenCV FileStorage XML file as the mapping :func:`_opencv_document` gives."""
    import xml.etree.ElementTree as ET

    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise ConfigError(f"{path}: XML with a document type or entities is not read")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise ConfigError(f"{path}: not valid XML ({quote(str(err))})") from None
    if root.tag != "opencv_storage":
        raise ConfigError(f"{path}: not an OpenCV FileStorage file (root element {quote(root.tag)})")

    def value(text: str | None) -> Any:
        words = (text or "").split()
        numbers: list[int | float] = []
        for w in words:
            try:
                numbers.append(int(w) if re.fullmatch(r"[-+]?[0-9]{1,18}", w) else float(w))
            except ValueError:
                return " ".join(words)
        return numbers[0] if len(numbers) == 1 else numbers

    doc: dict[str, Any] = {}
    for node in root:
        if node.get("type_id") in ("opencv-matrix", "opencv-nd-matrix"):
            matrix = {child.tag: value(child.text) for child in node}
            for key in ("data", "sizes"):
                if key in matrix and not isinstance(matrix[key], list):
                    matrix[key] = [matrix[key]]
            doc[node.tag] = matrix
        else:
            doc[node.tag] = value(node.text)
    return doc


def _opencv_matrix(path: Path, name: str, node: Any) -> FloatArray:
    """An OpenCV matrix node as a float array: ``rows``, ``cols``, ``dt``, ``data``
    (``opencv-matrix``), or ``sizes``, ``dt``, ``data`` (``opencv-nd-matrix``, one or two sizes)."""
    if (
        not isinstance(node, dict)
        or "data" not in node
        or not ({"rows", "cols"} <= set(node) or "sizes" in node)
    ):
        raise ConfigError(
            f"{path}: {name}: expected an opencv-matrix (rows, cols, dt, data); found {quote(node)}"
        )
    shape = node["sizes"] if "sizes" in node else [node["rows"], node["cols"]]
    data, dt = node["data"], node.get("dt", "d")
    if not (
        isinstance(shape, list)
        and 1 <= len(shape) <= 2
        and all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 16 for v in shape)
    ):
        raise ConfigError(
            f"{path}: {name}: its size must be one or two integers in [1, 16]; found {quote(shape)}"
        )
    if dt not in _OPENCV_TYPES:
        raise ConfigError(
            f"{path}: {name}: element type dt must be one of {', '.join(_OPENCV_TYPES)}; found {quote(dt)}"
        )
    count = int(np.prod(shape))
    if not isinstance(data, list) or len(data) != count:
        raise ConfigError(f"{path}: {name}: data must hold {count} numbers; found {quote(data)}")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in data):
        raise ConfigError(f"{path}: {name}: data must be finite numbers; found {quote(data)}")
    return np.asarray(data, dtype=float).reshape(shape)


def read_ros_stereo(
    left_path: Path, right_path: Path
) -> tuple[CameraModel, CameraModel, FloatArray, FloatArray]:
    """Read a stereo pair from two ROS ``camera_info`` YAML files (``camera_calibration`` output).

    The extrinsics come from the rectification rotations R1, R2 and the right projection matrix, whose
    ``P[0, 3] = -fx' * baseline``: ``R_right_left = R2^T R1``, ``t_right_left = -R2^T [b, 0, 0]``.
    """
    infos = []
    for p in (left_path, right_path):
        d, problems = load_yaml(p, str(p))
        if problems:
            raise ConfigError(str(problems[0]))
        try:
            K = np.asarray(d["camera_matrix"]["data"], dtype=float).reshape(3, 3)
            D = np.asarray(d["distortion_coefficients"]["data"], dtype=float)
            R = np.asarray(d["rectification_matrix"]["data"], dtype=float).reshape(3, 3)
            P = np.asarray(d["projection_matrix"]["data"], dtype=float).reshape(3, 4)
            if not all(np.all(np.isfinite(m)) for m in (K, D, R, P)):
                raise ValueError("a matrix holds a value that is not a finite number")
            width, height = d["image_width"], d["image_height"]
            if not all(isinstance(v, int) and not isinstance(v, bool) for v in (width, height)):
                raise ValueError(
                    f"image_width and image_height must be integers; found {quote(width)}, {quote(height)}"
                )
            cam = CameraModel(width, height, K, D)
        except (KeyError, TypeError, ValueError, OverflowError) as err:
            raise ConfigError(
                f"{p}: not a ROS camera_info YAML ({type(err).__name__}: {quote(str(err))})"
            ) from err
        if d.get("distortion_model", "plumb_bob") not in ("plumb_bob", "rational_polynomial"):
            raise ConfigError(f"{p}: unsupported distortion_model {quote(d.get('distortion_model'))}")
        if not is_rotation(R):
            raise ConfigError(f"{p}: rectification_matrix is not a rotation")
        infos.append((cam, R, P))
    (left, R1, _), (right, R2, P2) = infos
    baseline = -P2[0, 3] / P2[0, 0] if P2[0, 0] != 0 else 0.0
    if baseline == 0 or not math.isfinite(baseline):
        raise ConfigError(
            f"{right_path}: projection_matrix has no baseline (P[0,3] = 0); is it the right camera?"
        )
    return left, right, R2.T @ R1, -R2.T @ np.array([baseline, 0.0, 0.0])


def calibration_files(data: Any) -> list[str]:
    """The stereo calibration files a parsed vehicle.yaml names (relative to its folder), if any."""
    stereo = data.get("stereo") if isinstance(data, dict) else None
    files = stereo.get("calibration_file") if isinstance(stereo, dict) else None
    names = [files] if isinstance(files, str) else files if isinstance(files, list) else []
    return [n for n in names if isinstance(n, str) and n]


def image_size_problem(path: Path, display: str, cam: CameraModel, vehicle_display: str) -> Problem | None:
    """The problem when an image's size (read from its header) is not the calibrated one, or when the
    camera writes raw mosaics (:attr:`CameraModel.bayer`) and the image has more than one channel;
    else None (also when the header cannot be read: the stage that reads the image says so)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            (w, h), bands = image.size, len(image.getbands())
    except (OSError, UnidentifiedImageError, ValueError, Image.DecompressionBombError):
        return None
    if (w, h) != (cam.width, cam.height):
        return Problem(
            display,
            f"image is {w}x{h} but the stereo calibration in {vehicle_display} is for "
            f"{cam.width}x{cam.height}; images and calibration must match (scale the calibration with the images)",
        )
    if cam.bayer is not None and bands != 1:
        return Problem(
            display,
            f"image has {bands} channels but {vehicle_display} gives its camera a Bayer filter "
            f"({cam.bayer}): a raw mosaic has one (drop left_bayer / right_bayer for demosaiced images)",
        )
    return None


def _stereo(s: _StereoFile, base: Path) -> StereoRig:
    if s.calibration_file is None and s.left is not None and s.right is not None:
        left, right = _camera(s.left), _camera(s.right)
        R, t = np.asarray(s.R_right_left, dtype=float), np.asarray(s.t_right_left_m, dtype=float)
    elif s.calibration_format == "opencv":
        if not isinstance(s.calibration_file, str):
            raise ConfigError("stereo.calibration_file: an OpenCV calibration is one file")
        left, right, R, t = read_opencv_stereo(base / s.calibration_file)
    else:
        files = s.calibration_file
        if not isinstance(files, list) or len(files) != 2:
            raise ConfigError("stereo.calibration_file: a ROS calibration is two files [left, right]")
        left, right, R, t = read_ros_stereo(base / files[0], base / files[1])
    return StereoRig(left, right, R, t, s.mount.to_mount()).with_bayer(s.left_bayer, s.right_bayer)


def vehicle_from_mapping(data: Any, *, base: Path, display: str = "vehicle.yaml") -> Vehicle:
    """Build a :class:`Vehicle` from a parsed vehicle.yaml mapping (paths relative to ``base``)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{display}: must be a mapping of keys to values")
    try:
        f = _VehicleFile.model_validate(data)
        stereo = _stereo(f.stereo, base) if f.stereo is not None else None
    except ValidationError as err:
        raise ConfigError("\n".join(str(p) for p in pydantic_problems(err, display))) from err
    except ValueError as err:
        raise ConfigError(f"{display}: key stereo: {err}") from err
    return Vehicle(
        name=f.name,
        dvl=f.dvl.mount.to_mount(),
        dvl_velocity_sigma_mps=f.dvl.velocity_sigma_mps,
        dvl_scale_sigma=f.dvl.scale_sigma,
        dvl_max_altitude_m=f.dvl.max_altitude_m,
        compass=f.compass.mount.to_mount(),
        heading_sigma_rad=float(np.radians(f.compass.heading_sigma_deg)),
        pitch_roll_sigma_rad=float(np.radians(f.compass.pitch_roll_sigma_deg)),
        pressure=f.pressure.mount.to_mount(),
        pressure_sigma_pa=f.pressure.sigma_dbar * 1e4,
        gps=f.gps.mount.to_mount(),
        gps_sigma_m=f.gps.sigma_m,
        usbl_sigma_m=f.usbl.sigma_m,
        stereo=stereo,
    )


def vehicle_problems(path: Path, *, display: str = "vehicle.yaml") -> tuple[Vehicle | None, list[Problem]]:
    """Read vehicle.yaml, returning the vehicle or the problems found (never raises for content)."""
    data, problems = load_yaml(path, display)
    if problems:
        return None, problems
    try:
        return vehicle_from_mapping(data, base=path.parent, display=display), []
    except ConfigError as err:
        lines = str(err).splitlines()
        return None, [Problem(display, line.removeprefix(f"{display}: ")) for line in lines]


def read_vehicle(path: Path) -> Vehicle:
    """Read and check vehicle.yaml; raise :class:`ConfigError` naming the file and key."""
    vehicle, problems = vehicle_problems(Path(path), display=str(path))
    if vehicle is None:
        raise ConfigError("\n".join(str(p) for p in problems))
    return vehicle


def _mount_yaml(m: Mount) -> dict[str, Any]:
    return {"R_body_sensor": m.R_body_sensor.tolist(), "lever_arm_m": m.lever_arm_body_m.tolist()}


def _camera_yaml(c: CameraModel) -> dict[str, Any]:
    return {"width": c.width, "height": c.height, "K": c.K.tolist(), "D": c.D.tolist()}


def vehicle_to_mapping(v: Vehicle) -> dict[str, Any]:
    """The vehicle.yaml mapping (file units); stereo calibrations are written inline."""
    out: dict[str, Any] = {
        "name": v.name,
        "dvl": {
            "mount": _mount_yaml(v.dvl),
            "velocity_sigma_mps": v.dvl_velocity_sigma_mps,
            "scale_sigma": v.dvl_scale_sigma,
            "max_altitude_m": v.dvl_max_altitude_m,
        },
        "compass": {
            "mount": _mount_yaml(v.compass),
            "heading_sigma_deg": float(np.degrees(v.heading_sigma_rad)),
            "pitch_roll_sigma_deg": float(np.degrees(v.pitch_roll_sigma_rad)),
        },
        "pressure": {"mount": _mount_yaml(v.pressure), "sigma_dbar": v.pressure_sigma_pa / 1e4},
        "gps": {"mount": _mount_yaml(v.gps), "sigma_m": v.gps_sigma_m},
        "usbl": {"sigma_m": v.usbl_sigma_m},
    }
    if v.stereo is not None:
        s = v.stereo
        out["stereo"] = {
            "mount": _mount_yaml(s.mount),
            "left": _camera_yaml(s.left),
            "right": _camera_yaml(s.right),
            "R_right_left": s.R_right_left.tolist(),
            "t_right_left_m": s.t_right_left_m.tolist(),
        }
        for side, cam in (("left", s.left), ("right", s.right)):
            if cam.bayer is not None:
                out["stereo"][f"{side}_bayer"] = cam.bayer
    return out


def write_vehicle(v: Vehicle, path: Path) -> None:
    """Write vehicle.yaml (inline stereo calibration)."""
    path.write_text(dump_yaml(vehicle_to_mapping(v)), encoding="utf-8")


def mount_rpy_rad(m: Mount) -> tuple[float, float, float]:
    """A mount's rotation as (roll, pitch, yaw), radians, Euler ZYX."""
    y, p, r = rot2euler(m.R_body_sensor)
    return float(r), float(p), float(y)
