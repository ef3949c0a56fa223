"""Reconstruction: dense stereo, a fused 3D mesh, a DEM, a photomosaic and the false-relief check.

The paper's "3D optical reconstructions" (Fig. 10) and its Fig. 11 (false relief where an uncompensated
tide meets a revisit): :mod:`~auvnav.recon.dense` (semi-global matching per stereo pair, depth and its
uncertainty, cached), :mod:`~auvnav.recon.placement` (each depth map placed by a trajectory, with the
tide), :mod:`~auvnav.recon.fusion` (per map tile: DEM, orthophoto, TSDF mesh, revisits),
:mod:`~auvnav.recon.writers` (GeoTIFFs written tile by tile, the PLY), :mod:`~auvnav.recon.reconstruct`
(the whole run) and ``stage.py`` (``auvnav recon``). Open3D loads only through
:func:`auvnav.recon.o3d.open3d`.
"""
