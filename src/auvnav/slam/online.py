"""SLAM as the vehicle would run it: the dive replayed in time order, batched iSAM2 updates.

The replay (``auvnav slam DIVE --online``) adds the graph's poses in time order,
``poses_per_update`` per iSAM2 update (:data:`auvnav.slam.graph.DEFAULT_POSES_PER_UPDATE`: one update
every 10 s for a camera at 1 Hz; batched iSAM2, not a fixed-lag smoother: the whole dive stays in the
Bayes tree, so a loop closure back to the start of the dive corrects everything between). Each update
brings the sensor factors of its poses (DVL odometry, attitude, depth, compass, fixes) and the loop
closures that the vehicle knows by the time of the update's last pose:

- a loop closure between images ``i`` and ``j`` is found when the front end has processed the later
  image, ``latency_s`` after it was taken (the front end's time per stereo pair, 1 / its measured
  throughput, or a given figure);
- it is then held until its pairwise-consistency decision is made (:mod:`auvnav.slam.pcm`, causal:
  kept as soon as :data:`auvnav.slam.pcm.EARLY_SUPPORT` loop closures known by then agree with it
  and none disagrees, else decided once the poses :data:`auvnav.slam.pcm.WINDOW_POSES` after its
  later end are in), and added only if kept, with the next update.

The Cauchy kernel stays on every loop closure added (no graduation: an online solver meets each loop
closure once). The estimate of each image pose as it was known when the update that added it
finished is the online trajectory (``products/slam/online.csv``); the smoother's estimate after the
last update is the stage's trajectory. Each update is timed (building its factors, the iSAM2 update,
reading the estimates of its poses).

Where the online estimate's error comes from (``benchmarks/bench_slam_online.py --part diagnose``,
the navigation check dive and the default survey): not from the smoother. A Levenberg-Marquardt
solve, run to convergence, of the graph as known at an update (:func:`schedule`: the same factors)
puts that update's poses as far from the truth as iSAM2 with GTSAM's default relinearisation does
(check dive: 0.094 m against 0.096 m with a compass correction, 0.385 m against 0.395 m with the raw
compass, on the poses of every 20th update; survey: 0.226 m against 0.235 m, 3.58 m against 3.75 m,
every 50th); a zero front-end latency or one pose per update change the online error by at most 3%.
Relinearising any variable that moved more than 0.01 (rad, m) at every update
(:data:`RELINEARIZE_THRESHOLD`, :data:`RELINEARIZE_SKIP`; GTSAM's defaults are 0.1 every 10th
update, coarse against centimetre loop closures) takes the last few percent (3-5% on both dives
and compasses, 16% with the deviation estimated) for 4-8 times the time per pose, well inside the
budget.

What the causal estimate lacked was not the future alone. On the check dive with the correction,
a pose seconds after a loop closure back to old ground was as far from the truth as one after
minutes on new ground (0.074 m against 0.077 m horizontally): the error was in the map as known
then. The loop closures tie the star's legs together only near its centre, so the dead reckoning
between them, and with it the map's position against the surface fixes, moved whenever a revisit
tied them again. Most of that was not the sensors' error: with exact sensors and the true
deviation the online error was still 5.6 cm horizontally (7.6 cm with the simulated errors)
against the batch's 0.8 cm, and moved by up to 9.5 cm in one update (the vehicle back on its first
leg), because the simulator's truth lags its navigation sensors by half a step
(:mod:`auvnav.slam.dvl`), 5 cm along track at every reversal; shifting the DVL's time stamps by
that half step took it to 2.2 cm. With the DVL's scale, mounting and the images' time offset
estimated in the graph (``--estimate-dvl``, :mod:`auvnav.slam.dvl`; its odometry relinearised by
:class:`CalibratedOdometry`), the online error with the correction an earlier check dive exported
(``--compass-correction``, the paper's workflow and what a vehicle would run with) is 0.055 m on
the check dive, 1.89 times the batch's (which the calibration improves too, 0.043 -> 0.029 m), and
0.197 m on the default survey, 1.75 times (1.26 and 1.78 times the batch solve without the
calibration). Scale and mounting alone give 0.080 m online and a worse batch (0.062 m: the scale
absorbs the lag, -0.21% against -0.13%); the time offset alone 0.062 m online, 0.046 m batch. What
remains: the first minutes, before the loop closures have taught the calibration (0.077 m in the
first quarter of the check dive, 0.03-0.05 m after), and the vertical, which on new ground follows
the pressure depth and its tide unless a tide model is given (``--tide``): 0.038 m of the check
dive's 0.055 m, against 0.027 m in batch. With the raw compass the deviation's change through each
turn is unobservable until the vehicle comes back (its sigma is inflated ten-fold): 5.7-7.7 times
the batch's error; estimating the deviation in the graph (``--estimate-compass``) leaves it
unobservable early in the dive (4.7-5.8 times, most of it in the first quarter: 0.04-0.06 m in the
check dive's later quarters against the batch's 0.031 m).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from auvnav.frames import FloatArray
from auvnav.slam.compass import COEFFICIENTS_KEY
from auvnav.slam.dvl import CALIBRATION_KEY, N_CALIBRATION
from auvnav.slam.graph import SensorGraph
from auvnav.slam.pcm import LoopSelection, select_loops
from auvnav.slam.poses import pose_key
from auvnav.slam.solve import PoseGraphSolveError, one_line

log = logging.getLogger(__name__)

#: iSAM2's relinearisation threshold (every tangent component, radians and metres) and the updates
#: between relinearisation checks (module docstring: GTSAM's defaults, 0.1 and 10, leave the online
#: estimate 3-5% further from the truth than the graph allows).
RELINEARIZE_THRESHOLD = 0.01
RELINEARIZE_SKIP = 1


def relinearize_thresholds(
    sg: SensorGraph, threshold: float = RELINEARIZE_THRESHOLD
) -> gtsam.ISAM2ThresholdMap:
    """iSAM2's relinearisation thresholds by kind of unknown: ``threshold`` for the poses and the
    compass coefficients; never for the DVL calibration, whose factors are linear in it
    (:mod:`auvnav.slam.dvl`: relinearising it would relinearise every odometry factor)."""
    thresholds = gtsam.ISAM2ThresholdMap()
    thresholds.insert((chr(gtsam.Symbol(pose_key(0)).chr()), np.full(6, threshold)))
    if sg.compass.estimate:
        key = gtsam.Symbol(COEFFICIENTS_KEY)
        thresholds.insert((chr(key.chr()), np.full(sg.compass.n_coefficients, threshold)))
    if sg.dvl is not None:
        thresholds.insert((chr(gtsam.Symbol(CALIBRATION_KEY).chr()), np.full(N_CALIBRATION, np.inf)))
    return thresholds


class CalibratedOdometry:
    """The DVL odometry of an iSAM2 smoother that estimates the DVL calibration (:mod:`auvnav.slam.dvl`).

    Each odometry factor enters iSAM2 as GTSAM's ``LinearContainerFactor``
    (:meth:`~auvnav.slam.graph.SensorGraph.odometry_at`), exact at its linearisation point. iSAM2
    relinearises a nonlinear factor where it relinearises its variables; a container would only be
    carried there to first order, and the second order, left to accumulate, moves the whole dive
    (decimetres, update after update: nothing but a few surface fixes holds its position). So each
    update first predicts which poses iSAM2 will relinearise (iSAM2's own rule: a component of its
    current step above its threshold, every ``skip`` updates) and replaces their containers by ones
    at the point iSAM2 moves them to: the odometry is relinearised where, and when, every other
    factor is. The calibration is never relinearised (:func:`relinearize_thresholds`): the odometry
    is linear in it.

    Parameters
    ----------
    sg : SensorGraph
    threshold : float
        iSAM2's relinearisation threshold of the poses.
    skip : int
        iSAM2's ``relinearizeSkip``.
    """

    def __init__(self, sg: SensorGraph, threshold: float, skip: int) -> None:
        self._sg = sg
        self._threshold = threshold
        self._skip = skip
        self._updates = 0
        self._poses = 0  # poses in the smoother
        self._factor: list[int] = []  # odometry factors added, in order
        self._slot: list[int] = []  # their index in iSAM2's factor list

    def update(
        self,
        isam: gtsam.ISAM2,
        new_factors: gtsam.NonlinearFactorGraph,
        new_values: gtsam.Values,
        new: list[int],
    ) -> None:
        """``isam.update`` with the ``new`` odometry factors and the containers to relinearise."""
        self._updates += 1
        theta = isam.getLinearizationPoint()
        moving = np.zeros(self._poses + 1, dtype=bool)  # + 1: the index -1 of a new pose's predecessor
        if self._factor and self._updates % self._skip == 0:
            step = isam.getDelta().vector()  # in key order: coefficients (c), calibration (d), poses (x)
            poses = step[len(step) - 6 * self._poses :].reshape(self._poses, 6)
            moving[: self._poses] = np.any(np.abs(poses) > self._threshold, axis=1)
        k = self._sg.last_pose[np.array(self._factor, dtype=np.int64)]
        stale = moving[k] | moving[k - 1]
        redo = [f for f, s in zip(self._factor, stale, strict=True) if s]
        remove = [i for i, s in zip(self._slot, stale, strict=True) if s]
        self._factor = [f for f, s in zip(self._factor, stale, strict=True) if not s]
        self._slot = [i for i, s in zip(self._slot, stale, strict=True) if not s]

        points: dict[int, gtsam.Pose3] = {}

        def point_of(k: int) -> gtsam.Pose3:
            """Where iSAM2 will hold pose ``k`` after this update's relinearisation."""
            if k not in points:
                key = pose_key(k)
                if new_values.exists(key):
                    points[k] = new_values.atPose3(key)
                else:
                    points[k] = isam.calculateEstimatePose3(key) if moving[k] else theta.atPose3(key)
            return points[k]

        # iSAM2 eliminates the keys of new factors last; those of the containers it merely relinearises
        # are not new (constrained, a thousand of them would make one dense clique of the root).
        constrained = gtsam.KeyGroupMap()
        observed = {key for n in range(new_factors.size()) for key in new_factors.at(n).keys()}
        observed |= {pose_key(int(self._sg.last_pose[f]) + d) for f in new for d in (-1, 0)}
        observed |= {CALIBRATION_KEY} if new else set()
        for key in observed:
            constrained.insert2(key, 1)
        first = new_factors.size()
        numbers = [*redo, *new]
        for f in numbers:
            k = int(self._sg.last_pose[f])
            point = gtsam.Values()
            point.insert(pose_key(k - 1), point_of(k - 1))
            point.insert(pose_key(k), point_of(k))
            source = new_values if new_values.exists(CALIBRATION_KEY) else theta
            point.insert(CALIBRATION_KEY, source.atVector(CALIBRATION_KEY))
            new_factors.add(self._sg.odometry_at(f, point))
        result = isam.update(new_factors, new_values, remove, constrained)
        self._factor.extend(numbers)
        self._slot.extend(list(result.getNewFactorsIndices())[first:])
        self._poses += sum(1 for key in new_values.keys() if gtsam.Symbol(key).chr() == ord("x"))


