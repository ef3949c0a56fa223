"""Teledyne RDI PD0: bottom-track velocity, altitude, attitude, pressure and time of every ensemble.

A reader of the published format (Teledyne RDI, "WorkHorse Commands and Output Data Format",
P/N 957-6156-00, chapter "PD0 output data format"; the Explorer and Pathfinder DVL manuals give the
same structure with shorter leaders), not a current-profiler library: a DVL's ensembles often carry
no velocity profile at all, the Explorer's variable leader has no Y2K clock, and every ensemble's
checksum must be verified. dolfyn (the maintained Python reader) was tried and not used: its
newest release here (1.3.0) neither imports nor reads with this project's numpy 2 and scipy
(``np.RankWarning``, ``scipy.integrate.cumtrapz`` and ``np.NaN`` are gone), and it reads profiles
into xarray for moored current meters; this reader of the published layout verifies every checksum
and names the byte offset of every problem.

**Ensemble**: ``7F 7F``, the byte count (excluding the 2-byte checksum), a spare byte, the number of
data types and their offsets; the checksum is the sum of every byte before it, modulo 65536. Data
types are found by their offsets and identified by their first two bytes; those read:

- fixed leader (``00 00``): system configuration (bytes 4-5: facing up or down, convex or concave
  beams, beam angle 15/20/30 degrees or, for "other", byte 58), coordinate transformation
  (byte 25, EX), heading alignment (26-27, EA, 0.01 deg), heading bias (28-29, EB, 0.01 deg),
  sensors available (31); at least 32 bytes (Workhorse 59, Explorer and Pathfinder 58);
- variable leader (``80 00``): the real-time clock (bytes 4-10, two-digit year), heading (18-19,
  0.01 deg), pitch and roll (20-23, signed 0.01 deg), pressure (48-51, decapascals, relative to one
  atmosphere) and, when the leader is long enough (65 bytes: Workhorse, Pathfinder), the Y2K clock
  (57-64, with the century); at least 24 bytes (Explorer 60);
- bottom track (``00 06``): the four beams' vertical ranges (16-23, cm, with the high bytes at 77-80
  when the block has 81 bytes or more) and velocities (24-31, signed mm/s, -32768 = bad); at least 32
  bytes (Workhorse 85, Explorer and Pathfinder 81).

Other data types (velocity profile, correlation, echo intensity, percent good, status, vendor
navigation records) are skipped and counted by identifier.

**Velocity** as the fixed leader's EX says (bits 4-3): beam coordinates are turned into instrument
coordinates with RDI's matrix (RDI, "ADCP Coordinate Transformation", P/N 951-6079-00:
``X = c a (b1 - b2)``, ``Y = c a (b4 - b3)``, ``Z = b (b1 + b2 + b3 + b4)``, ``a = 1/(2 sin q)``,
``b = 1/(4 cos q)``, ``c`` +1 convex, -1 concave; a single bad beam gives RDI's three-beam solution,
the error velocity set to zero); instrument coordinates into ship coordinates (starboard, forward,
up) with the down-facing flip (RDI: roll + 180 degrees) and the heading alignment EA; earth
coordinates (east, north, up) back into ship coordinates with ``M(H + EA, P, R + 180)`` of the same
document (H, P, R the leader's heading, pitch and roll); ship coordinates with tilts (EX bit 2) are
un-levelled with the leader's pitch and roll. Ship coordinates then become the DVL frame FRD
(forward, starboard, down), which is what the dive's ``nav/dvl.csv`` holds; the vehicle's DVL
mount is identity unless the vehicle file says otherwise. The PD0 manual defines bottom-track
velocity as the vessel's relative to the bottom (``bottom_velocity: vessel``, the default); a
firmware that reports the bottom's relative to the vessel is read with ``bottom_velocity: bottom``.

**Altitude** is the mean of the valid beams' vertical ranges (the PD0 ranges are vertical already;
0 when no beam has a range). **Valid** when three or four beams (or all three components) are good.

**Time** from the Y2K clock when the leader has it, else the two-digit real-time clock (years 80-99
are 1900s, 00-79 2000s). Ensembles whose time is not after the previous one are skipped and counted.

**Attitude** (``attitude: true``): the leader's heading, pitch and roll as the vehicle's compass and
inclinometer. **Pressure** (``use_pressure: true``): the leader's, when the fixed leader says a
pressure sensor is available (byte 31 bit 5), as sea pressure. **Heading reference**: true when the
heading bias EB is not zero (RDI applies EB as the magnetic variation), else magnetic.

**Errors**: a byte that does not start an ensemble where one should, a truncated ensemble, a wrong
checksum, or a data type shorter than its layout is a one-line error naming the file and byte
offset; ``skip_bad_ensembles: true`` skips and counts them instead (resynchronising on the next
``7F 7F``). A file with no bottom-track data is refused.
"""

