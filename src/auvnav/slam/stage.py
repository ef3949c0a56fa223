"""The SLAM stage (``auvnav slam``): a dive's sensor graph solved, and its products.

Products (DESIGN section 6), in ``DIVE/products/slam/``:

- ``trajectory.csv``: the image poses (one per stereo pair), columns as the navigation's
  (``t, north_m, east_m, down_m, roll_deg, pitch_deg, yaw_deg``) with the marginal 1-sigma
  ``sigma_north_m, sigma_east_m, sigma_down_m, sigma_yaw_deg``;
- ``trajectory.tum``: the same poses for evo (``t x y z qx qy qz qw``, local NED);
- ``graph.g2o``: every pose of the graph (auxiliary ones included) at the solution, with the DVL
  odometry and the loop closures used as ``EDGE_SE3:QUAT`` records (:func:`auvnav.slam.g2o.write_g2o`;
  the unary factors, compass, attitude, depth and fixes, have no g2o record);
- ``summary.json``: :meth:`~auvnav.slam.result.SlamResult.summary` (with ``estimate_dvl``, ``dvl``:
  the DVL odometry's calibration estimated in the graph, :mod:`auvnav.slam.dvl`);
- ``online.csv`` with ``--online``: each image pose as the vehicle knew it when the iSAM2 update
  that added it finished (:mod:`auvnav.slam.online`), columns as ``trajectory.csv`` without sigmas;
  ``trajectory.csv`` is then the smoother's estimate after the last update. A vehicle runs it with
  the correction an earlier check dive exported (``compass_correction``): with the raw compass the
  deviation's change through each turn is unobservable until the vehicle comes back, and the online
  error is several times the batch's;
- ``correction.yaml`` with ``estimate_compass``: the estimated deviation as a correction file
  (``auvnav-compass-correction/1``, :func:`auvnav.compass.correction.write_correction`) with the
  coefficients' marginal covariance. Earlier releases called it ``compass_correction.yaml``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from auvnav import products as P
from auvnav.dive import ImageIndex, dive_files, find_stream_file, read_dive
from auvnav.errors import InsufficientDataError
from auvnav.stagekit import Stage, StageContext, setting
from auvnav.streams import write_json
from auvnav.trajectory import Trajectory, write_trajectory, write_tum
from auvnav.vision.loopfile import loops_file, read_loops

if TYPE_CHECKING:  # the models (GTSAM) load when the stage runs, not when the pipeline checks its key
    from auvnav.slam.graph import SlamOptions
    from auvnav.slam.result import SlamResult


@dataclass(frozen=True)
class SlamSettings:
    """Settings of the SLAM stage."""

    loops: Path | None = setting(
        None, "Loop-closure file [DIVE/products/vision/loops.csv]; pose i is row i of images/index.csv."
    )
    compass_correction: Path | None = setting(None, "Compass correction file applied to the heading (eq. 5).")
    estimate_compass: bool = setting(
        False, "Estimate the deviation (eq. 5) in the graph; writes products/slam/correction.yaml."
    )
    estimate_dvl: bool = setting(
        False, "Estimate the DVL odometry's scale, mounting and the images' time offset in the graph."
    )
    incremental: bool = setting(False, "iSAM2 (a vehicle's solver), not batch Levenberg-Marquardt.")
    poses_per_update: int | None = setting(
        None,
        "With --incremental or --online: poses per iSAM2 update [10: one update every 10 s at 1 Hz].",
        minimum=1,
    )
    online: bool = setting(
        False,
        "Replay the dive in time order as the vehicle would (iSAM2); writes products/slam/online.csv. "
        "Give it the --compass-correction an earlier check dive exported, as a vehicle would.",
    )
    loop_latency_s: float | None = setting(
        None,
        "With --online: delay from a loop closure's later image to its finding, s [1 / the vision "
        "stage's measured stereo pairs per second when its summary exists, else 1: the camera's period].",
        minimum=0.0,
    )
    tide: Path | None = setting(None, "Tide constituent file: the depth becomes depth below the datum.")
    compass_sigma_deg: float | None = setting(
        None, "Heading sigma of the compass factors, deg [raw 10x the vehicle's; else 1x].", minimum=1e-9
    )
    harmonics: int = setting(3, "Harmonics of the estimated deviation.", minimum=0)
    robust: Literal["none", "huber", "cauchy"] = setting(
        "cauchy", "Kernel on loop closures; lists those it rejects."
    )
    loop_selection: Literal["pcm", "none"] = setting(
        "pcm", "Loop closures selected by pairwise consistency against the odometry first (pcm), or not."
    )
    marginal_every: int = setting(1, "Marginals of every Nth stereo pair (0: none).", minimum=0)

    def options(self) -> SlamOptions:
        from auvnav.slam.graph import SlamOptions

        return SlamOptions(
            compass_sigma_rad=None
            if self.compass_sigma_deg is None
            else math.radians(self.compass_sigma_deg),
            estimate_compass=self.estimate_compass,
            harmonics=self.harmonics,
            estimate_dvl=self.estimate_dvl,
            robust=self.robust,
            loop_selection=self.loop_selection,
            incremental=self.incremental,
            online=self.online,
            **({} if self.poses_per_update is None else {"poses_per_update": self.poses_per_update}),
            marginal_every=self.marginal_every,
        )


def online_trajectory(result: SlamResult) -> Trajectory:
    """The image poses as known online (:class:`auvnav.slam.online.OnlineRecord`), no sigmas."""
    from auvnav.frames import rot2euler

    sol = result.solution
    assert sol.online is not None
    image = sol.graph.times.is_image
    T = sol.online.T_known[image]
    yaw, pitch, roll = rot2euler(T[:, :3, :3])
    return Trajectory(
        t_s=sol.graph.times.t_s[image], p_ned_m=T[:, :3, 3], roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw
    )


def write_products(result: SlamResult, out: Path) -> None:
    """Write the stage's products into ``out`` (a stage folder being written)."""
    from auvnav.compass.correction import FitRecord, write_correction
    from auvnav.slam.g2o import write_g2o

    write_trajectory(result.trajectory, P.SLAM_TRAJECTORY.inside(out))
    write_tum(result.trajectory, P.SLAM_TUM.inside(out))
    sol = result.solution
    write_g2o(sol.graph.pose_graph.with_poses(sol.T_ned_body), P.SLAM_GRAPH.inside(out), overwrite=True)
    if result.deviation is not None:
        record = FitRecord(reference="slam", dives=(result.name,), pairs=len(sol.graph.times))
        write_correction(result.deviation, P.SLAM_CORRECTION.inside(out), overwrite=True, record=record)
    if sol.online is not None:
        write_trajectory(online_trajectory(result), P.SLAM_ONLINE.inside(out))
    write_json(result.summary(), P.SLAM_SUMMARY.inside(out))


