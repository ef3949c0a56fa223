"""Before the dive: the line spacing and gaps a survey will have when the vehicle steers on its compass.

**Physics** (paper section I, Fig. 2). The vehicle's guidance holds its *own* dead-reckoned track on
the planned legs. Dead reckoning rotates the DVL's velocity by the vehicle's heading; if that heading
is wrong by ``e`` on a leg, the true track is the planned leg turned by ``e``: over a leg of length
``L`` it drifts ``L sin(e)`` across track (and ``L (1 - cos e)`` along it) while the vehicle believes
it is on the plan. The errors add up leg after leg (:func:`propagate`), until a surfacing resets the
navigation to GPS. On reciprocal lines a heading error that differs between the two directions makes
each pair a wedge, opening into the 'accordion' or closing into the 'figure 8'; an error common to
both (a constant offset) only shears and moves the survey.

**The heading error** is the true heading minus the vehicle's: ``e(h) = delta(h) - c(h)`` at compass
heading ``h``, ``delta`` the compass's true deviation (paper eq. 5) and ``c`` the correction the
vehicle applies (none: ``c = 0``). What is known before the dive (:class:`HeadingErrorPrior`):

- a correction the vehicle applies, with its stated uncertainty (the covariance of its coefficients,
  ``auvnav-compass-correction/1``): the deviation is the correction plus an error drawn from that
  covariance, so ``e = phi(h) . eta``, ``eta ~ N(0, C)``, ``phi`` the Fourier rows of eq. 6;
- the same file for a vehicle that flies *without* it (its deviation as estimated):
  ``e = phi(h) . (x + eta)``;
- only the deviation's size: ``e = X sin(h - phi0)``, a one-cycle deviation of peak ``X`` (what a hard
  iron leaves; its even harmonics are equal on reciprocal headings and cannot open lines) whose phase
  ``phi0`` is unknown, uniform;
- no deviation: ``X = 0``.

**Monte Carlo.** Each draw of the heading error gives the true track of every leg (the legs are the
mission's, corners for turns), the spacing of every adjacent pair at stations along it (as the
coverage stage measures it, :mod:`auvnav.coverage.lines`), and the coverage of the planned area: each
leg sweeps the stereo footprint at the planned altitude over a flat floor, rasterised as the stage's
images are (:mod:`auvnav.coverage.grid`) on a grid in the survey's frame, ``cell_m`` across the lines
and ``row_m`` along them. As in the stage, gaps are the unseen cells between adjacent true lines
(the accordion's), and unseen planned cells outside the lines are *not surveyed* (the figure 8's
shortfall, a moved survey); the widest gap is the longest run of uncovered cells across the lines,
counted as the stage counts a strip's width (:class:`auvnav.coverage.grid.Gaps`: ``n`` cells when
``n`` is odd, ``n - 1`` when even), which for the long gaps of a lawnmower is the width the stage
measures as its largest inscribed disc. Over the draws: the probability that any gap is at least a given
width, the coverage expected, each pair's spacing (mean and 90% band) and how likely each pair is to
be on plan, an accordion or a figure 8. :data:`NOT_MODELLED` lists what the prediction leaves out.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from auvnav.compass.deviation import DeviationModel, fourier_design
from auvnav.coverage.grid import count_cells
from auvnav.coverage.lines import LINE_END_M, across_profile
from auvnav.coverage.plan import SurveyPlan
from auvnav.errors import ConfigError
from auvnav.footprint import stereo_footprints
from auvnav.frames import FloatArray
from auvnav.vehicle import Vehicle

#: What the prediction does not model, each with its size where it can be said.
NOT_MODELLED = (
    "currents: a bottom-tracking DVL measures velocity over the ground, so a current does not move the "
    "dead-reckoned track, but the vehicle crabs (heading differs from course by the crab angle): the "
    "deviation applies at another heading and the footprint turns; without bottom lock a current "
    "drifts the track by its speed times the time without lock",
    "the DVL's scale error: it scales the lines and the steps between them alike "
    "(0.3% of a 1 m step is 3 mm)",
    "a constant heading offset beyond the stated uncertainty (the DVL's yaw misalignment, the "
    "declination): it shears and moves the survey without opening or closing lines",
    "the DVL's roll and pitch misalignment: it turns the vehicle's climbs and descents over sloping "
    "seafloor into a drift across track, the same on every line, which compresses or stretches the "
    "whole survey (a few centimetres a line, metres at the far side of a 50-line survey, in the "
    "simulator with 0.1-0.3 degree misalignments)",
    "guidance: the vehicle is taken to fly the planned legs exactly in its own navigation, turns as "
    "corners; it really overshoots each turn and settles on the line over a few metres",
    "the compass's noise, quantisation and tilt: the deviation is the one at level attitude; pitch "
    "and roll change it through the field's vertical component",
    "a deviation that changes during the dive (battery and thruster currents, equipment moved)",
    "relief and altitude changes: the footprint is the one at the planned altitude over a flat floor; "
    "where the vehicle rides low over coral heads (its altitude loop lags) the footprint shrinks and "
    "leaves holes no heading error made (in the simulator's reef, 1.22 m footprints on 1 m lines: in "
    "11 of 12 dives whose deviation was too small to open the lines a hole at least 0.5 m wide, in 5 "
    "of 12 one at least 1 m wide; over a floor without coral heads, 2 and 0 of 12)",
    "dead-reckoning noise (DVL velocity noise: centimetres over a line)",
)

PriorKind = Literal["corrected", "uncorrected", "deviation-peak"]


@dataclass(frozen=True)
class HeadingErrorPrior:
    """What is known before the dive of the heading error ``e(h)`` (module docstring).

    Parameters
    ----------
    kind : {"corrected", "uncorrected", "deviation-peak"}
    mean_rad : ndarray, shape (2N+1,)
        Mean of ``e``'s Fourier coefficients ``[a0, a1, b1, ...]``, radians.
    covariance_rad2 : ndarray, shape (2N+1, 2N+1), or None
        Their covariance (None: known exactly).
    peak_rad : float
        With ``deviation-peak``: the one-cycle deviation's peak, radians.
    correction : DeviationModel or None
        The correction the vehicle applies (its compass heading on a course depends on it).
    source : str
        Where the prior came from (a file, an option), for the record.
    """

    kind: PriorKind
    mean_rad: FloatArray
    covariance_rad2: FloatArray | None = None
    peak_rad: float = 0.0
    correction: DeviationModel | None = None
    source: str = ""

    @classmethod
    def from_correction(cls, model: DeviationModel, *, applied: bool, source: str = "") -> HeadingErrorPrior:
        """A correction file's prior: applied (``e`` = its error) or not (``e`` = the deviation)."""
        mean = np.zeros_like(model.coefficients_rad) if applied else model.coefficients_rad.copy()
        return cls(
            kind="corrected" if applied else "uncorrected",
            mean_rad=mean,
            covariance_rad2=None if model.covariance is None else np.array(model.covariance),
            correction=model if applied else None,
            source=source,
        )

    @classmethod
    def deviation_peak(cls, peak_rad: float, *, source: str = "") -> HeadingErrorPrior:
        """A one-cycle deviation of peak ``peak_rad`` with an unknown phase, no correction."""
        if not (math.isfinite(peak_rad) and peak_rad >= 0):
            raise ConfigError(f"the deviation's peak must be 0 or more; found {math.degrees(peak_rad):g} deg")
        return cls(kind="deviation-peak", mean_rad=np.zeros(3), peak_rad=float(peak_rad), source=source)

    @property
    def harmonics(self) -> int:
        return (len(self.mean_rad) - 1) // 2

    @property
    def exact(self) -> bool:
        """One outcome: no uncertainty to draw from."""
        if self.kind == "deviation-peak":
            return self.peak_rad == 0.0
        return self.covariance_rad2 is None or not np.any(self.covariance_rad2)

    def draw(self, rng: np.random.Generator, n: int) -> FloatArray:
        """``n`` draws of ``e``'s coefficients, shape (n, 2N+1), radians."""
        if self.kind == "deviation-peak":
            phase = rng.uniform(0.0, 2.0 * math.pi, n)  # e = X sin(h - phase)
            out = np.zeros((n, 3))
            out[:, 1], out[:, 2] = -self.peak_rad * np.sin(phase), self.peak_rad * np.cos(phase)
            return out
        if self.exact:
            return np.broadcast_to(self.mean_rad, (n, len(self.mean_rad))).copy()
        assert self.covariance_rad2 is not None
        return rng.multivariate_normal(self.mean_rad, self.covariance_rad2, size=n, method="eigh")

    def describe(self) -> str:
        if self.kind == "deviation-peak":
            if self.peak_rad == 0:
                return "no compass deviation"
            return (
                f"uncorrected compass, one-cycle deviation of peak {math.degrees(self.peak_rad):.2f} deg, "
                "phase unknown"
            )
        sigma = "no stated uncertainty" if self.covariance_rad2 is None else "its stated uncertainty"
        what = "correction applied" if self.kind == "corrected" else "flown without it (deviation estimate)"
        return f"{self.source or 'compass correction'}: {what}, {sigma}"


