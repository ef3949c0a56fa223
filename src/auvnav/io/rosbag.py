"""ROS 1 ``.bag`` files and ROS 2 bag folders, read with ``rosbags`` (pure Python), message by message.

Topics by role, each chosen by the settings or, by default, found by message type (the one topic of
that type; several are an error that lists them):

- ``dvl_topic``: ``geometry_msgs/TwistWithCovarianceStamped`` or ``TwistStamped`` (the DVL's
  bottom-track velocity in its frame), else ``nav_msgs/Odometry`` (its twist, in the child frame);
  a velocity with a NaN, or a covariance whose first element is -1 (ROS: "unknown"), is invalid;
- ``attitude_topic``: ``sensor_msgs/Imu``, else ``nav_msgs/Odometry`` (the pose's orientation);
- ``depth_topic``: ``sensor_msgs/FluidPressure`` (absolute pressure, Pa, ``type: absolute``), or,
  named in the settings, a ``std_msgs/Float64``/``Float32`` whose meaning ``depth_is`` gives
  (``depth_m``, the default, converted to sea pressure by TEOS-10; ``pressure_pa``; ``pressure_dbar``);
- ``gps_topic``: ``sensor_msgs/NavSatFix`` (status < 0 is no fix: skipped and counted; the sigma
  from the position covariance when its type is known, else the vehicle's);
- ``altitude_topic``: ``sensor_msgs/Range`` (the DVL's altitude, interpolated at its samples);
- ``left_image_topic``, ``right_image_topic``: ``sensor_msgs/Image`` or ``CompressedImage``; by
  default the two image topics, told apart by ``left``/``right`` in their names. A compressed
  image is written as it is (its ``format`` gives the extension); a raw image is written as PNG, a
  Bayer mosaic (``bayer_rggb8`` ... ``bayer_gbrg16``) as it is, its filter put on the vehicle's camera.
  Left and right images pair when their stamps are within ``pair_tolerance_s``; unpaired images are
  counted and not kept.

Frames follow REP-103 unless the settings say otherwise: body ``flu`` (x forward, y left, z up; FRD
is ``x, -y, -z``) and world ``enu`` (the orientation's yaw from east, counter-clockwise). The heading
reference is not in a bag: give ``heading_reference`` in the settings. Times are the messages'
header stamps (``time_source: header``) or the bag's receive times (``bag``); a zero stamp falls back
to the receive time. Messages are read one at a time and images go straight to disk, so memory is
bounded by the navigation streams, not by the bag (a 1 GB bag of images is measured in
``benchmarks/bench_import.py``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from auvnav.config import quote
from auvnav.dive import AttitudeStream, DvlStream, GpsStream, PressureStream
from auvnav.errors import ConfigError
from auvnav.frames import quat_wxyz2rot, rot2euler
from auvnav.io.common import DBAR, FormatError, ImportContext, Imported, ImportSettings, images_index
from auvnav.vehicle import BAYER_PATTERNS

TWIST = ("geometry_msgs/msg/TwistWithCovarianceStamped", "geometry_msgs/msg/TwistStamped")
ODOMETRY = "nav_msgs/msg/Odometry"
IMU = "sensor_msgs/msg/Imu"
FLUID = "sensor_msgs/msg/FluidPressure"
FLOATS = ("std_msgs/msg/Float64", "std_msgs/msg/Float32")
NAVSAT = "sensor_msgs/msg/NavSatFix"
RANGE = "sensor_msgs/msg/Range"
IMAGES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")

ROLES: dict[str, tuple[str, ...]] = {
    "dvl_topic": (*TWIST, ODOMETRY),
    "attitude_topic": (IMU, ODOMETRY),
    "depth_topic": (FLUID, *FLOATS),
    "gps_topic": (NAVSAT,),
    "altitude_topic": (RANGE,),
    "left_image_topic": IMAGES,
    "right_image_topic": IMAGES,
}

# REP-103 to the dive's frames: ENU -> NED and FLU -> FRD.
T_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
T_FLU_FRD = np.diag([1.0, -1.0, -1.0])


class RosbagSettings(ImportSettings):
    """Settings of the ``rosbag`` importer (besides :class:`ImportSettings`); see the module docstring."""

    dvl_topic: str | None = None
    attitude_topic: str | None = None
    depth_topic: str | None = None
    depth_is: Literal["depth_m", "pressure_pa", "pressure_dbar"] = "depth_m"
    gps_topic: str | None = None
    altitude_topic: str | None = None
    left_image_topic: str | None = None
    right_image_topic: str | None = None
    pair_tolerance_s: float = 0.001
    body_frame: Literal["flu", "frd"] = "flu"
    world_frame: Literal["enu", "ned"] = "enu"
    time_source: Literal["header", "bag"] = "header"


SETTINGS = RosbagSettings


def _choose(connections: list[Any], settings: RosbagSettings) -> dict[str, Any]:
    """The connection of each role (topic names from the settings, or found by type)."""
    by_topic: dict[str, list[Any]] = {}
    for c in connections:
        by_topic.setdefault(c.topic, []).append(c)
    chosen: dict[str, Any] = {}
    for role, types in ROLES.items():
        topic = getattr(settings, role)
        if topic is not None:
            if topic not in by_topic:
                raise ConfigError(
                    f"rosbag: {role}: no topic {quote(topic)} in the bag (topics: {', '.join(sorted(by_topic))})"
                )
            conns = by_topic[topic]
            if conns[0].msgtype not in types:
                raise ConfigError(
                    f"rosbag: {role}: topic {topic} carries {conns[0].msgtype}; {role} needs one of {', '.join(types)}"
                )
            chosen[role] = conns
    images = [t for t, cs in by_topic.items() if cs[0].msgtype in IMAGES]
    for role, preferred in (
        ("dvl_topic", TWIST),
        ("attitude_topic", (IMU,)),
        ("depth_topic", (FLUID,)),
        ("gps_topic", (NAVSAT,)),
        ("altitude_topic", (RANGE,)),
    ):
        if role in chosen:
            continue
        found = [t for t, cs in by_topic.items() if cs[0].msgtype in preferred]
        if not found and role in ("dvl_topic", "attitude_topic"):
            found = [t for t, cs in by_topic.items() if cs[0].msgtype == ODOMETRY]
        if len(found) > 1:
            raise ConfigError(
                f"rosbag: several topics could be the {role[:-6]}: {', '.join(sorted(found))}; set {role} in --config"
            )
        if found:
            chosen[role] = by_topic[found[0]]
    if "left_image_topic" not in chosen and "right_image_topic" not in chosen and images:
        left = [t for t in images if re.search("left", t, re.IGNORECASE)]
        right = [t for t in images if re.search("right", t, re.IGNORECASE)]
        if len(images) != 2 or len(left) != 1 or len(right) != 1:
            raise ConfigError(
                f"rosbag: image topics {', '.join(sorted(images))}: set left_image_topic and right_image_topic in --config"
            )
        chosen["left_image_topic"], chosen["right_image_topic"] = by_topic[left[0]], by_topic[right[0]]
    elif ("left_image_topic" in chosen) != ("right_image_topic" in chosen):
        raise ConfigError("rosbag: give both left_image_topic and right_image_topic")
    return chosen


@dataclass
class _Images:
    """Image files written as they arrive, paired at the end; the colour filter of each side whose
    images are raw mosaics (ROS ``bayer_*`` encodings), None for the others."""

    folder: Path
    left: list[tuple[float, str]]
    right: list[tuple[float, str]]
    bayer: dict[str, set[str | None]] = field(default_factory=lambda: {"left": set(), "right": set()})

    def write(self, side: str, t: float, msg: Any) -> None:
        name = f"{side}/{len(getattr(self, side)):06d}"
        if msg.__msgtype__.endswith("CompressedImage"):
            fmt = str(msg.format).lower()
            ext = ".png" if "png" in fmt else ".jpg"
            (self.folder / (name + ext)).write_bytes(bytes(msg.data))
            self.bayer[side].add(None)
        else:
            ext = ".png"
            self.bayer[side].add(_write_raw(self.folder / (name + ext), msg))
        getattr(self, side).append((t, name + ext))

    def filters(self) -> dict[str, str]:
        """The colour filter of each side whose images are all raw mosaics of one filter."""
        out = {}
        for side, seen in self.bayer.items():
            if len(seen) > 1:
                names = ", ".join(sorted(f"bayer_{s}" if s else "demosaiced" for s in seen))
                raise ConfigError(
                    f"rosbag: the {side} images change encoding ({names}): one camera, one kind"
                )
            if seen and None not in seen:
                out[side] = str(next(iter(seen)))
        return out


#: ROS ``sensor_msgs/Image`` encodings read, and their channels.
_CHANNELS = {
    "mono8": 1,
    "8uc1": 1,
    "bgr8": 3,
    "rgb8": 3,
    "8uc3": 3,
    "mono16": 1,
    "16uc1": 1,
    "bgra8": 4,
    "rgba8": 4,
}
#: ROS's Bayer encodings (one channel of 8 or 16 bits) and the colour filter each names.
_BAYER_ENCODINGS = {f"bayer_{p}{bits}": p for p in BAYER_PATTERNS for bits in (8, 16)}
_CHANNELS.update(dict.fromkeys(_BAYER_ENCODINGS, 1))


def _write_raw(path: Path, msg: Any) -> str | None:
    """Write a raw ``sensor_msgs/Image`` as PNG (a Bayer mosaic as it is); its colour filter if it
    is one (``bayer_rggb8`` -> ``rggb``), else None."""
    import cv2

    enc = str(msg.encoding).lower()
    if enc not in _CHANNELS:
        raise ConfigError(
            f"rosbag: image encoding {quote(msg.encoding)} is not supported (mono8/16, bgr8, rgb8, bgra8, "
            "rgba8, bayer_*8/16)"
        )
    dtype = np.uint16 if "16" in enc else np.uint8
    row = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)
    img = row[:, : msg.width * _CHANNELS[enc] * np.dtype(dtype).itemsize].copy().view(dtype)
    if dtype == np.uint16 and msg.is_bigendian:
        img = img.byteswap()
    img = (
        img.reshape(msg.height, msg.width, _CHANNELS[enc])
        if _CHANNELS[enc] > 1
        else img.reshape(msg.height, msg.width)
    )
    if enc.startswith("rgb"):
        img = img[..., ::-1] if _CHANNELS[enc] == 3 else img[..., [2, 1, 0, 3]]
    cv2.imwrite(str(path), img)
    return _BAYER_ENCODINGS.get(enc)


def _stamp(msg: Any, t_bag_ns: int, source: str) -> float:
    if source == "header" and hasattr(msg, "header"):
        s = msg.header.stamp
        if s.sec or s.nanosec:
            return s.sec + s.nanosec * 1e-9
    return t_bag_ns * 1e-9


def _pair(
    left: list[tuple[float, str]], right: list[tuple[float, str]], tol: float, imported: Imported
) -> tuple[list, list, list, list[str]]:
    """Pairs of stereo images within ``tol`` seconds; the unpaired files' names."""
    t_s, lnames, rnames, unpaired = [], [], [], []
    i = j = 0
    while i < len(left) and j < len(right):
        dt = left[i][0] - right[j][0]
        if abs(dt) <= tol:
            if t_s and left[i][0] <= t_s[-1]:
                imported.counts.skip("image pairs whose time is not after the previous pair", left[i][1])
                unpaired += [left[i][1], right[j][1]]
            else:
                t_s.append(left[i][0])
                lnames.append(left[i][1])
                rnames.append(right[j][1])
            i += 1
            j += 1
        elif dt < 0:
            imported.counts.skip("left images without a right image within the pairing tolerance", left[i][1])
            unpaired.append(left[i][1])
            i += 1
        else:
            imported.counts.skip(
                "right images without a left image within the pairing tolerance", right[j][1]
            )
            unpaired.append(right[j][1])
            j += 1
    for name in [n for _, n in left[i:]] + [n for _, n in right[j:]]:
        imported.counts.skip("images without a stereo partner", name)
        unpaired.append(name)
    return t_s, lnames, rnames, unpaired


