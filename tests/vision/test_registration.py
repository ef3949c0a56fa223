"""Descriptor matching, robust registration and its covariance, candidate probabilities, drift model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from auvnav.frames import euler2rot, se3
from auvnav.vision.candidates import (
    CandidateSettings,
    DriftModel,
    Footprints,
    candidate_pairs,
    disc_overlap,
    overlap_distance,
    overlap_probability,
    reach_distance,
)
from auvnav.vision.features import match_descriptors
from auvnav.vision.loops import body_pose_and_covariance
from auvnav.vision.registration import Registration, RegistrationSettings, expm_so3, register
from auvnav.vision.stereo import StereoFeatures


def _descriptors(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.integers(0, 120, (n, 128)).astype(np.uint8)


def test_matching_recovers_a_permutation_and_drops_ambiguous_matches() -> None:
    rng = np.random.default_rng(0)
    a = _descriptors(rng, 200)
    perm = rng.permutation(200)
    b = np.clip(a[perm].astype(int) + rng.integers(-3, 4, (200, 128)), 0, 255).astype(np.uint8)
    ia, ib = match_descriptors(a, b, ratio=0.8)
    assert len(ia) == 200
    np.testing.assert_array_equal(perm[ib], ia)
    # a descriptor of A with two near-identical twins in B is ambiguous: the ratio test drops it
    twins = np.vstack([b, b[:1]])
    ja, _ = match_descriptors(a, twins, ratio=0.8)
    assert len(ja) == 199 and perm[0] not in ja


def _point_sets(rng: np.random.Generator, T_a_b: np.ndarray, n: int, outliers: int = 0):
    """Matched stereo-like point sets: depth ~2 m, depth noise 15 mm, lateral noise 1 mm."""
    p_b = np.column_stack([rng.uniform(-0.6, 0.6, n), rng.uniform(-0.45, 0.45, n), rng.uniform(1.8, 2.3, n)])
    p_a_true = p_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]
    cov = np.diag([1e-3, 1e-3, 15e-3]) ** 2
    Sa = np.broadcast_to(cov, (n, 3, 3)).copy()
    Sb = Sa.copy()
    p_a = p_a_true + rng.multivariate_normal(np.zeros(3), cov, n)
    p_b = p_b + rng.multivariate_normal(np.zeros(3), cov, n)
    p_a[:outliers] += rng.uniform(-0.3, 0.3, (outliers, 3))
    desc = _descriptors(rng, n)
    return (
        StereoFeatures(np.zeros((n, 4)), p_a, Sa, desc),
        StereoFeatures(np.zeros((n, 4)), p_b, Sb, desc.copy()),
    )


def _error(reg: Registration, T_true: np.ndarray) -> np.ndarray:
    """(dt, dtheta) with T_true = (exp(dtheta) R, t + dt), as the registration's covariance."""
    import cv2

    dtheta = cv2.Rodrigues(T_true[:3, :3] @ reg.T_a_b[:3, :3].T)[0].ravel()
    return np.concatenate([T_true[:3, 3] - reg.T_a_b[:3, 3], dtheta])


def test_registration_is_robust_and_its_covariance_is_honest() -> None:
    """Monte Carlo: the normalised errors follow a chi-square with 6 degrees of freedom.

    The points' errors here are independent, as the registration's model assumes, so the covariance
    is tested without the inflation that real stereo pairs need (its docstring)."""
    rng = np.random.default_rng(3)
    exact = RegistrationSettings(covariance_inflation=1.0)
    T = se3(euler2rot(2.0, 0.03, -0.02), np.array([0.3, -0.2, 0.05]))
    d2 = []
    for _ in range(100):
        a, b = _point_sets(rng, T, 120, outliers=25)
        reg = register(a, b, exact)
        assert reg.accepted, reg.reason
        assert reg.inliers >= 90
        e = _error(reg, T)
        d2.append(e @ np.linalg.solve(reg.cov_xi, e))
    # mean of chi2(6) over 100 draws: 6 +- 3.5 * sqrt(12 / 100) (3.5 sigma)
    assert abs(np.mean(d2) - 6.0) < 3.5 * np.sqrt(12 / 100)
    assert np.mean(np.array(d2) > chi2.ppf(0.99, 6)) < 0.05


