"""The report as one self-contained HTML page (DESIGN section 6: ``report/index.html``, no network).

Everything the page needs is inside it: the style, plotly.js (from the plotly wheel, inlined once per
page: no CDN), the figures as base64 PNGs, the interactive figures as JSON. A Content-Security-Policy
forbids the browser any request that is not inline data, so a page that tried to fetch anything would
fail visibly (the browser test counts such failures) rather than silently work online only.
"""

from __future__ import annotations

import base64
import datetime
import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from auvnav import __version__
from auvnav.report.content import STAGE_TITLES, DiveFacts
from auvnav.report.paper_figures import Panel

CSP = (
    "default-src 'none'; img-src data: blob:; style-src 'unsafe-inline'; "
    "script-src 'unsafe-inline' 'unsafe-eval'; font-src data:; worker-src blob:"
)

STYLE = """
body { font-family: -apple-system, "Segoe UI", "DejaVu Sans", Helvetica, Arial, sans-serif; margin: 0;
       color: #222; background: #fafafa; line-height: 1.4; }
header { background: #0b3d5c; color: #fff; padding: 14px 28px; }
header h1 { margin: 0 0 4px 0; font-size: 22px; }
header p { margin: 0; font-size: 13px; opacity: 0.85; }
nav.toc { padding: 8px 28px; background: #e8eef2; font-size: 14px; }
nav.toc a { margin-right: 14px; color: #0b3d5c; }
main { padding: 10px 28px 40px 28px; max-width: 1500px; }
h2 { border-bottom: 2px solid #0b3d5c; padding-bottom: 4px; margin-top: 30px; }
h3 { margin: 18px 0 6px 0; }
table { border-collapse: collapse; font-size: 13px; background: #fff; margin: 6px 0 12px 0; }
th, td { border: 1px solid #ccd; padding: 4px 8px; text-align: left; vertical-align: top; }
th { background: #e8eef2; }
td.num { text-align: right; white-space: nowrap; }
.status-ran { color: #1b7f2a; } .status-skipped, .status-not { color: #a05a00; } .status-failed { color: #b00020; }
.grid { display: grid; grid-template-columns: repeat(auto-fill, minmax(560px, 1fr)); gap: 14px; }
figure { margin: 0; background: #fff; border: 1px solid #dde; padding: 8px; }
figure img { width: 100%; height: auto; display: block; }
figcaption { font-size: 13px; color: #444; margin-top: 4px; }
figcaption b { color: #222; }
.why { background: #fff8e6; border: 1px solid #f0d9a0; padding: 10px; font-size: 13px; }
.why b { display: block; margin-bottom: 4px; }
.plot { background: #fff; border: 1px solid #dde; }
p.note { font-size: 13px; color: #555; }
ul.absent { background: #fff8e6; border: 1px solid #f0d9a0; padding: 8px 8px 8px 28px; font-size: 13px; }
ul.absent li { margin: 2px 0; }
.grid > .why { align-self: start; }
"""


@dataclass(frozen=True)
class DiveSection:
    """A dive's part of the page: its facts, figures and interactive views.

    Parameters
    ----------
    facts : DiveFacts
    panels : list of Panel
    figures : Path
        The folder of the panels' PNGs.
    map_json, mesh_json : str or None
        Plotly figures (JSON), or None with the reason in ``map_why`` / ``mesh_why``.
    """

    facts: DiveFacts
    panels: list[Panel]
    figures: Path
    map_json: str | None = None
    map_caption: str = ""
    map_why: str | None = None
    mesh_json: str | None = None
    mesh_caption: str = ""
    mesh_why: str | None = None


@dataclass(frozen=True)
class ExtraFigure:
    """A figure of the whole campaign (e.g. the cross-dive compass fit): a PNG file or why absent."""

    title: str
    file: Path | None
    caption: str = ""
    why: str | None = None


@dataclass
class _Plots:
    """The interactive figures of a page, in order."""

    items: list[tuple[str, str]] = field(default_factory=list)

    def add(self, figure_json: str) -> str:
        div = f"plot{len(self.items)}"
        self.items.append((div, figure_json))
        return div


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _img(path: Path) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{_e(Path(path).stem)}" src="data:image/png;base64,{data}">'


def _why(title: str, why: str) -> str:
    return f'<div class="why" data-absent="1"><b>{_e(title)}</b>not drawn: {_e(why)}</div>'


