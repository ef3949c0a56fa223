"""Robust 6-DOF registration of two triangulated point sets, with a covariance.

The paper registers the 3-D points triangulated in two stereo pairs "accounting for uncertainty in the
triangulation", an approximation of the maximum-likelihood bundle adjustment that is much faster
(section III, its reference [13]: Mahon, Williams, Pizarro and Johnson-Roberson 2008, IEEE Trans.
Robotics 24(5)). Given matched points ``a_k`` (pair A's camera frame) and ``b_k`` (pair B's) with
covariances ``S_a,k`` and ``S_b,k``, the pose ``T_a_b = (R, t)`` minimises

    sum_k r_k^T (S_a,k + R S_b,k R^T)^-1 r_k,   r_k = a_k - (R b_k + t).

Steps (:func:`register`):

1. descriptor matches: mutual nearest neighbours passing Lowe's ratio test; with a navigation prior,
   searched only inside the window the prior's uncertainty allows (pose-constrained correspondence
   search, :func:`guided_matches`), otherwise over the whole overlap (within the words of a coarse
   vocabulary when one is given);
2. RANSAC on minimal sets of three matches (Kabsch/Horn closed form; Horn 1987, JOSA A 4(4)), inliers by
   the Mahalanobis distance above (chi-square, 3 degrees of freedom);
3. weighted least squares (Gauss-Newton on the pose, weights re-evaluated with the current rotation);
4. robust refinement: iteratively reweighted with Huber weights, inliers re-selected each iteration;
5. covariance ``(J^T W J)^-1`` of the pose perturbation ``(dt, dtheta)`` with ``T <- (exp(dtheta) R,
   t + dt)``, inflated by a measured factor (``RegistrationSettings.covariance_inflation``).

A registration is rejected, with the reason, when matches or inliers are too few, the inlier ratio too
low, the fit poor (normalised residual too large), its tilt far from the prior's (the attitude sensors'
roll and pitch), or the pose too uncertain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from auvnav.frames import se3, skew
from auvnav.vision.features import Vocabulary, best_two, match_by_word, mutual_ratio_test, squared_distances
from auvnav.vision.stereo import StereoFeatures

FloatArray = NDArray[np.float64]
RANSAC_SCORING_POINTS = 300


@dataclass(frozen=True)
class RegistrationSettings:
    """Matching, RANSAC and rejection thresholds.

    Parameters
    ----------
    ratio : float
        Lowe's ratio test for descriptor matches between the two pairs.
    inlier_probability : float
        An inlier's squared Mahalanobis residual lies below the chi-square (3 dof) quantile of this.
    ransac_confidence : float
        Stop RANSAC when a better set would have been drawn with this probability, a set smaller
        than registration accepts (``min_inliers``, ``min_inlier_ratio``) counting as none: most
        candidates that do not register have fewer than 125 matches, and their sampling stops
        there instead of at ``ransac_max_iterations``. On the check dive's first 900 s at half
        scale (features cached, one core) that took verification from 0.0685 to 0.0626 CPU s a pair
        in turbid water and from 0.057 to 0.053 in coastal water, for the same recall in every water
        (one wrong loop fewer in coastal water).
    ransac_max_iterations : int
    huber_k : float
        Huber threshold on the Mahalanobis residual, sigmas.
    min_matches, min_inliers : int
    min_inlier_ratio : float
        Inliers over descriptor matches.
    max_normalised_residual : float
        Reject when ``sqrt(chi2 / dof)`` of the fit exceeds this (a fit much worse than the noise model).
    covariance_inflation : float
        The reported covariance is ``(J^T W J)^-1`` times this. The points' noise model holds for
        each point (the registration's normalised residual is below 1), but the pose errors of
        simulated loop closures are larger than ``(J^T W J)^-1`` says: errors shared by the points of
        a stereo pair (the tracker's disparity errors vary smoothly over the image) that a per-point
        model cannot see. Statistic checked: the squared Mahalanobis distance ``e^T C^-1 e`` of the
        6-dof pose error, whose mean is 6 for an honest covariance. With guided matching and the
        factor 1, its mean over 150 verified loops of the check dive's first 900 s at half scale
        (camera frame, errors under 5 cm) was 5.5 in clear water, 5.7 in coastal and 9.8 in turbid.
        With 1.25, the loop stage's accepted loops (body frame, ``auvnav evaluate``'s
        ``mahalanobis_mean``) give means of 3.6 / 4.3 / 7.6 and medians of 2.7 / 3.3 / 5.9 (the
        chi-square's median is 5.3) in clear / coastal / turbid water (``benchmarks/bench_vision.py
        --water``). It was 2.1 for the earlier procedural reef, which gave a mean of 2.2 in clear water.
    max_sigma_translation_m, max_sigma_rotation_rad : float
        Reject when the largest 1-sigma of the translation / rotation (inflated) exceeds these.
    seed : int
        RANSAC's random samples.
    guided_sigmas : float
        Prior-guided matching (:func:`guided_matches`): when :func:`register` is given a prior, a
        point of A is matched only against the points of B that the prior puts within
        ``guided_sigmas`` times its lateral 1-sigma plus ``guided_margin_m`` (3.7: the chi-square
        2-dof 99.9% radius); the ratio test is then ``guided_ratio`` among those candidates. 0:
        global matching (mutual nearest neighbours with ``ratio``, within the overlap). On the check
        dive's first 900 s at half scale, with the tilt test below, loop recall rose from 0.743 /
        0.707 / 0.541 to 0.752 / 0.730 / 0.563 in clear / coastal / turbid water and precision from
        0.995 / 0.990 / 0.992 to 0.999 / 0.998 / 0.999; verification costs about 2.4 times as much
        (no vocabulary split), the stage about 12% more CPU per pair.
    guided_margin_m : float
        Added to the window's radius: the prior's relative heading error turns the points about
        the image centre (2 degrees move a point 1 m off the axis by 3.5 cm) and the footprint model
        has errors of its own.
    guided_ratio : float
        Ratio test among the candidates inside the window (looser than ``ratio``: the window has
        already removed the look-alikes elsewhere in the image).
    max_tilt_disagreement_rad : float
        With a prior, reject a registration whose relative tilt (its rotation about the camera's x
        and y axes, the optical axis looking at the seafloor) differs from the prior's by more than
        this: the prior's tilt comes from the attitude sensors' roll and pitch, which do not drift.
        A match set that slid along ripple crests, or settled on a plane of noise, fits a pose tilted
        by a degree or more. On the check dive's first 900 s in turbid water, the prior's tilt was
        within 1.1 degrees of the truth for every pair (median 0.33); of 759 registrations, the 29
        wrong by more than 1 degree or 5 cm were tilted 0.89-6.3 degrees from the prior, the right
        ones 0.4 median, 1.1 at the 99th percentile. 0: no test.
    """

    ratio: float = 0.8
    inlier_probability: float = 0.999
    ransac_confidence: float = 0.9999
    ransac_max_iterations: int = 1000
    huber_k: float = 3.0
    min_matches: int = 12
    min_inliers: int = 25
    min_inlier_ratio: float = 0.2
    max_normalised_residual: float = 3.0
    covariance_inflation: float = 1.25
    max_sigma_translation_m: float = 0.02
    max_sigma_rotation_rad: float = float(np.radians(0.5))
    seed: int = 0
    guided_sigmas: float = 3.7
    guided_margin_m: float = 0.1
    guided_ratio: float = 0.85
    max_tilt_disagreement_rad: float = float(np.radians(1.0))


@dataclass(frozen=True)
class Registration:
    """Outcome of one registration.

    Parameters
    ----------
    accepted : bool
    reason : str
        Why it was rejected ("" when accepted).
    T_a_b : ndarray, shape (4, 4)
        Pose of frame B in frame A (``p_a = T_a_b p_b``); identity when no estimate exists.
    cov_xi : ndarray, shape (6, 6)
        Covariance of the perturbation ``(dt, dtheta)`` (metres, radians) with
        ``T_a_b <- (exp(dtheta) R, t + dt)``.
    matches, inliers : int
    normalised_residual : float
        ``sqrt(sum of squared Mahalanobis residuals / (3 inliers - 6))``: about 1 when the noise model holds.
    """

    accepted: bool
    reason: str
    T_a_b: FloatArray
    cov_xi: FloatArray
    matches: int
    inliers: int
    normalised_residual: float


def expm_so3(w: FloatArray) -> FloatArray:
    """Rodrigues' formula: rotation matrices (..., 3, 3) of rotation vectors (..., 3)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = theta < 1e-12
    th = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(th) / th)
    b = np.where(small, 0.5, (1 - np.cos(th)) / th**2)
    return np.eye(3) + a * K + b * (K @ K)


