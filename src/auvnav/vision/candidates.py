"""Loop-closure candidates from the navigation prior: which image pairs probably overlap.

Footprints (:func:`footprints`): each image sees about a ``w x h`` rectangle of seafloor (``w = a W /
f_x`` at altitude ``a``), modelled as the disc of the same area centred where the optical axis meets
the floor. Two equal discs of radius ``r`` at distance ``d`` overlap by the fraction ``f(d / r)`` of
their area (the circle-circle lens), so "overlap of at least ``min_overlap``" is ``d <= d_max``.

Probability (:func:`overlap_probability`): the navigation's error in the relative horizontal position
of two images is taken as isotropic Gaussian with standard deviation ``sigma`` per axis, so
``P(d <= d_max)`` is a non-central chi-square with 2 degrees of freedom:
``ncx2.cdf(d_max^2 / sigma^2, 2, |mu|^2 / sigma^2)``.

Relative uncertainty (:class:`DriftModel`): dead-reckoned (and GPS-at-the-surface filtered) navigation
drifts slowly and systematically (a compass error of a degree bends every leg by 1.7% of its length;
the paper's section II), so the error between two images grows with the time between them, and not
independently for each. The drift is modelled per horizontal axis as a correction ``c(t)`` to add to
the prior positions: ``c`` at knots every ``knot_s`` seconds, its rate ``v`` a random walk
(``v(0) ~ N(0, (drift_fraction speed)^2)``), i.e. an integrated random walk: linear growth of the
error over a leg, direction changes at turns. Verified loop closures measure ``c(t_j) - c(t_i)``; a
batch linear least-squares fit gives the corrected prior and the posterior covariance of every
relative displacement, so the candidate search tightens as loops are found (:mod:`auvnav.vision.loops`).

The search (:func:`candidate_pairs`) uses a k-d tree: pairs whose prior distance is so large that no
uncertainty could give them ``p_min`` are never considered (:func:`reach_distance`, about twice the
overlap distance), and the work grows like ``N log N`` plus the pairs within that radius.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.stats import ncx2, norm

from auvnav.trajectory import Trajectory
from auvnav.vehicle import StereoRig

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class CandidateSettings:
    """How candidate pairs are chosen.

    Parameters
    ----------
    min_overlap : float
        Footprint overlap (fraction of the area) a candidate should reach.
    p_min : float
        Smallest probability of reaching ``min_overlap`` worth testing.
    drift_fraction : float
        1-sigma rate of navigation drift, fraction of the distance travelled (2%: a 1 degree heading
        error, 1.7%, plus the DVL's 0.2% scale error, vehicle.py).
    drift_turn_s : float
        Time over which the drift rate may change by its own size (turns, new headings), seconds.
    knot_s : float
        Spacing of the drift model's knots, seconds.
    sigma_floor_m : float
        Smallest relative uncertainty used, metres (footprint model error).
    """

    min_overlap: float = 0.2
    p_min: float = 0.1
    drift_fraction: float = 0.02
    drift_turn_s: float = 200.0
    knot_s: float = 20.0
    sigma_floor_m: float = 0.05

    def __post_init__(self) -> None:
        if not 0 < self.min_overlap < 1 or not 0 < self.p_min < 1:
            raise ValueError("min_overlap and p_min must lie in (0, 1)")
        if self.drift_fraction <= 0 or self.knot_s <= 0 or self.drift_turn_s <= 0:
            raise ValueError("drift_fraction, drift_turn_s and knot_s must be positive")


@dataclass(frozen=True)
class Footprints:
    """Where each image looks.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
    centre_ne_m : ndarray, shape (N, 2)
        Footprint centre (optical axis on the floor) from the prior, metres, north and east.
    radius_m : ndarray, shape (N,)
        Radius of the disc with the footprint's area, metres.
    yaw_rad : ndarray, shape (N,)
        Prior heading of the vehicle.
    offset_body_m : ndarray, shape (N, 3)
        Footprint centre relative to the body origin, body FRD (camera lever arm plus the optical axis
        down to the floor).
    """

    t_s: FloatArray
    centre_ne_m: FloatArray
    radius_m: FloatArray
    yaw_rad: FloatArray
    offset_body_m: FloatArray

    def measured_displacement(self, i: IntArray, j: IntArray, pose6: FloatArray) -> FloatArray:
        """Footprint-centre displacements (M, 2), north-east, implied by measured relative poses.

        ``pose6`` (M, 6) is ``(x, y, z, roll, pitch, yaw)`` of ``T_i_j`` (body j in body i); it is turned
        into the world with the prior heading of image i (roll and pitch neglected):
        ``Rz(yaw_i) (t_ij + Rz(yaw_ij) o_j - o_i)``.
        """
        i, j = np.asarray(i), np.asarray(j)
        pose6 = np.atleast_2d(pose6)
        c, s = np.cos(pose6[:, 5]), np.sin(pose6[:, 5])
        oj, oi = self.offset_body_m[j], self.offset_body_m[i]
        dx = pose6[:, 0] + c * oj[:, 0] - s * oj[:, 1] - oi[:, 0]
        dy = pose6[:, 1] + s * oj[:, 0] + c * oj[:, 1] - oi[:, 1]
        ci, si = np.cos(self.yaw_rad[i]), np.sin(self.yaw_rad[i])
        return np.stack([ci * dx - si * dy, si * dx + ci * dy], axis=1)


def footprints(prior: Trajectory, altitude_m: FloatArray, rig: StereoRig) -> Footprints:
    """Footprints of the left camera at the prior's times (``prior`` sampled at the image times).

    Parameters
    ----------
    prior : Trajectory
        Navigation at the image times.
    altitude_m : ndarray, shape (N,)
        Height of the vehicle above the seafloor at the image times (DVL), metres.
    rig : StereoRig
    """
    cam = rig.left
    alt = np.maximum(np.asarray(altitude_m, dtype=float), 0.1)
    axis_body = rig.mount.R_body_sensor[:, 2]
    offset_body = rig.mount.lever_arm_body_m[None, :] + alt[:, None] * axis_body[None, :]
    centre = prior.p_ned_m + np.einsum("nij,nj->ni", prior.R_ned_body, offset_body)
    area = (alt * cam.width / cam.K[0, 0]) * (alt * cam.height / cam.K[1, 1])
    return Footprints(prior.t_s, centre[:, :2], np.sqrt(area / np.pi), prior.yaw_rad, offset_body)


def disc_overlap(rho: FloatArray) -> FloatArray:
    """Overlap of two equal discs at centre distance ``rho`` radii, as a fraction of one disc's area."""
    rho = np.clip(np.asarray(rho, dtype=float), 0.0, 2.0)
    return (2 * np.arccos(rho / 2) - (rho / 2) * np.sqrt(4 - rho**2)) / np.pi


def overlap_distance(min_overlap: float) -> float:
    """The centre distance, in radii, at which two equal discs overlap by ``min_overlap``."""
    lo, hi = 0.0, 2.0
    for _ in range(60):  # bisection on a decreasing function
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if disc_overlap(mid) > min_overlap else (lo, mid)
    return 0.5 * (lo + hi)


def overlap_probability(mu_m: FloatArray, sigma_m: FloatArray, d_max_m: FloatArray) -> FloatArray:
    """``P(|x| <= d_max)`` for ``x ~ N(mu, sigma^2 I_2)``, with ``|mu| = mu_m`` (vectorised)."""
    sigma = np.maximum(np.asarray(sigma_m, dtype=float), 1e-9)
    return ncx2.cdf((np.asarray(d_max_m) / sigma) ** 2, 2, (np.asarray(mu_m) / sigma) ** 2)


class DriftModel:
    """The navigation drift between image times, fitted to verified loop closures (module docstring).

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Image times, increasing.
    speed_mps : float
        Typical horizontal speed, m/s (sets the drift rate).
    settings : CandidateSettings
    """

    def __init__(self, t_s: FloatArray, speed_mps: float, settings: CandidateSettings) -> None:
        s = settings
        self.t0 = float(t_s[0])
        self.knot_s = s.knot_s
        self.K = max(2, int(np.ceil((t_s[-1] - t_s[0]) / s.knot_s)) + 1)
        K = self.K
        sigma_v0 = s.drift_fraction * max(speed_mps, 0.05)
        sigma_vw = sigma_v0 * np.sqrt(s.knot_s / s.drift_turn_s)
        sigma_cw = s.sigma_floor_m
        # Prior information: state x = [c_0..c_K-1, v_0..v_K-1] (one axis; both axes share it).
        H = np.zeros((2 * K, 2 * K))
        H[0, 0] += 1.0 / 1e4  # c_0 ~ N(0, 100 m): the absolute offset is free
        H[K, K] += 1.0 / sigma_v0**2
        k = np.arange(K - 1)
        # c_{k+1} - c_k - v_k dt ~ N(0, sigma_cw^2)
        rows = np.zeros((K - 1, 2 * K))
        rows[k, k + 1] = 1.0
        rows[k, k] = -1.0
        rows[k, K + k] = -s.knot_s
        H += rows.T @ rows / sigma_cw**2
        # v_{k+1} - v_k ~ N(0, sigma_vw^2)
        rows = np.zeros((K - 1, 2 * K))
        rows[k, K + k + 1] = 1.0
        rows[k, K + k] = -1.0
        H += rows.T @ rows / sigma_vw**2
        self._H0 = H
        self.correction_ne_m = np.zeros((K, 2))
        self._P_cc = np.linalg.inv(H)[:K, :K]
        self.sigma_floor_m = s.sigma_floor_m

    def _weights(self, t_s: FloatArray) -> tuple[IntArray, FloatArray]:
        u = np.clip((np.asarray(t_s, dtype=float) - self.t0) / self.knot_s, 0, self.K - 1 - 1e-9)
        k = np.floor(u).astype(np.intp)
        return k, u - k

    def fit(self, t_i: FloatArray, t_j: FloatArray, z_ne_m: FloatArray, sigma_m: FloatArray) -> None:
        """Refit to loop closures: ``c(t_j) - c(t_i) = z`` (N, 2) with 1-sigma ``sigma_m`` (N,) per axis."""
        K = self.K
        H = self._H0.copy()
        b = np.zeros((2 * K, 2))
        if len(t_i):
            # Each loop's row of the design matrix has four entries (the knots around t_i and t_j):
            # its outer product adds 16 entries to H, summed with bincount.
            ki, ai = self._weights(t_i)
            kj, aj = self._weights(t_j)
            idx = np.stack([kj, kj + 1, ki, ki + 1], axis=1)
            a = np.stack([1 - aj, aj, -(1 - ai), -ai], axis=1)
            w = 1.0 / np.asarray(sigma_m, dtype=float) ** 2
            wa = a * w[:, None]
            flat = (idx[:, :, None] * (2 * K) + idx[:, None, :]).ravel()
            H += np.bincount(flat, (wa[:, :, None] * a[:, None, :]).ravel(), (2 * K) ** 2).reshape(
                2 * K, 2 * K
            )
            z = np.asarray(z_ne_m, dtype=float)
            for axis in range(2):
                b[:, axis] += np.bincount(idx.ravel(), (wa * z[:, axis : axis + 1]).ravel(), 2 * K)
        P = np.linalg.inv(H)
        self.correction_ne_m = (P @ b)[:K]
        self._P_cc = P[:K, :K]

    def correction(self, t_s: FloatArray) -> FloatArray:
        """The fitted correction (N, 2) to add to the prior's north, east at times ``t_s``."""
        k, a = self._weights(t_s)
        return (1 - a)[:, None] * self.correction_ne_m[k] + a[:, None] * self.correction_ne_m[k + 1]

    def relative_sigma(self, t_i: FloatArray, t_j: FloatArray) -> FloatArray:
        """1-sigma (per axis) of the corrected prior's displacement between times t_i and t_j."""
        ki, ai = self._weights(t_i)
        kj, aj = self._weights(t_j)
        idx = np.stack([kj, kj + 1, ki, ki + 1], axis=1)
        w = np.stack([1 - aj, aj, -(1 - ai), -ai], axis=1)
        P = self._P_cc[idx[:, :, None], idx[:, None, :]]
        var = np.einsum("na,nab,nb->n", w, P, w)
        return np.sqrt(np.maximum(var, 0.0) + self.sigma_floor_m**2)


@lru_cache(maxsize=16)
def reach_distance(d_max_m: float, p_min: float) -> float:
    """The largest prior distance between two footprint centres at which the probability of their
    overlap (:func:`overlap_probability`) can still reach ``p_min``, whatever the uncertainty.

    For each ``sigma`` the probability falls as the distance grows, and it reaches ``p_min`` at zero
    distance only while ``sigma <= d_max / sqrt(-2 ln(1 - p_min))``; the largest distance at which it
    still reaches ``p_min``, over those ``sigma``, bounds the neighbour search (about twice
    ``d_max`` for ``p_min = 0.1``). Found on a grid, plus a margin of a grid step and 2% of ``d_max``.
    """
    sigma_cap = d_max_m / np.sqrt(-2.0 * np.log1p(-p_min))
    sigma = np.linspace(sigma_cap / 400, sigma_cap, 400)[:, None]
    mu = np.linspace(0.0, d_max_m + 5.0 * sigma_cap, 2001)
    reaches = (overlap_probability(mu[None, :], sigma, d_max_m) >= p_min).any(axis=0)
    return float(mu[reaches].max() + (mu[1] - mu[0]) + 0.02 * d_max_m)


def candidate_pairs(
    fp: Footprints,
    drift: DriftModel,
    settings: CandidateSettings,
    *,
    exclude: set[tuple[int, int]] | None = None,
) -> tuple[IntArray, IntArray, FloatArray]:
    """Non-consecutive pairs (i < j - 1) likely to overlap by ``min_overlap``, most probable first.

    Returns
    -------
    i, j : ndarray of int
    probability : ndarray
    """
    rho = overlap_distance(settings.min_overlap)
    centre = fp.centre_ne_m + drift.correction(fp.t_s)
    radius = reach_distance(rho * float(fp.radius_m.max()), settings.p_min)
    pairs = cKDTree(centre).query_pairs(radius, output_type="ndarray")
    empty = (np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0))
    if len(pairs) == 0:
        return empty
    pairs = np.sort(pairs, axis=1)
    i, j = pairs[:, 0], pairs[:, 1]
    keep = j - i > 1
    if exclude:
        n = len(centre)
        done = np.fromiter((a * n + b for a, b in exclude), dtype=np.int64, count=len(exclude))
        keep &= ~np.isin(i.astype(np.int64) * n + j, done)
    i, j = i[keep], j[keep]
    sigma = drift.relative_sigma(fp.t_s[i], fp.t_s[j])
    mu = np.linalg.norm(centre[j] - centre[i], axis=1)
    d_max = rho * 0.5 * (fp.radius_m[i] + fp.radius_m[j])
    # A point of the disc |x| <= d_max lies at most d_max along mu's direction, so the probability is
    # at most Phi((d_max - mu) / sigma): pairs for which that bound is below p_min are dropped before
    # the (slow) exact probability is computed for the rest.
    keep = (d_max - mu) / np.maximum(sigma, 1e-9) >= norm.ppf(settings.p_min)
    i, j = i[keep], j[keep]
    p = overlap_probability(mu[keep], sigma[keep], d_max[keep])
    keep = p >= settings.p_min
    order = np.argsort(-p[keep], kind="stable")
    return i[keep][order], j[keep][order], p[keep][order]
