"""The SLAM graph's pieces: factors against finite differences, the loop covariance conversion
against sampling, DVL odometry and pose times on an exact synthetic dive."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from auvnav.frames import euler2rot, rot2euler, se3, se3_inverse, wrap_angle
from auvnav.nav.filter import FilterConfig, process_variance
from auvnav.nav.inputs import nav_inputs
from auvnav.nav.synthetic import START_TIME_S, Motion, Noise, legs_motion, synthetic_dive
from auvnav.slam.compass import COEFFICIENTS_KEY, CompassModel, heading_factor, yaw_jacobian
from auvnav.slam.graph import UNMEASURED_SIGMA_M, dvl_odometry, loop_covariance_tangent, position_factor
from auvnav.slam.poses import MERGE_S, build_pose_times, pose_key, pose_measurements
from auvnav.trajectory import Trajectory
from auvnav.vehicle import Mount, Vehicle
from auvnav.vision.loopfile import loops_from_transforms

angles = st.floats(-math.pi, math.pi)
tilts = st.floats(-1.2, 1.2)


def _values(T: np.ndarray, x: np.ndarray | None = None) -> gtsam.Values:
    values = gtsam.Values()
    values.insert(pose_key(0), gtsam.Pose3(T))
    if x is not None:
        values.insert(COEFFICIENTS_KEY, x)
    return values


def _numeric_pose_jacobian(
    factor: gtsam.NonlinearFactor, T: np.ndarray, x: np.ndarray | None = None
) -> np.ndarray:
    """d(unwhitened error)/d(xi) for the right perturbation T Exp(xi), central differences."""
    h = 1e-6
    columns = []
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = h
        plus = factor.unwhitenedError(_values(T @ gtsam.Pose3.Expmap(xi).matrix(), x))
        minus = factor.unwhitenedError(_values(T @ gtsam.Pose3.Expmap(-xi).matrix(), x))
        columns.append((plus - minus) / (2 * h))
    return np.column_stack(columns)


@settings(max_examples=50, deadline=None)
@given(angles, tilts, tilts)
def test_yaw_jacobian_matches_finite_differences(yaw: float, pitch: float, roll: float) -> None:
    R = euler2rot(yaw, pitch, roll)
    h = 1e-7
    numeric = [
        wrap_angle(
            rot2euler(R @ gtsam.Rot3.Expmap(h * e).matrix())[0]
            - rot2euler(R @ gtsam.Rot3.Expmap(-h * e).matrix())[0]
        )
        / (2 * h)
        for e in np.eye(3)
    ]
    np.testing.assert_allclose(yaw_jacobian(R), numeric, atol=1e-6)


@settings(max_examples=30, deadline=None)
@given(angles, st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.02, 0.02))
def test_heading_factor_measures_the_heading_only(
    yaw: float, pitch: float, roll: float, error: float
) -> None:
    """A heading error e costs (e / sigma)^2; pitch and roll errors are left to the inclinometer's factor."""
    sigma = math.radians(2.0)
    factor = heading_factor(pose_key(0), yaw, euler2rot(yaw, pitch, roll), np.eye(3), sigma)
    T = se3(euler2rot(yaw + error, pitch, roll), np.zeros(3))
    chi2 = 2.0 * factor.error(_values(T))
    assert chi2 == pytest.approx((error / sigma) ** 2, rel=1e-6, abs=1e-12)
    for tilted in (euler2rot(yaw, pitch + 0.02, roll), euler2rot(yaw, pitch, roll + 0.02)):
        # Euler ZYX: the yaw is unchanged; second order in the tilt at most (0.02^2 / 2 radians).
        assert 2.0 * factor.error(_values(se3(tilted, np.zeros(3)))) < (2e-4 / sigma) ** 2


