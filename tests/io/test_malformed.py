"""Malformed files of every format (issue 15): one line naming the file and the line or byte offset,
exit code 1, nothing written."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest
from io_writers import nmea, pack_ensemble

from auvnav.cli import main

T0 = dt.datetime(2009, 10, 15, 1, 0, tzinfo=dt.timezone.utc).timestamp()


def _fails(capsys, tmp_path: Path, args: list[str]) -> str:
    """Run ``auvnav import``; assert exit 1, one line, no output folder (nor a half-written one)."""
    out = tmp_path / "out" / "dive"
    capsys.readouterr()
    assert main(["import", *args, "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert not out.exists()
    assert not (out.parent.exists() and any(out.parent.iterdir())), list(out.parent.iterdir())
    return err[0]


# ---------------------------------------------------------------------------------------------
# ACFR
# ---------------------------------------------------------------------------------------------

GOOD_ACFR = [
    f"PHINS_COMPASS: {T0} r: 0.5 p: 1.0 h: 30.0 std_r: 0 std_p: 0 std_h: 0",
    f"RDI: {T0} alt:2.0 r1:0 r2:0 r3:0 r4:0 h:30 p:0 r:0 vx:0.5 vy:0 vz:0 nx:0 ny:0 nz:0 COG:0 SOG:0 "
    "bt_status:0 h_true:0 p_gimbal:0 sv: 1500",
    f"PAROSCI: {T0} 10.0",
]


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (f"RDI: {T0 + 1} alt:2.0 r1:0 r2:0 r3", "line 4: RDI line has no vx: field (truncated"),
        (f"PAROSCI: {T0 + 1} 10,5", "line 4: PAROSCI depth: not a number ('10,5')"),
        (f"OAS: {T0 + 1} 3.2", "line 4: unknown line type 'OAS'"),
        (f"GPS_RMC: {T0 + 1}\t Lat:91.5 N Lon:12 E Bad:0 A", "line 4: GPS_RMC: 91.5, 12.0 is not a latitude"),
    ],
    ids=["truncated", "not-a-number", "unknown-type", "impossible-value"],
)
def test_acfr(tmp_path: Path, capsys, bad: str, message: str) -> None:
    log = tmp_path / "combined.RAW.auv"
    log.write_text("\n".join([*GOOD_ACFR, bad]) + "\n", encoding="utf-8")
    err = _fails(capsys, tmp_path, ["acfr-raw", str(log)])
    assert err.startswith(f"auvnav: error: {log}: ") and message in err


def test_acfr_binary_names_the_byte(tmp_path: Path, capsys) -> None:
    log = tmp_path / "combined.RAW.auv"
    log.write_bytes(("\n".join(GOOD_ACFR) + "\n").encode() + b"RDI: \x00\x01")
    err = _fails(capsys, tmp_path, ["acfr-raw", str(log)])
    assert f"{log}: byte {len(chr(10).join(GOOD_ACFR)) + 1 + 5}: not a text file" in err


def test_acfr_skip_list_counts_instead(tmp_path: Path) -> None:
    from auvnav.io import import_dive

    lines = [*GOOD_ACFR, *(x.replace(str(T0), str(T0 + 0.2)) for x in GOOD_ACFR), f"OAS: {T0 + 1} 3.2"]
    log = tmp_path / "combined.RAW.auv"
    log.write_text("\n".join(lines) + "\n", encoding="utf-8")
    settings = tmp_path / "acfr.yaml"
    settings.write_text("skip: [OAS]\norigin: {latitude_deg: -14.05, longitude_deg: 121.78}\n")
    summary = import_dive("acfr-raw", [log], tmp_path / "dive", config=settings)
    assert summary["skipped"]["OAS lines (skipped by the settings)"] == {
        "count": 1,
        "first": "combined.RAW.auv line 7",
    }
    assert summary["declination_deg"] == "auto" and summary["origin"]["rule"] == "the settings file"


# ---------------------------------------------------------------------------------------------
# PD0
# ---------------------------------------------------------------------------------------------


def _pd0(n: int = 4) -> bytes:
    return b"".join(
        pack_ensemble(
            number=k + 1,
            t=T0 + 0.2 * k,
            v_frd_mps=(0.5, 0.0, 0.0),
            ranges_m=(2, 2, 2, 2),
            heading_deg=10,
            pitch_deg=0,
            roll_deg=0,
            sea_pressure_pa=1e5,
        )
        for k in range(n)
    )


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda d, n: d[: 3 * n - 10], f"byte {2 * 0}"),  # replaced below
        (lambda d, n: d[: n + 40] + bytes([d[n + 40] ^ 0xFF]) + d[n + 41 :], "checksum"),
        (lambda d, n: d[:n] + b"GARBAGE" + d[n:], "expected an ensemble header 7F 7F"),
    ],
    ids=["truncated", "checksum", "unknown-record"],
)
def test_pd0(tmp_path: Path, capsys, damage, message: str) -> None:
    data = _pd0()
    n = len(data) // 4
    path = tmp_path / "dvl.pd0"
    path.write_bytes(damage(data, n))
    err = _fails(capsys, tmp_path, ["pd0", str(path)])
    assert err.startswith(f"auvnav: error: {path}: byte ")
    if "checksum" in message:
        assert "ensemble 2: checksum" in err
    elif "header" in message:
        assert f"byte {n}: expected an ensemble header 7F 7F" in err
    else:
        assert f"byte {2 * n}: ensemble 3 is truncated" in err


# ---------------------------------------------------------------------------------------------
# NMEA (strict: every unusable line is an error; the default counts them, test_round_trip)
# ---------------------------------------------------------------------------------------------

GOOD_NMEA = [
    nmea("GPRMC,010000.000,A,1403.0000,S,12146.8000,E,0.5,45.0,151009,1.0,E"),
    nmea("GPGGA,010000.000,1403.0000,S,12146.8000,E,1,08,1.0,0.0,M,0.0,M,,"),
]


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (
            nmea("GPGGA,010001.000,1403.0000,S,12146.8000,E,1,08,1.0,0.0,M,0.0,M,,")[:-2] + "00",
            "wrong checksum",
        ),
        (nmea("GPGGA,010001.000,1403.0000,S"), "truncated sentences"),
        (nmea("GPXYZ,1,2,3"), "XYZ sentences (not used)"),
    ],
    ids=["checksum", "truncated", "unknown-type"],
)
def test_nmea_strict(tmp_path: Path, capsys, bad: str, message: str) -> None:
    log = tmp_path / "gps.nmea"
    log.write_text("\n".join([*GOOD_NMEA, bad]) + "\n", encoding="ascii")
    settings = tmp_path / "nmea.yaml"
    settings.write_text("strict: true\n")
    err = _fails(capsys, tmp_path, ["nmea", str(log), "--config", str(settings)])
    assert err.startswith(f"auvnav: error: {log}: line 3: ") and message in err


def test_nmea_without_any_usable_sentence(tmp_path: Path, capsys) -> None:
    log = tmp_path / "gps.nmea"
    log.write_bytes(b"\x00\xff\xfe binary\n" + nmea("GPGSV,1,1,00").encode() + b"\n")
    err = _fails(capsys, tmp_path, ["nmea", str(log)])
    assert f"{log}: no usable GGA, RMC, HDT, HDG or HDM sentence" in err


# ---------------------------------------------------------------------------------------------
# ROS bags
# ---------------------------------------------------------------------------------------------


def _small_bag(path: Path, version: int) -> None:
    from rosbags.typesys import Stores, get_typestore

    ros1 = version == 1
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import Writer

        writer = Writer(path, version=8)
    from rosbags.typesys import get_types_from_msg

    ts.register(get_types_from_msg("float64 x\nfloat64 y\n", "my_msgs/msg/Dvl"))
    with writer:
        c = writer.add_connection("/pressure", "sensor_msgs/msg/FluidPressure", typestore=ts)
        d = writer.add_connection("/vendor/dvl", "my_msgs/msg/Dvl", typestore=ts)
        for k in range(200):
            sec = int(T0) + k
            stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=0)
            header = T["std_msgs/msg/Header"](**({"seq": k} if ros1 else {}), stamp=stamp, frame_id="p")
            msg = T["sensor_msgs/msg/FluidPressure"](header=header, fluid_pressure=2e5, variance=0.0)
            ser = ts.serialize_ros1 if ros1 else ts.serialize_cdr
            writer.write(c, sec * 10**9, ser(msg, msg.__msgtype__))
            dvl = T["my_msgs/msg/Dvl"](x=0.5, y=0.0)
            writer.write(d, sec * 10**9, ser(dvl, dvl.__msgtype__))


def test_rosbag_truncated(tmp_path: Path, capsys) -> None:
    bag = tmp_path / "dive.bag"
    _small_bag(bag, 1)
    data = bag.read_bytes()
    bag.write_bytes(data[: len(data) // 2])
    err = _fails(capsys, tmp_path, ["rosbag", str(bag)])
    assert err.startswith(f"auvnav: error: {bag}: not a readable ROS bag")


def test_rosbag_unknown_message_type(tmp_path: Path, capsys) -> None:
    bag = tmp_path / "dive_bag"
    _small_bag(bag, 2)
    settings = tmp_path / "ros.yaml"
    settings.write_text("dvl_topic: /vendor/dvl\nheading_reference: true\n")
    err = _fails(capsys, tmp_path, ["rosbag", str(bag), "--config", str(settings)])
    assert "dvl_topic: topic /vendor/dvl carries my_msgs/msg/Dvl; dvl_topic needs one of" in err


# ---------------------------------------------------------------------------------------------
# CSV with a mapping
# ---------------------------------------------------------------------------------------------

MAPPING = """heading_reference: magnetic
origin: {latitude_deg: -14.05, longitude_deg: 121.78}
files:
  dvl.csv:
    time: {column: t, format: posix_s}
    dvl:
      vx: {column: vx, unit: mm/s}
      vy: {column: vy, unit: mm/s}
      vz: {value: 0, unit: m/s}
