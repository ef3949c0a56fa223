"""A dive's SLAM: its sensor graph built (:mod:`auvnav.slam.graph`), solved
(:mod:`auvnav.slam.optimize`) and summarised. The stage that writes the products is
:mod:`auvnav.slam.stage`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from auvnav.compass.deviation import DeviationModel
from auvnav.depth.tide import TideModel
from auvnav.dive import Dive
from auvnav.errors import ConfigError
from auvnav.nav.inputs import nav_inputs
from auvnav.slam.compass import CompassModel
from auvnav.slam.dvl import DvlCalibration
from auvnav.slam.graph import SensorGraph, SlamOptions, build_graph
from auvnav.slam.optimize import PoseMarginals, SlamSolution, marginals, solution_trajectory, solve
from auvnav.slam.poses import build_pose_times
from auvnav.trajectory import Trajectory
from auvnav.vision.loopfile import LoopClosures, check_loops


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
    dvl_calibration : DvlCalibration or None
        The DVL odometry's calibration estimated in the graph (``--estimate-dvl``).
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
    dvl_calibration: DvlCalibration | None
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
                "selection": None if sol.selection is None else sol.selection.summary(),
            },
            "factors": sg.factor_counts(),
            "compass": compass,
            "dvl": None if self.dvl_calibration is None else self.dvl_calibration.summary(),
            "tide": self.tide,
            "solver": sol.method,
            "robust": sol.robust,
            "iterations": sol.iterations,
            "seconds": sol.seconds,
            "cost_before": sol.cost_before,
            "cost_after": sol.cost_after,
            "chi2_after": sol.chi2_after,
            "marginals": None if self.sigmas is None else {"computed": self.sigmas.computed},
            "online": None if sol.online is None else sol.online.summary(),
        }


def sensor_graph(
    dive: Dive,
    image_t_s: np.ndarray,
    *,
    image_source: str = "",
    loops: LoopClosures | None = None,
    correction: DeviationModel | None = None,
    tide: TideModel | None = None,
    dvl_calibration: DvlCalibration | None = None,
    options: SlamOptions,
    loops_name: str = "loops",
) -> SensorGraph:
    """A dive's sensor graph, unsolved (:func:`slam`'s parameters; ``dvl_calibration`` a fixed
    calibration of the DVL odometry, :func:`auvnav.slam.graph.build_graph`)."""
    if correction is not None and options.estimate_compass:
        raise ConfigError("give --compass-correction or --estimate-compass, not both")
    if dvl_calibration is not None and options.estimate_dvl:
        raise ConfigError("give a DVL calibration or estimate it, not both")
    if loops is not None:
        check_loops(loops, len(image_t_s), loops_name)
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
    return build_graph(
        dive, inputs, times, loops, compass,
        options=options, tide=tide, dvl_calibration=dvl_calibration, loops_name=loops_name,
    )  # fmt: skip


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
    graph = sensor_graph(
        dive, image_t_s, image_source=image_source, loops=loops, correction=correction, tide=tide,
        options=options, loops_name=names.get("loops_file") or "loops",
    )  # fmt: skip
    compass = graph.compass
    solution = solve(graph, options)
    sigmas = marginals(solution, options.marginal_every) if options.marginal_every > 0 else None
    deviation = None
    if solution.coefficients_rad is not None:
        cov = None if sigmas is None else sigmas.coefficients_covariance
        deviation = compass.estimated_model(solution.coefficients_rad, cov)
    calibration = None
    if solution.calibration is not None:
        cov = None if sigmas is None else sigmas.calibration_covariance
        calibration = DvlCalibration(solution.calibration, cov, dive.vehicle.dvl.R_body_sensor)
    return SlamResult(
        name=dive.info.name,
        solution=solution,
        sigmas=sigmas,
        trajectory=solution_trajectory(solution, sigmas),
        deviation=deviation,
        dvl_calibration=calibration,
        options=options,
        loops_file=names.get("loops_file"),
        compass_correction=names.get("compass_correction"),
        tide=names.get("tide"),
        loops_given=0 if loops is None else len(loops),
    )
