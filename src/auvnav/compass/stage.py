"""The compass stage: the correction (eq. 5-6) fitted to a dive's own headings (paper section III-B).

The compass heading is paired with the SLAM heading (or another reference, :mod:`auvnav.compass.fit`)
and fitted; the constant is fixed from GPS course made good on the transit dives given, else on the
dive's own sub-sea legs between GPS fixes when it has two usable ones (the paper's future work:
shape and constant from one dive), else it stays arbitrary and the correction says so.

Products (DESIGN section 6), in ``DIVE/products/compass/``:

- ``correction.yaml``: the correction file (``auvnav-compass-correction/1``, with its 360-row table
  for the vehicle's firmware);
- ``pairs.csv``: every heading pair fitted (``t, dive, compass_heading_deg, reference_heading_deg,
  residual_deg, inlier``; the residual is against the shape fit);
- ``summary.json``: :meth:`~auvnav.compass.fit.CompassFit.summary`, the transit legs included.

Fitting several dives together into a correction file of its own is ``auvnav compass fit DIVE...
--out FILE`` (:func:`fit_to_file`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from auvnav import products as P
from auvnav.compass.reference import REFERENCE_FILES, reference_file
from auvnav.dive import dive_files
from auvnav.errors import InsufficientDataError, OutputExistsError
from auvnav.stagekit import Stage, StageContext, StageSkipped, setting
from auvnav.streams import write_json, write_table

if TYPE_CHECKING:  # the models load when the stage runs, not when the pipeline checks its key
    from auvnav.compass.fit import CompassFit


#: The stage gives a correction only where the dive's headings determine it: a 1-sigma band wider than
#: this anywhere on the compass rose (a sector without headings) is not a correction to fly with,
#: degrees (the raw compass's error is of this order, paper section I).
MAX_BAND_DEG = 1.0


@dataclass(frozen=True)
class CompassSettings:
    """Settings of the compass stage."""

    reference: str = setting(
        "slam", "slam (products/slam/trajectory.csv), truth (a simulated dive's) or a trajectory file."
    )
    transits: tuple[Path, ...] = setting(
        (), "A dive whose GPS course made good fixes the constant; repeat for more [the dive's own legs]."
    )
    harmonics: int = setting(3, "Harmonics of eq. 5.", minimum=0)
    max_turn_rate_deg_s: float | None = setting(
        None, "Pairs only while turning slower than this [2], deg/s.", minimum=0.0
    )


def fit(
    dives: Sequence[Path], settings: CompassSettings, *, own_legs: bool = False, allow_outside: bool = False
) -> CompassFit:
    """The correction of ``dives`` with ``settings`` (:func:`auvnav.compass.fit.fit_compass`); with
    ``own_legs`` and no transits given, the first dive's own legs fix the constant when they can."""
    from auvnav.compass.fit import fit_compass

    transits = list(settings.transits) or ([Path(dives[0])] if own_legs else [])
    turn = settings.max_turn_rate_deg_s
    return fit_compass(
        dives,
        reference=settings.reference,
        transits=transits,
        harmonics=settings.harmonics,
        transits_optional=own_legs and not settings.transits,
        allow_outside=allow_outside,
        **({} if turn is None else {"max_turn_rate_rad_s": math.radians(turn)}),
    )


def pairs_frame(result: CompassFit) -> pd.DataFrame:
    """The heading pairs and their residuals as a table in file units (``pairs.csv``)."""
    pairs, f = result.pairs, result.fit
    return pd.DataFrame(
        {
            "t": pairs.t_s,
            "dive": np.asarray(pairs.dives)[pairs.dive_index],
            "compass_heading_deg": np.degrees(pairs.compass_heading_rad),
            "reference_heading_deg": np.degrees(pairs.reference_heading_rad),
            "residual_deg": np.degrees(f.residuals_rad),
            "inlier": f.inlier.astype(int),
        }
    )


def write_products(result: CompassFit, out: Path) -> None:
    """Write the stage's products into ``out`` (a stage folder being written)."""
    from auvnav.compass.correction import write_correction

    write_correction(result.fit, P.COMPASS_CORRECTION.inside(out), record=result.record())
    write_table(pairs_frame(result), P.COMPASS_PAIRS.inside(out))
    write_json(result.summary(), P.COMPASS_SUMMARY.inside(out))


def fit_to_file(
    dives: Sequence[Path], settings: CompassSettings, out: Path, *, overwrite: bool = False
) -> CompassFit:
    """``auvnav compass fit DIVE... --out FILE``: the pooled fit written to a correction file.

    Raises
    ------
    OutputExistsError
        ``out`` exists and ``overwrite`` is False (checked before any work).
    """
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    from auvnav.compass.correction import write_correction

    result = fit(dives, settings)
    write_correction(result.fit, out, overwrite=True, record=result.record())
    return result