def isam2_update(
    isam: gtsam.ISAM2,
    sg: SensorGraph,
    odometry: CalibratedOdometry | None,
    factors: Iterable[int],
    first: int,
    last: int,
    current: FloatArray,
) -> FloatArray:
    """One iSAM2 update of a sensor graph: poses ``first`` to ``last`` (with the graph's other unknowns
    when ``first`` is 0), each predicted from the one before with its DVL odometry starting from
    ``current`` (the estimate of pose ``first - 1``, or pose 0's initial guess), and ``factors``
    (indices into ``sg.factors``), the DVL odometry through ``odometry`` when the DVL is calibrated in
    the graph. Returns the estimates of poses ``first`` to ``last``, shape (n, 4, 4).

    Raises
    ------
    PoseGraphSolveError
        When iSAM2 fails.
    """
    new_factors = gtsam.NonlinearFactorGraph()
    new_values = gtsam.Values()
    if first == 0:
        new_values.insert(sg.unknowns())
    for k in range(first, last + 1):
        if k > 0:
            current = current @ sg.pose_graph.T_ij[k - 1]
        new_values.insert(pose_key(k), gtsam.Pose3(current))
    new_odometry = []
    for f in factors:
        if odometry is not None and sg.kinds[f] == "odometry":
            new_odometry.append(int(f))
        else:
            new_factors.add(sg.factors[f])
    try:
        if odometry is None:
            isam.update(new_factors, new_values)
        else:
            odometry.update(isam, new_factors, new_values, new_odometry)
        return np.array([isam.calculateEstimatePose3(pose_key(k)).matrix() for k in range(first, last + 1)])
    except RuntimeError as err:
        raise PoseGraphSolveError(f"iSAM2 failed adding poses {first} to {last}: {one_line(err)}") from None