@dataclass(frozen=True)
class FootprintExtent:
    """The footprint of a level vehicle, in its body frame: along-track (forward) and across-track
    (right) extents, metres, relative to the vehicle reference point."""

    forward_m: tuple[float, float]
    right_m: tuple[float, float]

    def __post_init__(self) -> None:
        if not (self.forward_m[1] > self.forward_m[0] and self.right_m[1] > self.right_m[0]):
            raise ValueError(f"footprint extents must be increasing; found {self.forward_m}, {self.right_m}")

    @property
    def width_m(self) -> float:
        return self.right_m[1] - self.right_m[0]

    @classmethod
    def of_vehicle(cls, vehicle: Vehicle, altitude_m: float) -> FootprintExtent:
        """The stereo footprint of a level vehicle at ``altitude_m`` (the DVL's) over a flat floor."""
        if vehicle.stereo is None:
            raise ConfigError("the vehicle has no stereo rig (vehicle.yaml, key stereo)")
        floor = np.array([vehicle.dvl.lever_arm_body_m[2] + altitude_m])
        poly = stereo_footprints(np.eye(4)[None], vehicle.stereo, floor)[0]
        return cls(
            (float(poly[:, 0].min()), float(poly[:, 0].max())),
            (float(poly[:, 1].min()), float(poly[:, 1].max())),
        )

    @classmethod
    def of_width(cls, width_m: float) -> FootprintExtent:
        """A footprint ``width_m`` across, centred on the track, three quarters as long."""
        if not width_m > 0:
            raise ConfigError(f"--footprint-width-m must be positive; found {width_m:g}")
        return cls((-0.375 * width_m, 0.375 * width_m), (-0.5 * width_m, 0.5 * width_m))


