"""The SLAM stage (``auvnav slam``): a dive's sensor graph solved, and its products.

Products (DESIGN section 6), in ``DIVE/products/slam/``, replaced by a rerun:

- ``trajectory.csv``: the image poses (one per stereo pair), columns as the navigation's
  (``t, north_m, east_m, down_m, roll_deg, pitch_deg, yaw_deg``) with the marginal 1-sigma
  ``sigma_north_m, sigma_east_m, sigma_down_m, sigma_yaw_deg``;
- ``trajectory.tum``: the same poses for evo (``t x y z qx qy qz qw``, local NED);
- ``graph.g2o``: every pose of the graph (auxiliary ones included) at the solution, with the DVL
  odometry and the loop closures used as ``EDGE_SE3:QUAT`` records (:func:`auvnav.slam.g2o.write_g2o`;
  the unary factors, compass, attitude, depth and fixes, have no g2o record);
- ``summary.json``: :meth:`SlamResult.summary`;
- ``compass_correction.yaml`` with ``--estimate-compass``: the estimated deviation as a correction
  file (``auvnav-compass-correction/1``, :func:`auvnav.compass.correction.write_correction`) with the
  coefficients' marginal covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from auvnav.compass.correction import FitRecord, read_correction, write_correction
from auvnav.compass.deviation import DeviationModel
from auvnav.depth.tide import TideModel, read_constituents
from auvnav.dive import Dive, read_dive
from auvnav.errors import ConfigError, DiveFormatError, Problem
from auvnav.nav import nav_inputs
from auvnav.slam.compass import CompassModel
from auvnav.slam.g2o import write_g2o
from auvnav.slam.graph import (
    DEFAULT_POSES_PER_UPDATE,
    PoseMarginals,
    SlamOptions,
    SlamSolution,
    build_graph,
    build_pose_times,
    marginals,
    read_image_times,
    solution_trajectory,
    solve,
)
from auvnav.streams import write_json
from auvnav.trajectory import Trajectory, write_trajectory, write_tum
from auvnav.vision.loopfile import LoopClosures, check_loops, read_loops

PRODUCTS_DIR = Path("products") / "slam"
LOOPS_FILE = Path("products") / "vision" / "loops.csv"
CORRECTION_FILE = "compass_correction.yaml"


@dataclass(frozen=True)
class SlamResult:
    """The SLAM stage's result for one dive.

    Parameters
    ----------
    name : str
        The dive's name.
    solution : SlamSolution
    sigmas : PoseMarginals or None
        None when marginals were skipped.
    trajectory : Trajectory
        The image poses.
    deviation : DeviationModel or None
        The estimated compass correction (``--estimate-compass``).
    options : SlamOptions
    loops_file, compass_correction, tide : str or None
        The inputs used, as given.
    loops_given : int
        Rows of the loop file.
    """

    name: str
    solution: SlamSolution
    sigmas: PoseMarginals | None
    trajectory: Trajectory
    deviation: DeviationModel | None
    options: SlamOptions
    loops_file: str | None = None
    compass_correction: str | None = None
    tide: str | None = None
    loops_given: int = 0

    def summary(self) -> dict[str, Any]:
        """The machine-readable summary (``summary.json``, ``auvnav slam --json``).

        ``loops.rejected_rows`` are 1-based data rows of the loop file, as its readers name them.
        """
        sol, sg = self.solution, self.solution.graph
        times = sg.times
        mode = "estimated" if sg.compass.estimate else "corrected" if sg.compass.correction else "raw"
        compass: dict[str, Any] = {
            "mode": mode,
            "heading_sigma_deg": math.degrees(sg.compass_sigma_rad),
            "correction": self.compass_correction,
            "declination_deg": math.degrees(sg.compass.declination_rad),
        }
        if self.deviation is not None:
            cov = self.deviation.covariance
            compass.update(
                {
                    "harmonics": self.deviation.harmonics,
                    "a0_deg": math.degrees(self.deviation.a0_rad),
                    "a_deg": np.degrees(self.deviation.a_rad).tolist(),
                    "b_deg": np.degrees(self.deviation.b_rad).tolist(),
                    "sigma_deg": None if cov is None else np.degrees(np.sqrt(np.diag(cov))).tolist(),
                    "constant_source": self.deviation.constant_source,
                }
            )
        return {
            "dive": self.name,
            "poses": len(times),
            "image_poses": int(np.count_nonzero(times.is_image)),
            "image_times": times.source,
            "start_s": float(times.t_s[0]),
            "duration_s": float(times.t_s[-1] - times.t_s[0]),
            "loops": {
                "file": self.loops_file,
                "given": self.loops_given,
                "used": len(sg.loop_rows),
                "outside_span": sg.loops_outside,
                "rejected": len(sol.rejected),
                "rejected_rows": [int(r) + 1 for r in sol.rejected],
                "robust_k": sg.loop_k,
            },
            "factors": sg.factor_counts(),
            "compass": compass,
            "tide": self.tide,
            "solver": sol.method,
            "robust": sol.robust,
            "iterations": sol.iterations,
            "seconds": sol.seconds,
            "cost_before": sol.cost_before,
            "cost_after": sol.cost_after,
            "chi2_after": sol.chi2_after,
            "marginals": None if self.sigmas is None else {"computed": self.sigmas.computed},
        }


def slam(
    dive: Dive,
    image_t_s: np.ndarray,
    *,
    image_source: str = "",
    loops: LoopClosures | None = None,
    correction: DeviationModel | None = None,
    tide: TideModel | None = None,
    options: SlamOptions | None = None,
    names: dict[str, str | None] | None = None,
) -> SlamResult:
    """Build and solve a dive's sensor graph (:mod:`auvnav.slam.graph`).

    Parameters
    ----------
    dive : Dive
    image_t_s : ndarray, shape (I,)
        Stereo pair times, POSIX seconds (pose i of ``loops`` is row i).
    image_source : str
        Where the image times came from, for messages.
    loops : LoopClosures, optional
        Checked (:func:`auvnav.vision.loopfile.check_loops`): its poses must be image rows, its
        covariances positive definite, its times the image times.
    correction : DeviationModel, optional
        A fixed compass correction (not with ``options.estimate_compass``).
    tide : TideModel, optional
        Subtracted from the pressure depth.
    options : SlamOptions, optional
    names : dict, optional
        ``loops_file``, ``compass_correction``, ``tide``: how to name the inputs in the summary.

    Raises
    ------
    ConfigError
        A correction given together with ``estimate_compass``.
    DiveFormatError
        A bad loop row (one line naming it).
    """
    options = options or SlamOptions()
    names = names or {}
    if correction is not None and options.estimate_compass:
        raise ConfigError("give --compass-correction or --estimate-compass, not both")
    if loops is not None:
        check_loops(loops, len(image_t_s), names.get("loops_file") or "loops")
    inputs = nav_inputs(dive, None if options.estimate_compass else correction)
    times = build_pose_times(image_t_s, inputs, aux_period_s=options.aux_period_s, source=image_source)
    compass = CompassModel(
        R_body_compass=dive.vehicle.compass.R_body_sensor,
        declination_rad=inputs.declination_rad,
        correction=correction,
        estimate=options.estimate_compass,
        harmonics=options.harmonics,
        a0_prior_sigma_rad=dive.vehicle.heading_sigma_rad,
    )
    graph = build_graph(
        dive,
        inputs,
        times,
        loops,
        compass,
        options=options,
        tide=tide,
        loops_name=names.get("loops_file") or "loops",
    )
    solution = solve(graph, options)
    sigmas = marginals(solution, options.marginal_every) if options.marginal_every > 0 else None
    deviation = None
    if solution.coefficients_rad is not None:
        cov = None if sigmas is None else sigmas.coefficients_covariance
        deviation = compass.estimated_model(solution.coefficients_rad, cov)
    return SlamResult(
        name=dive.info.name,
        solution=solution,
        sigmas=sigmas,
        trajectory=solution_trajectory(solution, sigmas),
        deviation=deviation,
        options=options,
        loops_file=names.get("loops_file"),
        compass_correction=names.get("compass_correction"),
        tide=names.get("tide"),
        loops_given=0 if loops is None else len(loops),
    )


def write_products(result: SlamResult, out_dir: Path) -> list[Path]:
    """Write the stage's products into ``out_dir`` (normally ``DIVE/products/slam``), replacing them.

    Returns
    -------
    list of Path
        The files written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = [out_dir / "trajectory.csv", out_dir / "trajectory.tum", out_dir / "graph.g2o"]
    write_trajectory(result.trajectory, written[0])
    write_tum(result.trajectory, written[1])
    sol = result.solution
    write_g2o(sol.graph.pose_graph.with_poses(sol.T_ned_body), written[2], overwrite=True)
    if result.deviation is not None:
        record = FitRecord(reference="slam", dives=(result.name,), pairs=len(sol.graph.times))
        written.append(out_dir / CORRECTION_FILE)
        write_correction(result.deviation, written[-1], overwrite=True, record=record)
    else:
        (out_dir / CORRECTION_FILE).unlink(missing_ok=True)  # an earlier run's estimate is stale
    written.append(out_dir / "summary.json")
    write_json(result.summary(), written[-1])
    return written