@pytest.mark.parametrize("turn_deg", [90.0, 170.0, 179.0])
def test_heading_factor_grows_up_to_a_half_turn(turn_deg: float) -> None:
    """A pose turned by d about the vertical costs (d / sigma)^2 however large d: a flip is not free."""
    sigma = math.radians(10.0)
    R = euler2rot(0.4, 0.1, -0.2)
    factor = heading_factor(pose_key(0), 0.4, R, np.eye(3), sigma)
    turned = se3(euler2rot(0.4 + math.radians(turn_deg), 0.1, -0.2), np.zeros(3))
    assert 2.0 * factor.error(_values(turned)) == pytest.approx(
        (math.radians(turn_deg) / sigma) ** 2, rel=1e-6
    )


def test_heading_factor_of_a_rotated_compass() -> None:
    """A compass mounted at 90 deg yaw heads 90 deg further than the body."""
    mount = euler2rot(math.pi / 2, 0.0, 0.0)
    R_body = euler2rot(0.3, 0.05, -0.02)
    measured = float(rot2euler(R_body @ mount)[0])
    factor = heading_factor(pose_key(0), measured, R_body @ mount, mount, math.radians(1.0))
    assert factor.error(_values(se3(R_body, np.zeros(3)))) == pytest.approx(0.0, abs=1e-16)
    assert measured == pytest.approx(0.3 + math.pi / 2, abs=0.01)


def test_estimated_compass_factor_error_and_jacobians() -> None:
    """yaw - declination - h - phi(h) x for a heading far from the compass's, with the yaw's own
    Jacobian (finite differences of the compass frame's Euler yaw) and -phi(h)."""
    sigma = math.radians(1.0)
    model = CompassModel(
        R_body_compass=euler2rot(0.1, 0.0, 0.0), declination_rad=0.04, estimate=True, harmonics=2
    )
    h = 0.7
    x = np.array([0.01, 0.02, -0.03, 0.005, 0.004])
    phi = np.array([1.0, math.cos(h), math.sin(h), math.cos(2 * h), math.sin(2 * h)])
    T = se3(euler2rot(0.9, 0.1, -0.05), np.array([1.0, 2.0, 3.0]))
    factor = model.factor(pose_key(0), h, T[:3, :3], sigma)

    def heading_error(R: np.ndarray) -> float:
        return wrap_angle(rot2euler(R @ model.R_body_compass)[0] - 0.04 - h - phi @ x)

    A, b = factor.linearize(_values(T, x)).jacobian()  # whitened: A x - b, at the values
    assert heading_error(T[:3, :3]) == pytest.approx(0.25, abs=0.01)  # 14 degrees off the compass
    assert -b[0] * sigma == pytest.approx(heading_error(T[:3, :3]), abs=1e-12)
    step = 1e-7
    numeric = [
        wrap_angle(
            heading_error(T[:3, :3] @ gtsam.Rot3.Expmap(step * e).matrix())
            - heading_error(T[:3, :3] @ gtsam.Rot3.Expmap(-step * e).matrix())
        )
        / (2 * step)
        for e in np.eye(3)
    ]
    np.testing.assert_allclose(A[0, :3] * sigma, numeric, atol=1e-6)
    np.testing.assert_allclose(A[0, 3:6], 0.0)
    np.testing.assert_allclose(A[0, 6:] * sigma, -phi, atol=1e-12)


def test_position_factor_with_a_lever_arm_measures_only_what_is_given() -> None:
    T = se3(euler2rot(1.0, 0.1, 0.2), np.array([5.0, -3.0, 20.0]))
    lever = np.array([0.5, -0.2, -1.0])
    antenna = T[:3, 3] + T[:3, :3] @ lever
    sigma = np.array([3.0, 3.0, UNMEASURED_SIGMA_M])
    factor = position_factor(pose_key(0), antenna + np.array([0.0, 0.0, 7.0]), sigma, lever)
    assert 2.0 * factor.error(_values(T)) == 0.0  # 7 m off in the unmeasured coordinate costs nothing
    moved = se3(T[:3, :3], T[:3, 3] + np.array([3.0, 0.0, 0.0]))
    assert 2.0 * factor.error(_values(moved)) == pytest.approx(1.0, rel=1e-6)
    A = factor.linearize(_values(T)).jacobian()[0]  # whitened by sigma: no row for the depth
    np.testing.assert_allclose(A[:2] * sigma[:2, None], _numeric_pose_jacobian(factor, T)[:2], atol=1e-6)
    np.testing.assert_array_equal(A[2], 0.0)


