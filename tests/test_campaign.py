"""``auvnav campaign``: two small simulated surveys of one site (the second three days later, its
tallest coral head removed) put in one frame through inter-dive loop closures verified from the
truth, scored by ``auvnav evaluate CAMPAIGN``."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.spatial import cKDTree

from auvnav.cli import main
from auvnav.pipeline import run_stage
from auvnav.sim.repeat import CHANGE_FILE, simulate_repeat
from auvnav.sim.run import run_scenario
from auvnav.sim.seafloor import Seafloor
from auvnav.slam.stage import SlamSettings
from auvnav.trajectory import read_trajectory

GEOMETRY = {"width_m": 14.0, "height_m": 8.0, "lead_in_m": 5.0}


@pytest.fixture(scope="module")
def dives(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("campaign")
    a, b = root / "first", root / "repeat"
    run_scenario("survey", a, seed=21, truth_loops=True, geometry=GEOMETRY)
    simulate_repeat(a, b, seed=22, days_later=3.0, truth_loops=True, geometry=GEOMETRY)
    for d in (a, b):
        run_stage(
            d, "slam", SlamSettings(loops=d / "truth/loops.csv", tide=d / "truth/tide.csv", marginal_every=5)
        )
    return a, b


def test_the_repeat_survey_flies_the_same_site_with_a_coral_head_gone(dives: tuple[Path, Path]) -> None:
    a, b = dives
    ta = yaml.safe_load((a / "truth/truth.yaml").read_text(encoding="utf-8"))
    tb = yaml.safe_load((b / "truth/truth.yaml").read_text(encoding="utf-8"))
    assert tb["seafloor"]["seed"] == ta["seafloor"]["seed"] == 21
    assert tb["seed"] == 22 and tb["site"]["start_time"] != ta["site"]["start_time"]
    removed = yaml.safe_load((b / CHANGE_FILE).read_text(encoding="utf-8"))["removed"][0]
    assert removed["height_m"] >= 0.5 and removed["area_m2"] > 1.0
    before = Seafloor(21).depth_m(removed["north_m"], removed["east_m"])
    params = {k: tuple(v) if isinstance(v, list) else v for k, v in tb["seafloor"].items() if k != "seed"}
    from auvnav.sim.seafloor import SeafloorParams

    after = Seafloor(21, SeafloorParams(**params)).depth_m(removed["north_m"], removed["east_m"])
    assert after - before == pytest.approx(removed["height_m"], rel=0.05)  # the floor is deeper there


@pytest.fixture(scope="module")
def campaign(dives: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("campaign_out") / "campaign"
    args = ["campaign", *map(str, dives), "--out", str(out), "--truth-loops", "--false-loops", "0.2", "-q"]
    assert main([*args, "--json"]) == 0
    return out


def test_campaign_products_and_scores(
    dives: tuple[Path, Path], campaign: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    summary = json.loads((campaign / "summary.json").read_text(encoding="utf-8"))
    pair = summary["inter_dive"][0]
    assert pair["verified"] > 100 and 0 < pair["kept"] < pair["verified"]
    for name in summary["dives"]:
        traj = read_trajectory(campaign / "dives" / name / "trajectory.csv")
        assert len(traj.t_s) > 100
    loops = pd.read_csv(campaign / "inter_dive_loops.csv")
    assert len(loops) == pair["verified"] and loops["kept"].sum() == pair["kept"]
    capsys.readouterr()
    assert main(["evaluate", str(campaign), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out)["campaign"]
    assert scores["inter_dive_loop_precision"] >= 0.99
    assert scores["inter_dive_false_rejected"] > 0
    assert scores["inter_dive_rmse_m"] < 0.03
    assert scores["overlap_pairs"] > 50


def test_campaign_refuses_bad_input(
    dives: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One dive, a dive twice, a folder that is no dive, dives without images and no --truth-loops:
    known errors, no traceback, nothing written."""
    a, b = dives
    for args in ([a], [a, a], [a, tmp_path], [a, b]):
        capsys.readouterr()
        truth = ["--truth-loops"] if args != [a, b] else []
        assert main(["campaign", *map(str, args), "--out", str(tmp_path / "c"), *truth, "-q"]) == 1
        err = capsys.readouterr().err
        assert "auvnav: error:" in err and "Traceback" not in err
    assert "give --truth-loops" in err
    assert not (tmp_path / "c").exists()