def test_registration_rejects_unrelated_sets_with_a_reason() -> None:
    rng = np.random.default_rng(4)
    a, _ = _point_sets(rng, np.eye(4), 100)
    _, b = _point_sets(rng, np.eye(4), 100)  # different descriptors: nothing matches
    reg = register(a, b)
    assert not reg.accepted and "too few matches" in reg.reason
    a, b = _point_sets(rng, np.eye(4), 30)
    reg = register(a, b, RegistrationSettings(min_inliers=40))
    assert not reg.accepted and "too few inliers" in reg.reason


def test_ransac_finds_a_consensus_barely_larger_than_registration_accepts() -> None:
    """28 inliers among 100 matches (25 accepted): RANSAC's sampling, which stops once a set of 25
    would have been drawn with its confidence, still finds them, whatever the seed (stopped at a
    consensus of half the matches, it would miss them once in five)."""
    rng = np.random.default_rng(7)
    T = se3(euler2rot(0.5, 0.02, 0.01), np.array([0.4, 0.1, 0.02]))
    for seed in range(20):
        a, b = _point_sets(rng, T, 100, outliers=72)
        reg = register(a, b, RegistrationSettings(seed=seed))
        assert reg.accepted, reg.reason
        assert 25 <= reg.inliers <= 32  # the 28 (bar one or two past the gate), chance outliers
        e = _error(reg, T)
        assert e @ np.linalg.solve(reg.cov_xi, e) < chi2.ppf(0.9999, 6)  # the true pose, not a chance one


def test_expm_so3_is_rodrigues() -> None:
    import cv2

    w = np.array([[0.3, -0.2, 0.5], [1e-3, 0.0, -2e-3], [0.0, 0.0, 0.0]])
    R = expm_so3(w)
    assert R.shape == (3, 3, 3)
    for k in range(3):
        np.testing.assert_allclose(R[k], cv2.Rodrigues(w[k])[0], atol=1e-12)


