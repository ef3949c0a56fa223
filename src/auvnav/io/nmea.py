"""NMEA 0183 logs: GPS fixes (GGA, RMC) and heading (HDT, HDG, HDM), parsed with ``pynmea2``.

Real logs are untidy, so a line that cannot be used is skipped and counted by kind, with the first
line of each kind in the summary: sentences with a wrong checksum, truncated sentences (fields
missing or empty), lines that are not NMEA (or not text), proprietary (``$P...``) and AIS (``!``)
sentences, sentence types this importer does not use (GSV, VTG, ...), fixes that are not fixes (GGA
quality 0, RMC status V), and times that do not advance (a receiver clock jumping back, a repeated
time). Nothing is reordered. With ``strict: true`` every skip other than an invalid fix is an
error naming its line. Text before the first ``$`` or ``!`` of a line (a logger's time stamp) is
ignored.

**Time**: a fix takes the receiver's time: RMC gives the date and time, GGA only the time of day,
dated by the last RMC (or, before the first, by the first RMC of the file, or ``date`` in the
settings); a time of day that falls by more than 12 hours is the next day. Heading sentences carry
no time at all: they take the logger's time stamp before them on their line (POSIX seconds, or ISO
8601 with a zone, e.g. ``2009-10-15T01:00:00.100Z $HEHDT,123.4,T*..``); without one they are skipped
and counted.

**Fixes**: a GGA and an RMC of the same time are one fix (the GGA's, for its HDOP). The sigma is
``HDOP x uere_m`` (3 m by default, so that HDOP 1 gives the vehicle's default GPS accuracy); an
RMC-only fix has the vehicle's (or ``gps_sigma_m``).

**Heading**: HDT is true heading; HDG (its sensor heading; a deviation field is reported and not
applied, since auvnav fits its own deviation) and HDM are magnetic, HDG's variation field giving the
declination. When the log has HDT, magnetic sentences are counted and not used. The attitude's pitch
and roll come from the ``--base`` dive's attitude (interpolated) or, without one, are zero (said in
the summary).
"""

from __future__ import annotations

import datetime as dt
import math
import re
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field as PydanticField

from auvnav.dive import AttitudeStream, GpsStream
from auvnav.errors import ConfigError
from auvnav.frames import wrap_angle
from auvnav.io.common import Counts, FormatError, ImportContext, Imported, ImportSettings, read_bytes

DEG = math.pi / 180.0


class NmeaSettings(ImportSettings):
    """Settings of the ``nmea`` importer (besides :class:`ImportSettings`).

    Parameters
    ----------
    use : list of {"gps", "attitude"}
        The streams to take from the log (default both, when present).
    uere_m : float
        Metres of horizontal error per unit of HDOP.
    date : YYYY-MM-DD
        The date of times before the log's first RMC (when it has none).
    strict : bool
        Any unusable line (other than an invalid fix) is an error.
    """

    use: list[Literal["gps", "attitude"]] = PydanticField(default_factory=lambda: ["gps", "attitude"])
    uere_m: float = 3.0
    date: dt.date | None = None
    strict: bool = False


SETTINGS = NmeaSettings

_RMC_DATE = re.compile(rb"\$..RMC,[^,]*,A,[^,]*,[NS],[^,]*,[EW],[^,]*,[^,]*,(\d{6}),")


class _Skip(Exception):
    """A line skipped: ``reason`` is its kind in the summary; ``invalid_fix`` for fixes the receiver
    itself marks as no fix (counted even with ``strict``)."""

    def __init__(self, reason: str, *, invalid_fix: bool = False):
        super().__init__(reason)
        self.reason, self.invalid_fix = reason, invalid_fix


def _logger_time(prefix: str) -> float | None:
    """POSIX seconds of a logger's time stamp before a sentence (POSIX seconds or ISO 8601 with a
    zone), or None when there is none."""
    text = prefix.strip().strip(",;")
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        pass
    try:
        when = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise _Skip("lines whose text before the sentence is not a time stamp") from None
    if when.tzinfo is None:
        raise _Skip("logger time stamps without a time zone")
    return when.timestamp()


def _tod(text: str) -> float:
    """Seconds of the day of ``hhmmss(.sss)``."""
    if len(text) < 6 or not (text[:6].isascii() and text[:6].isdigit()):
        raise _Skip("truncated sentences (a field is missing or empty)")
    h, m, s = int(text[:2]), int(text[2:4]), _float(text[4:])
    if h > 23 or m > 59 or s >= 61:
        raise _Skip("sentences with an impossible time of day")
    return h * 3600 + m * 60 + s


def _coord(value: str, hemi: str, positive: str, negative: str) -> float:
    """Degrees of an NMEA ``(d)ddmm.mmmm`` field with its hemisphere letter."""
    if not value or hemi not in (positive, negative):
        raise _Skip("truncated sentences (a field is missing or empty)")
    dot = value.find(".")
    split = (dot if dot >= 0 else len(value)) - 2
    try:
        deg = float(value[:split]) + float(value[split:]) / 60.0
    except ValueError:
        raise _Skip("sentences with a field that is not a number") from None
    return -deg if hemi == negative else deg


