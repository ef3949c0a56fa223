"""Independent writers of the formats auvnav imports, for round trips and bad-input tests.

Each writer takes a :class:`~auvnav.dive.Dive` and writes it in a vendor's format from that format's
own description (the PD0 manual's byte layouts, oplab_pipeline's ACFR line layouts, NMEA 0183,
ROS messages through ``rosbags``), sharing no code with auvnav's readers. A writer returns the
dive as the format holds it (quantised where the format is), for the round trip to compare with.
The import benchmark (``benchmarks/bench_import.py``) uses the same writers.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
import struct
from pathlib import Path

import numpy as np

from auvnav.depth.pressure import depth_from_pressure, sea_pressure
from auvnav.dive import AttitudeStream, Dive, DvlStream, PressureStream
from auvnav.frames import geodetic2ned
from auvnav.nav.inputs import declination

D = math.degrees


def f(x: float) -> str:
    """Shortest round-trip text of a number (a numpy scalar too)."""
    return repr(float(x))


def _utc(t: float) -> dt.datetime:
    return dt.datetime.fromtimestamp(t, dt.timezone.utc)


def _sea_pressure(dive: Dive) -> np.ndarray:
    p = dive.pressure
    return sea_pressure(
        p.pressure_pa, p.t_s, pressure_type=dive.info.pressure_type, atmospheric_pa=dive.info.atmospheric_pa
    )


# ---------------------------------------------------------------------------------------------
# ACFR combined.RAW.auv (layouts of oplab_pipeline's ACFR writer)
# ---------------------------------------------------------------------------------------------


def write_acfr(dive: Dive, folder: Path, *, extra_lines: list[tuple[float, str]] = ()) -> tuple[Path, Path]:
    """``folder/dRAWLOGS_cv/combined.RAW.auv`` and ``folder/mission.cfg``; full float precision."""
    folder.mkdir(parents=True, exist_ok=True)
    logs = folder / "dRAWLOGS_cv"
    logs.mkdir(exist_ok=True)
    lat0, lon0 = D(dive.info.origin.latitude_rad), D(dive.info.origin.longitude_rad)
    decl, _ = declination(dive)
    date = _utc(dive.info.start_time_s).strftime("%Y/%m/%d")
    cfg = folder / "mission.cfg"
    cfg.write_text(
        f'MAG_VAR_LAT {f(lat0)}\nMAG_VAR_LNG {f(lon0)}\nMAG_VAR_DATE "{date}"\nMAGNETIC_VAR_DEG {f(D(decl))}\n'
        "SOME_OTHER_KEY 12\n",
        encoding="utf-8",
    )
    rows: list[tuple[float, int, str]] = []
    a = dive.attitude
    for t, h, p, r in zip(a.t_s, a.heading_rad, a.pitch_rad, a.roll_rad, strict=True):
        rows.append(
            (t, 1, f"PHINS_COMPASS: {f(t)} r: {f(D(r))} p: {f(D(p))} h: {f(D(h))} std_r: 0 std_p: 0 std_h: 0")
        )
    v = dive.dvl
    h_at = np.degrees(np.interp(v.t_s, a.t_s, np.unwrap(a.heading_rad)))
    alt = v.altitude_m if v.altitude_m is not None else np.zeros(len(v))
    for k in range(len(v)):
        vx, vy, vz = (float(x) for x in v.v_sensor_mps[k])
        status = 0 if v.valid[k] else 32768
        rows.append(
            (
                v.t_s[k],
                0,
                f"RDI: {f(v.t_s[k])} alt:{f(alt[k])} r1:0 r2:0 r3:0 r4:0 h:{f(h_at[k])} p:0 r:0 vx:{f(vx)} vy:{f(vy)} "
                f"vz:{f(vz)} nx:0 ny:0 nz:0 COG:0 SOG:0 bt_status:{status} h_true:0 p_gimbal:0 sv: 1500",
            )
        )
    depth = depth_from_pressure(_sea_pressure(dive), dive.info.origin.latitude_rad)
    for t, d in zip(dive.pressure.t_s, depth, strict=True):
        rows.append((t, 2, f"PAROSCI: {f(t)} {f(float(d))}"))
    if dive.gps is not None:
        g = dive.gps
        for t, la, lo in zip(g.t_s, np.degrees(g.latitude_rad), np.degrees(g.longitude_rad), strict=True):
            rows.append(
                (
                    t,
                    3,
                    f"GPS_RMC: {f(t)}\t Lat:{f(abs(la))} {'N' if la >= 0 else 'S'} Lon:{f(abs(lo))} "
                    f"{'E' if lo >= 0 else 'W'} Bad:0 A Spd:0 Crs:0 Mg:nan",
                )
            )
    if dive.usbl is not None:
        u = dive.usbl
        ned = geodetic2ned(u.latitude_rad, u.longitude_rad, np.zeros(len(u)), dive.info.origin)
        for k in range(len(u)):
            rows.append(
                (
                    u.t_s[k],
                    4,
                    f"SSBL_FIX: {f(u.t_s[k])} ship_x: 0 ship_y: 0 target_x: {f(ned[k, 0])} target_y: {f(ned[k, 1])} "
                    f"target_z: {f(u.depth_m[k])} target_hr: 0 target_sr: 0 target_bearing: 0",
                )
            )
    if dive.images is not None:
        for k, t in enumerate(dive.images.t_s):
            stamp = _utc(t).strftime("%Y%m%d_%H%M%S")
            for side in ("LC16", "RM16"):
                rows.append((t, 5, f"VIS: {f(t)} [{f(t)}] PR_{stamp}_{k:06d}_{side}.tif exp: 0"))
    rows.extend((t, 6, text) for t, text in extra_lines)
    rows.sort(key=lambda r: (r[0], r[1]))
    raw = logs / "combined.RAW.auv"
    with open(raw, "w", encoding="utf-8") as fh:
        for _, _, text in rows:
            fh.write(text + "\n")
    return raw, cfg


def acfr_expected(dive: Dive) -> Dive:
    """What the ACFR log holds: the dive with sea pressure (from depth) and no magnetometer."""
    info = dataclasses.replace(dive.info, declination_rad=declination(dive)[0], pressure_type="sea")
    return dataclasses.replace(
        dive, info=info, pressure=PressureStream(dive.pressure.t_s, _sea_pressure(dive)), magnetometer=None
    )


# ---------------------------------------------------------------------------------------------
# RDI PD0 (WorkHorse Commands and Output Data Format, PD0 chapter; Explorer and Pathfinder manuals)
# ---------------------------------------------------------------------------------------------

#: (fixed leader bytes, variable leader bytes, bottom-track bytes) of each instrument family.
LAYOUTS = {"workhorse": (59, 65, 85), "explorer": (58, 60, 81), "pathfinder": (58, 77, 81)}
COORDS = {"beam": 0, "instrument": 1, "ship": 2, "earth": 3}


def rdi_matrix(h_deg: float, p_deg: float, r_deg: float) -> np.ndarray:
    """RDI's M(H, P, R) (ADCP Coordinate Transformation, P/N 951-6079-00), written out."""
    CH, SH = math.cos(math.radians(h_deg)), math.sin(math.radians(h_deg))
    CP, SP = math.cos(math.radians(p_deg)), math.sin(math.radians(p_deg))
    CR, SR = math.cos(math.radians(r_deg)), math.sin(math.radians(r_deg))
    return np.array(
        [
            [CH * CR + SH * SP * SR, SH * CP, CH * SR - SH * SP * CR],
            [-SH * CR + CH * SP * SR, CH * CP, -SH * SR - CH * SP * CR],
            [-CP * SR, SP, CP * CR],
        ]
    )