def _unavailable(dive: Path, settings: CompassSettings) -> str | None:
    # A trajectory file the user named that is not there is an error (the run says so), not a skip.
    if settings.reference in REFERENCE_FILES and not reference_file(dive, settings.reference).is_file():
        return f"no reference headings ({settings.reference}: {reference_file(dive, settings.reference)} not found)"
    return None


def _inputs(dive: Path, settings: CompassSettings) -> dict[str, Path]:
    files = dive_files(dive)
    files["reference"] = reference_file(dive, settings.reference)
    for n, transit in enumerate(settings.transits):
        files.update({f"transits[{n}]/{rel}": path for rel, path in dive_files(Path(transit)).items()})
    return files


def _run(ctx: StageContext, settings: CompassSettings, out: Path) -> dict[str, Any]:
    try:
        result = fit([ctx.dive], settings, own_legs=True, allow_outside=ctx.allow_outside)
    except InsufficientDataError as err:
        raise StageSkipped(f"the dive's headings cannot give a correction: {err}") from err
    band_deg = np.degrees(result.fit.model.sigma(np.radians(np.arange(360.0))))
    if not np.all(band_deg <= MAX_BAND_DEG):
        worst = int(np.nanargmax(band_deg)) if np.isfinite(band_deg).any() else 0
        raise StageSkipped(
            f"the dive's compass headings do not cover the compass rose: the correction would be "
            f"uncertain to {np.nanmax(band_deg):.1f} deg (1 sigma) at {worst} deg (a navigation check dive "
            "covers it)"
        )
    write_products(result, out)
    return result.summary()


def format_summary(summary: dict[str, Any]) -> str:
    """A short human-readable account of :meth:`~auvnav.compass.fit.CompassFit.summary`."""
    p = summary["pairs"]
    c = summary["constant"]
    lines = []
    if "correction" in summary:
        lines.append(f"{summary['correction']}: compass correction ({summary['figure']})")
    lines += [
        f"reference {summary['reference']}: {p['used']} heading pairs of {p['candidates']} samples "
        f"from {', '.join(summary['dives'])} ({p['surface']} at the surface, {p['turning']} turning, "
        f"{p['outside_reference']} outside the reference)",
        f"{summary['harmonics']} harmonics (cross-validation prefers {summary['cv_harmonics']}), "
        f"residual RMS {summary['residual_rms_deg']:.3f} deg, {summary['n_outliers']} outliers",
        "a0 {:.3f} deg; a {} deg; b {} deg".format(
            summary["a0_deg"],
            ", ".join(f"{v:.3f}" for v in summary["a_deg"]),
            ", ".join(f"{v:.3f}" for v in summary["b_deg"]),
        ),
    ]
    sigma = "" if c["sigma_deg"] is None else f" +- {c['sigma_deg']:.3f} deg"
    if c["source"] == "gps-transits":
        lines.append(
            f"constant from GPS course made good: {c['legs']} legs of {', '.join(c['dives'])}{sigma} "
            f"(with {c['dvl_yaw_sigma_deg']:.2f} deg for the DVL's yaw mounting), "
            f"leg residual RMS {c['transit_rms_deg']:.3f} deg"
        )
    elif c["source"] == "truth":
        lines.append(f"constant from the truth (simulation){sigma}")
    else:
        lines.append("constant arbitrary: the reference does not fix it (give --transits)")
    for leg in summary["legs"]:
        state = "used" if leg["used"] else f"not used: {leg['reason']}"
        lines.append(
            f"  leg {leg['dive']} {leg['length_m']:7.1f} m at {leg['heading_deg']:5.1f} deg: CMG - DR "
            f"{leg['course_error_deg']:+.3f} +- {leg['course_sigma_deg']:.3f} deg ({state})"
        )
    for (start, end), sig in zip(summary["gaps_deg"], summary["gap_sigma_deg"], strict=True):
        lines.append(
            f"  no compass headings from {start:.0f} to {end:.0f} deg ({(end - start) % 360:.0f} deg wide): "
            f"the 1-sigma band reaches {sig:.2f} deg there"
        )
    return "\n".join(lines)


STAGE = Stage(
    name="compass",
    title="compass correction (eq. 5-6) from the SLAM headings, constant from GPS legs",
    after=("slam",),
    settings=CompassSettings,
    inputs=_inputs,
    unavailable=_unavailable,
    run=_run,
    describe=format_summary,
)
