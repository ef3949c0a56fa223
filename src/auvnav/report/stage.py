"""The report stage (``auvnav report``): the paper's figures drawn from a dive's products.

Products, in ``DIVE/products/report/``: ``figures/*.png`` and ``summary.json`` (which figures were
drawn, and why the others were not). It reads only products (and, for a simulated dive, the truth it
draws beside them) and computes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from auvnav import products as P
from auvnav.compass.evaluate import TRUE_DEVIATION_FILE, read_true_deviation
from auvnav.stagekit import Stage, StageContext
from auvnav.streams import write_json

FIGURES = {
    "fig5_compass.png": "compass correction against compass heading (Fig. 5)",
    "fig6_depth.png": "depth residuals of loop closures against time, with the tide (Fig. 6)",
}


@dataclass(frozen=True)
class ReportSettings:
    """Settings of the report stage (none yet)."""


def _inputs(dive: Path, settings: ReportSettings) -> dict[str, Path]:
    files = {"dive.yaml": dive / "dive.yaml"}
    root = dive / P.PRODUCTS
    if root.is_dir():
        for folder in sorted(root.iterdir()):
            if folder.name in ("report", P.CACHE) or folder.name.startswith(".") or not folder.is_dir():
                continue
            for path in sorted(folder.rglob("*")):
                if path.is_file() and path.name != P.STAGE_FILE:
                    files[str(path.relative_to(dive))] = path
    if (dive / TRUE_DEVIATION_FILE).is_file():
        files[str(TRUE_DEVIATION_FILE)] = dive / TRUE_DEVIATION_FILE
    return files


def _run(ctx: StageContext, settings: ReportSettings, out: Path) -> dict[str, Any]:
    from auvnav.report.compass_figures import CorrectionFigure, plot_correction
    from auvnav.report.depth_figures import DepthFigure, plot_depth

    dive = ctx.dive
    folder = P.REPORT_FIGURES.inside(out)
    folder.mkdir()
    drawn: dict[str, str] = {}
    missing: dict[str, str] = {}
    if P.COMPASS_CORRECTION.path(dive).is_file():
        truth = read_true_deviation(dive) if (dive / TRUE_DEVIATION_FILE).is_file() else None
        plot_correction(
            CorrectionFigure.from_products(dive), folder / "fig5_compass.png", true_deviation=truth
        )
        drawn["fig5_compass.png"] = FIGURES["fig5_compass.png"]
    else:
        missing["fig5_compass.png"] = (
            "no compass correction (products/compass: the compass stage did not run)"
        )
    if P.DEPTH_SUMMARY.path(dive).is_file():
        plot_depth(DepthFigure.from_products(dive), folder / "fig6_depth.png")
        drawn["fig6_depth.png"] = FIGURES["fig6_depth.png"]
    else:
        missing["fig6_depth.png"] = "no depth check (products/depth: the depth stage did not run)"
    summary = {"figures": drawn, "not_drawn": missing}
    write_json(summary, out / "summary.json")
    return summary


def format_summary(summary: dict[str, Any]) -> str:
    """The human account of the report stage."""
    lines = [f"figure {name}: {what}" for name, what in summary["figures"].items()]
    lines += [f"not drawn {name}: {why}" for name, why in summary["not_drawn"].items()]
    return "\n".join(lines)


STAGE = Stage(
    name="report",
    title="the paper's figures from the products",
    after=("nav", "vision", "slam", "compass", "depth"),
    settings=ReportSettings,
    inputs=_inputs,
    unavailable=lambda dive, settings: None,
    run=_run,
    describe=format_summary,
)
