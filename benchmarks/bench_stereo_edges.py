"""Edge-safe stereo: stereo matches against the truth on rendered scenes with depth steps.

Scenes: :class:`~auvnav.sim.camera.SteppedFloor` (flat-topped blocks 5-35 cm high on a level floor,
the reef's ledges and boulders), seen level from 2 m by the default rig at ``--image-scale``, in
``--water``. Every stereo match of the front end (:func:`~auvnav.vision.stereo.stereo_features`) is
compared with the truth: the left keypoint's ray cast into the scene, the hit point projected into the
rectified right image. A match is *near a depth edge* when the true disparity varies by more than 1 px
over the patch that was tracked (:meth:`~auvnav.vision.features.FeatureSettings.lk_window_for`). Prints,
for matches near edges and away from them: how many, the fraction within 1 px of the truth, and the
median Mahalanobis distance of the range error under the point's covariance (honest: about 0.67 for one
degree of freedom).

Usage: ``.venv/bin/python benchmarks/bench_stereo_edges.py [--scenes 12] [--image-scale 0.5]
[--water clear] [--set NAME=VALUE ...]`` (``--set`` as :class:`~auvnav.vision.features.FeatureSettings`
fields, e.g. ``--set edge_reject_px=0`` for the front end without its depth-edge test).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from auvnav.frames import euler2rot, se3
from auvnav.sim.camera import (
    Lighting,
    SteppedFloor,
    camera_poses,
    default_stereo_rig,
    render_stereo_pair,
    scale_camera_rig,
    to_grey,
    water_type,
)
from auvnav.sim.texture import SeafloorTexture
from auvnav.vision.camera import rectification
from auvnav.vision.features import FeatureSettings
from auvnav.vision.stereo import stereo_features

BASE_M = 20.0


def true_disparity(scene: SteppedFloor, rig, rect, T_ned_left, uv_rect: np.ndarray) -> np.ndarray:
    """The true right rectified column of left rectified points (N, 2): their rays cast into the scene."""
    f, cx, cy = rect.f_px, rect.cx_px, rect.cy_px
    rays_rect = np.column_stack([(uv_rect[:, 0] - cx) / f, (uv_rect[:, 1] - cy) / f, np.ones(len(uv_rect))])
    rays_cam = rays_rect @ rect.R1  # R1 rotates camera into rectified: camera = R1^T rectified
    rays_cam /= np.linalg.norm(rays_cam, axis=1, keepdims=True)
    R, c = T_ned_left[:3, :3], T_ned_left[:3, 3]
    s, _ = scene.intersect_rays(c, rays_cam @ R.T)
    p_cam = rays_cam * s[:, None]
    q = (rect.P2 @ np.column_stack([p_cam @ rect.R1.T, np.ones(len(p_cam))]).T).T
    return uv_rect[:, 0] - q[:, 0] / q[:, 2]


def scene_errors(seed: int, scale: float, water: str, settings: FeatureSettings) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    scene = SteppedFloor.random(seed, BASE_M, extent_m=3.0, count=14)
    rig = scale_camera_rig(default_stereo_rig(), scale)
    rect = rectification(rig)
    T = se3(euler2rot(float(rng.uniform(-np.pi, np.pi)), 0.0, 0.0), np.array([0.0, 0.0, BASE_M - 2.3]))
    T[:2, 3] = rng.uniform(-0.5, 0.5, 2)
    lighting = Lighting(water=water_type(water))  # type: ignore[arg-type]
    left, right = render_stereo_pair(scene, SeafloorTexture(seed=seed), rig, T, lighting=lighting, rng=rng)
    feats = stereo_features(to_grey(left), to_grey(right), rig, rect, settings)
    T_left = camera_poses(rig, T)[0]
    uv = feats.uv_rect_px
    d_meas = uv[:, 0] - uv[:, 2]
    d_true = true_disparity(scene, rig, rect, T_left, uv[:, :2])
    # The disparity's spread over the tracked patch (a 5 x 5 grid of it).
    half = 0.5 * settings.lk_window_for(rig.left.width)
    offsets = np.linspace(-half, half, 5)
    spread_lo, spread_hi = np.full(len(uv), np.inf), np.full(len(uv), -np.inf)
    for du in offsets:
        for dv in offsets:
            d = true_disparity(scene, rig, rect, T_left, uv[:, :2] + [du, dv])
            spread_lo, spread_hi = np.minimum(spread_lo, d), np.maximum(spread_hi, d)
    near = spread_hi - spread_lo > 1.0
    # range error under the covariance (Z in the rectified frame, along the optical axis)
    z_sigma = np.sqrt(np.einsum("i,nij,j->n", rect.R1[2], feats.cov_cam_m2, rect.R1[2]))
    z_meas = feats.p_cam_m @ rect.R1[2]
    z_true = rect.f_px * rect.baseline_m / d_true
    return {"error_px": np.abs(d_meas - d_true), "near": near, "z_mahal": np.abs(z_meas - z_true) / z_sigma}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=12)
    parser.add_argument("--image-scale", type=float, default=0.5)
    parser.add_argument("--water", choices=("clear", "coastal", "turbid"), default="clear")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    args = parser.parse_args()
    values = {
        k: float(v) if "." in v or "e" in v else int(v) for k, _, v in (s.partition("=") for s in args.set)
    }
    settings = FeatureSettings(**values)  # type: ignore[arg-type]
    started = time.perf_counter()
    parts = [scene_errors(seed, args.image_scale, args.water, settings) for seed in range(args.scenes)]
    err = np.concatenate([p["error_px"] for p in parts])
    near = np.concatenate([p["near"] for p in parts])
    mahal = np.concatenate([p["z_mahal"] for p in parts])
    out: dict[str, object] = {
        "scenes": args.scenes,
        "image_scale": args.image_scale,
        "water": args.water,
        "settings": values,
        "elapsed_s": round(time.perf_counter() - started, 1),
    }
    for name, mask in (("near_edges", near), ("away", ~near), ("all", np.ones_like(near))):
        out[name] = {
            "matches": int(mask.sum()),
            "within_1px": float(np.mean(err[mask] <= 1.0)) if mask.any() else float("nan"),
            "median_error_px": float(np.median(err[mask])) if mask.any() else float("nan"),
            "median_range_mahalanobis": float(np.median(mahal[mask])) if mask.any() else float("nan"),
        }  # fmt: skip
    print(json.dumps(out, indent=2))
    near_1px = out["near_edges"]["within_1px"]  # type: ignore[index]
    print(f"\nnear depth edges: {near_1px:.3f} of matches within 1 px (target >= 0.95)")


if __name__ == "__main__":
    main()
