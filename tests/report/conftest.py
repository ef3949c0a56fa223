"""The report tests' browser: a report page opened in headless Chromium (playwright driving the
system's browser: no browser download) and looked at as a reader would: every request, every
console message, every figure, the map's zoom. The ``chromium`` fixture skips where there is none."""

from __future__ import annotations

import io
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import pytest

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
LOCAL_SCHEMES = ("file:", "data:")


def find_chromium() -> str | None:
    """The system's Chromium: ``AUVNAV_CHROMIUM`` when set, else the first on the PATH."""
    given = os.environ.get("AUVNAV_CHROMIUM")
    if given:
        return given if Path(given).is_file() else None
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


@dataclass
class PageCheck:
    """What the browser saw."""

    console_errors: list[str] = field(default_factory=list)
    requests_outside: list[str] = field(default_factory=list)
    requests: int = 0
    figures: dict[str, int] = field(default_factory=dict)  # section/figure -> distinct colours seen
    plots: dict[str, int] = field(default_factory=dict)  # plot div -> distinct colours seen
    absent: list[str] = field(default_factory=list)  # the "not drawn: why" lines
    zoom: tuple[float, float] | None = None  # the map's x span before and after a wheel zoom
    load_s: float = 0.0
    screenshots: list[Path] = field(default_factory=list)


#: Distinct colours of a decoded image, sampled (0 when it did not decode): drawn into a canvas as the
#: browser decoded it (data: images do not taint the canvas).
COLOURS_JS = """i => {
  if (!i.complete || i.naturalWidth === 0) return 0;
  const c = document.createElement('canvas'); c.width = i.naturalWidth; c.height = i.naturalHeight;
  const x = c.getContext('2d'); x.drawImage(i, 0, 0);
  const d = x.getImageData(0, 0, c.width, c.height).data; const seen = new Set();
  const step = 4 * Math.max(1, Math.floor(d.length / 4 / 20000));
  for (let k = 0; k < d.length; k += step) seen.add((d[k] << 16) | (d[k + 1] << 8) | d[k + 2]);
  return seen.size;
}"""


def distinct_colours(png: bytes) -> int:
    """Distinct colours in a screenshot (a blank box has one or two)."""
    import numpy as np
    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3)
    return len(np.unique(a[:: max(1, len(a) // 20000)], axis=0))


def check_page(page_file: Path, chromium: str, artefacts: Path | None = None) -> PageCheck:
    """Load the page, wait for its plots, check each figure and the map's zoom, take screenshots."""
    import time

    from playwright.sync_api import sync_playwright

    result = PageCheck()
    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=chromium,
            headless=True,
            args=[
                "--no-sandbox",
                "--disable-dev-shm-usage",
                "--enable-unsafe-swiftshader",
                "--use-angle=swiftshader",
            ],
        )
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})

            def on_request(request):
                result.requests += 1
                if not request.url.startswith(LOCAL_SCHEMES):
                    result.requests_outside.append(request.url)

            page.on("request", on_request)
            page.on("console", lambda m: result.console_errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: result.console_errors.append(f"page error: {e}"))
            started = time.perf_counter()
            page.goto(Path(page_file).resolve().as_uri(), wait_until="load", timeout=60_000)
            page.wait_for_function(
                "() => Array.from(document.querySelectorAll('div.plot')).every(d => d.dataset.rendered === '1')",
                timeout=60_000,
            )
            result.load_s = time.perf_counter() - started
            for fig in page.query_selector_all("figure"):
                img = fig.query_selector("img")
                where = fig.evaluate("f => (f.closest('section') || {}).id || 'campaign'")
                key = f"{where}/{fig.get_attribute('data-figure') or '?'}"
                result.figures[key] = img.evaluate(COLOURS_JS) if img is not None else 0
            for div in page.query_selector_all("div.plot"):
                div.scroll_into_view_if_needed()
                page.wait_for_timeout(200)
                result.plots[div.get_attribute("id") or "?"] = distinct_colours(div.screenshot())
            result.absent = [e.inner_text() for e in page.query_selector_all("[data-absent]")]
            maps = page.query_selector_all("div[data-map]")
            if maps:
                m = maps[0]
                m.scroll_into_view_if_needed()
                span = "d => { const r = d._fullLayout.xaxis.range; return r[1] - r[0]; }"
                before = m.evaluate(span)
                box = m.query_selector(".nsewdrag").bounding_box()
                page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
                for _ in range(3):
                    page.mouse.wheel(0, -300)
                    page.wait_for_timeout(150)
                page.wait_for_timeout(500)
                result.zoom = (before, m.evaluate(span))
            if artefacts is not None:
                artefacts.mkdir(parents=True, exist_ok=True)
                shots = {"page.png": None, "summary.png": "#summary-table"}
                if maps:
                    shots["map.png"] = "div[data-map]"
                for key in ("fig5a", "fig9", "fig10", "campaign_fig5b_constant"):
                    if page.query_selector(f'figure[data-figure="{key}"]'):
                        shots[f"{key}.png"] = f'figure[data-figure="{key}"]'
                if page.query_selector("div[data-mesh]"):
                    shots["mesh3d.png"] = "div[data-mesh]"
                for name, selector in shots.items():
                    path = artefacts / name
                    if selector is None:
                        page.evaluate("window.scrollTo(0, 0)")
                        page.screenshot(path=str(path))
                    else:
                        page.query_selector(selector).screenshot(path=str(path))
                    result.screenshots.append(path)
        finally:
            browser.close()
    return result


@pytest.fixture(scope="session")
def chromium() -> str:
    """The system's Chromium for playwright; skip where either is missing."""
    pytest.importorskip("playwright")
    path = find_chromium()
    if path is None:
        pytest.skip("no Chromium on this machine (apt-get install chromium, or set AUVNAV_CHROMIUM)")
    return path


@pytest.fixture(scope="session")
def look_at_page():
    """:func:`check_page`, for the tests."""
    return check_page