from __future__ import annotations

import datetime as dt
import math
import struct
from pathlib import Path
from typing import Literal

import numpy as np

from auvnav.dive import AttitudeStream, DvlStream, PressureStream
from auvnav.errors import ConfigError
from auvnav.io.common import Counts, FormatError, ImportContext, Imported, ImportSettings, read_bytes

DEG = math.pi / 180.0
HEADER = b"\x7f\x7f"
FIXED, VARIABLE, BOTTOM = 0x0000, 0x0080, 0x0600
BAD = -32768
OTHER_IDS = {
    0x0100: "velocity profile",
    0x0200: "correlation",
    0x0300: "echo intensity",
    0x0400: "percent good",
    0x0500: "status",
}
MIN_LENGTH = {FIXED: 32, VARIABLE: 24, BOTTOM: 32}
NAMES = {FIXED: "fixed leader", VARIABLE: "variable leader", BOTTOM: "bottom track"}
BEAM_ANGLES_DEG = {0: 15.0, 1: 20.0, 2: 30.0}


class Pd0Settings(ImportSettings):
    """Settings of the ``pd0`` importer (besides :class:`ImportSettings`).

    Parameters
    ----------
    skip_bad_ensembles : bool
        Skip and count truncated ensembles, wrong checksums and stray bytes instead of stopping.
    bottom_velocity : {"vessel", "bottom"}
        What the bottom-track velocity is the velocity of (the PD0 manual: the vessel's).
    attitude : bool
        Write the leader's heading, pitch and roll as the attitude stream.
    use_pressure : bool
        Write the leader's pressure as the pressure stream (when a sensor is available).
    """

    skip_bad_ensembles: bool = False
    bottom_velocity: Literal["vessel", "bottom"] = "vessel"
    attitude: bool = True
    use_pressure: bool = True


SETTINGS = Pd0Settings

_U16 = struct.Struct("<H")
_I16 = struct.Struct("<h")
_U32 = struct.Struct("<I")
_BT = struct.Struct("<4H4h")


class _Bad(Exception):
    """A bad ensemble: skipped (lenient) or the error (strict)."""

    def __init__(self, message: str, byte: int):
        super().__init__(message)
        self.byte = byte