def _duration(seconds: float | None) -> str:
    if seconds is None:
        return "-"
    h, m = divmod(round(seconds / 60.0), 60)
    return f"{h} h {m:02d} min" if h else f"{m} min"


def section_from(
    facts: DiveFacts, panels: list[Panel], folder: Path, out: Path, views: dict[str, dict[str, Any]]
) -> DiveSection:
    """A dive's section from what its report stage drew into ``out`` (``views``: the map's and the 3D
    view's JSON file, caption and why absent)."""

    def view(key: str) -> tuple[str | None, str, str | None]:
        v = views.get(key) or {"file": None, "caption": "", "why": "not drawn"}
        path = out / v["file"] if v.get("file") else None
        text = path.read_text(encoding="utf-8") if path is not None and path.is_file() else None
        return text, v.get("caption", ""), v.get("why") if text is None else None

    map_json, map_caption, map_why = view("map")
    mesh_json, mesh_caption, mesh_why = view("mesh")
    return DiveSection(
        facts=facts,
        panels=panels,
        figures=folder,
        map_json=map_json,
        map_caption=map_caption,
        map_why=map_why,
        mesh_json=mesh_json,
        mesh_caption=mesh_caption,
        mesh_why=mesh_why,
    )


def summary_table(sections: list[DiveSection]) -> str:
    """One row per dive: distance, duration, sensors, stages run."""
    rows = []
    for s in sections:
        f = s.facts
        ran = [k for k, (status, _) in f.stages.items() if status == "ran"]
        rows.append(
            "<tr>"
            f'<td><a href="#dive-{_e(f.name)}">{_e(f.name)}</a>{" (simulated)" if f.simulated else ""}</td>'
            f"<td>{_e(f.start)}</td>"
            f'<td class="num" title="{_e(f.distance_source)}">'
            f"{'-' if f.distance_m is None else f'{f.distance_m:,.0f} m'}"
            f"{' (truth)' if f.distance_source == 'truth' else ' (DR)'}</td>"
            f'<td class="num">{_duration(f.duration_s)}</td>'
            f"<td>{_e(', '.join(f.sensors))}</td>"
            f"<td>{_e(', '.join(ran) or 'none')}</td>"
            "</tr>"
        )
    return (
        '<table id="summary-table"><tr><th>dive</th><th>start</th><th>distance</th><th>duration</th>'
        "<th>sensors</th><th>stages run</th></tr>" + "".join(rows) + "</table>"
    )


def _figures_table(facts: DiveFacts) -> str:
    if not facts.figures:
        return '<p class="note">No headline figures: no stage wrote a summary.</p>'
    truth = any(f.truth for f in facts.figures)
    head = (
        "<tr><th>figure</th><th>from the products</th>"
        + ("<th>against the truth</th>" if truth else "")
        + "</tr>"
    )
    rows = "".join(
        f"<tr><td>{_e(f.label)}</td><td>{_e(f.value)}</td>"
        + (f"<td>{_e(f.truth or '-')}</td>" if truth else "")
        + "</tr>"
        for f in facts.figures
    )
    note = ""
    if facts.simulated and not truth:
        note = (
            '<p class="note">A simulated dive: <code>auvnav evaluate DIVE</code> scores these products against '
            "its truth (the campaign report shows those scores).</p>"
        )
    return f"<table>{head}{rows}</table>{note}"


def _stages_table(facts: DiveFacts) -> str:
    rows = []
    for name, (status, reason) in facts.stages.items():
        css = "status-" + status.split()[0]
        rows.append(
            f"<tr><td>{_e(STAGE_TITLES.get(name, name))} (<code>{_e(name)}</code>)</td>"
            f'<td class="{css}">{_e(status)}</td><td>{_e(reason)}</td></tr>'
        )
    return "<table><tr><th>stage</th><th>status</th><th>why</th></tr>" + "".join(rows) + "</table>"


def _panel(panel: Panel, folder: Path) -> str:
    if panel.file is None or not (folder / panel.file).is_file():
        return _why(panel.title, panel.why or "no figure file")
    return (
        f'<figure data-figure="{_e(panel.key)}">{_img(folder / panel.file)}'
        f"<figcaption><b>{_e(panel.title)}.</b> {_e(panel.caption)}</figcaption></figure>"
    )


