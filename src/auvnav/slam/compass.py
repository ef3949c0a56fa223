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

With a raw or fixed correction the factor is GTSAM's ``PriorFactorPose3`` with a heading-only
information (:func:`heading_factor`); the estimated one is a Python ``CustomFactor`` (it joins the
coefficients). Its Jacobians are analytic, for GTSAM's right perturbation ``R Exp(w)`` of a pose
(tangent ordering ``(w, v)``): the yaw ``psi = atan2(R10, R00)`` of ``R' = R M`` moves by
``d psi = j(R') . M^T w``, ``j(R) = [0, R10 R02 - R00 R12, R00 R11 - R10 R01] / (R00^2 + R10^2)``,
and by ``-phi(h)`` with the coefficients.
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

#: A heading factor's sigma across the vertical (roll and pitch), radians: loose, the inclinometer's
#: factor holds them.
TILT_SIGMA_RAD = 1.0
#: Sigma of a coordinate a factor does not measure (a heading factor's translation, a fix's depth, the
#: pressure depth's north and east), metres: its information is 1e-10 of a centimetre-level
#: measurement's, so it neither constrains nor, at tens of metres from its nominal value, adds more
#: than 1e-5 to the chi-square.
UNMEASURED_SIGMA_M = 1e4

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
    p_ned_m: FloatArray,
) -> gtsam.PriorFactorPose3:
    """A unary factor on the heading of a sensor frame of a pose: a ``PriorFactorPose3`` on its heading.

    The prior is the body attitude whose sensor frame has the measured heading (and the measured
    pitch and roll), ``R0 = Rz(heading) Ry(pitch) Rx(roll) R_body_sensor^T``. A turn of the pose
    about the vertical by ``d`` is the rotation vector ``d u`` in GTSAM's tangent at ``R0``,
    ``u = R0^T e_z`` (the vertical in the body frame), exactly, for any ``|d| < pi``; the information
    ``u u^T / sigma^2`` on the rotation (plus :data:`TILT_SIGMA_RAD` across it and
    :data:`UNMEASURED_SIGMA_M` on the translation, at ``p_ned_m``, so that the matrix is positive
    definite) makes it a heading factor that leaves roll and pitch to the inclinometer's own factor.
    Its error grows all the way to a half turn (a flipped pose costs the most), and it is built in
    C++: fast in GTSAM's optimisers, unlike a Python ``CustomFactor``.

    Parameters
    ----------
    key : int
        The pose's key.
    heading_rad : float
        The measured heading of the sensor frame (true north), radians.
    R_ned_sensor : ndarray, shape (3, 3)
        The measured attitude of the sensor frame (its pitch and roll are used).
    R_body_sensor : ndarray, shape (3, 3)
        The sensor's mount.
    sigma_rad : float
        Heading sigma, radians.
    p_ned_m : ndarray, shape (3,)
        Where to put the prior's (unmeasured) translation: the pose's initial guess, metres.
    """
    _, pitch, roll = rot2euler(R_ned_sensor)
    R0 = euler2rot(heading_rad, pitch, roll) @ np.asarray(R_body_sensor, dtype=float).T
    u = R0[2]  # R0^T e_z
    info = np.zeros((6, 6))
    info[:3, :3] = np.outer(u, u) / sigma_rad**2 + (np.eye(3) - np.outer(u, u)) / TILT_SIGMA_RAD**2
    info[3:, 3:] = np.eye(3) / UNMEASURED_SIGMA_M**2
    prior = gtsam.Pose3(gtsam.Rot3(R0), np.asarray(p_ned_m, dtype=float))
    return gtsam.PriorFactorPose3(key, prior, gtsam.noiseModel.Gaussian.Information(info))


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
        self, key: int, h_rad: float, R_ned_body_measured: FloatArray, sigma_rad: float, p_ned_m: FloatArray
    ) -> gtsam.NonlinearFactor:
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
        p_ned_m : ndarray, shape (3,)
            The pose's initial position (see :func:`heading_factor`).
        """
        M = np.asarray(self.R_body_compass, dtype=float)
        if not self.estimate:
            target = float(self.heading_target(np.array(h_rad)))
            return heading_factor(key, target, R_ned_body_measured @ M, M, sigma_rad, p_ned_m)
        noise = gtsam.noiseModel.Isotropic.Sigma(1, sigma_rad)
        phi = fourier_design(np.array([h_rad]), self.harmonics)[0]
        base = float(wrap_angle(h_rad + self.declination_rad))

        def estimated(
            this: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None
        ) -> np.ndarray:
            keys = this.keys()
            R = values.atPose3(keys[0]).rotation().matrix() @ M
            x = values.atVector(keys[1])
            if H is not None:
                H[0] = np.concatenate([yaw_jacobian(R) @ M.T, np.zeros(3)])[None, :]
                H[1] = -phi[None, :]
            return np.array([wrap_angle(math.atan2(R[1, 0], R[0, 0]) - base - phi @ x)])

        return gtsam.CustomFactor(noise, [key, COEFFICIENTS_KEY], estimated)

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
