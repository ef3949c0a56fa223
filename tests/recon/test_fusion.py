"""The TSDF of one tile: a depth map with nothing in range adds nothing (Open3D would refuse it)."""

from __future__ import annotations

import numpy as np

from auvnav.recon.dense import DenseGeometry
from auvnav.recon.fusion import FusionSettings, _Tsdf


def test_a_depth_map_with_no_depth_in_range_is_left_out() -> None:
    geom = DenseGeometry(
        f_px=400.0, cx_px=160.0, cy_px=120.0, baseline_m=0.1, width=320, height=240, R1=np.eye(3),
        scale=0.5, min_disparity=0, num_disparities=64,
    )  # fmt: skip
    tsdf = _Tsdf(FusionSettings(), geom, np.zeros(2), 0.0, max_range_m=3.0)
    image = np.full((240, 320), 128, np.uint8)
    T = np.eye(4)  # camera at the tile's origin looking down (+z is down in NED)
    tsdf.integrate(np.zeros((240, 320), np.float32), image, T)  # all zero: nothing matched
    tsdf.integrate(np.full((240, 320), 50.0, np.float32), image, T)  # beyond the range
    sliver = np.zeros((240, 320), np.float32)
    sliver[101, 33] = 2.0  # one pixel in range, between the pixels Open3D samples: no block touched
    tsdf.integrate(sliver, image, T)
    assert len(tsdf.mesh(np.eye(2), np.zeros(2))[2]) == 0
    tsdf.integrate(np.full((240, 320), 2.0, np.float32), image, T)  # a floor 2 m below
    assert len(tsdf.mesh(np.eye(2), np.zeros(2))[2]) > 0
