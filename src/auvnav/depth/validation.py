"""Depth validation from loop closures (paper section III-C and Fig. 6; issue 8, parts 3 and 5).

Physics and signs
-----------------
Pressure gives the depth below the *instantaneous* sea surface, ``d_p(t) = z(t) + eta(t)``: ``z`` is
the true depth below the datum (positive down) and ``eta`` the tide, the water level above the datum
(positive up), so a higher tide puts more water above the vehicle (DESIGN section 4). A loop closure
between images ``i`` and ``j`` measures the true vertical change ``z(t_j) - z(t_i)`` directly, as the
down component of the relative pose in NED::

    dz_visual = (R_ned_body(t_i) @ t_ij)[2]

with ``T_i_j = inv(T_ned_body_i) @ T_ned_body_j`` (:mod:`auvnav.vision.loopfile`). The heading drops
out (the last row of ``Rz(yaw)`` is ``(0, 0, 1)``), so only the measured pitch and roll enter; the
attitude is the dive's own (:func:`auvnav.nav.inputs.nav_inputs`: compass mount removed). Then::

    residual_before = [d_p(t_j) - d_p(t_i)] - dz_visual = eta(t_j) - eta(t_i) + noise
    residual_after  = residual_before - [eta_pred(t_j) - eta_pred(t_i)]

Both sides refer to the vehicle's reference point: the pressure sensor's depth less its lever arm in
NED, ``(R_ned_body @ vehicle.pressure.lever_arm_body_m)[2]``.

Pressure depth at an image time
-------------------------------
Single pressure samples are too noisy for this check (the default vehicle's sensor is 0.1 dbar, about
0.1 m, 1 sigma). The depth at an image time is ``z_dvl(t) + c(t)``, where ``z_dvl`` is the DVL's
vertical displacement of the reference point (the integral of ``R_ned_body v``,
:meth:`auvnav.nav.inputs.NavInputs.displacement_ned_m`) and ``c(t)`` the local linear least-squares
fit of ``d_p - z_dvl`` over a window (:data:`WINDOW_S`) centred on ``t``. The DVL carries the
vehicle's vertical motion inside the window; the tide and the DVL's slowly varying errors (scale,
misalignment) are linear over a minute and go into the fit. The fit's standard error is the pressure
term's 1-sigma.

Each loop's 1-sigma combines both ends' pressure sigmas, the vertical variance of the loop's
translation ``e_d^T R_i C_t R_i^T e_d`` and the tilt error (``vehicle.pitch_roll_sigma_rad``) times
the loop's horizontal length.

False relief
------------
A loop whose images lie more than :data:`FAR_APART_S` apart and whose residual (after the correction,
or before when no tide is given) exceeds both :data:`RELIEF_STEP_M` and three sigmas is flagged
``false_relief``: reconstructions would show a step there (the paper's Fig. 11; it quotes O(0.1 m)
residuals after the tide correction, section III-C).

The stage that reads a dive and writes the products is :mod:`auvnav.depth.stage`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from auvnav.depth.estimation import TideEstimate, estimate_tide
from auvnav.depth.pressure import (
    DBAR_TO_PA,
    AtmosphericSeries,
    depth_from_pressure,
    sea_pressure,
)
from auvnav.depth.tide import TideModel
from auvnav.dive import Dive
from auvnav.errors import InsufficientDataError
from auvnav.frames import FloatArray
from auvnav.nav.inputs import NavInputs, nav_inputs
from auvnav.products import DEPTH_LOOPS
from auvnav.streams import Field, Stream
from auvnav.vision.loopfile import LoopClosures

log = logging.getLogger(__name__)

WINDOW_S: float = 60.0
"""Width of the window of the local pressure-depth fit at each image time, seconds."""

FAR_APART_S: float = 1200.0
"""Loops whose images are further apart in time than this (20 minutes) are 'far apart': the tide has
changed between them (issue 8 acceptance)."""

RELIEF_STEP_M: float = 0.1
"""A residual larger than this (and than 3 sigma) on a far-apart loop is flagged as false relief: the
O(0.1 m) the paper saw after its tide correction (section III-C)."""


# ---------------------------------------------------------------------------------------------
# Pressure depth at image times
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PressureDepth:
    """Depth of the vehicle reference point from pressure, with the DVL's vertical track.

    Parameters
    ----------
    t_s : ndarray, shape (N,), seconds since the POSIX epoch, UTC
        Pressure sample times, strictly increasing, N >= 3.
    depth_m : ndarray, shape (N,), metres, positive down
        Depth of the reference point below the instantaneous sea surface (lever arm removed).
    dvl_down_m : ndarray, shape (N,), metres, positive down
        The DVL's vertical displacement of the reference point at the same times, any origin.
    bridged : ndarray of bool, shape (N,), optional
        Where the DVL's velocity was bridged across a dropout (its vertical track is a guess there);
        none when omitted.
    """

    t_s: FloatArray
    depth_m: FloatArray
    dvl_down_m: FloatArray
    bridged: NDArray[np.bool_] | None = None

    def __post_init__(self) -> None:
        arrays = [np.array(getattr(self, n), dtype=float) for n in ("t_s", "depth_m", "dvl_down_m")]
        shapes = [a.shape for a in arrays]
        if arrays[0].ndim != 1 or len(set(shapes)) != 1:
            raise ValueError(f"t_s, depth_m and dvl_down_m must be 1-D and match; found {shapes}")
        if arrays[0].size < 3:
            raise ValueError(f"a pressure depth record needs at least 3 samples; found {arrays[0].size}")
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise ValueError("t_s, depth_m and dvl_down_m must be finite")
        if np.any(np.diff(arrays[0]) <= 0):
            raise ValueError("t_s must be strictly increasing")
        bridged = np.zeros(arrays[0].shape, dtype=bool) if self.bridged is None else np.array(self.bridged)
        if bridged.shape != arrays[0].shape or bridged.dtype != bool:
            raise ValueError(
                f"bridged must be boolean of shape {arrays[0].shape}; found {bridged.dtype} {bridged.shape}"
            )
        for name, a in zip(("t_s", "depth_m", "dvl_down_m", "bridged"), [*arrays, bridged], strict=True):
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def at(self, t_s: ArrayLike, *, window_s: float = WINDOW_S) -> tuple[FloatArray, FloatArray]:
        """Pressure depth at times ``t_s`` by the local fit of the module docstring.

        Parameters
        ----------
        t_s : array_like, shape (M,), seconds since the POSIX epoch, UTC
        window_s : float
            Width of the window centred on each time, seconds, > 0.

        Returns
        -------
        depth_m : ndarray, shape (M,), metres, positive down
            NaN where a time lies outside the record, or its window holds fewer than 3 samples or a
            bridged DVL sample.
        sigma_m : ndarray, shape (M,), metres
            1-sigma of ``depth_m`` (standard error of the fit at that time).
        """
        if not window_s > 0:
            raise ValueError(f"window_s must be positive; found {window_s!r}")
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        # Window sums from cumulative sums; x about the record's start keeps them well conditioned.
        x_all = self.t_s - self.t_s[0]
        offset = float(np.median(self.depth_m - self.dvl_down_m))
        y_all = self.depth_m - self.dvl_down_m - offset

        def cumulative(v: FloatArray) -> FloatArray:
            return np.concatenate([[0.0], np.cumsum(v)])

        columns = (np.ones_like(x_all), x_all, x_all**2, y_all, x_all * y_all, y_all**2, self.bridged)
        sums = [cumulative(v) for v in columns]
        lo = np.searchsorted(self.t_s, t - 0.5 * window_s, side="left")
        hi = np.searchsorted(self.t_s, t + 0.5 * window_s, side="right")
        n, sx, sxx, sy, sxy, syy, n_bridged = (s[hi] - s[lo] for s in sums)
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1]) & (n >= 3) & (n_bridged == 0)
        n = np.where(inside, n, 3.0)
        x_mean, y_mean = sx / n, sy / n
        sxx_c = np.maximum(sxx - n * x_mean**2, 1e-12)
        sxy_c = sxy - n * x_mean * y_mean
        syy_c = syy - n * y_mean**2
        slope = sxy_c / sxx_c
        x = t - self.t_s[0]
        c = y_mean + slope * (x - x_mean)
        variance = np.maximum(syy_c - slope * sxy_c, 0.0) / (n - 2) * (1.0 / n + (x - x_mean) ** 2 / sxx_c)
        depth = np.interp(t, self.t_s, self.dvl_down_m) + offset + c
        return np.where(inside, depth, np.nan), np.where(inside, np.sqrt(variance), np.nan)


def pressure_depth(
    dive: Dive, inputs: NavInputs, *, atmospheric_pa: float | AtmosphericSeries | None = None
) -> PressureDepth:
    """The reference point's pressure depth and DVL vertical track over the navigation time base.

    Parameters
    ----------
    dive : Dive
    inputs : NavInputs
        The dive on its navigation time base (attitude, DVL displacement).
    atmospheric_pa : float or AtmosphericSeries, optional
        Atmospheric pressure, Pa; dive.yaml's constant when None.

    Raises
    ------
    InsufficientDataError
        Fewer than 3 pressure samples inside the navigation time base.
    """
    pr = dive.pressure
    inside = (pr.t_s >= inputs.t_s[0]) & (pr.t_s <= inputs.t_s[-1])
    if np.count_nonzero(inside) < 3:
        raise InsufficientDataError(
            f"{dive.info.name}/nav/pressure: fewer than 3 samples inside the DVL and attitude records"
        )
    t = pr.t_s[inside]
    sea = sea_pressure(
        pr.pressure_pa[inside],
        t,
        pressure_type=dive.info.pressure_type,
        atmospheric_pa=dive.info.atmospheric_pa if atmospheric_pa is None else atmospheric_pa,
    )
    sensor_depth = depth_from_pressure(sea, dive.info.origin.latitude_rad)
    lever_down = (inputs.R_ned_body_at(t) @ dive.vehicle.pressure.lever_arm_body_m)[:, 2]
    dvl_down = np.interp(t, inputs.t_s, inputs.displacement_ned_m()[:, 2])
    # A pressure sample is bridged when a bridged DVL sample lies on either side of it.
    after = np.clip(np.searchsorted(inputs.t_s, t), 0, len(inputs) - 1)
    bridged = inputs.bridged[after] | inputs.bridged[np.maximum(after - 1, 0)]
    return PressureDepth(t_s=t, depth_m=sensor_depth - lever_down, dvl_down_m=dvl_down, bridged=bridged)


def loop_vertical_m(
    loops: LoopClosures, R_ned_body_i: FloatArray, *, tilt_sigma_rad: float
) -> tuple[FloatArray, FloatArray]:
    """The true vertical change each loop closure measures, and its 1-sigma.

    Parameters
    ----------
    loops : LoopClosures
        N loops; ``t_ij_m`` in body ``i`` (FRD) with its covariance.
    R_ned_body_i : ndarray, shape (N, 3, 3)
        Attitude at each loop's first image.
    tilt_sigma_rad : float
        1-sigma of pitch and roll, radians.

    Returns
    -------
    dz_m : ndarray, shape (N,), metres, positive down
        ``z(t_j) - z(t_i) = (R_ned_body_i @ t_ij)[2]``.
    sigma_m : ndarray, shape (N,), metres
    """
    R = np.asarray(R_ned_body_i, dtype=float)
    if R.shape != (len(loops), 3, 3):
        raise ValueError(f"R_ned_body_i must have shape ({len(loops)}, 3, 3); found {R.shape}")
    t_ned = np.einsum("nij,nj->ni", R, loops.t_ij_m)
    down_row = R[:, 2, :]
    variance = np.einsum("ni,nij,nj->n", down_row, loops.covariance[:, :3, :3], down_row)
    variance = variance + tilt_sigma_rad**2 * (t_ned[:, 0] ** 2 + t_ned[:, 1] ** 2)
    return t_ned[:, 2], np.sqrt(variance)


# ---------------------------------------------------------------------------------------------
# Per-loop table
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LoopDepth(Stream):
    """The vertical check of each loop closure (``products/depth/loop_depth.csv``).

    Rows are ordered in time within each loop: ``t_i_s < t_j_s`` (a loop given the other way round is
    turned, its vertical change negated).

    Parameters
    ----------
    i, j : ndarray of int, shape (N,)
        Pose (image pair) indices of the earlier and the later image.
    t_i_s, t_j_s : ndarray, shape (N,), seconds since the POSIX epoch, UTC
    dt_s : ndarray, shape (N,), seconds
        ``t_j_s - t_i_s``.
    dz_pressure_m : ndarray, shape (N,), metres, positive down
        ``d_p(t_j) - d_p(t_i)``.
    dz_visual_m : ndarray, shape (N,), metres, positive down
        ``z(t_j) - z(t_i)`` from the loop closure.
    sigma_m : ndarray, shape (N,), metres
        1-sigma of the residual.
    residual_before_m : ndarray, shape (N,), metres
        ``dz_pressure_m - dz_visual_m``: the false depth change, the tide change plus noise.
    tide_change_m, residual_after_m : ndarray, shape (N,), metres, optional
        The tide change predicted (or estimated) between the images, and the residual less it.
    estimated_change_m : ndarray, shape (N,), metres, optional
        The tide change estimated from the loops (``estimate``), whichever tide was applied.
    false_relief : ndarray of bool, shape (N,)
        Far apart in time with a residual over :data:`RELIEF_STEP_M` and 3 sigma (module docstring).
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    t_i_s: FloatArray
    t_j_s: FloatArray
    dt_s: FloatArray
    dz_pressure_m: FloatArray
    dz_visual_m: FloatArray
    sigma_m: FloatArray
    residual_before_m: FloatArray
    false_relief: NDArray[np.bool_]
    tide_change_m: FloatArray | None = None
    residual_after_m: FloatArray | None = None
    estimated_change_m: FloatArray | None = None
    FILE: ClassVar[str] = DEPTH_LOOPS.rel.removesuffix(".csv")
    TIME_ORDERED: ClassVar[bool] = False
    FIELDS: ClassVar[tuple[Field, ...]] = (
        Field("i", ("i",), kind="int"),
        Field("j", ("j",), kind="int"),
        Field("t_i_s", ("t_i",)),
        Field("t_j_s", ("t_j",)),
        Field("dt_s", ("dt_s",)),
        Field("dz_pressure_m", ("dz_pressure_m",)),
        Field("dz_visual_m", ("dz_visual_m",)),
        Field("sigma_m", ("sigma_m",)),
        Field("residual_before_m", ("residual_before_m",)),
        Field("tide_change_m", ("tide_change_m",), required=False),
        Field("residual_after_m", ("residual_after_m",), required=False),
        Field("estimated_change_m", ("tide_change_estimated_m",), required=False),
        Field("false_relief", ("false_relief",), kind="bool"),
    )


