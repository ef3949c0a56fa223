"""Every product of a dive, declared once (DESIGN section 6), and the atomic set a stage writes.

A stage's products live in ``DIVE/products/<stage>/``; their names are the :class:`Product`
constants below and nowhere else. Caches (features, verified pairs) live in
``DIVE/products/cache/<stage>/``: they are not products, survive a stage's rerun and are reused
by content.

A stage writes its products through :class:`ProductSet`: into a temporary folder beside
``products/<stage>``, the stage's ``stage.json`` (its key) last, then swapped in by two renames.
:func:`recover` repairs what a kill between the two renames leaves (the complete new set, else the
complete old one, is put back) and removes every unfinished temporary folder, so a stage killed at
any instant leaves either its old complete set or its new one.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from auvnav.errors import AuvnavError

log = logging.getLogger(__name__)

PRODUCTS = "products"
CACHE = "cache"
STAGE_FILE = "stage.json"


@dataclass(frozen=True)
class Product:
    """One product file (or folder) of a stage.

    Parameters
    ----------
    stage : str
        The stage that writes it: its folder under ``products/``.
    name : str
        The file's name inside that folder.
    """

    stage: str
    name: str

    @property
    def rel(self) -> str:
        """The path relative to the dive folder, e.g. ``products/slam/trajectory.csv``."""
        return f"{PRODUCTS}/{self.stage}/{self.name}"

    def path(self, dive: Path) -> Path:
        """The product's path in a dive folder."""
        return Path(dive) / PRODUCTS / self.stage / self.name

    def inside(self, folder: Path) -> Path:
        """The product's path inside a stage folder being written (:class:`ProductSet`)."""
        return Path(folder) / self.name


# navigation
NAV_DR = Product("nav", "dr.csv")
NAV_DR_TUM = Product("nav", "dr.tum")
NAV_FILTER = Product("nav", "filter.csv")
NAV_FILTER_TUM = Product("nav", "filter.tum")
NAV_INNOVATIONS = Product("nav", "innovations.csv")
NAV_CMG = Product("nav", "cmg.csv")
NAV_SUMMARY = Product("nav", "summary.json")
# vision (the loop-closure stage)
LOOPS = Product("vision", "loops.csv")
VISION_SUMMARY = Product("vision", "summary.json")
# slam
SLAM_TRAJECTORY = Product("slam", "trajectory.csv")
SLAM_TUM = Product("slam", "trajectory.tum")
SLAM_GRAPH = Product("slam", "graph.g2o")
SLAM_CORRECTION = Product("slam", "correction.yaml")  # the deviation estimated in the graph
SLAM_SUMMARY = Product("slam", "summary.json")
SLAM_ONLINE = Product("slam", "online.csv")  # the estimate as known at each moment (--online)
# compass
COMPASS_CORRECTION = Product("compass", "correction.yaml")
COMPASS_PAIRS = Product("compass", "pairs.csv")
COMPASS_SUMMARY = Product("compass", "summary.json")
# depth
DEPTH_LOOPS = Product("depth", "loop_depth.csv")
DEPTH_TIDE_ESTIMATED = Product("depth", "tide_estimated.csv")
DEPTH_SUMMARY = Product("depth", "summary.json")
# coverage
COVERAGE_TIF = Product("coverage", "coverage.tif")  # images per cell, GeoTIFF
COVERAGE_PNG = Product("coverage", "coverage.png")
COVERAGE_LINES = Product("coverage", "lines.csv")  # one row per adjacent line pair
COVERAGE_SPACING = Product("coverage", "spacing.csv")  # each pair's spacing at its stations
COVERAGE_GAPS = Product("coverage", "gaps.csv")
COVERAGE_SUMMARY = Product("coverage", "summary.json")
# recon (reconstruction)
RECON_MESH = Product("recon", "mesh.ply")  # coloured TSDF mesh, east-north-up about the dive's origin
RECON_DEM = Product("recon", "dem.tif")  # elevation and its 1-sigma, tiled GeoTIFF (UTM)
RECON_MOSAIC = Product("recon", "mosaic.tif")  # orthophoto, tiled GeoTIFF (UTM)
RECON_RELIEF = Product("recon", "relief.csv")  # the Fig. 11 check: steps between far-apart visits
RECON_PAIRS = Product("recon", "pairs.csv")  # every stereo pair considered: placement and status
RECON_SUMMARY = Product("recon", "summary.json")
# report
REPORT_FIGURES = Product("report", "figures")
REPORT_INDEX = Product("report", "index.html")  # the self-contained page (no network)
REPORT_MAP = Product("report", "map.json")  # the interactive map (plotly JSON), reused by a campaign's page
REPORT_MESH = Product("report", "mesh3d.json")  # the decimated mesh's 3D view (plotly JSON)
REPORT_SUMMARY = Product("report", "summary.json")  # facts, figures drawn and why the others were not

