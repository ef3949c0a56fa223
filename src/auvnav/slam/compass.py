"""The compass inside the pose graph: heading factors, and the deviation of eq. 5 as unknowns.

Each pose gets one unary heading factor. Its measurement is the compass heading ``h`` (as the compass
gives it, magnetic, the compass's own frame) at the pose's time; its prediction is the heading of the
compass frame of the pose, ``yaw(R_ned_body @ R_body_compass)`` (the compass mount of
``vehicle.yaml``), turned to magnetic north:

    e = wrap( yaw(R_ned_body R_body_compass) - declination - h - delta(h) )

- **Raw or corrected**: ``delta`` is zero (the raw compass) or a given correction (paper eq. 5, a file
  from ``auvnav compass fit``), held fixed.
- **Estimated** (``--estimate-compass``, the paper's future work): ``delta(h) = phi(h) . x`` with
  ``phi(h) = [1, cos h, sin h, ..., cos N h, sin N h]`` (eq. 5-6, :func:`fourier_design`) and the
  coefficients ``x = [a0, a1, b1, ..., aN, bN]`` one more unknown of the graph (one GTSAM vector
  value), so the SLAM headings no longer lean on the biased compass: the loop closures fix the
  relative headings and the compass, corrected by the estimated curve, the rest.

The constant ``a0`` is what no relative constraint sees (a rotation of the whole graph about the
vertical). It is kept as an unknown with a prior ``N(0, sigma_a0^2)`` (``sigma_a0`` the compass's
calibrated accuracy, ``vehicle.heading_sigma_rad``; paper section II-C), and the harmonics with a
weak prior ``N(0, HARMONIC_PRIOR_SIGMA^2)`` that only matters when the headings flown cannot
determine them (a survey's two headings). Absolute position fixes far apart under water (GPS at the
start and the end of a long dive, USBL) make ``a0`` observable through the dead-reckoned course; the
correction file then records ``constant.source: graph``. When the posterior of ``a0`` is not at
least :data:`OBSERVABLE_RATIO` tighter than its prior, the constant is reported as ``arbitrary`` (it
is the prior's, pulled by whatever weak information the dive holds), as a fit to SLAM headings is.

One heading factor serves the three modes (:func:`heading_factor`). It is linear in GTSAM's
tangent of the pose at ``R0``, the body attitude whose compass frame has the target heading
(``h + declination``, plus the fixed correction when there is one) and the measured pitch and roll,
``R0 = Rz(target) Ry(pitch) Rx(roll) R_body_compass^T``:

    e = j . w - phi(h) . x,    w = Log(R0^T R)  (the rotation part of GTSAM's right perturbation)

with ``j = j(R0 M) M^T``, ``j(R) = [0, R10 R02 - R00 R12, R00 R11 - R10 R01] / (R00^2 + R10^2)`` the
derivative of the yaw ``atan2(R10, R00)`` of the compass frame ``R M`` under ``R Exp(w)``
(:func:`yaw_jacobian`), and the ``phi . x`` term only when estimating. A turn of the pose about the
vertical by ``d`` is ``w = d u`` exactly (``u = R0^T e_z``) and ``j . u = 1``, so the error is the
heading error for any ``|d| < pi`` (the yaw-only prior is exact for any heading error; a flipped pose
costs the most); roll and pitch errors, which leave the heading unchanged to first order, do not
enter it (``j . w = 0`` for them; the inclinometer's factor holds them), and a tilt ``t`` on top of a
heading error ``d`` adds about ``d |t| / 2``. Its Jacobian, held at ``R0``, is the yaw's own at
every pose turned from ``R0`` about the vertical (the yaw's derivative does not depend on the yaw),
and ``-phi(h)`` with the coefficients. The factor is GTSAM's ``LinearContainerFactor`` around a
``JacobianFactor`` (keys: the pose, and the coefficients when estimating), so it is built and
evaluated in C++: fast in GTSAM's optimisers and in iSAM2, unlike a Python ``CustomFactor`` (which
GTSAM hands a copy of every value at every call).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from auvnav.compass.deviation import DeviationModel, fourier_design
from auvnav.frames import FloatArray, euler2rot, rot2euler, wrap_angle

#: Prior sigma of each harmonic coefficient (a1..bN): weak, several times a calibrated compass's
#: deviation (paper section II-C: O(1) degree after calibration, "several degrees" before).
HARMONIC_PRIOR_SIGMA_RAD = math.radians(10.0)
#: The constant counts as observed by the graph when its posterior sigma is at most this fraction of
#: its prior sigma.
OBSERVABLE_RATIO = 0.5

#: The key of the compass coefficients in the graph (poses are ``gtsam.symbol("x", k)``).
COEFFICIENTS_KEY = gtsam.symbol("c", 0)


def yaw_jacobian(R: FloatArray) -> FloatArray:
    """Derivative of ``yaw(R) = atan2(R10, R00)`` under the right perturbation ``R Exp(w)``, shape (3,)."""
    d = R[0, 0] ** 2 + R[1, 0] ** 2
    return np.array([0.0, R[1, 0] * R[0, 2] - R[0, 0] * R[1, 2], R[0, 0] * R[1, 1] - R[1, 0] * R[0, 1]]) / d


def heading_factor(
    key: int,
    heading_rad: float,
    R_ned_sensor: FloatArray,
    R_body_sensor: FloatArray,
    sigma_rad: float,
    phi: FloatArray | None = None,
) -> gtsam.LinearContainerFactor:
    """The unary heading factor of a sensor frame of a pose, with the deviation's coefficients when given.

    ``e = j . Log(R0^T R) - phi . x`` (module docstring): linear in the pose's tangent at ``R0``
    (the attitude whose sensor frame has ``heading_rad`` and the measured pitch and roll) and in
    the coefficients ``x`` (key :data:`COEFFICIENTS_KEY`, linearised at zero).

    Parameters
    ----------
    key : int
        The pose's key.
    heading_rad : float
        The target heading of the sensor frame (true north), radians: the compass heading plus the
        declination, plus a fixed correction.
    R_ned_sensor : ndarray, shape (3, 3)
        The measured attitude of the sensor frame (its pitch and roll are used).
    R_body_sensor : ndarray, shape (3, 3)
        The sensor's mount.
    sigma_rad : float
        Heading sigma, radians.
    phi : ndarray, shape (2N+1,), optional
        The Fourier design row of the compass heading (eq. 5-6): the factor then joins the
        coefficients, ``target + phi . x``.
    """
    _, pitch, roll = rot2euler(R_ned_sensor)
    M = np.asarray(R_body_sensor, dtype=float)
    R0_sensor = euler2rot(heading_rad, pitch, roll)
    R0 = R0_sensor @ M.T
    A_pose = np.concatenate([yaw_jacobian(R0_sensor) @ M.T, np.zeros(3)])[None, :]
    noise = gtsam.noiseModel.Isotropic.Sigma(1, sigma_rad)
    point = gtsam.Values()
    point.insert(key, gtsam.Pose3(gtsam.Rot3(R0), np.zeros(3)))
    if phi is None:
        linear = gtsam.JacobianFactor(key, A_pose, np.zeros(1), noise)
    else:
        phi = np.asarray(phi, dtype=float)
        point.insert(COEFFICIENTS_KEY, np.zeros(len(phi)))
        linear = gtsam.JacobianFactor(key, A_pose, COEFFICIENTS_KEY, -phi[None, :], np.zeros(1), noise)
    return gtsam.LinearContainerFactor(linear, point)


@dataclass(frozen=True)
class CompassModel:
    """How the graph treats the compass.

    Parameters
    ----------
    R_body_compass : ndarray, shape (3, 3)
        The compass mount (``vehicle.compass.R_body_sensor``).
    declination_rad : float
        Added to the magnetic heading (0 for a true-north compass).
    correction : DeviationModel or None
        A fixed correction (raw compass when None); ignored when ``estimate``.
    estimate : bool
        Estimate the coefficients of eq. 5 with the poses.
    harmonics : int
        N, when estimating.
    a0_prior_sigma_rad : float
        Prior sigma of the constant, when estimating.
    """

    R_body_compass: FloatArray
    declination_rad: float
    correction: DeviationModel | None = None
    estimate: bool = False
    harmonics: int = 3
    a0_prior_sigma_rad: float = math.radians(1.0)

    def __post_init__(self) -> None:
        if np.shape(self.R_body_compass) != (3, 3):
            raise ValueError(f"R_body_compass must have shape (3, 3); found {np.shape(self.R_body_compass)}")
        if self.harmonics < 0:
            raise ValueError(f"harmonics must be 0 or more; found {self.harmonics}")
        if not self.a0_prior_sigma_rad > 0:
            raise ValueError(f"a0_prior_sigma_rad must be positive; found {self.a0_prior_sigma_rad}")

    @property
    def n_coefficients(self) -> int:
        """2N+1 when estimating, else 0."""
        return 2 * self.harmonics + 1 if self.estimate else 0

    def heading_target(self, h_rad: FloatArray) -> FloatArray:
        """Magnetic-to-true target heading of the compass frame with the fixed correction, radians.

        ``h + delta(h) + declination`` with ``delta`` the fixed correction (zero when estimating or raw).
        """
        h = np.asarray(h_rad, dtype=float)
        delta = self.correction(h) if (self.correction is not None and not self.estimate) else 0.0
        return wrap_angle(h + delta + self.declination_rad)

    def factor(
        self, key: int, h_rad: float, R_ned_body_measured: FloatArray, sigma_rad: float
    ) -> gtsam.LinearContainerFactor:
        """The heading factor of the pose ``key`` for the compass heading ``h_rad`` (module docstring).

        Parameters
        ----------
        key : int
            The pose's key.
        h_rad : float
            Compass heading, radians, as the compass gives it.
        R_ned_body_measured : ndarray, shape (3, 3)
            The measured attitude (its pitch and roll place the compass's forward axis).
        sigma_rad : float
            Heading sigma.
        """
        M = np.asarray(self.R_body_compass, dtype=float)
        target = float(self.heading_target(np.array(h_rad)))
        phi = fourier_design(np.array([h_rad]), self.harmonics)[0] if self.estimate else None
        return heading_factor(key, target, R_ned_body_measured @ M, M, sigma_rad, phi)

    def coefficient_prior(self) -> gtsam.PriorFactorVector:
        """The prior on ``x = [a0, a1, b1, ...]``: zero mean, ``a0_prior_sigma_rad`` and the harmonics'."""
        sigmas = np.full(self.n_coefficients, HARMONIC_PRIOR_SIGMA_RAD)
        sigmas[0] = self.a0_prior_sigma_rad
        return gtsam.PriorFactorVector(
            COEFFICIENTS_KEY, np.zeros(self.n_coefficients), gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        )

    def estimated_model(self, x_rad: FloatArray, covariance: FloatArray | None) -> DeviationModel:
        """The deviation model from the solved coefficients and their marginal covariance (rad, rad^2).

        The constant's source is ``"graph"`` when the graph observed it (its posterior sigma at most
        :data:`OBSERVABLE_RATIO` of the prior's), else ``"arbitrary"``.
        """
        observed = (
            covariance is not None
            and math.sqrt(covariance[0, 0]) <= OBSERVABLE_RATIO * self.a0_prior_sigma_rad
        )
        cov = None if covariance is None else 0.5 * (covariance + covariance.T)
        return DeviationModel.from_coefficients(x_rad, cov, "graph" if observed else "arbitrary")