def pack_ensemble(
    *,
    number: int,
    t: float,
    v_frd_mps: tuple[float, float, float] | None,
    ranges_m: tuple[float, float, float, float],
    heading_deg: float,
    pitch_deg: float,
    roll_deg: float,
    sea_pressure_pa: float,
    layout: str = "workhorse",
    coords: str = "earth",
    ea_deg: float = 0.0,
    eb_deg: float = 0.0,
    beam_angle_deg: int = 30,
    bad_beam: int | None = None,
    profile_cells: int = 0,
    bottom_track: bool = True,
    tilts: bool = False,
) -> bytes:
    """One PD0 ensemble of a down-facing convex DVL, its checksum included."""
    fixed_len, var_len, bt_len = LAYOUTS[layout]
    # Fixed leader.
    fl = bytearray(fixed_len)
    struct.pack_into("<H", fl, 0, 0x0000)
    fl[2], fl[3] = 51, 40  # firmware
    angle_code = {15: 0, 20: 1, 30: 2}[beam_angle_deg]
    lsb = 0b100 | 0b1000  # 1200 kHz, convex; bit 7 clear: down-facing
    struct.pack_into("<H", fl, 4, lsb | ((0b0100 << 4 | angle_code) << 8))
    fl[8], fl[9] = 4, profile_cells
    fl[25] = (COORDS[coords] << 3) | (0b100 if tilts else 0) | 0b011  # tilts used?, 3-beam, bin mapping
    struct.pack_into("<h", fl, 26, round(ea_deg * 100))
    struct.pack_into("<h", fl, 28, round(eb_deg * 100))
    fl[30] = fl[31] = 0b0111101  # depth (pressure), heading, pitch, roll, temperature
    if fixed_len >= 59:
        fl[58] = beam_angle_deg
    # Variable leader.
    vl = bytearray(var_len)
    struct.pack_into("<H", vl, 0, 0x0080)
    struct.pack_into("<H", vl, 2, number & 0xFFFF)
    when = _utc(round(t, 2))
    hundredths = round((round(t, 2) - math.floor(round(t, 2))) * 100) % 100
    vl[4:11] = bytes([when.year % 100, when.month, when.day, when.hour, when.minute, when.second, hundredths])
    vl[11] = (number >> 16) & 0xFF
    struct.pack_into("<H", vl, 14, 1500)
    struct.pack_into("<H", vl, 18, round(heading_deg % 360.0 * 100) % 36000)
    struct.pack_into("<h", vl, 20, round(pitch_deg * 100))
    struct.pack_into("<h", vl, 22, round(roll_deg * 100))
    if var_len >= 52:
        struct.pack_into("<I", vl, 48, max(round(sea_pressure_pa / 10.0), 0))  # unsigned: 0 at the surface
    if var_len >= 65:
        vl[57:65] = bytes(
            [
                when.year // 100,
                when.year % 100,
                when.month,
                when.day,
                when.hour,
                when.minute,
                when.second,
                hundredths,
            ]
        )
    blocks = [bytes(fl), bytes(vl)]
    if profile_cells:
        blocks.append(struct.pack("<H", 0x0100) + bytes(8 * profile_cells))
    if bottom_track:
        bt = bytearray(bt_len)
        struct.pack_into("<H", bt, 0, 0x0600)
        cm = [round(r * 100) for r in ranges_m]
        struct.pack_into("<4H", bt, 16, *(c & 0xFFFF for c in cm))
        if bt_len >= 81:
            bt[77:81] = bytes((c >> 16) & 0xFF for c in cm)
        fields = velocity_fields(
            v_frd_mps, coords, ea_deg, heading_deg, pitch_deg, roll_deg, beam_angle_deg, bad_beam, tilts
        )
        struct.pack_into("<4h", bt, 24, *fields)
        blocks.append(bytes(bt))
    n_types = len(blocks)
    header_len = 6 + 2 * n_types
    offsets, pos = [], header_len
    for b in blocks:
        offsets.append(pos)
        pos += len(b)
    body = (
        struct.pack("<BBHBB", 0x7F, 0x7F, pos, 0, n_types)
        + struct.pack(f"<{n_types}H", *offsets)
        + b"".join(blocks)
    )
    return body + struct.pack("<H", sum(body) & 0xFFFF)


