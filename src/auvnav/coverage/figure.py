"""The coverage map as a PNG, drawn with OpenCV (no matplotlib outside report/).

Images per cell in a colour map (cells no image saw are white), the gaps between the flown lines in
red, the planned area's cells outside the flown lines that no image saw in orange (not surveyed), the
planned area's outline in black, a title, and a legend strip underneath: the colour bar with its counts, the gap
colour, a scale bar and north (map grid north is up). Large grids are reduced (by the maximum of each
block, so a gap or a single image never disappears) to at most ``max_px`` on their longer side.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from auvnav.coverage.analysis import Coverage
from auvnav.streams import atomic_write

GAP_BGR = (40, 40, 220)
NOT_SURVEYED_BGR = (80, 170, 255)
EMPTY_BGR = (255, 255, 255)
OUTLINE_BGR = (0, 0, 0)
MAX_COUNT = 8  # the colour bar's top: this many images or more


def _reduce(a: NDArray, factor: int) -> NDArray:
    """Block maximum of a 2D array by ``factor`` (padded with zeros)."""
    if factor <= 1:
        return a
    h, w = a.shape
    H, W = -(-h // factor), -(-w // factor)
    padded = np.zeros((H * factor, W * factor), dtype=a.dtype)
    padded[:h, :w] = a
    return padded.reshape(H, factor, W, factor).max(axis=(1, 3))


def _colour_bar() -> NDArray[np.uint8]:
    """BGR colours of 1..MAX_COUNT images (viridis through OpenCV)."""
    import cv2

    levels = np.linspace(0, 255, MAX_COUNT).astype(np.uint8)[:, None]
    return cv2.applyColorMap(levels, cv2.COLORMAP_VIRIDIS)[:, 0, :]


def _wrap(text: str, font: int, scale: float, width_px: int) -> list[str]:
    """``text`` in lines that fit ``width_px`` (split at spaces)."""
    import cv2

    rows: list[str] = []
    for word in text.split():
        trial = f"{rows[-1]} {word}" if rows else word
        if rows and cv2.getTextSize(trial, font, scale, 1)[0][0] <= width_px:
            rows[-1] = trial
        else:
            rows.append(word)
    return rows or [""]


def coverage_image(cov: Coverage, *, title: str = "", max_px: int = 1600) -> NDArray[np.uint8]:
    """The coverage map (BGR) with its legend strip (module docstring)."""
    import cv2

    factor = max(1, math.ceil(max(cov.grid.width, cov.grid.height) / max_px))
    counts = _reduce(np.minimum(cov.counts, MAX_COUNT).astype(np.uint8), factor)
    gaps = _reduce((cov.gaps.labels > 0).astype(np.uint8), factor) > 0
    region = _reduce(cov.region.astype(np.uint8), factor) > 0
    outside = _reduce((cov.region & ~cov.covered & ~cov.between).astype(np.uint8), factor) > 0
    colours = np.concatenate([[EMPTY_BGR], _colour_bar()]).astype(np.uint8)
    img = colours[counts]
    img[outside] = NOT_SURVEYED_BGR
    img[gaps] = GAP_BGR
    if region.any():
        contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(img, contours, -1, OUTLINE_BGR, 1)
    h, w = img.shape[:2]
    width = max(w, 620)
    canvas_map = np.full((h, width, 3), 255, np.uint8)
    canvas_map[:, :w] = img

    font = cv2.FONT_HERSHEY_SIMPLEX
    rows = _wrap(title, font, 0.5, width - 12)
    head = np.full((10 + 20 * len(rows), width, 3), 255, np.uint8)
    for k, text in enumerate(rows):
        cv2.putText(head, text, (6, 22 + 20 * k), font, 0.5, (0, 0, 0), 1, cv2.LINE_AA)

    legend = np.full((70, width, 3), 255, np.uint8)
    x = 8
    cv2.putText(legend, "images per cell", (x, 16), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    box = 22
    for k in range(MAX_COUNT + 1):
        colour = tuple(int(c) for c in colours[k])
        cv2.rectangle(legend, (x + k * box, 24), (x + (k + 1) * box - 1, 42), colour, -1)
        cv2.rectangle(legend, (x + k * box, 24), (x + (k + 1) * box - 1, 42), (128, 128, 128), 1)
        label = f"{k}+" if k == MAX_COUNT else str(k)
        cv2.putText(legend, label, (x + k * box + 4, 58), font, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    gx = x + (MAX_COUNT + 1) * box + 14
    cv2.rectangle(legend, (gx, 24), (gx + box, 42), GAP_BGR, -1)
    cv2.putText(legend, "gap", (gx + box + 4, 38), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    gx += box + 40
    cv2.rectangle(legend, (gx, 24), (gx + box, 42), NOT_SURVEYED_BGR, -1)
    cv2.putText(legend, "not surveyed", (gx + box + 4, 38), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    gx += 90
    # scale bar: a round length about a fifth of the map's width
    px_m = cov.grid.cell_m * factor
    target = 0.2 * w * px_m
    length = 10 ** math.floor(math.log10(max(target, 1e-3)))
    for step in (5, 2, 1):
        if step * length <= target:
            length *= step
            break
    bar = max(round(length / px_m), 1)
    sx = gx + box + 30
    cv2.line(legend, (sx, 36), (sx + bar, 36), (0, 0, 0), 2)
    cv2.putText(legend, f"{length:g} m", (sx, 58), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    nx = sx + max(bar, 40) + 24
    cv2.arrowedLine(legend, (nx, 50), (nx, 22), (0, 0, 0), 2, tipLength=0.35)
    cv2.putText(legend, "N", (nx + 8, 34), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([head, canvas_map, legend], axis=0)


def write_coverage_png(cov: Coverage, path: Path, *, title: str = "") -> None:
    """Write :func:`coverage_image` as a PNG, atomically."""
    import cv2

    image = coverage_image(cov, title=title)

    def write(tmp: Path) -> None:
        ok, data = cv2.imencode(".png", image)
        if not ok:
            raise OSError(f"could not encode {path}")
        tmp.write_bytes(data.tobytes())

    atomic_write(Path(path), write)
