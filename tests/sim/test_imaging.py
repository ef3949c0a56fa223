"""Underwater image formation of the simulator's camera (issue 20): water, scattering, sensor, texture."""

from __future__ import annotations

import numpy as np
import pytest

from auvnav.frames import euler2rot, se3
from auvnav.sim.camera import (
    Lighting,
    _backscatter,
    _dn_per_signal,
    default_stereo_rig,
    render_stereo_pair,
    scale_camera_rig,
    water_type,
)
from auvnav.sim.texture import SeafloorTexture

RIG = scale_camera_rig(default_stereo_rig(), 0.15)


def pose(floor_m: float, altitude_m: float = 2.0) -> np.ndarray:
    return se3(euler2rot(0.4, 0.0, 0.0), np.array([1.0, 2.0, floor_m - altitude_m]))


def test_water_types_follow_jerlov() -> None:
    """Red is lost first in clear ocean water, blue in coastal water; turbid attenuates most."""
    clear, coastal, turbid = (water_type(w) for w in ("clear", "coastal", "turbid"))
    assert clear.K[0] > clear.K[1] and clear.K[0] > clear.K[2]  # red attenuates most (Jerlov IB)
    assert coastal.K[2] > coastal.K[1]  # yellow substance: blue worse than green (3C)
    assert np.all(turbid.K > coastal.K) and np.all(coastal.K > clear.K)
    for w in (clear, coastal, turbid):
        assert np.all(w.c > w.K)  # the sharp image attenuates faster than the light that forms it
    assert (
        turbid.scattering_per_m[1] / turbid.absorption_per_m[1]
        > clear.scattering_per_m[1] / clear.absorption_per_m[1]
    )
    with pytest.raises(ValueError, match="water must be one of"):
        water_type("muddy")  # type: ignore[arg-type]


def test_colour_render_and_monochrome_camera(level_floor) -> None:
    floor = level_floor(20.0)
    left, right = render_stereo_pair(floor, SeafloorTexture(seed=1), RIG, pose(20.0))
    assert left.shape == (154, 204, 3) and right.shape == left.shape and left.dtype == np.uint8
    _, g, r = (left[..., k].mean() for k in range(3))
    assert r < g  # clear ocean water: the red is attenuated most
    grey, _ = render_stereo_pair(
        floor, SeafloorTexture(seed=1), RIG, pose(20.0), lighting=Lighting(bayer=False)
    )
    assert grey.shape == (154, 204)


def test_a_raw_camera_writes_the_mosaic_its_colour_image_is_made_from(level_floor, tmp_path) -> None:
    """``Lighting(raw=True)``: the same exposure (same noise) as the colour camera's, before its
    demosaicing, at 12 bits; read back by its filter it is the colour image's luminance."""
    import cv2

    from auvnav.sim.camera import to_grey
    from auvnav.vision.stereo import read_grey

    floor = level_floor(20.0)
    colour, _ = render_stereo_pair(floor, SeafloorTexture(seed=1), RIG, pose(20.0))
    raw, _ = render_stereo_pair(floor, SeafloorTexture(seed=1), RIG, pose(20.0), lighting=Lighting(raw=True))
    assert raw.shape == colour.shape[:2] and raw.dtype == np.uint16 and raw.max() <= 4095
    assert raw.max() > 255  # 12 bits, not 8
    # the red sites hold the colour image's red, 16 levels a DN
    assert raw[0::2, 0::2].mean() / 16 == pytest.approx(colour[0::2, 0::2, 2].mean(), abs=1.0)
    cv2.imwrite(str(tmp_path / "raw.png"), raw)
    grey, truth = read_grey(tmp_path / "raw.png", "rggb"), to_grey(colour)
    assert grey is not None
    inner = (slice(2, -2), slice(2, -2))
    assert np.corrcoef(grey[inner].ravel(), truth[inner].ravel())[0, 1] > 0.98
    with pytest.raises(ValueError, match="colour"):
        Lighting(raw=True, bayer=False)


def test_turbid_water_adds_a_veil_and_blurs() -> None:
    """Backscatter along a ray to a floor 2 m away, and the share of the returning light that arrives
    unscattered (sharp): more veil and less sharp light in turbid than in clear water."""
    c = np.zeros(3)
    d = np.array([[0.0, 0.0, 1.0]])
    s = np.array([2.0])
    veil, sharp = {}, {}
    for w in ("clear", "turbid"):
        water = water_type(w)
        veil[w] = _backscatter(c, d, s, np.eye(4), Lighting(water=water))[0] * _dn_per_signal(
            Lighting(water=water)
        )
        sharp[w] = np.exp(-(water.c - water.K) * s[0])
    assert np.all(veil["turbid"] > 5 * veil["clear"]) and np.all(veil["turbid"] > 5.0)  # digital numbers
    assert np.all(sharp["turbid"] < 0.3) and np.all(sharp["clear"] > 0.5)


def test_motion_blur_smears_along_the_track(level_floor) -> None:
    """At 2 m/s during a 20 ms flash the image loses detail, most of it along the motion."""
    floor = level_floor(20.0)
    T = se3(np.eye(3), np.array([0.0, 0.0, 18.0]))  # heading north: the image's rows run along the track
    lighting = Lighting(flash_s=0.02, bayer=False, read_noise_e=0.0, full_well_e=1e9)
    still, _ = render_stereo_pair(floor, SeafloorTexture(seed=4), RIG, T, lighting=lighting)
    moving, _ = render_stereo_pair(
        floor, SeafloorTexture(seed=4), RIG, T, lighting=lighting, v_ned_mps=np.array([2.0, 0.0, 0.0])
    )
    s, m = still.astype(float), moving.astype(float)
    along = np.abs(np.diff(m, axis=0)).mean() / np.abs(np.diff(s, axis=0)).mean()  # image y: forward
    across = np.abs(np.diff(m, axis=1)).mean() / np.abs(np.diff(s, axis=1)).mean()
    assert along < 0.6 and along < 0.75 * across


def test_texture_has_featureless_sand_and_ripple_fields() -> None:
    """Over a 40 m square: patches with almost no detail, and straight regular ripples elsewhere."""
    tex = SeafloorTexture(seed=0)
    rng = np.random.default_rng(0)
    centres = rng.uniform(-20, 20, (200, 2))
    u = np.arange(32) * 0.01  # 32 cm patches at 1 cm
    stds = []
    for n0, e0 in centres:
        n, e = np.meshgrid(n0 + u, e0 + u, indexing="ij")
        stds.append(float(tex.albedo(n, e).std()))
    stds = np.array(stds)
    assert (stds < 0.015).mean() > 0.02  # featureless sand somewhere (2% albedo contrast at most)
    assert (stds > 0.05).mean() > 0.4  # and texture elsewhere
    rgb = tex.albedo_rgb(*np.meshgrid(u, u, indexing="ij"))
    assert rgb.shape == (32, 32, 3) and 0.01 <= rgb.min() and rgb.max() <= 0.95