#: Names of earlier releases, read with a deprecation warning for one release: old -> current.
RENAMED: dict[str, Product] = {"products/slam/compass_correction.yaml": SLAM_CORRECTION}


def existing(dive: Path, product: Product) -> Path | None:
    """The product's file in a dive folder, or its earlier name (with a warning), or None."""
    path = product.path(dive)
    if path.exists():
        return path
    for old, new in RENAMED.items():
        if new == product and (Path(dive) / old).exists():
            warnings.warn(
                f"{Path(dive) / old}: an earlier release's name for {product.rel}; rerun the stage to "
                "rename it (the old name will not be read by the next release)",
                DeprecationWarning,
                stacklevel=2,
            )
            return Path(dive) / old
    return None


def stage_dir(dive: Path, stage: str) -> Path:
    """``DIVE/products/<stage>``."""
    return Path(dive) / PRODUCTS / stage


def cache_dir(dive: Path, stage: str) -> Path:
    """``DIVE/products/cache/<stage>``: a stage's reusable intermediate results."""
    return Path(dive) / PRODUCTS / CACHE / stage


def read_record(dive: Path, stage: str) -> dict[str, Any] | None:
    """A stage's ``stage.json`` (its key and what it did), or None when it has none or it is unreadable."""
    path = stage_dir(dive, stage) / STAGE_FILE
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def _leftovers(dive: Path, stage: str, kind: str) -> list[Path]:
    parent = Path(dive) / PRODUCTS
    if not parent.is_dir():
        return []
    return sorted(parent.glob(f".{stage}.{kind}-*"))


def recover(dive: Path, stage: str) -> None:
    """Repair a stage's folder after a kill and remove its unfinished temporary folders.

    A kill between the two renames of :meth:`ProductSet.commit` leaves no ``products/<stage>``: the
    new set (complete: it has its ``stage.json``) is put in place, else the old one.
    """
    final = stage_dir(dive, stage)
    new = [p for p in _leftovers(dive, stage, "new") if (p / STAGE_FILE).is_file()]
    old = [p for p in _leftovers(dive, stage, "old") if any(p.iterdir())]
    if not final.exists():
        for candidate in (*new, *old):
            os.replace(candidate, final)
            log.info("%s: restored from an interrupted run", final)
            break
    for leftover in (*_leftovers(dive, stage, "new"), *_leftovers(dive, stage, "old")):
        shutil.rmtree(leftover, ignore_errors=True)


class ProductSet:
    """One stage's products written together or not at all (see the module docstring).

    Use as a context manager: the folder it gives is empty; write the products there, then call
    :meth:`commit` with the stage's record. Leaving the block without committing (an exception, a
    signal turned into one) removes the folder and leaves the old products as they were.
    """

    def __init__(self, dive: Path, stage: str) -> None:
        self.dive = Path(dive)
        self.stage = stage
        self.final = stage_dir(dive, stage)
        self.folder: Path | None = None

    def __enter__(self) -> Path:
        parent = self.final.parent
        if parent.exists() and not parent.is_dir():
            raise AuvnavError(f"{parent}: exists and is not a folder; products cannot be written")
        if self.final.exists() and not self.final.is_dir():
            raise AuvnavError(f"{self.final}: exists and is not a folder; products cannot be written")
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self.folder = Path(tempfile.mkdtemp(dir=parent, prefix=f".{self.stage}.new-"))
        except PermissionError as err:
            raise AuvnavError(f"{parent}: not writable ({err.strerror})") from err
        os.chmod(self.folder, 0o777 & ~_umask())
        return self.folder

    def commit(self, record: dict[str, Any]) -> None:
        """Write ``stage.json`` last, then swap the new set in for the old one."""
        if self.folder is None:
            raise RuntimeError("ProductSet.commit outside its with-block")
        text = json.dumps(record, indent=2, default=float) + "\n"
        (self.folder / STAGE_FILE).write_text(text, encoding="utf-8")
        old = None
        if self.final.exists():
            old = Path(tempfile.mkdtemp(dir=self.final.parent, prefix=f".{self.stage}.old-"))
            os.replace(self.final, old)  # onto the empty folder just made: one rename
        os.replace(self.folder, self.final)
        self.folder = None
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def __exit__(self, *exc: object) -> None:
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)
            self.folder = None


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask
