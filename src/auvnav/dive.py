"""The Dive container and the dive folder format ``auvnav-dive/1`` (DESIGN section 5).

A dive folder holds ``dive.yaml``, ``vehicle.yaml``, navigation streams under ``nav/`` (``.csv`` or
``.parquet``), an image index, and for simulated dives a ``truth/`` folder. :func:`validate_dive` reads
everything and reports every problem with its file, row and column; :func:`read_dive` returns a
:class:`Dive` or raises :class:`~auvnav.errors.DiveFormatError`; :func:`write_dive` writes a folder
atomically (a temporary sibling, then a rename).

:func:`validate_dive` is the one checker of a dive's files: every stage reads a dive through it, so
a dive that validates is one the stages accept. Besides each file's own format it checks that the
streams' times agree with ``start_time`` and with each other (:data:`START_TOLERANCE_S`,
:data:`MAX_DIVE_S`, :data:`SURFACE_MARGIN_S`: a stream in the wrong epoch or unit is named with the
offset and the likely mistake), that GPS and USBL fixes lie near the origin, that images match the
stereo calibration, that no stream is given twice (``.csv`` and ``.parquet``) or as a folder, and
that every path the dive names (the vehicle file, its calibration, the streams, the images) stays
inside the dive folder: ``..``, an absolute path or a symbolic link leading out is a problem unless
``allow_outside``, and then each one is said in the warnings.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, ValidationError, field_validator, model_validator
from pydantic import Field as PydanticField

from auvnav.config import cut, dump_yaml, load_yaml, outside, pydantic_problems, quote
from auvnav.errors import AuvnavError, DiveFormatError, OutputExistsError, Problem
from auvnav.frames import GeodeticOrigin
from auvnav.streams import (
    Field,
    Stream,
    find_gaps,
    flag_rows,
    looks_like_radians,
    read_stream,
    read_table,
    within,
    write_stream,
)
from auvnav.vehicle import (
    Vehicle,
    calibration_files,
    image_size_problem,
    read_vehicle,
    vehicle_problems,
    write_vehicle,
)

log = logging.getLogger(__name__)

FORMAT = "auvnav-dive/1"
DEG = np.pi / 180.0
DBAR = 1e4  # Pa per dbar
T = Field("t_s", ("t",), check=within(0.0, 4.1e9, "s since 1970", " (POSIX seconds expected)"))

#: Time sanity (DESIGN section 5): every stream starts within this of dive.yaml's start_time, seconds.
START_TOLERANCE_S = 86400.0
#: No stream ends later than this after start_time, seconds (the longest AUV dives last about a day).
MAX_DIVE_S = 3 * 86400.0
#: Fixes, images and the magnetometer may lie this far outside the navigation's span, seconds
#: (GPS fixes at the surface before and after the dive).
SURFACE_MARGIN_S = 3600.0
#: A GPS or USBL fix farther than this from the dive's origin is an error, metres.
MAX_FIX_DISTANCE_M = 100e3
#: start_time must lie in [1980-01-06 (GPS epoch), 2100-01-01).
START_TIME_RANGE_S = (315964800.0, 4102444800.0)
#: Image pairs whose size is checked against the stereo calibration by validate (first, middle, last).
IMAGE_SIZE_SAMPLES = 3
_GPS_EPOCH_S = 315964800.0
_EARTH_RADIUS_M = 6371e3


# ---------------------------------------------------------------------------------------------
# Streams
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DvlStream(Stream):
    """DVL bottom-track velocity in the DVL's own frame as logged (FRD when mounted aligned); the
    altitude is optional (not every DVL log has it: what needs it says so)."""

    t_s: NDArray[np.float64]
    v_sensor_mps: NDArray[np.float64]  # (N, 3)
    altitude_m: NDArray[np.float64] | None
    valid: NDArray[np.bool_]
    FILE: ClassVar[str] = "nav/dvl"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        T,
        Field(
            "v_sensor_mps",
            ("vx_mps", "vy_mps", "vz_mps"),
            check=within(-10, 10, "m/s", ": not m/s?"),
        ),
        Field("altitude_m", ("altitude_m",), required=False, check=within(0, 1000, "m")),
        Field("valid", ("valid",), kind="bool"),
    )


@dataclass(frozen=True)
class AttitudeStream(Stream):
    """Heading as the compass gives it, pitch and roll from the inclinometer."""

    t_s: NDArray[np.float64]
    heading_rad: NDArray[np.float64]
    pitch_rad: NDArray[np.float64]
    roll_rad: NDArray[np.float64]
    FILE: ClassVar[str] = "nav/attitude"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        T,
        Field(
            "heading_rad",
            ("heading_deg",),
            DEG,
            check=lambda v: looks_like_radians(v) or within(-360, 360, "deg")(v),
        ),
        Field("pitch_rad", ("pitch_deg",), DEG, check=within(-90, 90, "deg")),
        Field("roll_rad", ("roll_deg",), DEG, check=within(-180, 180, "deg")),
    )


@dataclass(frozen=True)
class MagnetometerStream(Stream):
    """Raw three-axis magnetometer in the body frame (any one unit)."""

    t_s: NDArray[np.float64]
    m_body: NDArray[np.float64]  # (N, 3)
    FILE: ClassVar[str] = "nav/magnetometer"
    FIELDS: ClassVar[tuple[Field, ...]] = (T, Field("m_body", ("mx", "my", "mz")))


@dataclass(frozen=True)
class PressureStream(Stream):
    """Pressure as the sensor gives it (absolute or sea pressure, per dive.yaml), pascals."""

    t_s: NDArray[np.float64]
    pressure_pa: NDArray[np.float64]
    FILE: ClassVar[str] = "nav/pressure"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        T,
        Field("pressure_pa", ("pressure_dbar",), DBAR, check=within(-5, 12000, "dbar", ": not dbar?")),
    )


@dataclass(frozen=True)
class GpsStream(Stream):
    """GPS fixes (WGS84) while at the surface."""

    t_s: NDArray[np.float64]
    latitude_rad: NDArray[np.float64]
    longitude_rad: NDArray[np.float64]
    sigma_m: NDArray[np.float64]
    FILE: ClassVar[str] = "nav/gps"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        T,
        Field("latitude_rad", ("latitude_deg",), DEG, check=within(-90, 90, "deg")),
        Field("longitude_rad", ("longitude_deg",), DEG, check=within(-180, 360, "deg")),
        Field("sigma_m", ("sigma_m",), check=within(1e-6, 1e4, "m", ": must be positive")),
    )


@dataclass(frozen=True)
class UsblStream(Stream):
    """USBL fixes of the vehicle (WGS84 and depth)."""

    t_s: NDArray[np.float64]
    latitude_rad: NDArray[np.float64]
    longitude_rad: NDArray[np.float64]
    depth_m: NDArray[np.float64]
    sigma_m: NDArray[np.float64]
    FILE: ClassVar[str] = "nav/usbl"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        *GpsStream.FIELDS[:3],
        Field("depth_m", ("depth_m",), check=within(-10, 11000, "m")),
        GpsStream.FIELDS[3],
    )


@dataclass(frozen=True)
class ImageIndex(Stream):
    """Stereo pair times and file names relative to ``images/``."""

    t_s: NDArray[np.float64]
    left: NDArray[np.str_]
    right: NDArray[np.str_]
    FILE: ClassVar[str] = "images/index"
    FIELDS: ClassVar[tuple[Field, ...]] = (
        T,
        Field("left", ("left",), kind="str"),
        Field("right", ("right",), kind="str"),
    )


REQUIRED_STREAMS: dict[str, type[Stream]] = {
    "dvl": DvlStream,
    "attitude": AttitudeStream,
    "pressure": PressureStream,
}
OPTIONAL_STREAMS: dict[str, type[Stream]] = {
    "magnetometer": MagnetometerStream,
    "gps": GpsStream,
    "usbl": UsblStream,
    "images": ImageIndex,
}


# ---------------------------------------------------------------------------------------------
# dive.yaml
# ---------------------------------------------------------------------------------------------


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class _OriginFile(_Strict):
    latitude_deg: float = PydanticField(ge=-90, le=90)
    longitude_deg: float = PydanticField(ge=-180, le=360)


class _PressureFile(_Strict):
    type: Literal["absolute", "sea"]
    atmospheric_dbar: float | None = PydanticField(default=None, ge=0, le=12)

    @model_validator(mode="after")
    def _atmospheric(self) -> _PressureFile:
        if self.type == "absolute" and self.atmospheric_dbar is None:
            raise ValueError(
                "type absolute needs atmospheric_dbar, the pressure removed to give sea pressure "
                "(10.1325 for the standard atmosphere)"
            )
        return self


class _DiveFile(_Strict):
    format: Literal["auvnav-dive/1"]
    name: str
    origin: _OriginFile
    start_time: dt.datetime
    heading_reference: Literal["magnetic", "true"]
    declination_deg: float | Literal["auto"] = "auto"
    pressure: _PressureFile
    vehicle: str = PydanticField(default="vehicle.yaml", min_length=1)

    @field_validator("start_time", mode="before")
    @classmethod
    def _text(cls, v: Any) -> Any:
        if not isinstance(v, (str, dt.datetime)):
            raise ValueError("must be an ISO 8601 time with its zone, e.g. '2009-10-15T00:00:00Z'")
        return v

    @field_validator("start_time")
    @classmethod
    def _utc(cls, v: dt.datetime) -> dt.datetime:
        if v.tzinfo is None:
            raise ValueError("needs a time zone (ISO 8601 with Z or +00:00)")
        v = v.astimezone(dt.timezone.utc)
        lo, hi = START_TIME_RANGE_S
        if not lo <= v.timestamp() < hi:
            raise ValueError(f"{_iso(v.timestamp())} is not a plausible dive time (1980 to 2100)")
        return v

    @field_validator("heading_reference", mode="before")
    @classmethod
    def _yaml_boolean(cls, v: Any) -> Any:
        # DESIGN writes `heading_reference: true`, which YAML reads as the boolean: it means true north.
        if v is True:
            return "true"
        if v is False:
            raise ValueError("false is not a reference: write magnetic or true")
        return v

    @field_validator("declination_deg", mode="before")
    @classmethod
    def _declination(cls, v: Any) -> Any:
        if v == "auto":
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) > 180:
            raise ValueError("must be auto or a finite number of degrees in [-180, 180]")
        return float(v)


#: What to say of a key dive.yaml must have.
_MISSING_HINTS = {
    "heading_reference": "missing: write magnetic (the compass heading as logged) or true (already "
    "referred to true north)",
    "pressure": "missing: write {type: absolute, atmospheric_dbar: 10.1325} or {type: sea}",
    "pressure.type": "missing: absolute (the sensor includes the atmosphere) or sea",
}


def _iso(t_s: float) -> str:
    """A POSIX time as ISO 8601 UTC (or the number when it is not a time)."""
    try:
        return dt.datetime.fromtimestamp(t_s, dt.timezone.utc).isoformat().replace("+00:00", "Z")
    except (OverflowError, ValueError, OSError):
        return f"{t_s:g} s"


@dataclass(frozen=True)
class DiveInfo:
    """What dive.yaml says, in SI units.

    Parameters
    ----------
    name : str
    origin : GeodeticOrigin
        The local NED frame's origin.
    start_time_s : float
        POSIX seconds, UTC.
    heading_reference : {"magnetic", "true"}
        What the compass heading refers to.
    declination_rad : float or None
        East-positive declination; None means compute it from a geomagnetic model ("auto").
    pressure_type : {"absolute", "sea"}
    atmospheric_pa : float
        Atmospheric pressure removed from absolute pressure, pascals.
    vehicle_file : str
    """

    name: str
    origin: GeodeticOrigin
    start_time_s: float
    heading_reference: Literal["magnetic", "true"] = "magnetic"
    declination_rad: float | None = None
    pressure_type: Literal["absolute", "sea"] = "absolute"
    atmospheric_pa: float = 101325.0
    vehicle_file: str = "vehicle.yaml"

    def to_yaml(self) -> dict[str, Any]:
        """The dive.yaml mapping."""
        return {
            "format": FORMAT,
            "name": self.name,
            "origin": {
                "latitude_deg": float(np.degrees(self.origin.latitude_rad)),
                "longitude_deg": float(np.degrees(self.origin.longitude_rad)),
            },
            "start_time": dt.datetime.fromtimestamp(self.start_time_s, dt.timezone.utc)
            .isoformat()
            .replace("+00:00", "Z"),
            "heading_reference": self.heading_reference,
            "declination_deg": "auto"
            if self.declination_rad is None
            else float(np.degrees(self.declination_rad)),
            "pressure": {
                "type": self.pressure_type,
                "atmospheric_dbar": self.atmospheric_pa / DBAR,
            },
            "vehicle": self.vehicle_file,
        }


def _parse_dive_yaml(path: Path) -> tuple[DiveInfo | None, list[Problem]]:
    data, problems = load_yaml(path, "dive.yaml")
    if problems:
        return None, problems
    if not isinstance(data, dict):
        return None, [Problem("dive.yaml", "must be a mapping of keys to values")]
    try:
        f = _DiveFile.model_validate(data)
    except ValidationError as err:
        problems = pydantic_problems(err, "dive.yaml")
        for k, p in enumerate(problems):
            for key, hint in _MISSING_HINTS.items():
                if p.message == f"key {key}: missing":
                    problems[k] = Problem(p.file, f"key {key}: {hint}")
        return None, problems
    info = DiveInfo(
        name=f.name,
        origin=GeodeticOrigin.from_degrees(f.origin.latitude_deg, f.origin.longitude_deg),
        start_time_s=f.start_time.timestamp(),
        heading_reference=f.heading_reference,
        declination_rad=None if f.declination_deg == "auto" else float(np.radians(f.declination_deg)),
        pressure_type=f.pressure.type,
        atmospheric_pa=(10.1325 if f.pressure.atmospheric_dbar is None else f.pressure.atmospheric_dbar)
        * DBAR,
        vehicle_file=f.vehicle,
    )
    return info, []


def read_dive_info(path: Path) -> DiveInfo:
    """What a dive folder's dive.yaml says, without reading its streams (:class:`DiveFormatError`)."""
    info, problems = _parse_dive_yaml(Path(path) / "dive.yaml")
    if info is None:
        raise DiveFormatError([Problem(f"{path}/{p.file}", p.message, p.row, p.column) for p in problems])
    return info


