"""The reconstruction stage on a tiny dive with a revisit: products that other tools open, a DEM and an
orthophoto that match the simulated seafloor, the false-relief check, and bad input."""

from __future__ import annotations

import json
import logging
import shutil

import numpy as np
import pandas as pd
import pytest

from auvnav import products as P
from auvnav.cli import main
from auvnav.evaluate import align_yaw_translation
from auvnav.pipeline import run_stage
from auvnav.raster import ned2map
from auvnav.recon.evaluate import recon_section
from auvnav.recon.stage import ReconSettings

SETTINGS = {"tile_m": 2.56, "voxel_m": 0.02}
MM = 1e-3  # 1 millimetre


@pytest.fixture(scope="module")
def reconstructed(recon_dive) -> dict:
    settings = ReconSettings(tide=recon_dive.tide_file, **SETTINGS)
    return run_stage(recon_dive.path, "recon", settings, workers=1)


def test_products_open_in_open3d_trimesh_and_rasterio(recon_dive, reconstructed) -> None:
    import rasterio
    import trimesh

    from auvnav.recon.o3d import open3d

    folder = P.stage_dir(recon_dive.path, "recon")
    mesh = open3d().io.read_triangle_mesh(str(folder / "mesh.ply"))
    assert len(mesh.triangles) > 1000 and mesh.has_vertex_colors()
    tm = trimesh.load(folder / "mesh.ply", process=False)
    assert len(tm.faces) == len(mesh.triangles) == reconstructed["mesh"]["faces"]
    # x east, y north, z up about the origin: on the true floor (quarter-scale pairs: 2.6 cm a pixel)
    v = np.asarray(tm.vertices)
    error = np.abs(-v[:, 2] - recon_dive.floor.depth_m(v[:, 1], v[:, 0]))
    assert np.median(error) < 0.02 and np.percentile(error, 95) < 0.1
    assert -1.0 < np.median(tm.vertices[:, 1]) < 4.0 and -1.0 < np.median(tm.vertices[:, 0]) < 1.2
    track = ned2map(recon_dive.truth.p_ned_m[:, :2], _origin(recon_dive))
    for name, bands in (("dem.tif", 2), ("mosaic.tif", 1)):
        with rasterio.open(folder / name) as src:
            assert src.crs.to_epsg() == 32751
            assert src.count == bands and src.profile["compress"] == "deflate"
            b = src.bounds
            inside = (
                (track[:, 0] > b.left)
                & (track[:, 0] < b.right)
                & (track[:, 1] > b.bottom)
                & (track[:, 1] < b.top)
            )
            assert inside.all(), f"{name}: the track lies outside the raster's bounds {b}"
            assert b.right - b.left < 8.0 and b.top - b.bottom < 8.0
    with rasterio.open(folder / "mosaic.tif") as src:
        assert src.overviews(1)[:2] == [2, 4]
        assert 0.1 < np.mean(src.read(1) > 0) <= 1.0


def _origin(recon_dive):
    from auvnav.dive import read_dive_info

    return read_dive_info(recon_dive.path).origin


def test_dem_and_orthophoto_match_the_simulated_seafloor(recon_dive, reconstructed) -> None:
    scores = recon_section(
        recon_dive.path, recon_dive.truth, recon_dive.floor, recon_dive.texture, align_yaw_translation
    )
    assert scores is not None and scores["pairs"] == 16
    assert scores["dem_cells"] > 20_000
    assert scores["dem_rmse_m"] < 25 * MM  # quarter-scale images: 340 px wide
    assert scores["mosaic_blocks"] >= 4
    assert scores["mosaic_misregistration_median_px"] < 1.0
    assert reconstructed["pairs"]["used"] == 16 and reconstructed["pairs"]["failed"] == 0


def test_false_relief_of_the_tide_is_found_and_removed(recon_dive, reconstructed) -> None:
    relief = pd.read_csv(P.RECON_RELIEF.path(recon_dive.path))
    assert len(relief) >= 1 and (relief["dt_s"] > 1200).all()
    t = recon_dive.truth.t_s[0]
    change = recon_dive.tide.predict(np.array([t + 1256.0])) - recon_dive.tide.predict(np.array([t + 3.0]))
    # Placed with pressure depth, the second visit sits the tide's rise lower (elevation): a false step.
    assert np.allclose(relief["step_before_m"], -change, atol=0.03)
    assert np.all(np.abs(relief["step_after_m"]) < 0.02)
    assert np.all(np.abs(relief["step_placed_m"]) < 0.02)  # the SLAM trajectory is below the datum
    assert relief["false_relief_before"].all() and not relief["false_relief_after"].any()
    assert reconstructed["relief"]["removed_pct"] > 90


