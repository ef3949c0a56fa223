"""The reconstruction's mesh, decimated for the report's figure and its 3D view.

The mesh is read with Open3D (loaded only through :func:`auvnav.recon.o3d.open3d`) and reduced to at
most a given number of triangles: first by vertex clustering on a grid sized from the mesh's extent
(fast, linear in its size: a survey's mesh has millions of triangles), then by quadric error
decimation (:meth:`simplify_quadric_decimation`) to the target, which keeps the relief's shape.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from auvnav.errors import AuvnavError
from auvnav.frames import FloatArray

#: The report's mesh (its figure and its 3D view): at most this many triangles.
REPORT_TRIANGLES = 30_000
#: Vertex clustering first brings a mesh larger than this many times the target near the target.
_CLUSTER_FACTOR = 2


@dataclass(frozen=True)
class DecimatedMesh:
    """A mesh small enough to draw.

    Parameters
    ----------
    vertices_m : ndarray, shape (V, 3)
        East, north, up about the dive's origin, metres (the recon stage's frame).
    triangles : ndarray of int, shape (T, 3)
    colours : ndarray, shape (V, 3), or None
        RGB in [0, 1].
    full_triangles : int
        Triangles of the mesh as written.
    """

    vertices_m: FloatArray
    triangles: NDArray[np.int64]
    colours: FloatArray | None
    full_triangles: int

    @property
    def has_colour(self) -> bool:
        """The vertices have colours that vary (a mesh without texture has one grey everywhere)."""
        return self.colours is not None and float(self.colours.std(axis=0).max()) > 0.01


def read_decimated_mesh(path: Path, max_triangles: int) -> DecimatedMesh:
    """The PLY mesh at ``path`` with at most ``max_triangles`` triangles (module docstring); the last
    few are remembered by the file's size and time, so the figure and the 3D view read it once."""
    st = Path(path).stat()
    return _decimated(str(Path(path).resolve()), st.st_size, st.st_mtime_ns, int(max_triangles))


@functools.lru_cache(maxsize=2)
def _decimated(path: str, size: int, mtime_ns: int, max_triangles: int) -> DecimatedMesh:
    from auvnav.recon.o3d import open3d

    o3d = open3d()
    mesh = o3d.io.read_triangle_mesh(str(path))
    full = len(mesh.triangles)
    if full == 0:
        raise AuvnavError(f"{path}: no triangles")
    if full > _CLUSTER_FACTOR * max_triangles:
        lo, hi = mesh.get_min_bound(), mesh.get_max_bound()
        area = max(float((hi[0] - lo[0]) * (hi[1] - lo[1])), 1e-6)
        # a height field of V vertices on a grid has about 2 V triangles
        voxel = math.sqrt(area / (max_triangles / 2.0))
        mesh = mesh.simplify_vertex_clustering(
            voxel_size=voxel, contraction=o3d.geometry.SimplificationContraction.Average
        )
        mesh.remove_degenerate_triangles()
        mesh.remove_duplicated_triangles()
        mesh.remove_non_manifold_edges()
    if len(mesh.triangles) > max_triangles:
        mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=int(max_triangles))
    mesh.remove_unreferenced_vertices()
    vertices = np.asarray(mesh.vertices, dtype=float)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    colours = np.asarray(mesh.vertex_colors, dtype=float) if mesh.has_vertex_colors() else None
    return DecimatedMesh(vertices, triangles, colours, full)