# ---------------------------------------------------------------------------------------------
# The dive
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Dive:
    """A dive's metadata, vehicle and streams (SI units, radians)."""

    info: DiveInfo
    vehicle: Vehicle
    dvl: DvlStream
    attitude: AttitudeStream
    pressure: PressureStream
    magnetometer: MagnetometerStream | None = None
    gps: GpsStream | None = None
    usbl: UsblStream | None = None
    images: ImageIndex | None = None
    path: Path | None = field(default=None, compare=False)

    def streams(self) -> dict[str, Stream]:
        """The streams present, by name."""
        names = [*REQUIRED_STREAMS, *OPTIONAL_STREAMS]
        return {n: getattr(self, n) for n in names if getattr(self, n) is not None}

    def time_span_s(self) -> tuple[float, float]:
        """First and last time of any stream."""
        ts = [s.t_s for s in self.streams().values()]
        return float(min(t[0] for t in ts)), float(max(t[-1] for t in ts))


def _is_file(path: Path) -> bool:
    """``path.is_file()``, False for a path the system cannot even look up (a name too long)."""
    try:
        return path.is_file()
    except OSError:
        return False


#: Longest name of an image in images/index.csv, characters (file systems allow 255 per part).
MAX_IMAGE_NAME = 1024


def stream_paths(root: Path, stem: str) -> list[Path]:
    """Every ``.csv`` or ``.parquet`` path of a stream that exists in any form (a file, a folder,
    a link, even a broken one): more than one, or one that is not a file, is a problem."""
    return [
        root / f"{stem}{suffix}"
        for suffix in (".csv", ".parquet")
        if os.path.lexists(root / f"{stem}{suffix}")
    ]


