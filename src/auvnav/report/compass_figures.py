"""Compass correction figure, the analogue of the paper's Fig. 5 (matplotlib lives in ``report/`` only).

:func:`plot_correction` draws a :class:`CorrectionFigure`, which is read from the compass stage's
products (:meth:`CorrectionFigure.from_products`) or taken from a fit just made
(:meth:`CorrectionFigure.from_fit`, for ``auvnav compass fit --out FILE``): the same figure either way.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from numpy.typing import NDArray

from auvnav import products as P
from auvnav.compass.correction import read_correction
from auvnav.compass.deviation import DeviationModel
from auvnav.compass.fit import CompassFit
from auvnav.frames import FloatArray
from auvnav.streams import atomic_write

_GRID_DEG = np.arange(0.0, 360.25, 0.25)


@dataclass(frozen=True)
class CorrectionFigure:
    """What the Fig. 5 plot shows.

    Parameters
    ----------
    model : DeviationModel
        The correction, its covariance and the source of its constant.
    compass_heading_rad, residuals_rad : ndarray, shape (M,)
        Each heading pair's compass heading and its residual against the shape fit.
    inlier : ndarray of bool, shape (M,)
    gaps : list of (float, float)
        Compass sectors without pairs, radians.
    leg_heading_rad, leg_reduced_rad, leg_sigma_rad : ndarray, shape (L,)
        Each used transit leg's mean compass heading, what it measures of the correction reduced to
        that heading, and its 1-sigma.
    title : str
    """

    model: DeviationModel
    compass_heading_rad: FloatArray
    residuals_rad: FloatArray
    inlier: NDArray[np.bool_]
    gaps: list[tuple[float, float]]
    leg_heading_rad: FloatArray
    leg_reduced_rad: FloatArray
    leg_sigma_rad: FloatArray
    title: str

    @staticmethod
    def _title(n_pairs: int, dives: list[str], reference: str, legs: int, source: str) -> str:
        constant = {
            "truth": "constant from the truth",
            "gps-transits": f"constant from {legs} GPS legs",
            "arbitrary": "constant arbitrary",
            "graph": "constant from the pose graph",
        }[source]
        return (
            f"compass correction: {n_pairs} pairs from {', '.join(dives)} (reference {reference}); {constant}"
        )

    @classmethod
    def from_fit(cls, result: CompassFit) -> CorrectionFigure:
        """The figure of a fit just made."""
        fit, model = result.fit, result.fit.model
        used = result.used_legs
        heading = np.array([u.heading_rad for u in used])
        residual = np.zeros(0) if result.transit_residuals_rad is None else result.transit_residuals_rad
        return cls(
            model=model,
            compass_heading_rad=fit.compass_heading_rad,
            residuals_rad=fit.residuals_rad,
            inlier=fit.inlier,
            gaps=list(fit.gaps),
            leg_heading_rad=heading,
            leg_reduced_rad=residual + model(heading) if len(used) else np.zeros(0),
            leg_sigma_rad=np.array([u.leg.course_sigma_rad for u in used]),
            title=cls._title(
                len(result.pairs),
                list(result.pairs.dives),
                result.reference,
                len(used),
                model.constant_source,
            ),
        )

    @classmethod
    def from_products(cls, dive: Path) -> CorrectionFigure:
        """The figure of a dive's compass stage products."""
        model = read_correction(P.COMPASS_CORRECTION.path(dive))
        pairs = pd.read_csv(P.COMPASS_PAIRS.path(dive))
        summary = json.loads(P.COMPASS_SUMMARY.path(dive).read_text(encoding="utf-8"))
        used = [leg for leg in summary["legs"] if leg["used"]]
        heading = np.radians([leg["heading_deg"] for leg in used])
        return cls(
            model=model,
            compass_heading_rad=np.radians(pairs["compass_heading_deg"].to_numpy(dtype=float)),
            residuals_rad=np.radians(pairs["residual_deg"].to_numpy(dtype=float)),
            inlier=pairs["inlier"].to_numpy(dtype=bool),
            gaps=[(math.radians(a), math.radians(b)) for a, b in summary["gaps_deg"]],
            leg_heading_rad=heading,
            leg_reduced_rad=np.radians([leg["residual_deg"] for leg in used]) + model(heading)
            if used
            else np.zeros(0),
            leg_sigma_rad=np.radians([leg["course_sigma_deg"] for leg in used]),
            title=cls._title(
                len(pairs), summary["dives"], summary["reference"], len(used), model.constant_source
            ),
        )


