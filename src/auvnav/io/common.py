"""What every importer shares: settings, one-line errors, counted skips, and the assembly of a dive.

An importer reads its sources into an :class:`Imported`: the streams it found (SI units, the dive's
conventions), what its format says about the heading reference, the pressure and the origin, and a
count of everything it read and skipped, by reason. :func:`assemble` turns that into a
:class:`~auvnav.dive.Dive` by these rules, each written into the summary:

**Heading reference** (dive.yaml ``heading_reference`` and ``declination_deg``), first that applies:

1. the settings file's ``heading_reference`` (and ``declination_deg``), when given;
2. what the format says: an ACFR log's compass is magnetic and ``mission.cfg``'s
   ``MAGNETIC_VAR_DEG`` is its declination (the value ACFR's own processing adds); a PD0 heading
   with a heading bias (EB, fixed leader) is true (RDI applies EB as the magnetic variation), one
   without is magnetic; NMEA ``HDT`` is true, ``HDG``/``HDM`` magnetic (``HDG``'s variation field,
   when present, is its declination);
3. otherwise (ROS bags, CSV): an error that asks for ``heading_reference`` (REP-103 says east-north-up,
   not which north);
4. when the attitude comes from ``--base``, the base dive's.

A magnetic heading without a declination gets ``declination_deg: auto`` (the geomagnetic model at
the origin and start).

**Pressure** (dive.yaml ``pressure``): a format that logs depth (ACFR ``PAROSCI``, a ROS float, a
CSV depth column) is converted to sea pressure by TEOS-10 at the origin's latitude
(:func:`auvnav.depth.pressure.pressure_from_depth`), ``type: sea``; PD0's pressure is relative to
one atmosphere (``type: sea``); a ROS ``FluidPressure`` is absolute (``type: absolute``, atmospheric
pressure from the settings or 10.1325 dbar); a CSV pressure column needs ``pressure.type`` in the
mapping. The settings' ``pressure`` block overrides a format's own statement.

**Origin**: the settings' ``origin``; else what the format names (``mission.cfg``); else the base
dive's; else the first GPS fix; else the first USBL fix; else an error.

**Vehicle**: the settings' ``vehicle`` file (relative to the settings file); else the base dive's;
else the default vehicle (no lever arms, no stereo rig), said in the summary.

Errors in a source are one line, naming the file and the line or byte offset
(:class:`FormatError`); the dive is written only after everything is read and the written folder
is read back and validated (:func:`auvnav.io.api.import_dive`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import logging
import math
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, ValidationError, field_validator
from pydantic import Field as PydanticField

from auvnav.config import load_yaml, pydantic_problems
from auvnav.depth.pressure import pressure_from_depth
from auvnav.dive import (
    OPTIONAL_STREAMS,
    REQUIRED_STREAMS,
    Dive,
    DiveInfo,
    ImageIndex,
    PressureStream,
)
from auvnav.errors import AuvnavError, ConfigError, InsufficientDataError
from auvnav.frames import GeodeticOrigin, ned2geodetic
from auvnav.streams import Stream
from auvnav.vehicle import Vehicle, read_vehicle

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
DBAR = 1e4  # Pa per dbar
STANDARD_ATMOSPHERE_DBAR = 10.1325
#: A logged depth this far above the sea surface (metres) is not a depth (a sign or unit mistake).
ABOVE_SURFACE_M = 5.0
HeadingReference = Literal["magnetic", "true"]
PressureType = Literal["absolute", "sea"]


class FormatError(AuvnavError):
    """A source file that breaks its format: one line naming the file and where.

    Parameters
    ----------
    file : str or Path
    message : str
        What is wrong, in a phrase.
    line : int, optional
        1-based line of a text file.
    byte : int, optional
        0-based byte offset in a binary file.
    """

    def __init__(self, file: str | Path, message: str, *, line: int | None = None, byte: int | None = None):
        where = str(file)
        if line is not None:
            where += f": line {line}"
        if byte is not None:
            where += f": byte {byte}"
        self.file, self.line, self.byte = str(file), line, byte
        super().__init__(f"{where}: {' '.join(message.split())}")


# ---------------------------------------------------------------------------------------------
# Settings (--config FILE.yaml)
# ---------------------------------------------------------------------------------------------


class Strict(BaseModel):
    """A settings block: unknown keys are errors, values are checked."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class OriginSettings(Strict):
    latitude_deg: float = PydanticField(ge=-90, le=90)
    longitude_deg: float = PydanticField(ge=-180, le=360)