def _ensembles(path: Path, data: bytes, counts: Counts, lenient: bool):
    """Yield ``(number, byte offset, {id: (start, length)})`` of every good ensemble."""
    pos, n, k = 0, len(data), 0
    while pos < n:
        try:
            if data[pos : pos + 2] != HEADER:
                found = data[pos : pos + 2].hex(" ").upper()
                raise _Bad(f"expected an ensemble header 7F 7F, found {found} (not PD0, or stray bytes)", pos)
            if pos + 6 > n:
                raise _Bad(f"ensemble {k + 1} is truncated ({n - pos} bytes: the header alone needs 6)", pos)
            nbytes = _U16.unpack_from(data, pos + 2)[0]
            ndt = data[pos + 5]
            if nbytes < 6 + 2 * ndt:
                raise _Bad(f"ensemble {k + 1}: {ndt} data types do not fit its {nbytes} bytes", pos)
            if pos + nbytes + 2 > n:
                raise _Bad(
                    f"ensemble {k + 1} is truncated: its header says {nbytes + 2} bytes, {n - pos} remain",
                    pos,
                )
            stored = _U16.unpack_from(data, pos + nbytes)[0]
            computed = int(np.frombuffer(data, np.uint8, nbytes, pos).sum(dtype=np.uint64)) & 0xFFFF
            if stored != computed:
                raise _Bad(
                    f"ensemble {k + 1}: checksum {stored:04X} does not match its bytes ({computed:04X})",
                    pos + nbytes,
                )
            offsets = struct.unpack_from(f"<{ndt}H", data, pos + 6)
            bounds = [*sorted(offsets), nbytes]
            blocks: dict[int, tuple[int, int]] = {}
            for off in offsets:
                if not 6 + 2 * ndt <= off < nbytes - 1:
                    raise _Bad(f"ensemble {k + 1}: data type offset {off} outside its {nbytes} bytes", pos)
                ident = _U16.unpack_from(data, pos + off)[0]
                length = bounds[bounds.index(off) + 1] - off
                if ident in MIN_LENGTH and length < MIN_LENGTH[ident]:
                    raise _Bad(
                        f"ensemble {k + 1}: the {NAMES[ident]} has {length} bytes; its layout needs at least "
                        f"{MIN_LENGTH[ident]} (wrong field count)",
                        pos + off,
                    )
                blocks[ident] = (pos + off, length)
        except _Bad as bad:
            if not lenient:
                raise FormatError(path, str(bad), byte=bad.byte) from None
            counts.skip(
                "bad ensembles or stray bytes (resynchronised on the next 7F 7F)",
                f"{path.name} byte {bad.byte}",
            )
            nxt = data.find(HEADER, pos + 1)
            if nxt < 0:
                return
            pos = nxt
            continue
        k += 1
        yield k, pos, blocks
        pos += nbytes + 2


def _time(data: bytes, start: int, length: int, path: Path, k: int) -> float:
    if length >= 65 and data[start + 57] in (19, 20, 21):
        y = data[start + 57] * 100 + data[start + 58]
        fields = data[start + 59 : start + 65]
    else:
        yy = data[start + 4]
        y = 1900 + yy if yy >= 80 else 2000 + yy
        fields = data[start + 5 : start + 11]
    mo, d, h, mi, s, hu = fields
    try:
        when = dt.datetime(y, mo, d, h, mi, s, tzinfo=dt.timezone.utc)
        if hu > 99:
            raise ValueError
    except ValueError:
        raise FormatError(
            path,
            f"ensemble {k}: the variable leader's clock {y}-{mo}-{d} {h}:{mi}:{s}.{hu} is not a time",
            byte=start,
        ) from None
    return when.timestamp() + hu / 100.0


def _H(angle_rad: np.ndarray) -> np.ndarray:
    """RDI's heading matrix (ship to earth), shape (N, 3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, s, z], -1), np.stack([-s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _P(angle_rad: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _R(angle_rad: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def beam2instrument(
    b_mps: np.ndarray, beam_angle_rad: np.ndarray, convex: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Instrument-frame velocity (N, 3) from four beam velocities (N, 4, NaN where bad), and validity.

    RDI's matrix; with exactly one bad beam, RDI's three-beam solution (the bad beam set so that the
    error velocity is zero: ``b1 + b2 = b3 + b4``).
    """
    b = np.array(b_mps, dtype=float)
    bad = np.isnan(b)
    nbad = bad.sum(axis=1)
    fill = {0: (2, 3, 1), 1: (2, 3, 0), 2: (0, 1, 3), 3: (0, 1, 2)}  # bad = x + y - z
    for beam, (x, y, z) in fill.items():
        rows = (nbad == 1) & bad[:, beam]
        b[rows, beam] = b[rows, x] + b[rows, y] - b[rows, z]
    c = np.where(convex, 1.0, -1.0)
    a = 1.0 / (2.0 * np.sin(beam_angle_rad))
    bb = 1.0 / (4.0 * np.cos(beam_angle_rad))
    v = np.column_stack(
        [
            c * a * (b[:, 0] - b[:, 1]),
            c * a * (b[:, 3] - b[:, 2]),
            bb * (b[:, 0] + b[:, 1] + b[:, 2] + b[:, 3]),
        ]
    )
    return v, nbad <= 1