def false_relief(
    dt_s: FloatArray,
    residual_m: FloatArray,
    sigma_m: FloatArray,
    *,
    far_apart_s: float = FAR_APART_S,
    relief_step_m: float = RELIEF_STEP_M,
) -> NDArray[np.bool_]:
    """Loops that would show a false-relief step: images more than ``far_apart_s`` apart and a
    residual over both ``relief_step_m`` and three sigmas (module docstring); shape of the inputs."""
    return (np.asarray(dt_s) > far_apart_s) & (
        np.abs(residual_m) > np.maximum(relief_step_m, 3.0 * np.asarray(sigma_m))
    )


def loop_depth(
    i: ArrayLike,
    j: ArrayLike,
    t_i_s: ArrayLike,
    t_j_s: ArrayLike,
    dz_pressure_m: ArrayLike,
    dz_visual_m: ArrayLike,
    sigma_m: ArrayLike,
    *,
    tide_change_m: ArrayLike | None = None,
    far_apart_s: float = FAR_APART_S,
    relief_step_m: float = RELIEF_STEP_M,
) -> LoopDepth:
    """Build the per-loop table: residuals, and false relief flagged (module docstring).

    Loops given with ``t_j < t_i`` are turned (indices and times swapped, changes negated).
    Arguments are as the fields of :class:`LoopDepth`; ``tide_change_m`` is ``eta(t_j) - eta(t_i)``
    for the loops as given.
    """
    t_i, t_j = np.asarray(t_i_s, dtype=float), np.asarray(t_j_s, dtype=float)
    sign = np.where(t_j >= t_i, 1.0, -1.0)
    turned = sign < 0
    dz_p = sign * np.asarray(dz_pressure_m, dtype=float)
    dz_v = sign * np.asarray(dz_visual_m, dtype=float)
    sigma = np.asarray(sigma_m, dtype=float)
    before = dz_p - dz_v
    tide = None if tide_change_m is None else sign * np.asarray(tide_change_m, dtype=float)
    after = None if tide is None else before - tide
    remaining = before if after is None else after
    dt = np.abs(t_j - t_i)
    relief = false_relief(dt, remaining, sigma, far_apart_s=far_apart_s, relief_step_m=relief_step_m)
    i_arr, j_arr = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    return LoopDepth(
        i=np.where(turned, j_arr, i_arr),
        j=np.where(turned, i_arr, j_arr),
        t_i_s=np.minimum(t_i, t_j),
        t_j_s=np.maximum(t_i, t_j),
        dt_s=dt,
        dz_pressure_m=dz_p,
        dz_visual_m=dz_v,
        sigma_m=sigma,
        residual_before_m=before,
        false_relief=relief,
        tide_change_m=tide,
        residual_after_m=after,
    )


