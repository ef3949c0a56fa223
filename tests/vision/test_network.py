"""The loop stage's network of images (auvnav.vision.network)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from auvnav.frames import euler2rot, rot_z, se3, se3_inverse
from auvnav.vision import network as network_module
from auvnav.vision.network import solve_network


def test_the_network_places_a_pair_between_loops_that_the_dead_reckoning_misplaces() -> None:
    """Two passes half a metre apart in opposite directions, rolled 5 degrees; the second pass's
    dead reckoning turned 3 degrees, shifted 36 cm and 3% long. With loops (from the truth) near both
    ends of the passes, the network places the pair (7, 32), between them, within a few millimetres,
    and its sigma says so; the dead reckoning had it 10 cm off. A camera 0.3 m ahead of the
    body is carried through."""
    k = np.arange(40)
    first = k < 20
    yaw = np.where(first, 0.0, np.pi)
    x = np.where(first, 0.5 * k, 0.5 * (39 - k))
    p = np.column_stack([x, np.where(first, 0.0, 0.5), np.full(40, 10.0)])
    R = euler2rot(yaw, np.zeros(40), np.full(40, np.radians(5.0)))
    T_true = se3(R, p)
    p_dr = p.copy()
    p_dr[~first, 0] = 9.5 - 1.03 * (9.5 - p[~first, 0])
    misplace = se3(rot_z(np.radians(3.0)), np.array([0.3, -0.2, 0.0]))
    T_dr = np.where(first[:, None, None], T_true, misplace @ se3(R, p_dr))
    i = np.array([1, 3, 15, 17])
    j = 39 - i  # the image of the other pass at the same place
    T_ij = se3_inverse(T_true[i]) @ T_true[j]
    cov = np.broadcast_to(np.diag([1e-6] * 3 + [1e-6] * 3), (len(i), 6, 6)).copy()
    cov[:, 0, 1] = cov[:, 1, 0] = 2e-7
    network = solve_network(T_dr, i, j, T_ij, cov)
    # a covariance from a registration is symmetric to rounding only; the verification cache keeps its
    # upper triangle, and the network solved from either is the same to the bit
    rounded = cov.copy()
    rounded[:, 1, 0] += 1e-22
    again = solve_network(T_dr, i, j, T_ij, rounded)
    np.testing.assert_array_equal(again.T_ned_body, network.T_ned_body)
    assert network.loops == 4
    T_bc = se3(np.eye(3), np.array([0.3, 0.0, 0.0]))
    a, b = np.array([7]), np.array([32])
    T, sigma = network.relative(a, b, T_bc)
    truth = se3_inverse(T_true[7] @ T_bc) @ (T_true[32] @ T_bc)
    raw = se3_inverse(T_dr[7] @ T_bc) @ (T_dr[32] @ T_bc)
    assert np.linalg.norm(raw[:2, 3] - truth[:2, 3]) > 0.08
    error = np.linalg.norm(T[0, :2, 3] - truth[:2, 3])
    assert error < 0.01
    assert error < 3 * sigma[0] < 0.05
    yaw_error = np.arctan2(*(se3_inverse(T[0]) @ truth)[[1, 0], 0])
    assert abs(yaw_error) < np.radians(0.2)
    # away from every loop (the far end of the passes), the network is less certain
    far = network.relative(np.array([10]), np.array([29]), T_bc)[1]
    assert far[0] > sigma[0]


def test_relative_sigmas_from_joints_of_many_images_are_those_of_each_pair_alone(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Pairs of a 30-image track with loops, in no order and with repeats, their joints asked four
    images at a time: each lateral sigma is the one its own pair's joint marginal covariance gives."""
    rng = np.random.default_rng(3)
    n = 30
    T = se3(
        np.tile(np.eye(3), (n, 1, 1)), np.column_stack([0.4 * np.arange(n), np.zeros(n), np.full(n, 10.0)])
    )
    i, j = np.array([0, 5, 12]), np.array([20, 25, 29])
    cov = np.broadcast_to(np.diag([1e-4] * 3 + [1e-5] * 3), (3, 6, 6)).copy()
    net = solve_network(T, i, j, se3_inverse(T[i]) @ T[j], cov)
    a = rng.integers(0, n, 40)
    b = rng.integers(0, n, 40)
    b[b == a] = (a[b == a] + 7) % n
    monkeypatch.setattr(network_module, "JOINT_IMAGES", 4)
    _, sigma = net.relative(a, b, np.eye(4))
    for k in range(len(a)):
        keys = gtsam.KeyVector()
        keys.append(int(a[k]))
        keys.append(int(b[k]))
        joint = net.marginals.jointMarginalCovariance(keys).fullMatrix()
        between = net.solution.atPose2(int(a[k])).between(net.solution.atPose2(int(b[k])))
        H = np.hstack([-between.inverse().AdjointMap(), np.eye(3)])
        alone = np.sqrt(np.linalg.eigvalsh((H @ joint @ H.T)[:2, :2])[-1])
        assert sigma[k] == pytest.approx(alone, rel=1e-9)
    assert len(set(np.round(sigma, 6))) > 10  # the pairs differ: a mix-up would show


def test_chunks_hold_at_most_the_limit_of_images_and_every_pair_once() -> None:
    rng = np.random.default_rng(4)
    a, b = rng.integers(0, 50, 200), rng.integers(0, 50, 200)
    chunks = network_module._chunks(a, b, 10)
    assert sorted(np.concatenate(chunks).tolist()) == list(range(200))
    for chunk in chunks:
        assert len(chunk) == 1 or len(np.unique(np.concatenate([a[chunk], b[chunk]]))) <= 10