def test_body_covariance_is_the_camera_covariance_turned_into_the_body() -> None:
    """At the identity, a camera perturbation (dt, dtheta) is the body's turned by the mount, the
    rotation also moving the body through the lever arm: ``dt_b = R dt + [t]x R dtheta``."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    cov = 1e-6 * A @ A.T
    R_bc = expm_so3(np.array([0.2, -0.1, 1.3]))
    T_bc = se3(R_bc, np.array([0.5, 0.1, 0.2]))
    p, c = body_pose_and_covariance(np.eye(4), cov, T_bc)
    np.testing.assert_allclose(p, 0.0, atol=1e-12)
    M = np.zeros((6, 6))
    M[:3, :3] = M[3:, 3:] = R_bc
    t = T_bc[:3, 3]
    M[:3, 3:] = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ R_bc
    np.testing.assert_allclose(c, M @ cov @ M.T, rtol=1e-5, atol=1e-14)


def test_disc_overlap_reference_values() -> None:
    # lens area of two unit circles at distance 1: 2 pi / 3 - sqrt(3) / 2 (of pi)
    assert disc_overlap(0.0) == pytest.approx(1.0)
    assert disc_overlap(1.0) == pytest.approx((2 * np.pi / 3 - np.sqrt(3) / 2) / np.pi)
    assert disc_overlap(2.0) == pytest.approx(0.0)
    assert disc_overlap(overlap_distance(0.3)) == pytest.approx(0.3, abs=1e-9)


def test_overlap_probability_matches_monte_carlo() -> None:
    rng = np.random.default_rng(5)
    mu, sigma, d_max = 0.8, 0.5, 0.6
    x = rng.normal([mu, 0.0], sigma, (200000, 2))
    expected = np.mean(np.linalg.norm(x, axis=1) <= d_max)
    assert overlap_probability(np.array([mu]), np.array([sigma]), np.array([d_max]))[0] == pytest.approx(
        expected, abs=0.005
    )


@pytest.mark.parametrize("p_min", [0.01, 0.1, 0.5])
def test_no_pair_beyond_the_reach_distance_can_be_a_candidate(p_min: float) -> None:
    d_max = 1.0
    reach = reach_distance(d_max, p_min)
    sigma = np.geomspace(1e-3, 100.0, 4001)
    beyond = overlap_probability(np.full_like(sigma, reach), sigma, d_max)
    assert beyond.max() < p_min
    # ... and the bound is tight: a little closer, some uncertainty reaches p_min.
    inside = overlap_probability(np.full_like(sigma, 0.95 * reach), sigma, d_max)
    assert inside.max() >= p_min
    assert reach > d_max


def test_drift_model_grows_with_time_and_shrinks_at_loops() -> None:
    t = np.arange(0.0, 2000.0, 1.0)
    model = DriftModel(t, 0.5, CandidateSettings())
    s = model.relative_sigma(np.zeros(4), np.array([10.0, 100.0, 500.0, 1500.0]))
    assert np.all(np.diff(s) > 0)
    assert s[2] == pytest.approx(0.02 * 0.5 * 500, rel=0.5)  # about 2% of the distance travelled
    model.fit(np.array([200.0]), np.array([1200.0]), np.array([[1.0, -2.0]]), np.array([0.05]))
    assert model.relative_sigma(np.array([200.0]), np.array([1200.0]))[0] < 0.1
    np.testing.assert_allclose(
        model.correction(np.array([1200.0])) - model.correction(np.array([200.0])), [[1.0, -2.0]], atol=0.01
    )


def test_candidates_find_the_crossings_of_a_grid() -> None:
    """Two perpendicular passes over the same line of images: the crossing pairs are candidates."""
    t = np.arange(0.0, 400.0, 1.0)
    first = np.column_stack([0.5 * t[:200] - 50, np.zeros(200)])
    second = np.column_stack([np.zeros(200), 0.5 * t[:200] - 50])
    centre = np.vstack([first, second])
    fp = Footprints(t, centre, np.full(400, 0.75), np.zeros(400), np.zeros((400, 3)))
    settings = CandidateSettings()
    i, j, p = candidate_pairs(fp, DriftModel(t, 0.5, settings), settings)
    assert len(i) > 0 and np.all(p >= settings.p_min) and np.all(j - i > 1)
    crossing = (np.linalg.norm(centre[i], axis=1) < 1.5) & (np.linalg.norm(centre[j], axis=1) < 1.5)
    assert np.any(crossing)


def test_guided_matching_resolves_repetitive_texture_inside_the_prior_window() -> None:
    """Every descriptor repeats five times across the scene (ripples): global matching's ratio test
    rejects almost all of them; the prior-guided search finds them, and only the right ones."""
    from auvnav.vision.registration import guided_matches

    rng = np.random.default_rng(5)
    n = 300
    T = se3(euler2rot(0.05, 0.01, 0.0), np.array([0.4, -0.1, 0.02]))
    p_b = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-0.75, 0.75, n), rng.uniform(2.4, 2.6, n)])
    p_a = p_b @ T[:3, :3].T + T[:3, 3]
    patterns = rng.integers(0, 16, (n // 5, 128))
    desc = patterns[np.arange(n) % (n // 5)]
    noisy = lambda: np.clip(desc + rng.integers(-1, 2, desc.shape), 0, 15).astype(np.uint8)  # noqa: E731
    cov = np.broadcast_to(np.diag([1e-3, 1e-3, 1e-2]) ** 2, (n, 3, 3)).copy()
    a = StereoFeatures(np.zeros((n, 4)), p_a, cov, noisy())
    b = StereoFeatures(np.zeros((n, 4)), p_b, cov.copy(), noisy())
    ia, _ = match_descriptors(a.descriptors, b.descriptors, ratio=0.8)
    assert len(ia) < 0.1 * n
    prior = T.copy()
    prior[:2, 3] += [0.03, -0.02]  # the navigation's error, within its 1-sigma of 3 cm
    ga, gb = guided_matches(a, b, prior, 3.7 * 0.03 + 0.1, 0.85)
    assert len(ga) > 0.6 * n
    assert np.mean(ga == gb) > 0.97
    reg = register(a, b, RegistrationSettings(), prior=(prior, 0.03))
    assert reg.accepted and np.linalg.norm(reg.T_a_b[:3, 3] - T[:3, 3]) < 0.01
    # a prior far outside its own uncertainty (a false candidate): the window holds no true partner
    wrong = T.copy()
    wrong[:2, 3] += [0.9, 0.6]
    assert not register(a, b, RegistrationSettings(), prior=(wrong, 0.03)).accepted


@pytest.mark.parametrize("radius_m", [0.05, 0.3, 0.7, 5.0])
def test_guided_matching_in_bands_finds_what_comparing_every_pair_finds(radius_m: float) -> None:
    """The guided search compares A's points with B's in bands along x; it must give exactly the
    matches of the definition: every pair of points within the window compared, mutual best, ratio
    test against the second best capped by the typical distance of a sample of the candidates. Points
    on a 1 cm grid (ties in x, distances exactly at the radius) and repeated descriptors (ties in
    distance) probe the edges."""
    from auvnav.vision.features import mutual_matches, squared_distances
    from auvnav.vision.registration import guided_matches

    rng = np.random.default_rng(11)
    n = 1500
    p_b = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-0.75, 0.75, n), rng.uniform(2.4, 2.6, n)])
    p_b[:, :2] = np.round(p_b[:, :2], 2)
    T = se3(euler2rot(0.0, 0.0, 0.0), np.array([0.5, 0.2, 0.0]))
    p_a = p_b + T[:3, 3] + np.column_stack([np.round(rng.normal(0, 0.03, (n, 2)), 2), np.zeros(n)])
    patterns = rng.integers(0, 16, (n // 3, 128))
    desc = patterns[rng.integers(0, n // 3, n)]
    noisy = lambda: np.clip(desc + rng.integers(-2, 3, desc.shape), 0, 15).astype(np.uint8)  # noqa: E731
    cov = np.broadcast_to(np.eye(3) * 1e-6, (n, 3, 3)).copy()
    a = StereoFeatures(np.zeros((n, 4)), p_a, cov, noisy())
    b = StereoFeatures(np.zeros((n, 4)), p_b, cov.copy(), noisy())

    # the definition, every pair at once: the points of each side that may have a candidate ...
    q = p_b[:, :2] + T[:2, 3]
    pa = p_a[:, :2]
    lo, hi = q.min(axis=0) - radius_m, q.max(axis=0) + radius_m
    sa = np.flatnonzero(((pa >= lo) & (pa <= hi)).all(axis=1))
    lo, hi = pa[sa].min(axis=0) - radius_m, pa[sa].max(axis=0) + radius_m
    sb = np.flatnonzero(((q >= lo) & (q <= hi)).all(axis=1))
    # ... every descriptor distance within the window, the typical one from every 7th x 3rd
    d = pa[sa].astype(np.float32)[:, None, :] - q[sb].astype(np.float32)[None, :, :]
    outside = (d**2).sum(axis=2) > np.float32(radius_m**2)
    d2 = squared_distances(a.descriptors[sa], b.descriptors[sb])
    typical = float(np.median(d2[::7, ::3][~outside[::7, ::3]]))
    d2[outside] = np.inf
    ia, ib = mutual_matches(d2, ratio=0.85, second_cap=typical)

    ga, gb = guided_matches(a, b, T, radius_m, 0.85)
    assert len(ia) > 20
    np.testing.assert_array_equal(ga, sa[ia])
    np.testing.assert_array_equal(gb, sb[ib])


def test_a_registration_tilted_away_from_the_prior_is_rejected() -> None:
    """The prior's roll and pitch come from the attitude sensors: a fit tilted 3 degrees from them is
    a wrong one (matches slid along ripple crests), whatever its inliers say."""
    from auvnav.vision.registration import relative_tilt

    assert relative_tilt(np.eye(3), expm_so3(np.radians([0.3, -0.4, 5.0]))) == pytest.approx(
        np.radians(0.5), rel=1e-3
    )
    rng = np.random.default_rng(7)
    T = se3(euler2rot(0.2, 0.01, 0.0), np.array([0.2, 0.1, 0.0]))
    a, b = _point_sets(rng, T, 150)
    assert register(a, b, prior=(T, 0.05)).accepted
    tilted = T.copy()
    tilted[:3, :3] = expm_so3(np.radians([3.0, 0.0, 0.0])) @ T[:3, :3]
    reg = register(a, b, prior=(tilted, 0.05))
    assert not reg.accepted and reg.reason.startswith("tilt disagrees with the prior")
    assert register(a, b, RegistrationSettings(max_tilt_disagreement_rad=0.0), prior=(tilted, 0.05)).accepted