def find_stream_file(root: Path, stem: str, *, allow_outside: bool = False) -> Path | None:
    """The ``.csv`` or ``.parquet`` file of a stream, or None (:func:`validate_dive` reports a
    stream given twice, or as a folder). A file that leads outside ``root`` (a symbolic link) is
    not given unless ``allow_outside``."""
    for candidate in stream_paths(root, stem):
        if candidate.is_file() and (allow_outside or outside(root, candidate.relative_to(root)) is None):
            return candidate
    return None


def vehicle_file_name(path: Path, *, allow_outside: bool = False) -> str | None:
    """The vehicle file that a dive folder's dive.yaml names (``vehicle.yaml`` when it names none),
    or None when dive.yaml cannot say (reading the dive reports why), or when the file or a stereo
    calibration it names leads outside the dive folder and ``allow_outside`` is not given."""
    path = Path(path)
    if not allow_outside and outside(path, Path("dive.yaml")) is not None:
        return None
    data, problems = load_yaml(path / "dive.yaml", "dive.yaml")
    if problems or not isinstance(data, dict):
        return None
    name = data.get("vehicle", "vehicle.yaml")
    if not isinstance(name, str) or not name:
        return None
    if not allow_outside:
        if outside(path, Path(name)) is not None:
            return None
        if any(outside(path, Path(n)) is not None for n in _calibration_names(path, name)):
            return None
    return name


