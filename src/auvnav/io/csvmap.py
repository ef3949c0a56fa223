"""Any CSV, described by a mapping file: how the long tail of vendor logs gets in.

The mapping file (``--config MAP.yaml``) holds the common import settings (``heading_reference`` is
required when an attitude is mapped, ``pressure: {type: ...}`` when a pressure column is) and, under
``files``, one entry per CSV file named on the command line (by its file name)::

    heading_reference: magnetic
    pressure: {type: absolute, atmospheric_dbar: 10.1325}
    vehicle: vehicle.yaml
    files:
      dvl_log.csv:
        time: {column: time_ms, format: posix_ms}
        dvl:
          vx: {column: vel_fwd, unit: mm/s}
          vy: {column: vel_stbd, unit: mm/s}
          vz: {column: vel_down, unit: mm/s}
          altitude: {column: range, unit: m}        # optional
          valid: {column: bottom_lock}              # optional: 1/0, true/false, yes/no, A/V
      ahrs.csv:
        delimiter: ";"
        time: {column: utc, format: iso8601}        # with Z or +hh:mm, or give utc_offset_hours
        attitude:
          heading: {column: yaw, unit: rad}
          pitch: {column: pitch, unit: deg}
          roll: {value: 0.0, unit: deg}             # a constant
        pressure:
          pressure: {column: p, unit: bar}          # or depth: {column: d, unit: m}

Streams and their fields: ``dvl`` (``vx``, ``vy``, ``vz`` in the DVL frame FRD, ``altitude``,
``valid``), ``attitude`` (``heading``, ``pitch``, ``roll``), ``pressure`` (``pressure`` or
``depth``), ``magnetometer`` (``mx``, ``my``, ``mz``, any one unit), ``gps`` (``latitude``,
``longitude``, ``sigma``), ``usbl`` (``latitude``, ``longitude``, ``depth``, ``sigma``), ``images``
(``left``, ``right``: file names relative to the dive's ``images/``).

Units: angles ``deg``, ``rad``; pressure ``Pa``, ``kPa``, ``dbar``, ``bar``, ``mbar``, ``psi``;
lengths ``m``, ``cm``, ``mm``; speeds ``m/s``, ``cm/s``, ``mm/s``, ``knots``; ``counts`` with
``scale`` (SI units per count) and ``offset``. A field is ``{column: NAME, unit: U}`` or
``{value: V, unit: U}``.

Time formats: ``posix_s``, ``posix_ms``, ``posix_us``; ``iso8601`` (a zone is required in the text
unless ``utc_offset_hours`` is given: a time without one is not guessed to be UTC); ``gps_week``
(``columns: [WEEK, SECONDS_OF_WEEK]``, GPS time turned into UTC with the leap seconds in force,
GPS - UTC = 13 s from 1999 to 18 s since 2017; ``leap_seconds`` overrides).

A row with the wrong number of fields, a value that is not a number, or a time that cannot be read
is an error naming the file, line and column. Rows whose time is not after the previous row's are
skipped and counted, never reordered.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import math
import re
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd
from pydantic import Field as PydanticField

from auvnav.config import quote
from auvnav.dive import (
    AttitudeStream,
    DvlStream,
    GpsStream,
    ImageIndex,
    MagnetometerStream,
    PressureStream,
    UsblStream,
)
from auvnav.errors import ConfigError
from auvnav.io.common import (
    FormatError,
    ImportContext,
    Imported,
    ImportSettings,
    Strict,
    read_bytes,
)

DEG = math.pi / 180.0
ANGLE = {"deg": DEG, "rad": 1.0}
PRESSURE = {"Pa": 1.0, "kPa": 1e3, "dbar": 1e4, "bar": 1e5, "mbar": 1e2, "psi": 6894.757293168}
LENGTH = {"m": 1.0, "cm": 0.01, "mm": 0.001}
SPEED = {"m/s": 1.0, "cm/s": 0.01, "mm/s": 0.001, "knots": 1852.0 / 3600.0}
ANY = {"any": 1.0, "": 1.0, "T": 1.0, "uT": 1.0, "nT": 1.0, "G": 1.0, "mG": 1.0}
Kind = Literal["angle", "pressure", "length", "speed", "any", "bool", "text"]
UNITS: dict[str, dict[str, float]] = {
    "angle": ANGLE,
    "pressure": PRESSURE,
    "length": LENGTH,
    "speed": SPEED,
    "any": ANY,
}

#: Fields of each stream: kind and whether it is required.
STREAM_FIELDS: dict[str, dict[str, tuple[Kind, bool]]] = {
    "dvl": {
        "vx": ("speed", True),
        "vy": ("speed", True),
        "vz": ("speed", True),
        "altitude": ("length", False),
        "valid": ("bool", False),
    },
    "attitude": {"heading": ("angle", True), "pitch": ("angle", True), "roll": ("angle", True)},
    "pressure": {"pressure": ("pressure", False), "depth": ("length", False)},
    "magnetometer": {"mx": ("any", True), "my": ("any", True), "mz": ("any", True)},
    "gps": {"latitude": ("angle", True), "longitude": ("angle", True), "sigma": ("length", False)},
    "usbl": {
        "latitude": ("angle", True),
        "longitude": ("angle", True),
        "depth": ("length", True),
        "sigma": ("length", False),
    },
    "images": {"left": ("text", True), "right": ("text", True)},
}

GPS_EPOCH_S = dt.datetime(1980, 1, 6, tzinfo=dt.timezone.utc).timestamp()
#: GPS - UTC, seconds, from the UTC instant given (IERS Bulletin C; the leap seconds since 1999).
GPS_LEAP = [
    (dt.datetime(2017, 1, 1, tzinfo=dt.timezone.utc).timestamp(), 18),
    (dt.datetime(2015, 7, 1, tzinfo=dt.timezone.utc).timestamp(), 17),
    (dt.datetime(2012, 7, 1, tzinfo=dt.timezone.utc).timestamp(), 16),
    (dt.datetime(2009, 1, 1, tzinfo=dt.timezone.utc).timestamp(), 15),
    (dt.datetime(2006, 1, 1, tzinfo=dt.timezone.utc).timestamp(), 14),
    (dt.datetime(1999, 1, 1, tzinfo=dt.timezone.utc).timestamp(), 13),
]


class ColumnSpec(Strict):
    column: str | None = None
    value: float | str | None = None
    unit: str = ""
    scale: float | None = None
    offset: float = 0.0


class TimeSpec(Strict):
    column: str | None = None
    columns: list[str] | None = None
    format: Literal["posix_s", "posix_ms", "posix_us", "iso8601", "gps_week"]
    utc_offset_hours: float | None = None
    leap_seconds: int | None = None


class FileSpec(Strict):
    delimiter: str = ","
    comment: str | None = None
    skip_rows: int = 0
    time: TimeSpec
    dvl: dict[str, ColumnSpec] | None = None
    attitude: dict[str, ColumnSpec] | None = None
    pressure: dict[str, ColumnSpec] | None = None
    magnetometer: dict[str, ColumnSpec] | None = None
    gps: dict[str, ColumnSpec] | None = None
    usbl: dict[str, ColumnSpec] | None = None
    images: dict[str, ColumnSpec] | None = None


class CsvSettings(ImportSettings):
    """The mapping file: the common import settings and ``files`` (see the module docstring)."""

    files: dict[str, FileSpec] = PydanticField(default_factory=dict)


SETTINGS = CsvSettings


class _Table:
    """A CSV's header and rows as text, with the line number of each row."""

    def __init__(self, path: Path, spec: FileSpec):
        data = read_bytes(path)
        try:
            text = data.decode("utf-8-sig")
        except UnicodeDecodeError as err:
            raise FormatError(path, "not a UTF-8 text file", byte=err.start) from None
        if "\x00" in text:
            raise FormatError(path, "not a text file (NUL byte: binary content)", byte=data.find(b"\x00"))
        if len(spec.delimiter) != 1:
            raise ConfigError(f"{path.name}: delimiter must be one character; found {quote(spec.delimiter)}")
        self.path = path
        lines = text.splitlines()
        self.header: list[str] | None = None
        self.rows: list[list[str]] = []
        self.line_of: list[int] = []
        for number, row in enumerate(
            csv.reader(io.StringIO("\n".join(lines)), delimiter=spec.delimiter), start=1
        ):
            if number <= spec.skip_rows or not row or all(not c.strip() for c in row):
                continue
            if spec.comment and row[0].lstrip().startswith(spec.comment):
                continue
            row = [c.strip() for c in row]
            if self.header is None:
                self.header = row
                continue
            if len(row) != len(self.header):
                raise FormatError(
                    path,
                    f"has {len(row)} fields; the header has {len(self.header)} (wrong field count)",
                    line=number,
                )
            self.rows.append(row)
            self.line_of.append(number)
        if self.header is None:
            raise FormatError(path, "no header row")
        if not self.rows:
            raise FormatError(path, "no data rows")

    def column(self, name: str, what: str) -> list[str]:
        assert self.header is not None
        if name not in self.header:
            raise FormatError(
                self.path,
                f"no column {quote(name)} (the mapping's {what}); the header has {', '.join(self.header)}",
                line=self._header_line(),
            )
        k = self.header.index(name)
        return [row[k] for row in self.rows]

    def _header_line(self) -> int:
        return (self.line_of[0] - 1) if self.line_of else 1

    def numbers(self, name: str, what: str) -> np.ndarray:
        values = self.column(name, what)
        out = np.empty(len(values))
        for k, v in enumerate(values):
            try:
                out[k] = float(v)
            except ValueError:
                raise FormatError(
                    self.path, f"column {name}: not a number ({quote(v)})", line=self.line_of[k]
                ) from None
            if not math.isfinite(out[k]):
                raise FormatError(
                    self.path, f"column {name}: not a finite number ({quote(v)})", line=self.line_of[k]
                )
        return out