def compass_headings(plan: SurveyPlan, prior: HeadingErrorPrior, declination_rad: float) -> FloatArray:
    """The compass heading on each leg, radians: the leg's bearing less the declination and the applied
    correction (solved by fixed-point iteration; the vehicle's heading is ``h + c(h) + declination``)."""
    bearing = np.array([leg.bearing_rad for leg in plan.legs])
    h = bearing - declination_rad
    if prior.correction is not None:
        for _ in range(8):
            h = bearing - declination_rad - prior.correction(h)
    return h


def propagate(plan: SurveyPlan, e_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
    """True start and end of every leg for heading errors ``e_rad`` (D, legs), radians.

    Each leg's planned vector turned by its heading error; errors add up within a navigation epoch
    (between surfacings, when the vehicle resets to GPS). Returns ``(start, end)``, each (D, legs, 2),
    north and east in metres.
    """
    start = np.array([leg.start_ne_m for leg in plan.legs])  # (L, 2)
    vec = np.array([leg.end_ne_m - leg.start_ne_m for leg in plan.legs])
    epoch = np.array([leg.epoch for leg in plan.legs])
    c, s = np.cos(e_rad), np.sin(e_rad)  # (D, L)
    turned = np.stack([c * vec[:, 0] - s * vec[:, 1], s * vec[:, 0] + c * vec[:, 1]], axis=-1)
    delta = turned - vec  # (D, L, 2): what each leg adds to the error
    csum = np.cumsum(delta, axis=1)
    before = csum - delta  # error at each leg's start, from the first leg
    first = np.array([np.flatnonzero(epoch == epoch[k])[0] for k in range(len(epoch))])
    err0 = before - before[:, first]  # reset at each epoch's first leg
    true_start = start + err0
    return true_start, true_start + turned


@dataclass(frozen=True)
class PairPrediction:
    """One adjacent pair's predicted spacing over the draws.

    Parameters
    ----------
    line_a, line_b : int
        Survey line numbers (0-based).
    planned_m : float
    along_m : ndarray, shape (S,)
    mean_m, p05_m, p95_m : ndarray, shape (S,)
        Mean and 5th/95th percentiles over the draws at each station, metres.
    class_probability : dict
        Fraction of the draws with the pair on plan, an accordion or a figure 8.
    """

    line_a: int
    line_b: int
    planned_m: float
    along_m: FloatArray
    mean_m: FloatArray
    p05_m: FloatArray
    p95_m: FloatArray
    class_probability: dict[str, float]

    def row(self) -> dict[str, Any]:
        m = self.mean_m[np.isfinite(self.mean_m)]
        nan = math.nan
        return {
            "line_a": self.line_a,
            "line_b": self.line_b,
            "planned_m": self.planned_m,
            "min_m": float(m.min()) if m.size else nan,
            "mean_m": float(m.mean()) if m.size else nan,
            "max_m": float(m.max()) if m.size else nan,
            "p_on_plan": self.class_probability["on plan"],
            "p_accordion": self.class_probability["accordion"],
            "p_figure_8": self.class_probability["figure 8"],
        }


@dataclass(frozen=True)
class Prediction:
    """What :func:`predict_survey` predicts (module docstring)."""

    prior: HeadingErrorPrior
    footprint: FootprintExtent
    draws: int
    gap_width_m: float
    p_gap: float
    coverage_pct: FloatArray  # (D,)
    uncovered_m2: FloatArray  # (D,)
    not_surveyed_m2: FloatArray  # (D,): uncovered and outside the flown lines
    widest_gap_m: FloatArray  # (D,)
    spacing_min_m: FloatArray  # (D,): each draw's smallest spacing of any pair
    spacing_max_m: FloatArray  # (D,): and largest
    pairs: list[PairPrediction]
    area_m2: float
    options: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        rows = [p.row() for p in self.pairs]
        means = np.array([r["mean_m"] for r in rows]) if rows else np.zeros(0)
        classes = {
            k: float(np.mean([p.class_probability[k] for p in self.pairs])) if self.pairs else 0.0
            for k in ("on plan", "accordion", "figure 8")
        }
        cov = self.coverage_pct
        return {
            "prior": self.prior.describe(),
            "kind": self.prior.kind,
            "draws": self.draws,
            "footprint_width_m": self.footprint.width_m,
            "planned_area_m2": self.area_m2,
            "gap_width_m": self.gap_width_m,
            "p_gap": self.p_gap,
            "coverage_pct_mean": float(cov.mean()),
            "coverage_pct_p05": float(np.percentile(cov, 5)),
            "coverage_pct_p95": float(np.percentile(cov, 95)),
            "uncovered_m2_mean": float(self.uncovered_m2.mean()),
            "not_surveyed_m2_mean": float(self.not_surveyed_m2.mean()),
            "widest_gap_m_median": float(np.median(self.widest_gap_m)),
            "spacing": {
                "planned_m": float(np.median([p.planned_m for p in self.pairs])) if self.pairs else None,
                "mean_m": float(np.nanmean(means)) if means.size else None,
                "min_m": float(np.nanmedian(self.spacing_min_m)),
                "min_p05_m": float(np.nanpercentile(self.spacing_min_m, 5)),
                "max_m": float(np.nanmedian(self.spacing_max_m)),
                "max_p95_m": float(np.nanpercentile(self.spacing_max_m, 95)),
            },
            "pair_class_probability": classes,
            "pairs": rows,
            "not_modelled": list(NOT_MODELLED),
            **self.options,
        }


def _leg_strips(start: FloatArray, end: FloatArray, fp: FootprintExtent) -> FloatArray:
    """The footprint swept along each true leg: (D, L, 4, 2) rectangles, north-east."""
    d = end - start
    length = np.maximum(np.hypot(d[..., 0], d[..., 1]), 1e-9)
    f = d / length[..., None]
    r = np.stack([-f[..., 1], f[..., 0]], axis=-1)
    (x0, x1), (y0, y1) = fp.forward_m, fp.right_m
    corners = [
        start + x0 * f + y0 * r,
        end + x1 * f + y0 * r,
        end + x1 * f + y1 * r,
        start + x0 * f + y1 * r,
    ]
    return np.stack(corners, axis=-2)


def _pair_quads(plan: SurveyPlan, start: FloatArray, end: FloatArray, end_m: float) -> FloatArray:
    """The area between each adjacent pair's true lines, ``end_m`` in from the first line's planned
    ends (as :func:`auvnav.coverage.lines.pair_quad`): (D, pairs, 4, 2), north-east; a pair whose lines
    do not run side by side gives a quadrilateral of no area."""
    out = np.empty((start.shape[0], len(plan.pairs), 4, 2))
    for k, pair in enumerate(plan.pairs):
        leg = plan.legs[pair.a]
        o, u, v = leg.start_ne_m, leg.unit, pair.across_ne
        segs = []
        lo = np.full(start.shape[0], end_m)
        hi = np.full(start.shape[0], leg.length_m - end_m)
        for line in (pair.a, pair.b):
            al0, al1 = (start[:, line] - o) @ u, (end[:, line] - o) @ u
            ac0, ac1 = (start[:, line] - o) @ v, (end[:, line] - o) @ v
            lo, hi = np.maximum(lo, np.minimum(al0, al1)), np.minimum(hi, np.maximum(al0, al1))
            segs.append((al0, al1, ac0, ac1))
        hi = np.maximum(hi, lo)

        def across(seg: tuple[FloatArray, ...], s_m: FloatArray) -> FloatArray:
            al0, al1, ac0, ac1 = seg
            return ac0 + (s_m - al0) / np.where(al1 != al0, al1 - al0, 1.0) * (ac1 - ac0)

        corners = [
            (lo, across(segs[0], lo)),
            (hi, across(segs[0], hi)),
            (hi, across(segs[1], hi)),
            (lo, across(segs[1], lo)),
        ]
        for c, (s_m, x_m) in enumerate(corners):
            out[:, k, c] = o + s_m[:, None] * u + x_m[:, None] * v
    return out


def _classes(spacing: FloatArray, planned: float, tolerance: float) -> dict[str, float]:
    """Fraction of draws (rows of ``spacing``, (D, S)) on plan, accordion, figure 8 (as the stage's rule)."""
    dev = spacing - planned
    valid = np.isfinite(dev)
    big = np.where(valid, np.abs(dev), -np.inf).max(axis=1)
    hi = np.where(valid, dev, -np.inf).max(axis=1)
    lo = np.where(valid, dev, np.inf).min(axis=1)
    flown = valid.any(axis=1)
    on = flown & (big <= tolerance)
    acc = flown & ~on & (hi >= -lo)
    fig = flown & ~on & ~acc
    n = max(len(dev), 1)
    return {"on plan": on.sum() / n, "accordion": acc.sum() / n, "figure 8": fig.sum() / n}


def _longest_run(mask: NDArray[np.bool_]) -> int:
    """The longest run of True along the rows of a 2D mask, cells."""
    if not mask.any():
        return 0
    flat = np.pad(mask, ((0, 0), (1, 1))).ravel().astype(np.int8)
    step = np.diff(flat)
    return int(np.max(np.flatnonzero(step == -1) - np.flatnonzero(step == 1)))


def _nan_percentile(x: FloatArray, q: float) -> FloatArray:
    """Percentile ``q`` of each column of ``x`` (D, S) over its finite values (NaN where none), by
    linear interpolation between order statistics (numpy's default)."""
    xs = np.sort(np.where(np.isfinite(x), x, np.inf), axis=0)
    n = np.isfinite(x).sum(axis=0)
    pos = np.clip(q / 100.0 * (n - 1), 0, None)
    lo = np.floor(pos).astype(int)
    hi = np.minimum(lo + 1, np.maximum(n - 1, 0))
    cols = np.arange(x.shape[1])
    out = xs[lo, cols] + (pos - lo) * (xs[hi, cols] - xs[lo, cols])
    return np.where(n > 0, out, np.nan)


def predict_survey(
    plan: SurveyPlan,
    prior: HeadingErrorPrior,
    footprint: FootprintExtent,
    *,
    declination_rad: float = 0.0,
    draws: int = 500,
    seed: int = 0,
    cell_m: float = 0.05,
    row_m: float = 0.25,
    gap_width_m: float = 0.5,
    station_m: float = 1.0,
    margin_m: float = 10.0,
    tolerance_m: float = 0.1,
    line_end_m: float = LINE_END_M,
) -> Prediction:
    """Predict spacing, coverage and gaps of a planned survey (module docstring).

    Parameters
    ----------
    plan : SurveyPlan
        With at least one adjacent pair (a lawnmower).
    prior : HeadingErrorPrior
    footprint : FootprintExtent
    declination_rad : float
        Magnetic declination at the site (east positive): the compass heading on a true bearing.
    draws : int
        Monte Carlo draws (one when the prior is exact).
    seed : int
    cell_m : float
        Grid cell across the lines (as the stage's cell), metres.
    row_m : float
        Grid step along the lines, metres.
    gap_width_m : float
        A gap counts when at least this wide across the lines, metres.
    station_m, margin_m, tolerance_m, line_end_m : float
        As the coverage stage's.

    Raises
    ------
    ConfigError
        The mission plans no adjacent lines.
    """
    if not plan.pairs:
        raise ConfigError(f"mission {plan.name!r}: no adjacent parallel lines to predict the spacing of")
    n = 1 if prior.exact else int(draws)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC0FE]))
    coef = prior.draw(rng, n)  # (D, 2N+1)
    h = compass_headings(plan, prior, declination_rad)
    e = coef @ fourier_design(h, prior.harmonics).T  # (D, L)
    start, end = propagate(plan, e)

    number = {leg: k for k, leg in enumerate(plan.lines)}
    pairs = []
    draw_min, draw_max = np.full(n, np.nan), np.full(n, np.nan)
    for pair in plan.pairs:
        leg = plan.legs[pair.a]
        stations = np.arange(margin_m, leg.length_m - margin_m + 1e-9, station_m)
        if stations.size == 0:
            stations = np.array([0.5 * leg.length_m])
        spacing = np.empty((n, stations.size))
        for d in range(n):
            xa = across_profile(
                np.stack([start[d, pair.a], end[d, pair.a]]),
                leg.start_ne_m,
                leg.unit,
                pair.across_ne,
                stations,
            )
            xb = across_profile(
                np.stack([start[d, pair.b], end[d, pair.b]]),
                leg.start_ne_m,
                leg.unit,
                pair.across_ne,
                stations,
            )
            spacing[d] = xb - xa
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)  # stations no draw reaches: NaN
            draw_min = np.fmin(draw_min, np.nanmin(spacing, axis=1))
            draw_max = np.fmax(draw_max, np.nanmax(spacing, axis=1))
            pairs.append(
                PairPrediction(
                    line_a=number[pair.a],
                    line_b=number[pair.b],
                    planned_m=pair.spacing_m,
                    along_m=stations,
                    mean_m=np.nanmean(spacing, axis=0),
                    p05_m=_nan_percentile(spacing, 5),
                    p95_m=_nan_percentile(spacing, 95),
                    class_probability=_classes(spacing, pair.spacing_m, tolerance_m),
                )
            )

    # coverage of the planned area, on a grid in the survey's frame: columns across the lines every
    # cell_m, rows along them every row_m (coverage changes slowly along a line)
    first = plan.pairs[0]
    origin, u, v = plan.legs[first.a].start_ne_m, plan.legs[first.a].unit, first.across_ne

    def frame(poly_ne: FloatArray) -> FloatArray:
        rel = poly_ne - origin
        return np.stack([rel @ v, rel @ u], axis=-1)  # (across, along)

    region_polys = [frame(np.asarray(p)) for p in plan.area_ne_m]
    allp = np.concatenate(region_polys)
    c0, r0 = float(allp[:, 0].min()), float(allp[:, 1].min())
    width = math.ceil((float(allp[:, 0].max()) - c0) / cell_m) + 1
    height = math.ceil((float(allp[:, 1].max()) - r0) / row_m) + 1

    def cells(poly_frame: FloatArray) -> FloatArray:
        return np.stack(
            [(poly_frame[..., 0] - c0) / cell_m - 0.5, (poly_frame[..., 1] - r0) / row_m - 0.5], axis=-1
        )

    k = max(len(p) for p in region_polys)
    padded = np.stack([np.concatenate([p, np.repeat(p[-1:], k - len(p), axis=0)]) for p in region_polys])
    region = count_cells(cells(padded), height, width) > 0
    n_region = int(np.count_nonzero(region))
    strips = cells(frame(_leg_strips(start, end, footprint)))  # (D, L, 4, 2)
    between = cells(frame(_pair_quads(plan, start, end, line_end_m)))  # (D, pairs, 4, 2)
    coverage = np.empty(n)
    uncovered = np.empty(n)
    not_surveyed = np.empty(n)
    widest = np.empty(n)
    cell_area = cell_m * row_m
    for d in range(n):
        hole = region & ~(count_cells(strips[d], height, width) > 0)
        inside = count_cells(between[d], height, width) > 0
        holes = int(np.count_nonzero(hole))
        coverage[d] = 100.0 * (n_region - holes) / max(n_region, 1)
        uncovered[d] = holes * cell_area
        not_surveyed[d] = int(np.count_nonzero(hole & ~inside)) * cell_area
        run = _longest_run(hole & inside)
        widest[d] = (run if run % 2 else max(run - 1, 0)) * cell_m  # the stage's (2 d - 1) cells
    return Prediction(
        prior=prior,
        footprint=footprint,
        draws=n,
        gap_width_m=gap_width_m,
        p_gap=float(np.mean(widest >= gap_width_m)),
        coverage_pct=coverage,
        uncovered_m2=uncovered,
        not_surveyed_m2=not_surveyed,
        widest_gap_m=widest,
        spacing_min_m=draw_min,
        spacing_max_m=draw_max,
        pairs=pairs,
        area_m2=n_region * cell_area,
        options={
            "declination_deg": math.degrees(declination_rad),
            "seed": seed,
            "cell_m": cell_m,
            "row_m": row_m,
            "station_m": station_m,
            "margin_m": margin_m,
            "tolerance_m": tolerance_m,
            "line_end_m": line_end_m,
        },
    )