def _calibration_names(path: Path, vehicle: str) -> list[str]:
    """The stereo calibration files the vehicle file names, as paths from the dive folder."""
    data, problems = load_yaml(path / vehicle, vehicle)
    if problems:
        return []
    return [os.path.normpath(Path(vehicle).parent / name) for name in calibration_files(data)]


def dive_files(path: Path, *, allow_outside: bool = False) -> dict[str, Path]:
    """The files of a dive folder that its navigation depends on, by their path inside it.

    ``dive.yaml``, the vehicle file it names (and the stereo calibration files that names), and
    every stream file under ``nav/``. The image files are not included (see :func:`image_files`).
    Unreadable YAML leaves out what it would have named: reading the dive reports the problem. A
    file that leads outside the dive folder is left out (not even read for its key) unless
    ``allow_outside``.
    """
    path = Path(path)
    out: dict[str, Path] = {}

    def add(rel: str) -> bool:
        if _is_file(path / rel) and (allow_outside or outside(path, Path(rel)) is None):
            out[rel] = path / rel
            return True
        return False

    if not add("dive.yaml"):
        return out
    vehicle = vehicle_file_name(path, allow_outside=allow_outside)
    if vehicle is not None and add(vehicle):
        for name in _calibration_names(path, vehicle):
            add(name)
    for cls in (*REQUIRED_STREAMS.values(), *OPTIONAL_STREAMS.values()):
        if cls is not ImageIndex:
            found = find_stream_file(path, cls.FILE, allow_outside=allow_outside)
            if found is not None:
                add(str(found.relative_to(path)))
    return out


