"""SLAM back end: pose graphs, their files and their solution with GTSAM.

- :mod:`auvnav.slam.g2o`: the :class:`PoseGraph` container and the g2o/TORO reader and writer.
- :mod:`auvnav.slam.solve`: chi-square cost, batch Levenberg-Marquardt, incremental iSAM2, robust
  loop closures, marginal covariances.
- :mod:`auvnav.slam.synthetic`: survey pose graphs with a known truth, for tests and benchmarks.
- :mod:`auvnav.slam.graph`: a dive's sensor graph (DVL, attitude, depth, compass, fixes, loop
  closures), solved in batch or with iSAM2; :mod:`auvnav.slam.compass`: its heading factor and the
  deviation estimated inside it; :mod:`auvnav.slam.products`: the ``auvnav slam`` stage.
"""

from auvnav.slam.g2o import PoseGraph, PoseGraphFormatError, read_g2o, write_g2o
from auvnav.slam.solve import (
    PoseGraphSolveError,
    SolveResult,
    chi2_cost,
    marginal_covariances,
    optimize_batch,
    optimize_incremental,
    to_gtsam,
)

__all__ = [
    "PoseGraph",
    "PoseGraphFormatError",
    "PoseGraphSolveError",
    "SolveResult",
    "chi2_cost",
    "marginal_covariances",
    "optimize_batch",
    "optimize_incremental",
    "read_g2o",
    "to_gtsam",
    "write_g2o",
]
