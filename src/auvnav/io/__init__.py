"""Importers and exporters of the formats real vehicles and other tools use.

``auvnav import FORMAT SOURCE... --out DIVE`` reads a vehicle's own logs into a dive folder
(:func:`~auvnav.io.api.import_dive`); ``auvnav export DIVE FORMAT`` writes a dive's products for
other tools (:func:`~auvnav.io.api.export_dive`). One module per format, listed in
:mod:`auvnav.io.registry`:

- importers: :mod:`~auvnav.io.acfr` (ACFR ``combined.RAW.auv`` with ``mission.cfg``),
  :mod:`~auvnav.io.pd0` (Teledyne RDI PD0 binary ensembles), :mod:`~auvnav.io.rosbag` (ROS 1 and
  ROS 2 bags), :mod:`~auvnav.io.nmea` (NMEA 0183 GPS and heading), :mod:`~auvnav.io.csvmap`
  (any CSV, with a mapping file);
- exporters: :mod:`~auvnav.io.geo` (GeoJSON and KML), :mod:`~auvnav.io.tables` (the trajectory as
  CSV with latitude, longitude and sigmas), :mod:`~auvnav.io.acfr` (``stereo_pose_est.data``),
  :mod:`~auvnav.io.priors` (camera position priors for COLMAP and Metashape),
  :mod:`~auvnav.io.firmware` (the compass correction table for a vehicle's firmware).

What every importer shares (the settings, the rules for heading reference, pressure and origin,
one-line errors, the assembly of a dive) is in :mod:`~auvnav.io.common`.

Import from the modules; the package itself imports only the two entry points.
"""

from __future__ import annotations

from auvnav.io.api import export_dive, import_dive

__all__ = ["export_dive", "import_dive"]