@dataclass(frozen=True)
class OnlineRecord:
    """What the vehicle knew, update by update.

    Parameters
    ----------
    T_known : ndarray, shape (P, 4, 4)
        Each pose's estimate when the update that added it finished.
    known_s : ndarray, shape (P,)
        The dive time (POSIX seconds) of that update: the time of its last pose.
    update_seconds : ndarray, shape (U,)
        Wall time of each update.
    update_poses : ndarray of int64, shape (U,)
        Poses each update added.
    update_loops : ndarray of int64, shape (U,)
        Loop closures each update added.
    selection : LoopSelection
        The causal pairwise-consistency decisions.
    latency_s : float
        The front end's latency used.
    loop_delay_s : ndarray, shape (A,)
        For each loop closure added: the dive time of its update less the time of its later image.
    """

    T_known: FloatArray
    known_s: FloatArray
    update_seconds: FloatArray
    update_poses: NDArray[np.int64]
    update_loops: NDArray[np.int64]
    selection: LoopSelection
    latency_s: float
    loop_delay_s: FloatArray

    def per_pose_ms(self) -> FloatArray:
        """Each update's wall time divided by the poses it added, one value per pose, ms."""
        return np.repeat(1e3 * self.update_seconds / self.update_poses, self.update_poses)

    def summary(self) -> dict[str, float | int]:
        per_pose = self.per_pose_ms()
        return {
            "updates": len(self.update_seconds),
            "poses_per_update": int(np.max(self.update_poses)),
            "loop_latency_s": self.latency_s,
            "loops_added": int(self.update_loops.sum()),
            "update_median_ms": float(np.median(per_pose)),
            "update_p95_ms": float(np.percentile(per_pose, 95)),
            "update_max_ms": float(np.max(per_pose)),
            "whole_update_median_ms": float(1e3 * np.median(self.update_seconds)),
            "whole_update_p95_ms": float(1e3 * np.percentile(self.update_seconds, 95)),
            "loop_delay_median_s": float(np.median(self.loop_delay_s)) if len(self.loop_delay_s) else 0.0,
        }