def _leap(gps_s: np.ndarray, override: int | None, path: Path) -> np.ndarray:
    if override is not None:
        return np.full(len(gps_s), float(override))
    out = np.full(len(gps_s), np.nan)
    for start, leap in GPS_LEAP:
        undone = np.isnan(out) & (gps_s - leap >= start)
        out[undone] = leap
    if np.isnan(out).any():
        raise ConfigError(
            f"{path.name}: GPS time before 1999: give time.leap_seconds (GPS - UTC) in the mapping"
        )
    return out


_ZONE = re.compile(r"(Z|[+-]\d\d:?\d\d)$")


def _times(table: _Table, spec: TimeSpec) -> np.ndarray:
    path = table.path
    if spec.format == "gps_week":
        if not spec.columns or len(spec.columns) != 2:
            raise ConfigError(f"{path.name}: time format gps_week needs columns: [WEEK, SECONDS_OF_WEEK]")
        week = table.numbers(spec.columns[0], "time")
        tow = table.numbers(spec.columns[1], "time")
        gps = GPS_EPOCH_S + week * 604800.0 + tow
        return gps - _leap(gps, spec.leap_seconds, path)
    if spec.column is None:
        raise ConfigError(f"{path.name}: time needs column: NAME")
    if spec.format in ("posix_s", "posix_ms", "posix_us"):
        scale = {"posix_s": 1.0, "posix_ms": 1e-3, "posix_us": 1e-6}[spec.format]
        return table.numbers(spec.column, "time") * scale
    text = table.column(spec.column, "time")
    if spec.utc_offset_hours is None:
        for k, v in enumerate(text):
            if not _ZONE.search(v):
                raise FormatError(
                    path,
                    f"column {spec.column}: time {quote(v)} has no zone (give time.utc_offset_hours in the mapping)",
                    line=table.line_of[k],
                )
    parsed = pd.to_datetime(
        pd.Series(text), utc=spec.utc_offset_hours is None, format="ISO8601", errors="coerce"
    )
    bad = parsed.isna().to_numpy()
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise FormatError(
            path, f"column {spec.column}: not an ISO 8601 time ({quote(text[k])})", line=table.line_of[k]
        )
    if spec.utc_offset_hours is None:
        seconds = (parsed.dt.tz_convert("UTC") - pd.Timestamp(0, tz="UTC")).dt.total_seconds()
        return seconds.to_numpy(dtype=float)
    if parsed.dt.tz is not None:
        raise ConfigError(f"{path.name}: utc_offset_hours is given but the times carry their own zone")
    seconds = (parsed - pd.Timestamp(0)).dt.total_seconds()
    return seconds.to_numpy(dtype=float) - spec.utc_offset_hours * 3600.0


