"""The shared helpers of auvnav.streams."""

import numpy as np

from auvnav.streams import GAP_PERIODS, find_gaps


def test_a_gap_is_measured_in_the_streams_own_periods() -> None:
    """At 10 Hz a 2 s hole is a gap and a 0.4 s one is not; a log sampled every 8 s has no gap at
    every sample; fewer than two times have none."""
    t = np.concatenate([np.arange(0, 10, 0.1), np.arange(12, 20, 0.1), np.arange(20.3, 30, 0.1)])
    idx, period = find_gaps(t)
    assert period == np.float64(np.median(np.diff(t)))
    np.testing.assert_array_equal(idx, [99])  # the step from 9.9 s to 12 s
    assert t[idx[0] + 1] - t[idx[0]] > GAP_PERIODS * period
    slow = np.arange(0.0, 800.0, 8.0)
    assert find_gaps(slow)[0].size == 0
    assert find_gaps(np.append(slow, 1000.0))[0].tolist() == [len(slow) - 1]
    assert find_gaps(np.array([5.0]))[0].size == 0 and find_gaps(np.array([5.0]))[1] == 0.0
