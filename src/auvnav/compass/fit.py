"""The compass correction from dives: heading pairs against a reference, the fit of eq. 5-6, and
its constant from GPS course made good on sub-sea transits (paper section III-B, Fig. 5).

**Shape.** The compass heading of each dive (``nav/attitude``, as the compass gives it) is paired
with a reference heading at the same time: the SLAM trajectory (``products/slam/trajectory.csv``,
the paper's method), a simulated dive's truth (``truth/trajectory.csv``) or any trajectory file with
the same columns. The reference's body yaw is turned into the compass frame (the compass mount of
``vehicle.yaml``) and into magnetic north (less the dive's declination), so ``reference - compass``
is the correction ``delta(h)`` of eq. 5. The compass samples are decimated (1 Hz by default), and a
sample is paired only while the vehicle is submerged (reference depth over :data:`MIN_DEPTH_M`) and
steady (reference turn rate under :data:`MAX_TURN_RATE_DEG_S`); every skipped sample is counted.
Several dives are pooled. The robust least-squares fit is :func:`auvnav.compass.fit_deviation`.

**Constant.** A relative reference (SLAM) leaves the constant ``a0`` arbitrary. Each dive given as
a transit is dead-reckoned with the *uncorrected* compass (declination applied,
:func:`auvnav.nav.nav_inputs`), its sub-sea legs between GPS fixes (each surface stay's fixes
smoothed through the dead reckoning, :func:`smooth_surface_fixes`) give the GPS course made good
minus the dead-reckoned course (:func:`auvnav.nav.course_made_good`), and
:func:`auvnav.compass.fix_constant` fixes ``a0`` with the shape held, each leg weighted by its
inverse course variance. The constant's uncertainty adds the DVL's yaw misalignment to the
compass (:data:`DVL_YAW_SIGMA_DEG`), which turns every leg alike. A leg is used when it is long
(:data:`MIN_LEG_M`) and straight (its dead-reckoned displacement at least :data:`MIN_STRAIGHTNESS`
of its path); what it measures is the correction along it, each heading weighted by its step's
projection on the course (a dog-leg back to the start of a line counts against it). The same dive
may be both a reference dive and a transit: the paper's future work, shape and constant from one
dive that includes long legs between fixes.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from auvnav.compass.correction import FitRecord
from auvnav.compass.deviation import DeviationFit, fit_deviation, fix_constant, transit_deviation
from auvnav.compass.field import true2magnetic
from auvnav.compass.reference import REFERENCE_FILES, reference_file
from auvnav.dive import Dive, GpsStream, read_dive
from auvnav.errors import ConfigError, DiveFormatError, InsufficientDataError, Problem
from auvnav.frames import FloatArray, geodetic2ned, ned2geodetic, rot2euler, wrap_angle
from auvnav.nav.cmg import TransitLeg, course_made_good
from auvnav.nav.deadreckon import dead_reckon
from auvnav.nav.inputs import SURFACE_GAP_S, declination, nav_inputs
from auvnav.trajectory import Trajectory, read_trajectory

log = logging.getLogger(__name__)


#: Pairs per second kept: neighbouring compass samples at 10 Hz share their errors (tilt motion,
#: the reference's smoothing), so more would only make the covariance optimistic.
PAIR_RATE_HZ = 1.0
#: A sample counts as submerged below this reference depth, metres: the simulated vehicle floats
#: with its reference point at 0.3 m, where waves roll it (``VehicleDynamics.draft_m``).
MIN_DEPTH_M = 1.0
#: Steady: reference turn rate under this, degrees per second. Well under the vehicle's 10 deg/s
#: limit, so turns (and any lag between the compass and the reference in them) are left out while
#: the small corrections that hold a line are kept.
MAX_TURN_RATE_DEG_S = 2.0
#: The turn rate is the reference's yaw change over this window, centred, seconds.
TURN_RATE_WINDOW_S = 2.0
#: Sub-sea legs shorter than this between GPS fixes are not used for the constant, metres
#: (a 3 m GPS fix at each end already gives 2.4 degrees of course noise on 100 m).
MIN_LEG_M = 100.0
#: A leg is used when its dead-reckoned displacement is at least this fraction of its path.
MIN_STRAIGHTNESS = 0.8
#: Fewest GPS fixes of a surface stay for the straight-line fit of :func:`smooth_surface_fixes`.
MIN_STAY_FIXES = 3
#: 1-sigma yaw misalignment between the DVL and the compass, degrees. It turns every dead-reckoned
#: course alike, so transits measure it together with the constant (for dead reckoning with the
#: same DVL that is what is wanted; as the compass's own constant it is an error the legs' scatter
#: cannot show). vehicle.yaml does not record it; 0.1 degree is a careful installation's residual,
#: the simulator's figure (``auvnav.sim.sensors``), not a datasheet's. A DVL never aligned in situ
#: can be off by a degree or more: give the vehicle's own figure to :func:`fit_compass`.
DVL_YAW_SIGMA_DEG = 0.1

ReferenceName = Literal["truth", "slam"]


@dataclass(frozen=True)
class HeadingPairs:
    """Compass and reference headings at the same times, pooled over one or more dives.

    Parameters
    ----------
    t_s : ndarray, shape (M,)
        POSIX seconds.
    compass_heading_rad : ndarray, shape (M,)
        Heading as the compass gives it, radians.
    reference_heading_rad : ndarray, shape (M,)
        Reference heading of the compass frame from magnetic north, radians.
    dive_index : ndarray of int, shape (M,)
        Index into ``dives`` of each pair.
    dives : tuple of str
        Dive names.
    candidates : int
        Decimated compass samples considered.
    outside : int
        Of those, samples outside the reference's time span.
    surface : int
        Samples at the surface (reference depth under ``MIN_DEPTH_M``).
    turning : int
        Samples while turning (reference turn rate over the threshold).
    """

    t_s: FloatArray
    compass_heading_rad: FloatArray
    reference_heading_rad: FloatArray
    dive_index: NDArray[np.intp]
    dives: tuple[str, ...]
    candidates: int = 0
    outside: int = 0
    surface: int = 0
    turning: int = 0

    def __post_init__(self) -> None:
        shapes = {
            np.shape(a)
            for a in (self.t_s, self.compass_heading_rad, self.reference_heading_rad, self.dive_index)
        }
        if len(shapes) != 1 or len(next(iter(shapes))) != 1:
            raise ValueError(f"pair arrays must be 1-D and match; found {sorted(shapes)}")
        if len(self.dive_index) and (self.dive_index.min() < 0 or self.dive_index.max() >= len(self.dives)):
            raise ValueError(f"dive_index must index {len(self.dives)} dives")

    def __len__(self) -> int:
        return len(self.t_s)

    @classmethod
    def concatenate(cls, parts: Sequence[HeadingPairs]) -> HeadingPairs:
        """Pool the pairs of several dives (their dive lists joined in order)."""
        offsets = np.cumsum([0] + [len(p.dives) for p in parts[:-1]])
        return cls(
            t_s=np.concatenate([p.t_s for p in parts]),
            compass_heading_rad=np.concatenate([p.compass_heading_rad for p in parts]),
            reference_heading_rad=np.concatenate([p.reference_heading_rad for p in parts]),
            dive_index=np.concatenate([p.dive_index + o for p, o in zip(parts, offsets, strict=True)]),
            dives=tuple(d for p in parts for d in p.dives),
            candidates=sum(p.candidates for p in parts),
            outside=sum(p.outside for p in parts),
            surface=sum(p.surface for p in parts),
            turning=sum(p.turning for p in parts),
        )

    def summary(self) -> dict[str, int]:
        """Counts: pairs used and samples skipped, and why."""
        return {
            "used": len(self),
            "candidates": self.candidates,
            "outside_reference": self.outside,
            "surface": self.surface,
            "turning": self.turning,
        }


def _dive_name(dive: Dive) -> str:
    return dive.path.name if dive.path is not None else dive.info.name


def reference_trajectory(dive_path: Path, reference: str) -> Trajectory:
    """The reference trajectory of a dive: ``"truth"``, ``"slam"`` or a trajectory file.

    A file name is looked up in the dive folder first, then as given (one file may then serve
    several dives: each uses the part that overlaps it in time).

    Raises
    ------
    DiveFormatError
        The truth or SLAM trajectory is missing (one line naming the file), or the file is bad.
    ConfigError
        No such trajectory file.
    """
    dive_path = Path(dive_path)
    path = reference_file(dive_path, reference)
    if reference in REFERENCE_FILES and not path.is_file():
        hint = (
            "only simulated dives have a truth"
            if reference == "truth"
            else f"run `auvnav slam {dive_path}` first, or give --reference truth or a trajectory file"
        )
        raise DiveFormatError([Problem(str(path), f"not found: {hint}")])
    if not path.is_file():
        raise ConfigError(
            f"{reference}: --reference is neither truth, slam nor a trajectory file "
            f"(looked in {dive_path} and the current folder)"
        )
    return read_trajectory(path)


def heading_pairs(
    dive: Dive,
    reference: Trajectory,
    *,
    rate_hz: float = PAIR_RATE_HZ,
    min_depth_m: float = MIN_DEPTH_M,
    max_turn_rate_rad_s: float = math.radians(MAX_TURN_RATE_DEG_S),
) -> HeadingPairs:
    """Compass headings and reference headings (compass frame, magnetic) at the same times.

    Parameters
    ----------
    dive : Dive
        Its compass heading (``attitude``), declination and compass mount.
    reference : Trajectory
        Body poses in local NED (true north), interpolated at the compass samples.
    rate_hz : float
        Compass samples kept per second (the first of each ``1 / rate_hz`` interval).
    min_depth_m : float
        Samples where the reference is shallower are skipped (the surface), metres.
    max_turn_rate_rad_s : float
        Samples where the reference turns faster are skipped, rad/s.

    Returns
    -------
    HeadingPairs
        One dive's pairs with the counts of skipped samples.
    """
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be positive; found {rate_hz}")
    att = dive.attitude
    bins = np.floor((att.t_s - att.t_s[0]) * rate_hz)
    keep = np.concatenate([[True], np.diff(bins) > 0])
    t, compass = att.t_s[keep], att.heading_rad[keep]
    inside = (t >= reference.t_s[0]) & (t <= reference.t_s[-1])
    t_in = t[inside]
    ref = reference.interpolate(t_in)
    half = 0.5 * TURN_RATE_WINDOW_S
    t_before = np.clip(t_in - half, reference.t_s[0], reference.t_s[-1])
    t_after = np.clip(t_in + half, reference.t_s[0], reference.t_s[-1])
    yaw = np.unwrap(reference.yaw_rad)
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = np.abs(np.interp(t_after, reference.t_s, yaw) - np.interp(t_before, reference.t_s, yaw)) / (
            t_after - t_before
        )
    submerged = ref.p_ned_m[:, 2] >= min_depth_m
    steady = np.nan_to_num(rate, nan=np.inf) <= max_turn_rate_rad_s
    use = submerged & steady
    # The reference heading of the compass frame: R_ned_compass = R_ned_body @ R_body_compass.
    R_ned_compass = ref.R_ned_body[use] @ dive.vehicle.compass.R_body_sensor
    decl, _ = declination(dive)
    reference_heading = true2magnetic(rot2euler(R_ned_compass)[0], decl)
    name = _dive_name(dive)
    pairs = HeadingPairs(
        t_s=t_in[use],
        compass_heading_rad=compass[inside][use],
        reference_heading_rad=reference_heading,
        dive_index=np.zeros(int(use.sum()), dtype=np.intp),
        dives=(name,),
        candidates=len(t),
        outside=int(np.count_nonzero(~inside)),
        surface=int(np.count_nonzero(~submerged)),
        turning=int(np.count_nonzero(submerged & ~steady)),
    )
    log.info(
        "%s: %d heading pairs of %d samples at %g Hz (%d outside the reference, %d at the surface, "
        "%d turning faster than %.1f deg/s)",
        name,
        len(pairs),
        pairs.candidates,
        rate_hz,
        pairs.outside,
        pairs.surface,
        pairs.turning,
        math.degrees(max_turn_rate_rad_s),
    )
    return pairs


@dataclass(frozen=True)
class TransitUse:
    """A sub-sea leg of a transit dive, what it measures, and whether it fixes the constant.

    Parameters
    ----------
    dive : str
        The dive's name.
    leg : TransitLeg
        GPS course made good against the course dead-reckoned with the uncorrected compass.
    compass_heading_rad : ndarray, shape (K,)
        Compass heading of each dead-reckoned step along the leg, radians.
    step_weight : ndarray, shape (K,)
        Each step's projection on the dead-reckoned course over the course's length squared
        (the weights sum to one; see :func:`auvnav.compass.fix_constant`).
    straightness : float
        Dead-reckoned displacement over dead-reckoned path length.
    reason : str
        Empty when the leg is used; else why not.
    """

    dive: str
    leg: TransitLeg
    compass_heading_rad: FloatArray
    step_weight: FloatArray
    straightness: float
    reason: str = ""

    @property
    def used(self) -> bool:
        return not self.reason

    @property
    def heading_rad(self) -> float:
        """Compass heading of the leg: the circular mean of the steps, weighted by their progress."""
        w = np.maximum(self.step_weight, 0.0)
        return float(np.angle(np.sum(w * np.exp(1j * self.compass_heading_rad))))


def smooth_surface_fixes(dive: Dive, dr: Trajectory, *, min_gap_s: float = SURFACE_GAP_S) -> Dive:
    """The dive with the GPS fixes of each surface stay smoothed through its dead reckoning.

    A leg's course made good rests on the fixes at its two ends: one fix of 3 m at each end of a
    2 km leg is 0.12 degrees of course noise, as much as the constant's whole budget. Every fix of
    a stay (fixes less than ``min_gap_s`` apart) measures the offset of the dead-reckoned antenna
    position from the truth; a straight line in time fitted to a stay's offsets (so a steady drift
    the dead reckoning misses, such as a surface current without bottom lock, is followed rather
    than averaged away) and added back to the dead reckoning gives each smoothed fix, with the
    line's 1-sigma at its time, ``sigma * sqrt(1/n + (t - t_mean)^2 / S_tt)``. That assumes fix errors
    independent from second to second; a real receiver's are correlated over a minute or more, so
    it gains less than the sigma says, but the constant's uncertainty comes from the legs' scatter
    (:func:`auvnav.compass.fix_constant`) and leans on these sigmas only for relative weights.
    Stays of fewer than :data:`MIN_STAY_FIXES` fixes, and fixes outside the track, are kept as they are.

    Parameters
    ----------
    dive : Dive
        With GPS fixes (else returned as it is).
    dr : Trajectory
        Its dead-reckoned track, local NED about the dive's origin.
    min_gap_s : float
        Fixes further apart than this belong to different stays, seconds.

    Returns
    -------
    Dive
        A copy with the smoothed GPS stream.
    """
    gps = dive.gps
    if gps is None or len(gps) == 0:
        return dive
    origin = dive.info.origin
    antenna = geodetic2ned(gps.latitude_rad, gps.longitude_rad, np.zeros(len(gps)), origin)
    sigma = gps.sigma_m.copy()
    on_track = (gps.t_s >= dr.t_s[0]) & (gps.t_s <= dr.t_s[-1])
    smoothed = np.zeros(len(gps), dtype=bool)
    stay = np.concatenate([[0], np.cumsum(np.diff(gps.t_s) > min_gap_s)])
    for k in np.unique(stay[on_track]):
        rows = np.flatnonzero((stay == k) & on_track)
        if rows.size < MIN_STAY_FIXES:
            continue
        t = gps.t_s[rows]
        at = dr.interpolate(t)
        predicted = (
            at.p_ned_m[:, :2]
            + np.einsum("nij,j->ni", at.R_ned_body, dive.vehicle.gps.lever_arm_body_m)[:, :2]
        )
        dt = t - t.mean()
        s_tt = float(dt @ dt)
        design = np.column_stack([np.ones_like(dt), dt])
        line, *_ = np.linalg.lstsq(design, antenna[rows, :2] - predicted, rcond=None)
        antenna[rows, :2] = predicted + design @ line
        sigma[rows] *= np.sqrt(1.0 / rows.size + (dt**2 / s_tt if s_tt > 0 else 0.0))
        smoothed[rows] = True
    latitude, longitude = gps.latitude_rad.copy(), gps.longitude_rad.copy()
    if smoothed.any():
        lat, lon, _ = ned2geodetic(antenna[smoothed], origin)
        latitude[smoothed], longitude[smoothed] = np.reshape(lat, -1), np.reshape(lon, -1)
    stream = GpsStream(t_s=gps.t_s, latitude_rad=latitude, longitude_rad=longitude, sigma_m=sigma)
    return dataclasses.replace(dive, gps=stream)


def transit_legs(dive: Dive) -> list[TransitUse]:
    """The sub-sea legs of a dive with what each measures of the compass correction.

    The dive is dead-reckoned with the uncorrected compass (declination applied); each leg between
    GPS fixes (smoothed over each surface stay, :func:`smooth_surface_fixes`) gives
    ``course_error_rad = CMG - DR course``, the correction ``delta`` along it.

    Parameters
    ----------
    dive : Dive
        With GPS fixes at the surface between sub-sea legs.

    Returns
    -------
    list of TransitUse
        Every leg, used or not (with the reason).
    """
    name = _dive_name(dive)
    inputs = nav_inputs(dive)
    dr = dead_reckon(inputs)
    uses = []
    for leg in course_made_good(smooth_surface_fixes(dive, dr), dr):
        idx = np.flatnonzero((inputs.t_s >= leg.t_start_s) & (inputs.t_s <= leg.t_end_s))
        if idx.size < 2:
            uses.append(TransitUse(name, leg, np.zeros(0), np.zeros(0), 0.0, "no dead-reckoned samples"))
            continue
        p = dr.p_ned_m[idx, :2]
        steps = np.diff(p, axis=0)
        course = p[-1] - p[0]
        path_m = float(np.sum(np.linalg.norm(steps, axis=1)))
        straightness = float(np.linalg.norm(course) / path_m) if path_m > 0 else 0.0
        weight = steps @ course / max(float(course @ course), 1e-12)
        h = inputs.compass_heading_rad[idx]
        heading = np.angle(np.exp(1j * h[:-1]) + np.exp(1j * h[1:]))  # mid-step
        reason = ""
        if leg.length_m < MIN_LEG_M:
            reason = f"shorter than {MIN_LEG_M:g} m"
        elif straightness < MIN_STRAIGHTNESS:
            reason = f"not straight (displacement {100 * straightness:.0f}% of the path)"
        uses.append(TransitUse(name, leg, heading, weight, straightness, reason))
    log.info(
        "%s: %d sub-sea legs between GPS fixes, %d usable for the compass constant",
        name,
        len(uses),
        sum(u.used for u in uses),
    )
    return uses


@dataclass(frozen=True)
class CompassFit:
    """A compass correction fitted from dives, with the constant fixed from transits where given.

    Parameters
    ----------
    fit : DeviationFit
        The fit; its model carries the final constant (its residuals are those of the shape fit
        against the reference).
    pairs : HeadingPairs
    reference : str
        ``"truth"``, ``"slam"`` or the trajectory file given.
    legs : tuple of TransitUse
        Every sub-sea leg of the transit dives.
    transit_dives : tuple of str
        The transit dives' names.
    transit_residuals_rad : ndarray, shape (L,), or None
        Residual of each used leg about the final correction (course error minus what the
        correction predicts along the leg), radians.
    dvl_yaw_sigma_rad : float
        The DVL's yaw misalignment 1-sigma included in the constant's uncertainty, radians.
    """

    fit: DeviationFit
    pairs: HeadingPairs
    reference: str
    legs: tuple[TransitUse, ...] = ()
    transit_dives: tuple[str, ...] = ()
    transit_residuals_rad: FloatArray | None = None
    dvl_yaw_sigma_rad: float = 0.0

    def __post_init__(self) -> None:
        if self.transit_residuals_rad is not None and len(self.transit_residuals_rad) != len(self.used_legs):
            raise ValueError(
                f"transit_residuals_rad must have one value per used leg ({len(self.used_legs)}); "
                f"found {len(self.transit_residuals_rad)}"
            )

    @property
    def used_legs(self) -> list[TransitUse]:
        return [u for u in self.legs if u.used]

    @property
    def transit_rms_rad(self) -> float | None:
        """RMS of the used legs' residuals, radians; None without transits."""
        r = self.transit_residuals_rad
        return None if r is None else float(np.sqrt(np.mean(r**2)))

    def record(self) -> FitRecord:
        """What the correction file records of where the fit came from."""
        return FitRecord(
            reference=self.reference,
            dives=self.pairs.dives,
            pairs=len(self.pairs),
            transit_dives=self.transit_dives,
            transit_legs=len(self.used_legs) if self.transit_dives else None,
            transit_rms_rad=self.transit_rms_rad,
        )

    def summary(self) -> dict[str, Any]:
        """Machine-readable summary in degrees (``auvnav compass fit --json``)."""
        model = self.fit.model
        cov = model.covariance
        residuals = iter([] if self.transit_residuals_rad is None else np.degrees(self.transit_residuals_rad))
        rms = self.transit_rms_rad
        return {
            "reference": self.reference,
            "dives": list(self.pairs.dives),
            "pairs": self.pairs.summary(),
            **self.fit.summary(),
            "constant": {
                "source": model.constant_source,
                "sigma_deg": None if cov is None else math.degrees(math.sqrt(cov[0, 0])),
                "dvl_yaw_sigma_deg": math.degrees(self.dvl_yaw_sigma_rad) if self.transit_dives else None,
                "legs": len(self.used_legs) if self.transit_dives else None,
                "transit_rms_deg": None if rms is None else math.degrees(rms),
                "dives": list(self.transit_dives),
            },
            "legs": [
                {
                    "dive": u.dive,
                    "t_start_s": u.leg.t_start_s,
                    "t_end_s": u.leg.t_end_s,
                    "length_m": u.leg.length_m,
                    "straightness": u.straightness,
                    "heading_deg": math.degrees(u.heading_rad) % 360.0,
                    "course_error_deg": math.degrees(u.leg.course_error_rad),
                    "course_sigma_deg": math.degrees(u.leg.course_sigma_rad),
                    "residual_deg": float(next(residuals)) if u.used else None,
                    "used": u.used,
                    "reason": u.reason or None,
                }
                for u in self.legs
            ],
        }