def loop_latency_s(dive: Path, settings: SlamSettings) -> float:
    """The online replay's loop latency: as given, else the vision stage's time per stereo pair, else 1 s."""
    if settings.loop_latency_s is not None:
        return settings.loop_latency_s
    summary = P.VISION_SUMMARY.path(dive)
    if summary.is_file():
        rate = json.loads(summary.read_text(encoding="utf-8")).get("pairs_per_s")
        if isinstance(rate, (int, float)) and rate > 0:
            return 1.0 / float(rate)
    return 1.0


def _unavailable(dive: Path, settings: SlamSettings) -> str | None:
    if find_stream_file(dive, ImageIndex.FILE) is None:
        return "the dive has no images/index.csv (the graph has a pose per stereo pair)"
    if loops_file(dive, settings.loops) is None:
        return (
            "no loop closures (products/vision/loops.csv: run the loop-closure stage, or give --loops FILE)"
        )
    return None


def _inputs(dive: Path, settings: SlamSettings) -> dict[str, Path]:
    files = dive_files(dive)
    index = find_stream_file(dive, ImageIndex.FILE)
    if index is not None:
        files[str(index.relative_to(dive))] = index
    loops = loops_file(dive, settings.loops)
    if loops is not None:
        files["loops"] = loops
    if settings.online and settings.loop_latency_s is None and P.VISION_SUMMARY.path(dive).is_file():
        files[P.VISION_SUMMARY.rel] = P.VISION_SUMMARY.path(dive)
    for name in ("compass_correction", "tide"):
        if getattr(settings, name) is not None:
            files[name] = getattr(settings, name)
    return files