def velocity_fields(
    v_frd, coords, ea_deg, h_deg, p_deg, r_deg, beam_angle_deg, bad_beam, tilts=False
) -> list[int]:
    """The four bottom-track velocity fields (mm/s) of a vessel velocity in the DVL frame FRD."""
    if v_frd is None:
        return [-32768] * 4
    ship = np.array([v_frd[1], v_frd[0], -v_frd[2]])  # starboard, forward, up
    HF = rdi_matrix(ea_deg, 0.0, 180.0)  # down-facing: roll + 180 (instrument -> ship)
    inst = HF.T @ ship
    if coords == "ship":
        v = rdi_matrix(ea_deg, p_deg, r_deg + 180.0) @ inst if tilts else ship
    elif coords == "instrument":
        v = inst
    elif coords == "earth":
        v = rdi_matrix(h_deg + ea_deg, p_deg, r_deg + 180.0) @ inst
    else:
        a = 1.0 / (2.0 * math.sin(math.radians(beam_angle_deg)))
        b = 1.0 / (4.0 * math.cos(math.radians(beam_angle_deg)))
        z2 = inst[2] / (2.0 * b)
        beams = [
            (z2 + inst[0] / a) / 2,
            (z2 - inst[0] / a) / 2,
            (z2 - inst[1] / a) / 2,
            (z2 + inst[1] / a) / 2,
        ]
        out = [round(x * 1000) for x in beams]
        if bad_beam is not None:
            out[bad_beam] = -32768
        return out
    return [*(round(x * 1000) for x in v), 0]


