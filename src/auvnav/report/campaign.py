"""The report of a campaign: several dives in one folder (as ``auvnav demo`` writes them) on one page.

A campaign folder holds one dive folder per dive (each with its ``dive.yaml``) and, when the demo
wrote it, ``summary.json`` (every dive's scores against its truth, the compass fit across dives) and
``compass-correction.yaml`` and ``.png``. The page is ``CAMPAIGN/products/report/index.html``: the
summary table of every dive, the campaign's figures (the compass correction fitted across dives with
its constant from the GPS transits, Fig. 5a/5b, and each dive's dead reckoning with that correction,
Fig. 8), then each dive's section reused from its own report stage's products (figures, map, 3D
view), so the campaign's page redraws nothing a dive's report already drew.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from auvnav import products as P
from auvnav.errors import AuvnavError
from auvnav.report.content import dive_facts
from auvnav.report.html import DiveSection, ExtraFigure, render_page, section_from, write_page
from auvnav.report.paper_figures import NotDrawn, Panel
from auvnav.streams import write_json

CAMPAIGN_SUMMARY = "summary.json"
CAMPAIGN_CORRECTION = "compass-correction.yaml"


def is_campaign(folder: Path) -> bool:
    """A folder that is not a dive and holds at least one dive folder."""
    folder = Path(folder)
    return not (folder / "dive.yaml").exists() and bool(campaign_dives(folder))


def campaign_dives(folder: Path) -> list[Path]:
    """The dive folders of a campaign: in the order of its summary when it has one, else by name."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    found = {p.name: p for p in sorted(folder.iterdir()) if p.is_dir() and (p / "dive.yaml").is_file()}
    order = list((_campaign_summary(folder).get("dives") or {}).keys())
    return [found[n] for n in order if n in found] + [p for n, p in found.items() if n not in order]


def _campaign_summary(folder: Path) -> dict[str, Any]:
    path = Path(folder) / CAMPAIGN_SUMMARY
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _dive_section(dive: Path, evaluation: dict[str, Any] | None) -> DiveSection:
    facts = dive_facts(dive, evaluation)
    summary_path = P.REPORT_SUMMARY.path(dive)
    folder = P.REPORT_FIGURES.path(dive)
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
        panels = [Panel(**p) for p in summary["panels"]]
        views = summary["views"]
    except (OSError, ValueError, KeyError, TypeError):
        why = "the dive's report stage has not run (auvnav report DIVE draws its figures)"
        return DiveSection(
            facts=facts,
            panels=[Panel("report", "The dive's figures", why=why)],
            figures=folder,
            map_why=why,
            mesh_why=why,
        )
    return section_from(facts, panels, folder, P.stage_dir(dive, "report"), views)


def _campaign_figures(
    folder: Path, dives: list[Path], summary: dict[str, Any], out: Path
) -> list[ExtraFigure]:
    from auvnav.report.paper_figures import plot_dr_corrected, plot_transit_constant

    extra = []
    correction = folder / CAMPAIGN_CORRECTION
    png = correction.with_suffix(".png")
    compass = summary.get("compass") or {}
    caption = ""
    if compass:
        constant = compass.get("constant") or {}
        caption = (
            f"fitted on {', '.join(compass.get('dives') or [])} ({compass.get('reference', '?')} headings), "
            f"residual RMS {compass.get('residual_rms_deg', float('nan')):.3f} deg; constant "
            f"{compass.get('a0_deg', float('nan')):+.3f} deg from {constant.get('source', '?')}"
        )
    extra.append(
        ExtraFigure(
            "Fig. 5a: the campaign's compass correction",
            png if png.is_file() else None,
            caption,
            why=None
            if png.is_file()
            else f"no {png.name} in the campaign folder (auvnav compass fit ... --out {correction.name})",
        )
    )
    try:
        cap = plot_transit_constant(compass, out / "campaign_fig5b_constant.png") if compass else None
        if cap is None:
            raise NotDrawn(f"no compass fit in the campaign's {CAMPAIGN_SUMMARY}")
        extra.append(
            ExtraFigure("Fig. 5b: the constant from GPS transits", out / "campaign_fig5b_constant.png", cap)
        )
    except NotDrawn as why:
        extra.append(ExtraFigure("Fig. 5b: the constant from GPS transits", None, why=str(why)))
    for dive in dives:
        if not P.SLAM_TRAJECTORY.path(dive).is_file():
            continue
        title = f"Fig. 8: {dive.name}, dead reckoning with and without the campaign's correction"
        if not correction.is_file():
            extra.append(ExtraFigure(title, None, why=f"no {correction.name} in the campaign folder"))
            continue
        target = out / f"campaign_fig8_{dive.name}.png"
        try:
            extra.append(ExtraFigure(title, target, plot_dr_corrected(dive, correction, target)))
        except (AuvnavError, OSError, ValueError) as err:
            extra.append(ExtraFigure(title, None, why=f"could not be drawn: {err}"))
    return extra


def build_campaign_report(folder: Path) -> dict[str, Any]:
    """Write ``CAMPAIGN/products/report/index.html`` (module docstring); the summary.

    Raises
    ------
    AuvnavError
        The folder holds no dive.
    """
    started = time.perf_counter()
    folder = Path(folder)
    dives = campaign_dives(folder)
    if not dives:
        raise AuvnavError(f"{folder}: no dive folders (folders with a dive.yaml) in it: not a campaign")
    summary = _campaign_summary(folder)
    evaluations = {name: (d or {}).get("evaluation") for name, d in (summary.get("dives") or {}).items()}
    out = P.stage_dir(folder, "report")
    figures = P.REPORT_FIGURES.path(folder)
    figures.mkdir(parents=True, exist_ok=True)
    sections = [_dive_section(d, evaluations.get(d.name)) for d in dives]
    extra = _campaign_figures(folder, dives, summary, figures)
    intro = (
        "Scores against the truth come from the campaign's summary.json (auvnav evaluate on each simulated dive)."
        if any(evaluations.values())
        else ""
    )
    page = render_page(f"auvnav campaign report: {folder.resolve().name}", sections, extra=extra, intro=intro)
    size = write_page(page, P.REPORT_INDEX.path(folder))
    result = {
        "campaign": str(folder),
        "page": str(P.REPORT_INDEX.path(folder)),
        "page_bytes": size,
        "dives": [d.name for d in dives],
        "not_drawn": {
            **{f"{s.facts.name}/{p.key}": p.why for s in sections for p in s.panels if p.file is None},
            **{x.title: x.why for x in extra if x.file is None},
        },
        "seconds": time.perf_counter() - started,
    }
    write_json(result, out / "summary.json")
    return result


def format_campaign(result: dict[str, Any]) -> str:
    """The human account of :func:`build_campaign_report`."""
    lines = [
        f"campaign report of {len(result['dives'])} dives ({', '.join(result['dives'])}): {result['page']}",
        f"  {result['page_bytes'] / 1e6:.1f} MB, self-contained, written in {result['seconds']:.1f} s",
    ]
    lines += [f"  not drawn {k}: {v}" for k, v in result["not_drawn"].items()]
    return "\n".join(lines)
