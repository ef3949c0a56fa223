"""The PD0 reader on the layouts the manuals give (Workhorse, Explorer, Pathfinder), in every coordinate
system, on ensembles packed from the specification (io_writers.pack_ensemble)."""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
import pytest
from io_writers import pack_ensemble

from auvnav.io.common import FormatError, ImportContext
from auvnav.io.pd0 import Pd0Settings, read

T0 = dt.datetime(2009, 10, 15, 1, 0, tzinfo=dt.timezone.utc).timestamp()
V_FRD = (0.512, -0.034, 0.021)  # m/s, forward, starboard, down
MM = 1.5e-3  # the fields are whole mm/s; a transform mixes a few of them


def _read(path: Path, **settings) -> tuple:
    imported = read([path], Pd0Settings(**settings), ImportContext(None, path.parent, path.parent))
    return imported, imported.streams["dvl"]


def _file(tmp_path: Path, n: int = 5, **kwargs) -> Path:
    path = tmp_path / "dvl.pd0"
    with open(path, "wb") as fh:
        for k in range(n):
            args = {
                "number": k + 1,
                "t": T0 + 0.2 * k,
                "v_frd_mps": V_FRD,
                "ranges_m": (2.01, 1.99, 2.02, 1.98),
                "heading_deg": 30.0 + k,
                "pitch_deg": 4.0,
                "roll_deg": -3.0,
                "sea_pressure_pa": 2.0e5,
                **kwargs,
            }
            fh.write(pack_ensemble(**args))
    return path


@pytest.mark.parametrize("layout", ["workhorse", "explorer", "pathfinder"])
@pytest.mark.parametrize("coords", ["beam", "instrument", "ship", "earth"])
def test_layouts_and_coordinates(tmp_path: Path, layout: str, coords: str) -> None:
    """Velocity into the DVL frame FRD, altitude the mean vertical range, time from the Y2K clock or
    (Explorer) the two-digit one, attitude and pressure from the leader."""
    path = _file(tmp_path, layout=layout, coords=coords, ea_deg=7.5, profile_cells=2)
    imported, dvl = _read(path)
    np.testing.assert_allclose(dvl.v_sensor_mps, np.tile(V_FRD, (5, 1)), atol=MM)
    assert dvl.valid.all()
    np.testing.assert_allclose(dvl.altitude_m, 2.0, atol=1e-9)
    np.testing.assert_allclose(dvl.t_s, T0 + 0.2 * np.arange(5), atol=1e-6)
    att = imported.streams["attitude"]
    np.testing.assert_allclose(np.degrees(att.heading_rad), 30.0 + np.arange(5), atol=1e-9)
    np.testing.assert_allclose(np.degrees(att.pitch_rad), 4.0, atol=1e-9)
    np.testing.assert_allclose(imported.streams["pressure"].pressure_pa, 2.0e5)
    assert imported.pressure_type == "sea" and imported.heading_reference == "magnetic"
    assert imported.counts.read["velocity profile records (not used)"] == 5


def test_ship_coordinates_with_tilts_are_unlevelled(tmp_path: Path) -> None:
    _, dvl = _read(_file(tmp_path, coords="ship", tilts=True, ea_deg=-12.0))
    np.testing.assert_allclose(dvl.v_sensor_mps, np.tile(V_FRD, (5, 1)), atol=MM)


def test_heading_alignment_rotates_instrument_coordinates(tmp_path: Path) -> None:
    """Instrument velocities read without the heading alignment EA stay in the instrument's axes."""
    _, with_ea = _read(_file(tmp_path, coords="instrument", ea_deg=45.0))
    raw = tmp_path / "raw.pd0"
    data = bytearray(_file(tmp_path, coords="instrument", ea_deg=45.0).read_bytes())
    # The same ensembles with EA cleared (and the checksums mended): the velocity is not turned.
    pos = 0
    while pos < len(data):
        n = int.from_bytes(data[pos + 2 : pos + 4], "little")
        fixed = pos + int.from_bytes(data[pos + 6 : pos + 8], "little")
        data[fixed + 26 : fixed + 28] = b"\x00\x00"
        data[pos + n : pos + n + 2] = (sum(data[pos : pos + n]) & 0xFFFF).to_bytes(2, "little")
        pos += n + 2
    raw.write_bytes(bytes(data))
    _, without = _read(raw)
    angle = np.degrees(np.arctan2(with_ea.v_sensor_mps[:, 1], with_ea.v_sensor_mps[:, 0]))
    turned = np.degrees(np.arctan2(without.v_sensor_mps[:, 1], without.v_sensor_mps[:, 0]))
    # Beam 3 points 45 degrees clockwise of the bow, so in the instrument's axes the vehicle's
    # velocity lies 45 degrees anticlockwise of where it lies in the vehicle's.
    np.testing.assert_allclose((turned - angle + 180) % 360 - 180, -45.0, atol=0.3)