# ---------------------------------------------------------------------------------------------
# The whole check
# ---------------------------------------------------------------------------------------------


def rms(x: ArrayLike) -> float | None:
    """Root mean square of an array; None when it is empty."""
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x**2))) if x.size else None


@dataclass(frozen=True)
class DepthResult:
    """Everything the depth stage found for one dive.

    Parameters
    ----------
    dive : str
        The dive's name.
    start_time_s : float
        The dive's start, POSIX seconds (the figure's time axis).
    loops_file : str
    loops : LoopDepth
    n_dropped : int
        Loops left out: an image time outside the pressure record, or a DVL dropout near it.
    tide : TideModel or None
        The tide the residuals were corrected with.
    tide_source : str or None
        Where it came from: the constituent file, or ``"estimated"``.
    estimate : TideEstimate or None
        The tide estimated from the loops (``--estimate-tide``).
    atmospheric : str
        What atmospheric pressure was removed.
    window_s, far_apart_s, relief_step_m : float
        The settings used (module constants by default).
    """

    dive: str
    start_time_s: float
    loops_file: str
    loops: LoopDepth
    n_dropped: int
    tide: TideModel | None
    tide_source: str | None
    estimate: TideEstimate | None
    atmospheric: str
    window_s: float = WINDOW_S
    far_apart_s: float = FAR_APART_S
    relief_step_m: float = RELIEF_STEP_M

    def summary(self) -> dict[str, Any]:
        """The machine-readable summary (``summary.json``, ``auvnav depth --json``)."""
        loops = self.loops
        far = loops.dt_s > self.far_apart_s

        def stats(mask: NDArray[np.bool_]) -> dict[str, Any]:
            after = None if loops.residual_after_m is None else rms(loops.residual_after_m[mask])
            return {
                "n": int(np.count_nonzero(mask)),
                "residual_rms_before_m": rms(loops.residual_before_m[mask]),
                "residual_rms_after_m": after,
            }

        everything = stats(np.ones(len(loops), dtype=bool))
        before_relief = false_relief(
            loops.dt_s,
            loops.residual_before_m,
            loops.sigma_m,
            far_apart_s=self.far_apart_s,
            relief_step_m=self.relief_step_m,
        )
        summary: dict[str, Any] = {
            "dive": self.dive,
            "loops_file": self.loops_file,
            "n_loops": len(loops),
            "n_dropped": self.n_dropped,
            "tide": None
            if self.tide is None
            else {"source": self.tide_source, "reference": self.tide.reference},
            "atmospheric": self.atmospheric,
            "window_s": self.window_s,
            "far_apart_s": self.far_apart_s,
            "relief_step_m": self.relief_step_m,
            "residual_rms_before_m": everything["residual_rms_before_m"],
            "residual_rms_after_m": everything["residual_rms_after_m"],
            "far_apart": stats(far),
            "near": stats(~far),
            "sigma_median_m": float(np.median(loops.sigma_m)),
            "false_relief_before": int(np.count_nonzero(before_relief)),
            "false_relief_after": None
            if loops.residual_after_m is None
            else int(np.count_nonzero(loops.false_relief)),
            "estimated_tide": None if self.estimate is None else self._estimate_summary(far),
        }
        return summary

    def _estimate_summary(self, far: NDArray[np.bool_]) -> dict[str, Any]:
        est = self.estimate
        estimated = self.loops.estimated_change_m
        if est is None or estimated is None:
            raise ValueError("no tide estimate")
        loops = self.loops
        sigma_change = est.change_sigma_m(loops.t_i_s, loops.t_j_s)
        out: dict[str, Any] = {
            "file": "tide_estimated.csv",
            "record_h": est.record_s / 3600.0,
            "n_used": est.n_used,
            "n_outliers": est.n_outliers,
            "rms_fit_m": est.rms_fit_m,
            "reduced_chi2": est.reduced_chi2,
            "change_sigma_rms_m": rms(sigma_change),
            "change_sigma_rms_far_apart_m": rms(sigma_change[far]),
            "constituents": [
                {
                    "name": c.name,
                    "amplitude_m": c.amplitude_m,
                    "amplitude_sigma_m": c.amplitude_sigma_m,
                    "phase_deg": math.degrees(c.phase_rad),
                    "phase_sigma_deg": math.degrees(c.phase_sigma_rad),
                    "resolved": c.resolved,
                    "resolving_record_h": c.resolving_record_s / 3600.0,
                }
                for c in est.constituents
            ],
        }
        if self.tide is not None and self.tide_source != "estimated" and loops.tide_change_m is not None:
            out["change_rms_vs_tide_m"] = rms(estimated - loops.tide_change_m)
            out["change_rms_vs_tide_far_apart_m"] = rms((estimated - loops.tide_change_m)[far])
        return out