def to_ship(
    v: np.ndarray,
    coord: np.ndarray,
    tilts: np.ndarray,
    down: np.ndarray,
    ea_rad: np.ndarray,
    heading_rad: np.ndarray,
    pitch_rad: np.ndarray,
    roll_rad: np.ndarray,
) -> np.ndarray:
    """Velocities (N, 3) in instrument (1), ship (2) or earth (3) coordinates into ship coordinates
    (starboard, forward, up) of the DVL as mounted."""
    n = len(v)
    flip = np.where(down, np.pi, 0.0)
    F = _R(flip)  # RDI: a down-facing instrument's roll + 180 degrees
    HF = _H(ea_rad) @ F  # instrument -> ship (no tilt)
    out = np.empty((n, 3))
    inst = coord == 1
    out[inst] = np.einsum("nij,nj->ni", HF[inst], v[inst])
    ship = coord == 2
    level = ship & tilts
    out[ship & ~tilts] = v[ship & ~tilts]
    if level.any():
        M = _H(ea_rad[level]) @ _P(pitch_rad[level]) @ _R(roll_rad[level]) @ F[level]
        v_inst = np.einsum("nji,nj->ni", M, v[level])
        out[level] = np.einsum("nij,nj->ni", HF[level], v_inst)
    earth = coord == 3
    if earth.any():
        M = _H(heading_rad[earth] + ea_rad[earth]) @ _P(pitch_rad[earth]) @ _R(roll_rad[earth]) @ F[earth]
        v_inst = np.einsum("nji,nj->ni", M, v[earth])
        out[earth] = np.einsum("nij,nj->ni", HF[earth], v_inst)
    return out