def _float(value: str) -> float:
    if not value:
        raise _Skip("truncated sentences (a field is missing or empty)")
    try:
        return float(value)
    except ValueError:
        raise _Skip("sentences with a field that is not a number") from None


def _date(ddmmyy: str) -> dt.date:
    if len(ddmmyy) != 6 or not (ddmmyy.isascii() and ddmmyy.isdigit()):
        raise _Skip("truncated sentences (a field is missing or empty)")
    d, m, y = int(ddmmyy[:2]), int(ddmmyy[2:4]), int(ddmmyy[4:])
    try:
        return dt.date(1900 + y if y >= 80 else 2000 + y, m, d)
    except ValueError:
        raise _Skip("sentences with an impossible date") from None


class _Clock:
    """Turns times of day into POSIX seconds with the current date and day rollovers."""

    def __init__(self, date: dt.date | None):
        self.date = date
        self.last_tod: float | None = None
        self.rollovers = 0

    def at(self, tod: float, date: dt.date | None = None) -> float:
        if date is not None:
            self.date = date
        elif self.last_tod is not None and tod < self.last_tod - 43200.0 and self.date is not None:
            self.date = self.date + dt.timedelta(days=1)
            self.rollovers += 1
        if self.date is None:
            raise ConfigError(
                "nmea: the log has no RMC sentence to date its times: give date: YYYY-MM-DD in --config"
            )
        self.last_tod = tod
        midnight = dt.datetime(self.date.year, self.date.month, self.date.day, tzinfo=dt.timezone.utc)
        return midnight.timestamp() + tod


def read(sources: list[Path], settings: NmeaSettings, context: ImportContext) -> Imported:  # type: ignore[override]
    """Read NMEA logs (in time order) into GPS fixes and a heading."""
    import pynmea2

    if not sources:
        raise ConfigError("nmea: give one or more NMEA log files")
    imported = Imported()
    counts = imported.counts
    fixes: list[list] = []  # t, lat, lon, hdop (nan), kind, where
    headings: dict[str, list[tuple[float, float]]] = {"true": [], "magnetic": []}
    variation: list[float] = []
    deviation_seen = False
    for path in sources:
        data = read_bytes(path)
        first = _RMC_DATE.search(data)
        clock = _Clock(settings.date)
        if first is not None and clock.date is None:
            try:
                clock.date = _date(first.group(1).decode())
            except _Skip:
                pass
        used = 0
        for line_no, raw in enumerate(data.split(b"\n"), start=1):
            where = f"{path.name} line {line_no}"
            raw = raw.strip(b"\r\n\x00 \t")
            if not raw:
                continue
            try:
                try:
                    text = raw.decode("ascii")
                except UnicodeDecodeError:
                    raise _Skip("lines that are not text") from None
                start = min((i for i in (text.find("$"), text.find("!")) if i >= 0), default=-1)
                if start < 0:
                    raise _Skip("lines that are not NMEA sentences")
                logged = _logger_time(text[:start])
                text = text[start:]
                if text.startswith("!"):
                    raise _Skip("AIS sentences (!...)")
                if text[1:2] == "P":
                    raise _Skip("proprietary sentences ($P...)")
                try:
                    msg = pynmea2.parse(text, check=True)
                except pynmea2.ChecksumError:
                    raise _Skip("sentences with a wrong checksum") from None
                except pynmea2.SentenceTypeError:
                    raise _Skip(f"{text[3:6]} sentences (not used)") from None
                except pynmea2.ParseError:
                    raise _Skip("lines that are not NMEA sentences") from None
                kind = msg.sentence_type
                f = msg.data
                if kind == "GGA":
                    if len(f) < 8:
                        raise _Skip("truncated sentences (a field is missing or empty)")
                    tod = _tod(f[0])
                    quality = _float(f[5])
                    if quality == 0:
                        raise _Skip("GGA fixes with quality 0 (no fix)", invalid_fix=True)
                    lat, lon = _coord(f[1], f[2], "N", "S"), _coord(f[3], f[4], "E", "W")
                    hdop = _float(f[7]) if f[7] else math.nan
                    fixes.append([clock.at(tod), lat, lon, hdop, "GGA", where])
                elif kind == "RMC":
                    if len(f) < 9:
                        raise _Skip("truncated sentences (a field is missing or empty)")
                    tod, date = _tod(f[0]), _date(f[8])
                    if f[1] != "A":
                        clock.at(tod, date)
                        raise _Skip("RMC fixes with status V (void)", invalid_fix=True)
                    lat, lon = _coord(f[2], f[3], "N", "S"), _coord(f[4], f[5], "E", "W")
                    fixes.append([clock.at(tod, date), lat, lon, math.nan, "RMC", where])
                elif kind in ("HDT", "HDM", "HDG"):
                    heading = _float(f[0] if f else "")
                    if not 0.0 <= heading <= 360.0:
                        raise _Skip("heading sentences with a heading outside 0-360 degrees")
                    if logged is None:
                        raise _Skip(
                            "heading sentences without a logger time stamp (NMEA headings carry no time)"
                        )
                    if kind == "HDG":
                        if len(f) >= 3 and f[1] and _float(f[1]) != 0.0:
                            deviation_seen = True
                        if len(f) >= 5 and f[3] and f[4] in ("E", "W"):
                            variation.append(_float(f[3]) * (1.0 if f[4] == "E" else -1.0))
                    headings["true" if kind == "HDT" else "magnetic"].append((logged, heading))
                else:
                    raise _Skip(f"{kind} sentences (not used)")
                counts.read[f"{kind} sentences"] += 1
                used += 1
            except _Skip as skip:
                if settings.strict and not skip.invalid_fix:
                    raise FormatError(
                        path, f"{skip.reason}: refused with strict: true", line=line_no
                    ) from None
                counts.skip(skip.reason, where)
        if clock.rollovers:
            counts.read["day rollovers"] += clock.rollovers
        if used == 0:
            raise FormatError(path, "no usable GGA, RMC, HDT, HDG or HDM sentence in the file")
    if "gps" in settings.use and fixes:
        imported.streams["gps"] = _gps(fixes, counts, settings)
    heading_kind = "true" if headings["true"] else "magnetic"
    if headings["true"] and headings["magnetic"]:
        counts.skip("magnetic heading sentences (HDG/HDM) not used: the log has HDT", "-")
    if "attitude" in settings.use and headings[heading_kind]:
        _attitude(imported, headings[heading_kind], heading_kind, variation, deviation_seen, context)
    return imported