def run_slam(
    dive_path: Path,
    *,
    loops: Path | None = None,
    compass_correction: Path | None = None,
    estimate_compass: bool = False,
    incremental: bool = False,
    poses_per_update: int = DEFAULT_POSES_PER_UPDATE,
    tide: Path | None = None,
    compass_sigma_deg: float | None = None,
    harmonics: int = 3,
    robust: str = "cauchy",
    marginal_every: int = 1,
) -> dict[str, Any]:
    """Read a dive folder, solve its SLAM graph and write ``products/slam/``; the summary.

    Parameters
    ----------
    dive_path : Path
        A dive folder with ``images/index.csv`` (or a simulated dive's ``truth/image_times.csv``).
    loops : Path, optional
        A loop-closure file [``DIVE/products/vision/loops.csv``]; pose i is row i of the image times.
    compass_correction : Path, optional
        A correction file applied to the compass (``auvnav-compass-correction/1``).
    estimate_compass : bool
        Estimate the deviation in the graph; writes ``compass_correction.yaml``.
    incremental : bool
        iSAM2 instead of batch Levenberg-Marquardt.
    poses_per_update : int
        With ``incremental``: poses per iSAM2 update.
    tide : Path, optional
        A tide constituent file; the pressure depth is corrected to depth below the datum.
    compass_sigma_deg : float, optional
        Heading sigma of the compass factors, degrees (default: :mod:`auvnav.slam.graph`).
    harmonics : int
        Harmonics of the estimated deviation.
    robust : {"cauchy", "huber", "none"}
        Kernel on loop closures.
    marginal_every : int
        Marginals of every this-many-th image pose, interpolated between (0 skips them).

    Raises
    ------
    DiveFormatError
        No loop file (one line naming it), bad rows in it, no image times.
    ConfigError
        A bad option, correction or tide file.
    """
    if compass_sigma_deg is not None and not compass_sigma_deg > 0:
        raise ConfigError(f"--compass-sigma-deg must be positive; found {compass_sigma_deg}")
    dive_path = Path(dive_path)
    dive = read_dive(dive_path)
    image_t, image_source = read_image_times(dive_path, dive)
    loops_path = dive_path / LOOPS_FILE if loops is None else Path(loops)
    if not loops_path.is_file():
        hint = "run `auvnav loops` first, or give --loops FILE (a simulated dive's truth/loops.csv)"
        raise DiveFormatError([Problem(str(loops_path), f"not found: {hint}")])
    loop_data = read_loops(loops_path)  # its rows are checked against the image times by slam()
    options = SlamOptions(
        compass_sigma_rad=None if compass_sigma_deg is None else math.radians(compass_sigma_deg),
        estimate_compass=estimate_compass,
        harmonics=harmonics,
        robust=robust,  # type: ignore[arg-type]
        incremental=incremental,
        poses_per_update=poses_per_update,
        marginal_every=marginal_every,
    )
    result = slam(
        dive,
        image_t,
        image_source=image_source,
        loops=loop_data,
        correction=None if compass_correction is None else read_correction(compass_correction),
        tide=None
        if tide is None
        else read_constituents(Path(tide), latitude_rad=dive.info.origin.latitude_rad),
        options=options,
        names={
            "loops_file": str(loops_path),
            "compass_correction": None if compass_correction is None else str(compass_correction),
            "tide": None if tide is None else str(tide),
        },
    )
    write_products(result, dive_path / PRODUCTS_DIR)
    return result.summary()


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable account of :meth:`SlamResult.summary`."""
    loops, compass = summary["loops"], summary["compass"]
    factors = ", ".join(f"{kind} {n}" for kind, n in summary["factors"].items())
    lines = [
        f"dive '{summary['dive']}': {summary['poses']} poses ({summary['image_poses']} stereo pairs, "
        f"times from {summary['image_times']}), {summary['duration_s'] / 3600:.2f} h",
        f"factors: {factors}",
        f"loop closures: {loops['used']} used of {loops['given']} in {loops['file']}, "
        f"{loops['rejected']} rejected by the {summary['robust']} kernel (k = {loops['robust_k']:.2f})",
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
    if summary["tide"]:
        lines.append(f"depth below the datum with the tide of {summary['tide']}")
    return "\n".join(lines)