def image_files(path: Path, index: ImageIndex, *, allow_outside: bool = False) -> dict[str, Path]:
    """The image files an index names that exist, by their path inside the dive folder; those that
    lead outside it are left out unless ``allow_outside``."""
    path = Path(path)
    out = {}
    inside_dir: dict[Path, bool] = {}  # resolved once per folder: thousands of images share a few
    for name in (*index.left, *index.right):
        rel = Path("images", name)
        file = path / rel
        if not _is_file(file):
            continue
        if not allow_outside:
            if rel.parent not in inside_dir:
                inside_dir[rel.parent] = outside(path, rel.parent) is None
            inside = inside_dir[rel.parent] and (not file.is_symlink() or outside(path, rel) is None)
            if not inside:
                continue
        out[f"images/{name}"] = file
    return out


def read_image_index(path: Path) -> ImageIndex | None:
    """The dive's camera log (``images/index.csv``), None when it has none."""
    file = find_stream_file(Path(path), ImageIndex.FILE)
    return None if file is None else read_stream(ImageIndex, file, str(file.relative_to(path)))


def image_inputs(path: Path) -> dict[str, Path]:
    """What a stage that reads the images depends on: the dive's files, its camera log and every image
    the log names that exists (none when the log cannot be read: the stage's own check says why)."""
    path = Path(path)
    files = dive_files(path)
    index_file = find_stream_file(path, ImageIndex.FILE)
    if index_file is not None:
        files[str(index_file.relative_to(path))] = index_file
        try:
            index = read_image_index(path)
        except AuvnavError:
            index = None
        if index is not None:
            files.update(image_files(path, index))
    return files


def outside_inputs(path: Path, files: dict[str, Path]) -> dict[str, Path]:
    """``files`` (a stage's inputs) with the dive's files that lead outside its folder added, of the
    kinds it already has: what a stage's key covers when ``--allow-outside`` lets it read them."""
    out = dict(files)
    if "dive.yaml" in files:
        out.update({k: v for k, v in dive_files(path, allow_outside=True).items() if k not in out})
    index = find_stream_file(Path(path), ImageIndex.FILE)
    if index is not None and any(k.startswith("images/") and k != str(index.relative_to(path)) for k in out):
        values, problems, _ = read_table(index, ImageIndex.FIELDS, "images/index")
        if not problems:
            images = ImageIndex.from_columns(values)
            out.update(
                {k: v for k, v in image_files(path, images, allow_outside=True).items() if k not in out}
            )
    return out


@dataclass(frozen=True)
class StreamSummary:
    """What validate says of one stream."""

    name: str
    file: str
    rows: int
    start_s: float
    end_s: float
    rate_hz: float
    gaps: list[tuple[float, float]]  # (start time, length) of gaps (auvnav.streams.find_gaps)


@dataclass(frozen=True)
class ValidationReport:
    """Everything :func:`validate_dive` found."""

    path: Path
    problems: list[Problem]
    warnings: list[str]
    streams: list[StreamSummary]
    dive: Dive | None

    @property
    def ok(self) -> bool:
        return not self.problems


def _summarise(name: str, file: str, t: NDArray) -> StreamSummary:
    dt_s = np.diff(t)
    gap_idx, period = find_gaps(t)
    return StreamSummary(
        name=name,
        file=file,
        rows=int(t.size),
        start_s=float(t[0]),
        end_s=float(t[-1]),
        rate_hz=1.0 / period if period > 0 else 0.0,
        gaps=[(float(t[i]), float(dt_s[i])) for i in gap_idx],
    )


class _Checker:
    """The checks of :func:`validate_dive`, collecting problems and warnings as it goes."""

    def __init__(self, path: Path, allow_outside: bool) -> None:
        self.path = path
        self.allow_outside = allow_outside
        self.problems: list[Problem] = []
        self.warnings: list[str] = []
        self.vehicle_display = "vehicle.yaml"

    def confined(self, rel: str | Path, display: str, what: str, real: Path | None = None) -> bool:
        """Whether a path the dive names may be read: inside the folder, or outside and allowed
        (then said). ``what`` names the path in the message (the key or row that names it);
        ``real`` is where it leads when that is known (else it is resolved here)."""
        real = real or outside(self.path, Path(rel))
        if real is None:
            return True
        where = cut(str(real), 160)
        if self.allow_outside:
            self.warnings.append(
                f"{display}: {what} leads outside the dive folder, to {where}: read (--allow-outside)"
            )
            return True
        self.problems.append(
            Problem(
                display,
                f"{what} leads outside the dive folder, to {where}: copy it into the dive, or give "
                "--allow-outside",
            )
        )
        return False

    def stream_file(self, cls: type[Stream], required: bool) -> Path | None:
        """The one file of a stream: absent (a problem when required), given twice, not a regular
        file, or leading outside the folder are problems."""
        found = stream_paths(self.path, cls.FILE)
        if not found:
            if required:
                self.problems.append(Problem(f"{cls.FILE}.csv", "required stream file missing"))
            return None
        if len(found) > 1:
            names = " and ".join(p.name for p in found)
            self.problems.append(
                Problem(
                    f"{cls.FILE}.csv",
                    f"the stream is given twice ({names}): keep one file per stream",
                )
            )
            return None
        display = str(found[0].relative_to(self.path))
        if not self.confined(display, display, "a symbolic link"):
            return None
        if not found[0].is_file():
            kind = (
                "a folder"
                if found[0].is_dir()
                else "a broken link"
                if not found[0].exists()
                else "not a regular file"
            )
            self.problems.append(Problem(display, f"is {kind}, not a table file"))
            return None
        return found[0]