def format_prediction(summary: dict[str, Any]) -> str:
    """The human account of :meth:`Prediction.summary`."""

    def m(x: float | None) -> str:
        return "-" if x is None else f"{x:.2f} m"

    sp = summary["spacing"]
    cls = summary["pair_class_probability"]
    lines = [
        f"heading error: {summary['prior']} ({summary['draws']} draw{'s' if summary['draws'] != 1 else ''})",
        f"footprint {summary['footprint_width_m']:.2f} m across; planned area {summary['planned_area_m2']:.0f} m^2",
        f"line spacing (planned {m(sp['planned_m'])}): mean {m(sp['mean_m'])}; smallest {m(sp['min_m'])} "
        f"(5%: {m(sp['min_p05_m'])}), largest {m(sp['max_m'])} (95%: {m(sp['max_p95_m'])}) (medians over the draws)",
        f"pairs: on plan {100 * cls['on plan']:.0f}%, accordion {100 * cls['accordion']:.0f}%, "
        f"figure 8 {100 * cls['figure 8']:.0f}% (averaged over pairs and draws)",
        f"coverage of the planned area: {summary['coverage_pct_mean']:.1f}% expected "
        f"(90% between {summary['coverage_pct_p05']:.1f}% and {summary['coverage_pct_p95']:.1f}%); "
        f"uncovered {summary['uncovered_m2_mean']:.1f} m^2, of which {summary['not_surveyed_m2_mean']:.1f} m^2 "
        "outside the flown lines (not surveyed)",
        f"probability of a gap between lines at least {summary['gap_width_m']:.2f} m wide: {summary['p_gap']:.2f}",
        "not modelled:",
        *[f"  - {text}" for text in summary["not_modelled"]],
    ]
    return "\n".join(lines)
