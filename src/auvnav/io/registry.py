"""The formats ``auvnav import`` and ``auvnav export`` know, by name, and the module of each.

A format's module is imported only when the format is used, so listing them costs nothing. An
importer module defines ``SETTINGS`` (its pydantic settings class, a subclass of
:class:`auvnav.io.common.ImportSettings`) and ``read(sources, settings, context) -> Imported``; an
exporter module defines ``export(dive, out, options) -> dict`` for each format it writes (the
function named in :data:`EXPORTERS`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any

from auvnav.config import quote
from auvnav.errors import ConfigError


@dataclass(frozen=True)
class FormatInfo:
    """One format.

    Parameters
    ----------
    name : str
        The name on the command line.
    module : str
        The module that reads or writes it.
    function : str
        The function of that module (``read`` for importers).
    title : str
        One line for ``--help``.
    default_name : str
        Exporters: the file written in ``DIVE/exports/`` when no ``--out`` is given.
    """

    name: str
    module: str
    function: str
    title: str
    default_name: str = ""

    def load(self) -> Any:
        """The function that reads or writes the format."""
        module: ModuleType = importlib.import_module(self.module)
        return getattr(module, self.function)

    def load_module(self) -> ModuleType:
        return importlib.import_module(self.module)


IMPORTERS: dict[str, FormatInfo] = {
    f.name: f
    for f in (
        FormatInfo("acfr-raw", "auvnav.io.acfr", "read", "ACFR combined.RAW.auv with its mission.cfg"),
        FormatInfo("pd0", "auvnav.io.pd0", "read", "Teledyne RDI PD0 binary ensembles (bottom track)"),
        FormatInfo("rosbag", "auvnav.io.rosbag", "read", "ROS 1 .bag files or ROS 2 bag folders"),
        FormatInfo("nmea", "auvnav.io.nmea", "read", "NMEA 0183 logs: GGA, RMC (GPS), HDT, HDG, HDM"),
        FormatInfo("csv", "auvnav.io.csvmap", "read", "CSV files described by a mapping file (--config)"),
    )
}

EXPORTERS: dict[str, FormatInfo] = {
    f.name: f
    for f in (
        FormatInfo(
            "geojson", "auvnav.io.geo", "export_geojson", "track and loop closures, WGS84", "track.geojson"
        ),
        FormatInfo(
            "kml", "auvnav.io.geo", "export_kml", "track and loop closures for Google Earth", "track.kml"
        ),
        FormatInfo(
            "csv",
            "auvnav.io.tables",
            "export_csv",
            "trajectory with latitude, longitude and sigmas",
            "trajectory.csv",
        ),
        FormatInfo(
            "acfr-stereo-pose",
            "auvnav.io.acfr",
            "export_stereo_pose",
            "ACFR stereo_pose_est.data (left camera poses)",
            "stereo_pose_est.data",
        ),
        FormatInfo(
            "colmap-priors",
            "auvnav.io.priors",
            "export_priors",
            "camera position priors with accuracies (COLMAP, Metashape reference CSV)",
            "camera_priors.csv",
        ),
        FormatInfo(
            "compass-table",
            "auvnav.io.firmware",
            "export_table",
            "the compass correction as a 360-row table (CSV and a C header) for firmware",
            "compass_table.csv",
        ),
    )
}


def importer(name: str) -> FormatInfo:
    """The importer of a format; :class:`ConfigError` naming the known ones otherwise."""
    if name not in IMPORTERS:
        raise ConfigError(f"unknown import format {quote(name)}; known: {', '.join(IMPORTERS)}")
    return IMPORTERS[name]


def exporter(name: str) -> FormatInfo:
    """The exporter of a format; :class:`ConfigError` naming the known ones otherwise."""
    if name not in EXPORTERS:
        raise ConfigError(f"unknown export format {quote(name)}; known: {', '.join(EXPORTERS)}")
    return EXPORTERS[name]