def test_loop_covariance_in_gtsam_tangent_matches_sampling() -> None:
    """Sampled (x, y, z, roll, pitch, yaw) perturbations mapped through GTSAM's Logmap have the
    converted covariance (first order: the sample sigmas are small)."""
    rng = np.random.default_rng(0)
    rpy = np.array([0.3, -0.4, 1.0])
    T = se3(euler2rot(rpy[2], rpy[1], rpy[0]), np.array([0.4, -0.2, 0.05]))
    L = rng.normal(size=(6, 6)) * np.repeat([0.01, 0.003], 3)
    cov = L @ L.T + np.diag(np.repeat([1e-4, 1e-5], 3))
    loops = loops_from_transforms([0], [1], [0.0], [1.0], T[None], cov[None], [100])
    converted = loop_covariance_tangent(loops)[0]
    draws = rng.multivariate_normal(np.zeros(6), cov, 20000)
    p6 = np.concatenate([T[:3, 3], rpy]) + draws
    T_draw = se3(euler2rot(p6[:, 5], p6[:, 4], p6[:, 3]), p6[:, :3])
    xi = np.array([gtsam.Pose3.Logmap(gtsam.Pose3(se3_inverse(T) @ Td)) for Td in T_draw])
    sampled = np.cov(xi.T)
    scale = np.sqrt(np.outer(np.diag(converted), np.diag(converted)))
    np.testing.assert_allclose(sampled / scale, converted / scale, atol=0.05)


@pytest.fixture(scope="module")
def exact_dive():
    """A synthetic dive with exact sensors: a dog-leg with turns, lever arms and a rotated DVL."""
    motion = legs_motion(
        [(0.0, 30.0), (math.radians(100.0), 20.0), (math.radians(-120.0), 30.0)],
        rate_hz=10.0,
        turn_rate_rps=0.1,
    )
    vehicle = Vehicle(dvl=Mount(euler2rot(math.pi / 4, 0.0, 0.0), np.array([0.3, 0.1, 0.4])))
    return motion, synthetic_dive(motion, vehicle=vehicle)


def test_dvl_odometry_is_the_true_relative_pose(exact_dive) -> None:
    motion, dive = exact_dive
    inputs = nav_inputs(dive)
    t = np.arange(inputs.t_s[0] + 2.0, inputs.t_s[-1] - 2.0, 1.0)
    meas = pose_measurements(inputs, t, 1.0)
    config = FilterConfig.for_vehicle(dive.vehicle, 0.1)
    T_rel, cov = dvl_odometry(
        inputs,
        t,
        meas.R_ned_body,
        config,
        yaw_increment_sigma_rad=np.full(len(t) - 1, 1e-3),
        tilt_sigma_rad=0.01,
    )
    truth = motion.truth.interpolate(t)
    T_true = se3(truth.R_ned_body, truth.p_ned_m)
    expected = se3_inverse(T_true[:-1]) @ T_true[1:]
    assert np.abs(T_rel[:, :3, 3] - expected[:, :3, 3]).max() < 2e-3  # metres, per 0.5 m step
    rotation_error = [
        np.linalg.norm(gtsam.Rot3.Logmap(gtsam.Rot3(a[:3, :3].T @ b[:3, :3])))
        for a, b in zip(T_rel, expected, strict=True)
    ]
    assert max(rotation_error) < math.radians(0.05)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_odometry_noise_grows_across_a_dvl_dropout(exact_dive) -> None:
    motion, _ = exact_dive
    n = len(motion.truth.t_s)
    valid = np.ones(n, dtype=bool)
    valid[300:500] = False  # 20 s without bottom lock
    dive = synthetic_dive(motion, dvl_valid=valid, noise=Noise(seed=1))
    inputs = nav_inputs(dive)
    t = np.arange(inputs.t_s[0] + 2.0, inputs.t_s[-1] - 2.0, 1.0)
    meas = pose_measurements(inputs, t, 1.0)
    config = FilterConfig.for_vehicle(dive.vehicle, 0.1)
    _, cov = dvl_odometry(
        inputs,
        t,
        meas.R_ned_body,
        config,
        yaw_increment_sigma_rad=np.full(len(t) - 1, 1e-3),
        tilt_sigma_rad=0.01,
    )
    inside = (t[:-1] > motion.truth.t_s[310]) & (t[1:] < motion.truth.t_s[490])
    outside = (t[1:] < motion.truth.t_s[250]) | (t[:-1] > motion.truth.t_s[550])
    var_x = cov[:, 3, 3]
    assert var_x[inside].min() > 100 * var_x[outside].max()
    # The filter's process noise, horizontally: the same model in both (a level dive, so the body's
    # horizontal plane is the level one).
    Q_h, _ = process_variance(inputs, config)
    var_h = np.diff(np.interp(t, inputs.t_s, Q_h))
    np.testing.assert_allclose(0.5 * (var_x + cov[:, 4, 4])[inside], var_h[inside], rtol=0.05)