def _run(ctx: StageContext, settings: SlamSettings, out: Path) -> dict[str, Any]:
    from auvnav.compass.correction import read_correction
    from auvnav.depth.tide import read_constituents
    from auvnav.slam.result import slam

    dive = read_dive(ctx.dive, allow_outside=ctx.allow_outside)
    if dive.images is None:
        raise InsufficientDataError(f"{ctx.dive}/images/index.csv: not found (a pose per stereo pair)")
    loops_path = loops_file(ctx.dive, settings.loops)
    if loops_path is None or not loops_path.is_file():
        shown = loops_path or P.LOOPS.path(ctx.dive)
        raise InsufficientDataError(f"{shown}: not found: run `auvnav loops` first, or give --loops FILE")
    correction, tide = settings.compass_correction, settings.tide
    result = slam(
        dive,
        dive.images.t_s,
        image_source="images/index.csv",
        loops=read_loops(loops_path),  # its rows are checked against the image times by slam()
        correction=None if correction is None else read_correction(correction),
        tide=None if tide is None else read_constituents(tide, latitude_rad=dive.info.origin.latitude_rad),
        options=replace(settings.options(), loop_latency_s=loop_latency_s(ctx.dive, settings)),
        names={
            "loops_file": str(loops_path),
            "compass_correction": None if correction is None else str(correction),
            "tide": None if tide is None else str(tide),
        },
    )
    write_products(result, out)
    return result.summary()


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable account of :meth:`~auvnav.slam.result.SlamResult.summary`."""
    loops, compass = summary["loops"], summary["compass"]
    factors = ", ".join(f"{kind} {n}" for kind, n in summary["factors"].items())
    lines = [
        f"dive '{summary['dive']}': {summary['poses']} poses ({summary['image_poses']} stereo pairs, "
        f"times from {summary['image_times']}), {summary['duration_s'] / 3600:.2f} h",
        f"factors: {factors}",
        f"loop closures: {loops['used']} used of {loops['given']} in {loops['file']}, "
        f"{loops['rejected']} rejected by "
        + (f"pairwise consistency ({loops['selection']['rejected']}) and " if loops.get("selection") else "")
        + f"the {summary['robust']} kernel (k = {loops['robust_k']:.2f})",
        f"compass: {compass['mode']}, heading sigma {compass['heading_sigma_deg']:.2f} deg"
        + (f", correction {compass['correction']}" if compass["correction"] else ""),
        f"solver {summary['solver']}: cost {summary['cost_before']:.6g} -> {summary['cost_after']:.6g} "
        f"in {summary['iterations']} iterations, {summary['seconds']:.1f} s",
    ]
    if compass["mode"] == "estimated":
        a = ", ".join(f"{v:.3f}" for v in compass["a_deg"])
        b = ", ".join(f"{v:.3f}" for v in compass["b_deg"])
        lines.append(
            f"estimated deviation: a0 {compass['a0_deg']:.3f} deg ({compass['constant_source']}), "
            f"a [{a}], b [{b}] deg"
        )
    dvl = summary.get("dvl")
    if dvl:
        sigma = dvl.get("sigma")

        def pm(value: float, key: str, index: int | None = None, unit: float = 1.0, fmt: str = ".3f") -> str:
            if not sigma:
                return f"{unit * value:+{fmt}}"
            s = sigma[key] if index is None else sigma[key][index]
            return f"{unit * value:+{fmt}} +- {unit * s:{fmt}}"

        rpy = [pm(v, "misalignment_rpy_deg", i) for i, v in enumerate(dvl["misalignment_rpy_deg"])]
        lines.append(
            f"DVL calibration (estimated): scale factor {pm(dvl['scale_factor'], 'scale_factor', unit=100)}%, "
            f"mounting roll {rpy[0]} pitch {rpy[1]} yaw {rpy[2]} deg, "
            f"images' time offset {pm(dvl['time_offset_s'], 'time_offset_s', fmt='.4f')} s"
        )
    online = summary.get("online")
    if online:
        lines.append(
            f"online: {online['updates']} iSAM2 updates of {online['poses_per_update']} poses, "
            f"{online['loops_added']} loop closures added (latency {online['loop_latency_s']:.2f} s, "
            f"median delay {online['loop_delay_median_s']:.1f} s); per pose median "
            f"{online['update_median_ms']:.1f} ms, 95th percentile {online['update_p95_ms']:.1f} ms"
        )
    if summary["tide"]:
        lines.append(f"depth below the datum with the tide of {summary['tide']}")
    return "\n".join(lines)


STAGE = Stage(
    name="slam",
    title="pose graph (GTSAM): DVL, attitude, depth, compass, fixes and loop closures",
    after=("nav", "vision"),
    settings=SlamSettings,
    inputs=_inputs,
    unavailable=_unavailable,
    run=_run,
    describe=format_summary,
)
