"""ACFR logs: ``combined.RAW.auv`` with its ``mission.cfg`` in, ``stereo_pose_est.data`` out.

``combined.RAW.auv`` is the text log of the ACFR's AUVs (Sirius, the paper's vehicle): one line per
sensor record, the record type first, then the POSIX time, then fields. The layouts read here are
those oplab_pipeline writes and reads (ocean-perception/oplab_pipeline, ``auv_nav``'s ACFR
converter and parser, whose README gives an example of each line):

- ``RDI: t alt:A r1:.. r2:.. r3:.. r4:.. h:H p:P r:R vx:VX vy:VY vz:VZ ... bt_status:S ... sv: C`` —
  DVL bottom-track velocity (m/s) in the DVL frame as mounted (forward, starboard, down), altitude
  (m), and the DVL's attitude; ``bt_status`` 0 is a good bottom track (RDI PD5's status byte: any
  bit set is an error), so the sample is marked invalid otherwise;
- ``PHINS_COMPASS: t r: R p: P h: H std_r: .. std_p: .. std_h: ..`` — roll, pitch, heading, degrees;
  ``TCM: t`` lines are read with the same keys (``h``/``p``/``r``, or ``heading``/``pitch``/``roll``);
- ``PAROSCI: t D`` — depth, metres (as oplab_pipeline writes and reads it); converted to sea
  pressure by TEOS-10 at the origin's latitude;
- ``VIS: t [t] NAME exp: E`` — one line per camera image; the left and right images of a pair share
  their time and are told apart by their names (``left_pattern``/``right_pattern``, regular
  expressions; default ``LC`` and ``RM``, Sirius's names: a left colour camera that writes its
  sensor's raw mosaic, which vehicle.yaml's ``stereo.left_bayer`` names, and a right monochrome one);
- ``SSBL_FIX: t ship_x: .. ship_y: .. target_x: N target_y: E target_z: D ...`` — the vehicle's
  USBL position, metres north and east of the origin and depth;
- ``GPS_RMC: t Lat:L N Lon:L E Bad:0 A Spd:.. Crs:.. Mg:..`` — a GPS fix, degrees with hemisphere
  letters; status ``A`` (``V`` fixes are skipped and counted).

``mission.cfg`` holds ``KEY value`` lines; read are ``MAG_VAR_LAT``, ``MAG_VAR_LNG`` (the site,
used as the origin unless ``ORIGIN_LATITUDE``/``ORIGIN_LONGITUDE`` are given), ``MAG_VAR_DATE`` and
``MAGNETIC_VAR_DEG`` (the declination ACFR's processing adds to the compass: the dive's declination).
Other keys are ignored.

Blank lines and lines starting with ``%`` or ``#`` are comments. A line of an unknown type is an
error unless ``skip`` lists its type (then it is counted); a line that lacks a field its type needs
(a truncated line) or has a field that is not a number is an error naming its line. Records whose
time is not after the previous one of their type are skipped and counted, never reordered.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import re
import shutil
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field as PydanticField

from auvnav.config import quote
from auvnav.dive import AttitudeStream, DvlStream, GpsStream, UsblStream
from auvnav.errors import ConfigError, InsufficientDataError
from auvnav.frames import GeodeticOrigin, ned2geodetic, rot2euler
from auvnav.io.common import (
    Counts,
    FormatError,
    ImportContext,
    Imported,
    ImportSettings,
    fixes_from_ned,
    images_index,
    number,
    read_bytes,
    strictly_increasing,
    text_lines,
)
from auvnav.streams import atomic_write

DEG = math.pi / 180.0
KNOWN = ("RDI", "PHINS_COMPASS", "TCM", "PAROSCI", "VIS", "SSBL_FIX", "GPS_RMC")
Compass = Literal["PHINS_COMPASS", "TCM", "RDI"]


class AcfrSettings(ImportSettings):
    """Settings of the ``acfr-raw`` importer (besides :class:`ImportSettings`).

    Parameters
    ----------
    compass : {"PHINS_COMPASS", "TCM", "RDI"}
        The lines the attitude comes from (default: the one compass type the log has).
    left_pattern, right_pattern : str
        Regular expressions that tell a ``VIS`` image's camera from its name.
    images_dir : str
        A folder holding the image files the ``VIS`` lines name (relative to the settings file);
        they are linked into the dive's ``images/``.
    skip : list of str
        Line types to skip and count (e.g. ``[OAS, EVO]``).
    """

    compass: Compass | None = None
    left_pattern: str = "LC"
    right_pattern: str = "RM"
    images_dir: str | None = None
    skip: list[str] = PydanticField(default_factory=list)


SETTINGS = AcfrSettings


# ---------------------------------------------------------------------------------------------
# mission.cfg
# ---------------------------------------------------------------------------------------------


def read_mission_cfg(path: Path) -> dict[str, Any]:
    """The keys of ``mission.cfg`` this importer uses (numbers, and ``MAG_VAR_DATE`` as a date)."""
    data = read_bytes(path)
    out: dict[str, Any] = {}
    wanted = ("MAG_VAR_LAT", "MAG_VAR_LNG", "MAGNETIC_VAR_DEG", "ORIGIN_LATITUDE", "ORIGIN_LONGITUDE")
    for line_no, _, line in text_lines(path, data):
        parts = line.split()
        if not parts or parts[0].startswith((b"%", b"#")):
            continue
        key = parts[0].decode("ascii", "replace")
        if key in wanted or key == "MAG_VAR_DATE":
            if len(parts) < 2:
                raise FormatError(path, f"{key} has no value", line=line_no)
            if key == "MAG_VAR_DATE":
                text = parts[1].decode("ascii", "replace").strip('"')
                try:
                    out[key] = dt.datetime.strptime(text, "%Y/%m/%d").replace(tzinfo=dt.timezone.utc)
                except ValueError:
                    raise FormatError(
                        path, f"MAG_VAR_DATE: not a date YYYY/MM/DD ({quote(text)})", line=line_no
                    ) from None
            else:
                out[key] = number(parts[1], path, line_no, key)
    return out


def _cfg_origin(cfg: dict[str, Any], path: Path) -> GeodeticOrigin | None:
    for lat_key, lon_key in (("ORIGIN_LATITUDE", "ORIGIN_LONGITUDE"), ("MAG_VAR_LAT", "MAG_VAR_LNG")):
        if lat_key in cfg and lon_key in cfg:
            lat, lon = cfg[lat_key], cfg[lon_key]
            if not (-90 <= lat <= 90 and -180 <= lon <= 360):
                raise FormatError(path, f"{lat_key}/{lon_key} = {lat}, {lon}: not a latitude and longitude")
            return GeodeticOrigin.from_degrees(lat, lon)
    return None


def _find_cfg(sources: list[Path]) -> tuple[list[Path], Path | None]:
    logs = [p for p in sources if p.suffix.lower() != ".cfg"]
    cfgs = [p for p in sources if p.suffix.lower() == ".cfg"]
    if len(cfgs) > 1:
        raise ConfigError(f"acfr-raw: one mission.cfg, please; given {', '.join(map(str, cfgs))}")
    if cfgs:
        return logs, cfgs[0]
    if logs:
        for folder in (logs[0].parent, logs[0].parent.parent):
            if (folder / "mission.cfg").is_file():
                return logs, folder / "mission.cfg"
    return logs, None


# ---------------------------------------------------------------------------------------------
# combined.RAW.auv
# ---------------------------------------------------------------------------------------------


def _pairs(tokens: list[bytes]) -> dict[bytes, bytes]:
    """``key:value`` and ``key: value`` tokens as a mapping (bare tokens are left out)."""
    out: dict[bytes, bytes] = {}
    key = None
    for tok in tokens:
        if key is not None:
            out[key] = tok
            key = None
            continue
        k, sep, v = tok.partition(b":")
        if not sep:
            continue
        if v:
            out[k] = v
        else:
            key = k
    return out


class _Log:
    """Records of one log, in file order, with the line each came from."""

    def __init__(self) -> None:
        self.rdi: list[tuple[float, ...]] = []
        self.compass: dict[str, list[tuple[float, ...]]] = {"PHINS_COMPASS": [], "TCM": []}
        self.depth: list[tuple[float, float]] = []
        self.vis: list[tuple[float, str]] = []
        self.usbl: list[tuple[float, float, float, float]] = []
        self.gps: list[tuple[float, float, float]] = []
        self.where: dict[str, list[str]] = {
            k: [] for k in ("rdi", "PHINS_COMPASS", "TCM", "depth", "vis", "usbl", "gps")
        }


def _field(kv: dict[bytes, bytes], keys: tuple[bytes, ...], path: Path, line: int, kind: str) -> float:
    for k in keys:
        if k in kv:
            return number(kv[k], path, line, f"{kind} {k.decode()}")
    raise FormatError(
        path, f"{kind} line has no {keys[0].decode()}: field (truncated, or not the ACFR layout)", line=line
    )


def _gps_fix(tokens: list[bytes], path: Path, line: int) -> tuple[float, float, bool]:
    """Latitude, longitude (degrees, signed) and status of a ``GPS_RMC`` line."""
    values: dict[str, float] = {}
    status = True
    for k, tok in enumerate(tokens):
        for key, hemispheres in (("Lat", (b"N", b"S")), ("Lon", (b"E", b"W"))):
            if tok.startswith(key.encode() + b":"):
                text = tok[len(key) + 1 :]
                nxt = k + 1
                if not text:
                    if nxt >= len(tokens):
                        raise FormatError(path, f"GPS_RMC {key}: has no value (truncated)", line=line)
                    text, nxt = tokens[nxt], nxt + 1
                value = number(text, path, line, f"GPS_RMC {key}")
                if nxt < len(tokens) and tokens[nxt] in hemispheres:
                    value = abs(value) * (-1.0 if tokens[nxt] == hemispheres[1] else 1.0)
                values[key] = value
        if tok == b"V":
            status = False
    for key in ("Lat", "Lon"):
        if key not in values:
            raise FormatError(
                path, f"GPS_RMC line has no {key}: field (truncated, or not the ACFR layout)", line=line
            )
    if not (-90 <= values["Lat"] <= 90 and -180 <= values["Lon"] <= 360):
        raise FormatError(
            path, f"GPS_RMC: {values['Lat']}, {values['Lon']} is not a latitude and longitude", line=line
        )
    return values["Lat"], values["Lon"], status


def parse_log(path: Path, log: _Log, counts: Counts, skip: set[str]) -> None:
    """Read one ``combined.RAW.auv`` into ``log``."""
    data = read_bytes(path)
    name = path.name
    for line_no, _, line in text_lines(path, data):
        tokens = line.split()
        if not tokens or tokens[0][:1] in (b"%", b"#"):
            continue
        head = tokens[0]
        kind = (
            head[:-1].decode("ascii", "replace") if head.endswith(b":") else head.decode("ascii", "replace")
        )
        where = f"{name} line {line_no}"
        if kind not in KNOWN:
            if kind in skip:
                counts.skip(f"{kind} lines (skipped by the settings)", where)
                continue
            raise FormatError(
                path,
                f"unknown line type {quote(kind)} (known: {', '.join(KNOWN)}; list it under skip: in --config "
                "to skip such lines)",
                line=line_no,
            )
        if len(tokens) < 2:
            raise FormatError(path, f"{kind} line has no time (truncated)", line=line_no)
        t = number(tokens[1], path, line_no, f"{kind} time")
        counts.read[f"{kind} lines"] += 1
        if kind == "RDI":
            kv = _pairs(tokens[2:])
            vx = _field(kv, (b"vx",), path, line_no, kind)
            vy = _field(kv, (b"vy",), path, line_no, kind)
            vz = _field(kv, (b"vz",), path, line_no, kind)
            alt = _field(kv, (b"alt",), path, line_no, kind)
            status = _field(kv, (b"bt_status",), path, line_no, kind) if b"bt_status" in kv else 0.0
            h = _field(kv, (b"h",), path, line_no, kind) if b"h" in kv else math.nan
            p = _field(kv, (b"p",), path, line_no, kind) if b"p" in kv else math.nan
            r = _field(kv, (b"r",), path, line_no, kind) if b"r" in kv else math.nan
            log.rdi.append((t, vx, vy, vz, alt, status, h, p, r))
            log.where["rdi"].append(where)
        elif kind in ("PHINS_COMPASS", "TCM"):
            kv = _pairs(tokens[2:])
            h = _field(kv, (b"h", b"heading"), path, line_no, kind)
            p = _field(kv, (b"p", b"pitch"), path, line_no, kind)
            r = _field(kv, (b"r", b"roll"), path, line_no, kind)
            log.compass[kind].append((t, h, p, r))
            log.where[kind].append(where)
        elif kind == "PAROSCI":
            if len(tokens) < 3:
                raise FormatError(path, "PAROSCI line has no depth (truncated)", line=line_no)
            log.depth.append((t, number(tokens[2], path, line_no, "PAROSCI depth")))
            log.where["depth"].append(where)
        elif kind == "VIS":
            names = [tok for tok in tokens[2:] if not tok.startswith(b"[") and b":" not in tok]
            if not names:
                raise FormatError(path, "VIS line has no image name (truncated)", line=line_no)
            log.vis.append((t, names[0].decode("utf-8", "replace")))
            log.where["vis"].append(where)
        elif kind == "SSBL_FIX":
            kv = _pairs(tokens[2:])
            n = _field(kv, (b"target_x",), path, line_no, kind)
            e = _field(kv, (b"target_y",), path, line_no, kind)
            d = _field(kv, (b"target_z",), path, line_no, kind)
            log.usbl.append((t, n, e, d))
            log.where["usbl"].append(where)
        elif kind == "GPS_RMC":
            lat, lon, ok = _gps_fix(tokens[2:], path, line_no)
            if not ok:
                counts.skip("GPS_RMC fixes with status V (no fix)", where)
                continue
            log.gps.append((t, lat, lon))
            log.where["gps"].append(where)


def _array(rows: list[tuple[float, ...]], width: int) -> np.ndarray:
    return np.asarray(rows, dtype=float).reshape(-1, width)


def _ordered(a: np.ndarray, where: list[str], counts: Counts, what: str) -> tuple[np.ndarray, list[str]]:
    keep = strictly_increasing(a[:, 0], counts, what, where)
    return a[keep], [w for w, k in zip(where, keep, strict=True) if k]


def read(sources: list[Path], settings: AcfrSettings, context: ImportContext) -> Imported:  # type: ignore[override]
    """Read ``combined.RAW.auv`` files (in time order) and their ``mission.cfg``."""
    logs, cfg_path = _find_cfg(sources)
    if not logs:
        raise ConfigError("acfr-raw: give a combined.RAW.auv file (and its mission.cfg)")
    imported = Imported()
    counts = imported.counts
    cfg = read_mission_cfg(cfg_path) if cfg_path is not None else {}
    if cfg_path is None:
        imported.notes.append("no mission.cfg beside the log: no origin or declination from it")
    else:
        imported.origin = _cfg_origin(cfg, cfg_path)
        imported.origin_rule = f"{cfg_path.name} (site of the magnetic variation)" if imported.origin else ""
    log = _Log()
    skip = set(settings.skip)
    for path in logs:
        parse_log(path, log, counts, skip)

    origin = (
        GeodeticOrigin.from_degrees(settings.origin.latitude_deg, settings.origin.longitude_deg)
        if settings.origin is not None
        else imported.origin or (context.base.info.origin if context.base is not None else None)
    )

    # DVL.
    if log.rdi:
        rdi, _where = _ordered(_array(log.rdi, 9), log.where["rdi"], counts, "RDI")
        valid = rdi[:, 5] == 0
        imported.streams["dvl"] = DvlStream(
            t_s=rdi[:, 0],
            v_sensor_mps=np.where(valid[:, None], rdi[:, 1:4], 0.0),
            altitude_m=np.where(rdi[:, 4] > 0, rdi[:, 4], 0.0),
            valid=valid,
        )
    # Attitude.
    present = [k for k in ("PHINS_COMPASS", "TCM") if log.compass[k]]
    compass = settings.compass
    if compass is None:
        if len(present) > 1:
            raise ConfigError(
                "acfr-raw: the log has both PHINS_COMPASS and TCM lines: choose one with compass: in --config"
            )
        compass = present[0] if present else ("RDI" if log.rdi else None)  # type: ignore[assignment]
        if compass == "RDI":
            imported.notes.append("no PHINS_COMPASS or TCM lines: the attitude is the RDI lines' h, p, r")
    if compass in ("PHINS_COMPASS", "TCM"):
        if not log.compass[compass]:
            raise InsufficientDataError(f"acfr-raw: compass: {compass}, but the log has no {compass} lines")
        att, _ = _ordered(_array(log.compass[compass], 4), log.where[compass], counts, compass)
        imported.streams["attitude"] = AttitudeStream(
            att[:, 0], att[:, 1] * DEG, att[:, 2] * DEG, att[:, 3] * DEG
        )
    elif compass == "RDI" and "dvl" in imported.streams:
        rdi, _ = _ordered(_array(log.rdi, 9), log.where["rdi"], Counts(), "RDI")
        ok = np.all(np.isfinite(rdi[:, 6:9]), axis=1)
        if ok.sum() >= 2:
            imported.streams["attitude"] = AttitudeStream(
                rdi[ok, 0], rdi[ok, 6] * DEG, rdi[ok, 7] * DEG, rdi[ok, 8] * DEG
            )
    decl = cfg.get("MAGNETIC_VAR_DEG")
    imported.heading_reference = "magnetic"
    if decl is not None:
        imported.declination_rad = math.radians(decl)
        imported.heading_rule = f"ACFR compass is magnetic; declination MAGNETIC_VAR_DEG of {cfg_path.name}"  # type: ignore[union-attr]
    else:
        imported.heading_rule = (
            "ACFR compass is magnetic; no MAGNETIC_VAR_DEG in mission.cfg: declination auto"
        )
    # Depth.
    if log.depth:
        depth, _ = _ordered(_array(log.depth, 2), log.where["depth"], counts, "PAROSCI")
        imported.depth = (depth[:, 0], depth[:, 1])
    # USBL and GPS.
    if log.usbl:
        if origin is None:
            raise ConfigError(
                "acfr-raw: SSBL_FIX positions are metres from the origin and no origin is known: give "
                "origin: in --config, or a mission.cfg with MAG_VAR_LAT/MAG_VAR_LNG"
            )
        usbl, _ = _ordered(_array(log.usbl, 4), log.where["usbl"], counts, "SSBL_FIX")
        lat, lon = fixes_from_ned(usbl[:, 0], usbl[:, 1:3], origin)
        imported.streams["usbl"] = UsblStream(usbl[:, 0], lat, lon, usbl[:, 3], np.full(len(usbl), np.nan))
    if log.gps:
        gps, _ = _ordered(_array(log.gps, 3), log.where["gps"], counts, "GPS_RMC")
        imported.streams["gps"] = GpsStream(
            gps[:, 0], gps[:, 1] * DEG, gps[:, 2] * DEG, np.full(len(gps), np.nan)
        )
    # Images.
    if log.vis:
        _images(log, settings, context, imported)
    return imported


def _images(log: _Log, settings: AcfrSettings, context: ImportContext, imported: Imported) -> None:
    counts = imported.counts
    left_re, right_re = re.compile(settings.left_pattern), re.compile(settings.right_pattern)
    pending: dict[float, dict[str, str]] = {}
    order: list[float] = []
    for (t, name), where in zip(log.vis, log.where["vis"], strict=True):
        side = "left" if left_re.search(name) else "right" if right_re.search(name) else None
        if side is None:
            counts.skip(
                f"VIS images whose names match neither {settings.left_pattern!r} nor {settings.right_pattern!r}",
                where,
            )
            continue
        if t not in pending:
            pending[t] = {}
            order.append(t)
        pending[t][side] = name
    t_s, left, right = [], [], []
    last = -math.inf
    for t in order:
        pair = pending[t]
        if set(pair) != {"left", "right"}:
            counts.skip("VIS images without their stereo partner at the same time", f"t={t}")
            continue
        if t <= last:
            counts.skip("VIS pairs whose time is not after the previous pair", f"t={t}")
            continue
        last = t
        t_s.append(t)
        left.append(pair["left"])
        right.append(pair["right"])
    index = images_index(t_s, left, right)
    if index is None:
        return
    imported.streams["images"] = index
    if settings.images_dir is None:
        imported.notes.append("images/index.csv lists the VIS images; put the files under the dive's images/")
        return
    src = context.settings_dir / settings.images_dir
    dst = context.staging / "images"
    missing = 0
    for name in (*left, *right):
        target = dst / "files" / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if not (src / name).is_file():
            missing += 1
            continue
        try:
            os.link(src / name, target)
        except OSError:
            shutil.copy2(src / name, target)
    if missing:
        imported.notes.append(f"{missing} VIS image file(s) not found in {src}")
    # The index names files relative to images/: keep the VIS names as they are.
    imported.images_dir = dst / "files"


# ---------------------------------------------------------------------------------------------
# stereo_pose_est.data
# ---------------------------------------------------------------------------------------------

_STEREO_HEADER = """\
% STEREO_POSE_FILE VERSION 2
%
% Written by auvnav ({source} trajectory of dive {dive}).
%
% One line per stereo pair: the pose of the left camera in the local navigation frame (north, east,
% down about the origin below) when the pair was taken. The camera frame has z along the optical
% axis, x to the right of the image and y to its bottom. The three angles, radians, are the Euler
% angles of that frame in the navigation frame, R_nav_camera = Rz(c) Ry(b) Rx(a) with (a, b, c) the
% X-, Y- and Z-axis angles.
%
% Columns: pose id, time (POSIX s), latitude (deg), longitude (deg), x north (m), y east (m),
% z depth (m), X angle, Y angle, Z angle (rad), left image, right image, altitude (m), approximate
% radius of the image footprint (m), likely cross-over (0: not computed).
%
"""


def export_stereo_pose(dive_path: Path, out: Path, options: Any) -> dict[str, Any]:
    """Write ``stereo_pose_est.data``: the left camera's pose at every stereo pair."""
    from auvnav.io.tracks import camera_track

    cams = camera_track(dive_path, options.source, "acfr-stereo-pose")
    dive, source, inside, R_nc, p_c = cams.dive, cams.source, cams.inside, cams.R_ned_cam, cams.p_ned_cam_m
    t, rig = dive.images.t_s, dive.vehicle.stereo
    z_ang, y_ang, x_ang = rot2euler(R_nc)  # R_nc = Rz(z) Ry(y) Rx(x)
    lat, lon, _ = ned2geodetic(p_c, dive.info.origin)
    lat, lon = np.degrees(np.reshape(lat, -1)), np.degrees(np.reshape(lon, -1))
    if dive.dvl.altitude_m is not None and np.count_nonzero(dive.dvl.valid & (dive.dvl.altitude_m > 0)) >= 2:
        ok = dive.dvl.valid & (dive.dvl.altitude_m > 0)
        altitude = np.interp(t[inside], dive.dvl.t_s[ok], dive.dvl.altitude_m[ok])
    else:
        altitude = np.zeros(int(inside.sum()))
    cam = rig.left
    radius = altitude * math.hypot(cam.width / 2.0, cam.height / 2.0) / cam.K[0, 0]
    left, right = dive.images.left[inside], dive.images.right[inside]
    lines = [
        _STEREO_HEADER.format(source=source, dive=dive.info.name),
        f"ORIGIN_LATITUDE  {float(math.degrees(dive.info.origin.latitude_rad))!r}\n",
        f"ORIGIN_LONGITUDE {float(math.degrees(dive.info.origin.longitude_rad))!r}\n",
    ]
    for k in range(len(left)):
        lines.append(
            f"{k} \t{float(t[inside][k])!r} \t{float(lat[k])!r} \t{float(lon[k])!r} \t{float(p_c[k, 0])!r} \t{float(p_c[k, 1])!r} \t{float(p_c[k, 2])!r} "
            f"\t{float(x_ang[k])!r} \t{float(y_ang[k])!r} \t{float(z_ang[k])!r} \t{left[k]} \t{right[k]} \t{float(altitude[k])!r} "
            f"\t{float(radius[k])!r} \t0\n"
        )
    text = "".join(lines)
    atomic_write(out, lambda p: p.write_text(text, encoding="utf-8"))
    return {"poses": len(left), "trajectory": source}