def write_pd0(dive: Dive, path: Path, *, layout: str = "workhorse", coords: str = "ship") -> Dive:
    """The dive's DVL samples as PD0 ensembles (attitude and pressure in the leaders); returns the
    dive as PD0 holds it (time to 0.01 s, velocity to 1 mm/s, angles to 0.01 deg, pressure to 10 Pa)."""
    v = dive.dvl
    a = dive.attitude
    heading = np.degrees(np.interp(v.t_s, a.t_s, np.unwrap(a.heading_rad))) % 360.0
    pitch = np.degrees(np.interp(v.t_s, a.t_s, a.pitch_rad))
    roll = np.degrees(np.interp(v.t_s, a.t_s, np.unwrap(a.roll_rad)))
    sea = np.interp(v.t_s, dive.pressure.t_s, _sea_pressure(dive))
    alt = v.altitude_m if v.altitude_m is not None else np.zeros(len(v))
    with open(path, "wb") as fh:
        for k in range(len(v)):
            fh.write(
                pack_ensemble(
                    number=k + 1,
                    t=float(v.t_s[k]),
                    v_frd_mps=tuple(v.v_sensor_mps[k]) if v.valid[k] else None,
                    ranges_m=(alt[k],) * 4 if v.valid[k] else (0.0,) * 4,
                    heading_deg=heading[k],
                    pitch_deg=pitch[k],
                    roll_deg=roll[k],
                    sea_pressure_pa=sea[k],
                    layout=layout,
                    coords=coords,
                )
            )
    t = np.round(v.t_s, 2)
    q = np.round(v.v_sensor_mps * 1000.0) / 1000.0
    dvl = DvlStream(
        t, np.where(v.valid[:, None], q, 0.0), np.where(v.valid, np.round(alt * 100) / 100, 0.0), v.valid
    )
    att = AttitudeStream(
        t,
        np.radians((np.round(heading * 100) % 36000) / 100),
        np.radians(np.round(pitch * 100) / 100),
        np.radians(np.round(roll * 100) / 100),
    )
    pressure = PressureStream(t, np.maximum(np.round(sea / 10.0), 0.0) * 10.0)
    info = dataclasses.replace(dive.info, pressure_type="sea")
    return dataclasses.replace(dive, info=info, dvl=dvl, attitude=att, pressure=pressure, magnetometer=None)


# ---------------------------------------------------------------------------------------------
# NMEA 0183
# ---------------------------------------------------------------------------------------------


def nmea(body: str) -> str:
    """``$body*hh`` with its checksum (XOR of the characters between $ and *)."""
    c = 0
    for ch in body:
        c ^= ord(ch)
    return f"${body}*{c:02X}"


def _ddmm(value: float, width: int) -> str:
    deg = int(abs(value))
    minutes = (abs(value) - deg) * 60.0
    return f"{deg:0{width}d}{minutes:011.8f}"


