"""Coverage: where a survey's images fell, its gaps, and the spacing of its lines (paper Fig. 2).

- :mod:`~auvnav.coverage.plan`: the lines, adjacent pairs and planned area of a mission;
- :mod:`~auvnav.coverage.lines`: the lines a track flew and each pair's spacing, classified on plan,
  'accordion' or 'figure 8';
- :mod:`~auvnav.coverage.grid`: footprints counted on a map grid, gaps and their widths;
- :mod:`~auvnav.coverage.analysis`: the whole measurement on a dive's images
  (:func:`~auvnav.coverage.analysis.analyse_coverage`);
- :mod:`~auvnav.coverage.predict`: before the dive, spacing and gaps predicted from the compass
  correction's uncertainty (Monte Carlo over the heading error);
- :mod:`~auvnav.coverage.figure`: the coverage map as a PNG (OpenCV);
- :mod:`~auvnav.coverage.evaluate`: a simulated dive's coverage products against its truth;
- :mod:`~auvnav.coverage.stage`: the pipeline stage (``auvnav coverage DIVE``).
"""