def check_loop_depths(
    record: PressureDepth,
    loops: LoopClosures,
    R_ned_body_i: FloatArray,
    *,
    latitude_rad: float,
    tilt_sigma_rad: float,
    tide: TideModel | None = None,
    tide_source: str | None = None,
    estimate: bool = False,
    window_s: float = WINDOW_S,
    far_apart_s: float = FAR_APART_S,
    relief_step_m: float = RELIEF_STEP_M,
    dive: str = "",
    start_time_s: float | None = None,
    loops_file: str = "loops",
    atmospheric: str = "",
) -> DepthResult:
    """Check pressure depth against loop closures (module docstring): the stage without its files.

    Parameters
    ----------
    record : PressureDepth
        The reference point's pressure depth and DVL vertical track.
    loops : LoopClosures
        N >= 1 loop closures.
    R_ned_body_i : ndarray, shape (N, 3, 3)
        Attitude at each loop's first image (only pitch and roll matter).
    latitude_rad : float
        Latitude of the dive, radians (tide nodal corrections).
    tilt_sigma_rad : float
        1-sigma of pitch and roll, radians.
    tide : TideModel, optional
        The tide to correct with (an astronomical prediction, a gauge analysis, the truth).
    tide_source : str, optional
        What to call it in the summary.
    estimate : bool
        Also estimate the tide from the loops (:func:`auvnav.depth.estimation.estimate_tide`); it
        corrects the residuals when no ``tide`` is given.
    window_s, far_apart_s, relief_step_m : float
        See :data:`WINDOW_S`, :data:`FAR_APART_S`, :data:`RELIEF_STEP_M`.
    dive, start_time_s, loops_file, atmospheric
        Passed to :class:`DepthResult` for the summary (``start_time_s`` defaults to the record's start).

    Raises
    ------
    InsufficientDataError
        No loop, or no loop inside the pressure record.
    """
    if len(loops) == 0:
        raise InsufficientDataError(f"{loops_file}: no loop closures")
    d_i, s_i = record.at(loops.t_i_s, window_s=window_s)
    d_j, s_j = record.at(loops.t_j_s, window_s=window_s)
    covered = np.isfinite(d_i) & np.isfinite(d_j)
    n_dropped = int(np.count_nonzero(~covered))
    if n_dropped:
        log.warning(
            "%s: %d of %d loop closures left out: an image time lies outside the pressure record, "
            "or its %.0f s window holds fewer than 3 pressure samples or a DVL dropout",
            loops_file,
            n_dropped,
            len(loops),
            window_s,
        )
    if not np.any(covered):
        raise InsufficientDataError(f"{loops_file}: no loop closure lies inside the pressure record")
    loops = loops.select(covered)
    dz_visual, s_visual = loop_vertical_m(
        loops, np.asarray(R_ned_body_i)[covered], tilt_sigma_rad=tilt_sigma_rad
    )
    dz_pressure = d_j[covered] - d_i[covered]
    s_i, s_j = s_i[covered], s_j[covered]
    sigma = np.sqrt(s_i**2 + s_j**2 + s_visual**2)
    args = (loops.i, loops.j, loops.t_i_s, loops.t_j_s, dz_pressure, dz_visual, sigma)

    fit = None
    if estimate:
        fit = estimate_tide(
            loops.t_i_s,
            loops.t_j_s,
            dz_pressure - dz_visual,
            s_visual,
            latitude_rad,
            shared_sigma_i_m=s_i,
            shared_sigma_j_m=s_j,
            shared_bin_s=window_s,
        )
        if tide is None:
            tide, tide_source = fit.model, "estimated"
    change = None if tide is None else tide.predict(loops.t_j_s) - tide.predict(loops.t_i_s)
    table = loop_depth(*args, tide_change_m=change, far_apart_s=far_apart_s, relief_step_m=relief_step_m)
    if fit is not None:
        table = dataclasses.replace(table, estimated_change_m=fit.change_m(table.t_i_s, table.t_j_s))
    return DepthResult(
        dive=dive,
        start_time_s=float(record.t_s[0]) if start_time_s is None else start_time_s,
        loops_file=loops_file,
        loops=table,
        n_dropped=n_dropped,
        tide=tide,
        tide_source=tide_source,
        estimate=fit,
        atmospheric=atmospheric,
        window_s=window_s,
        far_apart_s=far_apart_s,
        relief_step_m=relief_step_m,
    )