def _dive_html(section: DiveSection, plots: _Plots) -> str:
    f = section.facts
    parts = [f'<section id="dive-{_e(f.name)}"><h2>{_e(f.name)}</h2>']
    parts.append("<h3>Headline figures</h3>" + _figures_table(f))
    parts.append("<h3>Stages</h3>" + _stages_table(f))
    parts.append("<h3>Map</h3>")
    if section.map_json is not None:
        div = plots.add(section.map_json)
        parts.append(
            f'<div class="plot" id="{div}" data-map="1"></div><p class="note">{_e(section.map_caption)}. '
            "Drag to pan, scroll or box-select to zoom, click a legend entry to hide or show it, "
            "double-click to reset.</p>"
        )
    else:
        parts.append(_why("Map", section.map_why or "no tracks"))
    drawn = [p for p in section.panels if p.file is not None and (section.figures / p.file).is_file()]
    absent = [p for p in section.panels if p not in drawn]
    parts.append("<h3>The paper's figures</h3>")
    if drawn:
        parts.append('<div class="grid">' + "".join(_panel(p, section.figures) for p in drawn) + "</div>")
    if absent:
        parts.append(
            '<ul class="absent">'
            + "".join(
                f'<li data-absent="1"><b>{_e(p.title)}</b>: not drawn: {_e(p.why or "no figure file")}</li>'
                for p in absent
            )
            + "</ul>"
        )
    parts.append("<h3>3D view of the reconstruction</h3>")
    if section.mesh_json is not None:
        div = plots.add(section.mesh_json)
        parts.append(
            f'<div class="plot" id="{div}" data-mesh="1"></div><p class="note">{_e(section.mesh_caption)}</p>'
        )
    else:
        parts.append(_why("3D view", section.mesh_why or "no mesh"))
    parts.append("</section>")
    return "\n".join(parts)


def render_page(
    title: str,
    sections: list[DiveSection],
    *,
    extra: list[ExtraFigure] | None = None,
    intro: str = "",
) -> str:
    """The whole page (module docstring): summary table, campaign figures, then each dive."""
    plots = _Plots()
    body = [f'<h2 id="summary">Summary</h2>{summary_table(sections)}']
    if intro:
        body.append(f'<p class="note">{_e(intro)}</p>')
    if extra:
        body.append('<h2 id="campaign">The campaign</h2><div class="grid">')
        for x in extra:
            if x.file is not None and x.file.is_file():
                body.append(
                    f'<figure data-figure="{_e(x.file.stem)}">{_img(x.file)}'
                    f"<figcaption><b>{_e(x.title)}.</b> {_e(x.caption)}</figcaption></figure>"
                )
            else:
                body.append(_why(x.title, x.why or "no figure"))
        body.append("</div>")
    body += [_dive_html(s, plots) for s in sections]
    toc = "".join(f'<a href="#dive-{_e(s.facts.name)}">{_e(s.facts.name)}</a>' for s in sections)
    scripts = ""
    if plots.items:
        import plotly.offline

        data = "".join(
            f'<script type="application/json" id="{div}-json">{_script_safe(j)}</script>'
            for div, j in plots.items
        )
        boot = (
            "<script>(function(){var cfg={responsive:true,scrollZoom:true,displaylogo:false,"
            "modeBarButtonsToRemove:['sendDataToCloud']};"
            'document.querySelectorAll(\'script[type="application/json"][id$="-json"]\').forEach(function(s){'
            "var fig=JSON.parse(s.textContent);var div=document.getElementById(s.id.slice(0,-5));"
            "Plotly.newPlot(div,fig.data,fig.layout,cfg).then(function(){div.setAttribute('data-rendered','1');});"
            "});})();</script>"
        )
        scripts = f"<script>{plotly.offline.get_plotlyjs()}</script>{data}{boot}"
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta http-equiv="Content-Security-Policy" content="{CSP}">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{STYLE}</style></head><body>"
        f"<header><h1>{_e(title)}</h1><p>auvnav {_e(__version__)}, {now}; drawn from the products only; "
        "this file needs no network.</p></header>"
        f'<nav class="toc"><a href="#summary">summary</a>{toc}</nav><main>'
        + "\n".join(body)
        + f"</main>{scripts}</body></html>\n"
    )


def write_page(text: str, path: Path) -> int:
    """Write the page atomically; its size in bytes."""
    from auvnav.streams import atomic_write

    data = text.encode("utf-8")
    atomic_write(Path(path), lambda p: p.write_bytes(data))
    return len(data)


def _script_safe(text: str) -> str:
    """JSON inside a ``<script>`` element: no ``</`` that would end it."""
    return text.replace("</", "<\\/")
