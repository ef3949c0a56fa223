"""The loop-closure stage end to end on a tiny rendered dive: command, products, cache, bad input."""

from __future__ import annotations

import itertools
import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from auvnav.cli import main
from auvnav.dive import read_dive
from auvnav.evaluate import read_truth
from auvnav.sim.camera import default_stereo_rig, rggb_mosaic
from auvnav.vehicle import read_vehicle, write_vehicle
from auvnav.vision.camera import rectification
from auvnav.vision.evaluate import loops_section
from auvnav.vision.features import FeatureSettings
from auvnav.vision.loopfile import read_loops
from auvnav.vision.loops import LoopSettings, find_loops
from auvnav.vision.stage import read_prior
from auvnav.vision.stereo import cache_path, pair_features, read_features

FAST = LoopSettings(features=FeatureSettings(max_features=1500))


@pytest.fixture(scope="module")
def loops_run(tiny_dive):
    """``auvnav loops DIVE --json --workers 1`` once; its printed summary."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["loops", str(tiny_dive.path), "--json", "--workers", "1"])
    assert code == 0
    return json.loads(out.getvalue())


def test_command_writes_loops_that_match_the_truth(tiny_dive, loops_run) -> None:
    loops = read_loops(tiny_dive.path / "products" / "vision" / "loops.csv", n_poses=20)
    assert loops_run["consecutive_tested"] == 19
    assert loops_run["nonconsecutive_accepted"] > 3
    assert len(loops) == loops_run["loops_accepted"]
    assert np.all(loops.i < loops.j)
    scores = loops_section(tiny_dive.path, read_truth(tiny_dive.path), 0.0)
    assert scores is not None
    assert scores["recall"] >= 0.8
    assert scores["precision"] >= 0.95
    assert scores["translation_error_median_m"] < 0.02  # 340 px images: coarser than the acceptance dive
    assert scores["rotation_error_median_deg"] < 0.5
    assert 1.0 < scores["mahalanobis_mean"] < 20.0
    assert scores["candidates_tested"] == loops_run["candidates_tested"]
    # every loop says how it was registered, and the evaluation scores each kind
    assert loops.method is not None and set(loops.method) <= {"features", "images"}
    assert int((loops.method == "images").sum()) == loops_run["direct_accepted"]
    assert sum(kind["n"] for kind in scores["by_method"].values()) == len(loops)


def test_the_report_says_how_many_loops_came_from_the_images(tiny_dive, loops_run, tmp_path: Path) -> None:
    from auvnav.report.content import dive_facts

    dive = tmp_path / "dive"
    (dive / "products" / "vision").mkdir(parents=True)
    for name in ("dive.yaml", "vehicle.yaml"):
        shutil.copy(tiny_dive.path / name, dive / name)
    summary = dive / "products" / "vision" / "summary.json"

    def loop_row(direct: int) -> str:
        summary.write_text(json.dumps({**loops_run, "direct_accepted": direct}), encoding="utf-8")
        return next(f.value for f in dive_facts(dive).figures if f.label.startswith("loop closures"))

    assert loop_row(7).endswith("; 7 from the images")
    assert "images" not in loop_row(0)


def test_features_are_cached(tiny_dive, loops_run) -> None:
    cache = tiny_dive.path / "products" / "cache" / "vision" / "features"
    files = sorted(cache.iterdir())
    assert len(files) == loops_run["pairs_with_features"]
    dive = read_dive(tiny_dive.path)
    rig = dive.vehicle.stereo
    left, right = (tiny_dive.path / "images" / str(n) for n in (dive.images.left[4], dive.images.right[4]))
    settings = FeatureSettings()
    path = cache_path(cache, left, right, rig, settings)
    assert path in files
    stamp = path.stat().st_mtime_ns
    again = pair_features(left, right, rig, rectification(rig), settings, cache)
    assert path.stat().st_mtime_ns == stamp  # read back, not recomputed
    assert len(again) > 100
    fresh = pair_features(left, right, rig, rectification(rig), settings, None)
    # Read back bit for bit: the points are triangulated from the stored grid coordinates.
    for name in ("uv_rect_px", "p_cam_m", "cov_cam_m2", "descriptors"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))
    assert again.sigma_px == fresh.sigma_px
    assert again.thumbnail == fresh.thumbnail and again.thumbnail_scale == fresh.thumbnail_scale
    thumb = again.thumbnail_image()
    assert thumb is not None and thumb.shape == (128, 170)  # half the 340 x 256 image SIFT sees
    assert again.thumbnail_scale == (170 / 340, 128 / 256)
    assert len(again.thumbnail) < thumb.size  # compressed
    features_bytes = path.stat().st_size - len(again.thumbnail)
    assert features_bytes < 100_000 * len(again) / 1400  # under 100 KB for 1,400 features
    # other settings are another cache entry
    assert cache_path(cache, left, right, rig, FeatureSettings(scale=0.5)) != path


def test_a_rerun_finds_every_verification_in_the_cache(tiny_dive, loops_run, tmp_path: Path) -> None:
    """The same dive and cache again: every pair is tested with the same priors, so none is registered
    anew (the network of loops is solved again as it was: test_network)."""
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy)
    result = find_loops(read_dive(copy), read_prior(copy))
    assert loops_run["network_solves"] >= 1
    assert result.summary["network_solves"] == loops_run["network_solves"]
    assert result.summary["verifications_reused"] >= result.summary["candidates_tested"]
    assert result.summary["loops_accepted"] == loops_run["loops_accepted"]


def test_a_key_that_ends_in_a_zero_byte_is_found_in_the_cache(tiny_dive, tmp_path: Path, monkeypatch) -> None:
    """One verification key in 256 ends in 0x00, which NumPy's bytes fields drop on reading: those
    verifications are found again all the same (CI once ran into one)."""
    from auvnav.vision import loops as stage_loops

    work_items = stage_loops._work_items

    def zero_last_byte(*args: object) -> list:
        return [(*w[:-1], w[-1][:-1] + b"\0") for w in work_items(*args)]

    monkeypatch.setattr(stage_loops, "_work_items", zero_last_byte)
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy, ignore=shutil.ignore_patterns("verify"))
    first = find_loops(read_dive(copy), read_prior(copy))
    assert first.summary["verifications_reused"] == 0
    again = find_loops(read_dive(copy), read_prior(copy))
    assert again.summary["verifications_reused"] >= again.summary["candidates_tested"]
    assert again.summary["loops_accepted"] == first.summary["loops_accepted"]


def test_a_corrupt_feature_cache_is_recomputed(tiny_dive, tmp_path: Path, caplog) -> None:
    dive = read_dive(tiny_dive.path)
    rig = dive.vehicle.stereo
    left, right = (tiny_dive.path / "images" / str(n) for n in (dive.images.left[2], dive.images.right[2]))
    settings = FeatureSettings()
    path = cache_path(tmp_path, left, right, rig, settings)
    path.write_bytes(b"AUVNAVF5 truncated")
    with caplog.at_level(logging.WARNING):
        feats = pair_features(left, right, rig, rectification(rig), settings, tmp_path)
    assert "unreadable feature cache" in caplog.text and path.name in caplog.text
    np.testing.assert_array_equal(read_features(path).descriptors, feats.descriptors)


def test_missing_and_corrupt_images_are_skipped_with_a_warning(tiny_dive, tmp_path: Path, caplog) -> None:
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy, ignore=shutil.ignore_patterns("cache"))
    index = copy / "images" / "index.csv"
    index.write_text("\n".join(index.read_text().splitlines()[:9]) + "\n")  # the first 8 pairs
    (copy / "images" / "left" / "000003.png").unlink()
    (copy / "images" / "right" / "000007.png").write_bytes(b"not a png")
    with caplog.at_level(logging.WARNING):
        result = find_loops(read_dive(copy), read_prior(copy), settings=FAST)
    text = caplog.text
    assert "000003.png: image missing" in text
    assert "000007.png: not a readable image" in text
    assert result.summary["pairs_skipped"] == 2
    assert result.summary["loops_accepted"] > 0


def test_calibration_that_does_not_match_the_images_is_one_line(tiny_dive, tmp_path: Path, capsys) -> None:
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy, ignore=shutil.ignore_patterns("products"))
    shutil.copytree(tiny_dive.path / "products" / "nav", copy / "products" / "nav")
    vehicle = read_vehicle(copy / "vehicle.yaml")
    import dataclasses

    write_vehicle(dataclasses.replace(vehicle, stereo=default_stereo_rig()), copy / "vehicle.yaml")
    assert main(["loops", str(copy), "--workers", "1", "-q"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "image is 340x256 but the stereo calibration" in err[0]
    assert not (copy / "products" / "vision").exists()  # nothing left behind


def test_a_dive_of_raw_mosaics_finds_the_loops_of_its_colour_images(
    tiny_dive, tmp_path: Path, capsys
) -> None:
    """The tiny dive's images as a survey camera writes them (raw 12-bit RGGB mosaics in 16-bit PNG,
    ``left_bayer``/``right_bayer`` in vehicle.yaml) give the loops of its colour images; colour images
    where vehicle.yaml says raw are one line from ``auvnav validate`` and from the loop stage, which
    leaves nothing behind."""
    import dataclasses

    import cv2

    colour = find_loops(read_dive(tiny_dive.path), read_prior(tiny_dive.path), settings=FAST)
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy, ignore=shutil.ignore_patterns("products"))
    shutil.copytree(tiny_dive.path / "products" / "nav", copy / "products" / "nav")
    vehicle = read_vehicle(copy / "vehicle.yaml")
    rig = vehicle.stereo
    assert rig is not None
    write_vehicle(dataclasses.replace(vehicle, stereo=rig.with_bayer("rggb", "rggb")), copy / "vehicle.yaml")
    assert main(["validate", str(copy)]) == 1
    assert "image has 3 channels but" in capsys.readouterr().err
    assert main(["loops", str(copy), "--workers", "1", "-q"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "000000.png: image has 3 channels but" in err[0] and "(rggb)" in err[0]
    assert not (copy / "products" / "vision").exists()
    for path in sorted((copy / "images").glob("*/*.png")):
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        cv2.imwrite(str(path), rggb_mosaic(bgr[..., ::-1]).astype(np.uint16) * 16)
    assert main(["validate", str(copy)]) == 0
    mosaics = find_loops(read_dive(copy), read_prior(copy), settings=FAST)
    found = lambda result: {(v.i, v.j) for v in result.tested if v.accepted}  # noqa: E731
    assert len(found(colour)) > 10 and len(found(mosaics) & found(colour)) >= 0.9 * len(found(colour))


def test_without_navigation_the_command_says_what_to_run(tiny_dive, tmp_path: Path, capsys) -> None:
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy, ignore=shutil.ignore_patterns("products"))
    assert main(["loops", str(copy), "-q"]) == 1
    assert "run `auvnav navigate` first" in capsys.readouterr().err


def test_the_prior_through_a_registered_loop_is_exact_when_each_pass_is() -> None:
    """Two passes half a metre apart in opposite directions, the second misplaced by the navigation
    (turned 3 degrees and shifted 36 cm: what a compass deviation leaves); with the loop (5, 34)
    registered, the pair (7, 32) is placed through it to the truth, with the sigma of two 1 m legs
    of dead reckoning and the loop, and the nearer of two loops is the one used."""
    from auvnav.frames import pose6 as to_pose6
    from auvnav.frames import rot_z, se3, se3_inverse
    from auvnav.vision.loops import (
        SHORT_DRIFT_FRACTION,
        SHORT_SIGMA_FLOOR_M,
        Verification,
        _Priors,
        path_turn,
    )

    k = np.arange(40)
    first = k < 20
    yaw = np.where(first, 0.0, np.pi)
    p = np.column_stack([np.where(first, 0.5 * k, 0.5 * (39 - k)), np.where(first, 0.0, 0.5), np.zeros(40)])
    T_true = se3(rot_z(yaw), p)
    misplace = se3(rot_z(np.radians(3.0)), np.array([0.3, -0.2, 0.0]))
    T_raw = np.where(first[:, None, None], T_true, misplace @ T_true)
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(T_raw[:, :3, 3], axis=0), axis=1))])

    def loop(c: int, d: int, sigma: float) -> Verification:
        pose = to_pose6(se3_inverse(T_true[c]) @ T_true[d])
        return Verification(c, d, True, "", pose, np.eye(6) * sigma**2, 100, 80, 1.0)

    anchors = [loop(15, 24, 0.001), loop(5, 34, 0.002)]
    priors = _Priors(None, None, np.eye(4), T_raw, None, path_turn(yaw), path)  # what `anchored` reads
    T, sigma = priors.anchored(np.array([7]), np.array([32]), anchors)
    truth = se3_inverse(T_true[7]) @ T_true[32]
    assert np.linalg.norm((se3_inverse(T_raw[7]) @ T_raw[32])[:3, 3] - truth[:3, 3]) > 0.2
    np.testing.assert_allclose(T[0], truth, atol=1e-9)
    leg = SHORT_SIGMA_FLOOR_M**2 + SHORT_DRIFT_FRACTION**2  # a 1 m leg's variance
    assert sigma[0] == pytest.approx(np.sqrt(2 * leg + 2 * 0.002**2 + 0.002**2), rel=1e-9)


def test_a_network_gtsam_cannot_solve_is_tried_again_only_as_the_loops_grow(
    tiny_dive, tmp_path: Path, monkeypatch, caplog
) -> None:
    """When GTSAM fails on the network of loops, the stage warns and keeps the priors through single
    loops; it tries again once the loops from features have grown by NETWORK_GROWTH, not every round."""
    from auvnav.errors import AuvnavError
    from auvnav.vision import loops as stage_loops

    tried: list[int] = []

    def failing(T_ned_body: np.ndarray, i: np.ndarray, *_: object) -> None:
        tried.append(len(i))
        raise AuvnavError("indeterminant system")

    monkeypatch.setattr(stage_loops, "solve_network", failing)
    copy = tmp_path / "dive"
    shutil.copytree(tiny_dive.path, copy)
    with caplog.at_level(logging.WARNING):
        result = find_loops(read_dive(copy), read_prior(copy))
    assert tried and "the network of" in caplog.text and "not solved" in caplog.text
    assert result.summary["network_solves"] == len(tried)
    assert all(b > (1 + stage_loops.NETWORK_GROWTH) * a for a, b in itertools.pairwise(tried))
    assert len(tried) < result.summary["rounds"]
    assert result.summary["nonconsecutive_accepted"] > 3