def _epoch_hint(t0_s: float, offset_s: float) -> str:
    """The likely mistake behind a stream's offset from start_time."""
    if t0_s < 1e7:
        return "seconds since the start of the dive (or another clock) instead of POSIX seconds (UTC)?"
    if abs(offset_s + _GPS_EPOCH_S) < 2 * 86400:
        return "GPS time (from 1980-01-06) instead of POSIX seconds (UTC)?"
    hours = offset_s / 3600
    if 0.5 <= abs(hours) <= 14.5 and abs(hours * 4 - round(hours * 4)) < 0.05:
        return f"local time {hours:+g} h from UTC instead of UTC?"
    if abs(offset_s) > 365 * 86400:
        return "another dive's file, or a clock that was not set?"
    return "another dive's file, or the wrong start_time in dive.yaml?"


def _offset(seconds: float) -> str:
    hours = seconds / 3600
    return f"{abs(seconds):.0f} s" if abs(hours) < 1 else f"{abs(hours):,.1f} h"


def _check_times(c: _Checker, info: DiveInfo, streams: dict[str, tuple[str, Stream]]) -> None:
    """Time sanity: each stream near start_time, no longer than a dive, overlapping the others."""
    start = info.start_time_s
    spans = {name: (float(s.t_s[0]), float(s.t_s[-1])) for name, (_, s) in streams.items()}
    offsets = [t0 - start for t0, _ in spans.values()]
    if (
        len(spans) > 1
        and min(abs(o) for o in offsets) > START_TOLERANCE_S
        and max(offsets) - min(offsets) < START_TOLERANCE_S
    ):  # every stream off by the same: one mistake (the clock, the epoch or start_time), one line
        t0 = min(t for t, _ in spans.values())
        offset = t0 - start
        c.problems.append(
            Problem(
                "dive.yaml",
                f"key start_time: {_iso(start)}, but every stream ({', '.join(d for d, _ in streams.values())}) "
                f"starts {_offset(offset)} {'after' if offset > 0 else 'before'} it, at {_iso(t0)}: "
                + _epoch_hint(t0, offset),
            )
        )
        return
    bad: set[str] = set()
    for name, (display, _) in streams.items():
        t0, t1 = spans[name]
        offset = t0 - start
        if abs(offset) > START_TOLERANCE_S:
            when = "after" if offset > 0 else "before"
            c.problems.append(
                Problem(
                    display,
                    f"starts at {_iso(t0)}, {_offset(offset)} {when} start_time {_iso(start)} (dive.yaml), "
                    f"more than {START_TOLERANCE_S / 3600:g} h: {_epoch_hint(t0, offset)}",
                    None,
                    "t",
                )
            )
            bad.add(name)
        elif t1 - start > MAX_DIVE_S:
            c.problems.append(
                Problem(
                    display,
                    f"ends at {_iso(t1)}, {_offset(t1 - start)} after start_time (dive.yaml); a dive lasts "
                    f"at most {MAX_DIVE_S / 3600:g} h: times in another unit, or a clock jump?",
                    None,
                    "t",
                )
            )
            bad.add(name)
    good = {n: spans[n] for n in spans if n not in bad}
    reference = next((n for n in REQUIRED_STREAMS if n in good), None)
    if reference is None:
        return
    r0, r1 = good[reference]
    ref_display = streams[reference][0]
    for name, (t0, t1) in good.items():
        if name == reference:
            continue
        margin = 0.0 if name in REQUIRED_STREAMS else SURFACE_MARGIN_S
        if t1 < r0 - margin or t0 > r1 + margin:
            offset = t0 - r0
            c.problems.append(
                Problem(
                    streams[name][0],
                    f"does not overlap {ref_display} in time"
                    + (f" (nor come within {margin / 3600:g} h of it)" if margin else "")
                    + f": it starts {_offset(offset)} {'after' if offset > 0 else 'before'} it: "
                    + _epoch_hint(t0, offset),
                    None,
                    "t",
                )
            )
    if "dvl" in good and "attitude" in good:
        dvl = streams["dvl"][1]
        a0, a1 = good["attitude"]
        d0, d1 = good["dvl"]
        inside = np.count_nonzero((dvl.t_s >= max(a0, d0)) & (dvl.t_s <= min(a1, d1)))
        if inside < 2 and a1 >= d0 and a0 <= d1:
            c.problems.append(
                Problem(
                    streams["dvl"][0],
                    f"fewer than two samples inside {streams['attitude'][0]}'s time span",
                    None,
                    "t",
                )
            )