class PressureSettings(Strict):
    type: PressureType
    atmospheric_dbar: float = PydanticField(default=STANDARD_ATMOSPHERE_DBAR, ge=0, le=12)


class ImportSettings(Strict):
    """Keys every format's settings file may hold (each format adds its own).

    Parameters
    ----------
    name : str
        The dive's name (default: the output folder's name).
    origin : {latitude_deg, longitude_deg}
        The local frame's origin (default: see the module's rules).
    start_time : ISO 8601 with a time zone
        dive.yaml's start time (default: the first sample).
    heading_reference : {"magnetic", "true"}
    declination_deg : float or "auto"
    pressure : {type, atmospheric_dbar}
    vehicle : str
        A vehicle.yaml, relative to the settings file.
    gps_sigma_m, usbl_sigma_m : float
        1-sigma of fixes whose format gives none (default: the vehicle's).
    """

    name: str | None = None
    origin: OriginSettings | None = None
    start_time: dt.datetime | None = None
    heading_reference: HeadingReference | None = None
    declination_deg: float | Literal["auto"] | None = None
    pressure: PressureSettings | None = None
    vehicle: str | None = None
    gps_sigma_m: float | None = PydanticField(default=None, gt=0)
    usbl_sigma_m: float | None = PydanticField(default=None, gt=0)

    @field_validator("heading_reference", mode="before")
    @classmethod
    def _yaml_boolean(cls, v: Any) -> Any:
        if v is True:  # YAML reads an unquoted true as a boolean
            return "true"
        if v is False:
            raise ValueError("false is not a reference: write magnetic or true")
        return v

    @field_validator("start_time")
    @classmethod
    def _utc(cls, v: dt.datetime | None) -> dt.datetime | None:
        if v is not None and v.tzinfo is None:
            raise ValueError("needs a time zone (ISO 8601 with Z or +00:00)")
        return v


def load_settings(
    cls: type[ImportSettings], path: Path | Mapping[str, Any] | None
) -> tuple[ImportSettings, Path]:
    """Read a settings file strictly (or take a mapping, or the defaults); also the folder its paths
    are relative to (the file's, else the working folder)."""
    if path is None:
        return cls(), Path.cwd()
    if isinstance(path, Mapping):
        data: Any = dict(path)
        display, base = "settings", Path.cwd()
    else:
        path = Path(path)
        data, problems = load_yaml(path, str(path))
        if problems:
            raise ConfigError(str(problems[0]))
        display, base = str(path), path.parent
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{display}: must be a mapping of keys to values")
    try:
        return cls.model_validate(data), base
    except ValidationError as err:
        problems = pydantic_problems(err, display)
        more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
        raise ConfigError(f"{problems[0]}{more}") from err


# ---------------------------------------------------------------------------------------------
# What an importer returns
# ---------------------------------------------------------------------------------------------


@dataclass
class Counts:
    """What a reader read and skipped, by kind and reason, with the first place of each skip."""

    read: Counter[str] = field(default_factory=Counter)
    skipped: Counter[str] = field(default_factory=Counter)
    first: dict[str, str] = field(default_factory=dict)

    def skip(self, reason: str, where: str) -> None:
        """Count one skipped record; ``where`` (e.g. ``"line 12"``) is kept for the first of each reason."""
        self.skipped[reason] += 1
        self.first.setdefault(reason, where)

    def summary(self) -> dict[str, Any]:
        return {
            "read": dict(self.read),
            "skipped": {r: {"count": n, "first": self.first.get(r)} for r, n in self.skipped.items()},
        }