def test_three_beam_solution_and_bad_velocity(tmp_path: Path) -> None:
    _, dvl = _read(_file(tmp_path, coords="beam", bad_beam=2))
    np.testing.assert_allclose(dvl.v_sensor_mps, np.tile(V_FRD, (5, 1)), atol=MM)
    assert dvl.valid.all()
    _, bad = _read(_file(tmp_path, coords="ship", v_frd_mps=None))
    assert not bad.valid.any() and np.all(bad.v_sensor_mps == 0.0)


def test_heading_bias_means_true_heading(tmp_path: Path) -> None:
    imported, _ = _read(_file(tmp_path, eb_deg=2.2))
    assert imported.heading_reference == "true" and "EB" in imported.heading_rule


def test_bottom_velocity_convention(tmp_path: Path) -> None:
    _, dvl = _read(_file(tmp_path, coords="ship"), bottom_velocity="bottom")
    np.testing.assert_allclose(dvl.v_sensor_mps, -np.tile(V_FRD, (5, 1)), atol=MM)


def test_no_bottom_track_is_refused(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match=r"no bottom-track data \(ID 0006\) in any of its 5 ensembles"):
        _read(_file(tmp_path, bottom_track=False, profile_cells=4))


@pytest.mark.parametrize(
    ("damage", "where", "message"),
    [
        ("truncate", lambda n: 2 * n, "ensemble 3 is truncated"),
        ("checksum", lambda n: 2 * n + n - 2, "ensemble 3: checksum"),
        ("junk", lambda n: 2 * n, "expected an ensemble header 7F 7F, found 00 11"),
        ("short_leader", lambda n: None, "the bottom track has 20 bytes; its layout needs at least 32"),
    ],
)
def test_damaged_files_name_the_byte(tmp_path: Path, damage: str, where, message: str) -> None:
    path = _file(tmp_path)
    data = bytearray(path.read_bytes())
    n = len(data) // 5
    if damage == "truncate":
        data = data[: 2 * n + n // 2]
    elif damage == "checksum":
        data[2 * n + n - 2] ^= 0xFF
    elif damage == "junk":
        data[2 * n : 2 * n] = b"\x00\x11\x22"
    else:
        # The bottom track starts 20 bytes before the checksum: declare the ensemble 65 bytes shorter.
        data = bytearray(
            pack_ensemble(
                number=1,
                t=T0,
                v_frd_mps=V_FRD,
                ranges_m=(2, 2, 2, 2),
                heading_deg=0,
                pitch_deg=0,
                roll_deg=0,
                sea_pressure_pa=0,
            )
        )
        nbytes = int.from_bytes(data[2:4], "little") - 65
        data = data[:nbytes]
        data[2:4] = nbytes.to_bytes(2, "little")
        data += (sum(data) & 0xFFFF).to_bytes(2, "little")
    path.write_bytes(bytes(data))
    with pytest.raises(FormatError, match=message) as err:
        _read(path)
    assert str(path) in str(err.value) and "byte " in str(err.value) and "\n" not in str(err.value)
    if where(n) is not None:
        assert err.value.byte == where(n)


def test_skip_bad_ensembles(tmp_path: Path) -> None:
    path = _file(tmp_path)
    data = bytearray(path.read_bytes())
    n = len(data) // 5
    data[n + 40] ^= 0xFF  # ensemble 2's checksum no longer matches
    path.write_bytes(bytes(data))
    imported, dvl = _read(path, skip_bad_ensembles=True)
    assert len(dvl) == 4
    skipped = imported.counts.summary()["skipped"]
    assert next(iter(skipped.values()))["count"] == 1
    assert math.isclose(dvl.t_s[1] - dvl.t_s[0], 0.4, abs_tol=1e-6)
