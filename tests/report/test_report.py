"""The HTML report: a dive's page and a campaign's, self-contained, with a line for every figure that
could not be drawn; opened in a real browser (headless Chromium) where one is installed.

One small simulated check dive (8 headings of 6 m, the simulator's loop closures, no images) is
processed (navigation, SLAM, compass, depth); a reconstruction's products are written beside them
(a small mesh, DEM, orthophoto and false-relief table: the recon stage itself is tested in
tests/recon), and a copy of the dive with its navigation products only stands for a dive where
nothing else ran. Both are the dives of a campaign folder.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from auvnav import products as P
from auvnav.cli import main
from auvnav.dive import read_dive_info
from auvnav.raster import MapGrid, write_geotiff

pytestmark = pytest.mark.xdist_group("report")

SIMULATE = ["simulate", "navcheck", "--seed", "3", "--headings", "8", "--leg-m", "6", "--grid-m", "2"]
SIMULATE += ["--no-images", "--truth-loops", "--duration-s", "700", "-q", "--json"]
DRAWN = {"fig2", "fig4", "fig5a", "fig6", "fig8", "fig9", "fig10", "fig11"}


def _fake_recon(dive: Path) -> None:
    """A reconstruction's products on a 3 m x 3 m patch at the origin (what the report reads)."""
    from auvnav.recon.o3d import open3d

    o3d = open3d()
    folder = P.stage_dir(dive, "recon")
    folder.mkdir(parents=True, exist_ok=True)
    n = 41
    e, nn = np.meshgrid(np.linspace(-1.5, 1.5, n), np.linspace(-1.5, 1.5, n))
    z = -20.0 + 0.1 * np.sin(2 * e) * np.cos(3 * nn)
    vertices = np.column_stack([e.ravel(), nn.ravel(), z.ravel()])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices),
        o3d.utility.Vector3iVector(np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])),
    )
    grey = 0.5 + 0.3 * np.sin(7 * vertices[:, :1]) * np.cos(5 * vertices[:, 1:2])
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.repeat(grey, 3, axis=1))
    o3d.io.write_triangle_mesh(str(P.RECON_MESH.path(dive)), mesh)
    origin = read_dive_info(dive).origin
    corners = np.array([[-1.5, -1.5], [1.5, 1.5]])
    dem_grid = MapGrid.covering(corners, origin, 0.05)
    zz = -20.0 + 0.1 * np.sin(np.linspace(0, 6, dem_grid.width))[None, :] * np.ones((dem_grid.height, 1))
    write_geotiff(
        P.RECON_DEM.path(dive),
        np.stack([zz, np.full_like(zz, 0.01)]).astype(np.float32),
        dem_grid,
        nodata=np.nan,
    )
    mosaic_grid = MapGrid.covering(corners, origin, 0.01)
    rng = np.random.default_rng(1)
    texture = rng.integers(20, 235, (mosaic_grid.height, mosaic_grid.width)).astype(np.uint8)
    write_geotiff(P.RECON_MOSAIC.path(dive), texture, mosaic_grid, nodata=0)
    pd.DataFrame(
        {
            "dt_s": [1300.0, 2500.0, 3100.0],
            "tide_change_m": [0.10, 0.18, 0.21],
            "step_before_m": [-0.11, -0.19, -0.20],
            "step_after_m": [-0.01, -0.01, 0.01],
        }
    ).to_csv(P.RECON_RELIEF.path(dive), index=False)
    summary = {"fusion": {"relief_step_m": 0.1}, "dem": {"area_m2": 9.0}, "pairs": {"used": 12}}
    summary |= {
        "mesh": {"faces": len(mesh.triangles)},
        "relief": {"step_before_rms_m": 0.17, "step_after_rms_m": 0.01},
    }
    P.RECON_SUMMARY.path(dive).write_text(json.dumps(summary), encoding="utf-8")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("report") / "campaign"
    dive = root / "navcheck"
    assert main([*SIMULATE, "--out", str(dive)]) == 0
    loops, tide = dive / "truth" / "loops.csv", dive / "truth" / "tide.csv"
    args = ["process", str(dive), "--loops", str(loops), "--tide", str(tide), "-q", "--json"]
    assert main([*args, *[x for s in ("nav", "slam", "compass", "depth") for x in ("--only", s)]]) == 0
    navonly = root / "navonly"
    shutil.copytree(dive, navonly, ignore=shutil.ignore_patterns("products", "truth"))
    shutil.copytree(P.stage_dir(dive, "nav"), P.stage_dir(navonly, "nav"))
    _fake_recon(dive)
    shutil.copy(P.COMPASS_CORRECTION.path(dive), root / "compass-correction.yaml")  # as the demo's fit
    return root


@pytest.fixture(scope="module")
def dive_report(campaign: Path) -> dict:
    assert main(["report", str(campaign / "navcheck"), "-q", "--json"]) == 0
    return json.loads(P.REPORT_SUMMARY.path(campaign / "navcheck").read_text(encoding="utf-8"))


class _Page(HTMLParser):
    """The page's external references and its figures."""

    def __init__(self) -> None:
        super().__init__()
        self.external: list[str] = []
        self.figures: list[str] = []
        self.absent = 0
        self.csp = ""

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        for key in ("src", "href", "data", "poster"):
            value = a.get(key) or ""
            if value and not value.startswith(("data:", "#")):
                self.external.append(f"{tag} {key}={value[:60]}")
        if tag == "link":
            self.external.append(f"link {a}")
        if tag == "figure":
            self.figures.append(a.get("data-figure") or "")
        if "data-absent" in a:
            self.absent += 1
        if tag == "meta" and a.get("http-equiv") == "Content-Security-Policy":
            self.csp = a.get("content") or ""