@dataclass
class Imported:
    """What an importer read.

    Parameters
    ----------
    streams : dict
        Streams by name (``dvl``, ``attitude``, ``pressure``, ``magnetometer``, ``gps``, ``usbl``,
        ``images``), SI units, the dive's frames.
    depth : (t_s, depth_m), optional
        A depth record (metres, positive down) to turn into sea pressure once the origin is known.
    heading_reference, declination_rad : what the format says (None: it does not say)
        ``declination_rad`` None with a magnetic reference means "auto".
    heading_rule : str
        Why, in a phrase.
    pressure_type, atmospheric_pa : what the format says about its pressure (None: nothing)
    origin : GeodeticOrigin, optional
        An origin the format names.
    counts : Counts
    notes : list of str
        Things worth saying.
    images_dir : Path, optional
        A staging folder holding the image files the index names (moved into ``images/``).
    image_bayer : dict
        The colour filter (:attr:`auvnav.vehicle.CameraModel.bayer`) of each side (``left``,
        ``right``) whose images are raw mosaics.
    """

    streams: dict[str, Stream] = field(default_factory=dict)
    depth: tuple[FloatArray, FloatArray] | None = None
    heading_reference: HeadingReference | None = None
    declination_rad: float | None = None
    heading_rule: str = ""
    pressure_type: PressureType | None = None
    atmospheric_pa: float | None = None
    pressure_rule: str = ""
    origin: GeodeticOrigin | None = None
    origin_rule: str = ""
    counts: Counts = field(default_factory=Counts)
    notes: list[str] = field(default_factory=list)
    images_dir: Path | None = None
    image_bayer: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ImportContext:
    """What a reader may use besides its sources and settings.

    Parameters
    ----------
    base : Dive, optional
        The ``--base`` dive (streams the format lacks; NMEA uses its pitch and roll).
    staging : Path
        A private folder for files that must not be held in memory (images); removed afterwards.
    settings_dir : Path
        The folder the settings file's paths are relative to.
    """

    base: Dive | None
    staging: Path
    settings_dir: Path


# ---------------------------------------------------------------------------------------------
# Reading text sources
# ---------------------------------------------------------------------------------------------


def read_bytes(path: Path) -> bytes:
    """A source file's bytes, or a one-line error."""
    path = Path(path)
    if not path.exists():
        raise FormatError(path, "file not found")
    if not path.is_file():
        raise FormatError(path, "not a regular file")
    try:
        return path.read_bytes()
    except OSError as err:
        raise FormatError(path, f"cannot be read ({err.strerror or type(err).__name__})") from err


def text_lines(path: Path, data: bytes) -> Iterator[tuple[int, int, bytes]]:
    """``(line number, byte offset, line)`` of a text file, 1-based lines, without end-of-line bytes.

    A NUL byte (binary content) is an error naming its byte offset.
    """
    nul = data.find(b"\x00")
    if nul >= 0:
        raise FormatError(path, "not a text file (NUL byte: binary content)", byte=nul)
    offset = 0
    for number, line in enumerate(data.split(b"\n"), start=1):
        start = offset
        offset += len(line) + 1
        if line.endswith(b"\r"):
            line = line[:-1]
        yield number, start, line


def number(text: bytes | str, path: Path, line: int, what: str) -> float:
    """A finite float, or a one-line error naming the line and the field."""
    try:
        value = float(text)
    except ValueError:
        raise FormatError(path, f"{what}: not a number ({_show(text)})", line=line) from None
    if not math.isfinite(value):
        raise FormatError(path, f"{what}: not a finite number ({_show(text)})", line=line)
    return value


def _show(text: bytes | str, limit: int = 40) -> str:
    s = text.decode("utf-8", "replace") if isinstance(text, bytes) else text
    return repr(s if len(s) <= limit else s[: limit - 1] + "…")


def strictly_increasing(t: FloatArray, counts: Counts, what: str, where: list[str]) -> NDArray[np.bool_]:
    """Mask of the samples to keep so that time strictly increases, in the given order (never
    reordered): a sample at or before the last kept one is skipped and counted."""
    keep = np.zeros(len(t), dtype=bool)
    last = -math.inf
    for k, tk in enumerate(t):
        if tk > last:
            keep[k] = True
            last = tk
        else:
            counts.skip(f"{what}: time not after the previous sample", where[k])
    return keep


# ---------------------------------------------------------------------------------------------
# Assembly
# ---------------------------------------------------------------------------------------------

_STREAM_FILES = {
    **{k: v.FILE for k, v in REQUIRED_STREAMS.items()},
    **{k: v.FILE for k, v in OPTIONAL_STREAMS.items()},
}


