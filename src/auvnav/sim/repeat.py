"""Repeat surveys of a simulated site, and inter-dive registration from the truth (testing aids).

- :func:`simulate_repeat`: the same mission flown over the seafloor of an earlier dive days later
  (another tide, its own seed: noise, DVL errors, GPS fixes), optionally with its tallest coral head
  inside the surveyed area removed (:func:`auvnav.sim.seafloor.tallest_mound`), the change written to
  ``truth/change.yaml`` (the mound's centre, height, half-axes and footprint area).
- :class:`TruthRegistration`: what a registration between images of two dives would measure, from
  the simulator's truth (as :mod:`auvnav.sim.truthloops` does within a dive): a candidate pair is
  verified when the true footprints overlap by ``min_overlap``, with the true relative pose plus 1 cm
  and 0.1 degree of noise; candidates that do not overlap pass now and then anyway with a
  plausible-looking wrong pose (a false match): ``false_fraction`` of the verified pairs of each call are
  false, as in :mod:`auvnav.sim.truthloops`. For dives simulated without images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from auvnav.config import dump_yaml
from auvnav.dive import ImageIndex, read_dive, vehicle_file_name
from auvnav.errors import InsufficientDataError
from auvnav.footprint import footprints, polygon_overlap
from auvnav.frames import FloatArray, GeodeticOrigin, euler2rot, geodetic2ned, se3, se3_inverse
from auvnav.sim.camera import body_poses, default_stereo_rig, seafloor_from_truth
from auvnav.sim.run import run_scenario
from auvnav.sim.seafloor import Mound, Seafloor, tallest_mound
from auvnav.sim.truthloops import (
    FALSE_OFFSET_M,
    SIGMA_ROTATION_RAD,
    SIGMA_TRANSLATION_M,
)
from auvnav.streams import read_stream
from auvnav.trajectory import read_trajectory
from auvnav.vehicle import read_vehicle

CHANGE_FILE = Path("truth") / "change.yaml"


def coral_to_remove(dive: Path, margin_m: float = 2.0) -> Mound:
    """The tallest reef mound centred inside a dive's imaged area (its true image poses' bounding box
    less ``margin_m``)."""
    truth = read_trajectory(dive / "truth" / "trajectory.csv")
    index = read_stream(ImageIndex, dive / "images" / "index.csv", "images/index.csv")
    p = truth.interpolate(index.t_s).p_ned_m
    floor = seafloor_from_truth(dive / "truth" / "truth.yaml")
    assert isinstance(floor, Seafloor)
    north = (float(p[:, 0].min()) + margin_m, float(p[:, 0].max()) - margin_m)
    east = (float(p[:, 1].min()) + margin_m, float(p[:, 1].max()) - margin_m)
    # Covered: at least half the images per m^2 of the survey's typical density (lines 1 m apart, an
    # image every 0.5 m: 2 per m^2), not the lead-in's single line.
    counts = np.array([len(c) for c in cKDTree(p[:, :2]).query_ball_point(p[:, :2], 2.0)])
    density = float(np.median(counts)) / (math.pi * 4.0)
    return tallest_mound(floor, north, east, points_ne_m=p[:, :2], min_density=0.5 * density)


def simulate_repeat(
    first: Path,
    out: Path,
    *,
    seed: int,
    days_later: float = 3.0,
    remove_coral: bool = True,
    scenario: str = "survey",
    **options: Any,
) -> dict[str, Any]:
    """Fly ``scenario`` again over the site of dive ``first`` (module docstring); ``options`` as
    :func:`auvnav.sim.run.run_scenario`'s (``geometry``, ``truth_loops``, ``overwrite`` ...)."""
    floor = seafloor_from_truth(first / "truth" / "truth.yaml")
    assert isinstance(floor, Seafloor)
    site = floor.seed
    try:
        mound = coral_to_remove(first) if remove_coral else None
    except ValueError as err:
        raise InsufficientDataError(
            f"{first}: {err}: no coral head to remove (keep it, or survey more)"
        ) from None
    summary = run_scenario(
        scenario,
        out,
        seed=seed,
        site_seed=int(site),
        days_later=days_later,
        removed_cells=() if mound is None else (mound.cell,),
        **options,
    )
    change: dict[str, Any] = {
        "format": "auvnav-seafloor-change/1",
        "site_seed": int(site),
        "days_later": days_later,
    }
    if mound is not None:
        change["removed"] = [
            {
                "cell": list(mound.cell),
                "north_m": mound.north_m,
                "east_m": mound.east_m,
                "height_m": mound.height_m,
                "a_m": mound.a_m,
                "b_m": mound.b_m,
                "area_m2": mound.area_m2,
            }
        ]
    (out / CHANGE_FILE).write_text(dump_yaml(change), encoding="utf-8")
    summary["change"] = change
    return summary


