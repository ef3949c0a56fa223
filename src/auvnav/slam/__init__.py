"""SLAM back end: pose graphs, their files and their solution with GTSAM.

- :mod:`auvnav.slam.g2o`: the :class:`PoseGraph` container and the g2o/TORO reader and writer.
- :mod:`auvnav.slam.solve`: chi-square cost, batch Levenberg-Marquardt, incremental iSAM2, robust
  loop closures, marginal covariances.
- :mod:`auvnav.slam.synthetic`: survey pose graphs with a known truth, for tests and benchmarks.
- :mod:`auvnav.slam.poses`, :mod:`auvnav.slam.graph`, :mod:`auvnav.slam.optimize`: a dive's
  sensor graph (its poses; DVL, attitude, depth, compass, fixes and loop-closure factors), solved
  in batch or with iSAM2, with marginals; :mod:`auvnav.slam.compass`: its heading factor and the
  deviation estimated inside it; :mod:`auvnav.slam.result`: all of it for one dive;
  :mod:`auvnav.slam.stage`: the ``auvnav slam`` stage.

Import from the modules; the package itself imports nothing, so that its parts load only when used.
"""