def plot_correction(
    figure: CorrectionFigure,
    path: Path,
    *,
    true_deviation: tuple[FloatArray, FloatArray] | None = None,
    dpi: int = 120,
) -> Path:
    """The correction against compass heading: data, fit, 2-sigma band, GPS legs, truth (Fig. 5).

    Top: each heading pair's reference minus compass heading (grey; outliers red), placed on the
    final constant when transits re-fixed it; the fitted curve with its 2-sigma band; compass
    sectors without data shaded; each transit leg's GPS course made good minus dead-reckoned course
    with its 1-sigma (reduced to the leg's mean heading: what the leg measures, less the fit's
    variation along it); the true curve when the dive is simulated. Bottom: the fit minus the true
    curve with the band when there is a truth, else the pairs' residuals.

    Parameters
    ----------
    figure : CorrectionFigure
    path : Path
        PNG file to write.
    true_deviation : (compass_heading_rad, deviation_rad), optional
        The simulator's true ``delta(h)``.
    dpi : int

    Returns
    -------
    Path
    """
    model = figure.model
    grid = np.radians(_GRID_DEG)
    curve = np.degrees(model(grid))
    band = 2.0 * np.degrees(model.sigma(grid))
    h_deg = np.degrees(figure.compass_heading_rad) % 360.0
    points = np.degrees(model(figure.compass_heading_rad) + figure.residuals_rad)
    inlier = figure.inlier

    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(9, 7), sharex=True, gridspec_kw={"height_ratios": [3, 1.4]}
    )
    top.scatter(h_deg[inlier], points[inlier], s=3, c="0.55", lw=0, label="reference - compass")
    outlier = np.isfinite(points) & ~inlier
    if outlier.any():
        top.scatter(h_deg[outlier], points[outlier], s=8, c="tab:red", marker="x", lw=0.6, label="outliers")
    if np.all(np.isfinite(band)):
        top.fill_between(
            _GRID_DEG, curve - band, curve + band, color="tab:blue", alpha=0.2, lw=0, label="2-sigma"
        )
    top.plot(_GRID_DEG, curve, c="tab:blue", lw=1.5, label=f"fit, {model.harmonics} harmonics")
    if true_deviation is not None:
        h_true, delta_true = true_deviation
        order = np.argsort(np.degrees(h_true) % 360.0)
        top.plot(
            (np.degrees(h_true) % 360.0)[order],
            np.degrees(delta_true)[order],
            c="k",
            lw=1.0,
            ls="--",
            label="true",
        )
    if len(figure.leg_heading_rad):
        top.errorbar(
            np.degrees(figure.leg_heading_rad) % 360.0,
            np.degrees(figure.leg_reduced_rad),
            yerr=np.degrees(figure.leg_sigma_rad),
            fmt="o",
            c="tab:orange",
            ms=5,
            capsize=3,
            label="GPS course made good - DR course",
        )
    for ax in (top, bottom):
        for start, end in figure.gaps:
            s, e = math.degrees(start) % 360.0, math.degrees(end) % 360.0
            spans = [(s, e)] if s < e else [(s, 360.0), (0.0, e)]
            for a, b in spans:
                ax.axvspan(a, b, color="tab:red", alpha=0.08, lw=0)
        ax.axhline(0.0, c="0.3", lw=0.5)
        ax.grid(True, lw=0.3)
    top.set_title(figure.title)
    top.set_ylabel("correction (deg)")
    top.legend(loc="best", fontsize="small", markerscale=2)
    if true_deviation is not None:
        h_true, delta_true = true_deviation
        order = np.argsort(np.degrees(h_true) % 360.0)
        error = np.degrees(model(h_true) - delta_true)[order]
        sigma = 2.0 * np.degrees(model.sigma(h_true))[order]
        x = (np.degrees(h_true) % 360.0)[order]
        if np.all(np.isfinite(sigma)):
            bottom.fill_between(x, -sigma, sigma, color="tab:blue", alpha=0.2, lw=0)
        bottom.plot(x, error, c="tab:blue", lw=1.2)
        bottom.set_ylabel("fit - true (deg)")
    else:
        bottom.scatter(h_deg[inlier], np.degrees(figure.residuals_rad[inlier]), s=3, c="0.55", lw=0)
        bottom.set_ylabel("residual (deg)")
    bottom.set_xlabel("compass heading (deg)")
    bottom.set_xlim(0.0, 360.0)
    bottom.set_xticks(np.arange(0, 361, 45))
    fig.tight_layout()
    atomic_write(Path(path), lambda p: fig.savefig(p, dpi=dpi, format="png"))
    plt.close(fig)
    return Path(path)
