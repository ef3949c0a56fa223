"""The Dive container and the dive folder format ``auvnav-dive/1`` (DESIGN section 5).

A dive folder holds ``dive.yaml``, ``vehicle.yaml``, navigation streams under ``nav/`` (``.csv`` or
``.parquet``), an image index, and for simulated dives a ``truth/`` folder. :func:`validate_dive` reads
everything and reports every problem with its file, row and column; :func:`read_dive` returns a
:class:`Dive` or raises :class:`~auvnav.errors.DiveFormatError`; :func:`write_dive` writes a folder
atomically (a temporary sibling, then a rename).
"""

from __future__ import annotations

import datetime as dt
import logging
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, ValidationError, field_validator
from pydantic import Field as PydanticField

from auvnav.config import dump_yaml, load_yaml, pydantic_problems
from auvnav.errors import DiveFormatError, OutputExistsError, Problem
from auvnav.frames import GeodeticOrigin
from auvnav.streams import Field, Stream, looks_like_radians, read_table, within, write_stream
from auvnav.vehicle import Vehicle, read_vehicle, vehicle_problems, write_vehicle

log = logging.getLogger(__name__)

FORMAT = "auvnav-dive/1"
DEG = np.pi / 180.0
DBAR = 1e4  # Pa per dbar
T = Field("t_s", ("t",), check=within(0.0, 4.1e9, "s since 1970", " (POSIX seconds expected)"))


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
    model_config = ConfigDict(extra="forbid", frozen=True)


class _OriginFile(_Strict):
    latitude_deg: float = PydanticField(ge=-90, le=90)
    longitude_deg: float = PydanticField(ge=-180, le=360)


class _PressureFile(_Strict):
    type: Literal["absolute", "sea"] = "absolute"
    atmospheric_dbar: float = PydanticField(default=10.1325, ge=0, le=12)