def read(sources: list[Path], settings: Pd0Settings, context: ImportContext) -> Imported:  # type: ignore[override]
    """Read PD0 files (in time order) into DVL, attitude and pressure streams."""
    if not sources:
        raise ConfigError("pd0: give one or more PD0 files")
    imported = Imported()
    counts = imported.counts
    rows: list[tuple] = []
    where: list[str] = []
    total = 0
    eb_nonzero = False
    for path in sources:
        data = read_bytes(path)
        if not data:
            raise FormatError(path, "empty file (no PD0 ensembles)")
        for k, pos, blocks in _ensembles(path, data, counts, settings.skip_bad_ensembles):
            total += 1
            for ident in blocks:
                if ident not in (FIXED, VARIABLE, BOTTOM):
                    counts.read[f"{OTHER_IDS.get(ident, f'data type {ident:04X}')} records (not used)"] += 1
            if FIXED not in blocks or VARIABLE not in blocks:
                missing = NAMES[FIXED] if FIXED not in blocks else NAMES[VARIABLE]
                raise FormatError(path, f"ensemble {k} has no {missing}", byte=pos)
            if BOTTOM not in blocks:
                counts.skip("ensembles without bottom track", f"{path.name} byte {pos}")
                continue
            f0, flen = blocks[FIXED]
            v0, vlen = blocks[VARIABLE]
            b0, blen = blocks[BOTTOM]
            config = _U16.unpack_from(data, f0 + 4)[0]
            angle_code = (config >> 8) & 0b11
            if angle_code in BEAM_ANGLES_DEG:
                angle = BEAM_ANGLES_DEG[angle_code]
            elif flen >= 59:
                angle = float(data[f0 + 58])
            else:
                raise FormatError(
                    path, f"ensemble {k}: beam angle 'other' and no byte 58 to give it", byte=f0 + 4
                )
            ex = data[f0 + 25]
            ea = _I16.unpack_from(data, f0 + 26)[0] / 100.0
            eb = _I16.unpack_from(data, f0 + 28)[0] / 100.0
            eb_nonzero |= eb != 0.0
            has_pressure = bool(data[f0 + 31] & 0x20) and vlen >= 52
            t = _time(data, v0, vlen, path, k)
            heading = _U16.unpack_from(data, v0 + 18)[0] / 100.0
            pitch = _I16.unpack_from(data, v0 + 20)[0] / 100.0
            roll = _I16.unpack_from(data, v0 + 22)[0] / 100.0
            pressure = _U32.unpack_from(data, v0 + 48)[0] * 10.0 if has_pressure else math.nan
            bt = _BT.unpack_from(data, b0 + 16)
            ranges = [float(r) for r in bt[:4]]
            if blen >= 81:
                ranges = [r + 65536.0 * data[b0 + 77 + i] for i, r in enumerate(ranges)]
            rows.append(
                (
                    t,
                    (ex >> 3) & 0b11,
                    bool(ex & 0b100),
                    not bool(config & 0x80),  # down-facing
                    bool(config & 0x08),  # convex
                    angle,
                    ea,
                    heading,
                    pitch,
                    roll,
                    pressure,
                    *bt[4:],
                    *ranges,
                )
            )
            where.append(f"{path.name} byte {pos}")
        counts.read["ensembles"] = total
    if not rows:
        raise FormatError(
            sources[0],
            f"no bottom-track data (ID 0006) in any of its {total} ensembles: a DVL log needs bottom tracking "
            "(a water-profile file cannot navigate)",
        )
    a = np.array([r[:11] for r in rows], dtype=float)
    vel_raw = np.array([r[11:15] for r in rows], dtype=float)
    ranges_cm = np.array([r[15:19] for r in rows], dtype=float)
    keep = np.zeros(len(a), dtype=bool)
    last = -math.inf
    for k, tk in enumerate(a[:, 0]):
        if tk > last:
            keep[k], last = True, tk
        else:
            counts.skip("ensembles whose time is not after the previous one", where[k])
    a, vel_raw, ranges_cm = a[keep], vel_raw[keep], ranges_cm[keep]
    t = a[:, 0]
    coord = a[:, 1].astype(int)
    tilts, down, convex = a[:, 2] > 0, a[:, 3] > 0, a[:, 4] > 0
    angle, ea = a[:, 5] * DEG, a[:, 6] * DEG
    heading, pitch, roll = a[:, 7] * DEG, a[:, 8] * DEG, a[:, 9] * DEG
    bad = vel_raw == BAD
    v = np.where(bad, np.nan, vel_raw / 1000.0)
    valid = np.zeros(len(t), dtype=bool)
    v3 = np.zeros((len(t), 3))
    beam = coord == 0
    if beam.any():
        v3[beam], valid[beam] = beam2instrument(v[beam], angle[beam], convex[beam])
        coord = np.where(beam, 1, coord)
    other = ~beam
    v3[other] = np.nan_to_num(v[other, :3])
    valid[other] = ~bad[other, :3].any(axis=1)
    ship = to_ship(v3, coord, tilts, down, ea, heading, pitch, roll)
    if settings.bottom_velocity == "bottom":
        ship = -ship
    frd = np.column_stack([ship[:, 1], ship[:, 0], -ship[:, 2]])
    good_range = ranges_cm > 0
    n_range = good_range.sum(axis=1)
    altitude = (
        np.where(n_range > 0, np.where(good_range, ranges_cm, 0.0).sum(axis=1) / np.maximum(n_range, 1), 0.0)
        / 100.0
    )
    imported.streams["dvl"] = DvlStream(
        t_s=t, v_sensor_mps=np.where(valid[:, None], frd, 0.0), altitude_m=altitude, valid=valid
    )
    counts.read["bottom-track samples"] = len(t)
    counts.read["valid bottom-track samples"] = int(valid.sum())
    if settings.attitude:
        imported.streams["attitude"] = AttitudeStream(t, heading, pitch, roll)
        imported.heading_reference = "true" if eb_nonzero else "magnetic"
        imported.heading_rule = (
            "PD0 heading with a heading bias EB (RDI's magnetic variation): true"
            if eb_nonzero
            else "PD0 heading without a heading bias (EB = 0): magnetic, declination auto"
        )
    pressure = a[:, 10]
    if settings.use_pressure and np.isfinite(pressure).sum() >= 2:
        ok = np.isfinite(pressure)
        imported.streams["pressure"] = PressureStream(t[ok], pressure[ok])
        imported.pressure_type = "sea"
        imported.pressure_rule = "PD0 pressure is relative to one atmosphere: sea pressure"
    elif settings.use_pressure:
        imported.notes.append(
            "the PD0 leaders carry no pressure (no sensor available): give --base DIVE with one"
        )
    return imported