def test_a_pair_whose_dense_stereo_fails_is_skipped_and_named(recon_dive, tmp_path, caplog) -> None:
    import cv2

    from auvnav.dive import read_dive
    from auvnav.executor import SerialExecutor
    from auvnav.recon.reconstruct import ReconInputs, reconstruct
    from auvnav.trajectory import read_trajectory

    dive_path = tmp_path / "dive"
    shutil.copytree(recon_dive.path, dive_path, ignore=shutil.ignore_patterns("products"))
    bad = dive_path / "images" / "right" / "000002.png"
    cv2.imwrite(str(bad), np.zeros((256, 340), np.uint8))  # a black right image: nothing to match
    dive = read_dive(dive_path)
    inputs = ReconInputs(read_trajectory(recon_dive.path / "products/slam/trajectory.csv"), "slam")
    out = tmp_path / "out"
    out.mkdir()
    with caplog.at_level(logging.WARNING), SerialExecutor() as ex:
        summary = reconstruct(dive, inputs, out, pairs=np.arange(5), executor=ex,
                              fusion=ReconSettings(**{**SETTINGS, "voxel_m": 0.0}).fusion())  # fmt: skip
    assert summary["pairs"]["failed"] == 1 and summary["pairs"]["used"] == 4
    assert any("right/000002.png" in r.message and "dense stereo failed" in r.message for r in caplog.records)
    pairs = pd.read_csv(out / "pairs.csv")
    assert pairs.loc[pairs["i"] == 2, "status"].item() == "failed" and summary["mesh"] is None


def test_a_dive_without_images_says_recon_needs_them(small_dive, tmp_path, capsys) -> None:
    from auvnav.dive import write_dive

    write_dive(small_dive(), tmp_path / "dive")
    assert main(["recon", str(tmp_path / "dive")]) == 1
    err = capsys.readouterr().err
    assert "reconstruction needs stereo images" in err and "Traceback" not in err


def test_the_summary_says_what_placed_the_maps(recon_dive, reconstructed) -> None:
    summary = json.loads(P.RECON_SUMMARY.path(recon_dive.path).read_text())
    assert summary["trajectory"] == "slam" and summary["trajectory_file"] == "products/slam/trajectory.csv"
    assert summary["tide"]["source"].startswith(str(recon_dive.tide_file))
    assert summary["dense"]["width_px"] == 340 and summary["fusion"]["tsdf"] == "blockgrid"


@pytest.mark.parametrize("shift_px", [20, 45])
def test_a_floor_nearer_than_the_search_fails_the_pair(recon_dive, monkeypatch, shift_px) -> None:
    import cv2

    from auvnav.recon import dense as D
    from auvnav.vehicle import read_vehicle
    from auvnav.vision.camera import rectification

    rig = read_vehicle(recon_dive.path / "vehicle.yaml").stereo
    rect = rectification(rig)
    settings = D.DenseSettings()
    geom = D.DenseGeometry.of(rig, rect, settings)
    top = geom.min_disparity + geom.num_disparities - 1
    assert 20 < top < 45  # one shift inside the disparity search, one beyond it (a floor too near)
    noise = np.random.default_rng(0).integers(0, 256, (geom.height, geom.width + 120)).astype(np.float32)
    blurred = cv2.GaussianBlur(noise, (0, 0), 3.0)  # a texture smooth over a few pixels, as the reef's
    texture = cv2.normalize(blurred, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    left = texture[:, 60 : 60 + geom.width]
    right = texture[:, 60 + shift_px : 60 + shift_px + geom.width]  # left x is right x - shift
    monkeypatch.setattr(D, "prepare_pair", lambda *args: (left, right))
    if shift_px < top:
        dense = D.dense_pair(left, right, rig, rect, geom, settings)
        assert abs(np.nanmedian(dense.disparity_px) - shift_px) < 0.1
    else:
        with pytest.raises(D.DenseFailed, match="nearer than min_range_m"):
            D.dense_pair(left, right, rig, rect, geom, settings)