@dataclass(frozen=True)
class Schedule:
    """Which iSAM2 update adds which factor (module docstring).

    Parameters
    ----------
    selection : LoopSelection
        The causal pairwise-consistency decisions.
    firsts, lasts : ndarray of int64, shape (U,)
        First and last pose of each update.
    update_of : ndarray of int64, shape (F,)
        The update that adds each factor of the sensor graph (loop closures due after the last pose:
        the last update).
    skip : ndarray of bool, shape (F,)
        Factors never added (rejected loop closures).
    """

    selection: LoopSelection
    firsts: NDArray[np.int64]
    lasts: NDArray[np.int64]
    update_of: NDArray[np.int64]
    skip: NDArray[np.bool_]

    def known_by(self, u: int) -> NDArray[np.int64]:
        """The factors (indices into the sensor graph's) added by update ``u`` or before."""
        return np.flatnonzero((self.update_of <= u) & ~self.skip)


def schedule(sg: SensorGraph, poses_per_update: int, latency_s: float, *, select: bool = True) -> Schedule:
    """When each factor of ``sg`` reaches the smoother (module docstring; ``select`` as :func:`replay`'s)."""
    if poses_per_update < 1 or not latency_s >= 0:
        raise ValueError("poses_per_update must be at least 1 and latency_s non-negative")
    P = len(sg.times)
    t = sg.times.t_s
    if select:
        selection = select_loops(sg.pose_graph, P - 1, causal=True)
    else:
        n = sg.pose_graph.n_edges - (P - 1)
        later = np.maximum(sg.pose_graph.edge_i, sg.pose_graph.edge_j)[P - 1 :].astype(np.int64)
        none = np.zeros(n, dtype=np.int64)
        selection = LoopSelection(np.ones(n, dtype=bool), none, none, later, 0)
    loop_factor = np.flatnonzero([kind == "loop" for kind in sg.kinds])
    # The pose after whose update each factor is added: sensor factors with their last pose, loop
    # closures when found and decided; rejected loop closures never.
    due_time = t[np.minimum(selection.decided_at, P - 1)] + latency_s
    due_pose = sg.last_pose.copy()
    due_pose[loop_factor] = np.searchsorted(t, due_time, side="left")
    skip = np.zeros(len(sg.factors), dtype=bool)
    skip[loop_factor] = ~selection.keep
    firsts = np.arange(0, P, poses_per_update, dtype=np.int64)
    lasts = np.minimum(firsts + poses_per_update, P) - 1
    update_of = np.searchsorted(lasts, np.clip(due_pose, -1, P - 1), side="left")
    return Schedule(selection, firsts, lasts, np.clip(update_of, 0, len(firsts) - 1).astype(np.int64), skip)