def test_pose_times_add_fixes_and_fill_gaps(exact_dive) -> None:
    motion, _ = exact_dive
    t0 = motion.truth.t_s[0]
    gps = t0 + np.array([0.5, 1.5, 2.5, 60.0 + MERGE_S / 2, 150.0])
    dive = synthetic_dive(motion, gps_times_s=gps)
    inputs = nav_inputs(dive)
    images = t0 + np.concatenate([np.arange(10.0, 100.0, 1.0), np.arange(120.0, 140.0, 1.0)])
    times = build_pose_times(images, inputs, aux_period_s=1.0, source="test")
    assert times.n_images == len(images)
    np.testing.assert_array_equal(times.t_s[times.is_image], images)
    np.testing.assert_array_equal(times.pose_of_image() >= 0, True)
    for fix in gps:  # every fix has a pose within MERGE_S
        assert np.min(np.abs(times.t_s - fix)) <= MERGE_S
    assert np.count_nonzero(np.abs(times.t_s - gps[3]) < 0.5) == 1  # merged into the image at 60 s
    assert np.diff(times.t_s).max() <= 1.5  # the gaps are filled
    assert times.t_s[0] == pytest.approx(gps[0]) and times.t_s[-1] == pytest.approx(gps[-1])


def test_a_hovering_descent_bridges_little_horizontally() -> None:
    """A vehicle sinking straight down at 0.3 m/s without bottom lock: the odometry's horizontal
    variance across the dropout follows its (zero) horizontal speed, its vertical one the 3D speed
    (the filter's model), so the GPS fixes at the surface reach the seafloor through the descent."""
    t = START_TIME_S + np.arange(0.0, 200.0, 0.2)
    n = len(t)
    down = 2.0 + 0.3 * t.clip(None, START_TIME_S + 100.0) - 0.3 * START_TIME_S
    zero = np.zeros(n)
    v_body = np.zeros((n, 3))
    v_body[:, 2] = np.where(t < START_TIME_S + 100.0, 0.3, 0.0)
    truth = Trajectory(t, np.column_stack([zero, zero, down]), zero, zero, zero)
    motion = Motion(truth, v_body, np.zeros((n, 3)))
    valid = t > START_TIME_S + 80.0  # bottom lock for the last 20 s of the descent
    dive = synthetic_dive(motion, dvl_valid=valid)
    inputs = nav_inputs(dive)
    times = np.arange(t[0] + 1.0, t[-1] - 1.0, 1.0)
    meas = pose_measurements(inputs, times, 1.0)
    config = FilterConfig.for_vehicle(dive.vehicle, 0.1)
    _, cov = dvl_odometry(
        inputs,
        times,
        meas.R_ned_body,
        config,
        yaw_increment_sigma_rad=np.full(len(times) - 1, 1e-3),
        tilt_sigma_rad=0.01,
    )
    gap = times[1:] < START_TIME_S + 75.0
    floor = config.bridge_velocity_sigma_mps**2 * inputs.dropouts.duration_s[0]  # per second
    np.testing.assert_allclose(cov[gap, 3, 3], floor, rtol=0.05)
    assert np.all(cov[gap, 5, 5] > 10 * floor)
