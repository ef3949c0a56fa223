"""The two entry points: :func:`import_dive` (a vehicle's logs into a dive folder) and
:func:`export_dive` (a dive's products for other tools)."""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from auvnav.dive import Dive, read_dive, validate_dive, write_dive
from auvnav.errors import AuvnavError, DiveFormatError, OutputExistsError
from auvnav.io.common import ImportContext, assemble, load_settings
from auvnav.io.registry import exporter, importer
from auvnav.streams import ensure_writable

log = logging.getLogger(__name__)

TrackSource = Literal["auto", "slam", "filter", "dr"]


def _mover(src: Path) -> Callable[[Path], None]:
    def move(target: Path) -> None:
        os.replace(src, target)

    return move


def _linker(base: Dive) -> Callable[[Path], None]:
    """Copies (hard links where it can) the base dive's image files the index names."""

    def link(target: Path) -> None:
        assert base.images is not None and base.path is not None
        for name in (*base.images.left, *base.images.right):
            src = base.path / "images" / str(name)
            if not src.is_file():
                continue
            dst = target / str(name)
            dst.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(src, dst)
            except OSError:
                shutil.copy2(src, dst)

    return link


def import_dive(
    fmt: str,
    sources: Sequence[str | Path],
    out: str | Path,
    *,
    config: str | Path | Mapping[str, Any] | None = None,
    base: str | Path | None = None,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Read a vehicle's logs into a dive folder; nothing is written unless all of it reads.

    Parameters
    ----------
    fmt : str
        A format of :data:`auvnav.io.registry.IMPORTERS` (``acfr-raw``, ``pd0``, ``rosbag``,
        ``nmea``, ``csv``).
    sources : sequence of paths
        The files (or ROS 2 bag folders) to read, in time order.
    out : path
        The dive folder to write.
    config : path or mapping, optional
        The format's settings file (YAML; for ``csv`` the mapping file), or the same settings as a
        mapping (paths in it relative to the working folder).
    base : path, optional
        A dive folder whose streams, vehicle and metadata fill in what the sources lack.
    overwrite : bool
        Replace an existing ``out``.

    Returns
    -------
    dict
        The summary: streams and their origin, what was read and skipped (by reason, with the first
        place), the heading, pressure and origin rules applied, notes.

    Raises
    ------
    FormatError
        A source breaks its format (one line naming the file and the line or byte).
    ConfigError, InsufficientDataError, OutputExistsError
    """
    info = importer(fmt)
    module = info.load_module()
    if config is not None and not isinstance(config, Mapping):
        config = Path(config)
    settings, settings_dir = load_settings(module.SETTINGS, config)
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExistsError(f"{out}: exists (use --overwrite to replace it)")
    base_dive = read_dive(Path(base)) if base is not None else None
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.import-"))
    try:
        context = ImportContext(base=base_dive, staging=staging / "work", settings_dir=settings_dir)
        context.staging.mkdir()
        imported = module.read([Path(s) for s in sources], settings, context)
        assembled = assemble(
            imported,
            settings,
            fmt=fmt,
            sources=[Path(s) for s in sources],
            base=base_dive,
            name=out.name,
            settings_dir=settings_dir,
        )
        extra: dict[str, Callable[[Path], None]] = {}
        if imported.images_dir is not None:
            for sub in sorted(imported.images_dir.iterdir()):
                extra[f"images/{sub.name}"] = _mover(sub)
        elif assembled.images_from_base and base_dive is not None:
            extra["images"] = _linker(base_dive)
        written = write_dive(assembled.dive, staging / "dive", extra=extra)
        report = validate_dive(written)  # read back through the dive format's own checks
        if not report.ok:
            raise DiveFormatError(report.problems)
        if out.exists():
            old = staging / "old"
            os.replace(out, old)
        os.replace(written, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    summary = {"out": str(out), **assembled.summary}
    summary["warnings"] = report.warnings
    return summary


@dataclass(frozen=True)
class ExportOptions:
    """Options every exporter may use.

    Parameters
    ----------
    source : {"auto", "slam", "filter", "dr"}
        The trajectory exported: ``auto`` takes SLAM's, else the filter's, else dead reckoning.
    sigma_m : float, optional
        1-sigma position accuracy to write when the trajectory has none (dead reckoning).
    correction : Path, optional
        A compass correction file (``compass-table``; default the dive's compass stage product).
    """

    source: TrackSource = "auto"
    sigma_m: float | None = None
    correction: Path | None = None


def export_dive(
    dive: str | Path,
    fmt: str,
    out: str | Path | None = None,
    *,
    options: ExportOptions | None = None,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Write a dive's products in another tool's format.

    Parameters
    ----------
    dive : path
        A dive folder with the products the format needs (a trajectory; images for camera
        formats; the compass stage's correction for ``compass-table``).
    fmt : str
        A format of :data:`auvnav.io.registry.EXPORTERS`.
    out : path, optional
        The file to write (default ``DIVE/exports/<the format's file name>``).
    options : ExportOptions, optional
    overwrite : bool

    Returns
    -------
    dict
        What was written.
    """
    info = exporter(fmt)
    dive = Path(dive)
    if not dive.is_dir():
        raise AuvnavError(f"{dive}: not a dive folder (no such directory)")
    target = Path(out) if out is not None else dive / "exports" / info.default_name
    ensure_writable(target, overwrite=overwrite)
    summary = info.load()(dive, target, options or ExportOptions())
    return {"format": fmt, "dive": str(dive), "out": str(target), **summary}


__all__ = ["ExportOptions", "OutputExistsError", "export_dive", "import_dive"]