@dataclass(frozen=True)
class Assembled:
    dive: Dive
    summary: dict[str, Any]
    images_from_base: bool


def _origin(imported: Imported, settings: ImportSettings, base: Dive | None) -> tuple[GeodeticOrigin, str]:
    if settings.origin is not None:
        o = settings.origin
        return GeodeticOrigin.from_degrees(o.latitude_deg, o.longitude_deg), "the settings file"
    if imported.origin is not None:
        return imported.origin, imported.origin_rule or "the source"
    if base is not None:
        return base.info.origin, "the base dive"
    for name in ("gps", "usbl"):
        fixes: Any = imported.streams.get(name)
        if fixes is not None and len(fixes):
            origin = GeodeticOrigin(float(fixes.latitude_rad[0]), float(fixes.longitude_rad[0]))
            return origin, f"the first {name} fix"
    raise ConfigError(
        "the dive needs an origin and the sources name none (no GPS or USBL fix): give "
        "origin: {latitude_deg: ..., longitude_deg: ...} in --config, or --base DIVE"
    )


def _heading(
    imported: Imported, settings: ImportSettings, base: Dive | None, fmt: str
) -> tuple[HeadingReference, float | None, str]:
    """(reference, declination_rad or None for auto, rule) for the imported attitude."""
    reference = settings.heading_reference or imported.heading_reference
    if settings.heading_reference is not None:
        rule = "the settings file's heading_reference"
    else:
        rule = imported.heading_rule
    if reference is None:
        raise ConfigError(
            f"{fmt}: the sources do not say whether the heading is magnetic or true: give "
            "heading_reference: magnetic|true in --config"
        )
    if reference == "true":
        return "true", None, rule
    if settings.declination_deg is not None:
        decl = None if settings.declination_deg == "auto" else math.radians(settings.declination_deg)
        return "magnetic", decl, rule + "; declination from the settings file"
    return "magnetic", imported.declination_rad, rule


def _depth_to_pressure(imported: Imported, origin: GeodeticOrigin) -> Stream | None:
    if imported.depth is None:
        return None
    t, depth = imported.depth
    above = np.asarray(depth, float) < -ABOVE_SURFACE_M
    if above.any():
        k = int(np.flatnonzero(above)[0])
        raise InsufficientDataError(
            f"depth record: {int(above.sum())} depth(s) more than {ABOVE_SURFACE_M:g} m above the sea surface "
            f"(first {float(depth[k]):.6g} m at t = {float(t[k]):.6f} s): depth in metres, positive down, expected"
        )
    return PressureStream(
        t_s=np.asarray(t, float), pressure_pa=pressure_from_depth(depth, origin.latitude_rad)
    )


def _with_image_filters(vehicle: Vehicle, rule: str, filters: dict[str, str], notes: list[str]) -> Vehicle:
    """The vehicle with the colour filters of the sides whose images the sources give as raw mosaics
    (a vehicle file that names another filter is an error); without a stereo rig, a note says what to
    add to it."""
    if not filters:
        return vehicle
    stereo = vehicle.stereo
    if stereo is None:
        keys = ", ".join(f"{side}_bayer: {pattern}" for side, pattern in sorted(filters.items()))
        notes.append(f"the images are raw mosaics: give the stereo calibration in vehicle.yaml with {keys}")
        return vehicle
    bayer = {"left": stereo.left.bayer, "right": stereo.right.bayer}
    for side, pattern in filters.items():
        if bayer[side] not in (None, pattern):
            raise ConfigError(
                f"{rule}: stereo.{side}_bayer is {bayer[side]} but the {side} images are raw {pattern} mosaics"
            )
        bayer[side] = pattern
        notes.append(f"the {side} images are raw {pattern} mosaics (vehicle.yaml: stereo.{side}_bayer)")
    return dataclasses.replace(vehicle, stereo=stereo.with_bayer(bayer["left"], bayer["right"]))


