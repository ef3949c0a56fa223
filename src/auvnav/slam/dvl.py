"""The DVL odometry's calibration inside the pose graph: scale, mounting and the images' time offset.

An online estimate rests on dead reckoning wherever the loop closures have not yet tied the track
together (:mod:`auvnav.slam.online`). With ``--estimate-dvl`` three calibrations of that dead
reckoning are unknowns of the graph, one GTSAM vector ``c = (kappa, theta_x, theta_y, theta_z, delta)``
(:data:`CALIBRATION_KEY`) learnt from the loop closures as they come, so that later odometry is
corrected causally:

- **scale** ``kappa``: true velocity = (1 + ``kappa``) x measured (the navigation filter's
  convention, :mod:`auvnav.nav.filter`); a DVL's scale follows the sound speed it assumes;
- **mounting** ``theta``: the true body velocity is the measured one turned by ``Exp(theta)``, a
  rotation vector in the body frame, radians (the DVL's misalignment against ``vehicle.yaml``);
- **time offset** ``delta``: each image pose is where the vehicle was ``delta`` seconds after the
  image's time stamp as the navigation's clock has it (a camera's trigger latency, clocks apart).
  The simulator has one of its own: its truth is integrated by forward Euler steps of 0.1 s from
  the velocity the DVL reports at the start of each step, so the true positions lag the navigation
  sensors by half a step, ``delta = -0.05 s``: 5 cm along track at every reversal of a 0.5 m/s
  vehicle, in every simulated dive.

The odometry's translation from pose ``k`` to ``k + 1`` (the DVL point's integrated displacement,
:func:`auvnav.slam.graph.dvl_odometry`) becomes, to first order, ``d_k + J_k c``
(:func:`odometry_sensitivity`), in the body frame of pose ``k``:
``J_k = R_k^T [dD, -d(int R [v]x dt), s_{k+1} w_{k+1} - s_k w_k]`` with ``D`` the DVL point's
displacement in NED, ``v`` its velocity in the body frame, ``w`` the reference point's velocity and
``s`` 1 at image poses, 0 at auxiliary ones. The neglected second order is ``kappa theta |d|``,
below a micrometre a step. Velocities bridged across a dropout are left out of ``J``: their error
is the bridge's process noise, and the 40 m of a bridged descent, turned by the roll and pitch of
the mounting as these are learnt, would move the whole dive against its surface fixes (the
navigation filter leaves the scale out of the vertical for the same reason). The time offset moves
positions, not attitudes: the attitude is measured directly, and a timing error makes it a few
tenths of a degree wrong in turns only. The prior is zero with sigmas ``vehicle.dvl_scale_sigma``,
:data:`MISALIGNMENT_PRIOR_SIGMA_RAD` and :data:`TIME_OFFSET_PRIOR_SIGMA_S`; the odometry's
covariance then drops its white scale term (the scale is a constant of the dive, now modelled as
one).

The factor. Its error is GTSAM's ``BetweenFactorPose3`` error with the calibrated measurement
``(R, t + J c)``: the calibration moves the measurement along its own translation tangent. GTSAM has
no C++ factor of two poses and a vector in one whitened residual, and the residual cannot be split
into two factors without changing the cost. A ``gtsam.CustomFactor`` computes it exactly, but GTSAM
hands its Python function a copy of every value of the graph at every call: a millisecond a call
on a 10,000-pose graph, so that one Levenberg-Marquardt iteration of the navigation check dive
takes 4.0 s against 0.14 s, and the online replay of the default survey was stopped unfinished
after 16 minutes of CPU (12 s without the calibration; ``benchmarks/bench_slam_online.py --part
factor-cost``). Here each odometry is linearised by this module on its own three values
(:func:`linearized_odometry`, 50 microseconds) and given to GTSAM as a ``LinearContainerFactor``,
exact at its linearisation point and relinearised by the solvers wherever they relinearise: the
batch solve at each of its rounds (:mod:`auvnav.slam.optimize`), iSAM2 at the poses it
relinearises, in the same update (:class:`auvnav.slam.online.CalibratedOdometry`). Both give the
custom factor's solution (the check dive online: the same error and calibration to the digits
printed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from numpy.typing import NDArray
from scipy.integrate import cumulative_trapezoid

from auvnav.frames import FloatArray, euler2rot, rot2euler, skew
from auvnav.nav.inputs import NavInputs, interp_rows
from auvnav.vehicle import Vehicle

#: The key of the calibration ``c = (kappa, theta_x, theta_y, theta_z, delta)`` in the graph.
CALIBRATION_KEY = gtsam.symbol("d", 0)
#: Unknowns of the calibration, in the order of ``c``.
N_CALIBRATION = 5
#: Prior sigma of each mounting angle: a DVL bolted to its mount without a measured alignment (the
#: simulator's residual after an installation alignment is 0.1 deg, ``sim.sensors``).
MISALIGNMENT_PRIOR_SIGMA_RAD = math.radians(1.0)
#: Prior sigma of the images' time offset against the navigation, seconds.
TIME_OFFSET_PRIOR_SIGMA_S = 0.1


def odometry_sensitivity(
    inputs: NavInputs, t_s: FloatArray, R_ned_body: FloatArray, image: NDArray[np.bool_]
) -> FloatArray:
    """First-order effect of the calibration ``c`` on each odometry translation, shape (P - 1, 3, 5).

    The odometry from pose ``k`` to ``k + 1`` becomes ``d_k + J_k c`` (module docstring), in the
    body frame of pose ``k`` (its measured attitude, as the odometry's translation).

    Parameters
    ----------
    inputs : NavInputs
    t_s : ndarray, shape (P,)
        Pose times inside the time base, POSIX seconds.
    R_ned_body : ndarray, shape (P, 3, 3)
        Measured attitude at the pose times.
    image : ndarray of bool, shape (P,)
        Poses at an image (the time offset moves those only).
    """
    R, t = inputs.R_ned_body, inputs.t_s
    v = inputs.v_body_mps * ~inputs.bridged[:, None]
    v_ned = np.einsum("nij,nj->ni", R, v)
    scale = np.diff(interp_rows(t_s, t, cumulative_trapezoid(v_ned, t, axis=0, initial=0.0)), axis=0)
    mounting = -np.diff(
        interp_rows(t_s, t, cumulative_trapezoid(R @ skew(v), t, axis=0, initial=0.0)), axis=0
    )
    w = np.gradient(inputs.displacement_ned_m(), t, axis=0)  # the reference point's velocity
    time = np.diff(interp_rows(t_s, t, w) * image[:, None], axis=0)
    J_ned = np.concatenate([scale[:, :, None], mounting, time[:, :, None]], axis=2)
    return np.einsum("nji,njk->nik", R_ned_body[:-1], J_ned)


def linearized_odometry(
    key_i: int,
    key_j: int,
    T_ij: FloatArray,
    J: FloatArray,
    noise: gtsam.noiseModel.Gaussian,
    X_i: gtsam.Pose3,
    X_j: gtsam.Pose3,
    c: FloatArray,
) -> gtsam.LinearContainerFactor:
    """The calibrated DVL odometry between two poses, linearised at ``(X_i, X_j, c)``.

    Its error is ``Local(T(c), X_i^-1 X_j)``, ``T(c) = (R, t + J c)``: GTSAM's ``BetweenFactorPose3``
    with the calibrated measurement, which the calibration moves along its own translation
    tangent ``R^T J``. Returned as GTSAM's ``LinearContainerFactor`` (module docstring: exact at its
    linearisation point, relinearised by :class:`OdometryLinearization` or the batch solve).

    Parameters
    ----------
    key_i, key_j : int
        The poses.
    T_ij : ndarray, shape (4, 4)
        The uncalibrated odometry, pose ``j`` in the body frame of pose ``i``.
    J : ndarray, shape (3, 5)
        Its sensitivity to the calibration (:func:`odometry_sensitivity`).
    noise : gtsam.noiseModel.Gaussian
    X_i, X_j : gtsam.Pose3
        The linearisation point of the poses.
    c : ndarray, shape (5,)
        That of the calibration.
    """
    R = np.asarray(T_ij[:3, :3], dtype=float)
    measured = gtsam.Pose3(gtsam.Rot3(R), np.asarray(T_ij[:3, 3], dtype=float) + J @ c)
    Ha, Hb = np.zeros((6, 6), order="F"), np.zeros((6, 6), order="F")
    Hm, Hz = np.zeros((6, 6), order="F"), np.zeros((6, 6), order="F")
    e = measured.localCoordinates(X_i.between(X_j, Ha, Hb), Hm, Hz)
    G = np.zeros((6, N_CALIBRATION))
    G[3:] = R.T @ J
    linear = gtsam.JacobianFactor(
        key_i, noise.Whiten(Hz @ Ha), key_j, noise.Whiten(Hz @ Hb), CALIBRATION_KEY, noise.Whiten(Hm @ G),
        -noise.whiten(e), gtsam.noiseModel.Unit.Create(6),
    )  # fmt: skip
    point = gtsam.Values()
    point.insert(key_i, X_i)
    point.insert(key_j, X_j)
    point.insert(CALIBRATION_KEY, np.asarray(c, dtype=float))
    return gtsam.LinearContainerFactor(linear, point)


@dataclass(frozen=True)
class DvlCalibration:
    """A calibration of the DVL odometry, as the graph's vector and as the simulator states it.

    Parameters
    ----------
    c : ndarray, shape (5,)
        ``(kappa, theta_x, theta_y, theta_z, delta)``: true velocity = ``(1 + kappa) Exp(theta)``
        measured velocity (body frame, ``theta`` a rotation vector, radians); the images taken
        ``delta`` seconds after their time stamps (module docstring).
    covariance : ndarray, shape (5, 5), or None
        Of ``c``, marginal.
    R_body_dvl : ndarray, shape (3, 3)
        The DVL's nominal mount (``vehicle.dvl.R_body_sensor``).
    """

    c: FloatArray
    covariance: FloatArray | None
    R_body_dvl: FloatArray

    def __post_init__(self) -> None:
        if np.shape(self.c) != (N_CALIBRATION,) or np.shape(self.R_body_dvl) != (3, 3):
            raise ValueError(
                f"c must have shape ({N_CALIBRATION},) and R_body_dvl (3, 3); found {np.shape(self.c)} "
                f"and {np.shape(self.R_body_dvl)}"
            )
        if self.covariance is not None and np.shape(self.covariance) != (N_CALIBRATION, N_CALIBRATION):
            raise ValueError(f"covariance must have shape (5, 5); found {np.shape(self.covariance)}")

    @property
    def scale_factor(self) -> float:
        """The DVL's scale error: measured = (1 + scale_factor) x true velocity."""
        return 1.0 / (1.0 + float(self.c[0])) - 1.0

    @property
    def misalignment_rpy_rad(self) -> FloatArray:
        """Roll, pitch, yaw of the DVL's true mount against its nominal one, radians.

        ``R_body_dvl_true = R_body_dvl @ euler2rot(yaw, pitch, roll)`` (the simulator's
        ``truth.yaml``), so ``Exp(theta) = R_body_dvl R_mis R_body_dvl^T``.
        """
        M = np.asarray(self.R_body_dvl, dtype=float)
        R_mis = M.T @ gtsam.Rot3.Expmap(np.asarray(self.c[1:4], dtype=float)).matrix() @ M
        yaw, pitch, roll = rot2euler(R_mis)
        return np.array([roll, pitch, yaw], dtype=float)

    @property
    def time_offset_s(self) -> float:
        return float(self.c[4])

    def sigmas(self) -> FloatArray | None:
        """1-sigma of ``(scale_factor, roll, pitch, yaw, time_offset_s)`` to first order, or None."""
        if self.covariance is None:
            return None
        M = np.asarray(self.R_body_dvl, dtype=float)
        A = np.zeros((N_CALIBRATION, N_CALIBRATION))
        A[0, 0] = -1.0 / (1.0 + float(self.c[0])) ** 2
        A[1:4, 1:4] = M.T  # small angles: the mount's roll, pitch, yaw are M^T theta
        A[4, 4] = 1.0
        return np.sqrt(np.diag(A @ self.covariance @ A.T))

    def summary(self) -> dict[str, Any]:
        """``scale_factor``, ``misalignment_rpy_deg``, ``time_offset_s`` and their ``sigma``."""
        sigma = self.sigmas()
        return {
            "scale_factor": self.scale_factor,
            "misalignment_rpy_deg": np.degrees(self.misalignment_rpy_rad).tolist(),
            "time_offset_s": self.time_offset_s,
            "sigma": None
            if sigma is None
            else {
                "scale_factor": float(sigma[0]),
                "misalignment_rpy_deg": np.degrees(sigma[1:4]).tolist(),
                "time_offset_s": float(sigma[4]),
            },
        }

    @classmethod
    def from_summary(cls, summary: dict[str, Any], R_body_dvl: FloatArray) -> DvlCalibration:
        """The calibration :meth:`summary` describes (its sigmas dropped)."""
        roll, pitch, yaw = np.radians(summary["misalignment_rpy_deg"])
        M = np.asarray(R_body_dvl, dtype=float)
        theta = gtsam.Rot3.Logmap(gtsam.Rot3(M @ euler2rot(yaw, pitch, roll) @ M.T))
        kappa = 1.0 / (1.0 + float(summary["scale_factor"])) - 1.0
        c = np.array([kappa, *theta, float(summary["time_offset_s"])])
        return cls(c, None, M)


