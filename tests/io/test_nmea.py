"""The NMEA reader on an untidy log: every unusable line skipped and counted by kind, nothing reordered."""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
import pytest
from io_writers import nmea

from auvnav.io.common import ImportContext
from auvnav.io.nmea import NmeaSettings, read


def _gga(hms: str, lat: str = "1403.0000,S", hdop: str = "1.2", quality: str = "1") -> str:
    return nmea(f"GPGGA,{hms},{lat},12146.8000,E,{quality},08,{hdop},0.0,M,0.0,M,,")


def _read(tmp_path: Path, lines: list[str], **settings):
    log = tmp_path / "log.nmea"
    log.write_bytes(("\r\n".join(lines) + "\r\n").encode("latin-1"))
    return read([log], NmeaSettings(**settings), ImportContext(None, tmp_path, tmp_path))


def test_untidy_log_is_counted(tmp_path: Path) -> None:
    lines = [
        nmea("GPRMC,235958.000,A,1403.0000,S,12146.8000,E,0.5,45.0,141009,1.0,E"),
        _gga("235958.000"),
        _gga("235959.000")[:-2] + "FF",  # wrong checksum
        nmea("GPGGA,235959.500,1403.0000,S"),  # truncated
        _gga("235957.000"),  # the receiver clock jumped back
        _gga("235959.000", quality="0"),  # no fix
        nmea("GPRMC,235959.500,V,,,,,,,141009,,"),  # void
        "\xff\xfe garbage",
        nmea("PGRMZ,246,f,3"),
        "!AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0*26",
        nmea("GPVTG,45.0,T,,M,0.5,N,0.9,K"),
        _gga("000001.000"),  # after midnight: the next day, without an RMC
        "2009-10-15T00:00:01.500Z " + nmea("HEHDT,123.4,T"),
        nmea("HEHDT,124.0,T"),  # no logger time stamp: no time at all
        "2009-10-15T00:00:02.500Z " + nmea("HEHDT,370.0,T"),  # impossible
    ]
    imported = _read(tmp_path, lines)
    skipped = {k: v["count"] for k, v in imported.counts.summary()["skipped"].items()}
    assert skipped == {
        "RMC fixes merged into the GGA fix of the same time": 1,
        "sentences with a wrong checksum": 1,
        "truncated sentences (a field is missing or empty)": 1,
        "fixes whose time goes back (receiver clock jump)": 1,
        "GGA fixes with quality 0 (no fix)": 1,
        "RMC fixes with status V (void)": 1,
        "lines that are not text": 1,
        "proprietary sentences ($P...)": 1,
        "AIS sentences (!...)": 1,
        "VTG sentences (not used)": 1,
        "heading sentences without a logger time stamp (NMEA headings carry no time)": 1,
        "heading sentences with a heading outside 0-360 degrees": 1,
    }
    gps = imported.streams["gps"]
    midnight = dt.datetime(2009, 10, 15, tzinfo=dt.timezone.utc).timestamp()
    np.testing.assert_allclose(gps.t_s, [midnight - 2.0, midnight + 1.0])
    np.testing.assert_allclose(gps.sigma_m, [3.6, 3.6])  # HDOP 1.2 x 3 m
    assert math.degrees(gps.latitude_rad[0]) == pytest.approx(-14.05)
    assert imported.counts.read["day rollovers"] == 1
    att = imported.streams["attitude"]
    assert imported.heading_reference == "true" and math.degrees(att.heading_rad[0]) == pytest.approx(123.4)
    assert any("written as 0" in n for n in imported.notes)


def test_strict_refuses_what_the_default_counts(tmp_path: Path) -> None:
    from auvnav.io.common import FormatError

    lines = [
        nmea("GPRMC,010000.000,A,1403.0000,S,12146.8000,E,0.5,45.0,151009,1.0,E"),
        nmea("GPVTG,45.0,T,,M,0.5,N,0.9,K"),
    ]
    assert _read(tmp_path, lines).counts.skipped["VTG sentences (not used)"] == 1
    with pytest.raises(FormatError, match="line 2: VTG sentences \\(not used\\): refused with strict: true"):
        _read(tmp_path, lines, strict=True)


def test_gga_before_any_rmc_needs_a_date(tmp_path: Path) -> None:
    from auvnav.errors import ConfigError

    with pytest.raises(ConfigError, match="give date: YYYY-MM-DD"):
        _read(tmp_path, [_gga("010000.000")])
    imported = _read(tmp_path, [_gga("010000.000")], date="2009-10-15")
    assert imported.streams["gps"].t_s[0] == dt.datetime(2009, 10, 15, 1, tzinfo=dt.timezone.utc).timestamp()