def write_nmea(
    dive: Dive, path: Path, *, junk: bool = True, uere_m: float = 3.0, heading: str = "HDG"
) -> None:
    """GGA and RMC for each GPS fix, HDG (magnetic, with the declination as variation) or HDT (true)
    for each attitude sample with a logger time stamp, and (with ``junk``) the sentences real logs
    mix in: proprietary, AIS, GSV, an invalid fix."""
    lines: list[tuple[float, str]] = []
    g = dive.gps
    assert g is not None
    for k, (t, la, lo) in enumerate(
        zip(g.t_s, np.degrees(g.latitude_rad), np.degrees(g.longitude_rad), strict=True)
    ):
        when = _utc(t)
        hms = when.strftime("%H%M%S") + f".{when.microsecond // 1000:03d}"
        lat = f"{_ddmm(la, 2)},{'N' if la >= 0 else 'S'}"
        lon = f"{_ddmm(lo, 3)},{'E' if lo >= 0 else 'W'}"
        hdop = g.sigma_m[k] / uere_m
        lines.append((t, nmea(f"GPRMC,{hms},A,{lat},{lon},0.5,45.0,{when.strftime('%d%m%y')},1.0,E")))
        lines.append((t, nmea(f"GPGGA,{hms},{lat},{lon},1,08,{hdop:.6f},0.0,M,0.0,M,,")))
        if junk and k % 10 == 0:
            lines.append((t, nmea("PGRME,15.0,M,45.0,M,25.0,M")))
            lines.append((t, "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C"))
            lines.append((t, nmea("GPGSV,3,1,11,03,03,111,00,04,15,270,00,06,01,010,00,13,06,292,00")))
            lines.append((t, nmea(f"GPGGA,{hms},,,,,0,00,99.0,,M,,M,,")))
    a = dive.attitude
    decl = D(declination(dive)[0])
    var = f"{abs(decl):.9f},{'E' if decl >= 0 else 'W'}"
    for t, h in zip(a.t_s, np.degrees(a.heading_rad) % 360.0, strict=True):
        stamp = _utc(t).isoformat(timespec="microseconds").replace("+00:00", "Z")
        if heading == "HDG":  # the compass heading as logged (magnetic), the declination as variation
            lines.append((t, f"{stamp} " + nmea(f"HCHDG,{h:.9f},0.0,E,{var}")))
        else:  # true heading
            lines.append((t, f"{stamp} " + nmea(f"HEHDT,{(h + decl) % 360.0:.9f},T")))
    lines.sort(key=lambda r: r[0])
    path.write_text("\r\n".join(text for _, text in lines) + "\r\n", encoding="ascii")


# ---------------------------------------------------------------------------------------------
# Vendor CSVs
# ---------------------------------------------------------------------------------------------

GPS_EPOCH_S = dt.datetime(1980, 1, 6, tzinfo=dt.timezone.utc).timestamp()
LEAP_2009_S = 15  # GPS - UTC from 2009-01-01 to 2012-06-30