@dataclass
class _DiveTruth:
    T: FloatArray  # true body poses at the image times, common frame
    polygons: FloatArray  # true footprints, common frame


@dataclass
class TruthRegistration:
    """Inter-dive registration from the truth (module docstring): call with the dives' indices and
    image rows; returns which pairs verify, their relative poses ``T_a_b`` and covariances (x, y, z,
    roll, pitch, yaw of the loop-file format)."""

    dives: list[Path]
    min_overlap: float = 0.2
    false_fraction: float = 0.0
    seed: int = 0
    sigma_translation_m: float = SIGMA_TRANSLATION_M
    sigma_rotation_rad: float = SIGMA_ROTATION_RAD
    _truth: dict[int, _DiveTruth] = field(default_factory=dict)

    def _dive(self, d: int) -> _DiveTruth:
        if d not in self._truth:
            path = self.dives[d]
            common = read_dive(self.dives[0]).info.origin
            origin = read_dive(path).info.origin
            offset = origin_offset(origin, common)
            index = read_stream(ImageIndex, path / "images" / "index.csv", "images/index.csv")
            T = body_poses(read_trajectory(path / "truth" / "trajectory.csv").interpolate(index.t_s))
            rig = (
                read_vehicle(path / (vehicle_file_name(path) or "vehicle.yaml")).stereo
                or default_stereo_rig()
            )
            poly = footprints(T, rig, seafloor_from_truth(path / "truth" / "truth.yaml")) + offset[:2]
            T[:, :2, 3] += offset[:2]
            self._truth[d] = _DiveTruth(T, poly)
        return self._truth[d]

    def __call__(
        self,
        a: int,
        rows_a: NDArray[np.int64],
        b: int,
        rows_b: NDArray[np.int64],
        prior_T_a_b: FloatArray | None = None,
        sigma_m: FloatArray | None = None,
    ) -> tuple[NDArray[np.bool_], FloatArray, FloatArray, NDArray[np.bool_]]:
        """Verify candidate pairs (image ``rows_a`` of dive ``a`` with ``rows_b`` of dive ``b``; the
        prior and its sigma, which the truth does not need, are ignored).

        Returns
        -------
        verified : ndarray of bool, shape (N,)
        T_a_b : ndarray, shape (N, 4, 4)
        covariance : ndarray, shape (N, 6, 6)
        false : ndarray of bool, shape (N,)
            Verified pairs that are false matches (the truth's flag, for scoring only).
        """
        A, B = self._dive(a), self._dive(b)
        n = len(rows_a)
        overlap = np.array(
            [polygon_overlap(A.polygons[i], B.polygons[j]) for i, j in zip(rows_a, rows_b, strict=True)]
        )
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, a, b, n, 0x1D1FE]))
        true = overlap >= self.min_overlap
        # False matches: as many as make false_fraction of what verifies, among pairs that do not overlap.
        n_false = round(self.false_fraction / (1.0 - self.false_fraction) * np.count_nonzero(true))
        disjoint = np.flatnonzero(overlap <= 0.0)
        false = np.zeros(n, dtype=bool)
        false[rng.permutation(disjoint)[: min(n_false, len(disjoint))]] = True
        T_true = se3_inverse(A.T[rows_a]) @ B.T[rows_b]
        noise = rng.standard_normal((n, 6)) * np.repeat(
            [self.sigma_translation_m, self.sigma_rotation_rad], 3
        )
        dR = euler2rot(noise[:, 5], noise[:, 4], noise[:, 3])
        T_meas = T_true @ se3(dR, noise[:, :3])
        if np.any(false):
            k = int(np.count_nonzero(false))
            wrong = se3(
                euler2rot(
                    rng.uniform(-math.pi, math.pi, k), rng.normal(0, 0.017, k), rng.normal(0, 0.017, k)
                ),
                np.column_stack(
                    [rng.uniform(-FALSE_OFFSET_M, FALSE_OFFSET_M, (k, 2)), rng.normal(0, 0.05, k)]
                ),
            )
            T_meas[false] = wrong
        cov = np.broadcast_to(
            np.diag(np.repeat([self.sigma_translation_m, self.sigma_rotation_rad], 3) ** 2), (n, 6, 6)
        ).copy()
        return true | false, T_meas, cov, false


def origin_offset(origin: GeodeticOrigin, common: GeodeticOrigin) -> FloatArray:
    """A dive origin's local NED position about the common origin (north, east, down), metres."""
    return geodetic2ned(origin.latitude_rad, origin.longitude_rad, origin.height_m, common).reshape(3)