def fit_compass(
    dive_paths: Sequence[Path],
    *,
    reference: str = "slam",
    transits: Sequence[Path] = (),
    harmonics: int = 3,
    rate_hz: float = PAIR_RATE_HZ,
    min_depth_m: float = MIN_DEPTH_M,
    max_turn_rate_rad_s: float = math.radians(MAX_TURN_RATE_DEG_S),
    dvl_yaw_sigma_rad: float = math.radians(DVL_YAW_SIGMA_DEG),
    transits_optional: bool = False,
    allow_outside: bool = False,
) -> CompassFit:
    """Fit the compass correction from dives against a reference; fix its constant from transits.

    Parameters
    ----------
    dive_paths : sequence of Path
        Dive folders whose heading pairs are pooled (at least one).
    reference : str
        ``"slam"`` (``products/slam/trajectory.csv``), ``"truth"`` (``truth/trajectory.csv``: the
        constant is then the true one) or a trajectory file (in each dive folder, or as given).
    transits : sequence of Path
        Dive folders with sub-sea legs between GPS fixes; their course made good fixes the
        constant with the shape held. A dive may also be in ``dive_paths``.
    harmonics : int
        N of eq. 5.
    rate_hz, min_depth_m, max_turn_rate_rad_s
        Pair selection (:func:`heading_pairs`).
    dvl_yaw_sigma_rad : float
        1-sigma of the DVL's yaw misalignment to the compass (:data:`DVL_YAW_SIGMA_DEG`), added
        to the transit constant's uncertainty, radians.
    transits_optional : bool
        With fewer than two usable legs, leave the constant arbitrary (the legs are still reported)
        instead of raising.
    allow_outside : bool
        Read files the dives name outside their folders (each is said; :func:`auvnav.dive.read_dive`).

    Returns
    -------
    CompassFit

    Raises
    ------
    InsufficientDataError
        Fewer pairs than unknowns, headings that cannot determine the harmonics, or transits
        without two usable legs.
    DiveFormatError, ConfigError
        A bad dive folder or a missing reference (one line naming the file).
    """
    if not dive_paths:
        raise ValueError("fit_compass needs at least one dive")
    loaded: dict[Path, Dive] = {}

    def load(path: Path) -> Dive:
        key = Path(path).resolve()
        if key not in loaded:
            loaded[key] = read_dive(Path(path), allow_outside=allow_outside)
        return loaded[key]

    parts = []
    for path in dive_paths:
        trajectory = reference_trajectory(Path(path), reference)
        parts.append(
            heading_pairs(
                load(path),
                trajectory,
                rate_hz=rate_hz,
                min_depth_m=min_depth_m,
                max_turn_rate_rad_s=max_turn_rate_rad_s,
            )
        )
    pairs = HeadingPairs.concatenate(parts)
    fit = fit_deviation(
        pairs.compass_heading_rad,
        pairs.reference_heading_rad,
        harmonics=harmonics,
        constant_source="truth" if reference == "truth" else "arbitrary",
    )
    if not transits:
        return CompassFit(fit, pairs, reference)

    legs = tuple(u for path in transits for u in transit_legs(load(path)))
    used = [u for u in legs if u.used]
    if len(used) < 2 and transits_optional:
        log.info("%d usable sub-sea legs: the constant stays arbitrary", len(used))
        return CompassFit(fit, pairs, reference, legs=legs)
    if len(used) < 2:
        raise InsufficientDataError(
            f"--transits: {len(used)} usable sub-sea legs of {len(legs)} (need 2 or more, each at least "
            f"{MIN_LEG_M:g} m between GPS fixes and straight)"
        )
    headings = [u.compass_heading_rad for u in used]
    weights = [u.step_weight for u in used]
    y = np.array([u.leg.course_error_rad for u in used])
    model = fix_constant(
        fit.model,
        headings,
        y,
        weights=1.0 / np.array([u.leg.course_sigma_rad for u in used]) ** 2,
        heading_weights=weights,
        common_sigma_rad=dvl_yaw_sigma_rad,
    )
    return CompassFit(
        fit=dataclasses.replace(fit, model=model),
        pairs=pairs,
        reference=reference,
        legs=legs,
        transit_dives=tuple(_dive_name(load(path)) for path in transits),
        transit_residuals_rad=wrap_angle(y - transit_deviation(model, headings, weights)),
        dvl_yaw_sigma_rad=dvl_yaw_sigma_rad,
    )
