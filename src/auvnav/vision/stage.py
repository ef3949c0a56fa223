"""The loop-closure stage (``auvnav loops``): stereo features, candidates, verification, ``loops.csv``.

Products (DESIGN section 6), in ``DIVE/products/vision/``: ``loops.csv`` (the format of
:mod:`auvnav.vision.loopfile`) and ``summary.json``. Its caches, features and verified pairs, are in
``DIVE/products/cache/vision/`` (:func:`auvnav.vision.loops.find_loops`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from auvnav import products as P
from auvnav.dive import (
    ImageIndex,
    find_stream_file,
    image_files,
    image_inputs,
    read_dive,
    read_image_index,
    vehicle_file_name,
)
from auvnav.errors import AuvnavError, InsufficientDataError
from auvnav.stagekit import Stage, StageContext, setting
from auvnav.streams import write_json
from auvnav.trajectory import Trajectory, read_trajectory
from auvnav.vehicle import read_vehicle
from auvnav.vision.loopfile import write_loops

if TYPE_CHECKING:  # the models load when the stage runs, not when the pipeline checks its key
    from auvnav.vision.loops import LoopSettings


@dataclass(frozen=True)
class VisionSettings:
    """Settings of the loop-closure stage."""

    feature_scale: float | None = setting(
        None, "Resize factor for SIFT (default: to 680 px wide, half of 1360).", minimum=1e-3, maximum=1.0
    )
    features: int = setting(1500, "Keypoints kept per image, strongest first.", minimum=10, maximum=20000)
    feature_contrast: float = setting(
        0.02,
        "SIFT's contrast threshold (OpenCV contrastThreshold), on the image stretched to --contrast-target.",
        minimum=1e-4,
        maximum=1.0,
    )
    contrast_target: float = setting(
        32.0,
        "Before SIFT, stretch the illumination-corrected image until the robust standard deviation of its "
        "grey levels is this many digital numbers (at most 8 times; never reduced); 0: no stretch.",
        minimum=0.0,
        maximum=128.0,
    )
    edge_reject: float = setting(
        0.5,
        "Edge-safe stereo: drop a stereo match whose disparity moves by more than this many pixels (at the "
        "SIFT scale, or 5 times the pair's lower quartile in noisy images) when its patch is shifted by half its "
        "side (it straddles a depth edge); 0: off.",
        minimum=0.0,
        maximum=100.0,
    )
    feature_spread: int = setting(
        0,
        "Choose the keypoints round-robin over an N x N grid of the image (well spread) instead of the "
        "strongest wherever they are; 0: off.",
        minimum=0,
        maximum=64,
    )

    direct: bool = setting(
        True,
        "Register a pair whose features do not (featureless sand, ripple fields, turbid water) from its "
        "images instead: photometric alignment through each pair's stereo surface.",
    )
    guided_window: float = setting(
        3.7,
        "Prior-guided matching: match a feature only against those the navigation prior puts within this "
        "many sigmas of it (plus 10 cm); 0: match every feature against every other.",
        minimum=0.0,
        maximum=100.0,
    )

    def loop_settings(self) -> LoopSettings:
        from auvnav.vision.direct import DirectSettings
        from auvnav.vision.features import FeatureSettings
        from auvnav.vision.loops import LoopSettings
        from auvnav.vision.registration import RegistrationSettings

        return LoopSettings(
            direct=DirectSettings() if self.direct else None,
            registration=RegistrationSettings(guided_sigmas=self.guided_window),
            features=FeatureSettings(
                scale=self.feature_scale,
                max_features=self.features,
                contrast_threshold=self.feature_contrast,
                contrast_target_dn=self.contrast_target,
                spread_cells=self.feature_spread,
                edge_reject_px=self.edge_reject,
            ),
        )


def prior_file(dive: Path) -> Path | None:
    """The navigation prior's file: the filter's track, else dead reckoning, or None."""
    for product in (P.NAV_FILTER, P.NAV_DR):
        if product.path(dive).is_file():
            return product.path(dive)
    return None


def read_prior(dive: Path) -> Trajectory:
    """The navigation prior (:func:`prior_file`)."""
    path = prior_file(dive)
    if path is None:
        raise InsufficientDataError(
            f"{P.stage_dir(dive, 'nav')}: no navigation (filter.csv or dr.csv); run `auvnav navigate` first"
        )
    return read_trajectory(path)


def _unavailable(dive: Path, settings: VisionSettings) -> str | None:
    if find_stream_file(dive, ImageIndex.FILE) is None:
        return "the dive has no images (images/index.csv)"
    try:
        index = read_image_index(dive)
        name = vehicle_file_name(dive)
        vehicle = None if name is None else read_vehicle(dive / name)
    except AuvnavError:
        return None  # the stage's run reports the problem with its file
    if vehicle is not None and vehicle.stereo is None:
        return "the vehicle has no stereo calibration (vehicle.yaml, key stereo)"
    if index is not None and not image_files(dive, index):
        return f"none of the {2 * len(index)} images that images/index.csv lists is in images/"
    if prior_file(dive) is None:
        return "no navigation to search from (products/nav: run `auvnav navigate` first)"
    return None


def _inputs(dive: Path, settings: VisionSettings) -> dict[str, Path]:
    files = image_inputs(dive)
    prior = prior_file(dive)
    if prior is not None:
        files[str(prior.relative_to(dive))] = prior
    return files


def _run(ctx: StageContext, settings: VisionSettings, out: Path) -> dict[str, Any]:
    from auvnav.vision.loops import find_loops

    dive = read_dive(ctx.dive, allow_outside=ctx.allow_outside)
    result = find_loops(
        dive,
        read_prior(ctx.dive),
        settings=settings.loop_settings(),
        cache_dir=P.cache_dir(ctx.dive, "vision"),
        executor=ctx.executor(),
        progress=ctx.progress,
    )
    write_loops(result.loops, P.LOOPS.inside(out))
    write_json(result.summary, P.VISION_SUMMARY.inside(out))
    return result.summary


def format_summary(summary: dict[str, Any]) -> str:
    """The human summary of the loop-closure stage."""
    lines = [
        f"{summary['pairs_with_features']} stereo pairs ({summary['pairs_skipped']} skipped), "
        f"median {summary['features_median']:.0f} triangulated features",
        f"{summary['candidates_tested']} pairs tested ({summary['consecutive_tested']} consecutive, "
        f"{summary['verifications_reused']} from the cache) in {summary['rounds']} rounds: "
        f"{summary['loops_accepted']} accepted, {summary['nonconsecutive_accepted']} of them loop closures"
        + (f", {summary['direct_accepted']} from the images" if summary.get("direct_accepted") else ""),
    ]
    for reason, n in sorted(summary["rejected"].items(), key=lambda kv: -kv[1]):
        lines.append(f"  rejected: {reason}: {n}")
    for reason, n in sorted(summary.get("direct_rejected", {}).items(), key=lambda kv: -kv[1]):
        lines.append(f"  then from the images: {reason}: {n}")
    if summary.get("altitude_source") == "stereo":
        lines.append("  image footprints from the stereo range: nav/dvl has no altitude")
    lines.append(
        f"{summary['elapsed_s']:.0f} s, {summary['pairs_per_s']:.1f} stereo pairs/s "
        f"({summary['executor']}, {summary['workers']} workers)"
    )
    return "\n".join(lines)


STAGE = Stage(
    name="vision",
    title="loop closures: stereo features, candidates from the navigation, robust 3D registration",
    after=("nav",),
    settings=VisionSettings,
    inputs=_inputs,
    unavailable=_unavailable,
    run=_run,
    describe=format_summary,
    uses_executor=True,
)