def assemble(
    imported: Imported,
    settings: ImportSettings,
    *,
    fmt: str,
    sources: list[Path],
    base: Dive | None,
    name: str,
    settings_dir: Path,
) -> Assembled:
    """A dive from what a format holds, the settings and an optional base dive (the module's rules).

    Raises
    ------
    ConfigError
        The heading reference, the pressure type or the origin cannot be told.
    InsufficientDataError
        A required stream (DVL, attitude, pressure) is in neither the sources nor the base dive.
    """
    streams = dict(imported.streams)
    origin, origin_rule = _origin(imported, settings, base)
    notes = list(imported.notes)
    from_base: list[str] = []

    # Pressure: a depth record becomes sea pressure at the origin's latitude.
    pressure_from_depth_record = "pressure" not in streams and imported.depth is not None
    if pressure_from_depth_record:
        streams["pressure"] = _depth_to_pressure(imported, origin)  # type: ignore[assignment]

    # Streams the sources lack, from the base dive.
    if base is not None:
        for key, stream in base.streams().items():
            if key not in streams:
                streams[key] = stream
                from_base.append(key)
    missing = [k for k in REQUIRED_STREAMS if k not in streams]
    if missing:
        files = ", ".join(f"{_STREAM_FILES[k]}.csv" for k in missing)
        raise InsufficientDataError(
            f"{fmt}: the sources hold no {', '.join(missing)} ({files}): give --base DIVE with "
            f"{'it' if len(missing) == 1 else 'them'}, or more sources"
        )

    # Heading reference of the attitude.
    if "attitude" in from_base and base is not None:
        reference, decl, heading_rule = (
            base.info.heading_reference,
            base.info.declination_rad,
            "the base dive's (its attitude)",
        )
    else:
        reference, decl, heading_rule = _heading(imported, settings, base, fmt)

    # Pressure type.
    if "pressure" in from_base and base is not None:
        ptype, atm, pressure_rule = base.info.pressure_type, base.info.atmospheric_pa, "the base dive's"
    elif settings.pressure is not None:
        ptype, atm = settings.pressure.type, settings.pressure.atmospheric_dbar * DBAR
        pressure_rule = "the settings file's pressure block"
    elif pressure_from_depth_record:
        ptype, atm = "sea", STANDARD_ATMOSPHERE_DBAR * DBAR
        pressure_rule = "depth converted to sea pressure (TEOS-10) at the origin's latitude"
    elif imported.pressure_type is not None:
        ptype = imported.pressure_type
        atm = (
            imported.atmospheric_pa
            if imported.atmospheric_pa is not None
            else STANDARD_ATMOSPHERE_DBAR * DBAR
        )
        pressure_rule = imported.pressure_rule
    else:
        raise ConfigError(
            f"{fmt}: the sources do not say whether the pressure is absolute or sea pressure: give "
            "pressure: {type: absolute|sea, atmospheric_dbar: ...} in --config"
        )

    # Vehicle.
    if settings.vehicle is not None:
        vehicle = read_vehicle(settings_dir / settings.vehicle)
        vehicle_rule = str(settings_dir / settings.vehicle)
    elif base is not None:
        vehicle, vehicle_rule = base.vehicle, "the base dive's"
    else:
        vehicle, vehicle_rule = Vehicle(), "the default vehicle (no lever arms, no stereo rig)"
        notes.append("no vehicle file: the default vehicle is written (give vehicle: FILE in --config)")

    vehicle = _with_image_filters(vehicle, vehicle_rule, imported.image_bayer, notes)

    # Fix sigmas where the format gives none (a NaN sigma from the reader).
    for key, sigma in (
        ("gps", settings.gps_sigma_m or vehicle.gps_sigma_m),
        ("usbl", settings.usbl_sigma_m or vehicle.usbl_sigma_m),
    ):
        s = streams.get(key)
        if s is not None and key not in from_base and np.any(np.isnan(s.sigma_m)):  # type: ignore[attr-defined]
            filled = np.where(np.isnan(s.sigma_m), sigma, s.sigma_m)  # type: ignore[attr-defined]
            streams[key] = dataclasses.replace(s, sigma_m=filled)  # type: ignore[type-var]
            notes.append(f"{key}: the sources give no uncertainty; sigma {sigma:g} m")

    first = min(float(s.t_s[0]) for s in streams.values() if len(s))  # type: ignore[attr-defined]
    start = settings.start_time.timestamp() if settings.start_time is not None else first
    info = DiveInfo(
        name=settings.name or name,
        origin=origin,
        start_time_s=start,
        heading_reference=reference,
        declination_rad=decl if reference == "magnetic" else None,
        pressure_type=ptype,
        atmospheric_pa=float(atm),
    )
    dive = Dive(info=info, vehicle=vehicle, **streams)  # type: ignore[arg-type]
    images_from_base = "images" in from_base
    summary = {
        "format": fmt,
        "sources": [str(s) for s in sources],
        "streams": {
            key: {
                "rows": len(s),
                "from": "base" if key in from_base else "sources",
                "start": _iso(float(s.t_s[0])),  # type: ignore[attr-defined]
                "end": _iso(float(s.t_s[-1])),  # type: ignore[attr-defined]
            }
            for key, s in dive.streams().items()
        },
        **imported.counts.summary(),
        "heading_reference": reference,
        "declination_deg": None if reference == "true" else ("auto" if decl is None else math.degrees(decl)),
        "heading_rule": heading_rule,
        "pressure": {"type": ptype, "atmospheric_dbar": atm / DBAR, "rule": pressure_rule},
        "origin": {
            "latitude_deg": math.degrees(origin.latitude_rad),
            "longitude_deg": math.degrees(origin.longitude_rad),
            "rule": origin_rule,
        },
        "vehicle": vehicle_rule,
        "notes": notes,
    }
    return Assembled(dive, summary, images_from_base)