def _rot(q: Any, settings: RosbagSettings) -> np.ndarray:
    R = quat_wxyz2rot(np.array([q.w, q.x, q.y, q.z], dtype=float))
    if settings.world_frame == "enu":
        R = T_NED_ENU @ R
    if settings.body_frame == "flu":
        R = R @ T_FLU_FRD
    return R


def _messages(reader: Any, conns: Iterable[Any], path_text: str) -> Iterable[tuple[Any, int, Any]]:
    from rosbags.highlevel import AnyReaderError

    it = reader.messages(connections=list(conns))
    while True:
        try:
            conn, t_ns, raw = next(it)
        except StopIteration:
            return
        except (AnyReaderError, Exception) as err:  # rosbags raises several reader errors
            raise FormatError(
                path_text, f"not a readable ROS bag past some point ({type(err).__name__}: {err})"
            ) from err
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as err:
            raise FormatError(
                path_text,
                f"topic {conn.topic}: a {conn.msgtype} message at {t_ns * 1e-9:.3f} s does not decode ({err})",
            ) from err
        yield conn, t_ns, msg


def read(sources: list[Path], settings: RosbagSettings, context: ImportContext) -> Imported:  # type: ignore[override]
    """Read ROS bags (all ROS 1 or all ROS 2) into the dive's streams and image files."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    if not sources:
        raise ConfigError("rosbag: give one or more bags (ROS 1 .bag files or ROS 2 bag folders)")
    for p in sources:
        if not p.exists():
            raise FormatError(p, "file not found")
    path_text = ", ".join(str(p) for p in sources)
    imported = Imported()
    counts = imported.counts
    try:
        reader = AnyReader(list(sources), default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except (AnyReaderError, Exception) as err:
        raise FormatError(path_text, f"not a readable ROS bag ({type(err).__name__}: {err})") from err
    try:
        chosen = _choose(list(reader.connections), settings)
        role_of = {id(c): role for role, cs in chosen.items() for c in cs}
        for cs in chosen.values():
            if cs[0].msgtype not in reader.typestore.types:
                raise FormatError(
                    path_text, f"topic {cs[0].topic}: unknown message type {cs[0].msgtype} (no definition)"
                )
        dvl: list[tuple[float, float, float, float, bool]] = []
        att: list[tuple[float, float, float, float]] = []
        depth: list[tuple[float, float]] = []
        gps: list[tuple[float, float, float, float]] = []
        alt: list[tuple[float, float]] = []
        images = _Images(context.staging / "images", [], [])
        if "left_image_topic" in chosen:
            (images.folder / "left").mkdir(parents=True)
            (images.folder / "right").mkdir(parents=True)
        all_conns = [c for cs in chosen.values() for c in cs]
        for conn, t_ns, msg in _messages(reader, all_conns, path_text):
            role = role_of[id(conn)]
            t = _stamp(msg, t_ns, settings.time_source)
            counts.read[f"{conn.topic} messages"] += 1
            if role == "dvl_topic":
                twist = msg.twist.twist if conn.msgtype in (TWIST[0], ODOMETRY) else msg.twist
                v = np.array([twist.linear.x, twist.linear.y, twist.linear.z], dtype=float)
                cov = msg.twist.covariance if conn.msgtype in (TWIST[0], ODOMETRY) else None
                ok = bool(np.all(np.isfinite(v))) and not (cov is not None and cov[0] == -1.0)
                if settings.body_frame == "flu":
                    v = T_FLU_FRD @ v
                dvl.append((t, *np.nan_to_num(v), ok))
            elif role == "attitude_topic":
                q = msg.orientation if conn.msgtype == IMU else msg.pose.pose.orientation
                if conn.msgtype == IMU and msg.orientation_covariance[0] == -1.0:
                    counts.skip(
                        f"{conn.topic}: Imu messages without orientation (covariance -1)", f"t={t:.3f}"
                    )
                    continue
                if (
                    not np.isfinite([q.w, q.x, q.y, q.z]).all()
                    or abs(q.w**2 + q.x**2 + q.y**2 + q.z**2 - 1) > 1e-3
                ):
                    counts.skip(f"{conn.topic}: orientations that are not unit quaternions", f"t={t:.3f}")
                    continue
                yaw, pitch, roll = rot2euler(_rot(q, settings))
                att.append((t, float(yaw), float(pitch), float(roll)))
            elif role == "depth_topic":
                value = float(msg.fluid_pressure) if conn.msgtype == FLUID else float(msg.data)
                depth.append((t, value))
            elif role == "gps_topic":
                if msg.status.status < 0:
                    counts.skip(f"{conn.topic}: NavSatFix without a fix (status < 0)", f"t={t:.3f}")
                    continue
                c = msg.position_covariance
                sigma = (
                    math.sqrt(max((c[0] + c[4]) / 2.0, 0.0)) if msg.position_covariance_type > 0 else math.nan
                )
                gps.append((t, msg.latitude, msg.longitude, sigma if sigma > 0 else math.nan))
            elif role == "altitude_topic":
                alt.append((t, float(msg.range)))
            else:
                images.write("left" if role == "left_image_topic" else "right", t, msg)
    finally:
        reader.close()
    _streams(imported, settings, dvl, att, depth, gps, alt, chosen)
    if images.left or images.right:
        t_s, lnames, rnames, unpaired = _pair(images.left, images.right, settings.pair_tolerance_s, imported)
        for name in unpaired:
            (images.folder / name).unlink(missing_ok=True)
        index = images_index(t_s, lnames, rnames)
        if index is not None:
            imported.streams["images"] = index
            imported.images_dir = images.folder
            imported.image_bayer = images.filters()
    imported.heading_rule = "a ROS bag does not say which north its orientation refers to"
    return imported


def _ordered(rows: list[tuple], imported: Imported, what: str) -> np.ndarray:
    a = np.asarray(rows, dtype=float)
    keep = np.zeros(len(a), dtype=bool)
    last = -math.inf
    for k, tk in enumerate(a[:, 0]):
        if tk > last:
            keep[k], last = True, tk
        else:
            imported.counts.skip(f"{what}: time not after the previous message", f"t={tk:.3f}")
    return a[keep]


def _streams(
    imported: Imported,
    settings: RosbagSettings,
    dvl: list,
    att: list,
    depth: list,
    gps: list,
    alt: list,
    chosen: dict[str, Any],
) -> None:
    if dvl:
        d = _ordered(dvl, imported, "dvl")
        altitude = None
        if alt:
            a = _ordered(alt, imported, "altitude")
            ok = np.isfinite(a[:, 1]) & (a[:, 1] > 0)
            if ok.sum() >= 2:
                altitude = np.interp(d[:, 0], a[ok, 0], a[ok, 1])
        if altitude is None:
            imported.notes.append(
                "no altitude topic: nav/dvl.csv has no altitude (loops use the stereo range)"
            )
        imported.streams["dvl"] = DvlStream(d[:, 0], d[:, 1:4], altitude, d[:, 4] > 0)
    if att:
        a = _ordered(att, imported, "attitude")
        imported.streams["attitude"] = AttitudeStream(a[:, 0], a[:, 1], a[:, 2], a[:, 3])
    if depth:
        p = _ordered(depth, imported, "depth")
        msgtype = chosen["depth_topic"][0].msgtype
        if msgtype == FLUID:
            imported.streams["pressure"] = PressureStream(p[:, 0], p[:, 1])
            imported.pressure_type, imported.pressure_rule = "absolute", "FluidPressure is absolute pressure"
        elif settings.depth_is == "depth_m":
            imported.depth = (p[:, 0], p[:, 1])
        else:
            scale = 1.0 if settings.depth_is == "pressure_pa" else DBAR
            imported.streams["pressure"] = PressureStream(p[:, 0], p[:, 1] * scale)
            imported.pressure_rule = f"depth_topic holds {settings.depth_is}"
    if gps:
        g = _ordered(gps, imported, "gps")
        imported.streams["gps"] = GpsStream(g[:, 0], np.radians(g[:, 1]), np.radians(g[:, 2]), g[:, 3])