def _check_fixes(c: _Checker, info: DiveInfo, display: str, fixes: Stream) -> None:
    """GPS or USBL fixes within :data:`MAX_FIX_DISTANCE_M` of the dive's origin."""
    lat0, lon0 = info.origin.latitude_rad, info.origin.longitude_rad
    lat, lon = fixes.latitude_rad, fixes.longitude_rad  # type: ignore[attr-defined]
    dlon = np.angle(np.exp(1j * (lon - lon0)))
    distance = (
        _EARTH_RADIUS_M
        * 2
        * np.arcsin(
            np.sqrt(np.sin((lat - lat0) / 2) ** 2 + np.cos(lat) * np.cos(lat0) * np.sin(dlon / 2) ** 2).clip(
                0, 1
            )
        )
    )
    far = np.flatnonzero(distance > MAX_FIX_DISTANCE_M)
    if not far.size:
        return
    lat_deg, lon_deg = np.degrees(lat), np.degrees(lon)
    radians = bool(np.all(np.abs(lat_deg) <= np.pi / 2) and np.all(np.abs(lon_deg) <= 2 * np.pi))
    hint = (
        "degrees written as radians?"
        if radians
        else "another dive's fixes, or the wrong origin in dive.yaml?"
    )
    first = int(far[0])
    c.problems.append(
        Problem(
            display,
            f"{far.size} of {distance.size} fixes lie more than {MAX_FIX_DISTANCE_M / 1e3:g} km from the "
            f"dive's origin (dive.yaml), the first {distance[first] / 1e3:,.0f} km away at row {first + 1}: "
            + hint,
        )
    )