def _truth(value: str) -> bool | None:
    v = value.strip().lower()
    if v in ("1", "true", "yes", "a", "t", "y"):
        return True
    if v in ("0", "false", "no", "v", "f", "n"):
        return False
    try:
        return float(v) != 0.0
    except ValueError:
        return None


def _field(table: _Table, stream: str, name: str, spec: ColumnSpec, kind: Kind) -> np.ndarray:
    n = len(table.rows)
    what = f"{stream}.{name}"
    if (spec.column is None) == (spec.value is None):
        raise ConfigError(f"{table.path.name}: {what}: give column or value (one of them)")
    if kind == "text":
        return np.asarray(
            table.column(spec.column, what) if spec.column else [str(spec.value)] * n, dtype=str
        )
    if kind == "bool":
        raw = table.column(spec.column, what) if spec.column else [str(spec.value)] * n
        out = np.empty(n, dtype=bool)
        for k, v in enumerate(raw):
            b = _truth(v)
            if b is None:
                raise FormatError(
                    table.path, f"column {spec.column}: not a truth value ({quote(v)})", line=table.line_of[k]
                )
            out[k] = b
        return out
    if spec.unit == "counts":
        if spec.scale is None:
            raise ConfigError(f"{table.path.name}: {what}: unit counts needs scale (SI units per count)")
        factor = spec.scale
    else:
        units = UNITS[kind]
        if spec.unit not in units:
            raise ConfigError(
                f"{table.path.name}: {what}: unit {quote(spec.unit)} is not a {kind} unit ({', '.join(u for u in units if u)}, counts)"
            )
        if spec.scale is not None:
            raise ConfigError(f"{table.path.name}: {what}: scale goes with unit counts")
        factor = units[spec.unit]
    if spec.column is not None:
        values = table.numbers(spec.column, what)
    else:
        try:
            values = np.full(n, float(spec.value))  # type: ignore[arg-type]
        except ValueError:
            raise ConfigError(
                f"{table.path.name}: {what}: value {quote(spec.value)} is not a number"
            ) from None
    return values * factor + spec.offset