def kabsch(a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least-squares rigid fit ``a ~ R b + t`` for point sets (..., n, 3); batched over leading axes."""
    ca, cb = a.mean(-2), b.mean(-2)
    H = np.swapaxes(b - cb[..., None, :], -1, -2) @ (a - ca[..., None, :])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros(H.shape)
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    R = np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)
    t = ca - (R @ cb[..., None])[..., 0]
    return R, t


def _inverse_sym3(S: FloatArray) -> FloatArray:
    """Inverses of symmetric 3x3 matrices (..., 3, 3) by their adjugates (much faster than a batched
    LAPACK call for millions of small matrices)."""
    a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 0, 2]
    d, e, f = S[..., 1, 1], S[..., 1, 2], S[..., 2, 2]
    A00, A01, A02 = d * f - e * e, c * e - b * f, b * e - c * d
    A11, A12, A22 = a * f - c * c, b * c - a * e, a * d - b * b
    inv_det = 1.0 / (a * A00 + b * A01 + c * A02)
    W = np.empty(S.shape)
    W[..., 0, 0], W[..., 1, 1], W[..., 2, 2] = A00 * inv_det, A11 * inv_det, A22 * inv_det
    W[..., 0, 1] = W[..., 1, 0] = A01 * inv_det
    W[..., 0, 2] = W[..., 2, 0] = A02 * inv_det
    W[..., 1, 2] = W[..., 2, 1] = A12 * inv_det
    return W


def _mahalanobis2(
    a: FloatArray, b: FloatArray, Sa: FloatArray, Sb: FloatArray, R: FloatArray, t: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals, their information matrices and squared Mahalanobis distances for one pose (R, t)."""
    r = a - b @ R.T - t
    n = len(b)
    # R Sb R^T of every point in two matrix products: Sb R^T, then R (Sb R^T) = (Sb R^T)^T R^T.
    SbRt = (Sb.reshape(-1, 3) @ R.T).reshape(n, 3, 3)
    W = _inverse_sym3(Sa + (np.swapaxes(SbRt, 1, 2).reshape(-1, 3) @ R.T).reshape(n, 3, 3))
    return r, W, _quadratic_form(W, r.T)


def _quadratic_form(W: FloatArray, r_t: FloatArray) -> FloatArray:
    """``r^T W r`` for symmetric W (n, 3, 3) and residuals ``r_t`` (..., 3, n) (axis before point),
    spelt out on W's six distinct entries: several times faster than ``einsum``."""
    x, y, z = r_t[..., 0, :], r_t[..., 1, :], r_t[..., 2, :]
    d2 = x * (W[:, 0, 0] * x + 2 * W[:, 0, 1] * y + 2 * W[:, 0, 2] * z)
    d2 += y * (W[:, 1, 1] * y + 2 * W[:, 1, 2] * z)
    d2 += W[:, 2, 2] * z * z
    return d2


def _normal_equations(
    b: FloatArray, R: FloatArray, r: FloatArray, W: FloatArray, w: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``H = sum w J^T W J`` and ``g = sum w J^T W r`` with ``J = dr/d(dt, dtheta) = [-I, [R b]x]``."""
    n = len(b)
    J = np.concatenate([-np.broadcast_to(np.eye(3), (n, 3, 3)), skew(b @ R.T)], axis=2)
    WJ = (W @ J) * w[:, None, None]
    H = J.reshape(3 * n, 6).T @ WJ.reshape(3 * n, 6)
    g = WJ.reshape(3 * n, 6).T @ r.reshape(3 * n)
    return H, g


def _weights(d2: FloatArray, gate: float, huber_k: float | None) -> tuple[NDArray[np.bool_], FloatArray]:
    inl = d2 < gate
    w = inl.astype(float)
    if huber_k is not None:
        d = np.sqrt(d2)
        w *= np.where(d <= huber_k, 1.0, huber_k / np.maximum(d, 1e-12))
    return inl, w


def _ransac(
    a: FloatArray, b: FloatArray, Sa: FloatArray, Sb: FloatArray, gate: float, s: RegistrationSettings
) -> NDArray[np.bool_]:
    """The largest consensus set of minimal 3-point fits."""
    rng = np.random.default_rng(s.seed)
    n = len(a)
    # Hypotheses are scored on at most RANSAC_SCORING_POINTS matches (preemptive scoring); the best
    # one's consensus set is then taken over all matches.
    if n > RANSAC_SCORING_POINTS:
        score = np.sort(rng.choice(n, RANSAC_SCORING_POINTS, replace=False))
    else:
        score = np.arange(n)
    # Hypotheses are scored with the rotation of B's covariances ignored (``Sa + Sb``): the points'
    # uncertainty lies mostly along the camera axis, which the small tilts between pairs hardly move,
    # and it saves a 3x3 inverse per point per hypothesis.
    sa_t, sb_t = np.ascontiguousarray(a[score].T), np.ascontiguousarray(b[score].T)  # (3, m)
    W = _inverse_sym3(Sa[score] + Sb[score])

    def needed_for(w: float) -> int:
        """Hypotheses that draw a minimal set from a consensus of fraction ``w`` with the confidence."""
        failure = np.log(max(1 - w**3, 1e-12))
        return min(s.ransac_max_iterations, int(np.ceil(np.log(1 - s.ransac_confidence) / failure)))

    # A consensus smaller than registration accepts (min_inliers, min_inlier_ratio) is as good as none:
    # sampling stops once such a set, were there one, would have been drawn with the confidence.
    floor = min(1.0, max(s.min_inliers, s.min_inlier_ratio * n) / n)
    best_count = 0
    best_model: tuple[FloatArray, FloatArray] | None = None
    needed, done, batch = needed_for(floor), 0, 64
    while done < needed:
        idx = rng.integers(0, n, (batch, 3))
        pa, pb = a[idx], b[idx]
        # Skip degenerate triples: repeated or nearly collinear matches (small triangle).
        area = np.linalg.norm(np.cross(pa[:, 1] - pa[:, 0], pa[:, 2] - pa[:, 0]), axis=1)
        ok = area > 1e-3  # m^2: sides of a few centimetres at least
        if ok.any():
            R, t = kabsch(pa[ok], pb[ok])
            # residuals (hypothesis, axis, point), R b for every hypothesis in one matrix product
            r = sa_t[None] - (R.reshape(-1, 3) @ sb_t).reshape(len(R), 3, -1) - t[:, :, None]
            d2 = _quadratic_form(W, r)
            counts = (d2 < gate).sum(axis=1)
            k = int(np.argmax(counts))
            if counts[k] > best_count:
                best_count = int(counts[k])
                best_model = (R[k], t[k])
                needed = needed_for(max(best_count / len(score), floor))
        done += batch
    if best_model is None:
        return np.zeros(n, dtype=bool)
    return _mahalanobis2(a, b, Sa, Sb, *best_model)[2] < gate


def _refine(
    a: FloatArray,
    b: FloatArray,
    Sa: FloatArray,
    Sb: FloatArray,
    R: FloatArray,
    t: FloatArray,
    gate: float,
    huber_k: float | None,
    iterations: int = 10,
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_], FloatArray]:
    """Gauss-Newton on the weighted (optionally Huber-reweighted) problem; inliers re-selected each step.

    Returns R, t, the information matrix ``J^T W J`` of ``(dt, dtheta)``, the inlier mask and d2.
    """
    for _ in range(iterations):
        r, W, d2 = _mahalanobis2(a, b, Sa, Sb, R, t)
        _, w = _weights(d2, gate, huber_k)
        H, g = _normal_equations(b, R, r, W, w)
        try:
            step = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        R = expm_so3(step[3:]) @ R
        t = t + step[:3]
        if np.abs(step).max() < 1e-6:  # a micrometre, a microradian: a thousandth of any sigma here
            break
    r, W, d2 = _mahalanobis2(a, b, Sa, Sb, R, t)
    inl, w = _weights(d2, gate, huber_k)
    H, _ = _normal_equations(b, R, r, W, w)
    return R, t, H, inl, d2


def relative_tilt(R_prior: FloatArray, R: FloatArray) -> float:
    """The angle, radians, of the rotation between ``R_prior`` and ``R`` about the axes other than the
    camera's optical axis (z): ``|(w_x, w_y)|`` of the rotation vector ``w`` of ``R_prior^T R``."""
    D = R_prior.T @ R
    angle = float(np.arccos(np.clip((np.trace(D) - 1) / 2, -1.0, 1.0)))
    axis = np.array([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    norm = float(np.linalg.norm(axis))
    if norm < 1e-12:
        return 0.0 if angle < 1.0 else angle
    return angle * float(np.hypot(axis[0], axis[1])) / norm


def overlap_subsets(
    a: StereoFeatures, b: StereoFeatures, T_a_b: FloatArray, sigma_m: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of the points of A and of B that may lie in the other pair's view, given a prior pose.

    A point of A is kept when its lateral (x, y) distance from the centroid of B's points, mapped into
    A by ``T_a_b``, is within B's lateral reach (largest distance of a B point from its centroid) plus
    ``3 sigma_m``; and the same for B. Matching only these saves most of the work of partial overlaps.
    """
    ca, cb = a.p_cam_m.mean(axis=0), b.p_cam_m.mean(axis=0)
    reach_a = float(np.max(np.linalg.norm(a.p_cam_m[:, :2] - ca[:2], axis=1)))
    reach_b = float(np.max(np.linalg.norm(b.p_cam_m[:, :2] - cb[:2], axis=1)))
    cb_in_a = T_a_b[:3, :3] @ cb + T_a_b[:3, 3]
    ca_in_b = T_a_b[:3, :3].T @ (ca - T_a_b[:3, 3])
    keep_a = np.linalg.norm(a.p_cam_m[:, :2] - cb_in_a[:2], axis=1) <= reach_b + 3 * sigma_m
    keep_b = np.linalg.norm(b.p_cam_m[:, :2] - ca_in_b[:2], axis=1) <= reach_a + 3 * sigma_m
    return np.flatnonzero(keep_a), np.flatnonzero(keep_b)


def guided_matches(
    a: StereoFeatures,
    b: StereoFeatures,
    T_a_b: FloatArray,
    radius_m: float,
    ratio: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Descriptor matches searched only where the prior pose predicts them (pose-constrained
    correspondence search: Pizarro, Eustice and Singh 2003, "Relative pose estimation for
    instrumented, calibrated imaging platforms", DICTA; Eustice, Pizarro and Singh 2008, IEEE J.
    Oceanic Eng. 33(2)).

    Each point of B is mapped into A's camera frame by ``T_a_b`` (through its stereo depth); the
    candidates of a point of A are the points of B whose prediction lies within ``radius_m`` of it
    laterally (x, y of the camera frame: the prior's uncertainty ellipse, taken as a circle).
    A match is mutual (A's best among its candidates is B's best among its own) and passes the ratio
    test among the candidates of A inside the window: a texture that repeats across the image
    (ripples, sand) no longer competes with itself outside the window. The second best is capped by
    the median distance of all candidate pairs, so that a point with a single candidate must still
    be well below the typical distance.
    """
    empty = np.zeros(0, dtype=np.intp)
    if len(a) < 2 or len(b) < 2:
        return empty, empty
    # Keep only the points of each side that have a candidate on the other (most of a partial overlap
    # has none), then the descriptor distances of the pairs within the window.
    q = b.p_cam_m @ T_a_b[:2, :3].T + T_a_b[:2, 3]
    pa = a.p_cam_m[:, :2]
    lo, hi = q.min(axis=0) - radius_m, q.max(axis=0) + radius_m
    sa = np.flatnonzero(((pa >= lo) & (pa <= hi)).all(axis=1))
    if len(sa) < 2:
        return empty, empty
    lo, hi = pa[sa].min(axis=0) - radius_m, pa[sa].max(axis=0) + radius_m
    sb = np.flatnonzero(((q >= lo) & (q <= hi)).all(axis=1))
    if len(sb) < 2:
        return empty, empty
    pa32, q32 = pa[sa].astype(np.float32), q[sb].astype(np.float32)
    da, db = a.descriptors[sa].astype(np.float32), b.descriptors[sb].astype(np.float32)
    na, nb = (da * da).sum(axis=1), (db * db).sum(axis=1)
    r2 = np.float32(radius_m * radius_m)

    def candidates(rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.float32]:
        """Descriptor distances of A's points ``rows`` against B's ``cols``; inf outside the window."""
        d2 = squared_distances(da[rows], db[cols], na[rows], nb[cols])
        dx = pa32[rows, None, 0] - q32[None, cols, 0]
        dy = pa32[rows, None, 1] - q32[None, cols, 1]
        dx *= dx
        dy *= dy
        dx += dy
        np.putmask(d2, dx > r2, np.float32(np.inf))
        return d2

    # the typical distance, from a sample of the candidates
    sample = candidates(np.arange(0, len(sa), 7), np.arange(0, len(sb), 3))
    sample = sample[np.isfinite(sample)]
    typical = float(np.median(sample)) if len(sample) else 0.0
    # A's points in bands along x, each against the B points within the radius of the band in x: the
    # window keeps a fraction of the pairs, and the distances outside it are never computed
    order_a = np.argsort(pa32[:, 0], kind="stable")
    order_b = np.argsort(q32[:, 0], kind="stable")
    qx = q32[order_b, 0]
    best, second = np.full(len(sa), np.inf, np.float32), np.full(len(sa), np.inf, np.float32)
    match = np.zeros(len(sa), dtype=np.intp)
    col_best = np.full(len(sb), np.inf, np.float32)
    reach = radius_m + 1e-6  # the window's own test (float32) decides at its edge
    for start in range(0, len(sa), GUIDED_BAND_ROWS):
        rows = order_a[start : start + GUIDED_BAND_ROWS]
        c0 = int(np.searchsorted(qx, pa32[rows[0], 0] - reach, side="left"))
        c1 = int(np.searchsorted(qx, pa32[rows[-1], 0] + reach, side="right"))
        if c1 <= c0:
            continue
        cols = order_b[c0:c1]
        d2 = candidates(rows, cols)
        col_best[cols] = np.minimum(col_best[cols], d2.min(axis=0))
        best[rows], second[rows], j = best_two(d2)
        match[rows] = cols[j]
    ok = mutual_ratio_test(best, second, col_best[match], ratio=ratio, second_cap=typical)
    return sa[ok], sb[match[ok]]


#: :func:`guided_matches` compares A's points with B's in bands of this many (sorted along x).
GUIDED_BAND_ROWS = 128


def register(
    a: StereoFeatures,
    b: StereoFeatures,
    settings: RegistrationSettings | None = None,
    *,
    prior: tuple[FloatArray, float] | None = None,
    vocabulary: Vocabulary | None = None,
) -> Registration:
    """Estimate ``T_a_b`` (the pose of pair B's left camera in pair A's) from two stereo feature sets.

    ``prior``: an approximate ``T_a_b`` and the 1-sigma of its lateral position, metres; when given,
    descriptors are matched in the prior's window (:func:`guided_matches`, with
    ``settings.guided_sigmas``), or, when that is 0, only points that may lie in both views are
    matched (:func:`overlap_subsets`). ``vocabulary``: without a guided search, descriptors are matched
    within its words only (:func:`~auvnav.vision.features.match_by_word`).
    """
    s = settings or RegistrationSettings()
    if prior is not None and s.guided_sigmas > 0:
        ia, ib = guided_matches(
            a, b, prior[0], s.guided_sigmas * prior[1] + s.guided_margin_m, s.guided_ratio
        )
    else:
        if prior is not None and len(a) and len(b):
            sub_a, sub_b = overlap_subsets(a, b, *prior)
        else:
            sub_a, sub_b = np.arange(len(a)), np.arange(len(b))
        ia, ib = match_by_word(a.descriptors[sub_a], b.descriptors[sub_b], vocabulary, ratio=s.ratio)
        ia, ib = sub_a[ia], sub_b[ib]

    def reject(
        reason: str, inliers: int = 0, rho: float = float("nan"), T: FloatArray | None = None
    ) -> Registration:
        return Registration(
            False, reason, np.eye(4) if T is None else T, np.full((6, 6), np.nan), len(ia), inliers, rho
        )

    if len(ia) < max(s.min_matches, 3):
        return reject(f"too few matches ({len(ia)} < {s.min_matches})")
    pa, pb = a.p_cam_m[ia], b.p_cam_m[ib]
    Sa, Sb = a.cov_cam_m2[ia], b.cov_cam_m2[ib]
    gate = float(chi2.ppf(s.inlier_probability, 3))
    inl = _ransac(pa, pb, Sa, Sb, gate, s)
    if inl.sum() < 3:
        return reject("no consistent set of matches")
    R, t = kabsch(pa[inl], pb[inl])
    R, t, _, inl, _ = _refine(pa, pb, Sa, Sb, R, t, gate, None)  # weighted fit
    R, t, H, inl, d2 = _refine(pa, pb, Sa, Sb, R, t, gate, s.huber_k)  # robust refinement
    n_in = int(inl.sum())
    T = se3(R, t)
    dof = 3 * n_in - 6
    rho = float(np.sqrt(d2[inl].sum() / dof)) if dof > 0 else float("nan")
    if n_in < s.min_inliers:
        return reject(f"too few inliers ({n_in} < {s.min_inliers})", n_in, rho, T)
    if n_in < s.min_inlier_ratio * len(ia):
        return reject(f"inlier ratio {n_in / len(ia):.2f} < {s.min_inlier_ratio}", n_in, rho, T)
    if not rho <= s.max_normalised_residual:
        return reject(f"poor fit (normalised residual {rho:.2f} > {s.max_normalised_residual})", n_in, rho, T)
    if prior is not None and s.max_tilt_disagreement_rad > 0:
        tilt = relative_tilt(prior[0][:3, :3], R)
        if tilt > s.max_tilt_disagreement_rad:
            return reject(f"tilt disagrees with the prior ({np.degrees(tilt):.2f} deg)", n_in, rho, T)
    try:
        cov = s.covariance_inflation * np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return reject("singular information matrix", n_in, rho, T)
    sig = np.sqrt(np.clip(np.diag(cov), 0, None))
    if not (sig[:3].max() <= s.max_sigma_translation_m and sig[3:].max() <= s.max_sigma_rotation_rad):
        return reject(
            f"pose too uncertain (sigma {sig[:3].max():.3f} m, {np.degrees(sig[3:].max()):.2f} deg)",
            n_in,
            rho,
            T,
        )
    return Registration(True, "", T, cov, len(ia), n_in, rho)