def _check_images(c: _Checker, display: str, index: ImageIndex, vehicle: Vehicle | None) -> None:
    """Image names that stay inside the dive folder; images that exist; their size against the
    stereo calibration (a sample of pairs); a calibration for a dive with images."""
    root = c.path / "images"
    problems: list[Problem] = []
    for column, names in (("left", index.left), ("right", index.right)):
        parts = [Path(str(n)) for n in names]
        bad = np.array([p.is_absolute() or ".." in p.parts for p in parts], dtype=bool)
        problems += flag_rows(
            bad,
            display,
            column,
            lambda r, names=names: (
                f"names {quote(str(names[r - 1]))}, outside images/ (names are relative to images/)"
            ),
            "names outside images/",
        )
        long = np.array(
            [
                len(str(n)) > MAX_IMAGE_NAME or any(len(x.encode()) > 255 for x in p.parts)
                for n, p in zip(names, parts, strict=True)
            ],
            dtype=bool,
        )
        problems += flag_rows(
            long & ~bad,
            display,
            column,
            lambda r, names=names: f"names {quote(str(names[r - 1]))}: a name too long for a file",
            "names too long",
        )
    c.problems += problems
    if problems:
        return
    present = np.array(
        [
            _is_file(root / str(a)) and _is_file(root / str(b))
            for a, b in zip(index.left, index.right, strict=True)
        ]
    )
    missing = [str(n) for n in (*index.left, *index.right) if not _is_file(root / str(n))]
    if missing:
        c.warnings.append(f"{display}: {len(missing)} image file(s) missing, first {quote(missing[0])}")
    real_root = str(c.path.resolve()) + os.sep
    reals = [os.path.realpath(root / str(n)) for n in (*index.left, *index.right)]
    leaving = [r for r in reals if os.path.exists(r) and not r.startswith(real_root)]
    if leaving:
        what = f"images/ ({len(leaving)} image file{'s' if len(leaving) > 1 else ''})"
        where = Path(leaving[0] if len(leaving) == 1 else os.path.commonpath(leaving))
        if not c.confined(leaving[0], display, what, where):
            return
    if not present.any():
        return
    if vehicle is not None and vehicle.stereo is None:
        c.warnings.append(
            f"{display}: the dive has images but {c.vehicle_display} has no stereo calibration (key stereo): "
            "loop closures cannot be found"
        )
        return
    if vehicle is None or vehicle.stereo is None:
        return
    rows = np.flatnonzero(present)
    sample = sorted({int(rows[0]), int(rows[len(rows) // 2]), int(rows[-1])})[:IMAGE_SIZE_SAMPLES]
    for r in sample:
        for name, cam in ((index.left[r], vehicle.stereo.left), (index.right[r], vehicle.stereo.right)):
            problem = image_size_problem(root / str(name), f"images/{name}", cam, c.vehicle_display)
            if problem is not None:
                c.problems.append(problem)
                return


def validate_dive(path: Path, *, allow_outside: bool = False) -> ValidationReport:
    """Read and check every file of a dive folder; never raises for bad content.

    Every check a stage would make of the dive's own files is made here (the stages read the dive
    through :func:`read_dive`): the schema of dive.yaml and the vehicle file, every stream's
    columns, values and times, the streams' times against start_time and each other, fixes near the
    origin, image names and sizes. Every path the dive names must stay inside its folder (no
    ``..``, absolute path or symbolic link leading out) unless ``allow_outside``, and then each one
    read outside is said in the warnings.
    """
    path = Path(path)
    if not path.is_dir():
        return ValidationReport(
            path, [Problem(str(path), "not a dive folder (no such directory)")], [], [], None
        )
    c = _Checker(path, allow_outside)
    info = None
    if c.confined("dive.yaml", "dive.yaml", "a symbolic link"):
        info, p = _parse_dive_yaml(path / "dive.yaml")
        c.problems += p
    vehicle_name = info.vehicle_file if info else "vehicle.yaml"
    c.vehicle_display = vehicle_name
    vehicle = None
    if c.confined(
        vehicle_name, "dive.yaml" if info else vehicle_name, f"key vehicle ({quote(vehicle_name)})"
    ):
        names = _calibration_names(path, vehicle_name)
        if all(c.confined(n, vehicle_name, f"key stereo.calibration_file ({quote(n)})") for n in names):
            vehicle, p = vehicle_problems(path / vehicle_name, display=vehicle_name)
            c.problems += [
                Problem(x.file, f"{x.message} (the vehicle file dive.yaml names, key vehicle)")
                if x.message in ("file not found", "not a regular file")
                else x
                for x in p
            ]
    loaded: dict[str, Stream] = {}
    displays: dict[str, str] = {}
    summaries: list[StreamSummary] = []
    for name, cls in {**REQUIRED_STREAMS, **OPTIONAL_STREAMS}.items():
        file = c.stream_file(cls, name in REQUIRED_STREAMS)
        if file is None:
            continue
        display = str(file.relative_to(path))
        values, p, w = read_table(file, cls.FIELDS, display)
        c.problems += p
        c.warnings += w
        if not p:
            stream = cls.from_columns(values)
            loaded[name] = stream
            displays[name] = display
            summaries.append(_summarise(name, display, stream.t_s))
    if "dvl" in loaded and not np.any(loaded["dvl"].valid):  # type: ignore[attr-defined]
        c.problems.append(
            Problem(
                displays["dvl"],
                "no sample is marked valid (no bottom lock): nothing to navigate with",
                None,
                "valid",
            )
        )
    if info is not None:
        _check_times(c, info, {n: (displays[n], s) for n, s in loaded.items()})
        for name in ("gps", "usbl"):
            if name in loaded:
                _check_fixes(c, info, displays[name], loaded[name])
    if "images" in loaded:
        _check_images(c, displays["images"], loaded["images"], vehicle)  # type: ignore[arg-type]
    dive = None
    if not c.problems and info is not None and vehicle is not None:
        dive = Dive(info=info, vehicle=vehicle, path=path, **loaded)  # type: ignore[arg-type]
    return ValidationReport(path, c.problems, c.warnings, summaries, dive)


def read_dive(path: Path, *, allow_outside: bool = False) -> Dive:
    """Read a dive folder; raise :class:`DiveFormatError` with every problem when it is invalid.

    With ``allow_outside``, files the dive names outside its folder are read, each with a warning.
    """
    report = validate_dive(path, allow_outside=allow_outside)
    for w in report.warnings:
        log.warning(w)
    if report.dive is None:
        raise DiveFormatError(
            [Problem(f"{path}/{p.file}", p.message, p.row, p.column) for p in report.problems]
        )
    return report.dive


def write_dive(
    dive: Dive,
    path: Path,
    *,
    fmt: Literal["csv", "parquet"] = "csv",
    overwrite: bool = False,
    extra: dict[str, Any] | None = None,
) -> Path:
    """Write a dive folder atomically.

    Parameters
    ----------
    dive : Dive
    path : Path
        The folder to create.
    fmt : {"csv", "parquet"}
        File format of the streams.
    overwrite : bool
        Replace an existing folder; otherwise an existing folder is an error.
    extra : dict, optional
        ``{relative path: callable(Path) -> None}`` writers for more files (truth, images), called
        inside the temporary folder before it is renamed into place.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: exists (use --overwrite to replace it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.tmp"))
    try:
        (tmp / "dive.yaml").write_text(dump_yaml(dive.info.to_yaml()), encoding="utf-8")
        write_vehicle(dive.vehicle, tmp / dive.info.vehicle_file)
        for stream in dive.streams().values():
            write_stream(stream, tmp / f"{stream.FILE}.{fmt}")
        for rel, writer in (extra or {}).items():
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            writer(target)
        if path.exists():
            old = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.old"))
            os.replace(path, old / "dive")
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


__all__ = [
    "FORMAT",
    "AttitudeStream",
    "Dive",
    "DiveInfo",
    "DvlStream",
    "GpsStream",
    "ImageIndex",
    "MagnetometerStream",
    "PressureStream",
    "UsblStream",
    "ValidationReport",
    "read_dive",
    "read_vehicle",
    "validate_dive",
    "write_dive",
]
