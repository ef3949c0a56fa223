"""Depth validation figure: the analogue of the paper's Fig. 6 (matplotlib lives in ``report/`` only),
drawn from the depth stage's products.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from auvnav import products as P
from auvnav.depth.validation import LoopDepth, rms
from auvnav.dive import read_dive_info
from auvnav.streams import atomic_write, read_stream


@dataclass(frozen=True)
class DepthFigure:
    """What the Fig. 6 plot shows: the depth stage's per-loop table and what its summary says."""

    dive: str
    start_time_s: float
    loops: LoopDepth
    tide_source: str | None
    relief_step_m: float

    @classmethod
    def from_products(cls, dive: Path) -> DepthFigure:
        summary = json.loads(P.DEPTH_SUMMARY.path(dive).read_text(encoding="utf-8"))
        tide = summary["tide"]
        return cls(
            dive=summary["dive"],
            start_time_s=read_dive_info(dive).start_time_s,
            loops=read_stream(LoopDepth, P.DEPTH_LOOPS.path(dive)),
            tide_source=None if tide is None else tide["source"],
            relief_step_m=summary["relief_step_m"],
        )


def plot_depth(result: DepthFigure, path: Path, *, dpi: int = 120) -> Path:
    """Loop-closure vertical residuals against the time of the second image, with the tide change.

    Top: the pressure-depth change minus the visual vertical change of each loop closure (the paper's
    red points), coloured by the time between the two images, and the tide change over the same
    interval (black: the tide applied; grey crosses: the tide estimated from the loops when a tide
    file was also given). Bottom, when a tide was applied: the residual after the correction, with the
    false-relief threshold and the flagged loops ringed.

    Parameters
    ----------
    result : DepthFigure
    path : Path
        PNG file to write.
    dpi : int

    Returns
    -------
    Path
    """
    loops = result.loops
    hours = (loops.t_j_s - result.start_time_s) / 3600.0
    minutes_apart = loops.dt_s / 60.0
    corrected = loops.residual_after_m is not None
    fig, axes = plt.subplots(
        2 if corrected else 1, 1, figsize=(9, 7 if corrected else 4), sharex=True, squeeze=False
    )
    top = axes[0, 0]
    colour = {
        "c": minutes_apart,
        "cmap": "viridis",
        "vmin": 0.0,
        "vmax": max(float(minutes_apart.max()), 1.0),
    }
    points = top.scatter(hours, loops.residual_before_m, s=8, label="pressure minus visual dz", **colour)
    if loops.tide_change_m is not None:
        label = "tide change (estimated)" if result.tide_source == "estimated" else "tide change (predicted)"
        top.scatter(hours, loops.tide_change_m, s=4, c="k", label=label)
    if loops.estimated_change_m is not None and result.tide_source != "estimated":
        top.scatter(
            hours,
            loops.estimated_change_m,
            s=10,
            c="0.5",
            marker="x",
            lw=0.6,
            label="tide change (estimated)",
        )
    top.axhline(0.0, color="0.3", lw=0.5)
    top.set_ylabel("depth change (m)")
    top.set_title(
        f"{result.dive + ': ' if result.dive else ''}{len(loops)} loop closures, residual RMS "
        f"{rms(loops.residual_before_m):.3f} m before correction"
    )
    top.legend(loc="best", fontsize="small")
    fig.colorbar(points, ax=axes[:, 0].tolist(), label="time between images (min)")
    bottom = top
    if loops.residual_after_m is not None:
        bottom = axes[1, 0]
        bottom.scatter(hours, loops.residual_after_m, s=8, **colour)
        flagged = loops.false_relief
        if np.any(flagged):
            bottom.scatter(
                hours[flagged],
                loops.residual_after_m[flagged],
                s=40,
                facecolors="none",
                edgecolors="r",
                label=f"false relief ({np.count_nonzero(flagged)})",
            )
            bottom.legend(loc="best", fontsize="small")
        for sign in (-1.0, 1.0):
            bottom.axhline(sign * result.relief_step_m, color="r", lw=0.5, ls="--")
        bottom.axhline(0.0, color="0.3", lw=0.5)
        bottom.set_ylabel("after tide correction (m)")
        source = (
            result.tide_source if result.tide_source == "estimated" else Path(str(result.tide_source)).name
        )
        bottom.set_title(f"residual RMS {rms(loops.residual_after_m):.3f} m after correction ({source})")
    bottom.set_xlabel("time of the second image since the dive's start (h)")
    for ax in axes[:, 0]:
        ax.grid(True, lw=0.3)
    atomic_write(Path(path), lambda p: fig.savefig(p, dpi=dpi, format="png"))
    plt.close(fig)
    return Path(path)
