"""Compass correction figure, the analogue of the paper's Fig. 5 (matplotlib lives in ``report/`` only).

:func:`run_compass_fit` fits the correction, writes the correction file and draws the figure beside
it: the one call of ``auvnav compass fit`` and of ``auvnav demo``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from auvnav.compass.correction import write_correction
from auvnav.compass.deviation import transit_deviation
from auvnav.compass.evaluate import TRUE_DEVIATION_FILE, read_true_deviation
from auvnav.compass.fit import (
    CORRECTION_FILE,
    MAX_TURN_RATE_DEG_S,
    PRODUCTS_DIR,
    CompassFit,
    fit_compass,
)
from auvnav.errors import OutputExistsError
from auvnav.frames import FloatArray
from auvnav.streams import atomic_write

_GRID_DEG = np.arange(0.0, 360.25, 0.25)


def plot_correction(
    result: CompassFit,
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
    result : CompassFit
    path : Path
        PNG file to write.
    true_deviation : (compass_heading_rad, deviation_rad), optional
        The simulator's true ``delta(h)``.
    dpi : int

    Returns
    -------
    Path
    """
    fit = result.fit
    model = fit.model
    grid = np.radians(_GRID_DEG)
    curve = np.degrees(model(grid))
    band = 2.0 * np.degrees(model.sigma(grid))
    h_deg = np.degrees(fit.compass_heading_rad) % 360.0
    points = np.degrees(model(fit.compass_heading_rad) + fit.residuals_rad)

    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(9, 7), sharex=True, gridspec_kw={"height_ratios": [3, 1.4]}
    )
    top.scatter(h_deg[fit.inlier], points[fit.inlier], s=3, c="0.55", lw=0, label="reference - compass")
    outlier = np.isfinite(points) & ~fit.inlier
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
    used = result.used_legs
    if used:
        leg_h = np.array([u.heading_rad for u in used])
        measured = transit_deviation(
            model, [u.compass_heading_rad for u in used], [u.step_weight for u in used]
        )
        reduced = np.array([u.leg.course_error_rad for u in used]) - measured + model(leg_h)
        top.errorbar(
            np.degrees(leg_h) % 360.0,
            np.degrees(reduced),
            yerr=np.degrees([u.leg.course_sigma_rad for u in used]),
            fmt="o",
            c="tab:orange",
            ms=5,
            capsize=3,
            label="GPS course made good - DR course",
        )
    for ax in (top, bottom):
        for start, end in fit.gaps:
            s, e = math.degrees(start) % 360.0, math.degrees(end) % 360.0
            spans = [(s, e)] if s < e else [(s, 360.0), (0.0, e)]
            for a, b in spans:
                ax.axvspan(a, b, color="tab:red", alpha=0.08, lw=0)
        ax.axhline(0.0, c="0.3", lw=0.5)
        ax.grid(True, lw=0.3)
    source = {
        "truth": "constant from the truth",
        "gps-transits": f"constant from {len(used)} GPS legs",
        "arbitrary": "constant arbitrary",
        "graph": "constant from the pose graph",
    }[model.constant_source]
    top.set_title(
        f"compass correction: {len(result.pairs)} pairs from {', '.join(result.pairs.dives)} "
        f"(reference {result.reference}); {source}"
    )
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
        bottom.scatter(h_deg[fit.inlier], np.degrees(fit.residuals_rad[fit.inlier]), s=3, c="0.55", lw=0)
        bottom.set_ylabel("residual (deg)")
    bottom.set_xlabel("compass heading (deg)")
    bottom.set_xlim(0.0, 360.0)
    bottom.set_xticks(np.arange(0, 361, 45))
    fig.tight_layout()
    atomic_write(Path(path), lambda p: fig.savefig(p, dpi=dpi, format="png"))
    plt.close(fig)
    return Path(path)


def run_compass_fit(
    dives: Sequence[Path],
    *,
    reference: str = "slam",
    transits: Sequence[Path] = (),
    harmonics: int = 3,
    out: Path | None = None,
    overwrite: bool = False,
    max_turn_rate_deg_s: float | None = None,
) -> dict[str, Any]:
    """Fit the compass correction, write it and its figure; the summary (``auvnav compass fit``).

    Parameters
    ----------
    dives : sequence of Path
        Dive folders whose heading pairs are pooled.
    reference : str
        ``"slam"``, ``"truth"`` or a trajectory file (:func:`auvnav.compass.fit.fit_compass`).
    transits : sequence of Path
        Dive folders whose GPS course made good fixes the constant (may repeat a dive of ``dives``).
    harmonics : int
        N of eq. 5.
    out : Path, optional
        The correction file; default ``DIVE/products/compass/correction.yaml`` of the first dive.
        The figure is written beside it with the suffix ``.png``.
    overwrite : bool
        Replace existing files (checked before any work).
    max_turn_rate_deg_s : float, optional
        Heading pairs are kept while the reference turns slower than this, deg/s; default
        :data:`auvnav.compass.fit.MAX_TURN_RATE_DEG_S`.

    Returns
    -------
    dict
        :meth:`CompassFit.summary` plus ``correction`` and ``figure`` (the files written).

    Raises
    ------
    OutputExistsError
        ``out`` exists and ``overwrite`` is False.
    """
    out = Path(out) if out is not None else Path(dives[0]) / PRODUCTS_DIR / CORRECTION_FILE
    figure = out.with_suffix(".png")
    if out.exists() and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    result = fit_compass(
        dives,
        reference=reference,
        transits=transits,
        harmonics=harmonics,
        max_turn_rate_rad_s=math.radians(
            MAX_TURN_RATE_DEG_S if max_turn_rate_deg_s is None else max_turn_rate_deg_s
        ),
    )
    write_correction(result.fit, out, overwrite=overwrite, record=result.record())
    truth = read_true_deviation(dives[0]) if (Path(dives[0]) / TRUE_DEVIATION_FILE).is_file() else None
    plot_correction(result, figure, true_deviation=truth)
    return {"correction": str(out), "figure": str(figure), **result.summary()}