def replay(
    sg: SensorGraph, poses_per_update: int, latency_s: float, *, select: bool = True
) -> tuple[gtsam.Values, OnlineRecord]:
    """Replay a sensor graph in time order (module docstring).

    ``select=False`` adds every loop closure as soon as it is found (the kernel alone against false ones).

    Returns
    -------
    gtsam.Values
        The smoother's estimate after the last update.
    OnlineRecord
    """
    plan = schedule(sg, poses_per_update, latency_s, select=select)
    selection, firsts, lasts, skip = plan.selection, plan.firsts, plan.lasts, plan.skip
    P = len(sg.times)
    t = sg.times.t_s
    is_loop = np.array([kind == "loop" for kind in sg.kinds], dtype=bool)

    params = gtsam.ISAM2Params()
    params.setFactorization("QR")  # as the batch iSAM2 (optimize._isam2): Cholesky fails on dive graphs
    params.setRelinearizeThreshold(relinearize_thresholds(sg))
    params.relinearizeSkip = RELINEARIZE_SKIP
    isam = gtsam.ISAM2(params)
    order = np.argsort(plan.update_of, kind="stable")
    bounds = np.searchsorted(plan.update_of[order], np.arange(len(firsts) + 1))
    T_known = np.empty((P, 4, 4))
    known_s = np.empty(P)
    seconds = np.empty(len(firsts))
    loops_added = np.zeros(len(firsts), dtype=np.int64)
    later = np.maximum(sg.pose_graph.edge_i, sg.pose_graph.edge_j)[P - 1 :]
    loop_number = np.cumsum(is_loop) - 1
    delays: list[float] = []
    current = sg.initial[0]
    odometry = None if sg.dvl is None else CalibratedOdometry(sg, RELINEARIZE_THRESHOLD, RELINEARIZE_SKIP)
    for u, (first, last) in enumerate(zip(firsts, lasts, strict=True)):
        start = time.perf_counter()
        factors = [int(f) for f in order[bounds[u] : bounds[u + 1]] if not skip[f]]
        for f in factors:
            if is_loop[f]:
                loops_added[u] += 1
                delays.append(float(t[last] - t[later[loop_number[f]]]))
        T_known[first : last + 1] = isam2_update(isam, sg, odometry, factors, first, last, current)
        current = T_known[last]
        known_s[first : last + 1] = t[last]
        seconds[u] = time.perf_counter() - start
    values = isam.calculateBestEstimate()  # every clique back-substituted (the calibration's small steps too)
    record = OnlineRecord(
        T_known=T_known,
        known_s=known_s,
        update_seconds=seconds,
        update_poses=(lasts - firsts + 1).astype(np.int64),
        update_loops=loops_added,
        selection=selection,
        latency_s=float(latency_s),
        loop_delay_s=np.array(delays),
    )
    log.info(
        "online: %d updates, %d loop closures added, median %.1f ms per pose",
        len(firsts),
        int(loops_added.sum()),
        float(np.median(record.per_pose_ms())),
    )
    return values, record