@dataclass(frozen=True)
class DvlModel:
    """The calibration's prior: zero mean, these sigmas.

    Parameters
    ----------
    scale_sigma : float
        Of ``kappa`` (``vehicle.dvl_scale_sigma``).
    misalignment_sigma_rad : float
        Of each mounting angle.
    time_offset_sigma_s : float
    """

    scale_sigma: float
    misalignment_sigma_rad: float = MISALIGNMENT_PRIOR_SIGMA_RAD
    time_offset_sigma_s: float = TIME_OFFSET_PRIOR_SIGMA_S

    def __post_init__(self) -> None:
        if not (self.scale_sigma > 0 and self.misalignment_sigma_rad > 0 and self.time_offset_sigma_s > 0):
            raise ValueError("the calibration's prior sigmas must be positive")

    @classmethod
    def for_vehicle(cls, vehicle: Vehicle) -> DvlModel:
        return cls(scale_sigma=vehicle.dvl_scale_sigma)

    def prior(self) -> gtsam.PriorFactorVector:
        sigmas = np.array([self.scale_sigma, *([self.misalignment_sigma_rad] * 3), self.time_offset_sigma_s])
        return gtsam.PriorFactorVector(
            CALIBRATION_KEY, np.zeros(N_CALIBRATION), gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        )
