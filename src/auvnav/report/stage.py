"""The report stage (``auvnav report DIVE``): the paper's figures and one self-contained HTML page,
drawn from a dive's products.

Products, in ``DIVE/products/report/``: ``index.html`` (opens offline: every script, style and image
inside it), ``figures/*.png`` (the paper's figures re-made from the products), ``map.json`` and
``mesh3d.json`` (the interactive map and 3D view as plotly JSON, which a campaign's page reuses) and
``summary.json`` (the dive's facts, the figures drawn and why the others were not). It reads only
products, the dive's own logs (for the fixes on the map and the dead reckoning of Fig. 8) and, for a
simulated dive, the truth it draws beside them; it scores nothing (``auvnav evaluate`` does).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from auvnav import products as P
from auvnav.compass.evaluate import TRUE_DEVIATION_FILE
from auvnav.dive import ImageIndex, dive_files, find_stream_file
from auvnav.report.content import STAGE_NAMES
from auvnav.stagekit import Stage, StageContext
from auvnav.streams import write_json

TRUTH_TRAJECTORY = Path("truth") / "trajectory.csv"


@dataclass(frozen=True)
class ReportSettings:
    """Settings of the report stage (none yet)."""


def _inputs(dive: Path, settings: ReportSettings) -> dict[str, Path]:
    files = dive_files(dive)
    index = find_stream_file(dive, ImageIndex.FILE)
    if index is not None:
        files[str(index.relative_to(dive))] = index
    root = dive / P.PRODUCTS
    if root.is_dir():
        for folder in sorted(root.iterdir()):
            if folder.name in ("report", P.CACHE) or folder.name.startswith(".") or not folder.is_dir():
                continue
            for path in sorted(folder.rglob("*")):
                if path.is_file():  # stage.json too: the stages' status and reasons are on the page
                    files[str(path.relative_to(dive))] = path
    for rel in (TRUE_DEVIATION_FILE, TRUTH_TRAJECTORY):
        if (dive / rel).is_file():
            files[str(rel)] = dive / rel
    return files


def build_dive_report(dive: Path, out: Path) -> dict[str, Any]:
    """Draw a dive's figures, map and 3D view into the report folder ``out`` and write its page;
    the summary (what was drawn, why the rest was not, the page's size and the time it took)."""
    from auvnav.report.content import dive_facts
    from auvnav.report.html import render_page, section_from, write_page
    from auvnav.report.interactive import map_figure, mesh_figure
    from auvnav.report.paper_figures import NotDrawn, draw_figures

    started = time.perf_counter()
    dive, out = Path(dive), Path(out)
    folder = P.REPORT_FIGURES.inside(out)
    folder.mkdir(parents=True, exist_ok=True)
    panels = draw_figures(dive, folder)
    facts = dive_facts(dive)
    views: dict[str, dict[str, Any]] = {}
    for key, make, product in (("map", map_figure, P.REPORT_MAP), ("mesh", mesh_figure, P.REPORT_MESH)):
        try:
            figure_json, caption = make(dive)
        except NotDrawn as why:
            views[key] = {"file": None, "caption": "", "why": str(why)}
            continue
        product.inside(out).write_text(figure_json, encoding="utf-8")
        views[key] = {"file": product.name, "caption": caption, "why": None}
    section = section_from(facts, panels, folder, out, views)
    size = write_page(render_page(f"auvnav report: {facts.name}", [section]), P.REPORT_INDEX.inside(out))
    summary = {
        "dive": facts.name,
        "page": P.REPORT_INDEX.name,
        "page_bytes": size,
        "figures": {p.file: p.title for p in panels if p.file is not None},
        "not_drawn": {p.key: p.why for p in panels if p.file is None},
        "panels": [p.as_dict() for p in panels],
        "views": views,
        "facts": facts.as_dict(),
        "seconds": time.perf_counter() - started,
    }
    write_json(summary, P.REPORT_SUMMARY.inside(out))
    return summary


def _run(ctx: StageContext, settings: ReportSettings, out: Path) -> dict[str, Any]:
    return build_dive_report(ctx.dive, out)


def format_summary(summary: dict[str, Any]) -> str:
    """The human account of the report stage."""
    lines = [f"figure {name}: {what}" for name, what in summary["figures"].items()]
    lines += [f"not drawn {name}: {why}" for name, why in summary["not_drawn"].items()]
    for key, view in (summary.get("views") or {}).items():
        if view.get("why"):
            lines.append(f"no {key} view: {view['why']}")
    if "page_bytes" in summary:
        lines.append(
            f"page {summary['page']}: {summary['page_bytes'] / 1e6:.1f} MB, self-contained "
            f"({summary['seconds']:.1f} s)"
        )
    return "\n".join(lines)


STAGE = Stage(
    name="report",
    title="the paper's figures and the HTML report from the products",
    after=STAGE_NAMES,
    settings=ReportSettings,
    inputs=_inputs,
    unavailable=lambda dive, settings: None,
    run=_run,
    describe=format_summary,
)