def _gps(fixes: list[list], counts: Counts, settings: NmeaSettings) -> GpsStream:
    kept: list[list] = []
    for fix in fixes:
        if kept and fix[0] == kept[-1][0]:
            if fix[4] == "GGA" and kept[-1][4] == "RMC":
                counts.skip("RMC fixes merged into the GGA fix of the same time", kept[-1][5])
                kept[-1] = fix
            else:
                counts.skip(f"{fix[4]} fixes repeating the time of the previous fix", fix[5])
            continue
        if kept and fix[0] < kept[-1][0]:
            counts.skip("fixes whose time goes back (receiver clock jump)", fix[5])
            continue
        kept.append(fix)
    a = np.array([k[:4] for k in kept], dtype=float)
    sigma = a[:, 3] * settings.uere_m  # NaN (no HDOP) is filled with the vehicle's
    counts.read["GPS fixes"] = len(a)
    return GpsStream(a[:, 0], np.radians(a[:, 1]), np.radians(a[:, 2]), sigma)


def _attitude(
    imported: Imported,
    rows: list[tuple[float, float]],
    kind: str,
    variation: list[float],
    deviation_seen: bool,
    context: ImportContext,
) -> None:
    a = np.asarray(rows, dtype=float)
    keep = np.zeros(len(a), dtype=bool)
    last = -math.inf
    for k, tk in enumerate(a[:, 0]):  # never reordered: a time at or before the last kept one is skipped
        if tk > last:
            keep[k], last = True, tk
        else:
            imported.counts.skip("heading sentences whose time is not after the previous one", f"t={tk:.3f}")
    a = a[keep]
    t, heading = a[:, 0], wrap_angle(a[:, 1] * DEG)
    base = context.base.attitude if context.base is not None else None
    if base is not None:
        pitch = np.interp(t, base.t_s, base.pitch_rad)
        roll = wrap_angle(np.interp(t, base.t_s, np.unwrap(base.roll_rad)))
        imported.notes.append(
            "pitch and roll from the base dive's attitude (interpolated at the heading times)"
        )
    else:
        pitch = roll = np.zeros(len(t))
        imported.notes.append(
            "NMEA has no pitch or roll: written as 0 (give --base DIVE to take them from a dive)"
        )
    imported.streams["attitude"] = AttitudeStream(t, heading, pitch, roll)
    imported.heading_reference = "true" if kind == "true" else "magnetic"
    if kind == "true":
        imported.heading_rule = "NMEA HDT is true heading"
    elif variation and np.ptp(variation) < 1e-9:
        imported.declination_rad = variation[0] * DEG
        imported.heading_rule = "NMEA HDG/HDM is magnetic; declination from HDG's variation field"
    else:
        imported.heading_rule = "NMEA HDG/HDM is magnetic; declination auto"
        if variation:
            imported.notes.append("HDG's variation field changes along the log: not used (declination auto)")
    if deviation_seen:
        imported.notes.append("HDG carries a deviation: not applied (auvnav fits its own, eq. 5)")
