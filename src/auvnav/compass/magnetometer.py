"""Heading from a three-axis magnetometer, the hard/soft-iron forward model and its calibration.

The paper's section II.C: a strapdown magnetometer measures the Earth field ``h_e`` distorted by
the vehicle's soft iron and offset by its hard iron (eq. 2),
``m_body = (H_soft + I) b_body + h_hard_body``; rotated into the local-level frame with the measured
pitch and roll it gives the heading by eq. 1, ``psi = atan2(-l_y, l_x)``. Eq. 3-4 are the same
distortion seen in the level frame: :func:`deviation_from_iron` evaluates them through eq. 2 and 1.

Calibration inverts eq. 2 from raw samples taken while the vehicle turns: the distorted field lies
on an ellipsoid centred on the hard-iron offset (a sphere without soft iron). Two variants:

- ``"ellipsoid"``: the full model of eq. 2 (three-dimensional hard iron and soft-iron matrix; the
  ellipsoid of Gebre-Egziabher, Elkaim, Powell and Parkinson, "Calibration of strapdown
  magnetometers in magnetic field domain", J. Aerosp. Eng. 19(2), 2006) fitted by nonlinear least
  squares so that the calibrated field, levelled with the measured pitch and roll, has a constant
  vertical component and a constant horizontal magnitude, as the Earth field does (the magnitude
  and dot-product invariants of Li and Li, "A new calibration method for tri-axial field sensors
  in strap-down navigation systems", Meas. Sci. Technol. 23, 105105, 2012,
  doi:10.1088/0957-0233/23/10/105105). Using the attitude makes the vertical axis observable from
  the degree or two of tilt a passively stable vehicle has, where a magnitude-only ellipsoid fit
  is ill-conditioned (tens of percent of error in the vertical offset at 0.1% noise). A rotation about the
  vertical remains unobservable: it is a constant heading offset, the deviation's constant term,
  and is fixed by keeping the horizontal block of ``A_soft`` symmetric.
- ``"levelled"``: for a passively stable vehicle (small pitch and roll, the paper's case), the samples
  are levelled with pitch and roll and a two-dimensional ellipse is fitted to the horizontal
  components; the vertical axis keeps its raw offset and scale, which near-level heading barely sees.

Frames: body = FRD; the level frame is the body frame rotated by ``Ry(pitch) @ Rx(roll)`` (the part of
``R_ned_body = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` that excludes yaw), so its x axis points along the
horizontal projection of the vehicle's nose and its z axis down.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from auvnav.compass.field import EarthField
from auvnav.errors import InsufficientDataError
from auvnav.frames import FloatArray, angle_diff, euler2rot, rot_x, rot_y, wrap_angle

log = logging.getLogger(__name__)

CalibrationMethod = Literal["ellipsoid", "levelled"]

# Fewest samples for each fit: about twice the unknowns (12 for the ellipsoid, 5 for the ellipse).
_MIN_SAMPLES = {"ellipsoid": 24, "levelled": 10}
# Warn when the vertical hard-iron offset is uncertain beyond this fraction of the field: the 1%
# accuracy asked of the calibration (issue 5).
_MAX_SIGMA_VERTICAL = 0.01


def _vectors(name: str, v: ArrayLike) -> FloatArray:
    """``v`` as floats with a last axis of length 3; ``ValueError`` naming ``name`` otherwise."""
    a = np.asarray(v, dtype=float)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3); found {a.shape}")
    return a


def _matrix3(name: str, m: ArrayLike) -> FloatArray:
    a = np.asarray(m, dtype=float)
    if a.shape != (3, 3):
        raise ValueError(f"{name} must have shape (3, 3); found {a.shape}")
    return a


def level_rotation(pitch_rad: ArrayLike, roll_rad: ArrayLike) -> FloatArray:
    """``R_level_body = Ry(pitch) @ Rx(roll)``, the tilt part of ``R_ned_body``; shape (..., 3, 3)."""
    return rot_y(pitch_rad) @ rot_x(roll_rad)


def distort_field(b_body: ArrayLike, H_soft: ArrayLike, h_hard_body: ArrayLike) -> FloatArray:
    """The field a magnetometer measures: ``(H_soft + I) b_body + h_hard_body`` (paper eq. 2).

    Parameters
    ----------
    b_body : array_like, shape (..., 3), any unit, body FRD
        The undisturbed (Earth) field in the body frame.
    H_soft : array_like, shape (3, 3), dimensionless
        Soft-iron scaling and coupling; zero for none.
    h_hard_body : array_like, shape (3,), same unit as ``b_body``, body FRD
        Hard-iron offset.

    Returns
    -------
    ndarray, shape (..., 3), body FRD
    """
    b = _vectors("b_body", b_body)
    S = _matrix3("H_soft", H_soft) + np.eye(3)
    return b @ S.T + _vectors("h_hard_body", h_hard_body)


def heading_from_magnetometer(m_body: ArrayLike, pitch_rad: ArrayLike, roll_rad: ArrayLike) -> FloatArray:
    """Heading from a (calibrated) magnetometer and the measured tilts (paper eq. 1).

    Parameters
    ----------
    m_body : array_like, shape (..., 3), any unit, body FRD
        Measured field.
    pitch_rad, roll_rad : array_like, radians
        Pitch and roll (Euler ZYX), broadcasting against ``m_body[..., 0]``.

    Returns
    -------
    ndarray, shape (...), radians in (-pi, pi]
        Heading from the field's horizontal direction (magnetic north), clockwise.
    """
    m = _vectors("m_body", m_body)
    level = (level_rotation(pitch_rad, roll_rad) @ m[..., None])[..., 0]
    return wrap_angle(np.arctan2(-level[..., 1], level[..., 0]))  # eq. 1


def deviation_from_iron(
    H_soft: ArrayLike,
    h_hard_body: ArrayLike,
    field: EarthField,
    heading_rad: ArrayLike,
    pitch_rad: ArrayLike = 0.0,
    roll_rad: ArrayLike = 0.0,
) -> FloatArray:
    """Heading error of a distorted magnetometer: measured minus true magnetic heading (eq. 2-4, 1).

    The Earth field is rotated into the body at the given attitude, distorted by eq. 2 and turned
    into a heading by eq. 1. The deviation correction of eq. 5 is the negative of this error taken
    at the *measured* heading: ``delta(h_measured) = -error``.

    Parameters
    ----------
    H_soft : array_like, shape (3, 3), dimensionless
        Soft-iron matrix of eq. 2.
    h_hard_body : array_like, shape (3,), tesla, body FRD
        Hard-iron offset.
    field : EarthField
        The Earth field at the site (its declination places magnetic north).
    heading_rad : array_like, radians
        True magnetic heading (from magnetic north).
    pitch_rad, roll_rad : array_like, radians, optional
        Attitude, broadcasting against ``heading_rad``.

    Returns
    -------
    ndarray, radians in (-pi, pi]
        Measured minus true magnetic heading.
    """
    heading = np.asarray(heading_rad, dtype=float)
    R_ned_body = euler2rot(heading + field.declination_rad, pitch_rad, roll_rad)
    b_body = np.swapaxes(R_ned_body, -1, -2) @ field.b_ned_T  # R^T b_ned
    measured = heading_from_magnetometer(distort_field(b_body, H_soft, h_hard_body), pitch_rad, roll_rad)
    return angle_diff(measured, heading)


@dataclass(frozen=True)
class MagnetometerCalibration:
    """A hard- and soft-iron calibration: ``calibrated = A_soft @ (m_body - h_hard_body)``.

    Parameters
    ----------
    h_hard_body : ndarray, shape (3,), unit of the samples, body FRD
        Hard-iron offset (the ellipsoid's centre). For ``"levelled"``, the effective horizontal
        offset of a near-level vehicle (hard iron plus the soft iron's response to the vertical
        field, which is constant when level) and a zero vertical component.
    A_soft : ndarray, shape (3, 3), dimensionless
        Maps measured-minus-offset to the calibrated field, an estimate of ``(H_soft + I)^-1`` up to
        an overall scale (chosen so the calibrated magnitude is the geometric-mean radius of the
        fitted ellipsoid or ellipse) and a rotation about the vertical.
    field_spread_before, field_spread_after : float, dimensionless
        Standard deviation over mean of the magnitude the method makes constant (total field for
        ``"ellipsoid"``, level-frame horizontal field for ``"levelled"``), raw and calibrated.
    method : {"ellipsoid", "levelled"}
    n_samples : int
        Samples used (0 for a calibration made by hand).
    """

    h_hard_body: FloatArray
    A_soft: FloatArray
    field_spread_before: float
    field_spread_after: float
    method: CalibrationMethod
    n_samples: int = 0

    def __post_init__(self) -> None:
        h = np.array(self.h_hard_body, dtype=float)
        A = np.array(self.A_soft, dtype=float)
        if h.shape != (3,) or A.shape != (3, 3):
            raise ValueError(f"h_hard_body must be (3,) and A_soft (3, 3); found {h.shape} and {A.shape}")
        if not (np.all(np.isfinite(h)) and np.all(np.isfinite(A))):
            raise ValueError("h_hard_body and A_soft must be finite")
        if self.method not in _MIN_SAMPLES:
            raise ValueError(f"method must be one of {sorted(_MIN_SAMPLES)}; found {self.method!r}")
        for a in (h, A):
            a.setflags(write=False)
        object.__setattr__(self, "h_hard_body", h)
        object.__setattr__(self, "A_soft", A)

    def apply(self, m_body: ArrayLike) -> FloatArray:
        """Calibrated field ``A_soft @ (m - h_hard)``; shape (..., 3), body FRD."""
        return (_vectors("m_body", m_body) - self.h_hard_body) @ self.A_soft.T

    def summary(self) -> dict[str, Any]:
        """Machine-readable summary for ``auvnav compass calibrate --json``."""
        return {
            "method": self.method,
            "n_samples": self.n_samples,
            "h_hard_body": self.h_hard_body.tolist(),
            "A_soft": self.A_soft.tolist(),
            "field_spread_before_pct": 100.0 * self.field_spread_before,
            "field_spread_after_pct": 100.0 * self.field_spread_after,
        }


def _relative_spread(v: FloatArray) -> float:
    """Standard deviation over mean of the row norms of ``v``."""
    norm = np.linalg.norm(v, axis=-1)
    return float(np.std(norm) / np.mean(norm))


def _fit_ellipse(x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Centre and shape of the ellipse through points ``x`` (N, 2).

    The algebraic conic fit ``x^T Q x + 2 g^T x + c = 0``, solved as the smallest right singular
    vector of the design matrix of normalised data. Returns the centre ``x0`` and ``M`` with
    ``(x - x0)^T M (x - x0) = 1`` on the fitted ellipse.
    """
    mu, s = x.mean(axis=0), x.std(axis=0).mean()
    u, v = ((x - mu) / s).T
    D = np.column_stack([u * u, 2.0 * u * v, v * v, 2.0 * u, 2.0 * v, np.ones_like(u)])
    qxx, qxy, qyy, gx, gy, c = np.linalg.svd(D, full_matrices=False)[2][-1]
    Q = np.array([[qxx, qxy], [qxy, qyy]])
    if np.linalg.det(Q) <= 0.0:
        raise InsufficientDataError(
            "magnetometer samples do not outline an ellipse: turn the vehicle through all headings"
        )
    centre = -np.linalg.solve(Q, [gx, gy])
    M = Q / (centre @ Q @ centre - c)
    return mu + s * centre, M / s**2


def _sqrtm_spd(M: FloatArray) -> FloatArray:
    """Symmetric square root of a symmetric positive-definite matrix."""
    w, V = np.linalg.eigh(M)
    return (V * np.sqrt(w)) @ V.T


def _fit_levelled(m: FloatArray, R_level_body: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Hard-iron offset and soft-iron matrix from the ellipse of the levelled horizontal field."""
    level_xy = (R_level_body @ m[:, :, None])[:, :2, 0]
    centre_xy, M = _fit_ellipse(level_xy)
    A = np.eye(3)
    A[:2, :2] = _sqrtm_spd(M) * np.linalg.det(M) ** (-1.0 / 4.0)  # unit determinant
    return np.array([centre_xy[0], centre_xy[1], 0.0]), A


def _unpack(p: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """``A`` (symmetric upper-left 2x2 block: no rotation about the vertical), ``h`` and ``Z``."""
    a00, a01, a02, a11, a12, a20, a21, a22, hx, hy, hz, z = p
    A = np.array([[a00, a01, a02], [a01, a11, a12], [a20, a21, a22]])
    return A, np.array([hx, hy, hz]), z


def _fit_ellipsoid(
    m: FloatArray, R_level_body: FloatArray, h0: FloatArray, A0: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Refine ``(h, A)`` so the levelled calibrated field has constant horizontal and vertical parts.

    Residuals, in units of the horizontal field: ``l_z - Z`` and ``|l_xy| - 1`` with
    ``l = R_level_body A (m - h)``. Returns ``h``, ``A`` (unit determinant) and the 1-sigma of the
    vertical offset as a fraction of the field.
    """
    level0 = (R_level_body @ ((m - h0) @ A0.T)[:, :, None])[:, :, 0]
    r0 = float(np.mean(np.hypot(level0[:, 0], level0[:, 1])))  # the unit: horizontal field
    u = m / r0

    def residuals(p: FloatArray) -> FloatArray:
        A, h, z = _unpack(p)
        level = (R_level_body @ ((u - h) @ A.T)[:, :, None])[:, :, 0]
        return np.concatenate([level[:, 2] - z, np.hypot(level[:, 0], level[:, 1]) - 1.0])

    p0 = np.concatenate(
        [A0[[0, 0, 0, 1, 1, 2, 2, 2], [0, 1, 2, 1, 2, 0, 1, 2]], h0 / r0, [np.mean(level0[:, 2]) / r0]]
    )
    sol = least_squares(residuals, p0, method="lm", x_scale="jac", xtol=1e-12, ftol=1e-12)
    log.debug("ellipsoid fit: %s after %d evaluations", sol.message, sol.nfev)
    A, h, z = _unpack(sol.x)
    dof = max(sol.fun.size - sol.x.size, 1)
    try:
        var_hz = np.linalg.inv(sol.jac.T @ sol.jac)[10, 10] * (sol.fun @ sol.fun) / dof
    except np.linalg.LinAlgError:  # no tilt at all: the vertical offset is not observable
        var_hz = math.inf
    sigma_hz = math.sqrt(abs(var_hz)) / math.hypot(1.0, z)
    A = A / r0
    return h * r0, A / np.cbrt(np.linalg.det(A)), sigma_hz


def calibrate_magnetometer(
    m_body: ArrayLike,
    pitch_rad: ArrayLike,
    roll_rad: ArrayLike,
    *,
    method: CalibrationMethod = "ellipsoid",
) -> MagnetometerCalibration:
    """Hard- and soft-iron calibration from raw magnetometer samples taken while turning.

    Parameters
    ----------
    m_body : array_like, shape (N, 3), any unit, body FRD
        Raw magnetometer samples, ideally several full turns (a spin).
    pitch_rad, roll_rad : array_like, shape (N,) or scalar, radians
        Measured attitude at each sample, used to level the calibrated field.
    method : {"ellipsoid", "levelled"}
        ``"ellipsoid"``: full 3D fit; its vertical axis needs some tilt (a degree or two suffices
        with low noise; a warning says when the vertical offset is uncertain beyond 1% of the
        field). ``"levelled"``: 2D fit of the levelled horizontal field for a passively
        stable vehicle; the vertical offset is left at zero.

    Returns
    -------
    MagnetometerCalibration

    Raises
    ------
    InsufficientDataError
        Too few samples, or samples that do not outline an ellipsoid (e.g. not turned through all
        headings).
    """
    if method not in _MIN_SAMPLES:
        raise ValueError(f"method must be one of {sorted(_MIN_SAMPLES)}; found {method!r}")
    m = _vectors("m_body", m_body)
    if m.ndim != 2:
        raise ValueError(f"m_body must have shape (N, 3); found {m.shape}")
    pitch, roll = np.broadcast_arrays(
        np.asarray(pitch_rad, dtype=float), np.asarray(roll_rad, dtype=float), m[:, 0]
    )[:2]
    good = np.all(np.isfinite(m), axis=1) & np.isfinite(pitch) & np.isfinite(roll)
    if not np.all(good):
        log.warning("magnetometer calibration: ignoring %d samples with NaN", np.sum(~good))
        m, pitch, roll = m[good], pitch[good], roll[good]
    if len(m) < _MIN_SAMPLES[method]:
        raise InsufficientDataError(
            f"{method} magnetometer calibration needs at least {_MIN_SAMPLES[method]} samples; got {len(m)}"
        )
    R_level_body = level_rotation(pitch, roll)
    h_hard, A = _fit_levelled(m, R_level_body)
    if method == "ellipsoid":
        h_hard, A, sigma_hz = _fit_ellipsoid(m, R_level_body, h_hard, A)
        if sigma_hz > _MAX_SIGMA_VERTICAL:
            log.warning(
                "the vertical hard-iron offset is poorly determined (1-sigma %.1f%% of the field): "
                "the samples need more pitch and roll, or use method='levelled'",
                100.0 * sigma_hz,
            )
        before = _relative_spread(m)
        after = _relative_spread((m - h_hard) @ A.T)
    else:
        before = _relative_spread((R_level_body @ m[:, :, None])[:, :2, 0])
        after = _relative_spread((R_level_body @ ((m - h_hard) @ A.T)[:, :, None])[:, :2, 0])
    log.info(
        "%s magnetometer calibration of %d samples: field spread %.2f%% -> %.2f%%",
        method,
        len(m),
        100.0 * before,
        100.0 * after,
    )
    return MagnetometerCalibration(
        h_hard_body=h_hard,
        A_soft=A,
        field_spread_before=before,
        field_spread_after=after,
        method=method,
        n_samples=len(m),
    )