def write_csvs(dive: Dive, folder: Path) -> tuple[list[Path], Path]:
    """Three vendor-style CSVs (DVL in mm/s with POSIX ms; attitude in radians with ISO 8601 times
    and a semicolon; pressure in bar with GPS week and seconds) and their mapping file."""
    folder.mkdir(parents=True, exist_ok=True)
    v = dive.dvl
    with open(folder / "dvl_log.csv", "w", encoding="utf-8") as fh:
        fh.write("# exported by a vendor tool\ntime_ms,vel_fwd,vel_stbd,vel_down,range,lock\n")
        for k in range(len(v)):
            vx, vy, vz = (float(x) * 1000.0 for x in v.v_sensor_mps[k])
            alt = float(v.altitude_m[k]) if v.altitude_m is not None else 0.0
            fh.write(
                f"{round(v.t_s[k] * 1000)},{f(vx)},{f(vy)},{f(vz)},{f(alt)},{'yes' if v.valid[k] else 'no'}\n"
            )
    a = dive.attitude
    with open(folder / "ahrs.csv", "w", encoding="utf-8") as fh:
        fh.write("utc;yaw;pitch;roll\n")
        for t, h, p, r in zip(a.t_s, a.heading_rad, a.pitch_rad, a.roll_rad, strict=True):
            stamp = _utc(t).isoformat(timespec="microseconds").replace("+00:00", "Z")
            fh.write(f"{stamp};{f(float(h))};{f(D(p))};{f(D(r))}\n")
    p = dive.pressure
    with open(folder / "ctd.csv", "w", encoding="utf-8") as fh:
        fh.write("week,tow,p_bar\n")
        for t, pa in zip(p.t_s, p.pressure_pa, strict=True):
            gps = t - GPS_EPOCH_S + LEAP_2009_S
            week = int(gps // 604800)
            fh.write(f"{week},{f(gps - week * 604800.0)},{f(float(pa) / 1e5)}\n")
    mapping = folder / "mapping.yaml"
    mapping.write_text(
        f"""heading_reference: {dive.info.heading_reference}
declination_deg: {f(D(declination(dive)[0]))}
pressure: {{type: {dive.info.pressure_type}, atmospheric_dbar: {f(dive.info.atmospheric_pa / 1e4)}}}
origin: {{latitude_deg: {f(D(dive.info.origin.latitude_rad))}, longitude_deg: {f(D(dive.info.origin.longitude_rad))}}}
files:
  dvl_log.csv:
    comment: "#"
    time: {{column: time_ms, format: posix_ms}}
    dvl:
      vx: {{column: vel_fwd, unit: mm/s}}
      vy: {{column: vel_stbd, unit: mm/s}}
      vz: {{column: vel_down, unit: mm/s}}
      altitude: {{column: range, unit: m}}
      valid: {{column: lock}}
  ahrs.csv:
    delimiter: ";"
    time: {{column: utc, format: iso8601}}
    attitude:
      heading: {{column: yaw, unit: rad}}
      pitch: {{column: pitch, unit: deg}}
      roll: {{column: roll, unit: deg}}
  ctd.csv:
    time: {{columns: [week, tow], format: gps_week}}
    pressure:
      pressure: {{column: p_bar, unit: bar}}
""",
        encoding="utf-8",
    )
    return [folder / "dvl_log.csv", folder / "ahrs.csv", folder / "ctd.csv"], mapping


# ---------------------------------------------------------------------------------------------
# ROS bags (rosbags writes them)
# ---------------------------------------------------------------------------------------------


def write_bag(
    dive: Dive,
    path: Path,
    *,
    version: int = 2,
    images: int = 4,
    image_bytes: bytes | None = None,
    altitude: bool = True,
    raw: tuple[str, str] | None = None,
) -> None:
    """The dive's streams as ROS messages (REP-103 frames: ENU world, FLU body): DVL twist, Imu,
    FluidPressure (absolute), NavSatFix, Range (altitude) and the first ``images`` stereo pairs as
    CompressedImage, or, with ``raw`` (the left and right encodings, 16-bit: ``mono16``,
    ``bayer_rggb16``), as Image holding :func:`raw_image` of the pair's number."""
    from rosbags.typesys import Stores, get_typestore

    from auvnav.frames import euler2rot, rot2quat_wxyz

    ros1 = version == 1
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]

    def header(t: float, frame: str):
        sec = math.floor(t)
        nsec = round((t - sec) * 1e9)
        if nsec >= 1_000_000_000:
            sec, nsec = sec + 1, nsec - 1_000_000_000
        stamp = Time(sec=sec, nanosec=nsec)
        return Header(seq=0, stamp=stamp, frame_id=frame) if ros1 else Header(stamp=stamp, frame_id=frame)

    flu = np.diag([1.0, -1.0, -1.0])
    enu_ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    msgs: list[tuple[float, str, object]] = []
    v = dive.dvl
    for k in range(len(v)):
        lin = flu @ v.v_sensor_mps[k] if v.valid[k] else np.full(3, np.nan)
        cov = np.zeros(36)
        twist = T["geometry_msgs/msg/Twist"](
            linear=V3(x=lin[0], y=lin[1], z=lin[2]), angular=V3(x=0.0, y=0.0, z=0.0)
        )
        msgs.append(
            (
                v.t_s[k],
                "/dvl/twist",
                T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                    header=header(v.t_s[k], "dvl"),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov),
                ),
            )
        )
        if altitude and v.altitude_m is not None and v.valid[k]:
            msgs.append(
                (
                    v.t_s[k],
                    "/dvl/altitude",
                    T["sensor_msgs/msg/Range"](
                        header=header(v.t_s[k], "dvl"),
                        radiation_type=0,
                        field_of_view=0.1,
                        min_range=0.5,
                        max_range=30.0,
                        range=float(v.altitude_m[k]),
                    ),
                )
            )
    a = dive.attitude
    R = enu_ned.T @ euler2rot(a.heading_rad, a.pitch_rad, a.roll_rad) @ flu
    q = rot2quat_wxyz(R)
    zero9 = np.zeros(9)
    for k in range(len(a)):
        msgs.append(
            (
                a.t_s[k],
                "/imu/data",
                T["sensor_msgs/msg/Imu"](
                    header=header(a.t_s[k], "base_link"),
                    orientation=Q(x=q[k, 1], y=q[k, 2], z=q[k, 3], w=q[k, 0]),
                    orientation_covariance=zero9,
                    angular_velocity=V3(x=0.0, y=0.0, z=0.0),
                    angular_velocity_covariance=zero9,
                    linear_acceleration=V3(x=0.0, y=0.0, z=0.0),
                    linear_acceleration_covariance=zero9,
                ),
            )
        )
    p = dive.pressure
    absolute = (
        p.pressure_pa if dive.info.pressure_type == "absolute" else p.pressure_pa + dive.info.atmospheric_pa
    )
    for t, pa in zip(p.t_s, absolute, strict=True):
        msgs.append(
            (
                t,
                "/pressure",
                T["sensor_msgs/msg/FluidPressure"](
                    header=header(t, "pressure"), fluid_pressure=float(pa), variance=0.0
                ),
            )
        )
    if dive.gps is not None:
        g = dive.gps
        for k in range(len(g)):
            cov = np.zeros(9)
            cov[0] = cov[4] = g.sigma_m[k] ** 2
            cov[8] = 100.0
            msgs.append(
                (
                    g.t_s[k],
                    "/gps/fix",
                    T["sensor_msgs/msg/NavSatFix"](
                        header=header(g.t_s[k], "gps"),
                        status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                        latitude=math.degrees(g.latitude_rad[k]),
                        longitude=math.degrees(g.longitude_rad[k]),
                        altitude=0.0,
                        position_covariance=cov,
                        position_covariance_type=2,
                    ),
                )
            )
    if dive.images is not None and images and raw is not None:
        for k, t in enumerate(dive.images.t_s[:images]):
            for side, encoding in zip(("left", "right"), raw, strict=True):
                pixels = raw_image(k)
                msgs.append(
                    (
                        t,
                        f"/stereo/{side}/image_raw",
                        T["sensor_msgs/msg/Image"](
                            header=header(t, "camera"),
                            height=pixels.shape[0],
                            width=pixels.shape[1],
                            encoding=encoding,
                            is_bigendian=0,
                            step=2 * pixels.shape[1],
                            data=np.frombuffer(pixels.astype("<u2").tobytes(), dtype=np.uint8),
                        ),
                    )
                )
    elif dive.images is not None and images:
        data = np.frombuffer(image_bytes or b"\xff\xd8\xff\xe0fake-jpeg\xff\xd9", dtype=np.uint8)
        for t in dive.images.t_s[:images]:
            for topic in ("/stereo/left/image_raw/compressed", "/stereo/right/image_raw/compressed"):
                msgs.append(
                    (
                        t,
                        topic,
                        T["sensor_msgs/msg/CompressedImage"](
                            header=header(t, "camera"), format="jpeg", data=data
                        ),
                    )
                )
    msgs.sort(key=lambda m: m[0])
    _write_messages(path, msgs, ts, ros1)


def raw_image(k: int) -> np.ndarray:
    """A 12-bit test picture the size of the default rig's images (uint16), different for each ``k``."""
    return (np.random.default_rng(k).random((1024, 1360)) * 4095).astype(np.uint16)


def _write_messages(path: Path, msgs: list, ts, ros1: bool) -> None:
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import Writer

        writer = Writer(path, version=8)
    conns: dict[str, object] = {}
    with writer:
        for t, topic, msg in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
            data = ts.serialize_ros1(msg, msg.__msgtype__) if ros1 else ts.serialize_cdr(msg, msg.__msgtype__)
            writer.write(conns[topic], round(t * 1e9), data)