def _iso(t_s: float) -> str:
    """A time as ISO 8601 UTC; a time no calendar holds (the dive's checks then refuse it) as seconds."""
    try:
        return (
            dt.datetime.fromtimestamp(t_s, dt.timezone.utc)
            .isoformat(timespec="milliseconds")
            .replace("+00:00", "Z")
        )
    except (OverflowError, OSError, ValueError):
        return f"{t_s:.3f} s"


def format_summary(summary: dict[str, Any]) -> str:
    """The human account of an import."""
    lines = [f"{summary['out']}: imported {summary['format']} from {len(summary['sources'])} source(s)"]
    for key, s in summary["streams"].items():
        lines.append(f"  {key:<13} {s['rows']:>8} rows  {s['start']} .. {s['end']}  ({s['from']})")
    if summary["read"]:
        lines.append("  read: " + ", ".join(f"{n} {k}" for k, n in summary["read"].items()))
    for reason, s in summary["skipped"].items():
        lines.append(f"  skipped {s['count']}: {reason} (first at {s['first']})")
    decl = summary["declination_deg"]
    decl_text = (
        "" if decl is None else (", declination auto" if decl == "auto" else f", declination {decl:.3f} deg")
    )
    lines.append(f"  heading: {summary['heading_reference']}{decl_text} ({summary['heading_rule']})")
    p = summary["pressure"]
    lines.append(f"  pressure: {p['type']} ({p['rule']})")
    o = summary["origin"]
    lines.append(f"  origin: {o['latitude_deg']:.6f}, {o['longitude_deg']:.6f} ({o['rule']})")
    lines.append(f"  vehicle: {summary['vehicle']}")
    lines.extend(f"  note: {n}" for n in summary["notes"])
    return "\n".join(lines)


def fixes_from_ned(
    t_s: FloatArray, p_ned_m: FloatArray, origin: GeodeticOrigin
) -> tuple[FloatArray, FloatArray]:
    """Latitude and longitude (radians) of local NED positions about ``origin``."""
    lat, lon, _ = ned2geodetic(np.column_stack([p_ned_m[:, 0], p_ned_m[:, 1], np.zeros(len(t_s))]), origin)
    return np.reshape(lat, -1), np.reshape(lon, -1)


def images_index(t_s: list[float], left: list[str], right: list[str]) -> ImageIndex | None:
    """The image index of stereo pairs (names relative to ``images/``), or None without pairs."""
    if not t_s:
        return None
    return ImageIndex(np.asarray(t_s, float), np.asarray(left, dtype=str), np.asarray(right, dtype=str))


__all__ = [
    "Assembled",
    "Counts",
    "FormatError",
    "ImportContext",
    "ImportSettings",
    "Imported",
    "assemble",
    "load_settings",
]