class _DiveFile(_Strict):
    format: Literal["auvnav-dive/1"]
    name: str
    origin: _OriginFile
    start_time: dt.datetime
    heading_reference: Literal["magnetic", "true"] = "magnetic"
    declination_deg: float | Literal["auto"] = "auto"
    pressure: _PressureFile = _PressureFile()
    vehicle: str = "vehicle.yaml"

    @field_validator("start_time")
    @classmethod
    def _utc(cls, v: dt.datetime) -> dt.datetime:
        if v.tzinfo is None:
            raise ValueError("needs a time zone (ISO 8601 with Z or +00:00)")
        return v.astimezone(dt.timezone.utc)


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
        return None, pydantic_problems(err, "dive.yaml")
    info = DiveInfo(
        name=f.name,
        origin=GeodeticOrigin.from_degrees(f.origin.latitude_deg, f.origin.longitude_deg),
        start_time_s=f.start_time.timestamp(),
        heading_reference=f.heading_reference,
        declination_rad=None if f.declination_deg == "auto" else float(np.radians(f.declination_deg)),
        pressure_type=f.pressure.type,
        atmospheric_pa=f.pressure.atmospheric_dbar * DBAR,
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


def find_stream_file(root: Path, stem: str) -> Path | None:
    """The ``.csv`` or ``.parquet`` file of a stream, or None."""
    for suffix in (".csv", ".parquet"):
        candidate = root / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def vehicle_file_name(path: Path) -> str | None:
    """The vehicle file that a dive folder's dive.yaml names (``vehicle.yaml`` when it names none),
    or None when dive.yaml cannot say (reading the dive reports why)."""
    data, problems = load_yaml(Path(path) / "dive.yaml", "dive.yaml")
    if problems or not isinstance(data, dict):
        return None
    name = data.get("vehicle", "vehicle.yaml")
    return name if isinstance(name, str) else None


def dive_files(path: Path) -> dict[str, Path]:
    """The files of a dive folder that its navigation depends on, by their path inside it.

    ``dive.yaml``, the vehicle file it names (and the stereo calibration files that names), and
    every stream file under ``nav/``. The image files are not included (see :func:`image_files`).
    Unreadable YAML leaves out what it would have named: reading the dive reports the problem.
    """
    path = Path(path)
    out: dict[str, Path] = {}

    def add(rel: str) -> None:
        if (path / rel).is_file():
            out[rel] = path / rel

    add("dive.yaml")
    vehicle = vehicle_file_name(path)
    if vehicle is not None:
        add(vehicle)
        data, _ = load_yaml(path / vehicle, vehicle)
        stereo = data.get("stereo") if isinstance(data, dict) else None
        files = stereo.get("calibration_file") if isinstance(stereo, dict) else None
        base = Path(vehicle).parent
        for name in [files] if isinstance(files, str) else files if isinstance(files, list) else []:
            if isinstance(name, str):
                add(str(base / name))
    for cls in (*REQUIRED_STREAMS.values(), *OPTIONAL_STREAMS.values()):
        if cls is not ImageIndex:
            found = find_stream_file(path, cls.FILE)
            if found is not None:
                out[str(found.relative_to(path))] = found
    return out


def image_files(path: Path, index: ImageIndex) -> dict[str, Path]:
    """The image files an index names that exist, by their path inside the dive folder."""
    root = Path(path) / "images"
    out = {}
    for name in (*index.left, *index.right):
        file = root / str(name)
        if file.is_file():
            out[f"images/{name}"] = file
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
    gaps: list[tuple[float, float]]  # (start time, length) of gaps over 5 median periods


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
    period = float(np.median(dt_s)) if dt_s.size else 0.0
    gap_idx = np.flatnonzero(dt_s > 5 * period) if period > 0 else np.array([], dtype=int)
    return StreamSummary(
        name=name,
        file=file,
        rows=int(t.size),
        start_s=float(t[0]),
        end_s=float(t[-1]),
        rate_hz=1.0 / period if period > 0 else 0.0,
        gaps=[(float(t[i]), float(dt_s[i])) for i in gap_idx],
    )


def validate_dive(path: Path) -> ValidationReport:
    """Read and check every file of a dive folder; never raises for bad content."""
    path = Path(path)
    if not path.is_dir():
        return ValidationReport(
            path, [Problem(str(path), "not a dive folder (no such directory)")], [], [], None
        )
    problems: list[Problem] = []
    warnings: list[str] = []
    info, p = _parse_dive_yaml(path / "dive.yaml")
    problems += p
    vehicle_name = info.vehicle_file if info else "vehicle.yaml"
    vehicle, p = vehicle_problems(path / vehicle_name, display=vehicle_name)
    problems += p
    loaded: dict[str, Stream] = {}
    summaries: list[StreamSummary] = []
    for name, cls in {**REQUIRED_STREAMS, **OPTIONAL_STREAMS}.items():
        file = find_stream_file(path, cls.FILE)
        if file is None:
            if name in REQUIRED_STREAMS:
                problems.append(Problem(f"{cls.FILE}.csv", "required stream file missing"))
            continue
        display = str(file.relative_to(path))
        values, p, w = read_table(file, cls.FIELDS, display)
        problems += p
        warnings += w
        if not p:
            stream = cls.from_columns(values)
            loaded[name] = stream
            summaries.append(_summarise(name, display, stream.t_s))
    if "images" in loaded:
        missing = [
            str(n)
            for n in np.concatenate([loaded["images"].left, loaded["images"].right])  # type: ignore[attr-defined]
            if not (path / "images" / str(n)).is_file()
        ]
        if missing:
            warnings.append(f"images/index.csv: {len(missing)} image file(s) missing, first {missing[0]}")
    dive = None
    if not problems and info is not None and vehicle is not None:
        dive = Dive(info=info, vehicle=vehicle, path=path, **loaded)  # type: ignore[arg-type]
    return ValidationReport(path, problems, warnings, summaries, dive)


def read_dive(path: Path) -> Dive:
    """Read a dive folder; raise :class:`DiveFormatError` with every problem when it is invalid."""
    report = validate_dive(path)
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