def read(sources: list[Path], settings: CsvSettings, context: ImportContext) -> Imported:  # type: ignore[override]
    """Read the CSV files the mapping describes."""
    if not settings.files:
        raise ConfigError("csv: the mapping file (--config) needs files: {FILE: {time: ..., STREAM: ...}}")
    if not sources:
        raise ConfigError("csv: give the CSV files the mapping describes")
    names = {p.name: p for p in sources}
    for p in sources:
        if p.name not in settings.files:
            raise ConfigError(f"csv: {p} is not in the mapping's files ({', '.join(settings.files)})")
    for name in settings.files:
        if name not in names:
            raise ConfigError(f"csv: the mapping describes {name}, which is not among the files given")
    imported = Imported()
    counts = imported.counts
    mapped: dict[str, str] = {}
    for name, spec in settings.files.items():
        path = names[name]
        table = _Table(path, spec)
        t = _times(table, spec.time)
        counts.read[f"{name} rows"] = len(t)
        keep = np.zeros(len(t), dtype=bool)
        last = -math.inf
        for k, tk in enumerate(t):
            if tk > last:
                keep[k], last = True, tk
            else:
                counts.skip(
                    f"{name}: rows whose time is not after the previous row", f"line {table.line_of[k]}"
                )
        for stream in STREAM_FIELDS:
            fields = getattr(spec, stream)
            if fields is None:
                continue
            if stream in mapped:
                raise ConfigError(f"csv: {stream} is mapped in both {mapped[stream]} and {name}")
            mapped[stream] = name
            known = STREAM_FIELDS[stream]
            for key in fields:
                if key not in known:
                    raise ConfigError(
                        f"csv: {name}: {stream}.{key} is not a field of {stream} ({', '.join(known)})"
                    )
            missing = [k for k, (_, req) in known.items() if req and k not in fields]
            if missing:
                raise ConfigError(f"csv: {name}: {stream} needs {', '.join(missing)}")
            values = {k: _field(table, stream, k, s, known[k][0])[keep] for k, s in fields.items()}
            _stream(imported, stream, t[keep], values, name)
    return imported


def _stream(imported: Imported, stream: str, t: np.ndarray, v: dict[str, np.ndarray], name: str) -> None:
    if stream == "dvl":
        valid = v.get("valid", np.ones(len(t), dtype=bool))
        vel = np.column_stack([v["vx"], v["vy"], v["vz"]])
        imported.streams["dvl"] = DvlStream(t, np.where(valid[:, None], vel, 0.0), v.get("altitude"), valid)
        if "altitude" not in v:
            imported.notes.append("no DVL altitude mapped: nav/dvl.csv has none (loops use the stereo range)")
    elif stream == "attitude":
        imported.streams["attitude"] = AttitudeStream(t, v["heading"], v["pitch"], v["roll"])
        imported.heading_rule = "the mapping's heading_reference"
    elif stream == "pressure":
        if ("pressure" in v) == ("depth" in v):
            raise ConfigError(f"csv: {name}: pressure needs one of pressure or depth")
        if "depth" in v:
            imported.depth = (t, v["depth"])
        else:
            imported.streams["pressure"] = PressureStream(t, v["pressure"])
    elif stream == "magnetometer":
        imported.streams["magnetometer"] = MagnetometerStream(t, np.column_stack([v["mx"], v["my"], v["mz"]]))
    elif stream == "gps":
        imported.streams["gps"] = GpsStream(
            t, v["latitude"], v["longitude"], v.get("sigma", np.full(len(t), np.nan))
        )
    elif stream == "usbl":
        imported.streams["usbl"] = UsblStream(
            t, v["latitude"], v["longitude"], v["depth"], v.get("sigma", np.full(len(t), np.nan))
        )
    elif stream == "images":
        imported.streams["images"] = ImageIndex(t, v["left"], v["right"])