def check_depth(
    dive: Dive,
    loops: LoopClosures,
    *,
    tide: TideModel | None = None,
    tide_source: str | None = None,
    estimate: bool = False,
    atmospheric_pa: float | AtmosphericSeries | None = None,
    atmospheric_source: str | None = None,
    loops_file: str = "loops",
    window_s: float = WINDOW_S,
    far_apart_s: float = FAR_APART_S,
    relief_step_m: float = RELIEF_STEP_M,
) -> DepthResult:
    """Check a dive's pressure depth against its loop closures: :func:`check_loop_depths` on the dive's record.

    The attitude and the DVL's vertical track come from :func:`auvnav.nav.inputs.nav_inputs`.

    Parameters
    ----------
    dive : Dive
    loops : LoopClosures
        Indices already checked against the image index.
    tide, tide_source, estimate, loops_file, window_s, far_apart_s, relief_step_m
        As :func:`check_loop_depths`.
    atmospheric_pa : float or AtmosphericSeries, optional
        Atmospheric pressure to remove, Pa; dive.yaml's constant when None.
    atmospheric_source : str, optional
        What to call it in the summary.
    """
    inputs = nav_inputs(dive)
    record = pressure_depth(dive, inputs, atmospheric_pa=atmospheric_pa)
    if atmospheric_source is None:
        atmospheric_source = (
            f"dive.yaml: {dive.info.atmospheric_pa / DBAR_TO_PA:g} dbar"
            if dive.info.pressure_type == "absolute"
            else "none (the sensor gives sea pressure)"
        )
    return check_loop_depths(
        record,
        loops,
        inputs.R_ned_body_at(loops.t_i_s),
        latitude_rad=dive.info.origin.latitude_rad,
        tilt_sigma_rad=dive.vehicle.pitch_roll_sigma_rad,
        dive=dive.info.name,
        start_time_s=dive.info.start_time_s,
        atmospheric=atmospheric_source,
        tide=tide,
        tide_source=tide_source,
        estimate=estimate,
        loops_file=loops_file,
        window_s=window_s,
        far_apart_s=far_apart_s,
        relief_step_m=relief_step_m,
    )