def _parse(path: Path) -> tuple[_Page, str]:
    text = path.read_text(encoding="utf-8")
    page = _Page()
    page.feed(text)
    return page, text


def test_a_dive_report_draws_every_figure_its_products_allow(campaign: Path, dive_report: dict) -> None:
    drawn = {p["key"] for p in dive_report["panels"] if p["file"]}
    assert drawn == DRAWN, dive_report["not_drawn"]
    # the coverage stage has not run and a short dive has no transit legs: the page says so
    assert set(dive_report["not_drawn"]) == {"coverage", "fig5b"}
    assert "coverage stage did not run" in dive_report["not_drawn"]["coverage"]
    assert "no sub-sea transit legs" in dive_report["not_drawn"]["fig5b"]
    assert (
        dive_report["views"]["map"]["file"] == "map.json"
        and dive_report["views"]["mesh"]["file"] == "mesh3d.json"
    )
    folder = P.REPORT_FIGURES.path(campaign / "navcheck")
    for name in dive_report["figures"]:
        assert (folder / name).stat().st_size > 10_000, name
    page, text = _parse(P.REPORT_INDEX.path(campaign / "navcheck"))
    assert page.external == [] and "default-src 'none'" in page.csp
    assert set(page.figures) == DRAWN and page.absent == 2
    markup = re.sub(r"<script.*?</script>", "", text, flags=re.S)  # plotly.js's strings are not links
    assert not re.search(r"""(src|href)\s*=\s*["']?https?:""", markup)
    assert dive_report["page_bytes"] < 15e6
    mesh = json.loads(P.REPORT_MESH.path(campaign / "navcheck").read_text(encoding="utf-8"))
    assert mesh["data"][0]["type"] == "mesh3d"
    facts = dive_report["facts"]
    assert facts["stages"]["slam"]["status"] == "ran" and facts["sensors"][0] == "DVL"


def test_a_dive_with_navigation_only_gets_a_shorter_valid_page(campaign: Path, dive_report: dict) -> None:
    navonly = campaign / "navonly"
    assert main(["report", str(navonly), "-q", "--json"]) == 0
    summary = json.loads(P.REPORT_SUMMARY.path(navonly).read_text(encoding="utf-8"))
    assert {p["key"] for p in summary["panels"] if p["file"]} == {"fig2", "fig9"}
    assert "slam stage did not run" in summary["not_drawn"]["fig4"]
    assert summary["views"]["mesh"]["why"].startswith("no reconstruction")
    page, _ = _parse(P.REPORT_INDEX.path(navonly))
    assert page.external == [] and page.figures == ["fig2", "fig9"]
    assert page.absent == 9  # 8 figures and the 3D view, each with its reason
    assert summary["page_bytes"] < dive_report["page_bytes"]


def test_a_campaign_report_holds_every_dive(campaign: Path, dive_report: dict, capsys) -> None:
    assert main(["report", str(campaign)]) == 0
    out = capsys.readouterr().out
    assert "campaign report of 2 dives (navcheck, navonly)" in out
    page, text = _parse(P.REPORT_INDEX.path(campaign))
    assert page.external == []
    assert text.count('id="dive-navcheck"') == 1 and text.count('id="dive-navonly"') == 1
    assert text.count("<script>") == 2  # plotly.js once, and the code that draws the plots
    assert page.figures.count("fig2") == 2 and "campaign_fig8_navcheck" in page.figures


def test_report_of_a_folder_that_holds_no_dive_is_one_line(tmp_path: Path, capsys) -> None:
    (tmp_path / "empty").mkdir()
    assert main(["report", str(tmp_path / "empty")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("auvnav: error:")


@pytest.mark.browser
def test_the_campaign_page_in_a_real_browser(
    chromium: str, look_at_page, campaign: Path, dive_report: dict, tmp_path_factory
) -> None:
    if not P.REPORT_INDEX.path(campaign).is_file():
        assert main(["report", str(campaign), "-q"]) == 0
    base = os.environ.get("AUVNAV_TEST_ARTEFACTS")
    artefacts = (Path(base) if base else tmp_path_factory.mktemp("artefacts")) / "report"
    seen = look_at_page(P.REPORT_INDEX.path(campaign), chromium, artefacts)
    assert seen.console_errors == []
    assert seen.requests_outside == [] and seen.requests == 1  # the page itself, nothing else
    expected = {"campaign_fig8_navcheck"} | DRAWN
    assert expected <= {k.split("/")[-1] for k in seen.figures}, seen.figures
    assert len(seen.figures) == len(DRAWN) + 2 + 1  # navcheck's, navonly's two, the campaign's Fig. 8
    blank = {k: v for k, v in {**seen.figures, **seen.plots}.items() if v < 20}
    assert not blank, f"blank figures: {blank}"
    assert len(seen.plots) == 3  # two maps and one 3D view
    before, after = seen.zoom
    assert after < 0.9 * before, f"the map did not zoom: x span {before:.2f} m -> {after:.2f} m"
    assert all(p.stat().st_size > 5_000 for p in seen.screenshots)
    print(f"report screenshots in {artefacts}")