"""


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        (
            "t,vx,vy\n1255568400,500,0\n1255568400.2,500\n",
            "line 3: has 2 fields; the header has 3 (wrong field count)",
        ),
        ("t,vx,vy\n1255568400,500,0\n1255568400.2,5OO,0\n", "line 3: column vx: not a number ('5OO')"),
        ("t,vx,v_y\n1255568400,500,0\n", "line 1: no column 'vy' (the mapping's dvl.vy)"),
        ("t,vx,vy\n1255568400,500,0\n1255568400.2,500,0,", "line 3: has 4 fields"),
    ],
    ids=["field-count", "not-a-number", "unknown-column", "truncated"],
)
def test_csv(tmp_path: Path, capsys, rows: str, message: str) -> None:
    data = tmp_path / "dvl.csv"
    data.write_text(rows, encoding="utf-8")
    mapping = tmp_path / "map.yaml"
    mapping.write_text(MAPPING, encoding="utf-8")
    err = _fails(capsys, tmp_path, ["csv", str(data), "--config", str(mapping)])
    assert err.startswith(f"auvnav: error: {data}: ") and message in err


def test_csv_time_without_zone_is_not_guessed(tmp_path: Path, capsys) -> None:
    data = tmp_path / "dvl.csv"
    data.write_text("t,vx,vy\n2009-10-15T01:00:00,500,0\n", encoding="utf-8")
    mapping = tmp_path / "map.yaml"
    mapping.write_text(MAPPING.replace("format: posix_s", "format: iso8601"), encoding="utf-8")
    err = _fails(capsys, tmp_path, ["csv", str(data), "--config", str(mapping)])
    assert "line 2: column t: time '2009-10-15T01:00:00' has no zone" in err


def test_unknown_settings_key_is_one_line(tmp_path: Path, capsys) -> None:
    data = tmp_path / "dvl.csv"
    data.write_text("t,vx,vy\n1255568400,500,0\n", encoding="utf-8")
    mapping = tmp_path / "map.yaml"
    mapping.write_text(MAPPING + "colour: blue\n", encoding="utf-8")
    err = _fails(capsys, tmp_path, ["csv", str(data), "--config", str(mapping)])
    assert f"{mapping}: key colour: unknown key" in err