def test_dem_difference_finds_the_removed_coral_head(
    dives: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """DEMs made from each dive's true seafloor where its SLAM placed it (5 cm cells, elevation = -depth,
    as products/recon/dem.tif) around the removed mound: the campaign's DEM difference finds it, its
    area and height as the truth's, and nothing else."""
    import rasterio

    from auvnav.dive import read_dive_info, vehicle_file_name
    from auvnav.raster import MapGrid, write_geotiff
    from auvnav.sim.camera import default_stereo_rig, seafloor_from_truth
    from auvnav.vehicle import read_vehicle, write_vehicle

    removed = yaml.safe_load((dives[1] / CHANGE_FILE).read_text(encoding="utf-8"))["removed"][0]
    copies = []
    for d in dives:
        copy = tmp_path / d.name
        shutil.copytree(d, copy)
        origin = read_dive_info(copy).origin
        centre = np.array([removed["north_m"], removed["east_m"]])
        grid = MapGrid.covering(np.stack([centre - 6.0, centre + 6.0]), origin, 0.05)
        # As a reconstruction placed with the dive's own SLAM: the floor where SLAM put it.
        slam = read_trajectory(copy / "products/slam/trajectory.csv")
        truth = read_trajectory(copy / "truth/trajectory.csv").interpolate(slam.t_s)
        near = np.hypot(*(truth.p_ned_m[:, :2] - centre).T) <= 6.0
        error = np.median(slam.p_ned_m[near, :2] - truth.p_ned_m[near, :2], axis=0)
        ne = grid.cell_centres_ned() - error
        depth = seafloor_from_truth(copy / "truth/truth.yaml").depth_m(ne[..., 0], ne[..., 1])
        dem = np.stack([-depth, np.full_like(depth, 0.01)]).astype(np.float32)
        path = copy / "products/recon/dem.tif"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_geotiff(path, dem, grid, nodata=np.nan, overviews=False)
        # A stereo rig: the cells each dive's images saw (support) can be counted.
        vehicle = copy / (vehicle_file_name(copy) or "vehicle.yaml")
        write_vehicle(dataclasses.replace(read_vehicle(vehicle), stereo=default_stereo_rig()), vehicle)
        copies.append(copy)
    # The SLAM summaries name their loop and tide files in the original folders: still there.
    out = tmp_path / "campaign"
    assert main(["campaign", *map(str, copies), "--out", str(out), "--truth-loops", "-q"]) == 0
    regions = pd.read_csv(out / "changes.csv")
    assert len(regions) >= 1 and (out / "dem_difference.tif").is_file()
    with rasterio.open(out / "dem_difference.tif") as src:
        diff = src.read(1)
    # Both DEMs cover the whole square, the dives' images not: cells outside them are no difference.
    assert 0.05 < np.isnan(diff).mean() < 0.9
    capsys.readouterr()
    assert main(["evaluate", str(out), "--json"]) == 0
    scores = json.loads(capsys.readouterr().out)["campaign"]
    assert scores["change_found"]
    assert scores["change_area_m2"] == pytest.approx(scores["change_area_true_m2"], rel=0.2)
    assert scores["change_height_m"] == pytest.approx(removed["height_m"], rel=0.2)
    assert scores["false_change_max_area_m2"] <= 0.25


def test_simulate_repeat_command(
    dives: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``auvnav simulate survey --repeat-of DIVE``: the same site's seafloor, the repeat's own seed and
    tide; the first dive's seed, or a folder that is no simulated dive, refused."""
    a, _ = dives
    geometry = ["--width-m", "14", "--height-m", "8", "--lead-in-m", "5", "--no-images", "-q"]
    out = tmp_path / "repeat"
    args = ["simulate", "survey", "--repeat-of", str(a), "--out", str(out), *geometry]
    assert main([*args, "--seed", "23", "--keep-coral", "--days-later", "1.5"]) == 0
    truth = yaml.safe_load((out / "truth/truth.yaml").read_text(encoding="utf-8"))
    assert truth["seafloor"]["seed"] == 21 and truth["seed"] == 23
    assert truth["site"]["start_time"].startswith("2009-10-16T13")  # 1.5 days after the default start
    change = yaml.safe_load((out / CHANGE_FILE).read_text(encoding="utf-8"))
    assert change["site_seed"] == 21 and "removed" not in change
    for bad in (["--seed", "21"], ["--seed", "24", "--repeat-of", str(tmp_path)]):
        capsys.readouterr()
        assert main([*args, *bad, "--overwrite"]) == 1
        err = capsys.readouterr().err
        assert "auvnav: error:" in err and "Traceback" not in err


def test_images_of_two_dives_register(dives: tuple[Path, Path], tmp_path: Path) -> None:
    """The repeat survey's images show the site's seafloor (its texture seeded by the site, not the
    dive), so the loop stage's registration (:class:`auvnav.campaign.ImageRegistration`) verifies
    pairs of images of the two dives with their true relative pose; pairs that do not overlap, their
    prior saying they do, do not verify."""
    from auvnav.campaign import ImageRegistration
    from auvnav.dive import ImageIndex, vehicle_file_name
    from auvnav.frames import se3, se3_inverse
    from auvnav.sim.camera import (
        body_poses,
        default_stereo_rig,
        render_dive_images,
        render_images,
        scale_camera_rig,
        seafloor_from_truth,
    )
    from auvnav.sim.texture import SeafloorTexture
    from auvnav.streams import read_stream
    from auvnav.vehicle import read_vehicle, write_vehicle

    a, b = (tmp_path / d.name for d in dives)
    for d, copy in zip(dives, (a, b), strict=True):
        shutil.copytree(d, copy, ignore=shutil.ignore_patterns("products", "images"))
    render_dive_images(b, scale=0.25, rate_hz=0.04, seed=22)
    assert yaml.safe_load((b / "truth/imaging.yaml").read_text(encoding="utf-8"))["texture"]["seed"] == 21
    # The first dive's images where it passed nearest to the repeat's.
    index_b = read_stream(ImageIndex, b / "images/index.csv", "images/index.csv")
    T_b = body_poses(read_trajectory(b / "truth/trajectory.csv").interpolate(index_b.t_s))
    truth_a = read_trajectory(a / "truth/trajectory.csv")
    dist, nearest = cKDTree(truth_a.p_ned_m).query(T_b[:, :3, 3])
    times, rows_a = np.unique(truth_a.t_s[nearest], return_inverse=True)
    rig = scale_camera_rig(default_stereo_rig(), 0.25)
    render_images(
        truth_a, seafloor_from_truth(a / "truth/truth.yaml"), rig, times, a / "images",
        texture=SeafloorTexture(seed=21), seed=21,
    )  # fmt: skip
    vehicle = a / (vehicle_file_name(a) or "vehicle.yaml")
    write_vehicle(dataclasses.replace(read_vehicle(vehicle), stereo=rig), vehicle)
    T_a = body_poses(truth_a.interpolate(times))
    rows_b = np.arange(len(index_b.t_s))
    near = dist < 0.3
    assert near.sum() >= 10
    # Overlapping pairs, their prior 25 cm off; pairs 3 m or more apart, their prior an overlap.
    ra, rb = rows_a[near], rows_b[near]
    T_true = se3_inverse(T_a[ra]) @ T_b[rb]
    prior = T_true.copy()
    prior[:, :2, 3] += [0.2, -0.15]
    far_b = rows_b[np.argsort(-np.linalg.norm(T_b[:, :2, 3] - T_a[rows_a[0], :2, 3], axis=1))[:5]]
    assert np.all(np.linalg.norm(T_b[far_b, :2, 3] - T_a[rows_a[0], :2, 3], axis=1) > 3.0)
    ra = np.concatenate([ra, np.full(5, rows_a[0])])
    rb = np.concatenate([rb, far_b])
    prior = np.concatenate([prior, np.broadcast_to(se3(np.eye(3), np.zeros(3)), (5, 4, 4))])
    ok, T, C = ImageRegistration([a, b])(0, ra, 1, rb, prior, np.full(len(ra), 0.3))
    n = int(near.sum())
    assert ok[:n].mean() >= 0.6 and not ok[n:].any()
    error = np.linalg.norm(T[:n][ok[:n], :3, 3] - T_true[ok[:n], :3, 3], axis=1)
    assert error.max() < 0.03
    assert np.all(np.isfinite(C[ok]))
